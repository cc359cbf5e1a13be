//! Character routes (docs/characters.md): create, list, get, replace,
//! delete. A character is stored and versioned like a clip (ETag,
//! `If-Match`, names that identify it); every write is checked whole
//! (`characters::admit`, priced and run off the async workers) before the
//! store is touched, and answered after the store committed.

use axum::Json;
use axum::extract::State;
use axum::http::header::IF_MATCH;
use axum::http::{HeaderMap, StatusCode};
use axum::response::Response;
use serde::Serialize;
use utoipa::ToSchema;

use crate::auth::{CallerKey, ReadAccess, WriteAccess};
use crate::characters::{self, RoleReport};
use crate::error::ApiError;
use crate::state::AppState;
use crate::store::{CharacterMeta, DocKind, NewCharacter};
use formats::import::Warning;
use formats::wire::character::parse_character_doc;

use super::documents;
use super::extract::{ClipId, JsonBody, etag, precondition};
use super::query::Query;
use super::summary::rfc3339;

/// A character's identity, skeleton size and role map, without its document.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct CharacterSummary {
    /// Opaque, URL-safe, time-ordered id.
    pub id: String,
    pub name: String,
    /// 1 on create, +1 on each replace.
    pub version: u64,
    /// Joints in the skeleton.
    pub joints: u32,
    #[serde(flatten)]
    pub roles: RoleReport,
    /// `missing_role` for each of hips, spine and the leg chains no joint plays.
    #[schema(value_type = Vec<super::schemas::Warning>)]
    pub warnings: Vec<Warning>,
    /// Whether a skinned mesh is kept with it (`GET /v1/characters/{id}/mesh`).
    pub mesh: bool,
    /// RFC 3339, UTC.
    pub created_at: String,
    pub updated_at: String,
    /// The strong entity tag of this version (as in the `ETag` header).
    pub etag: String,
}

impl From<&CharacterMeta> for CharacterSummary {
    fn from(m: &CharacterMeta) -> Self {
        // Written by `characters::admit`; a row changed behind the service's back reports no roles.
        let roles: RoleReport = serde_json::from_str(&m.roles_json).unwrap_or_default();
        CharacterSummary {
            id: m.id.clone(),
            name: m.name.clone(),
            version: m.version,
            joints: m.joints,
            warnings: roles.warnings(),
            roles,
            mesh: m.mesh,
            created_at: rfc3339(m.created_at),
            updated_at: rfc3339(m.updated_at),
            etag: etag(m.version),
        }
    }
}

/// A page of characters.
#[derive(Debug, Serialize, ToSchema)]
pub struct CharacterList {
    pub characters: Vec<CharacterSummary>,
    /// Pass as `cursor` for the next page; `null` on the last page.
    pub next_cursor: Option<String>,
}

/// A written character's summary (its `warnings` the role map's).
fn written(meta: &CharacterMeta, status: StatusCode, location: bool) -> Response {
    documents::written(DocKind::Character, (&meta.id, meta.version), status, location, CharacterSummary::from(meta))
}

/// Checks an uploaded document: [`characters::admit_priced`] of its bytes.
async fn admit_upload(state: &AppState, caller: &CallerKey, body: axum::body::Bytes) -> Result<NewCharacter, ApiError> {
    characters::admit_priced(state, caller, body.len(), "reading this character document", move || {
        Ok(parse_character_doc(&body)?)
    })
    .await
}

