//! The WebSocket side of a stream (docs/api.md): frames out as JSON text,
//! binary protobuf or binary compact frames (a delta frame preceded by the
//! key frame its viewer missed; a new layout, docs/compact-frames.md, as a
//! text message `{"layout": document, "seq": n}` before the first frame in
//! it), control messages in, ping/pong keepalive.
//!
//! [`serve`] is generic over any `Sink + Stream` of axum WebSocket messages,
//! so unit tests drive it with in-memory channels and a paused clock while
//! the server hands it the real socket. It is the only task of a WebSocket
//! stream that reads its socket; it owns its [`Subscription`]. A broadcast
//! viewer's frames are written by its broadcast's fan-out while its lane is
//! parked (`lane`, `fanout`): the task then waits for controls, pings and
//! the lane's hand-back, and first writes out whatever the fan-out left
//! unwritten. It ends (with a close frame saying why) on `max_frames`,
//! `stop`, shutdown, a client that goes away, one that stops answering
//! pings, or one that does not accept a frame for a whole keepalive period
//! (a slow consumer: close 1008 `slow_consumer` if that still fits; its
//! unsent bytes are bounded by `stream_buffer_bytes` meanwhile).
//!
//! Control messages are JSON text: `{"op":"pause"}`, `{"op":"play"}`,
//! `{"op":"seek","time":1.5}`, `{"op":"speed","speed":-1}`, `{"op":"stop"}`,
//! and for composition (docs/motion.md) `{"op":"crossfade","to":motion,
//! "duration":0.4,"ease":"ease_in_out"}` and `{"op":"layer","index":1,
//! "weight":0.3,"duration":0.5}`, and a graph stream's `{"op":"set",
//! "parameters":{…}}` (docs/graphs.md). A crossfade's motion names clips the
//! transport must look up ([`MotionResolver`]); while it does, the frames go
//! on and later controls wait behind it, so they apply in the order sent.
//! A bad control is answered with a text message
//! `{"error":{"code":"bad_control","detail":"..."}}` (a crossfade's motion
//! with the problem of its lookup: `clip_not_found` at `/to/layers/1/clip`)
//! and the stream goes on. So is a broadcast control refused by the
//! server's budgets, or withdrawn because it could not be stored: with the
//! server's whole problem (`{"error":{"status":429,"code":"rate_limited",…}}`).

use std::collections::VecDeque;
use std::future::Future;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::task::{Context, Poll, Wake, Waker};
use std::time::Duration;

use axum::extract::ws::{CloseFrame, Message, Utf8Bytes};
use futures_util::{Sink, SinkExt, Stream, StreamExt};
use tokio::time::{Instant, MissedTickBehavior, interval_at, timeout};

use futures_util::future::{BoxFuture, poll_fn};
use futures_util::stream::FuturesUnordered;
use futures_util::task::AtomicWaker;

use super::control::{Control, ControlError, ControlMsg, Crossfade, ParsedControl, not_a_control};
use super::encode::Encoding;
use super::hub::EndReason;
use super::lane::DirectWrite;
use super::pinned::StreamMotion;
use super::subscription::{Next, StoreOutcome, Subscription};

/// Builds the motion a control names (a crossfade's `to`): the transport's
/// lookup of its clips. A refusal is the problem document to send back, its
/// pointer relative to the control message.
pub trait MotionResolver: Send + Sync + 'static {
    fn resolve(&self, motion: serde_json::Value) -> BoxFuture<'static, Result<Arc<StreamMotion>, serde_json::Value>>;
}

/// Controls waiting behind a crossfade's lookup, at most.
const QUEUED_CONTROLS: usize = 32;

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

/// A crossfade whose motion is being looked up, and the controls sent after it.
type Lookup = BoxFuture<'static, LookedUp>;

/// A crossfade's motion looked up (or its refusal), with the rest of the
/// control: duration, ease, and the motion as sent.
type LookedUp = (Result<Arc<StreamMotion>, serde_json::Value>, f64, anim::Ease, Arc<serde_json::Value>);

