//! Spring chains served (docs/springs.md) with real clients: the chains
//! checked at upload with pointers, poses and samples simulated from rest a
//! warmup before, WebSocket streams carrying the simulation in stream time
//! (the same pose at shared instants whatever the frame rate), and
//! `reset_springs` showing the rest pose on its tick.
//!
//! The rig: `hips` swinging along x (0 → 0.3 → 0 m over 1 s, looping), a
//! tail of three 0.1 m bones pointing back (−z) from it, under gravity.
//! The tail's rest rotations are the identity, so a frame shows the rest
//! pose exactly when every tail joint's local rotation is `[0, 0, 0, 1]`.

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::{TestApp, within};
use crate::common::app::Ws;

const TAIL: [&str; 3] = ["tail0", "tail1", "tail2"];

fn tail_clip() -> String {
    json!({
        "name": "tailed",
        "skeleton": {"joints": [
            {"name": "hips", "parent": null},
            {"name": "tail0", "parent": "hips", "rest": {"translation": [0, 0, -0.1]}},
            {"name": "tail1", "parent": "tail0", "rest": {"translation": [0, 0, -0.1]}},
            {"name": "tail2", "parent": "tail1", "rest": {"translation": [0, 0, -0.1]}},
            {"name": "tail_end", "parent": "tail2", "rest": {"translation": [0, 0, -0.1]}}
        ]},
        "tracks": [{"joint": "hips", "channel": "translation", "interpolation": "linear",
                    "times": [0, 0.5, 1], "values": [[0, 0, 0], [0.3, 0, 0], [0, 0, 0]]}],
        "playback": "loop"
    })
    .to_string()
}

fn chain() -> Value {
    json!([{"name": "tail", "joints": ["tail0", "tail1", "tail2", "tail_end"],
            "stiffness": 1.0, "drag": 0.4, "gravity": [0, -9.81, 0]}])
}

fn sprung(clip: &str) -> Value {
    json!({"layers": [{"clip": clip}], "springs": chain()})
}

async fn post(app: &TestApp, path: &str, body: &Value) -> (u16, Value) {
    let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
    (resp.status().as_u16(), resp.json().await.unwrap())
}

async fn pose(app: &TestApp, motion: &Value, time: f64, space: &str) -> Value {
    let (status, pose) = post(app, "/v1/poses", &json!({"motion": motion, "time": time, "space": space})).await;
    assert_eq!(status, 200, "{pose}");
    pose
}

fn joint<'a>(pose: &'a Value, name: &str) -> &'a Value {
    let names = ["hips", "tail0", "tail1", "tail2", "tail_end"];
    &pose["joints"][names.iter().position(|n| *n == name).unwrap()]
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn at_rest(pose: &Value) -> bool {
    TAIL.iter().all(|j| numbers(&joint(pose, j)["rotation"]) == [0.0, 0.0, 0.0, 1.0])
}

/// The largest distance between the same joints of two model-space poses.
fn distance(a: &Value, b: &Value) -> f64 {
    let joints = a["joints"].as_array().unwrap().len();
    (0..joints)
        .map(|j| {
            let (p, q) = (numbers(&a["joints"][j]["translation"]), numbers(&b["joints"][j]["translation"]));
            p.iter().zip(&q).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
        })
        .fold(0.0, f64::max)
}

