//! Graphs in streams and broadcasts (docs/graphs.md, “Streams and
//! broadcasts”), with real clients: a WebSocket graph stream driven by
//! `set` controls shows, tick for tick, what `POST /v1/samples` answers for
//! the same settings at the same ticks (reports and joints equal to the number);
//! what a graph stream does not take is refused with its code and pointer;
//! a broadcast's `set` reaches every viewer at the seq it answers; gRPC
//! `StreamFrames` carries `Pose.graph` and `Play` takes `set`. A motion's
//! springs and IK on a graph stream are what samples answer from tick 0,
//! and a graph pose warms its springs up as a samples request from its tick.
//! A graph on a character streams, broadcasts and streams over gRPC the
//! poses samples answer on it; a graph stream's and a broadcast's root
//! motion is the samples' for the same inputs.
//!
//! The graph is the Fox's shipped locomotion (`examples/graphs/fox-locomotion.json`):
//! it stands (`idle`) until `speed` rises above 0.2, then `move`s at once
//! (the transition fires on the tick the setting takes effect), and the
//! `survey` trigger while moving fires `look` on its tick. So the first
//! frame showing the new state is the tick the `set` took effect, which the
//! samples request then names as its input's time.

use std::collections::BTreeMap;

use formats::wire::proto::pb;
use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::{TestApp, within};
use crate::api::character_routes::take_and_cesium;
use crate::api::graph_characters::pace_graph;
use crate::api::graph_root_motion::walks_graph;
use crate::api::graph_samples::fox_graph;
use crate::common::app::Ws;

const FPS: u32 = 60;

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

/// The next frame (an error message fails the test).
async fn next_frame(ws: &mut Ws) -> Value {
    let v = next_json(ws).await;
    assert!(v.get("seq").is_some(), "expected a frame, got {v}");
    v
}

/// The next error message, frames before it skipped.
async fn next_error(ws: &mut Ws) -> Value {
    for _ in 0..400 {
        let v = next_json(ws).await;
        if let Some(error) = v.get("error") {
            return error.clone();
        }
    }
    panic!("no error message within 400 messages");
}

async fn send(ws: &mut Ws, msg: Value) {
    ws.send(Message::Text(msg.to_string().into())).await.unwrap();
}

fn over(graph: &str) -> Value {
    json!({"layers": [{"graph": graph}]})
}

/// `GET /v1/stream` opened with `open`: the socket and the first message.
async fn open(app: &TestApp, open: Value) -> (Ws, Value) {
    let mut ws = app.ws("/v1/stream").await;
    send(&mut ws, open).await;
    let first = next_json(&mut ws).await;
    (ws, first)
}

fn state(frame_or_pose: &Value) -> &str {
    frame_or_pose["graph"]["state"].as_str().unwrap_or_else(|| panic!("no report: {frame_or_pose}"))
}

/// Reads frames until seq `until`: seq → frame.
async fn frames_until(ws: &mut Ws, until: u64) -> BTreeMap<u64, Value> {
    let mut out = BTreeMap::new();
    loop {
        let frame = next_frame(ws).await;
        let seq = frame["seq"].as_u64().unwrap();
        out.insert(seq, frame);
        if seq >= until {
            return out;
        }
    }
}

/// The first seq at or after `from` whose report shows `state`.
fn first_in(frames: &BTreeMap<u64, Value>, from: u64, want: &str) -> u64 {
    *frames.range(from..).find(|(_, f)| state(f) == want).unwrap_or_else(|| panic!("no frame in {want}")).0
}

/// `POST /v1/samples` over `graph` from tick 0 to `last` at `fps` with `inputs`.
async fn samples(app: &TestApp, graph: &str, last: u64, fps: u32, inputs: Value) -> Vec<Value> {
    samples_of(app, over(graph), last, fps, inputs).await
}

/// `POST /v1/samples` of `motion` (over a graph) from tick 0 to `last`.
async fn samples_of(app: &TestApp, motion: Value, last: u64, fps: u32, inputs: Value) -> Vec<Value> {
    let body = json!({"motion": motion, "start": 0, "end": last as f64 / f64::from(fps), "fps": fps,
                      "report": true, "inputs": inputs});
    let answer = app.post_json("/v1/samples", &body).await;
    let poses = answer["poses"].as_array().unwrap_or_else(|| panic!("{answer}")).clone();
    assert_eq!(poses.len() as u64, last + 1);
    poses
}

