//! A graph played on a character (docs/graphs.md, “What composes with a
//! graph”), against the real server: the CMU take 131_01 and the same take
//! played slower, in a synced 1D blend at a fixed parameter, on CesiumMan.
//! Each tick's pose is the clip motion of the same two layers at the
//! weights the graph reports, in one sync group, on the same character (the
//! independent path: a clip motion retargets each layer, then mixes them);
//! a graph over clips the character cannot map, a missing character and
//! bad retarget options are refused where a clip motion's are; a tick is
//! priced as the clip motion's pose, retargets included; its root motion on
//! the character is the clip motion's.

use serde_json::{Value, json};

use super::TestApp;
use super::character_routes::take_and_cesium;

const FPS: f64 = 30.0;
const LAST_TICK: u64 = 45;

async fn send(app: &TestApp, path: &str, body: &Value) -> (u16, Value) {
    let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
    let status = resp.status().as_u16();
    (status, resp.json().await.unwrap_or(Value::Null))
}

/// The clip `id`'s document with every key time stretched by `factor`,
/// stored as `name`: the same motion, played slower.
async fn stretched(app: &TestApp, id: &str, name: &str, factor: f64) -> String {
    let mut doc = app.get_json(&format!("/v1/clips/{id}")).await;
    doc["name"] = json!(name);
    for track in doc["tracks"].as_array_mut().unwrap() {
        let times = track["times"].as_array_mut().expect("every track has times");
        times.iter_mut().for_each(|t| *t = json!(t.as_f64().unwrap() * factor));
    }
    app.create_id(&doc.to_string(), None).await
}

/// The take and its slower copy blended on `pace` (0: the take, 1: the
/// copy), synced; the graph's id.
pub(crate) async fn pace_graph(app: &TestApp, take: &str) -> String {
    let slow = stretched(app, take, "131_01-slow", 1.6).await;
    let doc = json!({
        "name": "pace",
        "parameters": {"pace": {"type": "float", "default": 0.3, "min": 0, "max": 1}},
        "nodes": {"walk": {"blend1d": {"parameter": "pace", "points": [{"clip": take, "at": 0}, {"clip": slow, "at": 1}]}}},
        "output": "walk",
    });
    let resp = app.http.post(app.url("/v1/graphs")).json(&doc).send().await.unwrap();
    let created: Value = resp.json().await.unwrap();
    created["id"].as_str().unwrap_or_else(|| panic!("{created}")).to_owned()
}

/// The clip ids a graph names, in its document's order.
async fn graph_clips(app: &TestApp, graph: &str) -> Vec<String> {
    let doc = app.get_json(&format!("/v1/graphs/{graph}")).await;
    let points = doc["nodes"]["walk"]["blend1d"]["points"].as_array().unwrap().clone();
    points.iter().map(|p| p["clip"].as_str().unwrap().to_owned()).collect()
}

/// A pose's numbers (every joint's translation, rotation and scale) in order.
fn numbers(pose: &Value) -> Vec<f64> {
    let joints = pose["joints"].as_array().unwrap();
    let parts = |j: &Value| ["translation", "rotation", "scale"].map(|p| j[p].as_array().unwrap().clone()).concat();
    joints.iter().flat_map(parts).map(|x| x.as_f64().unwrap()).collect()
}

/// The character's joint names, from its stored document.
async fn joint_names(app: &TestApp, character: &str) -> Vec<Value> {
    let doc = app.get_json(&format!("/v1/characters/{character}")).await;
    doc["skeleton"]["joints"].as_array().unwrap().iter().map(|j| j["name"].clone()).collect()
}