#[tokio::test]
async fn chains_are_checked_at_upload_with_pointers() {
    let app = TestApp::start().await;
    let id = app.create_id(&tail_clip(), None).await;
    let cases = [
        (
            json!({"springs": [{"name": "t", "joints": ["tail0", "nowhere"]}]}),
            "unknown_joint",
            "/motion/springs/0/joints/1",
        ),
        (
            json!({"springs": [{"name": "t", "joints": ["tail2", "tail0"]}]}),
            "not_a_chain",
            "/motion/springs/0/joints/1",
        ),
        (
            json!({"springs": [{"name": "t", "joints": ["tail0", "tail1"], "drag": 2}]}),
            "drag_out_of_range",
            "/motion/springs/0/drag",
        ),
        (
            json!({"springs": chain(), "spring_substep_hz": 5000}),
            "substep_hz_out_of_range",
            "/motion/spring_substep_hz",
        ),
        (
            json!({"springs": [{"name": "t", "joints": ["tail0", "tail1"], "colliders": [{"joint": "tail0", "sphere": {"radius": 0.1}}]}]}),
            "collider_on_spring",
            "/motion/springs/0/colliders/0/joint",
        ),
    ];
    for (springs, code, pointer) in cases {
        let mut motion = json!({"layers": [{"clip": id}]});
        motion.as_object_mut().unwrap().extend(springs.as_object().unwrap().clone());
        let (status, problem) = post(&app, "/v1/poses", &json!({"motion": motion, "time": 0.5})).await;
        assert_eq!((status, problem["code"].as_str().unwrap()), (422, code), "{problem}");
        assert_eq!(problem["pointer"], pointer, "{problem}");
    }
    // A clip's chains are checked against its own skeleton, and kept.
    let mut clip: Value = serde_json::from_str(&tail_clip()).unwrap();
    clip["name"] = json!("tailed-bad");
    clip["springs"] = json!([{"name": "t", "joints": ["tail0", "hips"]}]);
    let (status, problem) = post(&app, "/v1/clips", &clip).await;
    assert_eq!(
        (status, &problem["code"], &problem["pointer"]),
        (422, &json!("not_a_chain"), &json!("/springs/0/joints/1"))
    );
    clip["name"] = json!("tailed-good");
    clip["springs"] = chain();
    let (status, written) = post(&app, "/v1/clips", &clip).await;
    assert_eq!(status, 201, "{written}");
    let stored = app.get_json(&format!("/v1/clips/{}", written["id"].as_str().unwrap())).await;
    assert_eq!(stored["springs"][0]["joints"], chain()[0]["joints"], "{stored}");
    app.stop().await;
}