/// A frame's pose against a sampled pose: the same report and the same
/// joints, number for number, at the same time.
fn assert_same_tick(seq: u64, frame: &Value, pose: &Value) {
    assert_eq!(frame["graph"], pose["graph"], "the report of tick {seq}");
    let (a, b) = (&frame["pose"], pose);
    assert_eq!(a["clip"], b["clip"], "tick {seq} names the graph");
    assert!((a["time"].as_f64().unwrap() - b["time"].as_f64().unwrap()).abs() < 1e-12, "tick {seq}'s time");
    assert_eq!(a["joints"], b["joints"], "tick {seq}'s joints");
}

#[tokio::test]
async fn a_websocket_graph_stream_shows_what_samples_answer_for_the_same_settings() {
    let app = TestApp::start().await;
    let (graph, _) = fox_graph(&app).await;
    let (mut ws, opened) = open(&app, json!({"op": "open", "motion": over(&graph), "fps": FPS, "report": true})).await;
    assert_eq!(opened["opened"]["clip"], graph.as_str(), "{opened}");
    let head = frames_until(&mut ws, 3).await;
    // Before any set the graph idles (a starved client may have missed tick 0 itself).
    assert_eq!(state(head.values().next().unwrap()), "idle");
    send(&mut ws, json!({"op": "set", "parameters": {"speed": 2.5}})).await;
    let mut frames = frames_until(&mut ws, 40).await;
    let moved = first_in(&frames, 0, "move");
    assert!(moved > 3, "a set applies at a tick after the frames already read: {moved}");
    let sent_at = *frames.keys().last().unwrap();
    send(&mut ws, json!({"op": "set", "parameters": {"survey": true}})).await;
    frames.extend(frames_until(&mut ws, sent_at + 40).await);
    frames.extend(head);
    let looked = first_in(&frames, sent_at + 1, "look");
    let last = *frames.keys().last().unwrap();
    let t = |k: u64| k as f64 / f64::from(FPS);
    let inputs = json!([{"time": t(moved), "set": {"speed": 2.5}}, {"time": t(looked), "set": {"survey": true}}]);
    let poses = samples(&app, &graph, last, FPS, inputs).await;
    for (seq, frame) in &frames {
        assert_same_tick(*seq, frame, &poses[*seq as usize]);
    }
    let fired = &frames[&moved]["graph"]["transition"];
    assert_eq!((&fired["from"], &fired["to"], fired["alpha"].as_f64()), (&json!("idle"), &json!("move"), Some(0.0)));
}

/// The Fox clip named `name`'s id.
async fn fox_clip(app: &TestApp, name: &str) -> String {
    app.get_json(&format!("/v1/clips?name={name}")).await["clips"][0]["id"].as_str().unwrap().to_owned()
}

/// The Fox's locomotion graph among clip layers (docs/graphs.md, “What
/// composes with a graph”): Survey on the upper body at half weight, Walk
/// added at half weight.
async fn mixed_over(app: &TestApp, graph: &str) -> Value {
    let (survey, walk) = (fox_clip(app, "Survey").await, fox_clip(app, "Walk").await);
    json!({"layers": [{"graph": graph},
        {"clip": survey, "weight": 0.5, "mask": {"joints": {"b_Spine01_02": 1}, "descendants": true}},
        {"clip": walk, "mode": "additive", "weight": 0.5}]})
}

