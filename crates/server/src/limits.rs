//! Admission: the one path from request bytes to something storable.
//!
//! `parse → limits → Clip::build → canonical JSON`, all before the store is
//! touched, so nothing half-valid is ever written. The canonical document is
//! the parsed [`ClipDoc`] re-serialised: `GET` returns exactly what was
//! accepted, normalised (defaults spelled out, numbers in shortest form).

use std::sync::atomic::AtomicBool;

use crate::store::{ClipStats, MeshWrite, NewClip};
use anim::ik::IkLimits;
use anim::lint::{Lint, lint};
use anim::spring::SpringsSpec;
use anim::{Clip, ClipError, ClipErrorKind, ClipSpec};
use formats::wire::json::{ClipDoc, DocError};

use super::config::Limits;
use super::error::ApiError;

/// A clip that passed every check: what to store, its compiled form, and
/// what in it looks valid but probably wrong (tracks and keys of the
/// document as given; the caller renders them where they were sent).
#[derive(Debug)]
pub struct Admitted {
    pub new_clip: NewClip,
    pub clip: Clip,
    /// Its spring chains, checked against the clip's skeleton.
    pub springs: SpringsSpec,
    pub lints: Vec<Lint>,
}

/// Validates a parsed document (importers: `ClipDoc::from_spec`, then this).
/// The build stops early once `cancel` is raised (its caller gave up).
///
/// # Errors
/// A type error, a documented rule or a limit (422), each with the JSON
/// pointer of the offending field.
pub fn admit_doc(doc: ClipDoc, limits: &Limits, cancel: &AtomicBool) -> Result<Admitted, ApiError> {
    let spec = checked_spec(&doc, limits)?;
    admit_spec(doc, &spec, limits, cancel)
}

/// The spec of a document within the limits on its counts (tracks, keys,
/// labels): what a build's price is worked out from.
///
/// # Errors
/// A limit, or a documented rule the spec's conversion checks (422).
pub fn checked_spec(doc: &ClipDoc, limits: &Limits) -> Result<ClipSpec, ApiError> {
    check(doc, limits)?;
    Ok(doc.to_spec()?)
}

/// Builds `spec` (of `doc`, checked by [`checked_spec`]) and makes the
/// clip to store.
///
/// # Errors
/// As [`admit_doc`], less the limits on counts.
pub fn admit_spec(doc: ClipDoc, spec: &ClipSpec, limits: &Limits, cancel: &AtomicBool) -> Result<Admitted, ApiError> {
    let clip = build(spec, limits.max_build_work, &limits.ik(), cancel)?;
    if clip.joint_count() > limits.max_joints {
        return Err(too_many("too_many_joints", "/tracks", "joints", clip.joint_count(), limits.max_joints));
    }
    let springs = doc.springs()?;
    formats::wire::spring::compile_springs(&springs, clip.skeleton(), "")?;
    let doc_json = serde_json::to_string(&doc).map_err(ApiError::internal)?;
    let stats = ClipStats {
        joints: clip.joint_count() as u32,
        tracks: clip.track_count() as u32,
        events: clip.events().len() as u32,
        start: clip.start(),
        end: clip.end(),
        playback: clip.playback(),
    };
    let joint_names = clip.skeleton().names().to_vec();
    let new_clip = NewClip { name: doc.name, doc_json, stats, tags: doc.tags, joint_names, mesh: MeshWrite::None };
    Ok(Admitted { new_clip, clip, springs, lints: lint(spec) })
}

/// `Clip::build_limited` within `max_work` and the IK ceilings, the budget
/// refusal naming its setting.
///
/// # Errors
/// A documented rule (422 with the rule's code), or `build_budget_exceeded` (422).
pub fn build(spec: &ClipSpec, max_work: u64, ik: &IkLimits, cancel: &AtomicBool) -> Result<Clip, ApiError> {
    Clip::build_limited(spec, max_work, ik, cancel).map_err(|e| match e {
        ClipError { kind: kind @ ClipErrorKind::BuildBudgetExceeded { .. }, path } => ApiError::TooMany {
            code: kind.code(),
            pointer: path.to_pointer(),
            detail: format!("{kind}; the limit is max_build_work (--max-build-work)"),
        },
        e => DocError::from(e).into(),
    })
}

