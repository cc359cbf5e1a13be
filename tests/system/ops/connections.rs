//! Slow and oversized clients: slowloris heads and bodies, idle keep-alive,
//! 413 before the body is read, WebSocket inbound limits.

use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use tokio::io::AsyncWriteExt;
use tokio_tungstenite::tungstenite::Message;

use super::{WAVE, raw_http, read_to_close, start};

/// 40 connections trickling heads and 40 trickling bodies (one byte every
/// 300 ms), plus an idle keep-alive connection, are all closed within the
/// timeouts (5 s here, so well within 10 s), the slow bodies with a 408
/// problem, while a normal client meanwhile sees no error at all.
#[tokio::test(flavor = "multi_thread")]
async fn slow_heads_slow_bodies_and_idle_connections_are_closed_while_others_are_served() {
    let dir = tempfile::tempdir().unwrap();
    let server =
        start(&dir.path().join("data"), &["--header-read-timeout-secs", "5", "--body-read-timeout-secs", "5"]).await;
    let http = crate::common::http_client();
    let id = server.create(&http, WAVE).await;
    let addr = server.http;
    let started = Instant::now();
    let mut trickles = Vec::new();
    for i in 0..80 {
        trickles.push(tokio::spawn(async move {
            let (head, trickle): (String, &[u8]) = if i % 2 == 0 {
                ("GET /healthz HTTP/1.1\r\nHost: x\r\n".into(), b"X-Slow: aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa")
            } else {
                let head = "POST /v1/clips HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 4000\r\n\r\n";
                (head.into(), &[b' '; 64])
            };
            let mut s = raw_http(addr, &head).await;
            let opened = Instant::now();
            let mut got = Vec::new();
            for b in trickle {
                // The time is the behaviour here: a slowloris, one byte every 300 ms.
                tokio::time::sleep(Duration::from_millis(300)).await;
                if s.write_all(&[*b]).await.is_err() {
                    break;
                }
                let (more, closed) = read_to_close(&mut s, Duration::from_millis(1)).await;
                got.extend(more);
                if closed {
                    return (i, got, opened.elapsed());
                }
            }
            let (more, _) = read_to_close(&mut s, Duration::from_secs(15)).await;
            got.extend(more);
            (i, got, opened.elapsed())
        }));
    }
    // An idle keep-alive connection: one request, then silence.
    let idle = tokio::spawn(async move {
        let mut s = raw_http(addr, "GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n").await;
        let opened = Instant::now();
        let (got, closed) = read_to_close(&mut s, Duration::from_secs(15)).await;
        (got, closed, opened.elapsed())
    });
    // The normal client, meanwhile.
    let mut served = 0;
    while started.elapsed() < Duration::from_secs(6) {
        let r = http.get(server.url(&format!("/v1/clips/{id}/pose?t=1"))).send().await.expect("a normal request");
        assert_eq!(r.status(), 200);
        served += 1;
        // Pacing the normal client: not a wait on anything.
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let mut slowest = Duration::ZERO;
    for t in trickles {
        let (i, got, took) = t.await.unwrap();
        let text = String::from_utf8_lossy(&got);
        assert!(took < Duration::from_secs(10), "connection {i} was open {took:?}");
        assert!(took >= Duration::from_millis(4500), "connection {i} closed too early ({took:?}): {text}");
        if i % 2 == 1 {
            assert!(text.starts_with("HTTP/1.1 408"), "a slow body gets 408, got: {text}");
            assert!(text.contains("application/problem+json") && text.contains("body_timeout"), "{text}");
        }
        slowest = slowest.max(took);
    }
    let (got, closed, took) = idle.await.unwrap();
    assert!(String::from_utf8_lossy(&got).starts_with("HTTP/1.1 200"));
    assert!(closed && took < Duration::from_secs(10), "idle keep-alive open {took:?}");
    println!(
        "slowloris: 80 slow connections closed after at most {slowest:?}; idle after {took:?}; {served} normal requests, 0 errors"
    );
    let r = http.get(server.url("/healthz")).send().await.unwrap();
    assert_eq!(r.status(), 200);
}

/// A declared body over the limit is refused before it is sent; a chunked
/// one is cut off at the limit (the client cannot finish sending it).
#[tokio::test(flavor = "multi_thread")]
async fn oversized_bodies_get_413_before_they_are_read() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("data"), &["--max-body-bytes", "65536"]).await;
    // Declared: the head alone gets the answer.
    let head =
        "POST /v1/clips HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 1000000000\r\n\r\n";
    let mut s = raw_http(server.http, head).await;
    let (got, closed) = read_to_close(&mut s, Duration::from_secs(5)).await;
    let text = String::from_utf8_lossy(&got);
    assert!(text.starts_with("HTTP/1.1 413"), "{text}");
    assert!(text.contains("body_too_large") && closed, "{text}");
    // Chunked: 8 KiB chunks, up to 10 MiB; the server answers at 64 KiB.
    let head =
        "POST /v1/clips HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n";
    let mut s = raw_http(server.http, head).await;
    let chunk = format!("2000\r\n{}\r\n", " ".repeat(8192));
    let mut sent = 0usize;
    while sent < 10 << 20 {
        if s.write_all(chunk.as_bytes()).await.is_err() {
            break;
        }
        sent += 8192;
        let (got, _) = read_to_close(&mut s, Duration::from_millis(2)).await;
        if !got.is_empty() {
            let text = String::from_utf8_lossy(&got);
            assert!(text.starts_with("HTTP/1.1 413") && text.contains("body_too_large"), "{text}");
            break;
        }
    }
    assert!(sent < 1 << 20, "the server read {sent} bytes of a body over a 64 KiB limit");
    let r = reqwest::get(server.url("/healthz")).await.unwrap();
    assert_eq!(r.status(), 200);
}

/// A control message over the inbound limit closes that stream with 1009;
/// the server and other streams carry on.
#[tokio::test(flavor = "multi_thread")]
async fn an_oversized_websocket_message_is_closed_with_1009() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("data"), &["--ws-max-message-bytes", "1024"]).await;
    let http = crate::common::http_client();
    let id = server.create(&http, WAVE).await;
    let url = format!("ws://{}/v1/clips/{id}/stream?fps=10", server.http);
    let (mut other, _) = tokio_tungstenite::connect_async(&url).await.unwrap();
    let (mut ws, _) = tokio_tungstenite::connect_async(&url).await.unwrap();
    // Small is fine (answered as a bad control, the stream goes on).
    ws.send(Message::Text(format!("{{\"op\":\"{}\"}}", "x".repeat(900)).into())).await.unwrap();
    ws.send(Message::Text("x".repeat(4096).into())).await.unwrap();
    let mut saw_error_reply = false;
    let code = tokio::time::timeout(Duration::from_secs(5), async {
        while let Some(msg) = ws.next().await {
            match msg {
                Ok(Message::Close(Some(frame))) => return Some(u16::from(frame.code)),
                Ok(Message::Text(t)) if t.contains("bad_control") => saw_error_reply = true,
                Ok(_) => {}
                Err(_) => return None,
            }
        }
        None
    })
    .await
    .expect("a close within 5 s");
    assert_eq!(code, Some(1009));
    assert!(saw_error_reply, "the small bad control was answered");
    // The other viewer still gets frames.
    let mut frames = 0;
    while frames < 3 {
        let msg = tokio::time::timeout(Duration::from_secs(2), other.next()).await.unwrap().unwrap().unwrap();
        frames += usize::from(msg.is_text());
    }
    assert_eq!(http.get(server.url("/healthz")).send().await.unwrap().status(), 200);
}