#[tokio::test]
async fn springs_off_is_the_layered_pose_and_on_only_turns_the_chain() {
    let app = TestApp::start().await;
    let id = app.create_id(&tail_clip(), None).await;
    let plain = json!({"layers": [{"clip": id}]});
    for t in [0.25, 0.8, 1.6] {
        let off = pose(&app, &plain, t, "local").await;
        // Hand-computed layered pose: hips at 0.6·t (first half) or 0.6·(1 − t) (second), looping.
        let phase = t % 1.0;
        let x = if phase <= 0.5 { 0.6 * phase } else { 0.6 * (1.0 - phase) };
        assert!((numbers(&joint(&off, "hips")["translation"])[0] - x).abs() < 1e-6, "{off}");
        assert!(at_rest(&off), "without springs the tail is its rest pose: {off}");
        let on = pose(&app, &sprung(&id), t, "local").await;
        assert_eq!(joint(&on, "hips"), joint(&off, "hips"), "springs turn their chain only");
        assert_eq!(joint(&on, "tail_end"), joint(&off, "tail_end"), "the last joint only marks a tail");
        assert!(!at_rest(&on), "gravity and the swing turn the tail: {on}");
        // Bone lengths are kept: each tail joint stays 0.1 m from the next.
        let model = pose(&app, &sprung(&id), t, "model").await;
        let names = ["tail0", "tail1", "tail2", "tail_end"];
        for pair in names.windows(2) {
            let (a, b) =
                (numbers(&joint(&model, pair[0])["translation"]), numbers(&joint(&model, pair[1])["translation"]));
            let length = a.iter().zip(&b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt();
            assert!((length - 0.1).abs() < 1e-5, "{} → {}: {length}", pair[0], pair[1]);
        }
        // The tail hangs below the hips under gravity.
        assert!(numbers(&joint(&model, "tail_end")["translation"])[1] < -0.01, "{model}");
    }
    app.stop().await;
}

async fn send(ws: &mut Ws, msg: Value) {
    ws.send(Message::Text(msg.to_string().into())).await.unwrap();
}

async fn next_json(ws: &mut Ws) -> Value {
    loop {
        match within(5, "a message", ws.next()).await.expect("the socket closed").unwrap() {
            Message::Text(t) => return serde_json::from_str(&t).unwrap(),
            Message::Ping(_) | Message::Pong(_) => {}
            other => panic!("expected a text message, got {other:?}"),
        }
    }
}

/// Every frame of a stream of `motion` opened with `extra`, by seq, until `frames` were sent.
async fn frames(app: &TestApp, motion: &Value, fps: u32, frames: u64, extra: Value) -> Vec<Option<Value>> {
    let mut ws = app.ws("/v1/stream").await;
    let mut open = json!({"op": "open", "motion": motion, "fps": fps, "max_frames": frames, "space": "model"});
    open.as_object_mut().unwrap().extend(extra.as_object().unwrap().clone());
    send(&mut ws, open).await;
    assert!(next_json(&mut ws).await.get("opened").is_some());
    let (mut out, mut next, mut parted) = (vec![None; frames as usize], 0, false);
    loop {
        match within(10, "a frame", ws.next()).await {
            Some(Ok(Message::Text(t))) => {
                let frame: Value = serde_json::from_str(&t).unwrap();
                let seq = frame["seq"].as_u64().expect("a frame") as usize;
                // Past a gap of more than 4 ticks a stream woken that late stepped the older ones without their
                // substeps (docs/graphs.md): a loaded machine's frames from there on are not compared.
                (parted, next) = (parted || seq > next + 4, seq + 1);
                // A dropped tick moves the last frames' seq past `frames`.
                if let Some(slot) = out.get_mut(seq).filter(|_| !parted) {
                    *slot = Some(frame["pose"].clone());
                }
            }
            Some(Ok(Message::Ping(_) | Message::Pong(_))) => {}
            _ => return out,
        }
    }
}

/// Streams at 30, 60, 120 and 24 fps show the same pose at the instants
/// they share (every 1/6 s), within 1e-5 of the scene's size (0.4 m).
#[tokio::test(flavor = "multi_thread")]
async fn streams_at_any_frame_rate_agree_at_shared_instants() {
    let app = TestApp::start().await;
    let id = app.create_id(&tail_clip(), None).await;
    let motion = sprung(&id);
    let rates = [30u32, 60, 120, 24];
    let runs =
        futures_util::future::join_all(rates.map(|fps| frames(&app, &motion, fps, u64::from(fps) + 1, json!({}))))
            .await;
    let mut compared = 0;
    for k in 0..=6u32 {
        let poses: Vec<&Value> =
            rates.iter().zip(&runs).filter_map(|(fps, run)| run[(k * fps / 6) as usize].as_ref()).collect();
        for pair in poses.windows(2) {
            assert!(distance(pair[0], pair[1]) <= 1e-5 * 0.4, "at {k}/6 s: {} vs {}", pair[0], pair[1]);
            compared += 1;
        }
        if k > 0 {
            assert!(!at_local_rest(&app, &id, poses[0]).await, "the tail swings at {k}/6 s");
        }
    }
    assert!(compared >= 12, "too few shared frames arrived: {compared}");
    app.stop().await;
}

/// Whether a model-space frame has the tail where its rest rotations put it.
async fn at_local_rest(app: &TestApp, id: &str, frame: &Value) -> bool {
    let rest = pose(app, &json!({"layers": [{"clip": id}]}), frame["time"].as_f64().unwrap(), "model").await;
    distance(frame, &rest) < 1e-6
}

/// A pose at τ simulates from rest at τ − 1 s (the warmup): the frame of a
/// stream started at τ − 1 that shows τ is that pose.
#[tokio::test(flavor = "multi_thread")]
async fn a_pose_is_the_frame_of_a_stream_started_a_warmup_before() {
    let app = TestApp::start().await;
    let id = app.create_id(&tail_clip(), None).await;
    let motion = sprung(&id);
    let tau = 1.7;
    let run = frames(&app, &motion, 60, 61, json!({"start": tau - 1.0})).await;
    let frame = run[60].as_ref().expect("the frame at τ arrived");
    assert!((frame["time"].as_f64().unwrap() - tau).abs() < 1e-9);
    let posed = pose(&app, &motion, tau, "model").await;
    assert!(distance(frame, &posed) <= 1e-5 * 0.4, "{frame} vs {posed}");
    // Samples: one simulation from the first time's warmup through them all.
    let times = [tau, tau + 0.25, tau + 0.5];
    let (status, samples) =
        post(&app, "/v1/samples", &json!({"motion": motion, "times": times, "space": "model"})).await;
    assert_eq!(status, 200, "{samples}");
    let first = &samples["poses"][0];
    assert!(distance(first, &posed) <= 1e-5 * 0.4, "the first sample is the pose at τ");
    let later = run_from(&app, &motion, tau - 1.0, 75).await;
    assert!(distance(&samples["poses"][1], &later) <= 1e-5 * 0.4, "the second is the same run 0.25 s on");
    app.stop().await;
}

/// The model pose a 60 fps stream started at `start` shows at frame `seq`.
async fn run_from(app: &TestApp, motion: &Value, start: f64, seq: u64) -> Value {
    let run = frames(app, motion, 60, seq + 1, json!({"start": start})).await;
    run[seq as usize].clone().expect("the frame arrived")
}

/// `reset_springs` restarts the chain at rest: the frame of its tick shows
/// the rest rotations, and the tail swings again after it.
#[tokio::test]
async fn reset_springs_shows_the_rest_pose_on_its_tick() {
    let app = TestApp::start().await;
    let id = app.create_id(&tail_clip(), None).await;
    let mut ws = app.ws("/v1/stream").await;
    send(&mut ws, json!({"op": "open", "motion": sprung(&id), "fps": 30})).await;
    assert!(next_json(&mut ws).await.get("opened").is_some());
    let first = next_json(&mut ws).await;
    assert!(at_rest(&first["pose"]), "a stream's first frame is the rest pose: {first}");
    for _ in 0..10 {
        let frame = next_json(&mut ws).await;
        assert!(!at_rest(&frame["pose"]), "the tail swings: {frame}");
    }
    send(&mut ws, json!({"op": "reset_springs"})).await;
    let mut rested = None;
    for _ in 0..30 {
        let frame = next_json(&mut ws).await;
        if at_rest(&frame["pose"]) {
            rested = Some(frame["seq"].as_u64().unwrap());
            break;
        }
    }
    let rested = rested.expect("a frame at rest after reset_springs");
    let after = next_json(&mut ws).await;
    assert_eq!(after["seq"].as_u64().unwrap(), rested + 1 + after["dropped"].as_u64().unwrap());
    assert!(!at_rest(&after["pose"]), "the chain runs again after the reset: {after}");
    app.stop().await;
}

/// The example Fox motion (examples/motions/fox-tail-springs.json) on the
/// Fox imported in metres: its tail swings, nothing else changes.
#[tokio::test]
async fn the_fox_example_swings_its_tail() {
    let app = TestApp::start().await;
    let walk = import_fox_walk(&app).await;
    let example = include_str!("../../../examples/motions/fox-tail-springs.json");
    let mut motion: Value = serde_json::from_str(example).unwrap();
    assert_eq!(motion["layers"][0]["clip"], "name:Walk");
    motion["layers"][0]["clip"] = walk["id"].clone();
    let plain = json!({"layers": motion["layers"]});
    let (with, without) = (pose(&app, &motion, 1.3, "local").await, pose(&app, &plain, 1.3, "local").await);
    let names: Vec<&str> = with["joints"].as_array().unwrap().iter().map(|j| j["name"].as_str().unwrap()).collect();
    for (k, name) in names.iter().enumerate() {
        let turned = with["joints"][k] != without["joints"][k];
        let turns = ["b_Tail01_012", "b_Tail02_013"].contains(name);
        assert_eq!(turned, turns, "{name}: only the tail's turning joints change");
    }
    app.stop().await;
}

/// The tail clip carrying its own chain.
fn sprung_clip() -> String {
    let mut clip: Value = serde_json::from_str(&tail_clip()).unwrap();
    clip["name"] = json!("tailed-with-chains");
    clip["springs"] = chain();
    clip.to_string()
}

async fn bytes(resp: reqwest::Response) -> (u16, Vec<u8>) {
    (resp.status().as_u16(), resp.bytes().await.unwrap().to_vec())
}

/// A clip's pose and samples routes run its chains exactly as `POST
/// /v1/poses` and `/v1/samples` run its one-layer motion (byte for byte),
/// and `springs=false` answers the keyed pose, the tail at rest.
#[tokio::test]
async fn a_clip_s_routes_run_its_chains_as_its_one_layer_motion_does() {
    let app = TestApp::start().await;
    let id = app.create_id(&sprung_clip(), None).await;
    let one_layer = json!({"layers": [{"clip": id}]});
    for (t, space) in [(0.4, "local"), (1.3, "model"), (2.05, "local")] {
        let route = app.http.get(app.url(&format!("/v1/clips/{id}/pose?t={t}&space={space}"))).send().await.unwrap();
        let motion = json!({"motion": one_layer, "time": t, "space": space});
        let composed = app.http.post(app.url("/v1/poses")).json(&motion).send().await.unwrap();
        let ((s1, a), (s2, b)) = (bytes(route).await, bytes(composed).await);
        assert_eq!((s1, s2), (200, 200), "{}", String::from_utf8_lossy(&a));
        assert_eq!(a, b, "the clip route at {t} is the one-layer motion's pose, byte for byte");
        let pose: Value = serde_json::from_slice(&a).unwrap();
        if space == "local" {
            assert!(!at_rest(&pose), "the chain swings at {t}: {pose}");
        }
        // Off: the keyed pose — the hips where the keys put them (hand-computed), the tail at rest.
        let off = app.get_json(&format!("/v1/clips/{id}/pose?t={t}&springs=false")).await;
        let phase = t % 1.0;
        let x = if phase <= 0.5 { 0.6 * phase } else { 0.6 * (1.0 - phase) };
        assert!((numbers(&joint(&off, "hips")["translation"])[0] - x).abs() < 1e-6, "{off}");
        assert!(at_rest(&off), "springs=false: the keyed pose: {off}");
    }
    let times = json!([0.5, 1.0, 1.7]);
    let route = app.http.post(app.url(&format!("/v1/clips/{id}/sample"))).json(&json!({"times": times}));
    let composed = app.http.post(app.url("/v1/samples")).json(&json!({"motion": one_layer, "times": times}));
    let ((s1, a), (s2, b)) = (bytes(route.send().await.unwrap()).await, bytes(composed.send().await.unwrap()).await);
    assert_eq!((s1, s2, &a), (200, 200, &b), "samples: the one-layer motion's, byte for byte");
    let off = json!({"times": times, "springs": false});
    let (status, off) = post(&app, &format!("/v1/clips/{id}/sample"), &off).await;
    assert_eq!(status, 200, "{off}");
    assert!(off["poses"].as_array().unwrap().iter().all(at_rest), "{off}");
    // A motion has no ease: refused while the chains run, fine with them off; a bad switch is refused.
    let eased = app.http.get(app.url(&format!("/v1/clips/{id}/pose?t=0.3&ease=ease_in"))).send().await.unwrap();
    let (status, problem): (u16, Value) = (eased.status().as_u16(), eased.json().await.unwrap());
    assert_eq!((status, &problem["code"]), (400, &json!("unknown_parameter")), "{problem}");
    let eased = app.http.get(app.url(&format!("/v1/clips/{id}/pose?t=0.3&ease=ease_in&springs=false")));
    assert_eq!(eased.send().await.unwrap().status(), 200);
    let bad = app.http.get(app.url(&format!("/v1/clips/{id}/pose?t=0.3&springs=maybe"))).send().await.unwrap();
    let (status, problem): (u16, Value) = (bad.status().as_u16(), bad.json().await.unwrap());
    assert_eq!((status, &problem["code"]), (400, &json!("bad_parameter")), "{problem}");
    app.stop().await;
}

/// gRPC's `Sample` and `SampleBatch` of a clip with chains are
/// `SampleMotion` and `SampleMotionBatch` of its one-layer motion;
/// `without_springs` gives the keyed pose.
#[tokio::test]
async fn grpc_sample_runs_a_clip_s_chains_as_sample_motion_does() {
    use formats::wire::proto::pb;
    let app = TestApp::start().await;
    let id = app.create_id(&sprung_clip(), None).await;
    let mut grpc = app.grpc().await;
    let motion =
        pb::Motion { layers: vec![pb::Layer { clip_id: id.clone(), ..Default::default() }], ..Default::default() };
    for t in [0.4, 1.3] {
        let route = grpc.sample(pb::SampleRequest { clip_id: id.clone(), time: t, ..Default::default() });
        let route = route.await.unwrap().into_inner();
        let composed = pb::SampleMotionRequest { motion: Some(motion.clone()), time: t, ..Default::default() };
        assert_eq!(route, grpc.sample_motion(composed).await.unwrap().into_inner(), "at {t}");
        let off = pb::SampleRequest { clip_id: id.clone(), time: t, without_springs: true, ..Default::default() };
        let off = grpc.sample(off).await.unwrap().into_inner();
        assert_ne!(route, off, "the chain turns the tail at {t}");
        let tail_rotations = |pose: &pb::Pose| pose.rotations[4..16].to_vec();
        assert_eq!(tail_rotations(&off), [0.0, 0.0, 0.0, 1.0].repeat(3), "without_springs: the tail at rest");
    }
    let times = pb::Times { values: vec![0.5, 1.0, 1.7] };
    let when = Some(pb::sample_batch_request::When::Times(times.clone()));
    let batch = pb::SampleBatchRequest { clip_id: id.clone(), when, ..Default::default() };
    let batch = grpc.sample_batch(batch).await.unwrap().into_inner();
    let motion_when = Some(pb::sample_motion_batch_request::When::Times(times));
    let composed = pb::SampleMotionBatchRequest { motion: Some(motion), when: motion_when, ..Default::default() };
    let composed = grpc.sample_motion_batch(composed).await.unwrap().into_inner();
    assert_eq!(batch, composed);
    app.stop().await;
}

/// A clip route whose chains run is priced as its one-layer motion: over
/// a limit its keyed pose stays under, both are refused with the same
/// price in the detail.
#[tokio::test]
async fn a_clip_route_s_chains_are_priced_as_the_motion_s() {
    let app = TestApp::builder().configure(|c| c.limits.max_request_work = 2_000).start().await;
    let id = app.create_id(&sprung_clip(), None).await;
    let keyed = app.http.get(app.url(&format!("/v1/clips/{id}/pose?t=1.3&springs=false"))).send().await.unwrap();
    assert_eq!(keyed.status(), 200, "the keyed pose is far under the limit");
    let route = app.http.get(app.url(&format!("/v1/clips/{id}/pose?t=1.3"))).send().await.unwrap();
    let (status, route): (u16, Value) = (route.status().as_u16(), route.json().await.unwrap());
    let motion = json!({"motion": {"layers": [{"clip": id}]}, "time": 1.3});
    let (motion_status, composed) = post(&app, "/v1/poses", &motion).await;
    assert_eq!((status, &route["code"]), (422, &json!("too_much_work")), "{route}");
    assert_eq!((motion_status, &route["detail"]), (422, &composed["detail"]), "{composed}");
    app.stop().await;
}

/// The first `n` frames of the clip stream of `id` at 60 fps opened with
/// `query`, and the work the open stream holds.
async fn clip_stream(app: &TestApp, id: &str, query: &str, n: usize) -> (Vec<Value>, u64) {
    let mut ws = app.ws(&format!("/v1/clips/{id}/stream?fps=60&{query}")).await;
    let mut frames = Vec::new();
    while frames.len() < n {
        frames.push(next_json(&mut ws).await);
    }
    let held = app.state.work.meter().held();
    drop(ws);
    crate::common::eventually(std::time::Duration::from_secs(5), "the stream's price comes back", || async {
        app.state.work.meter().held() == 0
    })
    .await;
    (frames, held)
}

/// `springs=false` on a clip stream: every frame is the keyed pose the
/// pose route answers at its clip time (`springs=false`), exactly, and the
/// stream is priced without its substeps; with them on the tail swings.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_clip_stream_without_springs_plays_the_keyed_poses() {
    let app = TestApp::start().await;
    let id = app.create_id(&sprung_clip(), None).await;
    let (off, off_held) = clip_stream(&app, &id, "springs=false", 40).await;
    for frame in &off {
        let t = frame["clip_time"].as_f64().unwrap();
        let keyed = app.get_json(&format!("/v1/clips/{id}/pose?t={t}&springs=false")).await;
        assert_eq!(frame["pose"]["joints"], keyed["joints"], "the keyed pose at {t}");
    }
    let (on, on_held) = clip_stream(&app, &id, "", 40).await;
    let swung = on.iter().filter(|f| f["seq"].as_u64().unwrap() > 0 && !at_rest(&f["pose"])).count();
    assert!(swung > 30, "with its springs the tail swings: {swung} of 40 frames");
    // 60 fps at 120 Hz: 2 substeps a frame, each the pose (5 joints) and 3 turning joints × 10, and the
    // frame's share of the 4 skipped ticks' substeps a second may catch up (docs/api.md): ⌈4 × 70 / 60⌉.
    assert_eq!(on_held - off_held, 60 * (2 * (5 + 3 * 10) + 5), "the substeps are all the difference");
    let bad = app.http.get(app.url(&format!("/v1/clips/{id}/stream?springs=no"))).send().await.unwrap();
    assert_eq!(bad.status(), 400);
    app.stop().await;
}

