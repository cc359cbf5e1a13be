//! Composed motions in streams (docs/motion.md) with real clients: `GET /v1/stream`
//! opened by its first message, crossfades and weight ramps as WebSocket
//! and gRPC `Play` controls, joint subsets and root motion in frames, and
//! the refusals with their codes and pointers.
//!
//! The clips move `hips` along x at a known rate, so every expected pose is
//! computed by hand from the frame's own times: `walk` at 2 units/s, `run`
//! at 6 units/s, over 10 s (no loop seam within a test).

use formats::wire::proto::pb;
use futures_util::{SinkExt, StreamExt};
use prost::Message as _;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tonic::Code;

use super::{TestApp, WAVE, within};
use crate::common::app::Ws;

/// `hips` moving along x at `rate` units/s over [0, 10] s, `arm` under it.
fn mover(name: &str, rate: f32) -> String {
    crate::common::hips_mover(name, 10.0 * rate, 10.0, "once")
}

struct Clips {
    walk: String,
    run: String,
}

async fn clips(app: &TestApp) -> Clips {
    Clips { walk: app.create_id(&mover("walk", 2.0), None).await, run: app.create_id(&mover("run", 6.0), None).await }
}

/// The next text message as JSON (pings skipped).
async fn next_json(ws: &mut Ws) -> Value {
    loop {
        match within(5, "a message", ws.next()).await.expect("the socket closed").unwrap() {
            Message::Text(t) => return serde_json::from_str(&t).unwrap(),
            Message::Ping(_) | Message::Pong(_) => {}
            other => panic!("expected a text message, got {other:?}"),
        }
    }
}

/// The next message, which must be a frame.
async fn next_frame(ws: &mut Ws) -> Value {
    let v = next_json(ws).await;
    assert!(v.get("seq").is_some(), "expected a frame, got {v}");
    v
}

/// The next error message, frames before it skipped.
async fn next_error(ws: &mut Ws) -> Value {
    for _ in 0..200 {
        let v = next_json(ws).await;
        if let Some(error) = v.get("error") {
            return error.clone();
        }
    }
    panic!("no error message within 200 messages");
}

async fn send(ws: &mut Ws, msg: Value) {
    ws.send(Message::Text(msg.to_string().into())).await.unwrap();
}

/// Opens `GET /v1/stream` with `open` and returns the socket after the `opened` message.
async fn open(app: &TestApp, open: Value) -> (Ws, Value) {
    let mut ws = app.ws("/v1/stream").await;
    send(&mut ws, open).await;
    let opened = next_json(&mut ws).await;
    assert!(opened.get("opened").is_some(), "{opened}");
    (ws, opened["opened"].clone())
}

fn hips_x(frame: &Value) -> f64 {
    frame["pose"]["joints"][0]["translation"][0].as_f64().unwrap()
}

fn time(frame: &Value) -> f64 {
    frame["pose"]["time"].as_f64().unwrap()
}

fn close(a: f64, b: f64, what: &str) {
    assert!((a - b).abs() < 1e-4, "{what}: {a} vs {b}");
}

#[tokio::test]
async fn a_motion_stream_plays_the_blend_and_answers_like_post_poses() {
    let app = TestApp::start().await;
    let c = clips(&app).await;
    let motion = json!({"layers": [{"clip": c.walk}, {"clip": c.run, "weight": 0.25}]});
    let (mut ws, opened) = open(&app, json!({"op": "open", "motion": motion, "fps": 30, "max_frames": 8})).await;
    assert_eq!(opened["clip"], c.walk.as_str());
    assert_eq!(opened["joints"], json!(["hips", "arm"]));
    assert!(opened["grid_phase_ms"].as_u64().is_some());
    let mut next_seq = 0;
    for _ in 0..8 {
        // A starved test client may miss a tick: it is reported, not hidden.
        let frame = next_frame(&mut ws).await;
        let seq = frame["seq"].as_u64().unwrap();
        assert_eq!(seq, next_seq + frame["dropped"].as_u64().unwrap(), "gaps in seq are reported as dropped");
        next_seq = seq + 1;
        let t = time(&frame);
        close(t, seq as f64 / 30.0, "the motion time advances 1/30 per tick");
        close(hips_x(&frame), 0.75 * 2.0 * t + 0.25 * 6.0 * t, "75 % walk, 25 % run");
        let body = json!({"motion": motion, "time": t});
        let pose: Value = app.http.post(app.url("/v1/poses")).json(&body).send().await.unwrap().json().await.unwrap();
        assert_eq!(frame["pose"], pose, "a frame is the pose POST /v1/poses answers at its time");
    }
    let Some(Ok(Message::Close(Some(f)))) = within(5, "the close", ws.next()).await else { panic!("no close") };
    assert_eq!(u16::from(f.code), 1000, "max_frames ends normally");
    app.stop().await;
}

