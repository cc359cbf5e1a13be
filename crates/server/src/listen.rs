//! The accept loop: hyper driven directly, so that every connection gets a
//! header-read timeout (a client that opens a connection and trickles its
//! request head is cut off instead of holding a task forever, the
//! "slowloris" attack), which `axum::serve` does not expose, and the
//! connection bounds of `connections`: at most `max_connections` open (more
//! are closed at accept), each closed after `idle_timeout` with nothing in
//! flight, HTTP/2 (h2c) advertising `max_concurrent_streams`. Otherwise it
//! does what `axum::serve` does: HTTP/1.1 with upgrades (WebSockets), and on
//! shutdown every connection finishes its in-flight request and closes.

use std::future::Future;
use std::time::Duration;

use axum::Router;
use axum::body::Body;
use axum::extract::{ConnectInfo, Request};
use hyper::body::Incoming;
use hyper_util::rt::{TokioExecutor, TokioIo, TokioTimer};
use hyper_util::server::conn::auto;
use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio::task::JoinSet;
use tokio_util::either::Either;
use tower::ServiceExt;

use super::connections::{ConnGate, Held, Tracked};
use super::tls;

/// The accept queue asked of the kernel (which caps it at `somaxconn`):
/// tokio's default of 1024 overflowed when a thousand clients connected at
/// once, and a client whose SYN is dropped waits a whole second to retry.
const ACCEPT_BACKLOG: u32 = 4096;

/// A listening socket on `addr` with [`ACCEPT_BACKLOG`] (address reuse as
/// `TcpListener::bind` sets it, so a restart can bind at once).
///
/// # Errors
/// The address cannot be bound.
pub fn bind(addr: std::net::SocketAddr) -> std::io::Result<TcpListener> {
    let socket = if addr.is_ipv4() { tokio::net::TcpSocket::new_v4()? } else { tokio::net::TcpSocket::new_v6()? };
    socket.set_reuseaddr(true)?;
    socket.bind(addr)?;
    socket.listen(ACCEPT_BACKLOG)
}

/// How each connection is bounded.
#[derive(Debug, Clone)]
pub struct Listening {
    pub header_read_timeout: Duration,
    pub idle_timeout: Duration,
    /// How long a write may make no progress before the connection is closed.
    pub write_stall_timeout: Duration,
    pub max_concurrent_streams: u32,
    pub connections: ConnGate,
    /// The kernel send buffer of an upgraded (WebSocket) connection.
    pub stream_buffer_bytes: usize,
}

/// Serves `router` on `listener` until `shutdown` resolves, then stops
/// accepting and resolves once every connection has closed (the caller bounds
/// that wait with the drain timeout). With `tls`, each connection first
/// completes a TLS handshake within `header_read_timeout`.
pub async fn serve(
    listener: TcpListener,
    router: Router,
    limits: Listening,
    tls: Option<tls::Acceptor>,
    shutdown: impl Future<Output = ()>,
) {
    let header_read_timeout = limits.header_read_timeout;
    let (closing_tx, closing_rx) = watch::channel(false);
    let mut connections = JoinSet::new();
    let mut shutdown = std::pin::pin!(shutdown);
    loop {
        let (stream, peer) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(conn) => conn,
                Err(e) => {
                    // Out of file descriptors and the like: back off instead of spinning.
                    tracing::warn!(error = %e, "accept failed");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        while connections.try_join_next().is_some() {}
        let Some(permit) = limits.connections.admit() else { continue };
        let _ = stream.set_nodelay(true);
        let stream = Tracked::new(stream, Some(peer), permit, limits.idle_timeout)
            .with_write_stall(limits.write_stall_timeout)
            .with_stream_buffer(limits.stream_buffer_bytes, true);
        let activity = std::sync::Arc::clone(stream.activity());
        // The peer address, as `axum::serve` provides it (`ConnectInfo`), for
        // the per-client caps; each request counted on its connection from
        // its head until its response body ends (an upgrade: for good).
        let router = router.clone();
        let service = hyper::service::service_fn(move |r: Request<Incoming>| {
            let active = activity.enter();
            let mut r = r.map(Body::new);
            r.extensions_mut().insert(ConnectInfo(peer));
            let (router, activity) = (router.clone(), std::sync::Arc::clone(&activity));
            async move {
                let response = router.oneshot(r).await?;
                if response.status() == axum::http::StatusCode::SWITCHING_PROTOCOLS {
                    activity.upgraded();
                }
                Ok::<_, std::convert::Infallible>(response.map(|body| Body::new(Held::new(body, Some(active)))))
            }
        });
        let mut closing = closing_rx.clone();
        let max_streams = limits.max_concurrent_streams;
        let tls = tls.clone();
        connections.spawn(async move {
            let stream = match tls {
                None => Either::Left(stream),
                Some(acceptor) => match tokio::time::timeout(header_read_timeout, acceptor.accept(stream)).await {
                    Ok(Ok(stream)) => Either::Right(stream),
                    Ok(Err(e)) => return tracing::debug!(error = %e, "TLS handshake failed"),
                    Err(_) => return tracing::debug!("TLS handshake timed out"),
                },
            };
            let mut builder = auto::Builder::new(TokioExecutor::new());
            builder.http1().timer(TokioTimer::new()).header_read_timeout(header_read_timeout);
            builder.http2().timer(TokioTimer::new()).max_concurrent_streams(max_streams);
            let mut conn = std::pin::pin!(builder.serve_connection_with_upgrades(TokioIo::new(stream), service));
            tokio::select! {
                result = conn.as_mut() => {
                    if let Err(e) = result {
                        tracing::debug!(error = %e, "connection ended with an error");
                    }
                    return;
                }
                _ = closing.wait_for(|closing| *closing) => conn.as_mut().graceful_shutdown(),
            }
            if let Err(e) = conn.await {
                tracing::debug!(error = %e, "connection ended with an error while draining");
            }
        });
    }
    drop(listener);
    let _ = closing_tx.send(true);
    while connections.join_next().await.is_some() {}
}