/// gRPC `StreamFrames` with `without_springs`: the keyed poses (gRPC
/// `Sample` with `without_springs` at each frame's clip time); a motion
/// stream refuses the switch.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn grpc_streams_without_springs_play_the_keyed_poses() {
    use formats::wire::proto::pb;
    let app = TestApp::start().await;
    let id = app.create_id(&sprung_clip(), None).await;
    let mut grpc = app.grpc().await;
    let request = |without_springs| pb::StreamRequest {
        clip_id: id.clone(),
        fps: 60,
        max_frames: 30,
        without_springs,
        ..Default::default()
    };
    for without_springs in [true, false] {
        let mut frames = grpc.stream_frames(request(without_springs)).await.unwrap().into_inner();
        let mut differ = 0;
        while let Some(frame) = frames.message().await.unwrap() {
            let time = f64::from(frame.clip_time);
            let keyed = pb::SampleRequest { clip_id: id.clone(), time, without_springs: true, ..Default::default() };
            let keyed = grpc.sample(keyed).await.unwrap().into_inner();
            let pose = frame.pose.unwrap();
            if without_springs {
                assert_eq!(pose.rotations, keyed.rotations, "the keyed pose at {time}");
                assert_eq!(pose.translations, keyed.translations, "the keyed pose at {time}");
            } else if pose.rotations != keyed.rotations {
                differ += 1;
            }
        }
        assert!(without_springs || differ > 20, "with springs the tail turns: {differ} of 30 frames differ");
    }
    let motion =
        pb::Motion { layers: vec![pb::Layer { clip_id: id.clone(), ..Default::default() }], ..Default::default() };
    let on_motion = pb::StreamRequest { motion: Some(motion), fps: 30, without_springs: true, ..Default::default() };
    let status = grpc.stream_frames(on_motion).await.unwrap_err();
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "unknown_parameter");
    assert!(status.message().contains("/without_springs"), "{}", status.message());
    app.stop().await;
}