#[tokio::test]
async fn a_graph_among_clip_layers_streams_what_samples_answer_for_the_same_settings() {
    let app = TestApp::start().await;
    let (graph, _) = fox_graph(&app).await;
    let motion = mixed_over(&app, &graph).await;
    let open_msg = json!({"op": "open", "motion": motion, "fps": FPS, "report": true});
    let (mut ws, opened) = open(&app, open_msg).await;
    assert_eq!(opened["opened"]["clip"], graph.as_str(), "{opened}");
    let mut frames = frames_until(&mut ws, 3).await;
    send(&mut ws, json!({"op": "set", "parameters": {"speed": 2.5}})).await;
    frames.extend(frames_until(&mut ws, 40).await);
    let moved = first_in(&frames, 0, "move");
    let last = *frames.keys().last().unwrap();
    let inputs = json!([{"time": moved as f64 / f64::from(FPS), "set": {"speed": 2.5}}]);
    let poses = samples_of(&app, motion.clone(), last, FPS, inputs.clone()).await;
    let alone = samples(&app, &graph, last, FPS, inputs.clone()).await;
    for (seq, frame) in &frames {
        assert_same_tick(*seq, frame, &poses[*seq as usize]);
        if *seq > 0 {
            assert_ne!(
                poses[*seq as usize]["joints"], alone[*seq as usize]["joints"],
                "the clip layers show, tick {seq}"
            );
        }
    }
    // A pose is the samples' pose of its tick; compact frames derive their ranges.
    let body = json!({"motion": motion, "time": 30.0 / f64::from(FPS), "fps": FPS, "report": true, "inputs": inputs});
    let pose = app.post_json("/v1/poses", &body).await;
    assert_eq!(pose["joints"], poses[30]["joints"], "{pose}");
    let (_, compact) =
        open(&app, json!({"op": "open", "motion": mixed_over(&app, &graph).await, "encoding": "compact"})).await;
    assert!(compact.get("opened").is_some(), "{compact}");
}

/// A motion over `graph` with the Fox's tail chain (`examples/motions/fox-tail-springs.json`)
/// and its leg and head constraints (`examples/motions/walk-look-and-plant.json`).
fn with_tail_and_ik(graph: &str) -> Value {
    let read = |file: &str| -> Value {
        let path = format!("{}/examples/motions/{file}", env!("CARGO_MANIFEST_DIR"));
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
    };
    let mut motion = read("fox-tail-springs.json");
    motion["layers"] = json!([{"graph": graph}]);
    motion["ik"] = read("walk-look-and-plant.json")["ik"].clone();
    motion
}

#[tokio::test]
async fn springs_and_ik_on_a_graph_stream_are_what_samples_answer_from_tick_0() {
    // A stream's springs run from its tick 0; a samples request's from a
    // warm-up (1 s) before its first tick, not before 0: from tick 0 the two
    // are one simulation, and IK solves each tick from its pose alone.
    let app = TestApp::start().await;
    let (graph, _) = fox_graph(&app).await;
    let motion = with_tail_and_ik(&graph);
    let (mut ws, opened) = open(&app, json!({"op": "open", "motion": motion, "fps": FPS, "report": true})).await;
    assert!(opened.get("opened").is_some(), "{opened}");
    let mut frames = frames_until(&mut ws, 3).await;
    send(&mut ws, json!({"op": "set", "parameters": {"speed": 2.5}})).await;
    frames.extend(frames_until(&mut ws, 70).await);
    let moved = first_in(&frames, 0, "move");
    let last = *frames.keys().last().unwrap();
    let inputs = json!([{"time": moved as f64 / f64::from(FPS), "set": {"speed": 2.5}}]);
    let poses = samples_of(&app, motion, last, FPS, inputs.clone()).await;
    for (seq, frame) in &frames {
        assert_same_tick(*seq, frame, &poses[*seq as usize]);
        assert_eq!(frame["pose"]["ik"], poses[*seq as usize]["ik"], "tick {seq}'s IK reports");
    }
    let plain = samples(&app, &graph, last, FPS, inputs).await;
    let joints = |pose: &Value| pose["joints"].as_array().unwrap().clone();
    let (sprung, unsprung) = (joints(&poses[last as usize]), joints(&plain[last as usize]));
    let named = |j: &Value, part: &str| j["name"].as_str().unwrap().contains(part);
    let differ = |part: &str| sprung.iter().zip(&unsprung).any(|(a, b)| named(a, part) && a != b);
    assert!(differ("Tail"), "the tail swings");
    assert!(differ("Head"), "the head aims");
    let untouched = sprung.iter().zip(&unsprung).filter(|(a, _)| named(a, "Spine") || named(a, "Right"));
    assert!(untouched.clone().count() > 0 && untouched.into_iter().all(|(a, b)| a == b), "the rest is the graph's");
    assert_eq!(poses[0]["ik"].as_array().map(Vec::len), Some(2), "each pose reports the two constraints");
}

