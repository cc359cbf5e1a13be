//! Broadcasts (docs/broadcasts.md): `POST /v1/broadcasts` (write), `GET /v1/broadcasts`
//! and `GET /v1/broadcasts/{id}` (read), `DELETE /v1/broadcasts/{id}` and
//! `POST /v1/broadcasts/{id}/controls` (write), and the WebSocket
//! `GET /v1/broadcasts/{id}/stream` (read).
//!
//! Handlers decode and render; the rules are the request layer's
//! (`request::RawBroadcast`, a motion stream's), the playback the stream
//! engine's (`stream::Broadcast`). The watch socket is also the
//! controlling socket: a caller with the write scope may send the stream
//! control messages on it and they act on the broadcast for every viewer
//! (refusals answered as on any stream); a read-only caller's are refused
//! with `{"error":{"code":"insufficient_scope"}}` and its frames go on.

use std::sync::Arc;

use axum::Extension;
use axum::Json;
use axum::extract::ws::Message;
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::http::header::LOCATION;
use axum::response::{IntoResponse, Response};
use futures_util::SinkExt;
use serde::Serialize;
use utoipa::ToSchema;

use crate::auth::{Identity, ReadAccess, Scope, WriteAccess};
use crate::error::ApiError;
use crate::request::{Raw, compact_watch, in_query};
use crate::state::AppState;
use crate::stream::{Broadcast, Encoding};
use crate::{broadcast_store, broadcast_work};

use super::extract::JsonBody;
use super::query::Query;
use super::stream::{configured, refuse, resolver, serve};

pub use crate::broadcast_store::CreateBroadcast;

/// A broadcast as `GET` shows it.
#[derive(Debug, Serialize, ToSchema)]
pub struct BroadcastSummary {
    pub id: String,
    pub fps: u32,
    /// Its tick now (frame `seq` is due at `created_at`'s grid tick + seq/fps).
    pub seq: u64,
    /// RFC 3339.
    pub created_at: String,
    /// `playing` or `paused`, after every accepted control.
    pub state: &'static str,
    pub speed: f64,
    pub viewers: usize,
    pub idle_timeout_secs: u64,
    /// The grid phase in whole ms (as a stream's `inbetween-grid-phase-ms`).
    pub grid_phase_ms: u32,
    /// The WebSocket to watch it on.
    pub stream: String,
    /// The motion it plays, as created (its clips at the versions pinned then).
    #[schema(value_type = Object)]
    pub motion: serde_json::Value,
    /// `local` or `model`.
    pub space: String,
    /// The joints frames carry (`null`: all).
    pub joints: Option<Vec<String>>,
    /// Its price now, in work units per second, charged to its creator
    /// (docs/api.md, "Work and its price").
    pub work_per_sec: u64,
    /// What looked wrong in its motion (docs/warnings.md,
    /// `joints_not_in_skeleton`); absent when nothing did.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    #[schema(value_type = Vec<super::schemas::Warning>)]
    pub warnings: Vec<serde_json::Value>,
}

/// `GET /v1/broadcasts`.
#[derive(Debug, Serialize, ToSchema)]
pub struct BroadcastList {
    pub broadcasts: Vec<BroadcastSummary>,
}

/// `POST /v1/broadcasts/{id}/controls`: the tick the control applies from.
#[derive(Debug, Serialize, ToSchema)]
pub struct ControlApplied {
    pub seq: u64,
}

/// The summary of `b`.
pub fn summary(b: &Broadcast) -> BroadcastSummary {
    let status = b.status();
    let described = &b.spec().description;
    let created_ms = b.created_at().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_millis() as i64);
    BroadcastSummary {
        id: b.id().to_owned(),
        fps: b.params().fps,
        seq: status.seq,
        created_at: super::summary::rfc3339(created_ms),
        state: if status.paused { "paused" } else { "playing" },
        speed: status.speed,
        viewers: status.viewers,
        idle_timeout_secs: b.spec().idle_timeout.as_secs(),
        grid_phase_ms: b.phase_ms(),
        stream: format!("/v1/broadcasts/{}/stream", b.id()),
        motion: described["motion"].clone(),
        space: described["space"].as_str().unwrap_or("local").to_owned(),
        joints: b.params().joints.as_ref().map(|_| b.params().joint_names()),
        work_per_sec: b.tick_price().saturating_mul(u64::from(b.params().fps)),
        warnings: crate::request::warnings(&b.params().motion, "/motion"),
    }
}

/// The broadcast `id` (live here, or stored by another node), or `broadcast_not_found`.
pub async fn live(state: &AppState, id: &str) -> Result<Arc<Broadcast>, ApiError> {
    broadcast_store::find(state, id).await
}

