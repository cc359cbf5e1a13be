//! Graph routes (docs/graphs.md): create, list, get, replace, delete. A
//! graph is a named, versioned document as a character is (`ETag`,
//! `If-Match`, names that identify it; `rest::documents`); every write is
//! checked whole (`graphs::check_body`: its size, shape and clips, then
//! built by the core, priced and off the async workers) before the store is
//! touched, and the graph it built goes into the cache of built graphs.

use axum::Json;
use axum::extract::State;
use axum::http::header::IF_MATCH;
use axum::http::{HeaderMap, StatusCode};
use axum::response::Response;
use serde::Serialize;
use utoipa::ToSchema;

use crate::auth::{ReadAccess, WriteAccess};
use crate::documents;
use crate::error::ApiError;
use crate::graphs::{GraphReport, check_body};
use crate::state::AppState;
use crate::store::{DocKind, DocMeta};

use super::documents::{delete, expected_version, get, list_page, written};
use super::extract::{ClipId, JsonBody, etag, precondition};
use super::query::Query;
use super::summary::rfc3339;

/// A graph's identity and what it is made of, without its document.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct GraphSummary {
    /// Opaque, URL-safe, time-ordered id.
    pub id: String,
    pub name: String,
    /// 1 on create, +1 on each replace.
    pub version: u64,
    /// Nodes in the graph.
    pub nodes: u32,
    #[serde(flatten)]
    pub report: GraphReport,
    /// RFC 3339, UTC.
    pub created_at: String,
    pub updated_at: String,
    /// The strong entity tag of this version (as in the `ETag` header).
    pub etag: String,
}

impl From<&DocMeta> for GraphSummary {
    fn from(m: &DocMeta) -> Self {
        // Written by `graphs::check_doc`; a row changed behind the service's back reports nothing more.
        let report: GraphReport = serde_json::from_str(&m.report_json).unwrap_or_default();
        GraphSummary {
            id: m.id.clone(),
            name: m.name.clone(),
            version: m.version,
            nodes: m.figure,
            report,
            created_at: rfc3339(m.created_at),
            updated_at: rfc3339(m.updated_at),
            etag: etag(m.version),
        }
    }
}

/// A page of graphs.
#[derive(Debug, Serialize, ToSchema)]
pub struct GraphList {
    pub graphs: Vec<GraphSummary>,
    /// Pass as `cursor` for the next page; `null` on the last page.
    pub next_cursor: Option<String>,
}

fn answer(meta: &DocMeta, status: StatusCode, location: bool) -> Response {
    written(DocKind::Graph, (&meta.id, meta.version), status, location, GraphSummary::from(meta))
}

