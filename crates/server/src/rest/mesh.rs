//! `GET /v1/clips/{id}/mesh` and `GET /v1/characters/{id}/mesh`: the
//! skinned mesh a glTF import kept with the clip or character, in the
//! binary form of docs/mesh-format.md, for the viewer to skin on the GPU.
//!
//! The bytes are served as the import stored them. Their entity tag is a
//! hash of them, so it survives a `PATCH` (which keeps the mesh) and a
//! browser revalidating with `If-None-Match` gets `304` from one small
//! read that never touches the blob. A clip without a mesh (JSON, BVH, an
//! unskinned glTF, or replaced by `PUT`) is `404 no_mesh`.

use axum::extract::State;
use axum::http::header::{CACHE_CONTROL, CONTENT_TYPE, ETAG};
use axum::http::{HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};

use crate::auth::ReadAccess;
use crate::characters::store_error;
use crate::error::ApiError;
use crate::state::AppState;
use crate::store::StoredMesh;
use formats::wire::mesh::CONTENT_TYPE as MESH_TYPE;

use super::extract::ClipId;
use super::viewer::matches_etag;

/// Revalidate every time (a `PUT` can drop the mesh), and only in the
/// caller's own cache (it may have needed a read token).
const CACHE: &str = "private, no-cache";

/// The clip's skinned mesh (binary, docs/mesh-format.md).
#[utoipa::path(
    get, path = "/v1/clips/{id}/mesh", tag = "clips",
    params(
        ("id" = String, Path, description = "Clip id"),
        ("If-None-Match" = Option<String>, Header, description = "The `ETag` of a mesh held: `304` while it is still the clip's"),
    ),
    responses(
        (status = 200, description = "The mesh: an `INBM` header, JSON and little-endian arrays (docs/mesh-format.md)",
            content_type = "application/vnd.inbetween.mesh", body = super::schemas::FileBytes),
        (status = 304, description = "`If-None-Match` matched"),
        (status = 401, description = "Read token missing or wrong", body = super::schemas::Problem),
        (status = 404, description = "No such clip (`clip_not_found`), or it has no mesh (`no_mesh`: only a glTF import of a skin with triangles keeps one)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn get_mesh(
    State(state): State<AppState>,
    _: ReadAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let tag = state.store.mesh_tag(&id).await?.ok_or(ApiError::NotFound { what: "clip" })?;
    serve(&headers, tag, async || Ok(state.store.mesh(&id).await?)).await
}

/// The character's skinned mesh, as a clip's is served.
#[utoipa::path(
    get, path = "/v1/characters/{id}/mesh", tag = "characters",
    params(
        ("id" = String, Path, description = "Character id"),
        ("If-None-Match" = Option<String>, Header, description = "The `ETag` of a mesh held: `304` while it is still the character's"),
    ),
    responses(
        (status = 200, description = "The mesh: an `INBM` header, JSON and little-endian arrays (docs/mesh-format.md)",
            content_type = "application/vnd.inbetween.mesh", body = super::schemas::FileBytes),
        (status = 304, description = "`If-None-Match` matched"),
        (status = 401, description = "Read token missing or wrong", body = super::schemas::Problem),
        (status = 404, description = "No such character (`character_not_found`), or it has no mesh (`no_mesh`: only an import of a glTF skin with triangles keeps one)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn get_character_mesh(
    State(state): State<AppState>,
    _: ReadAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let store = &state.store;
    let tag = store.character_mesh_tag(&id).await.map_err(store_error)?;
    let tag = tag.ok_or(ApiError::NotFound { what: "character" })?;
    serve(&headers, tag, async || store.character_mesh(&id).await.map_err(store_error)).await
}

/// A mesh whose tag is `tag` (`None`: no mesh): `304` when `headers`
/// revalidate it, else the bytes `fetch` reads.
async fn serve(
    headers: &HeaderMap,
    tag: Option<String>,
    fetch: impl AsyncFnOnce() -> Result<Option<StoredMesh>, ApiError>,
) -> Result<Response, ApiError> {
    let tag = tag.ok_or(ApiError::NotFound { what: "mesh" })?;
    let common = |tag: &str| {
        [
            (ETAG, HeaderValue::from_str(tag).unwrap_or(HeaderValue::from_static("\"m\""))),
            (CACHE_CONTROL, HeaderValue::from_static(CACHE)),
        ]
    };
    if matches_etag(headers, &tag) {
        return Ok((StatusCode::NOT_MODIFIED, common(&tag)).into_response());
    }
    // Dropped or replaced since the tag was read: as if asked a moment later.
    let mesh = fetch().await?.ok_or(ApiError::NotFound { what: "mesh" })?;
    let content_type = [(CONTENT_TYPE, HeaderValue::from_static(MESH_TYPE))];
    Ok((StatusCode::OK, common(&mesh.etag), content_type, mesh.bytes).into_response())
}
