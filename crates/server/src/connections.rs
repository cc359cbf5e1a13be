//! Connections, bounded on both ports: at most `max_connections` open per
//! port (more are closed at accept and counted), and each one closed once it
//! has had no request or stream open for `idle_timeout` (hyper has no idle
//! timeout for HTTP/2, tonic none at all, and a keepalive PING keeps an idle
//! connection looking busy at the socket).
//!
//! Every accepted socket is wrapped in [`Tracked`], which holds its port's
//! connection permit and its [`Activity`]: the requests (and streams, and
//! response bodies) in flight on it. The REST accept loop counts each request
//! itself; tonic hands the activity to [`GrpcConnLayer`] through its connect
//! info ([`ConnInfo`]). When a connection has been idle for the timeout,
//! its next read reports end of stream and hyper closes it. An upgraded
//! connection (a WebSocket) is never idle: its stream has its own keepalive.
//!
//! A write that makes no progress for `write_stall_timeout` fails, and hyper
//! closes the connection: a peer that stops reading a chunked answer, a
//! `SampleStream` or a stream's frames holds its slots and buffers for that
//! long, not for as long as it keeps the socket open.
//!
//! Stream connections (an upgraded WebSocket; every gRPC connection) get a
//! fixed kernel send buffer of `stream_buffer_bytes` instead of Linux's
//! autotuned one (up to 4 MiB each, charged to the server's memory cgroup):
//! a viewer that stops reading then holds at most that much in the kernel
//! beside its bounded user-space buffer, and when it is given up on, its
//! connection is reset so the kernel frees that at once.
//!
//! A gRPC connection's writes are gathered ([`Tracked::gathering`]): h2
//! sends a DATA frame of 256 bytes or more as its own vectored write, so a
//! connection carrying a hundred streams made a hundred `writev` calls a
//! tick. Told the socket cannot write vectored, h2 copies frames under 1 KiB
//! into its 16 KiB buffer and writes them together; a larger frame's head and
//! payload, which it then writes apart, are gathered here and go out in one
//! write when h2 flushes.

use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::http::{Request, Response};
use bytes::{Buf, BytesMut};
use http_body::{Body, Frame, SizeHint};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpStream;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio::time::{Instant, Sleep};
use tonic::transport::server::{Connected, TcpConnectInfo, TlsConnectInfo};

use crate::sync::lock;

/// The connection cap of one port.
#[derive(Debug, Clone)]
pub struct ConnGate {
    open: Arc<Semaphore>,
    port: &'static str,
}

impl ConnGate {
    /// `port` labels the refusal metric (`http` or `grpc`).
    pub fn new(max_connections: usize, port: &'static str) -> ConnGate {
        ConnGate { open: Arc::new(Semaphore::new(max_connections)), port }
    }

    /// A permit for one more connection, or `None` (counted) at the cap.
    pub fn admit(&self) -> Option<OwnedSemaphorePermit> {
        let permit = Arc::clone(&self.open).try_acquire_owned().ok();
        if permit.is_none() {
            metrics::counter!("inbetween_connections_refused_total", "port" => self.port).increment(1);
        }
        permit
    }
}

/// What is in flight on one connection.
#[derive(Debug)]
pub struct Activity {
    in_flight: AtomicUsize,
    upgraded: AtomicBool,
    idle_since: std::sync::Mutex<Instant>,
}

impl Activity {
    fn new() -> Arc<Activity> {
        Arc::new(Activity {
            in_flight: AtomicUsize::new(0),
            upgraded: AtomicBool::new(false),
            idle_since: std::sync::Mutex::new(Instant::now()),
        })
    }

    /// Counts one request until the returned guard is dropped.
    pub fn enter(self: &Arc<Self>) -> Active {
        self.in_flight.fetch_add(1, Ordering::AcqRel);
        Active(Arc::clone(self))
    }

    /// The connection now carries an upgraded protocol: never idle again.
    pub fn upgraded(&self) {
        self.upgraded.store(true, Ordering::Release);
    }