/// Create a character: a name, a skeleton (as in a clip document) and the roles given for its joints.
#[utoipa::path(
    post, path = "/v1/characters", tag = "characters",
    params(
        ("replace" = Option<bool>, Query, description = "true: when a character has this name, store the upload as its new version (same id, 200) instead of refusing it (409 name_taken)"),
    ),
    request_body(content = formats::wire::character::CharacterDoc, content_type = "application/json"),
    responses(
        (status = 201, description = "Stored; `Location` names the character; `roles` says which joint plays each role and how it was found, `warnings` which essential roles none does", body = CharacterSummary),
        (status = 200, description = "With replace=true, stored as the new version of the character of that name", body = CharacterSummary),
        (status = 400, description = "Not JSON", body = super::schemas::Problem),
        (status = 401, description = "Write token missing or wrong", body = super::schemas::Problem),
        (status = 409, description = "A character has this name (name_taken)", body = super::schemas::Problem),
        (status = 413, description = "Body over the limit", body = super::schemas::Problem),
        (status = 415, description = "Not application/json", body = super::schemas::Problem),
        (status = 422, description = "An invalid skeleton, an unknown role (unknown_role) or a given role naming a joint the skeleton lacks (unknown_joint), with a pointer", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn create_character(
    State(state): State<AppState>,
    WriteAccess(caller): WriteAccess,
    Query(params): Query,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let on_name = params.on_name()?;
    let character = admit_upload(&state, &caller.key(), body).await?;
    let meta = characters::create(&state, character, on_name).await?;
    tracing::info!(id = %meta.id, name = %meta.name, version = meta.version, "character created");
    let status = if meta.version == 1 { StatusCode::CREATED } else { StatusCode::OK };
    Ok(written(&meta, status, true))
}

/// List characters in creation order, a page at a time, optionally filtered by name.
#[utoipa::path(
    get, path = "/v1/characters", tag = "characters",
    params(
        ("limit" = Option<u32>, Query, minimum = 1, maximum = 1000, description = "Page size, 1..=1000 (default 100)"),
        ("cursor" = Option<String>, Query, pattern = "^[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}$", description = "`next_cursor` of the previous page (with the same filters)"),
        ("name" = Option<String>, Query, min_length = 1, max_length = 256, description = "Only the character with exactly this name"),
        ("name_prefix" = Option<String>, Query, min_length = 1, max_length = 256, description = "Only characters whose name starts with this (case-sensitive): a folder such as fox/"),
        ("name_contains" = Option<String>, Query, min_length = 1, max_length = 256, description = "Only characters whose name contains this (case-sensitive)"),
    ),
    responses(
        (status = 200, body = CharacterList),
        (status = 400, body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn list_characters(
    State(state): State<AppState>,
    _: ReadAccess,
    Query(q): Query,
) -> Result<Json<CharacterList>, ApiError> {
    let (metas, next_cursor) =
        crate::documents::page(&*state.store, DocKind::Character, documents::list_page(&q).check()?).await?;
    let metas: Vec<CharacterMeta> = metas.into_iter().map(Into::into).collect();
    Ok(Json(CharacterList { characters: metas.iter().map(CharacterSummary::from).collect(), next_cursor }))
}

/// The stored character document, exactly as accepted, with its `ETag`.
#[utoipa::path(
    get, path = "/v1/characters/{id}", tag = "characters",
    params(("id" = String, Path, description = "Character id")),
    responses(
        (status = 200, description = "The character document", body = formats::wire::character::CharacterDoc),
        (status = 304, description = "`If-None-Match` matched"),
        (status = 404, description = "No such character (character_not_found)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn get_character(
    State(state): State<AppState>,
    _: ReadAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    documents::get(&state, DocKind::Character, &id, &headers).await
}

/// Replace a character's document; the version goes up by one, and a kept mesh is dropped (the new skeleton may not fit it).
#[utoipa::path(
    put, path = "/v1/characters/{id}", tag = "characters",
    params(
        ("id" = String, Path, description = "Character id"),
        ("If-Match" = Option<String>, Header, pattern = r#"^(\*|"[0-9]{1,19}")$"#, description = "Replace only at this version (`\"3\"`) or `*`"),
    ),
    request_body(content = formats::wire::character::CharacterDoc, content_type = "application/json"),
    responses(
        (status = 200, description = "Replaced", body = CharacterSummary),
        (status = 404, body = super::schemas::Problem),
        (status = 409, description = "Renamed to another character's name (name_taken)", body = super::schemas::Problem),
        (status = 412, description = "`If-Match` did not match the current version", body = super::schemas::Problem),
        (status = 422, body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn replace_character(
    State(state): State<AppState>,
    WriteAccess(caller): WriteAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let condition = precondition(&headers, IF_MATCH, false)?;
    let character = admit_upload(&state, &caller.key(), body).await?;
    let expected = documents::expected_version(&state, DocKind::Character, &id, condition).await?;
    let meta = characters::replace(&state, &id, character, expected).await?;
    tracing::info!(id = %meta.id, version = meta.version, "character replaced");
    Ok(written(&meta, StatusCode::OK, false))
}

/// Delete a character (honours `If-Match`).
#[utoipa::path(
    delete, path = "/v1/characters/{id}", tag = "characters",
    params(
        ("id" = String, Path, description = "Character id"),
        ("If-Match" = Option<String>, Header, pattern = r#"^(\*|"[0-9]{1,19}")$"#, description = "Delete only at this version"),
    ),
    responses(
        (status = 204, description = "Deleted"),
        (status = 404, body = super::schemas::Problem),
        (status = 412, body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn delete_character(
    State(state): State<AppState>,
    _: WriteAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
) -> Result<StatusCode, ApiError> {
    documents::delete(&state, DocKind::Character, &id, &headers).await
}
