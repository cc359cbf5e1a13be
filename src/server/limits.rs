//! Admission: the one path from request bytes to something storable.
//!
//! `parse → limits → Clip::build → canonical JSON`, all before the store is
//! touched, so nothing half-valid is ever written. The canonical document is
//! the parsed [`ClipDoc`] re-serialised: `GET` returns exactly what was
//! accepted, normalised (defaults spelled out, numbers in shortest form).

use std::sync::atomic::AtomicBool;

use crate::anim::{Clip, ClipError, ClipErrorKind, ClipSpec};
use crate::store::{ClipStats, NewClip};
use crate::wire::json::{ClipDoc, DocError, parse_clip_doc};

use super::config::Limits;
use super::error::ApiError;

/// A clip that passed every check: what to store and its compiled form.
#[derive(Debug)]
pub struct Admitted {
    pub new_clip: NewClip,
    pub clip: Clip,
}

/// Validates an uploaded clip document.
///
/// # Errors
/// `malformed_json` (400); a type error, a SPEC rule or a limit (422), each
/// with the JSON pointer of the offending field.
pub fn admit(body: &[u8], limits: &Limits, cancel: &AtomicBool) -> Result<Admitted, ApiError> {
    admit_doc(parse_clip_doc(body)?, limits, cancel)
}

/// Validates a parsed document (importers: `ClipDoc::from_spec`, then this).
/// The build stops early once `cancel` is raised (its caller gave up).
///
/// # Errors
/// As [`admit`], less the JSON syntax.
pub fn admit_doc(doc: ClipDoc, limits: &Limits, cancel: &AtomicBool) -> Result<Admitted, ApiError> {
    check(&doc, limits)?;
    let spec = doc.to_spec()?;
    let clip = build(&spec, limits.max_build_work, cancel)?;
    if clip.joint_count() > limits.max_joints {
        return Err(too_many("too_many_joints", "/tracks", "joints", clip.joint_count(), limits.max_joints));
    }
    let doc_json = serde_json::to_string(&doc).map_err(ApiError::internal)?;
    let stats = ClipStats {
        joints: clip.joint_count() as u32,
        tracks: clip.track_count() as u32,
        events: clip.events().len() as u32,
        start: clip.start(),
        end: clip.end(),
        playback: clip.playback(),
    };
    Ok(Admitted { new_clip: NewClip { name: doc.name, doc_json, stats }, clip })
}

/// `Clip::build_cancellable` within `max_work`, the budget refusal naming
/// its setting.
///
/// # Errors
/// A SPEC rule (422 with the rule's code), or `build_budget_exceeded` (422).
pub fn build(spec: &ClipSpec, max_work: u64, cancel: &AtomicBool) -> Result<Clip, ApiError> {
    Clip::build_cancellable(spec, max_work, cancel).map_err(|e| match e {
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

fn check(doc: &ClipDoc, limits: &Limits) -> Result<(), ApiError> {
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
    Ok(())
}
