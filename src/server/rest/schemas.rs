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
}

#[derive(Serialize, ToSchema)]
pub struct PosesSchema {
    pub poses: Vec<PoseSchema>,
}

/// The raw bytes of an uploaded file (`format: binary` in the document).
#[derive(ToSchema)]
#[schema(value_type = String, format = Binary)]
pub struct FileBytes(pub Vec<u8>);
