//! The WebSocket side of a stream (SPEC §5): frames out as JSON text or
//! binary protobuf, control messages in, ping/pong keepalive.
//!
//! [`serve`] is generic over any `Sink + Stream` of axum WebSocket messages,
//! so unit tests drive it with in-memory channels and a paused clock while
//! the server hands it the real socket. It is the only task of a WebSocket
//! stream; it owns its [`Subscription`] and ends (with a close frame saying
//! why) on `max_frames`, `stop`, shutdown, a client that goes away, one that
//! stops answering pings, or one that does not accept a frame for a whole
//! keepalive period (a slow consumer: close 1008 `slow_consumer` if that still
//! fits; its unsent bytes are bounded by `stream_buffer_bytes` meanwhile).
//!
//! Control messages are JSON text: `{"op":"pause"}`, `{"op":"play"}`,
//! `{"op":"seek","time":1.5}`, `{"op":"speed","speed":-1}`, `{"op":"stop"}`.
//! A bad one is answered with a text message
//! `{"error":{"code":"bad_control","detail":"..."}}` and the stream goes on.

use std::time::Duration;

use axum::extract::ws::{CloseFrame, Message, Utf8Bytes};
use futures_util::{Sink, SinkExt, Stream, StreamExt};
use serde::Deserialize;
use tokio::time::{Instant, MissedTickBehavior, interval_at, timeout};

use super::encode::Encoding;
use super::hub::EndReason;
use super::playhead::Control;
use super::subscription::{Next, Subscription};

/// WebSocket close codes (RFC 6455 §7.4.1).
pub mod close {
    pub const NORMAL: u16 = 1000;
    pub const GOING_AWAY: u16 = 1001;
    pub const POLICY: u16 = 1008;
    /// A client message over the inbound size limit.
    pub const TOO_BIG: u16 = 1009;
    pub const INTERNAL: u16 = 1011;
    /// "Try again later": the stream caps are reached.
    pub const TRY_AGAIN_LATER: u16 = 1013;
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WsConfig {
    /// How often to ping; a client that has not answered the previous ping
    /// by the next one, or has not accepted a frame for this long, is closed.
    pub keepalive: Duration,
}

impl Default for WsConfig {
    fn default() -> Self {
        WsConfig { keepalive: Duration::from_secs(20) }
    }
}

/// A control message from a client.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(tag = "op", rename_all = "snake_case", deny_unknown_fields)]
enum ControlMsg {
    Play,
    Pause,
    Seek { time: f64 },
    Speed { speed: f64 },
    Stop,
}

impl From<ControlMsg> for Control {
    fn from(m: ControlMsg) -> Control {
        match m {
            ControlMsg::Play => Control::Play,
            ControlMsg::Pause => Control::Pause,
            ControlMsg::Seek { time } => Control::Seek(time),
            ControlMsg::Speed { speed } => Control::Speed(speed),
            ControlMsg::Stop => Control::Stop,
        }
    }
}

/// The close frame for an end reason.
pub fn close_frame(reason: EndReason) -> CloseFrame {
    let (code, reason) = match reason {
        EndReason::MaxFrames => (close::NORMAL, "max_frames reached"),
        EndReason::Stopped => (close::NORMAL, "stopped"),
        EndReason::Shutdown => (close::GOING_AWAY, "the server is shutting down"),
        EndReason::Failed => (close::INTERNAL, "the stream failed"),
    };
    CloseFrame { code, reason: Utf8Bytes::from_static(reason) }
}

fn error_message(detail: &str) -> Message {
    let body = serde_json::json!({"error": {"code": "bad_control", "detail": detail}});
    Message::Text(body.to_string().into())
}

/// Streams `sub` over `socket` until the stream ends (see the module doc).
pub async fn serve<S, E>(mut socket: S, mut sub: Subscription, config: WsConfig)
where
    S: Sink<Message, Error = E> + Stream<Item = Result<Message, E>> + Unpin,
    E: std::error::Error + 'static,
{
    let mut ping = interval_at(Instant::now() + config.keepalive, config.keepalive);
    ping.set_missed_tick_behavior(MissedTickBehavior::Delay);
    let mut awaiting_pong = false;
    loop {
        let outgoing = tokio::select! {
            next = sub.next() => match next {
                Next::Frame(f) => match sub.encoding() {
                    Encoding::Json => match Utf8Bytes::try_from(f.bytes) {
                        Ok(text) => Message::Text(text),
                        Err(_) => continue, // the JSON encoder writes UTF-8 only
                    },
                    Encoding::Protobuf => Message::Binary(f.bytes),
                },
                Next::End(reason) => {
                    let _ = timeout(config.keepalive, socket.send(Message::Close(Some(close_frame(reason))))).await;
                    return;
                }
            },
            incoming = socket.next() => match incoming {
                None | Some(Ok(Message::Close(_))) => return,
                Some(Err(e)) => {
                    // A message over the inbound limit is refused with 1009;
                    // other read errors leave nothing to answer.
                    if is_too_big(&e) {
                        let frame = CloseFrame { code: close::TOO_BIG, reason: Utf8Bytes::from_static("message too big") };
                        let _ = timeout(config.keepalive, socket.send(Message::Close(Some(frame)))).await;
                    }
                    return;
                }
                Some(Ok(Message::Pong(_))) => {
                    awaiting_pong = false;
                    continue;
                }
                Some(Ok(Message::Ping(_))) => continue, // the socket answers pings itself
                Some(Ok(Message::Binary(_))) => error_message("control messages are JSON text"),
                Some(Ok(Message::Text(text))) => match serde_json::from_str::<ControlMsg>(&text) {
                    Ok(msg) => match sub.control(msg.into()) {
                        Ok(()) => continue,
                        Err(e) => error_message(&e.to_string()),
                    },
                    Err(e) => error_message(&format!("expected {{\"op\": \"play\"|\"pause\"|\"seek\"|\"speed\"|\"stop\", ...}}: {e}")),
                },
            },
            _ = ping.tick() => {
                if awaiting_pong {
                    let frame = CloseFrame { code: close::POLICY, reason: Utf8Bytes::from_static("keepalive timeout") };
                    let _ = timeout(config.keepalive, socket.send(Message::Close(Some(frame)))).await;
                    return;
                }
                awaiting_pong = true;
                Message::Ping(bytes::Bytes::new())
            }
        };
        match timeout(config.keepalive, socket.send(outgoing)).await {
            Ok(Ok(())) => {}
            Ok(Err(_)) => return,
            Err(_) => return close_slow_consumer(&mut socket).await,
        }
    }
}

/// A viewer that accepted nothing for a whole keepalive period: its bounded
/// buffers are full. It is told why (1008) if the close frame still fits in
/// within a second, then dropped either way.
async fn close_slow_consumer<S, E>(socket: &mut S)
where
    S: Sink<Message, Error = E> + Unpin,
{
    metrics::counter!("inbetween_slow_consumers_closed_total").increment(1);
    let frame = CloseFrame { code: close::POLICY, reason: Utf8Bytes::from_static("slow_consumer: frames not read") };
    let _ = timeout(Duration::from_secs(1), socket.send(Message::Close(Some(frame)))).await;
}

/// Whether a read error (anywhere in its source chain) is tungstenite's
/// "message or frame over the configured size".
fn is_too_big(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut cause = Some(e);
    while let Some(err) = cause {
        if let Some(tokio_tungstenite::tungstenite::Error::Capacity(_)) = err.downcast_ref() {
            return true;
        }
        cause = err.source();
    }
    false
}
