//! A viewer's own stream's controls are writes (docs/api.md, "Streams"):
//! each draws on its caller's write budget, as REST's and a broadcast's
//! controls do. A flood on one socket is refused 429 `rate_limited` (the
//! socket told `{"error": problem}` and left open), `Play` ends with
//! `RESOURCE_EXHAUSTED` `rate_limited`, and another client's stream keeps
//! its frame rate meanwhile.

use std::time::{Duration, Instant};

use formats::wire::proto::pb;
use futures_util::{SinkExt, StreamExt};
use pb::playback_control::Op;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tonic::Code;

use super::{TestApp, line_clip, within};

const FPS: u64 = 30;
/// How long the flood lasts.
const FLOOD: Duration = Duration::from_secs(2);

fn budget(c: &mut server::Config) {
    c.limits.write_rate = 1;
    c.limits.write_burst = 4;
}

/// The `seq` of each frame of a stream over `span`.
async fn frames_for(ws: &mut crate::common::app::Ws, span: Duration) -> Vec<u64> {
    let (mut frames, end) = (Vec::new(), Instant::now() + span);
    while Instant::now() < end {
        let Ok(message) = tokio::time::timeout_at(end.into(), ws.next()).await else { break };
        if let Message::Text(t) = message.expect("the socket stays open").unwrap() {
            let v: Value = serde_json::from_str(&t).unwrap();
            assert!(v.get("error").is_none(), "the bystander sent no control: {v}");
            frames.push(v["seq"].as_u64().unwrap());
        }
    }
    frames
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_of_controls_on_a_private_stream_is_refused_rate_limited_and_others_keep_their_frames() {
    let app = TestApp::builder().configure(budget).start().await;
    let id = app.create_id(&line_clip(4), None).await; // one write of four
    let (mut tx, mut rx) = app.ws(&format!("/v1/clips/{id}/stream?fps={FPS}")).await.split();
    // Another playback (half speed), so the two never share one.
    let mut bystander = app.ws(&format!("/v1/clips/{id}/stream?fps={FPS}&speed=0.5")).await;
    within(5, "a first frame", bystander.next()).await.unwrap().unwrap();

    let started = Instant::now();
    let flood = tokio::spawn(async move {
        // 1,000 a second, 20 at a time.
        let mut sent = 0u64;
        let mut every = tokio::time::interval(Duration::from_millis(20));
        while started.elapsed() < FLOOD {
            every.tick().await;
            for _ in 0..20 {
                let op = if sent.is_multiple_of(2) {
                    json!({"op": "seek", "time": 1.0})
                } else {
                    json!({"op": "speed", "speed": 2.0})
                };
                tx.send(Message::Text(op.to_string().into())).await.unwrap();
                sent += 1;
            }
        }
        (sent, tx)
    });
    let refusals = tokio::spawn(async move {
        let (mut problems, mut frames) = (Vec::new(), 0u64);
        // Frames keep coming: read until the refusals have surely all come.
        let until = tokio::time::Instant::now() + FLOOD + Duration::from_secs(3);
        while let Ok(Some(message)) = tokio::time::timeout_at(until, rx.next()).await {
            let Message::Text(t) = message.unwrap() else { continue };
            let v: Value = serde_json::from_str(&t).unwrap();
            match v.get("error") {
                Some(problem) => problems.push(problem.clone()),
                None => frames += 1,
            }
        }
        (problems, frames)
    });
    let watched_frames = frames_for(&mut bystander, FLOOD).await;
    let (sent, _tx) = flood.await.unwrap();
    let (problems, frames) = refusals.await.unwrap();

    // Three writes left, and one back a second: every control past them refused.
    let allowed = 3 + started.elapsed().as_secs() + 1;
    assert!(sent > 100, "the flood sent {sent}");
    assert!(problems.len() as u64 >= sent - allowed && problems.len() as u64 <= sent, "{} of {sent}", problems.len());
    for problem in &problems {
        assert_eq!((problem["status"].as_u64(), problem["code"].as_str()), (Some(429), Some("rate_limited")));
    }
    assert!(frames > FPS, "the flooded socket stays open with its frames: {frames}");
    // The bystander's 30 fps held: its frames came, no gap of half a second.
    let expected = FLOOD.as_secs() * FPS;
    // Loose bounds (the tests share a busy machine); a stalled node fails both.
    assert!(watched_frames.len() as u64 >= expected * 3 / 4, "{} frames of {expected}", watched_frames.len());
    let longest = watched_frames.windows(2).map(|w| w[1] - w[0]).max().unwrap();
    assert!(longest <= FPS / 2, "a gap of {longest} ticks");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn play_controls_past_the_write_budget_end_the_call_resource_exhausted() {
    let app = TestApp::builder().configure(budget).start().await;
    let id = app.create_id(&line_clip(2), None).await; // three writes left
    let (tx, rx) = tokio::sync::mpsc::channel(16);
    let stream = pb::StreamRequest { clip_id: id, fps: FPS as u32, ..Default::default() };
    tx.send(pb::PlaybackControl { op: Some(Op::Open(pb::Open { stream: Some(stream), paused: false })) })
        .await
        .unwrap();
    let mut frames = app.grpc().await.play(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    within(5, "a frame", frames.message()).await.unwrap().expect("a first frame");
    // Eight controls: at most four fit (three left, one back meanwhile).
    for k in 0..8 {
        let op = if k % 2 == 0 { Op::Pause(pb::Pause {}) } else { Op::Play(pb::Resume {}) };
        tx.send(pb::PlaybackControl { op: Some(op) }).await.unwrap();
    }
    let status = loop {
        match within(5, "the end of the call", frames.message()).await {
            Ok(Some(_)) => {}
            Ok(None) => panic!("the call ended OK"),
            Err(status) => break status,
        }
    };
    assert_eq!(status.code(), Code::ResourceExhausted, "{status:?}");
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "rate_limited", "{status:?}");
    app.stop().await;
}
