//! `POST /v1/clips/import`: glTF, GLB and BVH files in, stored clips out.
//!
//! The file is imported and every clip it yields is admitted (the same
//! checks as an uploaded JSON clip) before the store is touched; then all of
//! them are stored in one transaction. A file is imported whole or not at
//! all, and parsing runs on the blocking pool, off the async workers.
//!
//! The body is the file itself, or `multipart/form-data` carrying a `.gltf`
//! and the buffer files it names (what a browser's file picker sends): the
//! part named `file`, else the first part whose file name ends in `.gltf`,
//! `.glb` or `.bvh`, is the document, and the other parts answer its buffer
//! URIs by plain file name only. Nothing else is ever fetched. Buffers that
//! name the same part share its bytes, and the bytes they declare count
//! against `max_import_resolved_bytes` (413 `resolved_bytes_too_large`).

use std::sync::Arc;

use axum::Json;
use axum::body::Bytes;
use axum::extract::{FromRequest, Multipart, Request, State};
use axum::http::StatusCode;
use axum::http::header::CONTENT_TYPE;
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use utoipa::ToSchema;

use crate::anim::Interpolation;
use crate::import::{
    ErrorClass, Format, ImportError, ImportLimits, ImportOptions, Resolver, Skipped, import_with, sniff,
};
use crate::server::auth::WriteAccess;
use crate::server::cache::CachedClip;
use crate::server::config::Limits;
use crate::server::error::ApiError;
use crate::server::limits::{Admitted, admit_doc};
use crate::server::state::AppState;
use crate::wire::json::{ClipDoc, InterpolationDoc};

use super::query::Query;
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
        ("format" = Option<String>, Query, pattern = "^(gltf|glb|bvh)$", description = "gltf | glb | bvh; inferred from Content-Type or the bytes when absent"),
        ("interpolation" = Option<String>, Query, pattern = "^(linear|catmull_rom)$", description = "BVH keys: linear (default) or catmull_rom"),
        ("name" = Option<String>, Query, min_length = 1, max_length = 256, description = "Clip name (BVH) or name prefix (glTF with several animations)"),
    ),
    request_body(content = super::schemas::FileBytes, content_type = "application/octet-stream",
        description = "The file; or multipart/form-data with the .gltf and the buffer files it names"),
    responses(
        (status = 201, description = "Every clip of the file, stored", body = ImportResult),
        (status = 400, description = "Not a well-formed glTF, GLB or BVH file", body = super::schemas::Problem),
        (status = 401, description = "Write token missing or wrong", body = super::schemas::Problem),
        (status = 413, description = "Body or file content over a limit", body = super::schemas::Problem),
        (status = 422, description = "Well-formed but not importable (code says why)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn import_clips(
    State(state): State<AppState>,
    _: WriteAccess,
    Query(params): Query,
    request: Request,
) -> Result<Response, ApiError> {
    let content_type = request.headers().get(CONTENT_TYPE).and_then(|v| v.to_str().ok()).map(str::to_owned);
    let (body, siblings) = if content_type.as_deref().is_some_and(|c| c.starts_with("multipart/form-data")) {
        let multipart =
            Multipart::from_request(request, &state).await.map_err(|e| rejected(e.status(), e.body_text(), &state))?;
        read_parts(multipart, &state).await?
    } else {
        let body =
            Bytes::from_request(request, &state).await.map_err(|e| rejected(e.status(), e.body_text(), &state))?;
        (body, Vec::new())
    };
    let format = match params.get("format") {
        Some(f) => f.parse::<Format>().map_err(|e| ApiError::parameter("bad_format", "format", e))?,
        None => sniff(&body, content_type.as_deref()).ok_or(ImportError::UnknownFormat)?,
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
    let (admitted, skipped) = state
        .builds
        .run(move |cancel| -> Result<_, ApiError> {
            // A shared handle on the part, never a copy: the importer asks once
            // per name and slices it per buffer.
            let mut resolve = |uri: &str| -> Result<Bytes, String> {
                siblings
                    .iter()
                    .find(|(name, _)| name == uri)
                    .map(|(_, data)| data.clone())
                    .ok_or_else(|| format!("no part named {uri:?} in the upload"))
            };
            let resolver: Option<Resolver<'_>> = if siblings.is_empty() { None } else { Some(&mut resolve) };
            let imported = import_with(&body, format, &options, resolver)?;
            let admitted = imported
                .clips
                .iter()
                .map(|spec| admit_doc(ClipDoc::from_spec(spec), &limits, cancel))
                .collect::<Result<Vec<Admitted>, ApiError>>()?;
            Ok((admitted, imported.skipped))
        })
        .await?;

    let (new_clips, clips): (Vec<_>, Vec<_>) = admitted.into_iter().map(|a| (a.new_clip, a.clip)).unzip();
    let metas = state.store.create_all(new_clips).await?;
    tracing::info!(format = format.as_str(), clips = metas.len(), "file imported");
    let summaries = metas.iter().map(ClipSummary::from).collect();
    for (meta, clip) in metas.into_iter().zip(clips) {
        state.cache_written(Arc::new(CachedClip { meta, clip }));
    }
    Ok((StatusCode::CREATED, Json(ImportResult { clips: summaries, skipped })).into_response())
}

/// The document part and the named sibling parts of a multipart upload.
async fn read_parts(mut multipart: Multipart, state: &AppState) -> Result<(Bytes, Vec<(String, Bytes)>), ApiError> {
    let mut document: Option<Bytes> = None;
    let mut siblings = Vec::new();
    let failed = |e: axum::extract::multipart::MultipartError| rejected(e.status(), e.body_text(), state);
    while let Some(field) = multipart.next_field().await.map_err(failed)? {
        let field_name = field.name().unwrap_or_default().to_owned();
        let file_name = field.file_name().map(str::to_owned);
        let data = field.bytes().await.map_err(failed)?;
        let is_document = |n: &str| [".gltf", ".glb", ".bvh"].iter().any(|ext| n.to_ascii_lowercase().ends_with(ext));
        if document.is_none() && (field_name == "file" || file_name.as_deref().is_some_and(is_document)) {
            document = Some(data);
        } else if let Some(name) = file_name.filter(|n| !n.is_empty() && !n.contains(['/', '\\']) && n != "..") {
            siblings.push((name, data));
        }
    }
    let document = document.ok_or_else(|| {
        bad_multipart("no document part: name it `file`, or give it a .gltf, .glb or .bvh file name".into())
    })?;
    Ok((document, siblings))
}

/// A body that could not be read: over the size limit (413), else malformed (400).
fn rejected(status: StatusCode, detail: String, state: &AppState) -> ApiError {
    if status == StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::PayloadTooLarge { limit: state.config.limits.max_body_bytes }
    } else {
        bad_multipart(detail)
    }
}

fn bad_multipart(detail: String) -> ApiError {
    ApiError::Import { class: ErrorClass::Malformed, code: "bad_upload", pointer: None, detail }
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
        max_resolved_bytes: limits.max_import_resolved_bytes as u64,
        max_build_work: limits.max_build_work,
        ..ImportLimits::default()
    }
}