#[tokio::test]
async fn a_graph_pose_warms_its_springs_up_as_a_samples_request_from_its_tick() {
    let app = TestApp::start().await;
    let (graph, _) = fox_graph(&app).await;
    let motion = with_tail_and_ik(&graph);
    let inputs = json!([{"time": 0.5, "set": {"speed": 3}}]);
    let body = json!({"motion": motion, "time": 2.5, "fps": FPS, "inputs": inputs});
    let pose = app.post_json("/v1/poses", &body).await;
    let body = json!({"motion": motion, "start": 2.5, "end": 3, "fps": FPS, "inputs": inputs});
    let sampled = app.post_json("/v1/samples", &body).await;
    assert_eq!(pose["joints"], sampled["poses"][0]["joints"], "both run from rest at 1.5 s: {pose}");
    let from_zero = samples_of(&app, motion, 150, FPS, inputs).await;
    assert_ne!(pose["joints"], from_zero[150]["joints"], "a run from 0 differs: the chains were not at rest at 1.5 s");
}

#[tokio::test]
async fn pause_holds_a_graph_stream_and_play_goes_on_from_its_tick() {
    let app = TestApp::start().await;
    let (graph, _) = fox_graph(&app).await;
    let (mut ws, _) = open(&app, json!({"op": "open", "motion": over(&graph), "fps": FPS, "report": true})).await;
    send(&mut ws, json!({"op": "set", "parameters": {"speed": 3}})).await;
    frames_until(&mut ws, 10).await;
    send(&mut ws, json!({"op": "pause"})).await;
    let frames = frames_until(&mut ws, 40).await;
    let mut last_two = frames.values().rev().take(2).map(|f| f["pose"].clone());
    let (held, before) = (last_two.next().unwrap(), last_two.next().unwrap());
    assert_eq!(before, held, "paused frames repeat one pose and graph time");
    send(&mut ws, json!({"op": "play"})).await;
    let after = frames_until(&mut ws, 60).await;
    let moved = after.values().last().unwrap();
    let step = moved["pose"]["time"].as_f64().unwrap() - held["time"].as_f64().unwrap();
    assert!(step > 0.0 && step < 25.0 / f64::from(FPS), "play goes on from the held tick: {step}");
    send(&mut ws, json!({"op": "stop"})).await;
    loop {
        match within(5, "the close", ws.next()).await {
            Some(Ok(Message::Close(Some(frame)))) => return assert_eq!(u16::from(frame.code), 1000),
            Some(Ok(_)) => {}
            other => panic!("expected a close, got {other:?}"),
        }
    }
}