/// Create a broadcast.
#[utoipa::path(
    post, path = "/v1/broadcasts", tag = "broadcasts",
    request_body(content = CreateBroadcast, content_type = "application/json"),
    responses(
        (status = 201, description = "Live from its next tick; `Location` names it", body = BroadcastSummary),
        (status = 400, description = "Not JSON, or a value that does not parse", body = super::schemas::Problem),
        (status = 404, description = "A layer's clip does not exist (`clip_not_found`)", body = super::schemas::Problem),
        (status = 422, description = "`invalid_field`, a motion rule at `/motion/…`, `fps_out_of_range`, `unknown_joint`, `format_not_streamable`, `idle_timeout_out_of_range`, `frame_too_large`, `stream_rate_too_high`", body = super::schemas::Problem),
        (status = 429, description = "`too_many_broadcasts` (max_broadcasts); `caller_work_limit` (its price over the caller's share of the node)", body = super::schemas::Problem),
        (status = 503, description = "`overloaded`: the node's or the broadcasts' thread's work capacity is taken (`Retry-After`)", body = super::schemas::Problem),
    ),
    security(("bearer" = []))
)]
pub async fn create(
    State(state): State<AppState>,
    WriteAccess(caller): WriteAccess,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let spec = broadcast_store::spec_from_body(&state, &body).await?;
    let charge = broadcast_work::charge(&state, &spec, &caller.key())?;
    let b = state.streams.broadcasts().create(spec, charge).map_err(ApiError::TooManyBroadcasts)?;
    if let Err(e) = broadcast_store::store_created(&state, &b, &body).await {
        state.streams.broadcasts().delete(b.id());
        return Err(e);
    }
    tracing::info!(id = %b.id(), "broadcast created");
    let location = format!("/v1/broadcasts/{}", b.id());
    Ok((StatusCode::CREATED, [(LOCATION, location)], Json(summary(&b))).into_response())
}

/// List the live broadcasts.
#[utoipa::path(
    get, path = "/v1/broadcasts", tag = "broadcasts",
    responses((status = 200, body = BroadcastList)),
    security((), ("bearer" = []))
)]
pub async fn list(State(state): State<AppState>, _: ReadAccess) -> Json<BroadcastList> {
    Json(BroadcastList { broadcasts: state.streams.broadcasts().list().iter().map(|b| summary(b)).collect() })
}

/// One broadcast: what it plays, playing or paused, its speed and tick.
#[utoipa::path(
    get, path = "/v1/broadcasts/{id}", tag = "broadcasts",
    params(("id" = String, Path, description = "Broadcast id")),
    responses(
        (status = 200, body = BroadcastSummary),
        (status = 404, description = "`broadcast_not_found`", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn get(
    State(state): State<AppState>,
    _: ReadAccess,
    Path(id): Path<String>,
) -> Result<Json<BroadcastSummary>, ApiError> {
    let b = live(&state, &id).await?;
    Ok(Json(summary(&b)))
}

/// End a broadcast: its viewers get close 1000 / gRPC OK.
#[utoipa::path(
    delete, path = "/v1/broadcasts/{id}", tag = "broadcasts",
    params(("id" = String, Path, description = "Broadcast id")),
    responses(
        (status = 204, description = "Ended"),
        (status = 404, description = "`broadcast_not_found`", body = super::schemas::Problem),
    ),
    security(("bearer" = []))
)]
pub async fn delete(
    State(state): State<AppState>,
    _: WriteAccess,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    if !broadcast_store::delete(&state, &id).await? {
        return Err(ApiError::NotFound { what: "broadcast" });
    }
    tracing::info!(%id, "broadcast deleted");
    Ok(StatusCode::NO_CONTENT)
}

/// Control a broadcast for every viewer.
#[utoipa::path(
    post, path = "/v1/broadcasts/{id}/controls", tag = "broadcasts",
    params(("id" = String, Path, description = "Broadcast id")),
    request_body(content = Object, content_type = "application/json", description = "One stream control (`docs/motion.md`, \"Controls\"; `ik`: `docs/ik.md`): `{\"op\":\"play\"}`, `pause`, `{\"op\":\"seek\",\"time\"}`, `{\"op\":\"speed\",\"speed\"}`, `{\"op\":\"crossfade\",\"to\":motion,\"duration\",\"ease\"}`, `{\"op\":\"layer\",\"index\",\"weight\",\"duration\"}`, `{\"op\":\"ik\",\"constraints\"}`"),
    responses(
        (status = 200, description = "The tick from which it applies for every viewer", body = ControlApplied),
        (status = 400, description = "Not JSON", body = super::schemas::Problem),
        (status = 404, description = "`broadcast_not_found`; a crossfade's clip (`clip_not_found` at `/to/…`)", body = super::schemas::Problem),
        (status = 422, description = "`bad_control` (not a control, out of range, `stop`, a crossfade to another skeleton, a layer the motion lacks, too many pending); an `ik` rule's code at `/constraints/…`; `too_much_work` (a crossfade or `ik` control that would price the broadcast over `max_request_work`)", body = super::schemas::Problem),
        (status = 429, description = "`rate_limited` (the write budget); `caller_work_limit` (a re-priced broadcast over its creator's share)", body = super::schemas::Problem),
        (status = 503, description = "`unavailable`: the broadcast's store queue is full or the store failed (not applied; `Retry-After`); `overloaded`", body = super::schemas::Problem),
    ),
    security(("bearer" = []))
)]
pub async fn control(
    State(state): State<AppState>,
    _: WriteAccess,
    Path(id): Path<String>,
    JsonBody(body): JsonBody,
) -> Result<Json<ControlApplied>, ApiError> {
    let b = live(&state, &id).await?;
    let seq = broadcast_store::control(&state, &b, &body).await?;
    Ok(Json(ControlApplied { seq }))
}

