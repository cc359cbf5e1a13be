//! `GET /v1/clips/{id}/skeleton`: what a client needs to bind a clip to a
//! rig (joints with parents and rest pose, parameter names, time range)
//! without downloading its keys: a few KB where the document can be
//! megabytes. Read from the compiled clip in the cache, so it costs no
//! store round trip on a cached clip and never parses the document.

use axum::Json;
use axum::extract::State;
use axum::http::HeaderMap;
use axum::http::header::IF_NONE_MATCH;
use axum::response::{IntoResponse, Response};
use glam::{Quat, Vec3A};
use serde::Serialize;
use utoipa::ToSchema;

use crate::auth::ReadAccess;
use crate::cache::CachedClip;
use crate::error::ApiError;
use crate::request::clip;
use crate::state::AppState;
use anim::Skeleton;
use formats::wire::json::RestDoc;

use super::extract::{ClipId, precondition, unless_modified};

/// A clip's skeleton and time range.
#[derive(Debug, Serialize, ToSchema)]
pub struct ClipSkeleton {
    pub id: String,
    pub name: String,
    pub version: u64,
    /// Smallest first key time, seconds.
    pub start: f32,
    /// Largest last key time, seconds.
    pub end: f32,
    pub duration: f32,
    /// Parents before children, in the order poses list them.
    pub joints: Vec<SkeletonJoint>,
    /// The names of the clip's parameter tracks (docs/clip-format.md §3), in order.
    pub parameters: Vec<String>,
    /// Whether the clip has inverse bind matrices (`format=skinning`).
    pub inverse_binds: bool,
}

/// One joint: its parent and its rest transform (identity parts omitted,
/// as in the clip document).
#[derive(Debug, Serialize, ToSchema)]
pub struct SkeletonJoint {
    pub name: String,
    /// `null` for a root.
    pub parent: Option<String>,
    pub rest: RestDoc,
}

impl ClipSkeleton {
    pub fn of(cached: &CachedClip) -> ClipSkeleton {
        let (meta, clip) = (&cached.meta, &cached.clip);
        let skeleton = clip.skeleton();
        ClipSkeleton {
            id: meta.id.clone(),
            name: meta.name.clone(),
            version: meta.version,
            start: clip.start(),
            end: clip.end(),
            duration: clip.duration(),
            joints: (0..skeleton.len()).map(|j| joint(skeleton, j)).collect(),
            parameters: clip.parameters().names().to_vec(),
            inverse_binds: skeleton.has_inverse_binds(),
        }
    }
}

fn joint(skeleton: &Skeleton, j: usize) -> SkeletonJoint {
    let rest = skeleton.rest();
    let (t, r, s) = (rest.translations[j], rest.rotations[j], rest.scales[j]);
    SkeletonJoint {
        name: skeleton.names()[j].clone(),
        parent: skeleton.parent(j).map(|p| skeleton.names()[p].clone()),
        rest: RestDoc {
            translation: (t != Vec3A::ZERO).then(|| t.to_array()),
            rotation: (r != Quat::IDENTITY).then(|| r.to_array()),
            scale: (s != Vec3A::ONE).then(|| s.to_array()),
        },
    }
}

/// A clip's joints (parents, rest pose), parameter names and time range.
#[utoipa::path(
    get, path = "/v1/clips/{id}/skeleton", tag = "clips",
    params(("id" = String, Path, description = "Clip id")),
    responses(
        (status = 200, description = "The skeleton; `ETag` is the clip's", body = ClipSkeleton),
        (status = 304, description = "`If-None-Match` matched"),
        (status = 404, body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn get_skeleton(
    State(state): State<AppState>,
    _: ReadAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let if_none_match = precondition(&headers, IF_NONE_MATCH, true)?;
    let cached = clip(&state, &id).await?;
    unless_modified(if_none_match, cached.meta.version, || Json(ClipSkeleton::of(&cached)).into_response())
}
