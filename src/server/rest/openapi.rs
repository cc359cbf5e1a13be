//! The OpenAPI 3 document, generated from the handlers' `#[utoipa::path]`
//! annotations and the wire types' `ToSchema` derives, served at
//! `/openapi.json`, with Swagger UI at `/docs` (vendored into the binary:
//! the page needs no download at build or run time).

use serde::Serialize;
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::{Modify, OpenApi, ToSchema};
use utoipa_swagger_ui::SwaggerUi;

use super::{clips, health, import, poses, stream, viewer};

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

struct BearerAuth;

impl Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
    }
}

#[derive(OpenApi)]
#[openapi(
    info(title = "inbetween", description = "Keyframe clips in, inbetweens out. See SPEC §3."),
    paths(
        clips::create_clip, clips::list_clips, clips::get_clip, clips::replace_clip, clips::delete_clip,
        import::import_clips,
        poses::get_pose, poses::sample, stream::stream,
        health::healthz, health::readyz, health::metrics,
        viewer::viewer_page,
    ),
    components(schemas(Problem, PoseSchema, PosesSchema, JointPoseSchema)),
    modifiers(&BearerAuth),
    tags(
        (name = "clips", description = "Store and fetch keyframe clips"),
        (name = "poses", description = "Evaluate poses"),
        (name = "streams", description = "Fixed-rate frames over a WebSocket"),
        (name = "operations", description = "Health and metrics"),
        (name = "viewer", description = "The browser viewer page"),
    )
)]
pub struct ApiDoc;

/// `/openapi.json` and `/docs`.
pub fn router<S: Clone + Send + Sync + 'static>() -> axum::Router<S> {
    SwaggerUi::new("/docs").url("/openapi.json", ApiDoc::openapi()).into()
}
