//! Characters at the service's edge (docs/characters.md): a character
//! document, uploaded or imported, checked and turned into what the store
//! keeps (`store::NewCharacter`) and what answers report (its role map and
//! `missing_role` warnings). REST, gRPC and imports share it, and so do the
//! motions that play on a stored character ([`resolve`]: checked once per
//! version, kept in the cache of built documents by id and version).
//!
//! The skeleton is checked by the core, as a clip's is: a "rest clip" (the
//! skeleton with one constant key) goes through `Clip::build` under the clip
//! limits, so a character's joints obey exactly the rules and limits of a
//! clip's, and its errors point into the character document (`/name`,
//! `/skeleton/joints/3/parent`). The roles are `anim::character::RoleMap`'s:
//! the given ones, then names, then structure.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use glam::Vec4;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::auth::CallerKey;
use crate::built::BuiltCharacter;
use crate::config::Limits;
use crate::error::{ApiError, At};
use crate::limits::{Admitted, admit_spec, checked_spec};
use crate::state::AppState;
use crate::store::{
    CharacterMeta, DocKind, MeshWrite, NewCharacter, OnName, StoreError, StoredCharacter, name_reference,
};
use anim::character::{Role, RoleError, RoleMap};
use anim::motion::CharacterSpec;
use anim::{Channel, Clip, Interpolation, Keys, Skeleton, TrackSpec};
use formats::import::Warning;
use formats::wire::character::{CharacterDoc, parse_character_doc};
use formats::wire::json::{ClipDoc, SkeletonDoc};

/// The `missing_role` warning code (docs/warnings.md).
pub const MISSING_ROLE: &str = "missing_role";

/// A checked character: its skeleton (as the rest clip's), its role map,
/// and what the store keeps.
#[derive(Debug)]
pub struct Character {
    /// The skeleton with one constant key at its first joint: what the
    /// core built, so its skeleton obeys every clip rule.
    pub rest_clip: Clip,
    pub roles: RoleMap,
    pub report: RoleReport,
}

impl Character {
    pub fn skeleton(&self) -> &Skeleton {
        self.rest_clip.skeleton()
    }

    /// A stored character as checked again from its document (stored
    /// documents were accepted by [`admit`], so this fails only on a store
    /// whose rows were changed behind the service's back).
    ///
    /// # Errors
    /// As [`admit`].
    pub fn of_stored(stored: &StoredCharacter, limits: &Limits, cancel: &AtomicBool) -> Result<Character, ApiError> {
        let doc = parse_character_doc(stored.doc_json.as_bytes())?;
        Ok(admit(doc, MeshWrite::None, limits, cancel)?.character)
    }
}

/// An admitted write: the character and the row to store (its warnings
/// are its role report's, [`RoleReport::warnings`]).
#[derive(Debug)]
pub struct AdmittedCharacter {
    pub character: Character,
    pub new_character: NewCharacter,
}

/// How each mapped role was found, as summaries report it.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, ToSchema)]
pub struct RoleReport {
    /// Role (VRM 1.0 humanoid bone name) → the joint playing it.
    pub roles: BTreeMap<String, RoleEntry>,
    /// The naming family the joint names were read by (`mixamo`,
    /// `motionbuilder`, `cmu_asf`, `daz`, `unreal`, `vrm`, `blender`), if any.
    pub family: Option<String>,
}

/// The joint playing a role, and how it was found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct RoleEntry {
    pub joint: String,
    /// `given` (in the document's `roles`), `name` (read from the joint
    /// names) or `structure` (read from the rest pose's shape).
    #[schema(pattern = "^(given|name|structure)$")]
    pub by: String,
}

impl RoleReport {
    pub fn of(roles: &RoleMap, skeleton: &Skeleton) -> RoleReport {
        let entry = |j: anim::character::RoleJoint| RoleEntry {
            joint: skeleton.names()[j.joint].clone(),
            by: j.by.as_str().to_owned(),
        };
        RoleReport {
            roles: roles.iter().map(|(role, j)| (role.name().to_owned(), entry(j))).collect(),
            family: roles.family().map(str::to_owned),
        }
    }

    /// The `missing_role` warnings: the essential roles no joint plays.
    pub fn warnings(&self) -> Vec<Warning> {
        anim::character::ESSENTIAL_ROLES
            .iter()
            .filter(|role| !self.roles.contains_key(role.name()))
            .map(|role| Warning {
                code: MISSING_ROLE.to_owned(),
                pointer: format!("/roles/{}", role.name()),
                detail: format!(
                    "no joint plays {}: give it in `roles` (a joint name), or retargeting onto or from this \
                     skeleton leaves it out",
                    role.name()
                ),
            })
            .collect()
    }
}