#[tokio::test]
async fn what_a_graph_stream_does_not_take_is_refused_at_its_field() {
    let app = TestApp::start().await;
    let (graph, _) = fox_graph(&app).await;
    let clip = app.create_id(super::WAVE, None).await;
    let refusals = [
        (json!({"start": 1}), "graph_unsupported", "/start"),
        (json!({"speed": 2}), "graph_unsupported", "/speed"),
        (json!({"ease": "ease_in"}), "graph_unsupported", "/ease"),
        (json!({"parameters": ["fov"]}), "graph_unsupported", "/parameters/0"),
        (json!({"fps": 0}), "fps_out_of_range", "/fps"),
        (json!({"motion": {"layers": [{"graph": graph, "speed": 2}]}}), "graph_unsupported", "/motion/layers/0/speed"),
        (
            json!({"motion": {"layers": [{"clip": clip}, {"graph": graph, "sync": "s"}]}}),
            "graph_unsupported",
            "/motion/layers/1/sync",
        ),
        (
            json!({"motion": {"layers": [{"graph": graph}, {"clip": clip}, {"graph": graph}]}}),
            "graph_unsupported",
            "/motion/layers/2/graph",
        ),
        (
            json!({"motion": {"layers": [{"graph": graph, "weight": 0.5}], "root_motion": {}}}),
            "graph_unsupported",
            "/motion/root_motion",
        ),
        (
            json!({"motion": {"layers": [{"graph": graph}, {"clip": clip, "mask": {"joints": {"nope": 1}}}]}}),
            "unknown_joint",
            "/motion/layers/1/mask/joints/nope",
        ),
        (json!({"motion": over("0193e0c0-0000-7000-8000-000000000000")}), "graph_not_found", "/motion/layers/0/graph"),
        (
            // The Fox's root joints carry no translation track (docs/motion.md, “Root motion”).
            json!({"motion": {"layers": [{"graph": graph}], "root_motion": {}}}),
            "no_root_joint",
            "/motion/root_motion",
        ),
        (
            json!({"motion": {"layers": [{"graph": graph}], "springs": [{"name": "t", "joints": ["nope", "b_Tail01_012"]}]}}),
            "unknown_joint",
            "/motion/springs/0/joints/0",
        ),
        (json!({"motion": {"layers": [{"clip": clip}]}}), "graph_unsupported", "/report"),
    ];
    for (fields, code, pointer) in refusals {
        let mut msg = json!({"op": "open", "motion": over(&graph), "report": true});
        for (k, v) in fields.as_object().unwrap() {
            msg[k] = v.clone();
        }
        let (_, first) = open(&app, msg.clone()).await;
        let error = &first["error"];
        assert_eq!((error["code"].as_str(), error["pointer"].as_str()), (Some(code), Some(pointer)), "{msg}: {first}");
    }

    let (mut ws, _) = open(&app, json!({"op": "open", "motion": over(&graph), "report": true})).await;
    let controls = [
        (json!({"op": "seek", "time": 1}), "graph_unsupported", None),
        (json!({"op": "speed", "speed": 2}), "graph_unsupported", None),
        (json!({"op": "layer", "index": 0, "weight": 0.5}), "graph_unsupported", None),
        (json!({"op": "crossfade", "to": {"layers": [{"clip": clip}]}, "duration": 0.2}), "graph_unsupported", None),
        (json!({"op": "set", "parameters": {"sped": 1}}), "unknown_parameter", Some("/parameters/sped")),
        (json!({"op": "set", "parameters": {"speed": true}}), "parameter_type", Some("/parameters/speed")),
        (json!({"op": "set", "parameters": {"survey": 1}}), "parameter_type", Some("/parameters/survey")),
        (json!({"op": "set", "parameters": {"speed": 4.5}}), "parameter_out_of_range", Some("/parameters/speed")),
    ];
    for (control, code, pointer) in controls {
        send(&mut ws, control.clone()).await;
        let error = next_error(&mut ws).await;
        assert_eq!((error["code"].as_str(), error["pointer"].as_str()), (Some(code), pointer), "{control}: {error}");
    }
    // The stream goes on, still at the defaults.
    assert_eq!(state(&next_frame(&mut ws).await), "idle");

    let (mut plain, _) = open(&app, json!({"op": "open", "motion": {"layers": [{"clip": clip}]}})).await;
    send(&mut plain, json!({"op": "set", "parameters": {"speed": 1}})).await;
    assert_eq!(next_error(&mut plain).await["code"], "graph_unsupported");
}

#[tokio::test]
async fn a_broadcast_set_reaches_every_viewer_at_the_seq_it_answers() {
    let app = TestApp::start().await;
    let (graph, _) = fox_graph(&app).await;
    let body = json!({"motion": over(&graph), "fps": 30, "report": true});
    let resp = app.http.post(app.url("/v1/broadcasts")).json(&body).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    let path = format!("/v1/broadcasts/{id}/stream");
    let (mut a, mut b) = (app.ws(&path).await, app.ws(&path).await);
    next_frame(&mut a).await;
    let control = json!({"op": "set", "parameters": {"speed": 2.5}});
    let answer = app.post_json(&format!("/v1/broadcasts/{id}/controls"), &control).await;
    let seq = answer["seq"].as_u64().unwrap_or_else(|| panic!("{answer}"));
    let (fa, fb) = (frames_until(&mut a, seq + 10).await, frames_until(&mut b, seq + 10).await);
    for (k, frame) in fa.range(..=seq + 10) {
        let Some(other) = fb.get(k) else { continue };
        assert_eq!((&frame["pose"], &frame["graph"]), (&other["pose"], &other["graph"]), "tick {k}");
    }
    assert_eq!(state(&fa[&seq]), "move", "the set takes effect at the seq it answered");
    if let Some(before) = fa.get(&(seq - 1)) {
        assert_eq!(state(before), "idle");
    }
    let poses = samples(&app, &graph, seq + 10, 30, json!([{"time": seq as f64 / 30.0, "set": {"speed": 2.5}}])).await;
    for (k, frame) in fa.range(seq.saturating_sub(2)..) {
        assert_same_tick(*k, frame, &poses[*k as usize]);
    }
    let problem =
        app.post_json(&format!("/v1/broadcasts/{id}/controls"), &json!({"op": "set", "parameters": {"x": 1}})).await;
    assert_eq!(
        (problem["code"].as_str(), problem["pointer"].as_str()),
        (Some("unknown_parameter"), Some("/parameters/x"))
    );
}