    /// When the connection will have been idle for `timeout`, if it is idle.
    fn idle_deadline(&self, timeout: Duration) -> Option<Instant> {
        if self.upgraded.load(Ordering::Acquire) || self.in_flight.load(Ordering::Acquire) > 0 {
            return None;
        }
        Some(*lock(&self.idle_since) + timeout)
    }
}

/// One request in flight on a connection (see [`Activity::enter`]).
#[derive(Debug)]
pub struct Active(Arc<Activity>);

impl Drop for Active {
    fn drop(&mut self) {
        *lock(&self.0.idle_since) = Instant::now();
        self.0.in_flight.fetch_sub(1, Ordering::AcqRel);
    }
}

/// An accepted socket with its connection permit and idle timeout.
pub struct Tracked {
    io: TcpStream,
    activity: Arc<Activity>,
    /// `stream_buffer_bytes`, for a connection that carries streams.
    stream_buffer: usize,
    /// Whether the stream bounds are in force (gRPC: from the start; REST: once upgraded).
    bounded: bool,
    peer: Option<SocketAddr>,
    idle_timeout: Duration,
    timer: Pin<Box<Sleep>>,
    expired: bool,
    write_stall_timeout: Duration,
    /// Armed while a write cannot proceed.
    stall: Option<Pin<Box<Sleep>>>,
    /// Writes held until the next flush, when gathering (module doc).
    gathered: Option<BytesMut>,
    _permit: OwnedSemaphorePermit,
}

/// The most a gathering connection holds before it writes: room for h2's
/// whole buffer and a largest (16 KiB) DATA frame's payload.
const GATHER_BYTES: usize = 32 * 1024;

impl Tracked {
    pub fn new(io: TcpStream, peer: Option<SocketAddr>, permit: OwnedSemaphorePermit, idle_timeout: Duration) -> Self {
        let timer = Box::pin(tokio::time::sleep(idle_timeout));
        let activity = Activity::new();
        let (stream_buffer, bounded, expired) = (0, false, false);
        // Until `with_write_stall` says otherwise: as long as the idle timeout.
        let (write_stall_timeout, stall) = (idle_timeout, None);
        Tracked {
            io,
            activity,
            stream_buffer,
            bounded,
            peer,
            idle_timeout,
            timer,
            expired,
            write_stall_timeout,
            stall,
            gathered: None,
            _permit: permit,
        }
    }

    /// Gathers writes until a flush (module doc): for connections whose
    /// writer, h2, flushes after each batch of frames.
    pub fn gathering(mut self) -> Self {
        self.gathered = Some(BytesMut::new());
        self
    }

    /// Writes what was gathered, all of it or `Pending`.
    fn poll_write_gathered(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        while let Some(gathered) = self.gathered.as_mut().filter(|g| !g.is_empty()) {
            let written = Pin::new(&mut self.io).poll_write(cx, gathered);
            let n = std::task::ready!(self.unless_stalled(cx, written))?;
            if n == 0 {
                return Poll::Ready(Err(io::ErrorKind::WriteZero.into()));
            }
            if let Some(gathered) = self.gathered.as_mut() {
                gathered.advance(n);
            }
        }
        Poll::Ready(Ok(()))
    }

    /// Holds `buf` for the next flush, writing what was held first when it
    /// would not fit; `None` when not gathering.
    fn poll_gather(&mut self, cx: &mut Context<'_>, buf: &[u8]) -> Option<Poll<io::Result<usize>>> {
        let held = self.gathered.as_ref()?.len();
        if held + buf.len() > GATHER_BYTES {
            match self.poll_write_gathered(cx) {
                Poll::Ready(Ok(())) => {}
                other => return Some(other.map_ok(|()| 0)),
            }
        }
        let gathered = self.gathered.as_mut()?;
        let taken = buf.len().min(GATHER_BYTES - gathered.len());
        gathered.extend_from_slice(&buf[..taken]);
        Some(Poll::Ready(Ok(taken)))
    }

    /// Fails a write that has made no progress for `timeout`.
    pub fn with_write_stall(mut self, timeout: Duration) -> Self {
        self.write_stall_timeout = timeout;
        self
    }

