//! The server's end of a stream WebSocket: the upgrade ([`StreamUpgrade`])
//! and a socket ([`StreamSocket`]) whose frames skip tungstenite's write
//! buffer.
//!
//! Through axum's `WebSocket`, tungstenite copies every message into a
//! per-connection write buffer before writing it, and that buffer keeps its
//! capacity (one or two frames) for the connection's life: with thousands of
//! broadcast viewers a few KiB each of the server's memory, and a copy of
//! every frame for every viewer (issue 19). Here a frame is its header (2–10
//! bytes, server frames are not masked) and the playback's shared `Bytes`,
//! written with one `writev`; the payload is never copied. tungstenite still
//! does everything else: it reads (controls, pings, close, the size limits)
//! and writes pongs, pings, closes and error messages. Both writers go
//! through one ordered queue ([`FrameIo`]) that takes whole frames only, so
//! their frames never interleave on the wire. That queue is shared with a
//! broadcast's fan-out ([`FrameWriter`], `stream::fanout`), which writes a
//! parked viewer's frames from its own task the same way, and only when
//! nothing waits before them.
//!
//! The upgrade is axum's `WebSocketUpgrade` (its checks, rejections and
//! subprotocol choice) with hyper's upgrade future kept aside, because axum
//! hands over only its own socket type.

use std::collections::VecDeque;
use std::io::{self, IoSlice};
use std::pin::Pin;
use std::sync::{Arc, Mutex, MutexGuard};
use std::task::{Context, Poll, Waker, ready};

use axum::body::Body;
use axum::extract::FromRequestParts;
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{CloseFrame, Message, Utf8Bytes, WebSocketUpgrade};
use axum::http::request::Parts;
use axum::http::{HeaderValue, StatusCode, Version, header};
use axum::response::Response;
use bytes::{Buf, Bytes};
use futures_util::{Sink, Stream, StreamExt};
use hyper::upgrade::{OnUpgrade, Upgraded};
use hyper_util::rt::TokioIo;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio_tungstenite::WebSocketStream;
use tokio_tungstenite::tungstenite::protocol::{Role, WebSocketConfig, frame::coding::CloseCode};
use tokio_tungstenite::tungstenite::{self as ts, handshake::derive_accept_key};

use crate::stream::ws::FrameSocket;
use crate::stream::{Direct, DirectWrite, Encoding};

/// A WebSocket upgrade of a stream route: axum's checks, and hyper's
/// upgrade to finish it with a [`StreamSocket`].
pub struct StreamUpgrade {
    upgrade: WebSocketUpgrade,
    on_upgrade: OnUpgrade,
    /// `Sec-WebSocket-Key` (HTTP/1.1; HTTP/2 has none).
    key: Option<HeaderValue>,
}

impl<S: Send + Sync> FromRequestParts<S> for StreamUpgrade {
    type Rejection = WebSocketUpgradeRejection;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        // axum's extractor takes hyper's upgrade out of the request; a clone
        // of it (the same upgrade) stays here.
        let on_upgrade = parts.extensions.get::<OnUpgrade>().cloned();
        let key = (parts.version <= Version::HTTP_11).then(|| parts.headers.get(header::SEC_WEBSOCKET_KEY).cloned());
        let upgrade = WebSocketUpgrade::from_request_parts(parts, state).await?;
        let on_upgrade = on_upgrade.expect("axum's extractor found it");
        Ok(StreamUpgrade { upgrade, on_upgrade, key: key.flatten() })
    }
}

