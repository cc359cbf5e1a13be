//! WebSocket streams (docs/api.md and docs/motion.md): `GET /v1/clips/{id}/stream` plays a
//! clip (a one-layer motion) and `GET /v1/stream` a composed motion named
//! in the client's first message, `{"op":"open","motion":…}`.
//!
//! On the clip route the query is validated and the clip loaded before the
//! upgrade, so a bad request is an ordinary 4xx problem. The motion route
//! upgrades first (a browser cannot send a body with the handshake) and
//! answers a bad `open` with `{"error": problem}` and close 1008; a good one
//! with `{"opened":{"grid_phase_ms","clip","joints"}}` before the frames (the clip
//! route too when its frames are compact, with the layout under `compact`). A request over the stream caps is
//! upgraded and then closed at once with code 1013 ("try again later") and
//! the reason, because a browser's WebSocket API cannot read the body of a
//! refused handshake. After the upgrade, `crate::stream::ws::serve` owns the
//! connection; it is not covered by axum's graceful shutdown, so the
//! application ends it through the streaming engine's shutdown (close 1001).

use std::net::SocketAddr;

use axum::Extension;
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{CloseFrame, Message};
use axum::extract::{ConnectInfo, State};
use axum::response::Response;

use std::sync::Arc;

use axum::extract::ws::Utf8Bytes;
use futures_util::future::BoxFuture;
use futures_util::{SinkExt, StreamExt};
use serde::Deserialize;
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;

use crate::auth::{Caller, CallerKey, ReadAccess};
use crate::config::Limits;
use crate::error::ApiError;
use crate::request::{
    Opening, Raw, RawGraphStream, RawModes, RawMotion, RawStream, at_clip_route, crossfade_target, graph_layer,
    in_body, in_query, on_character, parse_json,
};
use crate::state::AppState;
use crate::stream::ws::{MotionResolver, WsConfig, close};
use crate::stream::{StreamMotion, Subscription};
use formats::wire::motion::MotionDoc;

use super::extract::ClipId;
use super::query::Query;
use super::socket::{StreamSocket, StreamUpgrade};