    /// `written`, unless the write has been stuck for the stall timeout: a
    /// pending write arms the stall timer, progress disarms it, and a write
    /// still pending when it fires fails (hyper then closes the connection).
    fn unless_stalled(&mut self, cx: &mut Context<'_>, written: Poll<io::Result<usize>>) -> Poll<io::Result<usize>> {
        if written.is_ready() {
            self.stall = None;
            return written;
        }
        let timeout = self.write_stall_timeout;
        let timer = self.stall.get_or_insert_with(|| Box::pin(tokio::time::sleep(timeout)));
        if timer.as_mut().poll(cx).is_pending() {
            return Poll::Pending;
        }
        metrics::counter!("inbetween_write_stalls_total").increment(1);
        Poll::Ready(Err(io::Error::new(io::ErrorKind::TimedOut, "the peer stopped reading")))
    }

    /// Bounds the connection as a stream carrier now (`upgraded_only`:
    /// once it is upgraded): see [`Tracked::bound_streams`].
    pub fn with_stream_buffer(mut self, bytes: usize, upgraded_only: bool) -> Self {
        self.stream_buffer = bytes;
        if !upgraded_only {
            self.bound_streams();
        }
        self
    }

    pub fn activity(&self) -> &Arc<Activity> {
        &self.activity
    }

    /// A fixed kernel send buffer of `stream_buffer` bytes (Linux doubles
    /// what it is given), instead of the autotuned one.
    fn bound_streams(&mut self) {
        if !self.bounded && self.stream_buffer > 0 {
            let _ = socket2::SockRef::from(&self.io).set_send_buffer_size((self.stream_buffer / 2).max(4096));
            self.bounded = true;
        }
    }

    /// Applies the stream bounds once the connection has been upgraded.
    fn bound_if_upgraded(&mut self) {
        if !self.bounded && self.activity.upgraded.load(Ordering::Acquire) {
            self.bound_streams();
        }
    }

    /// Whether the connection has been idle for the timeout; otherwise the
    /// timer is armed to wake the reader when it may have been.
    fn idle_expired(&mut self, cx: &mut Context<'_>) -> bool {
        if !self.expired && self.activity.upgraded.load(Ordering::Acquire) {
            // Never idle again, and read once per message: no clock, no timer.
            return false;
        }
        loop {
            if self.expired {
                return true;
            }
            let now = Instant::now();
            match self.activity.idle_deadline(self.idle_timeout) {
                Some(deadline) if deadline <= now => {
                    self.expired = true;
                    metrics::counter!("inbetween_idle_connections_closed_total").increment(1);
                }
                Some(deadline) => self.timer.as_mut().reset(deadline),
                // Busy: look again a timeout from now.
                None => self.timer.as_mut().reset(now + self.idle_timeout),
            }
            if !self.expired && self.timer.as_mut().poll(cx).is_pending() {
                return false;
            }
        }
    }
}

/// A stream connection closed with more than a quarter of its buffer still
/// unsent is a peer that stopped reading: it is reset rather than closed, so
/// the kernel frees its queue at once instead of keeping an orphaned socket
/// probing a closed window for minutes (its memory charged to the server).
impl Drop for Tracked {
    fn drop(&mut self) {
        if self.bounded && unsent_bytes(&self.io) > self.stream_buffer / 4 {
            metrics::counter!("inbetween_abandoned_connections_reset_total").increment(1);
            let _ = socket2::SockRef::from(&self.io).set_linger(Some(Duration::ZERO));
        }
    }
}

/// Bytes the kernel still holds to send on `socket` (`SIOCOUTQ`).
#[cfg(target_os = "linux")]
fn unsent_bytes(socket: &TcpStream) -> usize {
    use std::os::fd::AsRawFd;
    let mut unsent: libc::c_int = 0;
    // SAFETY: SIOCOUTQ writes one c_int through the pointer, which points at
    // a live, aligned c_int; the descriptor is this live socket's.
    let ok = unsafe { libc::ioctl(socket.as_raw_fd(), libc::TIOCOUTQ, &raw mut unsent) } == 0;
    if ok { usize::try_from(unsent).unwrap_or(0) } else { 0 }
}