#[tokio::test]
async fn crossfades_blend_both_sides_at_alpha_and_a_second_one_mid_fade_does_not_jump() {
    let app = TestApp::start().await;
    let c = clips(&app).await;
    let (walk, run) = (json!({"layers": [{"clip": c.walk}]}), json!({"layers": [{"clip": c.run}]}));
    let (mut ws, _) = open(&app, json!({"op": "open", "motion": walk, "fps": 30})).await;
    let mut last = next_frame(&mut ws).await;
    for _ in 0..3 {
        last = next_frame(&mut ws).await;
    }
    send(&mut ws, json!({"op": "crossfade", "to": run, "duration": 0.5})).await;
    // Frames until the fade starts are still pure walk.
    let mut frame = next_frame(&mut ws).await;
    while time(&frame) > time(&last) {
        close(hips_x(&frame), 2.0 * time(&frame), "walk before the fade");
        last = frame;
        frame = next_frame(&mut ws).await;
    }
    // The fade's first frame: run at motion time 0, walk one frame on, α = 0.
    let fade_start = time(&last) + 1.0 / 30.0;
    close(time(&frame), 0.0, "the target starts at motion time 0");
    close(hips_x(&frame), 2.0 * fade_start, "no jump: the first fade frame is A's pose");
    let fade1 = |tb: f64| {
        let alpha = (tb / 0.5).min(1.0);
        let (a, b) = (2.0 * (fade_start + tb), 6.0 * tb);
        a + (b - a) * alpha
    };
    for _ in 0..5 {
        frame = next_frame(&mut ws).await;
        close(hips_x(&frame), fade1(time(&frame)), "the docs blend at α = elapsed/duration");
    }
    // A second crossfade, back to walk, mid-fade: the fade in progress is its A.
    last = frame;
    send(&mut ws, json!({"op": "crossfade", "to": walk, "duration": 0.4, "ease": "linear"})).await;
    frame = next_frame(&mut ws).await;
    while time(&frame) > time(&last) {
        close(hips_x(&frame), fade1(time(&frame)), "the first fade goes on until the second starts");
        last = frame;
        frame = next_frame(&mut ws).await;
    }
    let tb_at_start = time(&last) + 1.0 / 30.0;
    close(hips_x(&frame), fade1(tb_at_start), "no jump: the second fade starts from the first's pose");
    for _ in 0..20 {
        let previous = hips_x(&frame);
        frame = next_frame(&mut ws).await;
        let tc = time(&frame);
        let alpha = (tc / 0.4).min(1.0);
        let (a, b) = (fade1(tb_at_start + tc), 2.0 * tc);
        close(hips_x(&frame), a + (b - a) * alpha, "the nested blend");
        assert!((hips_x(&frame) - previous).abs() < 0.75, "no jump between frames");
    }
    close(hips_x(&frame), 2.0 * time(&frame), "after the fade only the target remains");
    app.stop().await;
}

#[tokio::test]
async fn layer_ramps_and_bad_controls_on_a_motion_stream() {
    let app = TestApp::start().await;
    let c = clips(&app).await;
    let wave = app.create_id(WAVE, None).await;
    let motion = json!({"layers": [{"clip": c.walk}, {"clip": c.run, "weight": 0}]});
    let (mut ws, _) = open(&app, json!({"op": "open", "motion": motion, "fps": 30})).await;
    let frame = next_frame(&mut ws).await;
    close(hips_x(&frame), 2.0 * time(&frame), "run at weight 0");
    send(&mut ws, json!({"op": "layer", "index": 1, "weight": 0.5})).await;
    let mut frame = next_frame(&mut ws).await;
    for _ in 0..3 {
        frame = next_frame(&mut ws).await;
    }
    let t = time(&frame);
    close(hips_x(&frame), 0.5 * 2.0 * t + 0.5 * 6.0 * t, "a zero-duration ramp sets the weight at once");

    for (control, code, detail) in [
        (json!({"op": "layer", "index": 2, "weight": 0.5}), "bad_control", "no such layer"),
        (json!({"op": "layer", "index": 0, "weight": 1.5}), "bad_control", "[0, 1]"),
        (json!({"op": "crossfade", "to": {"layers": [{"clip": c.run}]}, "duration": -1}), "bad_control", "duration"),
        (json!({"op": "crossfade", "to": {"layers": [{"clip": wave}]}, "duration": 1}), "bad_control", "skeleton"),
    ] {
        send(&mut ws, control.clone()).await;
        let error = next_error(&mut ws).await;
        assert_eq!(error["code"], code, "{control}: {error}");
        assert!(error["detail"].as_str().unwrap().contains(detail), "{control}: {error}");
    }
    let unknown = "0193a5b2-0000-7000-8000-000000000000";
    send(&mut ws, json!({"op": "crossfade", "to": {"layers": [{"clip": c.run}, {"clip": unknown}]}, "duration": 1}))
        .await;
    let error = next_error(&mut ws).await;
    assert_eq!(error["code"], "clip_not_found", "{error}");
    assert_eq!(error["pointer"], "/to/layers/1/clip", "the refusal names the layer");
    let bad_mask = json!({"layers": [{"clip": c.run, "mask": {"joints": {"tail": 1}}}]});
    send(&mut ws, json!({"op": "crossfade", "to": bad_mask, "duration": 1})).await;
    let error = next_error(&mut ws).await;
    assert_eq!(
        (error["code"].as_str(), error["pointer"].as_str()),
        (Some("unknown_joint"), Some("/to/layers/0/mask/joints/tail"))
    );
    // The stream went on through every refusal.
    assert!(next_frame(&mut ws).await["seq"].as_u64().unwrap() > 4);
    app.stop().await;
}

