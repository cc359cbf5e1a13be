//! The graph RPCs (docs/graphs.md): the gRPC mirror of `/v1/graphs`. A
//! graph travels as its JSON document (the one REST takes), so it is
//! checked by the same code (`server::graphs`), priced and off the async
//! workers, with refusals at the same JSON pointers and the same codes, and
//! stored by the same store calls; answers carry the REST summary's fields.

use bytes::Bytes;

use crate::auth::Caller;
use crate::documents::{page, raw_page};
use crate::error::ApiError;
use crate::graphs::{check_body, store_error};
use crate::request::{Raw, in_body};
use crate::rest::graphs::GraphSummary;
use crate::state::AppState;
use crate::store::{DocKind, DocMeta, OnName};
use formats::wire::proto::pb;

/// `CreateGraph`: `POST /v1/graphs`.
pub async fn create(
    state: &AppState,
    caller: &Caller,
    req: pb::CreateGraphRequest,
) -> Result<pb::GraphSummary, ApiError> {
    let on_name = if req.replace { OnName::Replace } else { OnName::Refuse };
    let checked = check_body(state, &caller.key(), Bytes::from(req.document.into_bytes())).await?;
    let meta = checked.create(state, on_name).await?;
    tracing::info!(id = %meta.id, version = meta.version, "graph written over gRPC");
    Ok(summary_to_pb(&meta))
}

/// `ReplaceGraph`: `PUT /v1/graphs/{id}`.
pub async fn replace(
    state: &AppState,
    caller: &Caller,
    req: pb::ReplaceGraphRequest,
) -> Result<pb::GraphSummary, ApiError> {
    let checked = check_body(state, &caller.key(), Bytes::from(req.document.into_bytes())).await?;
    let meta = checked.replace(state, &req.graph_id, req.if_version).await?;
    Ok(summary_to_pb(&meta))
}

/// `GetGraph`: the summary and the document, by id or `name:` reference.
pub async fn get(state: &AppState, req: pb::GetGraphRequest) -> Result<pb::GraphRecord, ApiError> {
    let stored = state.store.doc_by_ref(DocKind::Graph, &req.graph_id).await.map_err(store_error)?;
    let stored = stored.ok_or(ApiError::NotFound { what: "graph" })?;
    Ok(pb::GraphRecord { summary: Some(summary_to_pb(&stored.meta)), document: stored.doc_json })
}

/// `ListGraphs`: `GET /v1/graphs`.
pub async fn list(state: &AppState, req: pb::ListGraphsRequest) -> Result<pb::ListGraphsResponse, ApiError> {
    let text = |s: &str| (!s.is_empty()).then(|| s.to_owned());
    let (name, name_prefix, name_contains) = (text(&req.name), text(&req.name_prefix), text(&req.name_contains));
    // 0: the default.
    let limit = (req.limit > 0).then_some(Raw::Number(f64::from(req.limit)));
    let cursor = (!req.cursor.is_empty()).then_some(req.cursor.as_str());
    let names = [name.as_deref(), name_prefix.as_deref(), name_contains.as_deref()];
    let (metas, next_cursor) =
        page(&*state.store, DocKind::Graph, raw_page(limit, cursor, names, in_body).check()?).await?;
    Ok(pb::ListGraphsResponse {
        graphs: metas.iter().map(summary_to_pb).collect(),
        next_cursor: next_cursor.unwrap_or_default(),
    })
}

/// `DeleteGraph`: `DELETE /v1/graphs/{id}`.
pub async fn delete(state: &AppState, req: pb::DeleteGraphRequest) -> Result<pb::DeleteGraphResponse, ApiError> {
    state.store.delete_doc(DocKind::Graph, &req.graph_id, req.if_version).await.map_err(store_error)?;
    state.document_changed(DocKind::Graph, &req.graph_id);
    tracing::info!(id = %req.graph_id, "graph deleted over gRPC");
    Ok(pb::DeleteGraphResponse {})
}

fn summary_to_pb(meta: &DocMeta) -> pb::GraphSummary {
    let s = GraphSummary::from(meta);
    pb::GraphSummary {
        id: s.id,
        name: s.name,
        version: s.version,
        nodes: s.nodes,
        parameters: s.report.parameters.into_iter().collect(),
        states: s.report.states,
        clips: s.report.clips,
    }
}
