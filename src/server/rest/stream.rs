//! `GET /v1/clips/{id}/stream`: fixed-rate frames over a WebSocket
//! (SPEC §5).
//!
//! The query is validated and the clip loaded before the upgrade, so a bad
//! request is an ordinary 4xx problem. A request over the stream caps is
//! upgraded and then closed at once with code 1013 ("try again later") and
//! the reason, because a browser's WebSocket API cannot read the body of a
//! refused handshake. After the upgrade, `crate::stream::ws::serve` owns the
//! connection; it is not covered by axum's graceful shutdown, so the
//! application ends it through the streaming engine's shutdown (close 1001).

use std::net::SocketAddr;

use axum::Extension;
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{CloseFrame, Message, WebSocket, WebSocketUpgrade};
use axum::extract::{ConnectInfo, State};
use axum::response::Response;

use crate::server::auth::ReadAccess;
use crate::server::config::Limits;
use crate::server::error::ApiError;
use crate::server::request::{Opening, RawStream, in_query};
use crate::server::state::AppState;
use crate::stream::ws::{WsConfig, close};

use super::extract::ClipId;
use super::query::Query;

/// The socket's read buffer. tungstenite's default (128 KiB) made a WebSocket
/// stream cost the server ~125 KiB of RSS (measured by `inbetween load
/// ws-stream`); clients only send small controls.
const READ_BUFFER_BYTES: usize = 8 * 1024;

/// Most bytes a viewer may leave unsent in user space: `stream_buffer_bytes`,
/// or the older `ws_max_write_buffer_bytes` when that is smaller.
fn ws_max_write_buffer(l: &Limits) -> usize {
    l.stream_buffer_bytes.min(l.ws_max_write_buffer_bytes)
}

/// Bytes gathered before a write: below the bound above, as tungstenite needs.
fn ws_write_buffer(l: &Limits) -> usize {
    l.ws_write_buffer_bytes.min(ws_max_write_buffer(l) / 2)
}

/// Stream a clip: upgrade to a WebSocket of frames.
#[utoipa::path(
    get, path = "/v1/clips/{id}/stream", tag = "streams",
    params(
        ("id" = String, Path, description = "Clip id"),
        ("fps" = Option<u32>, Query, minimum = 1, maximum = 240, description = "Frames per second, 1..=240 (default 30)"),
        ("speed" = Option<f64>, Query, description = "Request seconds per second, may be negative (default 1)"),
        ("start" = Option<f64>, Query, description = "Request time of frame 0 (default: the clip's start)"),
        ("playback" = Option<String>, Query, pattern = "^(once|loop|ping_pong)$", description = "once | loop | ping_pong (default: the clip's)"),
        ("space" = Option<String>, Query, pattern = "^(local|model)$", description = "local (default) | model"),
        ("ease" = Option<String>, Query, pattern = "^(linear|ease_in|ease_out|ease_in_out)$", description = "linear (default) | ease_in | ease_out | ease_in_out"),
        ("encoding" = Option<String>, Query, pattern = "^(json|protobuf)$", description = "json (default, text frames) | protobuf (binary `Frame`)"),
        ("max_frames" = Option<u64>, Query, minimum = 1, description = "End after this many frames (close 1000)"),
    ),
    responses(
        (status = 101, description = "Switching to WebSocket; frames follow"),
        (status = 400, description = "A parameter does not parse (`bad_number`, `bad_parameter`)", body = super::schemas::Problem),
        (status = 404, body = super::schemas::Problem),
        (status = 422, description = "`fps_out_of_range`, `speed_out_of_range`, `max_frames_out_of_range`", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn stream(
    State(state): State<AppState>,
    ReadAccess(caller): ReadAccess,
    ClipId(id): ClipId,
    connect: Option<Extension<ConnectInfo<SocketAddr>>>,
    Query(q): Query,
    upgrade: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    // A plain GET (no upgrade headers) gets a problem body like every other refusal.
    let upgrade = upgrade.map_err(|e| ApiError::parameter("websocket_upgrade_required", "upgrade", e.body_text()))?;
    let raw = RawStream {
        fps: q.raw("fps"),
        start: q.raw("start"),
        speed: q.raw("speed"),
        modes: q.modes(),
        encoding: q.raw("encoding"),
        max_frames: q.raw("max_frames"),
        paused: false,
        at: in_query,
    };
    // The peer address, when served with connect info (`Application` is);
    // the caps count the caller (auth's `Caller`: its address and its token).
    let peer = connect.map(|Extension(ConnectInfo(addr))| addr);
    let Opening { params, permit } = raw.open(&state, &id, &caller).await?;
    // The playback is chosen now, so that the response can say its phase;
    // each WebSocket has its own connection, whose port is its lane.
    let engine = &state.streams;
    let watched = permit.map(|permit| engine.watch(params, permit, peer.map(|a| u64::from(a.port()))));
    let phase_ms = watched.as_ref().ok().map(|sub| sub.grid().phase_ms);
    // Inbound messages are small controls; outbound frames are buffered up
    // to a bound, so a viewer that stops reading cannot grow memory.
    let l = &state.config.limits;
    let upgrade = upgrade
        .max_message_size(l.ws_max_message_bytes)
        .max_frame_size(l.ws_max_message_bytes)
        .write_buffer_size(ws_write_buffer(l))
        .max_write_buffer_size(ws_max_write_buffer(l))
        .read_buffer_size(READ_BUFFER_BYTES);
    let mut response = upgrade.on_upgrade(move |socket: WebSocket| async move {
        match watched {
            Ok(sub) => {
                crate::panics::guarded("websocket", crate::stream::ws::serve(socket, sub, WsConfig::default())).await;
            }
            Err(refused) => {
                let mut socket = socket;
                let frame = CloseFrame { code: close::TRY_AGAIN_LATER, reason: refused.to_string().into() };
                let _ = socket.send(Message::Close(Some(frame))).await;
            }
        }
    });
    if let Some(phase_ms) = phase_ms {
        response.headers_mut().insert(crate::stream::PHASE_HEADER, phase_ms.into());
    }
    Ok(response)
}