#[tokio::test]
async fn grpc_frames_of_a_graph_among_clip_layers_are_what_samples_answer() {
    let app = TestApp::start().await;
    let (graph, _) = fox_graph(&app).await;
    let survey = fox_clip(&app, "Survey").await;
    let layers = vec![
        pb::Layer { clip_id: survey.clone(), ..Default::default() },
        pb::Layer { graph: graph.clone(), weight: Some(0.5), ..Default::default() },
    ];
    let motion = pb::Motion { layers, ..Default::default() };
    let request = pb::StreamRequest { fps: FPS, motion: Some(motion), max_frames: 30, ..Default::default() };
    let mut frames = app.grpc().await.stream_frames(request).await.unwrap().into_inner();
    let json_motion = json!({"layers": [{"clip": survey}, {"graph": graph, "weight": 0.5}]});
    let poses = samples_of(&app, json_motion, 60, FPS, json!([])).await;
    let mut seen = 0;
    while let Some(frame) = within(5, "a frame", frames.message()).await.unwrap() {
        let k = frame.seq as usize;
        let Some(pose) = poses.get(k) else { break };
        let rotations: Vec<f32> = (pose["joints"].as_array().unwrap().iter())
            .flat_map(|j| j["rotation"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32))
            .collect();
        assert_eq!(frame.pose.unwrap().rotations, rotations, "tick {k}'s rotations");
        seen += 1;
    }
    assert!(seen >= 20, "{seen} frames compared");
}