/// The Fox imported in metres: the summary of its Walk clip.
async fn import_fox_walk(app: &TestApp) -> Value {
    let glb = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/gltf/Fox/Fox.glb")).unwrap();
    let url = app.url("/v1/clips/import?format=glb&scale=0.01");
    let resp = app.http.post(url).header("content-type", "application/octet-stream").body(glb).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let imported: Value = resp.json().await.unwrap();
    imported["clips"].as_array().unwrap().iter().find(|c| c["name"] == "Walk").expect("a Walk clip").clone()
}

/// The Fox's Walk as a clip carrying the example's tail chain
/// (examples/motions/fox-tail-springs.json); its id.
async fn fox_walk_with_tail_springs(app: &TestApp) -> String {
    let walk = import_fox_walk(app).await;
    let mut doc = app.get_json(&format!("/v1/clips/{}", walk["id"].as_str().unwrap())).await;
    let example: Value = serde_json::from_str(include_str!("../../../examples/motions/fox-tail-springs.json")).unwrap();
    doc["springs"] = example["springs"].clone();
    doc["name"] = json!("Walk with its tail");
    app.create_id(&doc.to_string(), None).await
}

/// gRPC `SampleStream` of a clip with chains answers the poses
/// `SampleBatch` answers, byte for byte, over several messages (one
/// simulation through them all); `without_springs` too, and the two differ.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn grpc_sample_stream_runs_a_clip_s_chains_as_sample_batch_does() {
    use formats::wire::proto::pb;
    use prost::Message as _;
    let app = TestApp::start().await;
    let id = fox_walk_with_tail_springs(&app).await;
    let mut grpc = app.grpc().await;
    let range = pb::FrameRange { start: 0.0, end: 40.0, fps: 60.0 };
    let request = |without_springs| pb::SampleBatchRequest {
        clip_id: id.clone(),
        when: Some(pb::sample_batch_request::When::Range(range)),
        without_springs,
        ..Default::default()
    };
    let mut answers = Vec::new();
    for without_springs in [false, true] {
        let batch = grpc.sample_batch(request(without_springs)).await.unwrap().into_inner();
        let mut messages = grpc.sample_stream(request(without_springs)).await.unwrap().into_inner();
        let (mut streamed, mut count) = (Vec::new(), 0);
        while let Some(message) = messages.message().await.unwrap() {
            if count == 0 {
                assert_eq!(message.joint_names, batch.joint_names);
            }
            streamed.extend(message.poses);
            count += 1;
        }
        assert!(count > 1, "the answer takes several messages: {count}");
        let bytes = |poses: &[pb::Pose]| poses.iter().map(|p| p.encode_to_vec()).collect::<Vec<_>>();
        assert_eq!(streamed.len(), batch.poses.len());
        assert!(bytes(&streamed) == bytes(&batch.poses), "SampleStream's poses are SampleBatch's");
        answers.push(batch);
    }
    let tail = answers[0].joint_names.iter().position(|n| n == "b_Tail02_013").unwrap();
    let rotation = |pose: &pb::Pose| pose.rotations[4 * tail..4 * tail + 4].to_vec();
    let (on, off) = (&answers[0].poses[90], &answers[1].poses[90]);
    assert_ne!(rotation(on), rotation(off), "the chain turns the tail at 1.5 s");
    app.stop().await;
}