/// Admits the document `read` makes (an upload parsed, a gRPC message
/// converted) on the work pool, priced as a clip document's reading of
/// `bytes` bytes (its skeleton's build is part of that price: one key, and
/// names and rest values the bytes bound); `what` names the work in a
/// refusal of its price. REST's and gRPC's creates and replaces.
///
/// # Errors
/// `too_much_work` over `max_request_work`; what `read` returns; as [`admit`].
pub async fn admit_priced<F>(
    state: &AppState,
    caller: &CallerKey,
    bytes: usize,
    what: &str,
    read: F,
) -> Result<NewCharacter, ApiError>
where
    F: FnOnce() -> Result<CharacterDoc, ApiError> + Send + 'static,
{
    let limits = state.config.limits.clone();
    let units = crate::work::price::parse(bytes as u64);
    crate::builds::run(&state.work, caller, &state.config.limits, units, what, move |cancel| {
        Ok(admit(read()?, MeshWrite::None, &limits, cancel)?.new_character)
    })
    .await
}

/// Stores `characters` in one transaction, each a new character or, as
/// `on_name` allows, the new version of the one holding its name, and
/// tells every node: the creates and imports of REST and gRPC.
///
/// # Errors
/// The store's refusal (`name_taken`, …).
pub async fn create_all(
    state: &AppState,
    characters: Vec<NewCharacter>,
    on_name: OnName,
) -> Result<Vec<CharacterMeta>, ApiError> {
    let metas = state.store.create_characters(characters, on_name).await.map_err(store_error)?;
    metas.iter().for_each(|m| state.document_changed(DocKind::Character, &m.id));
    Ok(metas)
}

/// [`create_all`] of one character: `POST /v1/characters` and `CreateCharacter`.
///
/// # Errors
/// As [`create_all`].
pub async fn create(state: &AppState, character: NewCharacter, on_name: OnName) -> Result<CharacterMeta, ApiError> {
    let meta = create_all(state, vec![character], on_name).await?.pop();
    meta.ok_or_else(|| ApiError::internal(anyhow::anyhow!("a create wrote no character")))
}

/// Stores `character` as character `id`'s next version (at `expected` if
/// given) and tells every node: `PUT /v1/characters/{id}` and `ReplaceCharacter`.
///
/// # Errors
/// The store's refusal (not found, a version race, `name_taken`).
pub async fn replace(
    state: &AppState,
    id: &str,
    character: NewCharacter,
    expected: Option<u64>,
) -> Result<CharacterMeta, ApiError> {
    let meta = state.store.replace_character(id, character, expected).await.map_err(store_error)?;
    state.document_changed(DocKind::Character, &meta.id);
    Ok(meta)
}

/// Checks `doc` (its skeleton by the clip rules and limits, its given
/// roles against its joints) and makes the row to store with `mesh`.
///
/// # Errors
/// 422 with a pointer: `empty_skeleton`, any skeleton rule or limit of a
/// clip, `unknown_role` (a `roles` key that is no VRM humanoid bone), and
/// the role map's own (`unknown_joint`, `joint_has_two_roles`) at `/roles/<role>`.
pub fn admit(
    doc: CharacterDoc,
    mesh: MeshWrite,
    limits: &Limits,
    cancel: &AtomicBool,
) -> Result<AdmittedCharacter, ApiError> {
    let rest_clip = rest_clip(&doc, limits, cancel)?;
    let given = given_roles(&doc)?;
    let roles = RoleMap::infer(rest_clip.skeleton(), &given).map_err(role_error)?;
    let report = RoleReport::of(&roles, rest_clip.skeleton());
    let new_character = NewCharacter {
        name: doc.name.clone(),
        doc_json: serde_json::to_string(&doc).map_err(ApiError::internal)?,
        joints: rest_clip.joint_count() as u32,
        roles_json: serde_json::to_string(&report).map_err(ApiError::internal)?,
        mesh,
    };
    Ok(AdmittedCharacter { character: Character { rest_clip, roles, report }, new_character })
}

/// A clip document of the character's skeleton and nothing else: how the
/// core checks and builds a skeleton (and the wire writes one).
pub fn skeleton_clip(doc: &CharacterDoc) -> ClipDoc {
    ClipDoc {
        name: doc.name.clone(),
        skeleton: Some(doc.skeleton.clone()),
        tracks: Vec::new(),
        events: Vec::new(),
        playback: Default::default(),
        ik: Vec::new(),
        parameters: Vec::new(),
        tags: Vec::new(),
        metadata: None,
        springs: Vec::new(),
    }
}