#[cfg(not(target_os = "linux"))]
fn unsent_bytes(_: &TcpStream) -> usize {
    0
}

impl AsyncRead for Tracked {
    fn poll_read(self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        if this.idle_expired(cx) {
            // End of stream: hyper closes the connection.
            return Poll::Ready(Ok(()));
        }
        Pin::new(&mut this.io).poll_read(cx, buf)
    }
}

impl AsyncWrite for Tracked {
    fn poll_write(self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        this.bound_if_upgraded();
        if let Some(gathered) = this.poll_gather(cx, buf) {
            return gathered;
        }
        let written = Pin::new(&mut this.io).poll_write(cx, buf);
        this.unless_stalled(cx, written)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        this.bound_if_upgraded();
        if this.gathered.is_some() {
            let first = bufs.iter().find(|b| !b.is_empty()).map_or(&[][..], |b| &**b);
            return Pin::new(this).poll_write(cx, first);
        }
        let written = Pin::new(&mut this.io).poll_write_vectored(cx, bufs);
        this.unless_stalled(cx, written)
    }

    fn is_write_vectored(&self) -> bool {
        self.gathered.is_none() && self.io.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        std::task::ready!(this.poll_write_gathered(cx))?;
        Pin::new(&mut this.io).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        std::task::ready!(this.poll_write_gathered(cx))?;
        Pin::new(&mut this.io).poll_shutdown(cx)
    }
}

/// tonic's connect info for a [`Tracked`] socket: the addresses tonic
/// reports (re-inserted as [`TcpConnectInfo`] by [`GrpcConnLayer`], so
/// `Request::remote_addr` keeps working) and the connection's activity.
#[derive(Debug, Clone)]
pub struct ConnInfo {
    tcp: TcpConnectInfo,
    activity: Arc<Activity>,
}

impl Connected for Tracked {
    type ConnectInfo = ConnInfo;

    fn connect_info(&self) -> ConnInfo {
        let mut tcp = self.io.connect_info();
        tcp.remote_addr = tcp.remote_addr.or(self.peer);
        ConnInfo { tcp, activity: Arc::clone(&self.activity) }
    }
}

/// Accepted gRPC sockets: over the cap closed at once, the rest tracked,
/// with Nagle's algorithm off. (tonic sets `TCP_NODELAY` only on listeners
/// it binds itself; without it, frames of the many streams multiplexed on one
/// HTTP/2 connection wait for the previous segment's ACK: measured, 100
/// streams on one connection received their frames 4.7 ms late at the median
/// instead of 0.2 ms.)
pub fn tracked_incoming(
    listener: tokio::net::TcpListener,
    gate: ConnGate,
    (idle_timeout, write_stall_timeout): (Duration, Duration),
    stream_buffer: usize,
) -> impl futures_util::Stream<Item = io::Result<Tracked>> {
    use futures_util::StreamExt;
    tokio_stream::wrappers::TcpListenerStream::new(listener).filter_map(move |accepted| {
        let tracked = match accepted {
            Ok(stream) => gate.admit().map(|permit| {
                let _ = stream.set_nodelay(true);
                let peer = stream.peer_addr().ok();
                Ok(Tracked::new(stream, peer, permit, idle_timeout)
                    .with_write_stall(write_stall_timeout)
                    .with_stream_buffer(stream_buffer, false)
                    .gathering())
            }),
            Err(e) => Some(Err(e)),
        };
        std::future::ready(tracked)
    })
}

/// A response body that keeps its request counted until it ends (streams
/// included).
pub struct Held<B> {
    body: B,
    _active: Option<Active>,
}

impl<B> Held<B> {
    pub fn new(body: B, active: Option<Active>) -> Held<B> {
        Held { body, _active: active }
    }
}

impl<B: Body + Unpin> Body for Held<B> {
    type Data = B::Data;
    type Error = B::Error;