/// The socket's read buffer. tungstenite's default (128 KiB) made a WebSocket
/// stream cost the server ~125 KiB of RSS (measured by `inbetween load
/// ws-stream`); clients mostly send small controls, and a bigger message
/// reserves its own length when its header arrives. Small also because
/// tungstenite zero-fills the buffer's free space on every read attempt, which
/// is once per frame sent (8 KiB of memset per frame when this was 8 KiB).
const READ_BUFFER_BYTES: usize = 1024;

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
        ("encoding" = Option<String>, Query, pattern = "^(json|protobuf|compact)$", description = "json (default, text frames) | protobuf (binary `Frame`) | compact (binary compact frames, docs/compact-frames.md; the first message is `{\"opened\":{…,\"compact\":layout}}`)"),
        ("max_error" = Option<f64>, Query, description = "Compact frames: the error bound in metres, at least 1e-6 (default 1e-4)"),
        ("distance" = Option<f64>, Query, description = "Compact frames: the distance of the checked points along each joint's axes, metres, at least 0.01 (default 10 % of the rest height)"),
        ("max_frames" = Option<u64>, Query, minimum = 1, description = "End after this many frames (close 1000)"),
        ("joints" = Option<String>, Query, description = "Comma-separated joint names: frames carry only those joints, in skeleton order"),
        ("parameters" = Option<String>, Query, description = "Comma-separated parameter names (docs/clip-format.md §3): frames carry only those parameters, in the clip's order"),
        ("springs" = Option<bool>, Query, description = "true (default) | false. A clip with spring chains streams its one-layer motion, its chains running (docs/springs.md, “Clip routes”); false: its keyed poses, priced without spring substeps"),
        ("character" = Option<String>, Query, description = "A character id or `name:<name>`: the clip played on it, the stream `GET /v1/stream` opens for the one-layer motion `{\"layers\":[{\"clip\":id}],\"character\":…}` (its `opened` message first; docs/characters.md); refusals `character_not_found` (404), `unmappable_skeleton` (422) at `character`"),
    ),
    responses(
        (status = 101, description = "Switching to WebSocket; frames follow. Controls (text): pause, play, seek, speed, stop, crossfade (to a motion with this clip's skeleton), layer"),
        (status = 400, description = "A parameter does not parse (`bad_number`, `bad_parameter`)", body = super::schemas::Problem),
        (status = 404, body = super::schemas::Problem),
        (status = 422, description = "`fps_out_of_range`, `speed_out_of_range`, `max_frames_out_of_range`, `unknown_joint`, compact frames' `max_error_out_of_range`, `distance_out_of_range`, `compact_unsupported` (model space, a joint subset, or poses no range bounds: a character whose hips sit below a joint of another role), `too_much_work` (the price per second of playback over `max_request_work`), `frame_too_large`, `stream_rate_too_high`", body = super::schemas::Problem),
        (status = 429, description = "The caller holds its share of the node's work (`caller_work_limit`, with `Retry-After`)", body = super::schemas::Problem),
        (status = 503, description = "The node's work capacity is taken (`overloaded`, with `Retry-After`)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn stream(
    State(state): State<AppState>,
    ReadAccess(caller): ReadAccess,
    ClipId(id): ClipId,
    connect: Option<Extension<ConnectInfo<SocketAddr>>>,
    Query(q): Query,
    upgrade: Result<StreamUpgrade, WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    // A plain GET (no upgrade headers) gets a problem body like every other refusal.
    let upgrade = upgrade.map_err(|e| ApiError::parameter("websocket_upgrade_required", "upgrade", e.body_text()))?;
    let list = |name: &str| -> Option<Vec<String>> {
        q.raw(name).map(|raw| match raw {
            Raw::Text(text) => text.split(',').map(str::to_owned).collect(),
            _ => Vec::new(),
        })
    };
    let (joints, parameters) = (list("joints"), list("parameters"));
    let raw = RawStream {
        fps: q.raw("fps"),
        start: q.raw("start"),
        speed: q.raw("speed"),
        modes: q.modes(),
        encoding: q.raw("encoding"),
        max_error: q.raw("max_error"),
        distance: q.raw("distance"),
        max_frames: q.raw("max_frames"),
        paused: false,
        springs: q.springs()?,
        joints: joints.as_deref(),
        parameters: parameters.as_deref(),
        at: in_query,
    };
    // The peer address, when served with connect info (`Application` is);
    // the caps count the caller (auth's `Caller`: its address and its token).
    let peer = connect.map(|Extension(ConnectInfo(addr))| addr);
    let on_character = q.get("character");
    let admitted = match on_character {
        Some(character) => open_on_character(&state, raw, (&id, character), &caller).await?,
        None => raw.open(&state, &id, &caller).await?,
    };
    let hello_first = on_character.is_some();
    // The playback is chosen now, so that the response can say its phase;
    // each WebSocket has its own connection, whose port is its lane.
    let engine = &state.streams;
    let lane = peer.map(|a| u64::from(a.port()));
    let watched = admitted.map(|Opening { params, permit }| engine.watch(params, permit, lane));
    let phase_ms = watched.as_ref().ok().map(|sub| sub.grid().phase_ms);
    let motions = resolver_for(&state, caller.key());
    let mut response = upgrade.on_upgrade(configured(&state.config.limits), move |socket| async move {
        match watched {
            // A compact stream states its layout first (docs/compact-frames.md), and a stream
            // on a character what it plays, as a motion stream does.
            Ok(sub) if sub.params().compact.is_some() || hello_first => {
                let mut socket = socket;
                if socket.send(Message::Text(opened_message(&sub).to_string().into())).await.is_ok() {
                    serve(socket, sub, motions).await;
                }
            }
            Ok(sub) => serve(socket, sub, motions).await,
            Err(refused) => refuse(socket, close::TRY_AGAIN_LATER, refused.to_string()).await,
        }
    });
    if let Some(phase_ms) = phase_ms {
        response.headers_mut().insert(crate::stream::PHASE_HEADER, phase_ms.into());
    }
    Ok(response)
}

/// `GET …/stream?character=`: the one-layer motion of the clip on the
/// character (docs/characters.md), opened as `GET /v1/stream` opens it, the
/// query's `playback` the layer's; refusals at the query's names.
/// Not via `ClipRoute::motion`: a stream eases its motion (a route refuses `ease`); a sprung clip streams as a clip.
async fn open_on_character(
    state: &AppState,
    raw: RawStream<'_>,
    (id, character): (&str, &str),
    caller: &Caller,
) -> Result<Result<Opening, crate::stream::AdmitError>, ApiError> {
    let playback = raw.modes.check(in_query)?.playback;
    let doc = on_character(id, playback, character);
    let raw = RawStream { modes: RawModes { playback: None, ..raw.modes }, ..raw };
    let motion = RawMotion::of_doc(&doc).map_err(ApiError::from)?;
    raw.open_motion(state, motion, caller).await.map_err(|e| at_clip_route(e, in_query))
}

/// Stream a composed motion: upgrade, then `{"op":"open","motion":…}`.
#[utoipa::path(
    get, path = "/v1/stream", tag = "streams",
    responses(
        (status = 101, description = "Switching to WebSocket. The client's first text message is a `StreamOpen` (the fields of the clip stream's query, but `playback`, which each layer has); the server answers `{\"opened\":{\"grid_phase_ms\",\"clip\",\"joints\",\"warnings\"?}}` (`warnings` when a layer has joints the output skeleton lacks) and frames follow, or `{\"error\":problem}` (pointers into the message: `/motion/layers/1/clip`) and close 1008. Controls as on the clip stream."),
        (status = 400, description = "Not a WebSocket upgrade (`websocket_upgrade_required`)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn motion_stream(
    State(state): State<AppState>,
    ReadAccess(caller): ReadAccess,
    connect: Option<Extension<ConnectInfo<SocketAddr>>>,
    upgrade: Result<StreamUpgrade, WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    let upgrade = upgrade.map_err(|e| ApiError::parameter("websocket_upgrade_required", "upgrade", e.body_text()))?;
    let lane = connect.map(|Extension(ConnectInfo(addr))| u64::from(addr.port()));
    let limits = state.config.limits.clone();
    Ok(upgrade.on_upgrade(configured(&limits), move |socket| async move {
        let mut socket = socket;
        let wait = limits.request_message_timeout;
        let opened = match tokio::time::timeout(wait, first_text(&mut socket)).await {
            Ok(Some(text)) => open(&state, &caller, &text, lane).await,
            Ok(None) => return,
            Err(_) => Err(ApiError::BodyTimeout { secs: wait.as_secs() }),
        };
        match opened {
            Ok(Ok(sub)) => {
                let mut hello = opened_message(&sub);
                let warnings = crate::request::warnings(&sub.params().motion, "/motion");
                if !warnings.is_empty() {
                    hello["opened"]["warnings"] = warnings.into();
                }
                if socket.send(Message::Text(hello.to_string().into())).await.is_ok() {
                    serve(socket, sub, resolver_for(&state, caller.key())).await;
                }
            }
            Ok(Err(refused)) => refuse(socket, close::TRY_AGAIN_LATER, refused.to_string()).await,
            Err(e) => {
                let error = serde_json::json!({ "error": e.problem_json() });
                let _ = socket.send(Message::Text(error.to_string().into())).await;
                refuse(socket, close::POLICY, e.code().to_owned()).await;
            }
        }
    }))
}

/// `{"opened":{"grid_phase_ms","clip","joints","compact"?}}`: what a stream
/// plays, and a compact stream's layout document.
pub(super) fn opened_message(sub: &Subscription) -> serde_json::Value {
    let mut hello = serde_json::json!({"opened": {
        "grid_phase_ms": sub.grid().phase_ms,
        "clip": &*sub.params().clip_id,
        "joints": sub.params().joint_names(),
    }});
    if let Some(compact) = &sub.params().compact {
        let layout: serde_json::Value = serde_json::from_str(&compact.document).expect("a layout document is JSON");
        hello["opened"]["compact"] = layout;
    }
    hello
}

/// The first message of `GET /v1/stream`: what to play and how.
#[derive(Debug, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct StreamOpen {
    /// Always `open`.
    #[allow(dead_code)]
    op: OpenOp,
    /// The composed motion (`docs/motion.md`); its clips are pinned at their current versions.
    motion: MotionDoc,
    /// Frames per second, 1..=240 (default 30).
    fps: Option<f64>,
    /// The motion time of frame 0 (default: the first layer's clip's start).
    start: Option<f64>,
    /// Motion seconds per second, within ±1000 (default 1; negative plays backwards).
    speed: Option<f64>,
    /// `local` (default) or `model`.
    space: Option<String>,
    /// Applied to every layer's clip time: `linear` (default), `ease_in`, `ease_out`, `ease_in_out`.
    ease: Option<String>,
    /// `json` (default, text frames), `protobuf` (binary `Frame`s) or `compact` (docs/compact-frames.md).
    encoding: Option<String>,
    /// Compact frames: the error bound, metres (default 1e-4, at least 1e-6).
    max_error: Option<f64>,
    /// Compact frames: the distance of the checked points, metres (default 10 % of the rest height).
    distance: Option<f64>,
    /// End after this many frames (close 1000).
    max_frames: Option<f64>,
    /// Only these joints in every frame, in skeleton order (default: all).
    joints: Option<Vec<String>>,
    /// Only these parameters in every frame (docs/clip-format.md §3), in the first layer's clip's order (default: all).
    parameters: Option<Vec<String>>,
    /// Start paused (a private playback; `play` resumes it).
    #[serde(default)]
    paused: bool,
    /// A graph stream's frames carry the tick's `graph` report (docs/graphs.md).
    #[serde(default)]
    report: bool,
}

#[derive(Debug, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
enum OpenOp {
    Open,
}

/// The client's first text message (`None`: it left first).
async fn first_text(socket: &mut StreamSocket) -> Option<String> {
    loop {
        match socket.next().await? {
            Ok(Message::Text(text)) => return Some(text.to_string()),
            Ok(Message::Close(_)) | Err(_) => return None,
            Ok(_) => {}
        }
    }
}

/// Opens the stream an `open` message asks for: the outer error is the
/// request's problem, the inner one a refusal of the stream caps.
async fn open(
    state: &AppState,
    caller: &Caller,
    text: &str,
    lane: Option<u64>,
) -> Result<Result<Subscription, crate::stream::AdmitError>, ApiError> {
    let msg: StreamOpen = parse_json(text.as_bytes())?;
    let raw = RawStream {
        fps: msg.fps.map(Raw::Number),
        start: msg.start.map(Raw::Number),
        speed: msg.speed.map(Raw::Number),
        modes: RawModes {
            space: msg.space.as_deref().map(Raw::Text),
            playback: None,
            ease: msg.ease.as_deref().map(Raw::Text),
        },
        encoding: msg.encoding.as_deref().map(Raw::Text),
        max_error: msg.max_error.map(Raw::Number),
        distance: msg.distance.map(Raw::Number),
        max_frames: msg.max_frames.map(Raw::Number),
        paused: msg.paused,
        springs: true,
        joints: msg.joints.as_deref(),
        parameters: msg.parameters.as_deref(),
        at: in_body,
    };
    let admitted = match graph_layer(&msg.motion)? {
        Some(layer) => {
            let graph = RawGraphStream { reference: layer.reference, stages: &layer.stages, report: msg.report };
            raw.open_graph(state, graph, caller).await?
        }
        None if msg.report => {
            let detail = "`report` is a graph stream's: the motion's layer names no `graph`";
            return Err(ApiError::invalid("graph_unsupported", "/report", detail));
        }
        None => raw.open_motion(state, RawMotion::of_doc(&msg.motion)?, caller).await?,
    };
    let engine = &state.streams;
    // A graph stream is its viewer's own (its `set`s are), and so is a paused one.
    Ok(admitted.map(|Opening { params, permit }| {
        if params.paused || params.graph.is_some() {
            engine.play(params, permit, lane)
        } else {
            engine.watch(params, permit, lane)
        }
    }))
}

/// Inbound messages are small controls; outbound messages are buffered up
/// to a bound, so a viewer that stops reading cannot grow memory (frames
/// skip that buffer: `socket`). The `inbetween` subprotocol is selected
/// when offered (`StreamUpgrade`): a browser offers it with its token
/// (`server::auth`) and needs one of its offers chosen.
pub(super) fn configured(l: &Limits) -> WebSocketConfig {
    WebSocketConfig::default()
        .max_message_size(Some(l.ws_max_message_bytes))
        .max_frame_size(Some(l.ws_max_message_bytes))
        .write_buffer_size(ws_write_buffer(l))
        .max_write_buffer_size(ws_max_write_buffer(l))
        .read_buffer_size(READ_BUFFER_BYTES)
}

pub(super) async fn serve(socket: StreamSocket, sub: Subscription, motions: Arc<dyn MotionResolver>) {
    let served = crate::stream::ws::serve(socket, sub, WsConfig::default(), Some(motions));
    crate::panics::guarded("websocket", served).await;
}

pub(super) async fn refuse(mut socket: StreamSocket, code: u16, reason: String) {
    let frame = CloseFrame { code, reason: Utf8Bytes::from(reason) };
    let _ = socket.send(Message::Close(Some(frame))).await;
}

/// Crossfade targets, looked up like a composed request's motion, their
/// builds charged to the stream's caller.
struct StateMotions(AppState, CallerKey);

/// Crossfade targets whose builds the node pays for.
pub(super) fn resolver(state: &AppState) -> Arc<dyn MotionResolver> {
    resolver_for(state, CallerKey::Node)
}

/// Crossfade targets whose builds `caller` pays for.
pub(super) fn resolver_for(state: &AppState, caller: CallerKey) -> Arc<dyn MotionResolver> {
    Arc::new(StateMotions(state.clone(), caller))
}

impl MotionResolver for StateMotions {
    fn resolve(&self, motion: serde_json::Value) -> BoxFuture<'static, Result<Arc<StreamMotion>, serde_json::Value>> {
        let (state, caller) = (self.0.clone(), self.1.clone());
        Box::pin(async move { crossfade_target(&state, &caller, &motion).await.map_err(|e| e.problem_json()) })
    }
}