/// The skeleton of a clip (an imported skin's, a gRPC message's) as a
/// character document's: the way back from [`skeleton_clip`].
pub fn skeleton_doc(spec: &anim::ClipSpec) -> SkeletonDoc {
    ClipDoc::from_spec(spec).skeleton.unwrap_or(SkeletonDoc { joints: Vec::new() })
}

/// The skeleton built by the core as a clip with one constant key.
fn rest_clip(doc: &CharacterDoc, limits: &Limits, cancel: &AtomicBool) -> Result<Clip, ApiError> {
    let Some(first) = doc.skeleton.joints.first() else {
        let detail = "a character's skeleton needs at least one joint".to_owned();
        return Err(ApiError::Invalid { code: "empty_skeleton", at: At::Pointer("/skeleton/joints".into()), detail });
    };
    let clip_doc = skeleton_clip(doc);
    let mut spec = checked_spec(&clip_doc, limits)?;
    let key = Keys::Vec4(vec![Vec4::W]);
    spec.tracks.push(TrackSpec::new(&first.name, Channel::Rotation, Interpolation::Step, vec![0.0], key));
    let Admitted { clip, .. } = admit_spec(clip_doc, &spec, limits, cancel)?;
    Ok(clip)
}

/// The document's `roles`, each key a role.
fn given_roles(doc: &CharacterDoc) -> Result<Vec<(Role, Option<&str>)>, ApiError> {
    doc.roles
        .iter()
        .map(|(name, joint)| match Role::from_name(name) {
            Some(role) => Ok((role, joint.as_deref())),
            None => Err(ApiError::Invalid {
                code: "unknown_role",
                at: At::Pointer(format!("/roles/{}", pointer_token(name))),
                detail: format!(
                    "{name:?} is not a humanoid role: roles are VRM 1.0's bone names, such as hips, spine, \
                     leftUpperArm, rightFoot (docs/characters.md)"
                ),
            }),
        })
        .collect()
}

fn role_error(e: RoleError) -> ApiError {
    let at = At::Pointer(format!("/roles/{}", e.role().name()));
    ApiError::Invalid { code: e.code(), at, detail: e.to_string() }
}

/// `s` as one JSON pointer reference token (RFC 6901).
fn pointer_token(s: &str) -> String {
    s.replace('~', "~0").replace('/', "~1")
}

/// A store refusal of a character write or read: as a clip's, but a
/// missing row is a missing character.
pub fn store_error(e: StoreError) -> ApiError {
    crate::documents::store_error(DocKind::Character, e)
}

/// The character `reference` names (an id or `name:…`) at its current
/// version: the cache's entry, or its document read and checked on the
/// pool (priced by its bytes, charged to `caller`) and cached.
///
/// # Errors
/// `character_not_found` (404) at `/motion/character`; the price's
/// refusals; the store's errors.
pub async fn resolve(state: &AppState, caller: &CallerKey, reference: &str) -> Result<Arc<BuiltCharacter>, ApiError> {
    if name_reference(reference).is_none()
        && let Some(hit) = state.characters.get(reference)
    {
        return Ok(hit);
    }
    let seen = state.characters.epoch();
    let stored = state.store.doc_by_ref(DocKind::Character, reference).await.map_err(store_error)?;
    let stored = stored.ok_or_else(|| ApiError::CharacterNotFoundAt {
        at: At::Pointer("/motion/character".into()),
        detail: format!("the character `{reference}` does not exist"),
    })?;
    if let Some(hit) = state.characters.get(&stored.meta.id).filter(|hit| hit.meta.version == stored.meta.version) {
        return Ok(hit);
    }
    let (limits, units) = (state.config.limits.clone(), crate::work::price::parse(stored.doc_json.len() as u64));
    let read = crate::builds::run(&state.work, caller, &state.config.limits, units, "reading the character", {
        move |cancel| {
            // The skeleton's names and rest pose, the role map: about the document's size twice over.
            let bytes = std::mem::size_of::<BuiltCharacter>() + stored.doc_json.len() * 2;
            let meta = stored.meta.clone();
            let character = Character::of_stored(&StoredCharacter::from(stored), &limits, cancel)?;
            let spec =
                CharacterSpec { skeleton: character.skeleton().clone(), roles: character.roles, reference: None };
            Ok(BuiltCharacter { meta, spec: Arc::new(spec), bytes })
        }
    });
    let built = Arc::new(read.await?);
    state.characters.insert_loaded(Arc::clone(&built), seen);
    state.cache_gauges();
    Ok(built)
}