#[tokio::test]
async fn a_bad_open_gets_its_problem_and_close_1008() {
    let app = TestApp::start().await;
    let c = clips(&app).await;
    let unknown = "0193a5b2-0000-7000-8000-000000000000";
    for (open, code, pointer) in [
        (
            json!({"op": "open", "motion": {"layers": [{"clip": c.walk, "weight": 2}]}}),
            "weight_out_of_range",
            "/motion/layers/0/weight",
        ),
        (
            json!({"op": "open", "motion": {"layers": [{"clip": c.walk, "mask": {"joints": {"spine": 1}}}]}}),
            "unknown_joint",
            "/motion/layers/0/mask/joints/spine",
        ),
        (json!({"op": "open", "motion": {"layers": [{"clip": c.walk}]}, "fps": 0}), "fps_out_of_range", "/fps"),
        (
            json!({"op": "open", "motion": {"layers": [{"clip": c.walk}]}, "joints": ["hips", "tail"]}),
            "unknown_joint",
            "/joints/1",
        ),
        (json!({"op": "open", "motion": {"layers": [{"clip": c.walk}]}, "playback": "loop"}), "invalid_field", ""),
        (json!({"op": "open", "motion": {"layers": []}}), "no_layers", "/motion/layers"),
        (json!({"op": "open", "motion": {"layers": [{"clip": unknown}]}}), "clip_not_found", "/motion/layers/0/clip"),
    ] {
        let mut ws = app.ws("/v1/stream").await;
        send(&mut ws, open.clone()).await;
        let error = next_json(&mut ws).await["error"].clone();
        assert_eq!(error["code"], code, "{open}: {error}");
        if !pointer.is_empty() {
            assert_eq!(error["pointer"], pointer, "{open}: {error}");
        }
        let Some(Ok(Message::Close(Some(f)))) = within(5, "the close", ws.next()).await else { panic!("no close") };
        assert_eq!((u16::from(f.code), f.reason.to_string()), (1008, code.to_owned()));
    }
    app.stop().await;
}

#[tokio::test]
async fn joint_subsets_shrink_frames_and_root_motion_rides_along() {
    let app = TestApp::start().await;
    let c = clips(&app).await;
    // The clip route: `joints=` keeps only those joints, in both encodings.
    let mut full = app.ws(&format!("/v1/clips/{}/stream?fps=30&encoding=protobuf&max_frames=2", c.walk)).await;
    let mut some =
        app.ws(&format!("/v1/clips/{}/stream?fps=30&encoding=protobuf&max_frames=2&joints=arm", c.walk)).await;
    let (Some(Ok(Message::Binary(a))), Some(Ok(Message::Binary(b)))) = (full.next().await, some.next().await) else {
        panic!("binary frames")
    };
    let (fa, fb) = (pb::Frame::decode(a.clone()).unwrap(), pb::Frame::decode(b.clone()).unwrap());
    assert_eq!(fb.pose.as_ref().unwrap().joint_names, ["arm"]);
    assert_eq!(fb.pose.as_ref().unwrap().translations.len(), 3);
    assert!(b.len() < a.len(), "a subset's frame is smaller: {} < {}", b.len(), a.len());
    assert_eq!(fa.pose.unwrap().translations[3..6], fb.pose.unwrap().translations[..]);
    let mut json_subset = app.ws(&format!("/v1/clips/{}/stream?fps=30&max_frames=1&joints=hips", c.walk)).await;
    let frame = next_frame(&mut json_subset).await;
    assert_eq!(frame["pose"]["joints"].as_array().unwrap().len(), 1);
    assert_eq!(frame["pose"]["joints"][0]["name"], "hips");

    // A motion with root motion: each frame's delta is the travel since the
    // previous frame (2 units/s), the total their sum, and `extract` keeps hips in place.
    let motion = json!({"layers": [{"clip": c.walk}], "root_motion": {"mode": "extract"}});
    let (mut ws, _) =
        open(&app, json!({"op": "open", "motion": motion, "fps": 20, "joints": ["hips"], "max_frames": 6})).await;
    let mut sum = 0.0;
    for k in 0..6 {
        let frame = next_frame(&mut ws).await;
        let root = &frame["pose"]["root_motion"];
        let delta = root["delta"]["translation"][0].as_f64().unwrap();
        close(delta, if k == 0 { 0.0 } else { 2.0 / 20.0 }, "the delta since the previous frame");
        sum += delta;
        close(root["total"]["translation"][0].as_f64().unwrap(), sum, "the total is the sum of deltas");
        close(hips_x(&frame), 0.0, "extract keeps the character in place");
        assert_eq!(frame["pose"]["joints"].as_array().unwrap().len(), 1);
    }
    app.stop().await;
}