/// The controls of one WebSocket stream: applied in the order sent, each
/// crossfade's lookup holding back the ones after it.
struct Controls {
    motions: Option<Arc<dyn MotionResolver>>,
    lookup: Option<Lookup>,
    queued: VecDeque<ControlMsg>,
    /// Broadcast controls sent whose store writes are under way.
    storing: FuturesUnordered<StoreOutcome>,
}

impl Controls {
    /// Takes a control message's text; returns the error message to send, if any.
    async fn receive(&mut self, text: &str, sub: &mut Subscription) -> Option<Message> {
        let msg = match serde_json::from_str::<ControlMsg>(text) {
            Ok(msg) => msg,
            Err(e) => return Some(error_message(&not_a_control(&e, true))),
        };
        if self.lookup.is_some() {
            if self.queued.len() >= QUEUED_CONTROLS {
                return Some(error_message("too many controls pending; wait for a frame before sending more"));
            }
            self.queued.push_back(msg);
            return None;
        }
        self.apply(msg, sub).await
    }

    /// Applies `msg` now, or starts its motion's lookup.
    async fn apply(&mut self, msg: ControlMsg, sub: &mut Subscription) -> Option<Message> {
        match msg.parse() {
            Ok(ParsedControl::Ready(control)) => {
                let sent = sub.control(control).await;
                self.storing.extend(sub.storing());
                sent.err().map(|e| refusal(&e))
            }
            Err(e) => Some(problem_message(e.code, Some(e.pointer), &e.detail)),
            Ok(ParsedControl::Crossfade { to, duration, ease }) => {
                let Some(motions) = &self.motions else {
                    return Some(error_message("this stream cannot resolve motions"));
                };
                let source = Arc::new(to.clone());
                let lookup = motions.resolve(to);
                self.lookup = Some(Box::pin(async move { (lookup.await, duration, ease, source) }));
                None
            }
        }
    }

    /// A lookup finished: the crossfade goes to the playback (or its refusal
    /// back to the client), then the controls queued behind it, up to the
    /// next crossfade. Returns the error messages to send.
    async fn looked_up(&mut self, (motion, duration, ease, source): LookedUp, sub: &mut Subscription) -> Vec<Message> {
        self.lookup = None;
        let mut errors = Vec::new();
        match motion {
            Ok(to) => {
                let fade = Control::Crossfade(Crossfade { to, duration, ease, source: Some(source) });
                errors.extend(sub.control(fade).await.err().map(|e| refusal(&e)));
                self.storing.extend(sub.storing());
            }
            Err(problem) => errors.push(Message::Text(serde_json::json!({ "error": problem }).to_string().into())),
        }
        while self.lookup.is_none()
            && let Some(msg) = self.queued.pop_front()
        {
            errors.extend(self.apply(msg, sub).await);
        }
        errors
    }
}

/// Waits for a control whose store write failed (it was withdrawn); never
/// resolves while none does. Cancel-safe.
async fn not_stored(storing: &mut FuturesUnordered<StoreOutcome>) -> ControlError {
    loop {
        match storing.next().await {
            Some(Ok(refusal)) => return refusal,
            // Stored: its sender has nothing more to hear.
            Some(Err(_)) => {}
            None => std::future::pending().await,
        }
    }
}

/// Waits for a pending lookup; never resolves without one.
async fn lookup_done(lookup: &mut Option<Lookup>) -> LookedUp {
    match lookup.as_mut() {
        Some(lookup) => lookup.await,
        None => std::future::pending().await,
    }
}

/// The close frame for an end reason.
pub fn close_frame(reason: EndReason) -> CloseFrame {
    let (code, reason) = match reason {
        EndReason::MaxFrames => (close::NORMAL, "max_frames reached"),
        EndReason::Stopped => (close::NORMAL, "stopped"),
        EndReason::Ended => (close::NORMAL, "the broadcast ended"),
        EndReason::Shutdown => (close::GOING_AWAY, "the server is shutting down"),
        EndReason::Failed => (close::INTERNAL, "the stream failed"),
        EndReason::TooMuchWork => (close::POLICY, "too_much_work: the broadcast's ticks overran their price"),
    };
    CloseFrame { code, reason: Utf8Bytes::from_static(reason) }
}

fn error_message(detail: &str) -> Message {
    problem_message("bad_control", None, detail)
}

