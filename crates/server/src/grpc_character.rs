//! The character RPCs (docs/characters.md): the gRPC mirror of
//! `/v1/characters`. A `Character` message becomes the character document
//! (its skeleton through the clip conversion of `wire::proto`, so pointers
//! read `/skeleton/joints/3/…` as over REST), is admitted by
//! `server::characters` priced and off the async workers, and stored by the
//! same store calls; answers carry the REST summary's fields and codes.

use std::collections::BTreeMap;

use bytes::Bytes;
use prost::Message;

use crate::auth::Caller;
use crate::characters::{self, store_error};
use crate::documents::{page, raw_page};
use crate::error::ApiError;
use crate::request::{Raw, in_body};
use crate::rest::characters::CharacterSummary;
use crate::rest::import::{ImportFile, admit_characters, checked_name, checked_scale, import_limits, run_import};
use crate::state::AppState;
use crate::store::{CharacterMeta, DocKind, NewCharacter, OnName};
use formats::import::{ImportOptions, Source, Warning, file_stem};
use formats::wire::character::{CharacterDoc, parse_character_doc};
use formats::wire::proto::{clip_from_pb, clip_to_pb, pb};

/// `CreateCharacter`: `POST /v1/characters`.
pub async fn create(
    state: &AppState,
    caller: &Caller,
    req: pb::CreateCharacterRequest,
) -> Result<pb::CharacterSummary, ApiError> {
    let on_name = if req.replace { OnName::Replace } else { OnName::Refuse };
    let character = admit_message(state, caller, req.character).await?;
    let meta = characters::create(state, character, on_name).await?;
    tracing::info!(id = %meta.id, version = meta.version, "character written over gRPC");
    Ok(summary_to_pb(&meta))
}

/// `ReplaceCharacter`: `PUT /v1/characters/{id}`.
pub async fn replace(
    state: &AppState,
    caller: &Caller,
    req: pb::ReplaceCharacterRequest,
) -> Result<pb::CharacterSummary, ApiError> {
    let character = admit_message(state, caller, req.character).await?;
    let meta = characters::replace(state, &req.character_id, character, req.if_version).await?;
    Ok(summary_to_pb(&meta))
}

/// `GetCharacter`: the summary and the document, by id or `name:` reference.
pub async fn get(state: &AppState, req: pb::GetCharacterRequest) -> Result<pb::CharacterRecord, ApiError> {
    let stored = state.store.character_by_ref(&req.character_id).await.map_err(store_error)?;
    let stored = stored.ok_or(ApiError::NotFound { what: "character" })?;
    let doc = parse_character_doc(stored.doc_json.as_bytes())?;
    Ok(pb::CharacterRecord { summary: Some(summary_to_pb(&stored.meta)), character: Some(doc_to_pb(doc)?) })
}

/// `ListCharacters`: `GET /v1/characters`.
pub async fn list(state: &AppState, req: pb::ListCharactersRequest) -> Result<pb::ListCharactersResponse, ApiError> {
    let text = |s: &str| (!s.is_empty()).then(|| s.to_owned());
    let (name, name_prefix, name_contains) = (text(&req.name), text(&req.name_prefix), text(&req.name_contains));
    // 0: the default.
    let limit = (req.limit > 0).then_some(Raw::Number(f64::from(req.limit)));
    let cursor = (!req.cursor.is_empty()).then_some(req.cursor.as_str());
    let names = [name.as_deref(), name_prefix.as_deref(), name_contains.as_deref()];
    let (metas, next_cursor) =
        page(&*state.store, DocKind::Character, raw_page(limit, cursor, names, in_body).check()?).await?;
    let metas: Vec<CharacterMeta> = metas.into_iter().map(Into::into).collect();
    let next_cursor = next_cursor.unwrap_or_default();
    Ok(pb::ListCharactersResponse { characters: metas.iter().map(summary_to_pb).collect(), next_cursor })
}

/// `DeleteCharacter`: `DELETE /v1/characters/{id}`.
pub async fn delete(
    state: &AppState,
    req: pb::DeleteCharacterRequest,
) -> Result<pb::DeleteCharacterResponse, ApiError> {
    state.store.delete_character(&req.character_id, req.if_version).await.map_err(store_error)?;
    state.document_changed(DocKind::Character, &req.character_id);
    tracing::info!(id = %req.character_id, "character deleted over gRPC");
    Ok(pb::DeleteCharacterResponse {})
}

