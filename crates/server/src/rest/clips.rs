//! Clip routes: create, list, get, replace, delete (docs/api.md).
//!
//! Every write validates fully (`limits::admit_doc`, priced and run by
//! `builds`) before the store is touched, and answers only after the store
//! committed; the cache is updated after the commit (write-through), never
//! before.

use std::sync::Arc;

use axum::Json;
use axum::extract::State;
use axum::http::header::{CONTENT_TYPE, ETAG, IF_MATCH, IF_NONE_MATCH, LOCATION};
use axum::http::{HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use utoipa::ToSchema;

use crate::auth::{CallerKey, ReadAccess, WriteAccess};
use crate::cache::CachedClip;
use crate::error::ApiError;
use crate::limits::Admitted;
use crate::request::{Page, RawPage, in_query};
use crate::state::AppState;
use crate::store::ClipMeta;
use anim::lint::Lint;
use formats::import::Warning;
use formats::import::warning::in_document;

use super::extract::{ClipId, JsonBody, Precondition, etag, expected, precondition, unless_modified};
use super::query::Query;
use super::summary::ClipSummary;

/// A page of clips.
#[derive(Debug, Serialize, ToSchema)]
pub struct ClipList {
    pub clips: Vec<ClipSummary>,
    /// Pass as `cursor` for the next page; `null` on the last page.
    pub next_cursor: Option<String>,
}

/// A written clip's summary, and what in its document looks valid but
/// probably wrong (the write succeeded; docs/warnings.md).
#[derive(Debug, Serialize, ToSchema)]
pub struct ClipWritten {
    #[serde(flatten)]
    pub summary: ClipSummary,
    /// Pointers into the document as uploaded; `[]` when nothing looked wrong.
    #[schema(value_type = Vec<super::schemas::Warning>)]
    pub warnings: Vec<Warning>,
}

/// Parses, checks and builds an upload through the build gate (never on
/// the async workers, whatever its size).
pub(super) async fn admit_body(
    state: &AppState,
    caller: &CallerKey,
    body: axum::body::Bytes,
) -> Result<Admitted, ApiError> {
    crate::builds::upload(&state.work, caller, &state.config.limits, body).await
}

pub(super) fn with_etag(
    meta: &ClipMeta,
    status: StatusCode,
    extra: Option<(axum::http::HeaderName, String)>,
) -> Response {
    etagged(meta, status, extra, ClipSummary::from(meta))
}

/// `body` with the version's `ETag` and the `extra` header.
fn etagged(
    meta: &ClipMeta,
    status: StatusCode,
    extra: Option<(axum::http::HeaderName, String)>,
    body: impl Serialize,
) -> Response {
    let mut headers = HeaderMap::new();
    if let Ok(v) = HeaderValue::from_str(&etag(meta.version)) {
        headers.insert(ETAG, v);
    }
    if let Some((name, value)) = extra
        && let Ok(v) = HeaderValue::from_str(&value)
    {
        headers.insert(name, v);
    }
    (status, headers, Json(body)).into_response()
}

/// A create's or replace's answer: the summary with the upload's warnings.
fn written(meta: &ClipMeta, status: StatusCode, location: bool, lints: &[Lint]) -> Response {
    let extra = location.then(|| (LOCATION, format!("/v1/clips/{}", meta.id)));
    etagged(meta, status, extra, ClipWritten { summary: ClipSummary::from(meta), warnings: in_document(lints) })
}

/// Upload a clip: the JSON document of `docs/clip-format.md`.
#[utoipa::path(
    post, path = "/v1/clips", tag = "clips",
    params(
        ("replace" = Option<bool>, Query, description = "true: when a clip has this name, store the upload as its new version (same id, 200) instead of refusing it (409 name_taken)"),
    ),
    request_body(content = formats::wire::json::ClipDoc, content_type = "application/json"),
    responses(
        (status = 201, description = "Stored; `Location` names the clip; `warnings` lists what looks valid but probably wrong", body = ClipWritten),
        (status = 200, description = "With replace=true, stored as the new version of the clip of that name", body = ClipWritten),
        (status = 400, description = "Not JSON", body = super::schemas::Problem),
        (status = 401, description = "Write token missing or wrong", body = super::schemas::Problem),
        (status = 409, description = "A clip has this name (name_taken), or several clips stored before names were unique do (ambiguous_name, with replace=true)", body = super::schemas::Problem),
        (status = 413, description = "Body over the limit", body = super::schemas::Problem),
        (status = 415, description = "Not application/json", body = super::schemas::Problem),
        (status = 422, description = "Invalid clip (code and pointer say why and where)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn create_clip(
    State(state): State<AppState>,
    WriteAccess(caller): WriteAccess,
    Query(params): Query,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let on_name = params.on_name()?;
    let Admitted { new_clip, clip, springs, lints } = admit_body(&state, &caller.key(), body).await?;
    let meta = state.store.create(new_clip, on_name).await?;
    tracing::info!(id = %meta.id, name = %meta.name, version = meta.version, warnings = lints.len(), "clip created");
    let status = if meta.version == 1 { StatusCode::CREATED } else { StatusCode::OK };
    let response = written(&meta, status, true, &lints);
    state.cache_written(Arc::new(CachedClip { meta, clip, springs }));
    Ok(response)
}

/// List clips in creation order, a page at a time, optionally filtered
/// (the filters combine with AND, never a read of documents; each is served
/// by the store's indexes except `name_contains`, which tests each clip's
/// name in id order).
#[utoipa::path(
    get, path = "/v1/clips", tag = "clips",
    params(
        ("limit" = Option<u32>, Query, minimum = 1, maximum = 1000, description = "Page size, 1..=1000 (default 100)"),
        ("cursor" = Option<String>, Query, pattern = "^[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}$", description = "`next_cursor` of the previous page (with the same filters)"),
        ("name" = Option<String>, Query, min_length = 1, max_length = 256, description = "Only clips with exactly this name"),
        ("name_prefix" = Option<String>, Query, min_length = 1, max_length = 256, description = "Only clips whose name starts with this (case-sensitive)"),
        ("name_contains" = Option<String>, Query, min_length = 1, max_length = 256, description = "Only clips whose name contains this (case-sensitive). The one filter no index serves: each clip's name is tested in id order, never its document"),
        ("tag" = Option<String>, Query, min_length = 1, max_length = 256, description = "Only clips carrying this tag"),
        ("min_duration" = Option<f64>, Query, minimum = 0, description = "Only clips at least this long (`end - start`, seconds, inclusive)"),
        ("max_duration" = Option<f64>, Query, minimum = 0, description = "Only clips at most this long (seconds, inclusive)"),
        ("compatible_with" = Option<String>, Query, description = "A clip id: only clips whose joint names include every joint name of that clip (the ones a layer of it can be put on; the clip itself included). 404 `clip_not_found` if it does not exist"),
    ),
    responses(
        (status = 200, body = ClipList),
        (status = 400, body = super::schemas::Problem),
        (status = 404, description = "`compatible_with` names no clip", body = super::schemas::Problem),
        (status = 422, description = "A negative duration, or `min_duration` above `max_duration` (`bad_duration_range`)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn list_clips(
    State(state): State<AppState>,
    _: ReadAccess,
    Query(q): Query,
) -> Result<Json<ClipList>, ApiError> {
    let raw = RawPage {
        limit: q.raw("limit"),
        cursor: q.get("cursor"),
        name: q.get("name"),
        name_prefix: q.get("name_prefix"),
        name_contains: q.get("name_contains"),
        tag: q.get("tag"),
        min_duration: q.raw("min_duration"),
        max_duration: q.raw("max_duration"),
        compatible_with: q.get("compatible_with"),
        at: in_query,
    };
    let Page { clips, next_cursor } = raw.read(&state).await?;
    Ok(Json(ClipList { clips: clips.iter().map(ClipSummary::from).collect(), next_cursor }))
}

/// The stored clip document, exactly as accepted (normalised), with its `ETag`.
#[utoipa::path(
    get, path = "/v1/clips/{id}", tag = "clips",
    params(("id" = String, Path, description = "Clip id")),
    responses(
        (status = 200, description = "The clip document", body = formats::wire::json::ClipDoc),
        (status = 304, description = "`If-None-Match` matched"),
        (status = 404, body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn get_clip(
    State(state): State<AppState>,
    _: ReadAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let if_none_match = precondition(&headers, IF_NONE_MATCH, true)?;
    let stored = state.store.get(&id).await?.ok_or(ApiError::NotFound { what: "clip" })?;
    let content_type = HeaderValue::from_static("application/json");
    unless_modified(if_none_match, stored.meta.version, || {
        ([(CONTENT_TYPE, content_type)], stored.doc_json).into_response()
    })
}

/// The version `expected` must name for a conditional write of clip `id`.
pub(super) async fn expected_version(
    state: &AppState,
    id: &str,
    condition: Option<Precondition>,
) -> Result<Option<u64>, ApiError> {
    expected(condition, async || {
        let stored = state.store.get(id).await?.ok_or(ApiError::NotFound { what: "clip" })?;
        Ok(stored.meta.version)
    })
    .await
}

/// Replace a clip's document; the version goes up by one.
#[utoipa::path(
    put, path = "/v1/clips/{id}", tag = "clips",
    params(
        ("id" = String, Path, description = "Clip id"),
        ("If-Match" = Option<String>, Header, pattern = r#"^(\*|"[0-9]{1,19}")$"#, description = "Replace only at this version (`\"3\"`) or `*`"),
    ),
    request_body(content = formats::wire::json::ClipDoc, content_type = "application/json"),
    responses(
        (status = 200, description = "Replaced; `warnings` lists what looks valid but probably wrong", body = ClipWritten),
        (status = 404, body = super::schemas::Problem),
        (status = 412, description = "`If-Match` did not match the current version", body = super::schemas::Problem),
        (status = 422, body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn replace_clip(
    State(state): State<AppState>,
    WriteAccess(caller): WriteAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let condition = precondition(&headers, IF_MATCH, false)?;
    let Admitted { new_clip, clip, springs, lints } = admit_body(&state, &caller.key(), body).await?;
    let expected = expected_version(&state, &id, condition).await?;
    let meta = state.store.replace(&id, new_clip, expected).await?;
    tracing::info!(id = %meta.id, version = meta.version, warnings = lints.len(), "clip replaced");
    let response = written(&meta, StatusCode::OK, false, &lints);
    state.cache_written(Arc::new(CachedClip { meta, clip, springs }));
    Ok(response)
}

/// Delete a clip (honours `If-Match`).
#[utoipa::path(
    delete, path = "/v1/clips/{id}", tag = "clips",
    params(
        ("id" = String, Path, description = "Clip id"),
        ("If-Match" = Option<String>, Header, pattern = r#"^(\*|"[0-9]{1,19}")$"#, description = "Delete only at this version"),
    ),
    responses(
        (status = 204, description = "Deleted"),
        (status = 404, body = super::schemas::Problem),
        (status = 412, body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn delete_clip(
    State(state): State<AppState>,
    _: WriteAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
) -> Result<StatusCode, ApiError> {
    let condition = precondition(&headers, IF_MATCH, false)?;
    let expected = expected_version(&state, &id, condition).await?;
    state.store.delete(&id, expected).await?;
    state.cache_invalidate(&id);
    tracing::info!(%id, "clip deleted");
    Ok(StatusCode::NO_CONTENT)
}