fn too_many(code: &'static str, pointer: &str, what: &str, got: usize, max: usize) -> ApiError {
    ApiError::TooMany { code, pointer: pointer.to_owned(), detail: format!("{got} {what}; the limit is {max}") }
}

/// At most this many tags per clip, each 1..=[`MAX_TAG_CHARS`] characters.
pub const MAX_TAGS: usize = 32;
pub const MAX_TAG_CHARS: usize = 64;
/// The largest `metadata` object, as compact JSON.
pub const MAX_METADATA_BYTES: usize = 16 * 1024;

/// Tags are labels to filter by: short, distinct, printable. Metadata is
/// kept, never read, but bounded: it travels with every `GET` of the clip.
///
/// # Errors
/// `too_many_tags`, `bad_tag`, `duplicate_tag`, `metadata_too_large`.
fn check_labels(doc: &ClipDoc) -> Result<(), ApiError> {
    if doc.tags.len() > MAX_TAGS {
        return Err(too_many("too_many_tags", "/tags", "tags", doc.tags.len(), MAX_TAGS));
    }
    for (i, tag) in doc.tags.iter().enumerate() {
        let chars = tag.chars().count();
        if chars == 0 || chars > MAX_TAG_CHARS || tag.chars().any(char::is_control) || tag.trim() != tag {
            let detail = format!(
                "a tag has 1..={MAX_TAG_CHARS} characters, no control characters and no surrounding spaces; got {tag:?}"
            );
            return Err(ApiError::invalid("bad_tag", format!("/tags/{i}"), detail));
        }
        if doc.tags[..i].contains(tag) {
            return Err(ApiError::invalid(
                "duplicate_tag",
                format!("/tags/{i}"),
                format!("the tag {tag:?} is given twice"),
            ));
        }
    }
    if let Some(metadata) = &doc.metadata {
        let bytes = serde_json::to_vec(metadata).map_err(ApiError::internal)?.len();
        if bytes > MAX_METADATA_BYTES {
            return Err(too_many("metadata_too_large", "/metadata", "bytes of metadata", bytes, MAX_METADATA_BYTES));
        }
    }
    Ok(())
}

fn check(doc: &ClipDoc, limits: &Limits) -> Result<(), ApiError> {
    check_labels(doc)?;
    if doc.tracks.len() > limits.max_tracks {
        return Err(too_many("too_many_tracks", "/tracks", "tracks", doc.tracks.len(), limits.max_tracks));
    }
    if let Some(skeleton) = &doc.skeleton
        && skeleton.joints.len() > limits.max_joints
    {
        let n = skeleton.joints.len();
        return Err(too_many("too_many_joints", "/skeleton/joints", "joints", n, limits.max_joints));
    }
    for (i, t) in doc.tracks.iter().enumerate() {
        let n = t.times.len().max(t.values.len());
        if n > limits.max_keys_per_track {
            let pointer = format!("/tracks/{i}/times");
            return Err(too_many("too_many_keys", &pointer, "keys", n, limits.max_keys_per_track));
        }
    }
    if doc.parameters.len() > limits.max_parameters {
        let n = doc.parameters.len();
        return Err(too_many("too_many_parameters", "/parameters", "parameters", n, limits.max_parameters));
    }
    for (i, p) in doc.parameters.iter().enumerate() {
        let n = p.times.len().max(p.values.len());
        if n > limits.max_keys_per_track {
            let pointer = format!("/parameters/{i}/times");
            return Err(too_many("too_many_keys", &pointer, "keys", n, limits.max_keys_per_track));
        }
    }
    Ok(())
}