/// A refused control's `{"error": {code, detail, pointer?}}` (the server's
/// whole problem document for a refusal of its budgets).
fn refusal(e: &ControlError) -> Message {
    if let ControlError::Refused { problem, .. } = e {
        return Message::Text(serde_json::json!({ "error": problem }).to_string().into());
    }
    problem_message(e.code(), e.pointer(), &e.to_string())
}

fn problem_message(code: &str, pointer: Option<String>, detail: &str) -> Message {
    let mut problem = serde_json::json!({"code": code, "detail": detail});
    if let Some(pointer) = pointer {
        problem["pointer"] = pointer.into();
    }
    Message::Text(serde_json::json!({ "error": problem }).to_string().into())
}

/// A socket that sends a stream's frames: by default as messages through
/// its `Sink`; the server's socket writes the playback's shared bytes to the
/// connection itself, behind a frame header, without copying them into a
/// per-viewer buffer (`server::rest::socket`, issue 19).
pub trait FrameSocket: Sink<Message> + Unpin {
    /// A writer another task may write whole frames to (a broadcast's
    /// fan-out, `fanout`); `None` (the default): every frame goes through
    /// [`FrameSocket::send_frame`].
    fn direct(&self) -> Option<Arc<dyn DirectWrite>> {
        None
    }

    /// Sends one frame: JSON text or protobuf binary, as `encoding` says.
    fn send_frame(&mut self, encoding: Encoding, bytes: bytes::Bytes) -> impl Future<Output = Result<(), Self::Error>> {
        async move {
            match frame_message(encoding, bytes) {
                Some(message) => self.send(message).await,
                None => Ok(()), // the JSON encoder writes UTF-8 only
            }
        }
    }
}

/// A compact stream's new layout (docs/compact-frames.md, "A new layout"):
/// `{"layout": document, "seq": n}`, `n` the first frame in it.
fn layout_message(seq: u64, document: &str) -> Message {
    Message::Text(format!("{{\"layout\":{document},\"seq\":{seq}}}").into())
}

/// A frame as a WebSocket message.
fn frame_message(encoding: Encoding, bytes: bytes::Bytes) -> Option<Message> {
    match encoding {
        Encoding::Json => text(bytes).map(Message::Text),
        Encoding::Protobuf | Encoding::Compact => Some(Message::Binary(bytes)),
    }
}