/// A crossfade on a clip stream with chains is priced with its substeps
/// evaluating both motions, and over `max_request_work` it is refused
/// `too_much_work` while the stream goes on.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_crossfades_substeps_are_priced_on_both_motions() {
    let fade = |id: &str| json!({"op": "crossfade", "to": {"layers": [{"clip": id}]}, "duration": 30});
    let app = TestApp::start().await;
    let id = app.create_id(&sprung_clip(), None).await;
    let meter = app.state.work.meter();
    let mut ws = app.ws(&format!("/v1/clips/{id}/stream?fps=60")).await;
    next_json(&mut ws).await;
    let opened = meter.held();
    send(&mut ws, fade(&id)).await;
    // A frame was 5 + 2 × (5 + 30); fading, each of the 2 substeps evaluates both 5-joint motions: 10 + 2 × (10 + 30);
    // each with its share of the substeps of 4 skipped ticks a second may catch up: ⌈4 × 70 / 60⌉, ⌈4 × 80 / 60⌉.
    let fading = opened + 60 * ((10 + 2 * (10 + 30) + 6) - (5 + 2 * (5 + 30) + 5));
    crate::common::eventually(std::time::Duration::from_secs(5), "the crossfade is charged", || async {
        meter.held() == fading
    })
    .await;
    drop(ws);
    app.stop().await;
    // One unit under that price: the stream opens, its crossfade is refused, and it goes on.
    let app = TestApp::builder().configure(|c| c.limits.max_request_work = fading - 1).start().await;
    let id = app.create_id(&sprung_clip(), None).await;
    let mut ws = app.ws(&format!("/v1/clips/{id}/stream?fps=60")).await;
    next_json(&mut ws).await;
    assert_eq!(app.state.work.meter().held(), opened, "the same stream, the same price");
    send(&mut ws, fade(&id)).await;
    let problem = loop {
        if let Some(problem) = next_json(&mut ws).await.get("error") {
            break problem.clone();
        }
    };
    assert_eq!((problem["code"].as_str(), problem["status"].as_u64()), (Some("too_much_work"), Some(422)));
    assert!(problem["detail"].as_str().unwrap().contains(&fading.to_string()), "{problem}");
    let seqs: Vec<u64> = {
        let mut seqs = Vec::new();
        while seqs.len() < 3 {
            seqs.push(next_json(&mut ws).await["seq"].as_u64().expect("a frame"));
        }
        seqs
    };
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "the stream goes on: {seqs:?}");
    assert_eq!(app.state.work.meter().held(), opened, "holding what it held");
    app.stop().await;
}