#[tokio::test]
async fn grpc_graph_frames_carry_the_report_and_play_takes_set() {
    let app = TestApp::start().await;
    let (graph, _) = fox_graph(&app).await;
    let motion =
        pb::Motion { layers: vec![pb::Layer { graph: graph.clone(), ..Default::default() }], ..Default::default() };
    let request =
        pb::StreamRequest { fps: FPS, motion: Some(motion.clone()), report: true, max_frames: 3, ..Default::default() };
    let mut frames = app.grpc().await.stream_frames(request.clone()).await.unwrap().into_inner();
    let first = within(5, "a frame", frames.message()).await.unwrap().unwrap();
    let pose = first.pose.unwrap();
    assert_eq!(pose.graph.as_ref().map(|g| g.state.as_str()), Some("idle"));
    assert!(!pose.joint_names.is_empty());

    // The refusals of the WebSocket, with the same codes.
    let synced = pb::Layer { graph: graph.clone(), sync: "s".into(), ..Default::default() };
    let refusals = [
        (pb::StreamRequest { start_time: Some(1.0), ..request.clone() }, "graph_unsupported"),
        (pb::StreamRequest { playback: 2, ..request.clone() }, "graph_unsupported"),
        (
            pb::StreamRequest {
                motion: Some(pb::Motion { layers: vec![synced], ..Default::default() }),
                ..request.clone()
            },
            "graph_unsupported",
        ),
        (pb::StreamRequest { motion: None, clip_id: graph.clone(), ..request.clone() }, "graph_unsupported"),
    ];
    for (refused, code) in refusals {
        let status = app.grpc().await.stream_frames(refused.clone()).await.unwrap_err();
        assert_eq!(status.code(), tonic::Code::InvalidArgument, "{refused:?}: {status:?}");
        assert_eq!(status.metadata().get("x-error-code").unwrap(), code, "{refused:?}");
    }

    // A motion's springs on the graph: the frames of `StreamFrames` are what REST samples answer.
    let joints = ["b_Tail01_012", "b_Tail02_013", "b_Tail03_014"];
    let gravity = Some(pb::Vec3 { x: 0.0, y: -9.81, z: 0.0 });
    let spring =
        pb::Spring { name: "tail".into(), joints: joints.map(Into::into).to_vec(), gravity, ..Default::default() };
    let sprung = pb::Motion { springs: vec![spring], ..motion.clone() };
    let sprung_request = pb::StreamRequest { motion: Some(sprung), max_frames: 30, report: false, ..request.clone() };
    let mut frames = app.grpc().await.stream_frames(sprung_request).await.unwrap().into_inner();
    let json_motion = json!({"layers": [{"graph": graph}], "springs": [{"name": "tail", "joints": joints, "gravity": [0, -9.81, 0]}]});
    // Frame `seq` is tick `seq`, a tick the server woke late for evaluated all the same, up to 4 skipped
    // ticks (docs/graphs.md): after a longer gap a loaded machine's springs may part from the samples'.
    let poses = samples_of(&app, json_motion, 120, FPS, json!([])).await;
    let (mut compared, mut next) = (0, 0);
    while let Some(frame) = within(5, "a frame", frames.message()).await.unwrap() {
        let k = frame.seq as usize;
        let Some(pose) = poses.get(k).filter(|_| k <= next + 4) else { break };
        (compared, next) = (compared + 1, k + 1);
        let rotations: Vec<f32> = pose["joints"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|j| {
                j["rotation"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect::<Vec<_>>()
            })
            .collect();
        assert_eq!(frame.pose.unwrap().rotations, rotations, "tick {k}'s rotations");
    }
    assert!(compared > 0, "the first frame is always compared");

    let plain = pb::StreamRequest { report: false, ..request.clone() };
    let mut frames = app.grpc().await.stream_frames(plain).await.unwrap().into_inner();
    let first = within(5, "a frame", frames.message()).await.unwrap().unwrap();
    assert_eq!(first.pose.unwrap().graph, None, "no report unless asked");

    let (tx, rx) = tokio::sync::mpsc::channel(8);
    let open = pb::StreamRequest { max_frames: 0, ..request };
    let control = |op| pb::PlaybackControl { op: Some(op) };
    tx.send(control(pb::playback_control::Op::Open(pb::Open { stream: Some(open), ..Default::default() })))
        .await
        .unwrap();
    let mut play = app.grpc().await.play(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    within(5, "a frame", play.message()).await.unwrap().unwrap();
    let number = |n| pb::GraphValue { value: Some(pb::graph_value::Value::Number(n)) };
    let set = pb::SetParameters { parameters: [("speed".to_owned(), number(2.5))].into() };
    tx.send(control(pb::playback_control::Op::Set(set))).await.unwrap();
    let moved = loop {
        let frame = within(5, "a frame", play.message()).await.unwrap().unwrap();
        let report = frame.pose.unwrap().graph.unwrap();
        if report.state == "move" {
            break report;
        }
    };
    assert_eq!(moved.transition.map(|t| (t.from, t.to)), Some(("idle".to_owned(), "move".to_owned())));
    let bad = pb::SetParameters { parameters: [("speed".to_owned(), number(99.0))].into() };
    tx.send(control(pb::playback_control::Op::Set(bad))).await.unwrap();
    let status = loop {
        match within(5, "the refusal", play.message()).await {
            Ok(Some(_)) => {}
            Err(status) => break status,
            Ok(None) => panic!("the call ended without the refusal"),
        }
    };
    assert_eq!(status.code(), tonic::Code::InvalidArgument);
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "parameter_out_of_range");
}

#[tokio::test]
async fn a_graph_on_a_character_streams_and_broadcasts_what_samples_answer() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let graph = pace_graph(&app, &take).await;
    let motion = json!({"layers": [{"graph": graph}], "character": cesium});
    let poses = samples_of(&app, motion.clone(), 120, FPS, json!([])).await;
    let cesium_joints = app.get_json(&format!("/v1/characters/{cesium}")).await["skeleton"]["joints"].clone();
    assert_eq!(poses[0]["joints"].as_array().unwrap().len(), cesium_joints.as_array().unwrap().len());

    let (mut ws, opened) = open(&app, json!({"op": "open", "motion": motion, "fps": FPS, "report": true})).await;
    assert!(opened.get("opened").is_some(), "{opened}");
    for (seq, frame) in frames_until(&mut ws, 20).await {
        assert_same_tick(seq, &frame, &poses[seq as usize]);
    }

    let body = json!({"motion": motion, "fps": FPS, "report": true});
    let resp = app.http.post(app.url("/v1/broadcasts")).json(&body).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    let mut viewer = app.ws(&format!("/v1/broadcasts/{id}/stream")).await;
    for (seq, frame) in frames_until(&mut viewer, 10).await.into_iter().filter(|(seq, _)| *seq <= 120) {
        assert_same_tick(seq, &frame, &poses[seq as usize]);
    }

    let layer = pb::Layer { graph: graph.clone(), ..Default::default() };
    let on = pb::Motion { layers: vec![layer], character: cesium.clone(), ..Default::default() };
    let request = pb::StreamRequest { fps: FPS, motion: Some(on), max_frames: 5, ..Default::default() };
    let mut frames = app.grpc().await.stream_frames(request).await.unwrap().into_inner();
    while let Some(frame) = within(5, "a frame", frames.message()).await.unwrap() {
        let pose = frame.pose.unwrap();
        let want = &poses[frame.seq as usize]["joints"];
        let rotations: Vec<f32> = (want.as_array().unwrap().iter())
            .flat_map(|j| j["rotation"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32))
            .collect();
        assert_eq!(pose.rotations, rotations, "tick {}'s rotations", frame.seq);
    }
}