fn motion_pb(layers: &[(&str, f32)]) -> pb::Motion {
    pb::Motion {
        layers: layers
            .iter()
            .map(|&(clip, weight)| pb::Layer { clip_id: clip.to_owned(), weight: Some(weight), ..Default::default() })
            .collect(),
        ..Default::default()
    }
}

#[tokio::test]
async fn grpc_play_opens_a_motion_crossfades_ramps_and_refuses_with_codes() {
    let app = TestApp::start().await;
    let c = clips(&app).await;
    let mut grpc = app.grpc().await;
    let (tx, rx) = tokio::sync::mpsc::channel(8);
    let op = |op| pb::PlaybackControl { op: Some(op) };
    use pb::playback_control::Op;
    let stream = pb::StreamRequest {
        fps: 30,
        motion: Some(motion_pb(&[(&c.walk, 1.0), (&c.run, 0.0)])),
        joints: vec!["hips".into()],
        ..Default::default()
    };
    tx.send(op(Op::Open(pb::Open { stream: Some(stream), paused: false }))).await.unwrap();
    let mut frames = grpc.play(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    let x = |f: &pb::Frame| f64::from(f.pose.as_ref().unwrap().translations[0]);
    let t = |f: &pb::Frame| f.pose.as_ref().unwrap().time;
    let first = within(5, "a frame", frames.message()).await.unwrap().unwrap();
    assert_eq!(first.pose.as_ref().unwrap().joint_names, ["hips"]);
    close(x(&first), 2.0 * t(&first), "walk");
    tx.send(op(Op::Layer(pb::LayerWeight { index: 1, weight: 1.0, duration: 0.0 }))).await.unwrap();
    let mut f = first;
    for _ in 0..4 {
        f = within(5, "a frame", frames.message()).await.unwrap().unwrap();
    }
    close(x(&f), 6.0 * t(&f), "run at full weight");
    let to = motion_pb(&[(&c.walk, 1.0)]);
    tx.send(op(Op::Crossfade(pb::Crossfade { to: Some(to), duration: 0.0, ease: 0 }))).await.unwrap();
    for _ in 0..4 {
        f = within(5, "a frame", frames.message()).await.unwrap().unwrap();
    }
    close(x(&f), 2.0 * t(&f), "a zero-duration crossfade cuts to walk");
    let unknown = "0193a5b2-0000-7000-8000-000000000000";
    let to = motion_pb(&[(unknown, 1.0)]);
    tx.send(op(Op::Crossfade(pb::Crossfade { to: Some(to), duration: 1.0, ease: 0 }))).await.unwrap();
    let status = loop {
        match within(5, "the end", frames.message()).await {
            Ok(Some(_)) => {}
            Ok(None) => panic!("ended OK"),
            Err(status) => break status,
        }
    };
    assert_eq!(status.code(), Code::NotFound, "{status:?}");
    // StreamFrames takes a motion too, and refuses a clip and a motion together.
    let both = pb::StreamRequest {
        clip_id: c.walk.clone(),
        fps: 30,
        motion: Some(motion_pb(&[(&c.walk, 1.0)])),
        ..Default::default()
    };
    assert_eq!(grpc.stream_frames(both).await.unwrap_err().code(), Code::InvalidArgument);
    let alone =
        pb::StreamRequest { fps: 30, max_frames: 2, motion: Some(motion_pb(&[(&c.run, 1.0)])), ..Default::default() };
    let mut frames = grpc.stream_frames(alone).await.unwrap().into_inner();
    let f = within(5, "a frame", frames.message()).await.unwrap().unwrap();
    assert_eq!(f.pose.unwrap().joint_names, ["hips", "arm"]);
    app.stop().await;
}
