//! Viewers that never read: 1,024 WebSocket viewers that opened a stream and
//! read nothing once held 2 GB. Each stream's outbound bytes are now
//! bounded, and a viewer that does not take its frames is closed, while a
//! viewer that reads keeps getting them.

use std::time::{Duration, Instant};

use futures_util::StreamExt;
use tokio::io::AsyncWriteExt;

use super::{target, wide_clip};

const VIEWERS: usize = 1024;

/// Opens a WebSocket to `path` with a 4 KiB receive buffer and never reads.
async fn deaf_viewer(addr: std::net::SocketAddr, path: &str) -> tokio::net::TcpStream {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    let mut s = socket.connect(addr).await.unwrap();
    let head = format!(
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    );
    s.write_all(head.as_bytes()).await.unwrap();
    s
}

#[tokio::test(flavor = "multi_thread")]
async fn viewers_that_never_read_are_closed_in_bounded_memory() {
    let n = VIEWERS.to_string();
    let mut target = target(&["--max-streams", "2048", "--max-streams-per-client", "2048"]).await;
    let http = crate::common::http_client();
    let id = target.server.create(&http, &wide_clip(128, 128)).await;
    let path = format!("/v1/clips/{id}/stream?fps=10&playback=loop");
    let probes = target.probes().await;
    let (mut reader, _) = tokio_tungstenite::connect_async(target.server.ws_url(&path)).await.unwrap();
    let mut deaf = Vec::with_capacity(VIEWERS);
    for _ in 0..VIEWERS {
        deaf.push(deaf_viewer(target.server.http, &path).await);
    }
    // The reading viewer gets every frame meanwhile; the deaf ones are closed.
    let started = Instant::now();
    let mut frames = 0u64;
    let mut active = f64::MAX;
    while started.elapsed() < Duration::from_secs(40) {
        // A 10 fps stream's frame is due every 100 ms; 5 s without one is a stall
        // even on a machine loaded by other builds (the probes judge latency).
        let message = tokio::time::timeout(Duration::from_secs(5), reader.next()).await;
        let message = message.expect("the reading viewer keeps getting frames").unwrap().unwrap();
        if !message.is_text() {
            continue; // the server's keepalive pings
        }
        frames += 1;
        if frames.is_multiple_of(10) {
            active = target.metric("inbetween_streams_active").await.unwrap_or(f64::MAX);
            if active <= 1.0 {
                break;
            }
        }
    }
    let report = probes.finish();
    println!("FIGURE {n} deaf viewers closed after {:.1} s", started.elapsed().as_secs_f64());
    assert!(active <= 1.0, "{active} streams still open: viewers that never read were not closed");
    drop(deaf);
    target.assert_survived(&format!("{n} WebSocket viewers that never read"), &report);
}