    fn poll_frame(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Result<Frame<B::Data>, B::Error>>> {
        Pin::new(&mut self.get_mut().body).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.body.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.body.size_hint()
    }
}

/// The layer that counts each gRPC call on its connection (module doc).
#[derive(Debug, Clone, Copy)]
pub struct GrpcConnLayer;

impl<S> tower::Layer<S> for GrpcConnLayer {
    type Service = GrpcConn<S>;
    fn layer(&self, inner: S) -> GrpcConn<S> {
        GrpcConn { inner }
    }
}

#[derive(Debug, Clone)]
pub struct GrpcConn<S> {
    inner: S,
}

type BoxFuture<T> = Pin<Box<dyn Future<Output = T> + Send>>;

impl<S, B, RB> tower::Service<Request<B>> for GrpcConn<S>
where
    S: tower::Service<Request<B>, Response = Response<RB>> + Send,
    S::Future: Send + 'static,
    S::Error: Send + 'static,
    RB: Body + Unpin + Send + 'static,
{
    type Response = Response<Held<RB>>;
    type Error = S::Error;
    type Future = BoxFuture<Result<Response<Held<RB>>, S::Error>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), S::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, mut request: Request<B>) -> Self::Future {
        let info = conn_info(request.extensions());
        let active = info.map(|info| {
            request.extensions_mut().insert(info.tcp);
            info.activity.enter()
        });
        let response = self.inner.call(request);
        Box::pin(async move {
            let response = response.await?;
            Ok(response.map(|body| Held::new(body, active)))
        })
    }
}

fn conn_info(extensions: &axum::http::Extensions) -> Option<ConnInfo> {
    extensions
        .get::<ConnInfo>()
        .or_else(|| extensions.get::<TlsConnectInfo<ConnInfo>>().map(TlsConnectInfo::get_ref))
        .cloned()
}

#[cfg(test)]
mod tests {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    use super::*;

    /// A gathering socket and the peer reading it, over loopback.
    async fn gathering_pair() -> (Tracked, TcpStream) {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let peer = TcpStream::connect(listener.local_addr().unwrap()).await.unwrap();
        let (io, _) = listener.accept().await.unwrap();
        let permit = ConnGate::new(1, "grpc").admit().unwrap();
        (Tracked::new(io, None, permit, Duration::from_secs(60)).gathering(), peer)
    }

    /// Whether `peer` has anything to read within 50 ms.
    async fn readable(peer: &mut TcpStream) -> bool {
        let mut byte = [0u8; 1];
        tokio::time::timeout(Duration::from_millis(50), peer.peek(&mut byte)).await.is_ok()
    }

    #[tokio::test]
    async fn gathered_writes_wait_for_the_flush_and_arrive_whole_and_in_order() {
        let (mut tracked, mut peer) = gathering_pair().await;
        assert!(!tracked.is_write_vectored(), "h2 must copy small frames into its buffer");
        let sent: Vec<u8> = (0..3000u32).map(|i| (i % 251) as u8).collect();
        for chunk in sent.chunks(700) {
            tracked.write_all(chunk).await.unwrap();
        }
        assert!(!readable(&mut peer).await, "nothing is written before the flush");
        tracked.flush().await.unwrap();
        let mut got = vec![0u8; sent.len()];
        peer.read_exact(&mut got).await.unwrap();
        assert_eq!(got, sent);
    }

    #[tokio::test]
    async fn more_than_the_gather_bound_is_written_without_a_flush() {
        let (mut tracked, mut peer) = gathering_pair().await;
        let sent: Vec<u8> = (0..GATHER_BYTES as u32 + 5000).map(|i| (i % 253) as u8).collect();
        for chunk in sent.chunks(4096) {
            tracked.write_all(chunk).await.unwrap();
        }
        let mut got = vec![0u8; GATHER_BYTES];
        peer.read_exact(&mut got).await.unwrap();
        assert_eq!(got, sent[..GATHER_BYTES], "the first bound's worth went out when it filled");
        tracked.shutdown().await.unwrap();
        let mut rest = Vec::new();
        peer.read_to_end(&mut rest).await.unwrap();
        assert_eq!(rest, sent[GATHER_BYTES..], "the rest went out at shutdown");
    }
}