/// Create a graph: parameters, nodes (clips, blend spaces, layers) and a state machine or an output node.
#[utoipa::path(
    post, path = "/v1/graphs", tag = "graphs",
    params(
        ("replace" = Option<bool>, Query, description = "true: when a graph has this name, store the upload as its new version (same id, 200) instead of refusing it (409 name_taken)"),
    ),
    request_body(content = Object, content_type = "application/json", description = "The graph document (docs/graphs.md)"),
    responses(
        (status = 201, description = "Stored; `Location` names the graph", body = GraphSummary),
        (status = 200, description = "With replace=true, stored as the new version of the graph of that name", body = GraphSummary),
        (status = 400, description = "Not JSON", body = super::schemas::Problem),
        (status = 401, description = "Write token missing or wrong", body = super::schemas::Problem),
        (status = 404, description = "A clip the graph names does not exist (clip_not_found), with the pointer of the field naming it", body = super::schemas::Problem),
        (status = 409, description = "A graph has this name (name_taken)", body = super::schemas::Problem),
        (status = 413, description = "Over max_graph_bytes (body_too_large)", body = super::schemas::Problem),
        (status = 415, description = "Not application/json", body = super::schemas::Problem),
        (status = 422, description = "A rule of docs/graphs.md broken (unknown_parameter, unknown_node, unknown_state, node_cycle, degenerate_blend_space, parameter_range, incompatible_skeleton, skeleton_mismatch, …), a limit (too_many_nodes, too_many_points) or the price (too_much_work), with a pointer", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn create_graph(
    State(state): State<AppState>,
    WriteAccess(caller): WriteAccess,
    Query(params): Query,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let on_name = params.on_name()?;
    let checked = check_body(&state, &caller.key(), body).await?;
    let meta = checked.create(&state, on_name).await?;
    tracing::info!(id = %meta.id, name = %meta.name, version = meta.version, "graph created");
    let status = if meta.version == 1 { StatusCode::CREATED } else { StatusCode::OK };
    Ok(answer(&meta, status, true))
}

/// List graphs in creation order, a page at a time, optionally filtered by name.
#[utoipa::path(
    get, path = "/v1/graphs", tag = "graphs",
    params(
        ("limit" = Option<u32>, Query, minimum = 1, maximum = 1000, description = "Page size, 1..=1000 (default 100)"),
        ("cursor" = Option<String>, Query, pattern = "^[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}$", description = "`next_cursor` of the previous page (with the same filters)"),
        ("name" = Option<String>, Query, min_length = 1, max_length = 256, description = "Only the graph with exactly this name"),
        ("name_prefix" = Option<String>, Query, min_length = 1, max_length = 256, description = "Only graphs whose name starts with this (case-sensitive): a folder such as hero/"),
        ("name_contains" = Option<String>, Query, min_length = 1, max_length = 256, description = "Only graphs whose name contains this (case-sensitive)"),
    ),
    responses(
        (status = 200, body = GraphList),
        (status = 400, body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn list_graphs(
    State(state): State<AppState>,
    _: ReadAccess,
    Query(q): Query,
) -> Result<Json<GraphList>, ApiError> {
    let (metas, next_cursor) = documents::page(&*state.store, DocKind::Graph, list_page(&q).check()?).await?;
    Ok(Json(GraphList { graphs: metas.iter().map(GraphSummary::from).collect(), next_cursor }))
}

/// The stored graph document, exactly as accepted, with its `ETag`.
#[utoipa::path(
    get, path = "/v1/graphs/{id}", tag = "graphs",
    params(("id" = String, Path, description = "Graph id")),
    responses(
        (status = 200, description = "The graph document (docs/graphs.md)", body = Object),
        (status = 304, description = "`If-None-Match` matched"),
        (status = 404, description = "No such graph (graph_not_found)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn get_graph(
    State(state): State<AppState>,
    _: ReadAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    get(&state, DocKind::Graph, &id, &headers).await
}

/// Replace a graph's document; the version goes up by one. Streams already playing keep the version they started on.
#[utoipa::path(
    put, path = "/v1/graphs/{id}", tag = "graphs",
    params(
        ("id" = String, Path, description = "Graph id"),
        ("If-Match" = Option<String>, Header, pattern = r#"^(\*|"[0-9]{1,19}")$"#, description = "Replace only at this version (`\"3\"`) or `*`"),
    ),
    request_body(content = Object, content_type = "application/json", description = "The graph document (docs/graphs.md)"),
    responses(
        (status = 200, description = "Replaced", body = GraphSummary),
        (status = 404, description = "No such graph (graph_not_found), or a clip it names does not exist (clip_not_found, with a pointer)", body = super::schemas::Problem),
        (status = 409, description = "Renamed to another graph's name (name_taken)", body = super::schemas::Problem),
        (status = 412, description = "`If-Match` did not match the current version (version_mismatch)", body = super::schemas::Problem),
        (status = 413, description = "Over max_graph_bytes (body_too_large)", body = super::schemas::Problem),
        (status = 422, description = "As for create", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn replace_graph(
    State(state): State<AppState>,
    WriteAccess(caller): WriteAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let condition = precondition(&headers, IF_MATCH, false)?;
    let checked = check_body(&state, &caller.key(), body).await?;
    let expected = expected_version(&state, DocKind::Graph, &id, condition).await?;
    let meta = checked.replace(&state, &id, expected).await?;
    tracing::info!(id = %meta.id, version = meta.version, "graph replaced");
    Ok(answer(&meta, StatusCode::OK, false))
}

/// Delete a graph (honours `If-Match`).
#[utoipa::path(
    delete, path = "/v1/graphs/{id}", tag = "graphs",
    params(
        ("id" = String, Path, description = "Graph id"),
        ("If-Match" = Option<String>, Header, pattern = r#"^(\*|"[0-9]{1,19}")$"#, description = "Delete only at this version"),
    ),
    responses(
        (status = 204, description = "Deleted"),
        (status = 404, description = "No such graph (graph_not_found)", body = super::schemas::Problem),
        (status = 412, description = "`If-Match` did not match (version_mismatch)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn delete_graph(
    State(state): State<AppState>,
    _: WriteAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
) -> Result<StatusCode, ApiError> {
    delete(&state, DocKind::Graph, &id, &headers).await
}