#[tokio::test]
async fn a_graph_on_a_character_is_its_layers_clip_motion_on_the_character() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let graph = pace_graph(&app, &take).await;
    let end = LAST_TICK as f64 / FPS;
    let body = json!({"motion": {"layers": [{"graph": graph}], "character": cesium}, "start": 0, "end": end,
                      "fps": FPS, "report": true, "space": "model"});
    let (status, answer) = send(&app, "/v1/samples", &body).await;
    assert_eq!(status, 200, "{answer}");
    let poses = answer["poses"].as_array().unwrap();
    assert_eq!(poses.len() as u64, LAST_TICK + 1);
    // The line's weights at 0.3: 0.7 of the take, 0.3 of the slower copy.
    let weights: Vec<f64> =
        poses[0]["graph"]["weights"]["walk"].as_array().unwrap().iter().map(|w| w.as_f64().unwrap()).collect();
    assert!((weights[0] - 0.7).abs() < 1e-9 && (weights[1] - 0.3).abs() < 1e-9, "{weights:?}");
    let names = joint_names(&app, &cesium).await;
    let answered: Vec<Value> = poses[0]["joints"].as_array().unwrap().iter().map(|j| j["name"].clone()).collect();
    assert_eq!(answered, names, "the character's joints, in its order");

    // The same layers as a clip motion on the character: the second layer
    // at w₂ / (w₁ + w₂), both in one sync group, at the ticks' times.
    let clips = graph_clips(&app, &graph).await;
    let layers = json!([{"clip": clips[0], "sync": "pace"},
                        {"clip": clips[1], "sync": "pace", "weight": weights[1] / (weights[0] + weights[1])}]);
    let times: Vec<f64> = (0..=LAST_TICK).map(|k| k as f64 / FPS).collect();
    let clip_motion = json!({"motion": {"layers": layers, "character": cesium}, "times": times, "space": "model"});
    let (status, want) = send(&app, "/v1/samples", &clip_motion).await;
    assert_eq!(status, 200, "{want}");
    let mut moved = 0.0f64;
    for (k, (got, want)) in poses.iter().zip(want["poses"].as_array().unwrap()).enumerate() {
        let (got, want) = (numbers(got), numbers(want));
        assert_eq!(got.len(), want.len());
        let worst = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst <= 1e-5, "tick {k}: {worst} from the clip motion on the character");
        moved = moved.max(got.iter().zip(numbers(&poses[0])).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max));
    }
    assert!(moved > 0.01, "the take moves the character: {moved}");

    // One pose is the samples' pose of its tick, byte for byte.
    let one = json!({"motion": {"layers": [{"graph": graph}], "character": cesium}, "time": 0.5, "fps": FPS,
                     "report": true, "space": "model"});
    let (status, pose) = send(&app, "/v1/poses", &one).await;
    assert_eq!(status, 200, "{pose}");
    assert_eq!(pose, poses[15], "tick 15 at {FPS} fps");
    app.stop().await;
}

#[tokio::test]
async fn a_graph_on_a_character_is_refused_where_a_clip_motion_on_it_is() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let graph = pace_graph(&app, &take).await;
    let over = |extra: Value| {
        let mut motion = json!({"layers": [{"graph": graph}]});
        motion.as_object_mut().unwrap().extend(extra.as_object().unwrap().clone());
        json!({"motion": motion, "start": 0, "end": 1})
    };
    let missing = over(json!({"character": "no-such-character"}));
    let (status, problem) = send(&app, "/v1/samples", &missing).await;
    assert_eq!((status, problem["code"].as_str()), (404, Some("character_not_found")), "{problem}");
    assert_eq!(problem["pointer"], "/motion/character");

    let bad_pose =
        over(json!({"character": cesium, "retarget": {"target_pose": {"rotations": {"nope": [0, 0, 0, 1]}}}}));
    let (status, problem) = send(&app, "/v1/samples", &bad_pose).await;
    assert_eq!((status, problem["code"].as_str()), (422, Some("unknown_joint")), "{problem}");
    assert_eq!(problem["pointer"], "/motion/retarget/target_pose/rotations/nope");

    // A two-joint rig shares no hips with CesiumMan: its clips cannot play there.
    let mover = json!({
        "name": "mover",
        "skeleton": {"joints": [{"name": "a", "parent": null}, {"name": "b", "parent": "a"}]},
        "tracks": [{"joint": "a", "channel": "translation", "times": [0, 1], "values": [[0, 0, 0], [1, 0, 0]]}],
    });
    let mover = app.create_id(&mover.to_string(), None).await;
    let doc = json!({"name": "tiny", "parameters": {}, "nodes": {"n": {"clip": mover}}, "output": "n"});
    let tiny: Value = app.post_json("/v1/graphs", &doc).await;
    let tiny = tiny["id"].as_str().unwrap_or_else(|| panic!("{tiny}"));
    let body = json!({"motion": {"layers": [{"graph": tiny}], "character": cesium}, "start": 0, "end": 1});
    let (status, problem) = send(&app, "/v1/samples", &body).await;
    assert_eq!((status, problem["code"].as_str()), (422, Some("unmappable_skeleton")), "{problem}");
    assert_eq!(problem["pointer"], "/motion/character");
    assert!(problem["detail"].as_str().unwrap().contains("/nodes/n"), "{problem}");
    app.stop().await;
}

