//! What broadcasts and their controllers may spend (docs/broadcasts.md, "Work"
//! and "Control"), with real clients: controls from a socket and from gRPC
//! `Play` draw on the caller's write budget (the socket is told 429
//! `rate_limited` and stays open); a broadcast's price is charged to its
//! creator until it ends (429 `caller_work_limit`, 503 `overloaded`); a
//! broadcast whose ticks overrun their price ends with `too_much_work`
//! (WebSocket close 1008, gRPC `RESOURCE_EXHAUSTED`) and is deleted.

use std::time::Duration;

use formats::wire::proto::pb;
use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::websocket::close_frame;
use super::{TestApp, line_clip, within};
use crate::common::app::Ws;
use crate::common::eventually;
use crate::security::{ADMIN, WRITER, scoped_tokens};

const FPS: u64 = 20;

async fn create(app: &TestApp, clip: &str, token: Option<&str>) -> (u16, Value, Option<String>) {
    let body = json!({"motion": {"layers": [{"clip": clip}]}, "fps": FPS});
    let mut req = app.http.post(app.url("/v1/broadcasts")).json(&body);
    if let Some(t) = token {
        req = req.bearer_auth(t);
    }
    let resp = req.send().await.unwrap();
    let status = resp.status().as_u16();
    let retry_after = resp.headers().get("retry-after").map(|v| v.to_str().unwrap().to_owned());
    (status, resp.json().await.unwrap(), retry_after)
}

/// Reads `ws` until `n` frames have come; returns the `{"error"}` problems met meanwhile.
async fn frames_and_errors(ws: &mut Ws, n: usize) -> Vec<Value> {
    let (mut frames, mut errors) = (0, Vec::new());
    while frames < n {
        match within(5, "a message", ws.next()).await.expect("the socket stays open").unwrap() {
            Message::Text(t) => {
                let v: Value = serde_json::from_str(&t).unwrap();
                match v.get("error") {
                    Some(problem) => errors.push(problem.clone()),
                    None => frames += 1,
                }
            }
            Message::Close(f) => panic!("closed: {f:?}"),
            _ => {}
        }
    }
    errors
}

#[tokio::test]
async fn socket_and_play_controls_draw_on_the_write_budget_and_the_socket_stays_open() {
    let app = TestApp::builder()
        .configure(|c| {
            c.limits.write_rate = 1;
            c.limits.write_burst = 4;
        })
        .start()
        .await;
    let clip = app.create_id(&line_clip(1), None).await; // one write
    let (status, b, _) = create(&app, &clip, None).await; // two
    assert_eq!(status, 201, "{b}");
    let id = b["id"].as_str().unwrap();
    let mut ws = app.ws(&format!("/v1/broadcasts/{id}/stream")).await;
    for k in 0..8 {
        let op = if k % 2 == 0 { "pause" } else { "play" };
        ws.send(Message::Text(json!({"op": op}).to_string().into())).await.unwrap();
    }
    // Two writes were left: six controls refused (one more if a token came back meanwhile).
    let errors = frames_and_errors(&mut ws, 10).await;
    assert!((5..=6).contains(&errors.len()), "{errors:?}");
    for problem in &errors {
        assert_eq!((problem["status"].as_u64(), problem["code"].as_str()), (Some(429), Some("rate_limited")));
    }
    // The same budget as REST's: a control posted now is refused too.
    let url = app.url(&format!("/v1/broadcasts/{id}/controls"));
    let resp = app.http.post(&url).json(&json!({"op": "play"})).send().await.unwrap();
    assert_eq!(resp.status(), 429);
    assert!(resp.headers().contains_key("retry-after"));
    // gRPC `Play` bound to the broadcast: its control ends the call with the same code.
    let (tx, rx) = tokio::sync::mpsc::channel(4);
    let bind = pb::playback_control::Op::Broadcast(pb::BindBroadcast { broadcast_id: id.to_owned() });
    tx.send(pb::PlaybackControl { op: Some(bind) }).await.unwrap();
    let mut play = app.grpc().await.play(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    within(5, "a bound frame", play.message()).await.unwrap().expect("a frame");
    // Three controls: a write may have come back meanwhile, not three.
    for _ in 0..3 {
        tx.send(pb::PlaybackControl { op: Some(pb::playback_control::Op::Pause(pb::Pause {})) }).await.unwrap();
    }
    let status = loop {
        match within(5, "the end of the call", play.message()).await {
            Ok(Some(_)) => {}
            Ok(None) => panic!("ended OK"),
            Err(status) => break status,
        }
    };
    assert_eq!(status.code(), tonic::Code::ResourceExhausted, "{status:?}");
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "rate_limited");
    // The socket still gets its frames.
    assert!(frames_and_errors(&mut ws, 3).await.is_empty());
    app.stop().await;
}