#[tokio::test]
async fn a_graph_stream_s_root_motion_is_what_samples_answer_for_the_same_inputs() {
    let app = TestApp::start().await;
    let graph = walks_graph(&app, [(0.25, 1.0), (0.5, 4.0)], 0.0, 0.2).await;
    let motion = json!({"layers": [{"graph": graph}], "root_motion": {"joint": "hips"}});
    let (mut ws, opened) = open(&app, json!({"op": "open", "motion": motion, "fps": FPS, "report": true})).await;
    assert!(opened.get("opened").is_some(), "{opened}");
    let mut frames = frames_until(&mut ws, 3).await;
    send(&mut ws, json!({"op": "set", "parameters": {"pace": 0.6}})).await;
    frames.extend(frames_until(&mut ws, 30).await);
    let set_at = *frames.iter().find(|(_, f)| f["graph"]["weights"]["walk"][1] != json!(0.0)).unwrap().0;
    let sent = *frames.keys().last().unwrap();
    send(&mut ws, json!({"op": "set", "parameters": {"halt": true}})).await;
    frames.extend(frames_until(&mut ws, sent + 30).await);
    let halted = first_in(&frames, sent + 1, "stop");
    let last = *frames.keys().last().unwrap();
    let t = |k: u64| k as f64 / f64::from(FPS);
    let inputs = json!([{"time": t(set_at), "set": {"pace": 0.6}}, {"time": t(halted), "set": {"halt": true}}]);
    let poses = samples_of(&app, motion.clone(), last, FPS, inputs).await;
    for (seq, frame) in &frames {
        assert_same_tick(*seq, frame, &poses[*seq as usize]);
        let root = &frame["pose"]["root_motion"];
        assert!(root.is_object(), "tick {seq}: {frame}");
        assert_eq!(root, &poses[*seq as usize]["root_motion"], "tick {seq}'s root motion");
    }

    let body = json!({"motion": motion, "fps": FPS});
    let resp = app.http.post(app.url("/v1/broadcasts")).json(&body).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    let mut viewer = app.ws(&format!("/v1/broadcasts/{id}/stream")).await;
    let seen = frames_until(&mut viewer, 10).await;
    let poses = samples_of(&app, motion, *seen.keys().last().unwrap(), FPS, json!([])).await;
    for (seq, frame) in &seen {
        assert_eq!(frame["pose"]["root_motion"], poses[*seq as usize]["root_motion"], "broadcast tick {seq}");
    }

    // gRPC `StreamFrames`: the same numbers.
    let layer = pb::Layer { graph: graph.clone(), ..Default::default() };
    let root = pb::RootMotionOptions { joint: "hips".into(), ..Default::default() };
    let on = pb::Motion { layers: vec![layer], root_motion: Some(root), ..Default::default() };
    let request = pb::StreamRequest { fps: FPS, motion: Some(on), max_frames: 5, ..Default::default() };
    let mut frames = app.grpc().await.stream_frames(request).await.unwrap().into_inner();
    while let Some(frame) = within(5, "a frame", frames.message()).await.unwrap() {
        let total = frame.pose.unwrap().root_motion.unwrap().total.unwrap();
        let want = &poses[frame.seq as usize]["root_motion"]["total"];
        assert_eq!(json!([total.x, total.y, total.z]), want["translation"], "gRPC tick {}", frame.seq);
    }
}