impl StreamUpgrade {
    /// Answers the upgrade (101, or 200 on HTTP/2) and runs `callback` with
    /// the socket once the connection is upgraded. The `inbetween`
    /// subprotocol is selected when offered (see `server::auth`).
    pub fn on_upgrade<C, Fut>(self, config: WebSocketConfig, callback: C) -> Response
    where
        C: FnOnce(StreamSocket) -> Fut + Send + 'static,
        Fut: Future<Output = ()> + Send + 'static,
    {
        let upgrade = self.upgrade.protocols([crate::auth::WS_PROTOCOL]);
        let protocol = upgrade.selected_protocol().cloned();
        drop(upgrade);
        let on_upgrade = self.on_upgrade;
        tokio::spawn(async move {
            let Ok(upgraded) = on_upgrade.await else { return };
            let io = FrameIo::new(TokioIo::new(upgraded), config.max_write_buffer_size);
            let ws = WebSocketStream::from_raw_socket(io, Role::Server, Some(config)).await;
            callback(StreamSocket { ws }).await;
        });
        let mut response = match &self.key {
            Some(key) => {
                let mut response = Response::new(Body::empty());
                *response.status_mut() = StatusCode::SWITCHING_PROTOCOLS;
                let headers = response.headers_mut();
                headers.insert(header::CONNECTION, HeaderValue::from_static("upgrade"));
                headers.insert(header::UPGRADE, HeaderValue::from_static("websocket"));
                let accept = derive_accept_key(key.as_bytes());
                headers.insert(header::SEC_WEBSOCKET_ACCEPT, HeaderValue::from_str(&accept).expect("base64"));
                response
            }
            // HTTP/2 (RFC 8441): a 2xx with an empty body.
            None => Response::new(Body::empty()),
        };
        if let Some(protocol) = protocol {
            response.headers_mut().insert(header::SEC_WEBSOCKET_PROTOCOL, protocol);
        }
        response
    }
}

/// A stream's WebSocket: axum's messages in and out through tungstenite,
/// frames through [`FrameIo`].
pub struct StreamSocket {
    ws: WebSocketStream<FrameIo<TokioIo<Upgraded>>>,
}

impl FrameSocket for StreamSocket {
    async fn send_frame(&mut self, encoding: Encoding, bytes: Bytes) -> Result<(), ts::Error> {
        self.ws.get_ref().frames().push_frame(opcode(encoding), bytes);
        // Written out and flushed (TLS keeps records until flushed), as a
        // message sent through tungstenite is.
        std::future::poll_fn(|cx| Pin::new(self.ws.get_mut()).poll_flush(cx)).await.map_err(ts::Error::Io)
    }

    fn direct(&self) -> Option<Arc<dyn DirectWrite>> {
        Some(Arc::new(FrameWriter(Arc::clone(&self.ws.get_ref().shared))))
    }
}

/// The opcode of a frame of `encoding`: JSON text, else binary.
fn opcode(encoding: Encoding) -> u8 {
    match encoding {
        Encoding::Json => OP_TEXT,
        Encoding::Protobuf | Encoding::Compact => OP_BINARY,
    }
}

impl Stream for StreamSocket {
    type Item = Result<Message, ts::Error>;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Self::Item>> {
        loop {
            match ready!(self.ws.poll_next_unpin(cx)) {
                Some(Ok(message)) => {
                    if let Some(message) = from_tungstenite(message) {
                        return Poll::Ready(Some(Ok(message)));
                    }
                }
                other => return Poll::Ready(other.map(|r| r.map(|_| unreachable!("handled above")))),
            }
        }
    }
}

impl Sink<Message> for StreamSocket {
    type Error = ts::Error;

