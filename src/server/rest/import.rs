//! `POST /v1/clips/import`: glTF, GLB and BVH files in, stored clips out.
//!
//! The file is imported and every clip it yields is admitted (the same
//! checks as an uploaded JSON clip) before the store is touched; then all of
//! them are stored in one transaction. A file is imported whole or not at
//! all, and parsing runs on the blocking pool, off the async workers.

use std::sync::Arc;

use axum::Json;
use axum::body::Bytes;
use axum::extract::{RawQuery, State};
use axum::http::header::CONTENT_TYPE;
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use utoipa::ToSchema;

use crate::anim::Interpolation;
use crate::import::{Format, ImportError, ImportLimits, ImportOptions, Skipped, import, sniff};
use crate::server::auth::WriteAccess;
use crate::server::cache::CachedClip;
use crate::server::config::Limits;
use crate::server::error::ApiError;
use crate::server::limits::{Admitted, admit_doc};
use crate::server::state::AppState;
use crate::wire::json::{ClipDoc, InterpolationDoc};

use super::extract::QueryParams;
use super::summary::ClipSummary;

/// What an import created, and what in the file it left out.
#[derive(Debug, Serialize, ToSchema)]
pub struct ImportResult {
    pub clips: Vec<ClipSummary>,
    /// Parts of the file not imported (e.g. morph-target weights), with why.
    #[schema(value_type = Vec<Object>)]
    pub skipped: Vec<Skipped>,
}

/// Import a glTF 2.0 (`.gltf` with embedded buffers, `.glb`) or BVH file.
#[utoipa::path(
    post, path = "/v1/clips/import", tag = "clips",
    params(
        ("format" = Option<String>, Query, description = "gltf | glb | bvh; inferred from Content-Type or the bytes when absent"),
        ("interpolation" = Option<String>, Query, description = "BVH keys: linear (default) or catmull_rom"),
        ("name" = Option<String>, Query, description = "Clip name (BVH) or name prefix (glTF with several animations)"),
    ),
    request_body(content = Vec<u8>, content_type = "application/octet-stream"),
    responses(
        (status = 201, description = "Every clip of the file, stored", body = ImportResult),
        (status = 400, description = "Not a well-formed glTF, GLB or BVH file", body = super::openapi::Problem),
        (status = 401, description = "Write token missing or wrong", body = super::openapi::Problem),
        (status = 413, description = "Body or file content over a limit", body = super::openapi::Problem),
        (status = 422, description = "Well-formed but not importable (code says why)", body = super::openapi::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn import_clips(
    State(state): State<AppState>,
    _: WriteAccess,
    RawQuery(query): RawQuery,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, ApiError> {
    let params = QueryParams::parse(query.as_deref(), &["format", "interpolation", "name"])?;
    let format = match params.get("format") {
        Some(f) => f.parse::<Format>().map_err(|e| ApiError::parameter("bad_format", "format", e))?,
        None => {
            let content_type = headers.get(CONTENT_TYPE).and_then(|v| v.to_str().ok());
            sniff(&body, content_type).ok_or(ImportError::UnknownFormat)?
        }
    };
    let bvh_interpolation = match params.get("interpolation") {
        None => Interpolation::Linear,
        Some(text) => match text.parse::<InterpolationDoc>().map(Interpolation::from) {
            Ok(i @ (Interpolation::Linear | Interpolation::CatmullRom)) => i,
            _ => {
                let detail = format!("`interpolation` must be linear or catmull_rom, got `{text}`");
                return Err(ApiError::parameter("bad_interpolation", "interpolation", detail));
            }
        },
    };
    let options = ImportOptions {
        bvh_interpolation,
        name: params.get("name").map(str::to_owned),
        limits: import_limits(&state.config.limits),
    };
    let limits = state.config.limits.clone();
    let (admitted, skipped) = tokio::task::spawn_blocking(move || -> Result<_, ApiError> {
        let imported = import(&body, format, &options)?;
        let admitted = imported
            .clips
            .iter()
            .map(|spec| admit_doc(ClipDoc::from_spec(spec), &limits))
            .collect::<Result<Vec<Admitted>, ApiError>>()?;
        Ok((admitted, imported.skipped))
    })
    .await
    .map_err(ApiError::internal)??;

    let (new_clips, clips): (Vec<_>, Vec<_>) = admitted.into_iter().map(|a| (a.new_clip, a.clip)).unzip();
    let metas = state.store.create_all(new_clips).await?;
    tracing::info!(format = format.as_str(), clips = metas.len(), "file imported");
    let summaries = metas.iter().map(ClipSummary::from).collect();
    for (meta, clip) in metas.into_iter().zip(clips) {
        state.cache_written(Arc::new(CachedClip { meta, clip }));
    }
    Ok((StatusCode::CREATED, Json(ImportResult { clips: summaries, skipped })).into_response())
}

/// The importer's bounds, from the server's: a clip an import produces
/// obeys the same limits as one uploaded as JSON.
fn import_limits(limits: &Limits) -> ImportLimits {
    ImportLimits {
        max_bytes: limits.max_body_bytes as u64,
        max_joints: limits.max_joints,
        max_tracks: limits.max_tracks,
        max_keys_per_track: limits.max_keys_per_track,
        max_frames: limits.max_keys_per_track,
        ..ImportLimits::default()
    }
}
