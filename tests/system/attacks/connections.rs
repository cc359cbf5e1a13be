//! Connections that ask for nothing: 128 body-less POSTs on one HTTP/2
//! connection once got 238 of 240 normal requests shed with 503; gRPC calls
//! whose message never came (and a `Play` that never sent `open`) shed every
//! other gRPC call for as long as they waited; 1,000 idle HTTP/2 connections
//! on the REST port were never closed. Now a request is admitted once its
//! body (or first message) has arrived, a missing message times out, and an
//! idle connection is closed on both ports.

use std::net::SocketAddr;
use std::time::Duration;

use bytes::Bytes;
use formats::wire::proto::pb;
use formats::wire::proto::pb::animation_client::AnimationClient;
use futures_util::StreamExt;

use super::{grpc_code, target};
use crate::common::WAVE;

/// An HTTP/2 connection (prior knowledge) driven by hand.
async fn h2_connection(addr: SocketAddr) -> h2::client::SendRequest<Bytes> {
    let tcp = tokio::net::TcpStream::connect(addr).await.unwrap();
    let (send, connection) = h2::client::handshake(tcp).await.unwrap();
    tokio::spawn(async move {
        let _ = connection.await;
    });
    send.ready().await.unwrap()
}

/// Starts a request whose body never comes; keeps its send half open.
async fn silent(
    send: &mut h2::client::SendRequest<Bytes>,
    request: axum::http::Request<()>,
) -> (h2::client::ResponseFuture, h2::SendStream<Bytes>) {
    *send = send.clone().ready().await.unwrap();
    send.send_request(request, false).unwrap()
}

#[tokio::test(flavor = "multi_thread")]
async fn bodyless_posts_on_one_http2_connection_shed_nobody() {
    let mut target = target(&[]).await;
    let http = crate::common::http_client();
    let id = target.server.create(&http, WAVE).await;
    let probes = target.probes().await;
    let mut attacker = h2_connection(target.server.http).await;
    let mut held = Vec::new();
    for _ in 0..128 {
        let request = axum::http::Request::post(target.server.url("/v1/clips"))
            .header("content-type", "application/json")
            .header("content-length", "100")
            .body(())
            .unwrap();
        held.push(silent(&mut attacker, request).await);
    }
    // The held ones are in, awaiting their bodies, before the probes.
    target.server.until_metric(&http, "inbetween_bodies_awaited", 128.0).await;
    let url = target.server.url(&format!("/v1/clips/{id}/pose?t=1"));
    // 240 normal requests, 16 at a time: within this caller's own in-flight
    // limit (32), so any refusal is the held requests' doing.
    let answers: Vec<_> =
        futures_util::stream::iter((0..240).map(|_| http.get(&url).send())).buffer_unordered(16).collect().await;
    let statuses: Vec<u16> = answers.into_iter().map(|r| r.unwrap().status().as_u16()).collect();
    let report = probes.finish();
    assert!(statuses.iter().all(|s| *s == 200), "normal requests refused: {:?}", shed(&statuses));
    drop(held);
    target.assert_survived("128 body-less POSTs on one HTTP/2 connection", &report);
}

fn shed(statuses: &[u16]) -> Vec<(u16, usize)> {
    let mut counts = std::collections::BTreeMap::new();
    for s in statuses.iter().filter(|s| **s != 200) {
        *counts.entry(*s).or_insert(0) += 1;
    }
    counts.into_iter().collect()
}

#[tokio::test(flavor = "multi_thread")]
async fn grpc_calls_that_never_send_their_message_time_out_and_shed_nobody() {
    let mut target = target(&["--request-message-timeout-secs", "2"]).await;
    let http = crate::common::http_client();
    let id = target.server.create(&http, WAVE).await;
    let probes = target.probes().await;
    let mut attacker = h2_connection(target.server.grpc).await;
    let mut held = Vec::new();
    for _ in 0..128 {
        let request = axum::http::Request::post(format!("{}/inbetween.v1.Animation/Sample", target.server.grpc_url()))
            .header("content-type", "application/grpc")
            .header("te", "trailers")
            .body(())
            .unwrap();
        held.push(silent(&mut attacker, request).await);
    }
    // A Play that never sends `open`.
    let mut player = AnimationClient::connect(target.server.grpc_url()).await.unwrap();
    let play = tokio::spawn(async move { player.play(futures_util::stream::pending::<pb::PlaybackControl>()).await });
    // The held ones and the Play are in, awaiting their first messages, before the probes.
    target.server.until_metric(&http, "inbetween_bodies_awaited", 129.0).await;
    // 240 honest calls, 16 at a time: within this caller's own in-flight
    // limit (32), so any refusal is the held calls' doing.
    let client = AnimationClient::connect(target.server.grpc_url()).await.unwrap();
    let calls = (0..240).map(|_| {
        let mut client = client.clone();
        let request = pb::SampleRequest { clip_id: id.clone(), time: 1.0, ..Default::default() };
        async move { client.sample(request).await.map(|_| ()).map_err(|s| format!("{:?}: {}", s.code(), s.message())) }
    });
    let results: Vec<_> = futures_util::stream::iter(calls).buffer_unordered(16).collect().await;
    let refused: Vec<_> = results.iter().filter_map(|r| r.as_ref().err()).collect();
    assert!(refused.is_empty(), "{} of 240 calls refused: {:?}", refused.len(), &refused[..refused.len().min(5)]);

    // The silent calls end with the timeout, as REST's 408 does.
    for (response, _body) in held {
        let answer = tokio::time::timeout(Duration::from_secs(10), response).await.expect("the silent call ends");
        let head = answer.expect("a trailers-only answer");
        assert_eq!(head.headers()["grpc-status"], "4", "DEADLINE_EXCEEDED: {:?}", head.headers());
        assert_eq!(head.headers()["x-error-code"], "body_timeout", "{:?}", head.headers());
    }
    let status = tokio::time::timeout(Duration::from_secs(10), play).await.expect("Play ends").unwrap().unwrap_err();
    assert_eq!(status.code(), tonic::Code::DeadlineExceeded, "{status:?}");
    assert_eq!(grpc_code(&status), "body_timeout", "{status:?}");
    let report = probes.finish();
    target.assert_survived("128 silent gRPC calls and a Play without open", &report);
}

#[tokio::test(flavor = "multi_thread")]
async fn idle_http2_connections_are_closed_on_both_ports() {
    let mut target = target(&["--idle-timeout-secs", "2"]).await;
    let probes = target.probes().await;
    let (rest, grpc) = (target.server.http, target.server.grpc);
    let open = |addr: SocketAddr| async move {
        let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
        tokio::io::AsyncWriteExt::write_all(&mut s, b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n\0\0\0\x04\0\0\0\0\0")
            .await
            .unwrap();
        s
    };
    let mut idle = Vec::new();
    for i in 0..1000 {
        idle.push(open(if i % 4 == 3 { grpc } else { rest }).await);
    }
    let closed =
        futures_util::future::join_all(idle.iter_mut().map(|s| crate::ops::read_to_close(s, Duration::from_secs(15))))
            .await;
    let report = probes.finish();
    let still_open = closed.iter().filter(|(_, closed)| !closed).count();
    assert_eq!(still_open, 0, "idle HTTP/2 connections still open after the idle timeout");
    target.assert_survived("1,000 idle HTTP/2 connections", &report);
}