/// Watch a broadcast: upgrade to a WebSocket of its frames.
#[utoipa::path(
    get, path = "/v1/broadcasts/{id}/stream", tag = "broadcasts",
    params(
        ("id" = String, Path, description = "Broadcast id"),
        ("encoding" = Option<String>, Query, pattern = "^(json|protobuf|compact)$", description = "json (default, text frames) | protobuf (binary `Frame`) | compact (binary compact frames, docs/compact-frames.md, after an `{\"opened\":{…,\"compact\":layout}}` text message)"),
        ("max_error" = Option<f64>, Query, description = "Compact frames: the error bound in metres, at least 1e-6 (default 1e-4)"),
        ("distance" = Option<f64>, Query, description = "Compact frames: the distance of the checked points, metres, at least 0.01 (default 10 % of the rest height)"),
    ),
    responses(
        (status = 101, description = "Switching to WebSocket; frames follow from the next tick (`seq` is the broadcast's tick, the first frame's `dropped` 0). A caller with the write scope may send stream controls (not `stop`, which only ends its own socket) that act on the broadcast for every viewer; a read-only caller's are answered `{\"error\":{\"code\":\"insufficient_scope\"}}`. Close 1000 when the broadcast ends, 1001 at shutdown, 1013 over the stream caps"),
        (status = 400, description = "`websocket_upgrade_required`, `bad_parameter`", body = super::schemas::Problem),
        (status = 404, description = "`broadcast_not_found`", body = super::schemas::Problem),
        (status = 422, description = "Compact frames: `max_error_out_of_range`, `distance_out_of_range`, `compact_unsupported` (a broadcast whose poses no range bounds: a character whose hips sit below a joint of another role; or one that crossfaded to such a motion, or to more distinct motions than its layouts keep track of), `too_many_compact_layouts`, `too_much_work`", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn watch(
    State(state): State<AppState>,
    ReadAccess(caller): ReadAccess,
    Extension(identity): Extension<Identity>,
    Path(id): Path<String>,
    Query(q): Query,
    upgrade: Result<super::socket::StreamUpgrade, WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    let upgrade = upgrade.map_err(|e| ApiError::parameter("websocket_upgrade_required", "upgrade", e.body_text()))?;
    let encoding = match q.raw("encoding") {
        None | Some(Raw::Text("json")) => Encoding::Json,
        Some(Raw::Text("protobuf")) => Encoding::Protobuf,
        Some(Raw::Text("compact")) => Encoding::Compact,
        Some(_) => {
            return Err(ApiError::parameter("bad_parameter", "encoding", "expected one of: json, protobuf, compact"));
        }
    };
    let compact_asked = (q.raw("max_error"), q.raw("distance"));
    let b = live(&state, &id).await?;
    let compact = match encoding {
        Encoding::Compact => Some(compact_watch(&state, &b, compact_asked, in_query, &caller).await?),
        _ if compact_asked.0.is_some() || compact_asked.1.is_some() => {
            let detail = "`max_error` and `distance` apply to `encoding=compact` only";
            return Err(ApiError::parameter("unknown_parameter", "max_error", detail));
        }
        _ => None,
    };
    let gate = identity.authorize(Scope::Write).is_ok().then(|| broadcast_work::gate(&state, caller.clone()));
    let permit = state.streams.admit_for(caller.addr, caller.token.clone());
    let (watched, ticket) = match (permit, compact) {
        (Err(refused), _) => (Err(refused), None),
        (Ok(permit), None) => (Ok(b.watch(encoding, permit, gate)), None),
        (Ok(permit), Some((layout, ticket))) => {
            let sub = b.watch_compact(layout, permit, gate).map_err(|e| ApiError::Invalid {
                code: e.code,
                at: crate::error::At::Parameter(e.field.to_owned()),
                detail: e.detail,
            })?;
            (Ok(sub), Some(ticket))
        }
    };
    let motions = resolver(&state);
    let mut response = upgrade.on_upgrade(configured(&state.config.limits), move |socket| async move {
        // The compact encoding's price is held while the viewer watches.
        let _held = ticket;
        match watched {
            Ok(sub) if sub.params().compact.is_some() => {
                let mut socket = socket;
                if socket.send(Message::Text(super::stream::opened_message(&sub).to_string().into())).await.is_ok() {
                    serve(socket, sub, motions).await;
                }
            }
            Ok(sub) => serve(socket, sub, motions).await,
            Err(refused) => refuse(socket, crate::stream::ws::close::TRY_AGAIN_LATER, refused.to_string()).await,
        }
    });
    response.headers_mut().insert(crate::stream::PHASE_HEADER, b.phase_ms().into());
    Ok(response)
}
