//! The shapes the OpenAPI document names that no handler returns as a
//! type of its own: the problem body, poses as JSON (written by hand in
//! `wire::json`) and uploaded file bytes. Apart from `openapi`, so handlers
//! can name them without importing the document that lists the handlers.

use serde::Serialize;
use utoipa::ToSchema;

/// An error body (RFC 9457 `application/problem+json`).
#[derive(Serialize, ToSchema)]
pub struct Problem {
    /// `urn:inbetween:problem:<code>`.
    #[serde(rename = "type")]
    pub type_: String,
    pub title: String,
    pub status: u16,
    /// Stable machine-readable code, e.g. `times_not_increasing`.
    pub code: String,
    /// Human explanation.
    pub detail: String,
    /// JSON pointer of the offending body field (validation errors).
    pub pointer: Option<String>,
    /// Name of the offending query parameter or header.
    pub parameter: Option<String>,
}

/// Something valid but probably wrong in an upload or import: the upload
/// succeeded, the clip is stored (docs/warnings.md lists every code).
#[derive(Serialize, ToSchema)]
pub struct Warning {
    /// Stable machine-readable code, e.g. `rotation_not_unit`.
    pub code: String,
    /// JSON pointer into what was uploaded: the clip document
    /// (`/tracks/3/values/5`), the glTF file (`/animations/0/channels/3`),
    /// or a BVH header (`/MOTION/Frame Time`); empty for `too_many_warnings`.
    pub pointer: String,
    /// What was noticed, and what the server did about it.
    pub detail: String,
}

/// One joint of a `format=trs` pose.
#[derive(Serialize, ToSchema)]
pub struct JointPoseSchema {
    pub name: String,
    pub translation: [f32; 3],
    /// `[x, y, z, w]`.
    pub rotation: [f32; 4],
    pub scale: [f32; 3],
}

/// A pose (`format=trs`); `format=matrix|skinning` gives `joints: [{name, matrix: [16]}]`
/// (column-major) with `format` set, in model space.
#[derive(Serialize, ToSchema)]
pub struct PoseSchema {
    /// The clip id.
    pub clip: String,
    /// The request time.
    pub time: f64,
    /// The clip time it mapped to after playback and ease.
    pub clip_time: f32,
    /// `local` or `model`.
    pub space: String,
    pub joints: Vec<JointPoseSchema>,
    /// IK reports (`docs/ik.md`), one per constraint solved, when there are any:
    /// each layer's clip constraints bottom to top, then the request's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ik: Option<Vec<formats::wire::ik::IkReportDoc>>,
    /// The clip's parameters (docs/clip-format.md §3) by name, each its values (the key's
    /// width), when the clip has any; only a request's `parameters` if given.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Object>)]
    pub parameters: Option<std::collections::BTreeMap<String, Vec<f32>>>,
}

#[derive(Serialize, ToSchema)]
pub struct PosesSchema {
    pub poses: Vec<PoseSchema>,
}

/// The raw bytes of an uploaded file (`format: binary` in the document).
/// A schema only: the import handler reads the multipart body itself.
#[derive(ToSchema)]
#[schema(value_type = String, format = Binary)]
pub struct FileBytes(#[allow(dead_code)] pub Vec<u8>);

/// A merge patch of a clip (RFC 7396): each field given replaces the
/// document's (an object merges into `metadata`); `null` removes it.
#[derive(Serialize, ToSchema)]
pub struct ClipPatch {
    #[schema(min_length = 1, max_length = 256)]
    pub name: Option<String>,
    /// Replaces the whole list; `null` or `[]` removes every tag.
    pub tags: Option<Vec<String>>,
    /// Merged into the stored object key by key; a key set to `null` is removed.
    #[schema(value_type = Option<Object>)]
    pub metadata: Option<serde_json::Value>,
    pub playback: Option<formats::wire::json::PlaybackDoc>,
    /// Replaces the whole list.
    pub events: Option<Vec<formats::wire::json::EventDoc>>,
}
