//! A stream's controls are priced (docs/api.md, “Work and its price”): an
//! `ik` control or a crossfade that would take the stream's work per second
//! over `max_request_work` is refused `too_much_work` (422), one over its
//! caller's share `caller_work_limit` (429); the stream goes on as it was
//! and holds what it held. One that fits is charged for what it adds.

use std::time::Duration;

use formats::wire::proto::pb;
use futures_util::{SinkExt, StreamExt};
use pb::playback_control::Op;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tonic::Code;

use super::{TestApp, within};
use crate::common::app::Ws;
use crate::common::{chain_clip, eventually};

/// Joints of the stream's chain, and its frames per second.
const JOINTS: u64 = 256;
const FPS: u64 = 30;

/// A chain constraint on the whole chain, toward a point out of reach.
fn chain(iterations: u32) -> Value {
    json!({"op": "ik", "constraints": [{"kind": "chain", "effectors": [{"joint": "j255", "target": [50, 50, 0]}],
                                        "max_iterations": iterations, "tolerance": 1e-9}]})
}

/// What a chain of `iterations` adds to the stream per second: 15 units per
/// joint and iteration, each frame.
fn chain_per_sec(iterations: u64) -> u64 {
    FPS * JOINTS * iterations * 15
}

async fn send(ws: &mut Ws, msg: Value) {
    ws.send(Message::Text(msg.to_string().into())).await.unwrap();
}

/// The next text message: a frame, or `{"error": …}`.
async fn next_json(ws: &mut Ws) -> Value {
    loop {
        match within(5, "a message", ws.next()).await.expect("the socket closed").unwrap() {
            Message::Text(t) => return serde_json::from_str(&t).unwrap(),
            Message::Ping(_) | Message::Pong(_) => {}
            other => panic!("expected a text message, got {other:?}"),
        }
    }
}

/// The refusal of the control just sent (frames before it skipped).
async fn refusal(ws: &mut Ws) -> Value {
    for _ in 0..200 {
        let message = next_json(ws).await;
        if let Some(problem) = message.get("error") {
            return problem.clone();
        }
    }
    panic!("no refusal within 200 messages")
}

fn has_ik(frame: &Value) -> bool {
    frame["pose"].get("ik").and_then(Value::as_array).is_some_and(|r| !r.is_empty())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_ik_control_over_the_streams_limit_is_refused_and_the_stream_goes_on() {
    let app = TestApp::start().await;
    let id = app.create_id(&chain_clip(JOINTS as usize, json!([])), None).await;
    let mut ws = app.ws(&format!("/v1/clips/{id}/stream?fps={FPS}")).await;
    assert!(!has_ik(&next_json(&mut ws).await));
    let meter = app.state.work.meter();
    let opened = meter.held();
    assert!(opened > FPS * JOINTS, "the stream holds its price: {opened}");
    // 1,000 iterations: 115,200,000 units a second on top, over the limit.
    send(&mut ws, chain(1000)).await;
    let problem = refusal(&mut ws).await;
    assert_eq!((problem["code"].as_str(), problem["status"].as_u64()), (Some("too_much_work"), Some(422)));
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.contains("per second") && detail.contains("100000000"), "{detail}");
    assert_eq!(meter.held(), opened, "the stream holds what it held");
    for _ in 0..3 {
        let frame = next_json(&mut ws).await;
        assert!(frame.get("seq").is_some() && !has_ik(&frame), "the stream goes on unchanged: {frame}");
    }
    // 10 iterations fit: charged for exactly what they add, then solved.
    send(&mut ws, chain(10)).await;
    let mut solved = false;
    for _ in 0..60 {
        if has_ik(&next_json(&mut ws).await) {
            solved = true;
            break;
        }
    }
    assert!(solved, "the accepted constraint shows in the frames");
    assert_eq!(meter.held(), opened + chain_per_sec(10));
    drop(ws);
    eventually(Duration::from_secs(5), "the stream's price comes back", || async { meter.held() == 0 }).await;
    app.stop().await;
}

/// `layers` layers of the clip `id`.
fn layers(id: &str, layers: usize) -> Value {
    json!({"layers": vec![json!({"clip": id}); layers]})
}

/// A crossfade to `layers` layers of `id`.
fn crossfade(id: &str, n: usize) -> Value {
    json!({"op": "crossfade", "to": layers(id, n), "duration": 0.5})
}