    fn poll_ready(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Result<(), ts::Error>> {
        Pin::new(&mut self.ws).poll_ready(cx)
    }

    fn start_send(mut self: Pin<&mut Self>, item: Message) -> Result<(), ts::Error> {
        Pin::new(&mut self.ws).start_send(into_tungstenite(item))
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Result<(), ts::Error>> {
        Pin::new(&mut self.ws).poll_flush(cx)
    }

    fn poll_close(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Result<(), ts::Error>> {
        Pin::new(&mut self.ws).poll_close(cx)
    }
}

/// An outgoing message as tungstenite's. Texts are copied: these are the
/// rare messages (errors, `opened`), not frames.
fn into_tungstenite(message: Message) -> ts::Message {
    match message {
        Message::Text(text) => ts::Message::Text(text.as_str().into()),
        Message::Binary(bytes) => ts::Message::Binary(bytes),
        Message::Ping(bytes) => ts::Message::Ping(bytes),
        Message::Pong(bytes) => ts::Message::Pong(bytes),
        Message::Close(frame) => ts::Message::Close(
            frame.map(|f| ts::protocol::CloseFrame { code: CloseCode::from(f.code), reason: f.reason.as_str().into() }),
        ),
    }
}

/// An incoming message as axum's (`None`: a raw frame, which reading never gives).
fn from_tungstenite(message: ts::Message) -> Option<Message> {
    Some(match message {
        ts::Message::Text(text) => Message::Text(Utf8Bytes::from(text.as_str())),
        ts::Message::Binary(bytes) => Message::Binary(bytes),
        ts::Message::Ping(bytes) => Message::Ping(bytes),
        ts::Message::Pong(bytes) => Message::Pong(bytes),
        ts::Message::Close(frame) => Message::Close(
            frame.map(|f| CloseFrame { code: f.code.into(), reason: Utf8Bytes::from(f.reason.as_str()) }),
        ),
        ts::Message::Frame(_) => return None,
    })
}

const OP_TEXT: u8 = 0x1;
const OP_BINARY: u8 = 0x2;

/// Bytes waiting to be written: a frame header (or nothing) and a payload.
struct Chunk {
    head: [u8; 10],
    /// The unwritten part of `head`.
    head_at: u8,
    head_len: u8,
    body: Bytes,
}

impl Chunk {
    /// A whole unmasked frame with FIN set: RFC 6455 §5.2.
    fn frame(opcode: u8, body: Bytes) -> Self {
        let mut head = [0; 10];
        head[0] = 0x80 | opcode;
        let len = body.len();
        let head_len = if len < 126 {
            head[1] = len as u8;
            2
        } else if let Ok(len) = u16::try_from(len) {
            head[1] = 126;
            head[2..4].copy_from_slice(&len.to_be_bytes());
            4
        } else {
            head[1] = 127;
            head[2..10].copy_from_slice(&(len as u64).to_be_bytes());
            10
        };
        Chunk { head, head_at: 0, head_len, body }
    }

    fn bytes(body: Bytes) -> Self {
        Chunk { head: [0; 10], head_at: 0, head_len: 0, body }
    }

    fn head(&self) -> &[u8] {
        &self.head[usize::from(self.head_at)..usize::from(self.head_len)]
    }

    fn len(&self) -> usize {
        self.head().len() + self.body.len()
    }

    /// Takes up to `n` written bytes off the front; returns the rest of `n`.
    fn advance(&mut self, n: usize) -> usize {
        let head = self.head().len().min(n);
        self.head_at += head as u8;
        let body = self.body.len().min(n - head);
        self.body.advance(body);
        n - head - body
    }
}

/// Most slices handed to one `writev`.
const MAX_SLICES: usize = 16;

/// The upgraded connection with an ordered queue of whole frames in front
/// of its write side. [`Frames::push_frame`] queues a stream frame;
/// tungstenite's writes (`AsyncWrite`) are taken whole or not at all —
/// written through when nothing is queued, else queued behind the frames
/// (copied: they are small and rare) up to `limit` bytes — so its frames
/// and ours never interleave. Reads pass through. A handle to [`Frames`],
/// which a [`FrameWriter`] shares: each call holds its lock for one write
/// or read, never across an await.
pub struct FrameIo<T> {
    shared: Arc<Mutex<Frames<T>>>,
}

/// The connection and its queue.
pub struct Frames<T> {
    io: T,
    queue: VecDeque<Chunk>,
    /// Bytes in `queue`.
    queued: usize,
    /// Most bytes tungstenite's writes may add to the queue.
    limit: usize,
}

impl<T> FrameIo<T> {
    fn new(io: T, limit: usize) -> Self {
        let frames = Frames { io, queue: VecDeque::new(), queued: 0, limit };
        FrameIo { shared: Arc::new(Mutex::new(frames)) }
    }

    fn frames(&self) -> MutexGuard<'_, Frames<T>> {
        crate::sync::lock(&self.shared)
    }
}

impl<T: AsyncWrite + Unpin> Frames<T> {
    /// Queues a frame of `body`; [`Frames::poll_drain`] writes it.
    fn push_frame(&mut self, opcode: u8, body: Bytes) {
        self.push(Chunk::frame(opcode, body));
    }

    fn push(&mut self, chunk: Chunk) {
        self.queued += chunk.len();
        self.queue.push_back(chunk);
    }

    /// Writes the queue out, as many chunks per `writev` as fit.
    fn poll_drain(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        while !self.queue.is_empty() {
            let mut slices = [IoSlice::new(&[]); MAX_SLICES];
            let mut n = 0;
            for chunk in self.queue.iter().take(MAX_SLICES / 2) {
                for part in [chunk.head(), &chunk.body[..]] {
                    if !part.is_empty() {
                        slices[n] = IoSlice::new(part);
                        n += 1;
                    }
                }
            }
            let written = ready!(Pin::new(&mut self.io).poll_write_vectored(cx, &slices[..n]))?;
            if written == 0 {
                return Poll::Ready(Err(io::ErrorKind::WriteZero.into()));
            }
            self.queued -= written;
            let mut left = written;
            while let Some(front) = self.queue.front_mut() {
                left = front.advance(left);
                if front.len() > 0 {
                    break;
                }
                self.queue.pop_front();
            }
        }
        Poll::Ready(Ok(()))
    }

    fn poll_write(&mut self, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        if let Poll::Ready(Err(e)) = self.poll_drain(cx) {
            return Poll::Ready(Err(e));
        }
        if self.queue.is_empty() {
            let written = match Pin::new(&mut self.io).poll_write(cx, buf) {
                Poll::Ready(Ok(n)) => n,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Pending => 0,
            };
            if written < buf.len() {
                self.push(Chunk::bytes(Bytes::copy_from_slice(&buf[written..])));
            }
            return Poll::Ready(Ok(buf.len()));
        }
        if self.queued + buf.len() > self.limit {
            // The drain above is pending: it wakes the task.
            return Poll::Pending;
        }
        self.push(Chunk::bytes(Bytes::copy_from_slice(buf)));
        Poll::Ready(Ok(buf.len()))
    }

    fn poll_flush(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        ready!(self.poll_drain(cx))?;
        Pin::new(&mut self.io).poll_flush(cx)
    }

    fn poll_shutdown(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        ready!(self.poll_drain(cx))?;
        Pin::new(&mut self.io).poll_shutdown(cx)
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for FrameIo<T> {
    fn poll_read(self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.frames().io).poll_read(cx, buf)
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for FrameIo<T> {
    fn poll_write(self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        self.frames().poll_write(cx, buf)
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        self.frames().poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        self.frames().poll_shutdown(cx)
    }
}

/// A broadcast's fan-out's way into a viewer's socket (`stream::lane`): a
/// whole frame, written now without waiting, only when nothing is queued
/// before it. What the socket does not take at once stays queued for the
/// viewer's task, which the fan-out then wakes; the write side's wake-up is
/// registered by that task's next write (the one here has no task to wake).
pub struct FrameWriter<T>(Arc<Mutex<Frames<T>>>);

impl<T: AsyncWrite + Unpin + Send> DirectWrite for FrameWriter<T> {
    fn try_frame(&self, encoding: Encoding, frame: &mut dyn FnMut() -> Bytes) -> Direct {
        let mut frames = crate::sync::lock(&self.0);
        if !frames.queue.is_empty() {
            return Direct::Busy;
        }
        frames.push_frame(opcode(encoding), frame());
        match frames.poll_drain(&mut Context::from_waker(Waker::noop())) {
            Poll::Ready(Ok(())) => Direct::Written,
            Poll::Ready(Err(_)) => Direct::Failed,
            Poll::Pending => Direct::Partly,
        }
    }

    fn idle(&self) -> bool {
        crate::sync::lock(&self.0).queue.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A writer that takes at most `step` bytes a call, one slice at a time,
    /// and `room` bytes in all before it is pending.
    struct Trickle {
        out: Vec<u8>,
        step: usize,
        room: usize,
        pending: bool,
    }

    impl AsyncWrite for Trickle {
        fn poll_write(self: Pin<&mut Self>, _: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
            let this = self.get_mut();
            if this.pending || this.room == 0 {
                return Poll::Pending;
            }
            let n = buf.len().min(this.step).min(this.room);
            this.room -= n;
            this.out.extend_from_slice(&buf[..n]);
            Poll::Ready(Ok(n))
        }
        fn poll_flush(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<io::Result<()>> {
            Poll::Ready(Ok(()))
        }
        fn poll_shutdown(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<io::Result<()>> {
            Poll::Ready(Ok(()))
        }
    }

    fn cx() -> Context<'static> {
        Context::from_waker(std::task::Waker::noop())
    }

    #[test]
    fn frame_headers_follow_rfc_6455() {
        assert_eq!(Chunk::frame(OP_TEXT, Bytes::from_static(b"hi")).head(), [0x81, 2]);
        let mid = Chunk::frame(OP_BINARY, Bytes::from(vec![0; 2390]));
        assert_eq!(mid.head(), [0x82, 126, 0x09, 0x56]);
        let big = Chunk::frame(OP_BINARY, Bytes::from(vec![0; 70_000]));
        assert_eq!(big.head(), [0x82, 127, 0, 0, 0, 0, 0, 1, 0x11, 0x70]);
        assert_eq!(big.len(), 70_010);
    }

    #[test]
    fn frames_and_tungstenite_writes_leave_whole_and_in_order() {
        let mut io = FrameIo::new(Trickle { out: Vec::new(), step: 3, room: usize::MAX, pending: true }, 64);
        io.frames().push_frame(OP_TEXT, Bytes::from_static(b"frame one"));
        assert!(io.frames().poll_drain(&mut cx()).is_pending());
        // Behind a queued frame, tungstenite's bytes are queued whole.
        assert!(matches!(Pin::new(&mut io).poll_write(&mut cx(), b"PONG"), Poll::Ready(Ok(4))));
        // Over the limit, they wait.
        assert!(Pin::new(&mut io).poll_write(&mut cx(), &[0; 64]).is_pending());
        io.frames().io.pending = false;
        io.frames().push_frame(OP_TEXT, Bytes::from_static(b"two"));
        assert!(matches!(io.frames().poll_drain(&mut cx()), Poll::Ready(Ok(()))));
        assert_eq!(io.frames().queued, 0);
        // Written through when nothing is queued; a partial write queues the rest.
        assert!(matches!(Pin::new(&mut io).poll_write(&mut cx(), b"CLOSE"), Poll::Ready(Ok(5))));
        assert!(matches!(Pin::new(&mut io).poll_flush(&mut cx()), Poll::Ready(Ok(()))));
        let mut want = vec![0x81, 9];
        want.extend_from_slice(b"frame onePONG");
        want.extend_from_slice(&[0x81, 3]);
        want.extend_from_slice(b"twoCLOSE");
        assert_eq!(io.frames().io.out, want);
    }

    #[test]
    fn a_direct_frame_waits_for_nothing_and_is_written_whole_or_left_to_the_task() {
        let io = FrameIo::new(Trickle { out: Vec::new(), step: 100, room: usize::MAX, pending: false }, 64);
        let writer = FrameWriter(Arc::clone(&io.shared));
        let frame = |body: &'static [u8]| move || Bytes::from_static(body);
        assert_eq!(writer.try_frame(Encoding::Json, &mut frame(b"one")), Direct::Written);
        assert!(writer.idle());
        // The socket has room for 4 bytes: a frame of 7 is taken, its rest left queued.
        io.frames().io.room = 4;
        assert_eq!(writer.try_frame(Encoding::Protobuf, &mut frame(b"two..")), Direct::Partly);
        assert!(!writer.idle());
        // Behind it, a frame is not taken at all (nor made).
        let mut never = || -> Bytes { panic!("a frame made for a busy socket") };
        assert_eq!(writer.try_frame(Encoding::Json, &mut never), Direct::Busy);
        io.frames().io.room = usize::MAX;
        assert!(matches!(io.frames().poll_drain(&mut cx()), Poll::Ready(Ok(()))));
        assert!(writer.idle());
        let mut want = vec![0x81, 3];
        want.extend_from_slice(b"one");
        want.extend_from_slice(&[0x82, 5]);
        want.extend_from_slice(b"two..");
        assert_eq!(io.frames().io.out, want);
    }
}
