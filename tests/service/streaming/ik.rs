//! Inverse kinematics in WebSocket streams (docs/ik.md) with a real client:
//! a clip's keyed IK in every frame, and the `ik` control that replaces a
//! stream's constraints at the next tick — two-bone and aim on target
//! within one frame, a chain within its tolerance after the iterations it
//! reports, warm-started from the previous frame — and its refusals.
//!
//! The leg (`common::ik_leg`) is under hips that move along x at 1 unit/s,
//! so each frame's expected positions follow from its own time.

use futures_util::{SinkExt, StreamExt};
use glam::{DQuat, DVec3};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::{TestApp, within};
use crate::common::app::Ws;
use crate::common::ik_leg;

async fn next_json(ws: &mut Ws) -> Value {
    loop {
        match within(5, "a message", ws.next()).await.expect("the socket closed").unwrap() {
            Message::Text(t) => return serde_json::from_str(&t).unwrap(),
            Message::Ping(_) | Message::Pong(_) => {}
            other => panic!("expected a text message, got {other:?}"),
        }
    }
}

async fn next_frame(ws: &mut Ws) -> Value {
    let v = next_json(ws).await;
    assert!(v.get("seq").is_some(), "expected a frame, got {v}");
    v
}

async fn send(ws: &mut Ws, msg: Value) {
    ws.send(Message::Text(msg.to_string().into())).await.unwrap();
}

fn joint<'a>(frame: &'a Value, name: &str) -> &'a Value {
    let joints = frame["pose"]["joints"].as_array().unwrap();
    joints.iter().find(|j| j["name"] == name).unwrap_or_else(|| panic!("no {name} in {frame}"))
}

fn position(frame: &Value, name: &str) -> DVec3 {
    let v = &joint(frame, name)["translation"];
    DVec3::new(v[0].as_f64().unwrap(), v[1].as_f64().unwrap(), v[2].as_f64().unwrap())
}

fn rotation(frame: &Value, name: &str) -> DQuat {
    let r = &joint(frame, name)["rotation"];
    let q = |i: usize| r[i].as_f64().unwrap();
    DQuat::from_xyzw(q(0), q(1), q(2), q(3))
}

fn reports(frame: &Value) -> Vec<Value> {
    frame["pose"].get("ik").and_then(Value::as_array).cloned().unwrap_or_default()
}

/// A model-space stream of a 10 s leg under a motion with `ik`, paused at
/// motion time 1 (so every frame shows the same layered pose).
async fn open_leg(app: &TestApp, ik: Value) -> Ws {
    let id = app.create_id(&ik_leg("walk", 10.0, json!([])), None).await;
    let mut ws = app.ws("/v1/stream").await;
    let motion = json!({"layers": [{"clip": id}], "ik": ik});
    send(&mut ws, json!({"op": "open", "motion": motion, "fps": 30, "space": "model", "start": 1.0, "paused": true}))
        .await;
    let opened = next_json(&mut ws).await;
    assert!(opened.get("opened").is_some(), "{opened}");
    ws
}

/// Frames until one satisfies `done`, at most `frames` of them.
async fn until(ws: &mut Ws, frames: usize, done: impl Fn(&Value) -> bool) -> Value {
    for _ in 0..frames {
        let frame = next_frame(ws).await;
        if done(&frame) {
            return frame;
        }
    }
    panic!("no frame within {frames} satisfied the condition");
}

#[tokio::test]
async fn a_clip_stream_solves_its_keyed_target_in_every_frame() {
    let app = TestApp::start().await;
    let (a, b) = (DVec3::new(0.1, -0.8, 0.2), DVec3::new(2.1, -0.7, -0.2));
    let ik = json!([{"kind": "two_bone", "joints": ["thigh", "knee", "foot"],
                     "target": {"times": [0, 2], "values": [a.to_array(), b.to_array()]}}]);
    let id = app.create_id(&ik_leg("step", 2.0, ik), None).await;
    let mut ws = app.ws(&format!("/v1/clips/{id}/stream?fps=30&space=model&max_frames=20")).await;
    for _ in 0..20 {
        let frame = next_frame(&mut ws).await;
        let t = frame["pose"]["clip_time"].as_f64().unwrap();
        let target = a.lerp(b, t / 2.0);
        assert!(position(&frame, "foot").distance(target) <= 1e-5, "t={t}: {}", position(&frame, "foot"));
        let report = &reports(&frame)[0];
        assert_eq!((report["kind"].as_str(), report["converged"].as_bool()), (Some("two_bone"), Some(true)));
    }
}