/// A server over a stored 256-joint chain whose callers may each hold
/// `share` units a second; the chain's id.
async fn sharing(dir: &std::path::Path, share: u64) -> (TestApp, String) {
    let app = TestApp::builder().data_dir(dir).start().await;
    // A fresh name: a second server over the same data dir adds its own chain.
    let chain = crate::common::fresh_name(&chain_clip(JOINTS as usize, json!([])));
    let id = app.create_id(&chain, None).await;
    app.stop().await;
    let app = TestApp::builder()
        .data_dir(dir)
        .configure(|c| {
            c.limits.node_work_per_sec = 2 * share;
            c.limits.caller_work_share = 0.5;
        })
        .start()
        .await;
    (app, id)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_crossfade_over_the_callers_share_is_refused_429() {
    let dir = tempfile::tempdir().unwrap();
    // One stream's price per second, measured on a generous server.
    let (app, id) = sharing(dir.path(), 1 << 40).await;
    let path = format!("/v1/clips/{id}/stream?fps={FPS}");
    let mut ws = app.ws(&path).await;
    next_json(&mut ws).await;
    let one = app.state.work.meter().held();
    drop(ws);
    app.stop().await;
    // Room for two such streams and 100,000 units a second more.
    let (app, id) = sharing(dir.path(), 2 * one + 100_000).await;
    let meter = app.state.work.meter();
    // The targets built once (the motion cache), so the controls find them.
    for n in [2, 32] {
        let pose = json!({"motion": layers(&id, n), "time": 0.5, "joints": ["j0"]});
        assert_eq!(app.http.post(app.url("/v1/poses")).json(&pose).send().await.unwrap().status(), 200);
    }
    let mut a = app.ws(&path).await;
    let mut b = app.ws(&path).await;
    next_json(&mut a).await;
    next_json(&mut b).await;
    assert_eq!(meter.held(), 2 * one);
    // The fade evaluates both motions: 32 layers of 256 joints on top,
    // 245,760 units a second, over the caller's share.
    send(&mut b, crossfade(&id, 32)).await;
    let problem = refusal(&mut b).await;
    assert_eq!((problem["code"].as_str(), problem["status"].as_u64()), (Some("caller_work_limit"), Some(429)));
    assert_eq!(meter.held(), 2 * one, "both streams hold what they held");
    let frame = next_json(&mut b).await;
    assert!(frame.get("seq").is_some(), "the stream goes on: {frame}");
    // Two layers fit: 15,360 units a second on top.
    send(&mut b, crossfade(&id, 2)).await;
    eventually(Duration::from_secs(5), "the crossfade is charged", || async {
        meter.held() == 2 * one + FPS * 2 * JOINTS
    })
    .await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_play_control_over_the_streams_limit_is_refused_invalid_argument() {
    let app = TestApp::start().await;
    let id = app.create_id(&chain_clip(JOINTS as usize, json!([])), None).await;
    let (tx, rx) = tokio::sync::mpsc::channel(8);
    let stream = pb::StreamRequest { clip_id: id, fps: FPS as u32, ..Default::default() };
    tx.send(pb::PlaybackControl { op: Some(Op::Open(pb::Open { stream: Some(stream), paused: false })) })
        .await
        .unwrap();
    let mut grpc = app.grpc().await;
    let mut frames = grpc.play(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    within(5, "a frame", frames.message()).await.unwrap().expect("a first frame");
    let meter = app.state.work.meter();
    let opened = meter.held();
    let target = pb::Vec3 { x: 50.0, y: 50.0, z: 0.0 };
    let effector = pb::IkEffector {
        joint: "j255".into(),
        target: Some(pb::IkTarget { target: Some(pb::ik_target::Target::Point(target)) }),
        tip: None,
    };
    let chain = pb::IkChain {
        effectors: vec![effector],
        max_iterations: Some(1000),
        tolerance: Some(1e-9),
        ..Default::default()
    };
    let constraints = vec![pb::IkConstraint { kind: Some(pb::ik_constraint::Kind::Chain(chain)) }];
    tx.send(pb::PlaybackControl { op: Some(Op::Ik(pb::IkControl { constraints })) }).await.unwrap();
    let status = loop {
        match within(5, "the refusal", frames.message()).await {
            Ok(Some(frame)) => {
                assert!(frame.pose.is_some_and(|p| p.ik.is_empty()), "the control was not applied");
                assert_eq!(meter.held(), opened, "nor charged");
            }
            Ok(None) => panic!("the stream ended OK"),
            Err(status) => break status,
        }
    };
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "too_much_work", "{status:?}");
    assert!(status.message().contains("per second"), "{}", status.message());
    eventually(Duration::from_secs(5), "the stream's price comes back", || async { meter.held() == 0 }).await;
    app.stop().await;
}
