//! The accept loop: hyper driven directly, so that every connection gets a
//! header-read timeout (a client that opens a connection and trickles its
//! request head is cut off instead of holding a task forever, the
//! "slowloris" attack), which `axum::serve` does not expose. Otherwise it
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
use hyper_util::service::TowerToHyperService;
use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio::task::JoinSet;
use tokio_util::either::Either;
use tower::ServiceExt;

use super::tls;

/// Serves `router` on `listener` until `shutdown` resolves, then stops
/// accepting and resolves once every connection has closed (the caller bounds
/// that wait with the drain timeout). With `tls`, each connection first
/// completes a TLS handshake within `header_read_timeout`.
pub async fn serve(
    listener: TcpListener,
    router: Router,
    header_read_timeout: Duration,
    tls: Option<tls::Acceptor>,
    shutdown: impl Future<Output = ()>,
) {
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
        let _ = stream.set_nodelay(true);
        // The peer address, as `axum::serve` provides it (`ConnectInfo`), for
        // the per-client stream caps.
        let service = TowerToHyperService::new(router.clone().map_request(move |r: Request<Incoming>| {
            let mut r = r.map(Body::new);
            r.extensions_mut().insert(ConnectInfo(peer));
            r
        }));
        let mut closing = closing_rx.clone();
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