/// `ImportCharacter`: `POST /v1/characters/import` with the file in the message.
pub async fn import(
    state: &AppState,
    caller: &Caller,
    req: pb::ImportCharacterRequest,
) -> Result<pb::ImportCharacterResponse, ApiError> {
    let on_name = if req.replace { OnName::Replace } else { OnName::Refuse };
    let text = given;
    let format = match text(&req.format) {
        Some(f) => Some(f.parse().map_err(|e| ApiError::parameter("bad_format", "format", e))?),
        None => None,
    };
    let up = match text(&req.up) {
        Some(up) => up.parse().map_err(|e| ApiError::parameter("bad_parameter", "up", e))?,
        None => Default::default(),
    };
    let scale = match req.scale {
        Some(s) if s.is_finite() => checked_scale(s, &s.to_string())?,
        Some(s) => return Err(ApiError::parameter("bad_number", "scale", format!("`scale` must be finite, got {s}"))),
        None => 1.0,
    };
    let options = ImportOptions {
        name: checked_name(text(&req.name), "name")?,
        name_prefix: checked_name(text(&req.name_prefix), "name_prefix")?,
        file_name: text(&req.file_name).and_then(file_stem),
        up,
        scale,
        characters_only: true,
        limits: import_limits(&state.config.limits),
        ..ImportOptions::default()
    };
    let file = ImportFile {
        document: Source::memory(Bytes::from(req.data)),
        siblings: Vec::new(),
        content_type: None,
        format,
    };
    let (_, _, (characters, warnings)) = run_import(state, &caller.key(), file, options, |imported, limits, cancel| {
        Ok((admit_characters(imported.characters, limits, cancel)?, imported.warnings))
    })
    .await?;
    let metas = characters::create_all(state, characters, on_name).await?;
    Ok(pb::ImportCharacterResponse {
        characters: metas.iter().map(summary_to_pb).collect(),
        warnings: warnings.into_iter().map(warning_to_pb).collect(),
    })
}

/// A `Character` message admitted as a document: [`characters::admit_priced`]
/// of its encoded size.
async fn admit_message(
    state: &AppState,
    caller: &Caller,
    character: Option<pb::Character>,
) -> Result<NewCharacter, ApiError> {
    let character = character
        .ok_or_else(|| ApiError::invalid("missing_character", "/character", "the request needs a character"))?;
    let bytes = character.encoded_len();
    characters::admit_priced(state, &caller.key(), bytes, "reading this character", move || doc_from_pb(character))
        .await
}

/// The document of a `Character` message: its skeleton as a clip's.
fn doc_from_pb(character: pb::Character) -> Result<CharacterDoc, ApiError> {
    let clip = pb::Clip { name: character.name.clone(), skeleton: character.skeleton, ..Default::default() };
    let spec = clip_from_pb(&clip)?;
    let skeleton = crate::characters::skeleton_doc(&spec);
    let mut roles: BTreeMap<String, Option<String>> =
        character.roles.into_iter().map(|(role, joint)| (role, Some(joint))).collect();
    roles.extend(character.unmapped_roles.into_iter().map(|role| (role, None)));
    Ok(CharacterDoc { name: character.name, skeleton, roles })
}

/// A stored document as a `Character` message.
fn doc_to_pb(doc: CharacterDoc) -> Result<pb::Character, ApiError> {
    let skeleton = clip_to_pb(&crate::characters::skeleton_clip(&doc).to_spec()?).skeleton;
    let (mut roles, mut unmapped_roles) = (std::collections::HashMap::new(), Vec::new());
    for (role, joint) in doc.roles {
        match joint {
            Some(joint) => drop(roles.insert(role, joint)),
            None => unmapped_roles.push(role),
        }
    }
    Ok(pb::Character { name: doc.name, skeleton, roles, unmapped_roles })
}

fn summary_to_pb(meta: &CharacterMeta) -> pb::CharacterSummary {
    let s = CharacterSummary::from(meta);
    pb::CharacterSummary {
        id: s.id,
        name: s.name,
        version: s.version,
        joints: s.joints,
        roles: (s.roles.roles.into_iter())
            .map(|(role, e)| (role, pb::RoleJoint { joint: e.joint, by: e.by }))
            .collect(),
        family: s.roles.family.unwrap_or_default(),
        warnings: s.warnings.into_iter().map(warning_to_pb).collect(),
        mesh: s.mesh,
    }
}

/// A string field given (proto3 has no absent strings: empty is absent).
fn given(s: &str) -> Option<&str> {
    (!s.is_empty()).then_some(s)
}

fn warning_to_pb(w: Warning) -> pb::Warning {
    pb::Warning { code: w.code, pointer: w.pointer, detail: w.detail }
}
