//! What the routes of every kind of named, versioned document share
//! (characters, graphs; `server::documents`): the written answer with its
//! `ETag` and `Location`, the stored document with `If-None-Match`, the
//! version `If-Match` asks for, delete, and the list's parameters. A kind's
//! routes add their document's checks, their summary and their OpenAPI.

use axum::Json;
use axum::http::header::{CONTENT_TYPE, ETAG, IF_MATCH, IF_NONE_MATCH, LOCATION};
use axum::http::{HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

use crate::documents::{raw_page, store_error};
use crate::error::ApiError;
use crate::request::{RawPage, in_query};
use crate::state::AppState;
use crate::store::DocKind;

use super::extract::{Precondition, etag, expected, precondition, unless_modified};
use super::query::QueryParams;

/// The collection path of `kind` (`/v1/characters`, `/v1/graphs`).
pub fn collection(kind: DocKind) -> &'static str {
    match kind {
        DocKind::Character => "/v1/characters",
        DocKind::Graph => "/v1/graphs",
    }
}

/// The document `id` written at `version`: its `summary`, with the `ETag`
/// of that version and, for a create, its `Location`.
pub fn written(
    kind: DocKind,
    (id, version): (&str, u64),
    status: StatusCode,
    location: bool,
    summary: impl Serialize,
) -> Response {
    let mut headers = HeaderMap::new();
    if let Ok(v) = HeaderValue::from_str(&etag(version)) {
        headers.insert(ETAG, v);
    }
    if location && let Ok(v) = HeaderValue::from_str(&format!("{}/{id}", collection(kind))) {
        headers.insert(LOCATION, v);
    }
    (status, headers, Json(summary)).into_response()
}

/// The list's raw parameters: the page and the name filters.
pub fn list_page(q: &QueryParams) -> RawPage<'_> {
    raw_page(q.raw("limit"), q.get("cursor"), [q.get("name"), q.get("name_prefix"), q.get("name_contains")], in_query)
}

/// `GET …/{id}`: the stored document exactly as accepted, with its `ETag`;
/// 304 when `If-None-Match` names its version.
///
/// # Errors
/// `<kind>_not_found`; a malformed `If-None-Match` (400); the store's failure.
pub async fn get(state: &AppState, kind: DocKind, id: &str, headers: &HeaderMap) -> Result<Response, ApiError> {
    let if_none_match = precondition(headers, IF_NONE_MATCH, true)?;
    let stored = state.store.doc(kind, id).await.map_err(|e| store_error(kind, e))?;
    let stored = stored.ok_or(ApiError::NotFound { what: kind.what() })?;
    let content_type = HeaderValue::from_static("application/json");
    unless_modified(if_none_match, stored.meta.version, || {
        ([(CONTENT_TYPE, content_type)], stored.doc_json).into_response()
    })
}

/// The version a conditional write of document `id` must find.
///
/// # Errors
/// `<kind>_not_found` when the condition needs the current version of a
/// missing document; `version_mismatch` (412); the store's failure.
pub async fn expected_version(
    state: &AppState,
    kind: DocKind,
    id: &str,
    condition: Option<Precondition>,
) -> Result<Option<u64>, ApiError> {
    expected(condition, async || {
        let stored = state.store.doc(kind, id).await.map_err(|e| store_error(kind, e))?;
        Ok(stored.ok_or(ApiError::NotFound { what: kind.what() })?.meta.version)
    })
    .await
}

/// `DELETE …/{id}`, honouring `If-Match`: 204.
///
/// # Errors
/// As [`expected_version`]; `<kind>_not_found`.
pub async fn delete(state: &AppState, kind: DocKind, id: &str, headers: &HeaderMap) -> Result<StatusCode, ApiError> {
    let expected = expected_version(state, kind, id, precondition(headers, IF_MATCH, false)?).await?;
    state.store.delete_doc(kind, id, expected).await.map_err(|e| store_error(kind, e))?;
    state.document_changed(kind, id);
    tracing::info!(%id, what = kind.what(), "document deleted");
    Ok(StatusCode::NO_CONTENT)
}