/// The work units per pose a `too_much_work` refusal of `body` names.
async fn units_per_pose(app: &TestApp, body: &Value) -> u64 {
    let (status, problem) = send(app, "/v1/samples", body).await;
    assert_eq!((status, problem["code"].as_str()), (422, Some("too_much_work")), "{problem}");
    let detail = problem["detail"].as_str().unwrap();
    let after = detail.split(" poses × ").nth(1).unwrap_or_else(|| panic!("{detail}"));
    after.split(' ').next().unwrap().parse().unwrap()
}

#[tokio::test]
async fn a_graph_tick_on_a_character_pays_its_layers_retargets_as_a_clip_motion_s_pose_does() {
    let app = TestApp::builder().configure(|c| c.limits.max_request_work = 10_000_000).start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let graph = pace_graph(&app, &take).await;
    // One answered tick at 1666 s, 399,841 played at 240 fps: over the limit either way.
    let at = |character: Option<&str>| {
        let mut motion = json!({"layers": [{"graph": graph}]});
        if let Some(c) = character {
            motion["character"] = json!(c);
        }
        json!({"motion": motion, "start": 1666, "end": 1666, "fps": 240})
    };
    let plain = units_per_pose(&app, &at(None)).await;
    let on_cesium = units_per_pose(&app, &at(Some(&cesium))).await;
    let take_joints = app.get_json(&format!("/v1/clips/{take}/skeleton")).await["joints"].as_array().unwrap().len();
    let cesium_joints =
        app.get_json(&format!("/v1/characters/{cesium}")).await["skeleton"]["joints"].as_array().unwrap().len();
    assert_eq!(plain, 2 * take_joints as u64, "a tick of the blend samples its two layers' joints");
    // docs/motion.md, “Playing a take on a character”: a retargeted layer adds a pass over its clip and the character.
    assert_eq!(on_cesium, plain + 2 * (take_joints + cesium_joints) as u64);
    app.stop().await;
}

#[tokio::test]
async fn a_graph_on_a_character_travels_as_its_layers_clip_motion_does() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let graph = pace_graph(&app, &take).await;
    let root = json!({"mode": "extract"});
    let end = LAST_TICK as f64 / FPS;
    let motion = json!({"layers": [{"graph": graph}], "character": cesium, "root_motion": root});
    let (status, answer) =
        send(&app, "/v1/samples", &json!({"motion": motion, "start": 0, "end": end, "fps": FPS})).await;
    assert_eq!(status, 200, "{answer}");
    let clips = graph_clips(&app, &graph).await;
    let layers = json!([{"clip": clips[0], "sync": "pace"}, {"clip": clips[1], "sync": "pace", "weight": 0.3}]);
    let times: Vec<f64> = (0..=LAST_TICK).map(|k| k as f64 / FPS).collect();
    let clip_motion = json!({"layers": layers, "character": cesium, "root_motion": root});
    let (status, want) = send(&app, "/v1/samples", &json!({"motion": clip_motion, "times": times})).await;
    assert_eq!(status, 200, "{want}");
    let travel = |pose: &Value, which: &str| -> Vec<f64> {
        let part = &pose["root_motion"][which];
        let t = part["translation"].as_array().unwrap_or_else(|| panic!("{pose}"));
        t.iter().chain([&part["yaw"]]).map(|x| x.as_f64().unwrap()).collect()
    };
    let (got, want) = (answer["poses"].as_array().unwrap(), want["poses"].as_array().unwrap());
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        for which in ["delta", "total"] {
            let worst = travel(g, which).iter().zip(travel(w, which)).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(worst <= 1e-5, "tick {k}'s {which}: {worst} from the clip motion's");
        }
    }
    let total = travel(&got[LAST_TICK as usize], "total");
    // The take's first 1.5 s mostly turn on the spot.
    assert!(total[0].hypot(total[2]) > 1e-3 && total[3].abs() > 0.1, "the character moves: {total:?}");
    app.stop().await;
}