/// Streams `sub` over `socket` until the stream ends (see the module doc);
/// `motions` looks up a crossfade's motion (`None`: crossfades are refused).
pub async fn serve<S, E>(
    mut socket: S,
    mut sub: Subscription,
    config: WsConfig,
    motions: Option<Arc<dyn MotionResolver>>,
) where
    S: FrameSocket + Sink<Message, Error = E> + Stream<Item = Result<Message, E>> + Unpin,
    E: std::error::Error + 'static,
{
    let mut ping = interval_at(Instant::now() + config.keepalive, config.keepalive);
    ping.set_missed_tick_behavior(MissedTickBehavior::Delay);
    let mut awaiting_pong = false;
    let mut controls = Controls { motions, lookup: None, queued: VecDeque::new(), storing: FuturesUnordered::new() };
    let mut outbox: VecDeque<Message> = VecDeque::new();
    let mut reads = ReadGate::new();
    let direct = socket.direct().filter(|writer| sub.attach(Arc::clone(writer)));
    loop {
        if let Some(writer) = &direct
            && !writer.idle()
        {
            // What the fan-out handed back unwritten goes before anything else.
            match timeout(config.keepalive, socket.flush()).await {
                Ok(Ok(())) => {}
                Ok(Err(_)) => return,
                Err(_) => return close_slow_consumer(&mut socket).await,
            }
        }
        let outgoing = if let Some(message) = outbox.pop_front() {
            message
        } else {
            let parked = sub.park();
            tokio::select! {
                next = next_or_handed_back(&mut sub, parked) => match next {
                    // The broadcast's fan-out sent the frames meanwhile.
                    None => continue,
                    // Sent here (not below) so that a frame's bytes go to the
                    // socket's own frame path.
                    Some(Next::Frame(f)) => {
                        let encoding = sub.encoding();
                        let send = async {
                            if let Some((seq, doc)) = f.layout
                                && let Err(e) = socket.send(layout_message(seq, &doc)).await
                            {
                                return Err(e);
                            }
                            if let Some(key) = f.prelude
                                && let Err(e) = socket.send_frame(encoding, key).await
                            {
                                return Err(e);
                            }
                            socket.send_frame(encoding, f.bytes).await
                        };
                        match timeout(config.keepalive, send).await {
                            Ok(Ok(())) => continue,
                            Ok(Err(_)) => return,
                            Err(_) => return close_slow_consumer(&mut socket).await,
                        }
                    }
                    Some(Next::End(reason)) => {
                        let _ = timeout(config.keepalive, socket.send(Message::Close(Some(close_frame(reason))))).await;
                        return;
                    }
                },
                incoming = poll_fn(|cx| reads.poll_next(&mut socket, cx)) => match incoming {
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
                    Some(Ok(Message::Text(text))) => match controls.receive(&text, &mut sub).await {
                        Some(error) => error,
                        None => continue,
                    },
                },
                refused = not_stored(&mut controls.storing) => refusal(&refused),
                done = lookup_done(&mut controls.lookup) => {
                    outbox.extend(controls.looked_up(done, &mut sub).await);
                    continue;
                }
                _ = ping.tick() => {
                    if awaiting_pong {
                        let frame = CloseFrame { code: close::POLICY, reason: Utf8Bytes::from_static("keepalive timeout") };
                        let _ = timeout(config.keepalive, socket.send(Message::Close(Some(frame)))).await;
                        return;
                    }
                    awaiting_pong = true;
                    Message::Ping(bytes::Bytes::new())
                }
            }
        };
        match timeout(config.keepalive, socket.send(outgoing)).await {
            Ok(Ok(())) => {}
            Ok(Err(_)) => return,
            Err(_) => return close_slow_consumer(&mut socket).await,
        }
    }
}

/// The stream's next frame or end; while its lane is `parked`, `None` once
/// its broadcast's fan-out hands it back (`lane`). Cancel-safe.
async fn next_or_handed_back(sub: &mut Subscription, parked: bool) -> Option<Next> {
    if parked {
        sub.unparked().await;
        return None;
    }
    Some(sub.next().await)
}

/// Reads the socket only when it has woken the task (or gave a message
/// the last time, since more may be buffered). Polled beside the frames,
/// the socket would otherwise be read once per frame sent, each attempt
/// going through tungstenite, hyper's upgraded connection and the
/// connection's wrappers to find nothing: a tenth of a broadcast viewer's
/// cost per frame (issue 19).
struct ReadGate {
    wake: Arc<ReadWake>,
    /// Wakes `wake`: the waker the socket's read side is polled with.
    waker: Waker,
}

struct ReadWake {
    woken: AtomicBool,
    task: AtomicWaker,
}

impl Wake for ReadWake {
    fn wake(self: Arc<Self>) {
        self.wake_by_ref();
    }

    fn wake_by_ref(self: &Arc<Self>) {
        self.woken.store(true, Ordering::Release);
        self.task.wake();
    }
}

impl ReadGate {
    fn new() -> Self {
        let wake = Arc::new(ReadWake { woken: AtomicBool::new(true), task: AtomicWaker::new() });
        ReadGate { waker: Waker::from(Arc::clone(&wake)), wake }
    }

    fn poll_next<S: Stream + Unpin>(&mut self, socket: &mut S, cx: &mut Context<'_>) -> Poll<Option<S::Item>> {
        // Registered before the flag is taken: a wake-up in between polls again.
        self.wake.task.register(cx.waker());
        if !self.wake.woken.swap(false, Ordering::AcqRel) {
            return Poll::Pending;
        }
        let item = socket.poll_next_unpin(&mut Context::from_waker(&self.waker));
        if item.is_ready() {
            self.wake.woken.store(true, Ordering::Release);
        }
        item
    }
}

/// A JSON frame as a text message (the default `send_frame`; the server's
/// socket writes the bytes itself and needs no check).
fn text(bytes: bytes::Bytes) -> Option<Utf8Bytes> {
    Utf8Bytes::try_from(bytes).ok()
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