#[tokio::test]
async fn the_ik_control_moves_the_effectors_to_each_new_target_within_one_frame() {
    let app = TestApp::start().await;
    let mut ws = open_leg(&app, json!([])).await;
    let first = next_frame(&mut ws).await;
    assert!(reports(&first).is_empty(), "no constraints yet: {first}");
    let rest_foot = position(&first, "foot");
    // Hips are at x = 1 (motion time 1); the thigh at x = 1.1.
    let targets = [DVec3::new(1.2, -0.7, 0.3), DVec3::new(0.9, -0.6, -0.3), DVec3::new(1.1, -0.95, 0.1)];
    let look = DVec3::new(-2.0, 3.0, 1.0);
    for target in targets {
        let control = json!({"op": "ik", "constraints": [
            {"kind": "two_bone", "joints": ["thigh", "knee", "foot"], "target": target.to_array(), "pole": [1.1, -0.5, 2]},
            {"kind": "aim", "joint": "head", "target": look.to_array(), "forward": [0, 0, 1]}
        ]});
        let sent_after = next_frame(&mut ws).await["seq"].as_u64().unwrap();
        send(&mut ws, control).await;
        // The control acts at the next tick: the frame after the one in
        // flight when it was sent shows it.
        let frame = until(&mut ws, 3, |f| position(f, "foot").distance(target) <= 1e-5).await;
        assert!(frame["seq"].as_u64().unwrap() <= sent_after + 2, "within one frame: {frame}");
        let head = position(&frame, "head");
        let forward = rotation(&frame, "head") * DVec3::Z;
        let to_look = (look - head).normalize();
        assert!(forward.cross(to_look).length().atan2(forward.dot(to_look)) <= 1e-5, "the head aims");
        let kinds: Vec<_> = reports(&frame).iter().map(|r| r["kind"].as_str().unwrap().to_owned()).collect();
        assert_eq!(kinds, ["two_bone", "aim"]);
    }
    // An empty list lets go: the animated pose comes back.
    send(&mut ws, json!({"op": "ik", "constraints": []})).await;
    let frame = until(&mut ws, 3, |f| reports(f).is_empty()).await;
    assert!(position(&frame, "foot").distance(rest_foot) < 1e-6);
}

#[tokio::test]
async fn a_dragged_chain_target_converges_warm_from_the_previous_frame() {
    let app = TestApp::start().await;
    let mut ws = open_leg(&app, json!([])).await;
    let chain = |target: DVec3| {
        json!({"op": "ik", "constraints": [{"kind": "chain", "joints": ["thigh", "knee"],
            "effectors": [{"joint": "foot", "target": target.to_array()}],
            "limits": {"knee": {"min": [-2.5, -0.2, -0.2], "max": [0.2, 0.2, 0.2]}}}]})
    };
    let mut iterations = Vec::new();
    for k in 0..8 {
        // A target dragged in small steps, as a client's mouse moves it.
        let target = DVec3::new(1.1 + 0.02 * k as f64, -0.8, 0.25);
        send(&mut ws, chain(target)).await;
        let frame = until(&mut ws, 4, |f| {
            reports(f).first().is_some_and(|r| r["converged"] == true)
                && position(f, "foot").distance(target) <= 1e-4 + 1e-6
        })
        .await;
        let report = &reports(&frame)[0];
        let residual = report["residual"].as_f64().unwrap();
        assert!((residual - position(&frame, "foot").distance(target)).abs() < 1e-5, "{report}");
        iterations.push(report["iterations"].as_u64().unwrap());
    }
    // Warm starts: each nearby target begins next to its answer.
    let (cold, warm) = (iterations[0], iterations[1..].iter().max().copied().unwrap());
    assert!(warm < cold, "warm solves take fewer iterations than the cold first one: {iterations:?}");
}

#[tokio::test]
async fn motion_constraints_apply_from_the_first_frame_and_bad_controls_are_refused() {
    let app = TestApp::start().await;
    let target = DVec3::new(1.2, -0.8, 0.2);
    let ik = json!([{"kind": "two_bone", "joints": ["thigh", "knee", "foot"], "target": target.to_array()}]);
    let mut ws = open_leg(&app, ik).await;
    let first = next_frame(&mut ws).await;
    assert!(position(&first, "foot").distance(target) <= 1e-5, "the open message's constraints: {first}");
    for (control, code, pointer) in [
        (
            json!({"op": "ik", "constraints": [{"kind": "aim", "joint": "tail", "target": [0, 0, 1]}]}),
            "unknown_joint",
            "/constraints/0/joint",
        ),
        (
            json!({"op": "ik", "constraints": [{"kind": "aim", "joint": "head", "target": {"times": [0], "values": [[0, 0, 1]]}}]}),
            "keys_not_allowed",
            "/constraints/0/target",
        ),
        (
            json!({"op": "ik", "constraints": [{"kind": "two_bone", "joints": ["thigh", "head", "foot"], "target": [0, 0, 0]}]}),
            "not_descendant",
            "/constraints/0/joints/1",
        ),
    ] {
        send(&mut ws, control.clone()).await;
        let error = loop {
            let v = next_json(&mut ws).await;
            if let Some(e) = v.get("error") {
                break e.clone();
            }
        };
        assert_eq!((error["code"].as_str(), error["pointer"].as_str()), (Some(code), Some(pointer)), "{control}");
    }
    // Refusals change nothing: the stream's constraint still holds.
    let frame = next_frame(&mut ws).await;
    assert!(position(&frame, "foot").distance(target) <= 1e-5);
}