#[tokio::test]
async fn a_broadcast_is_charged_to_its_creator_until_it_ends() {
    // Its price, from an unconstrained server.
    let app = TestApp::start().await;
    let clip = app.create_id(&line_clip(1), None).await;
    let (status, b, _) = create(&app, &clip, None).await;
    assert_eq!(status, 201, "{b}");
    let n = b["work_per_sec"].as_u64().unwrap();
    // Its pose (one joint), a tick and its frame's encoding, 20 times a second.
    assert!(n >= 20 * 501, "{b}");
    app.stop().await;

    // A node of 4 prices a second, one work thread: a caller's share is 2, the broadcasts' thread's 2.
    let app = TestApp::builder()
        .configure(scoped_tokens)
        .configure(move |c| {
            c.limits.node_work_per_sec = 4 * n;
            c.limits.work_threads = 1;
        })
        .start()
        .await;
    let clip = app.create_id(&line_clip(1), Some(ADMIN)).await;
    let (s1, first, _) = create(&app, &clip, Some(WRITER)).await;
    let (s2, _, _) = create(&app, &clip, Some(WRITER)).await;
    assert_eq!((s1, s2), (201, 201));
    let (s3, problem, retry) = create(&app, &clip, Some(WRITER)).await;
    assert_eq!((s3, problem["code"].as_str()), (429, Some("caller_work_limit")), "{problem}");
    assert!(retry.is_some());
    // Another caller: the node has room, the broadcasts' thread has not.
    let (s4, problem, retry) = create(&app, &clip, Some(ADMIN)).await;
    assert_eq!((s4, problem["code"].as_str()), (503, Some("overloaded")), "{problem}");
    assert!(retry.is_some());
    // Deleted, its charge is given back at once.
    let url = app.url(&format!("/v1/broadcasts/{}", first["id"].as_str().unwrap()));
    assert_eq!(app.http.delete(&url).bearer_auth(WRITER).send().await.unwrap().status(), 204);
    let (s5, b, _) = create(&app, &clip, Some(WRITER)).await;
    assert_eq!(s5, 201, "{b}");
    app.stop().await;
}

#[tokio::test]
async fn the_broadcasts_thread_holds_the_configured_share_of_a_core() {
    let app = TestApp::start().await;
    let clip = app.create_id(&line_clip(1), None).await;
    let (_, b, _) = create(&app, &clip, None).await;
    let n = b["work_per_sec"].as_u64().unwrap();
    app.stop().await;
    // 8 prices a second on one thread, a quarter of it for broadcasts: room for two, whoever asks.
    let app = TestApp::builder()
        .configure(scoped_tokens)
        .configure(move |c| {
            c.limits.node_work_per_sec = 8 * n;
            c.limits.work_threads = 1;
            c.limits.broadcast_work_share = 0.25;
        })
        .start()
        .await;
    let clip = app.create_id(&line_clip(1), Some(ADMIN)).await;
    let (s1, _, _) = create(&app, &clip, Some(WRITER)).await;
    let (s2, _, _) = create(&app, &clip, Some(ADMIN)).await;
    let (s3, problem, _) = create(&app, &clip, Some(ADMIN)).await;
    assert_eq!((s1, s2, s3), (201, 201, 503), "{problem}");
    assert_eq!(problem["code"], "overloaded");
    app.stop().await;
}

#[tokio::test]
async fn a_broadcast_whose_ticks_overrun_their_price_ends_with_too_much_work() {
    // A node that says a unit of work takes a femtosecond: every real tick overruns its price.
    let app = TestApp::builder().configure(|c| c.limits.node_work_per_sec = 1 << 60).start().await;
    let clip = app.create_id(&line_clip(1), None).await;
    let (status, b, _) = create(&app, &clip, None).await;
    assert_eq!(status, 201, "{b}");
    let id = b["id"].as_str().unwrap();
    let mut ws = app.ws(&format!("/v1/broadcasts/{id}/stream")).await;
    let watch = pb::WatchRequest { broadcast_id: id.to_owned(), ..Default::default() };
    let mut grpc = app.grpc().await.watch(watch).await.unwrap().into_inner();
    let (code, reason) = close_frame(&mut ws).await;
    assert_eq!(code, 1008);
    assert!(reason.starts_with("too_much_work"), "{reason}");
    let status = loop {
        match within(5, "the end of the watch", grpc.message()).await {
            Ok(Some(_)) => {}
            Ok(None) => panic!("ended OK"),
            Err(status) => break status,
        }
    };
    assert_eq!(status.code(), tonic::Code::ResourceExhausted, "{status:?}");
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "too_much_work");
    let url = app.url(&format!("/v1/broadcasts/{id}"));
    eventually(Duration::from_secs(5), "the broadcast deleted from the store", || async {
        app.http.get(&url).send().await.unwrap().status() == 404
    })
    .await;
    app.stop().await;
}
