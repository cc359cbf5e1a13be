//! Sampling a stored graph over REST (docs/graphs.md, “Using a graph”): a
//! motion whose only layer names `"graph"`, played on the tick grid with
//! timed `inputs`, against the real server. The Fox's shipped graph goes
//! through the state schedule the formats test holds; a one-clip graph's
//! poses are the clip's own; every tick played is priced; bad inputs are
//! 422 with pointers.

use serde_json::{Value, json};

use super::TestApp;

async fn send(app: &TestApp, path: &str, body: &Value) -> (u16, Value) {
    let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
    let status = resp.status().as_u16();
    let text = resp.text().await.unwrap();
    (status, serde_json::from_str(&text).unwrap_or(Value::Null))
}

/// Stores `doc` as a graph (with `token` if given); its id.
async fn store_graph_as(app: &TestApp, doc: &Value, token: Option<&str>) -> String {
    let mut req = app.http.post(app.url("/v1/graphs")).json(doc);
    if let Some(t) = token {
        req = req.bearer_auth(t);
    }
    let resp = req.send().await.unwrap();
    let status = resp.status().as_u16();
    let created: Value = resp.json().await.unwrap_or(Value::Null);
    assert_eq!(status, 201, "{created}");
    created["id"].as_str().unwrap().to_owned()
}

/// Stores `doc` as a graph; its id.
async fn store_graph(app: &TestApp, doc: &Value) -> String {
    store_graph_as(app, doc, None).await
}

fn over(graph: &str) -> Value {
    json!({"layers": [{"graph": graph}]})
}

/// The Fox imported, and `examples/graphs/fox-locomotion.json` stored with
/// its `name:X` clips replaced by ids, as docs/graphs.md shows.
pub(crate) async fn fox_graph(app: &TestApp) -> (String, f64) {
    fox_graph_as(app, None).await
}

/// [`fox_graph`] on a server whose writes need `token`.
pub(crate) async fn fox_graph_as(app: &TestApp, token: Option<&str>) -> (String, f64) {
    let glb = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/gltf/Fox/Fox.glb")).unwrap();
    let mut req = app.http.post(app.url("/v1/clips/import?replace=true")).body(glb);
    if let Some(t) = token {
        req = req.bearer_auth(t);
    }
    let resp = req.send().await.unwrap();
    assert!(resp.status().is_success(), "{}", resp.text().await.unwrap());
    let mut text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/graphs/fox-locomotion.json")).unwrap();
    let mut survey = 0.0;
    for name in ["Survey", "Walk", "Run"] {
        let list = app.get_json(&format!("/v1/clips?name={name}")).await;
        let clip = &list["clips"][0];
        text = text.replace(&format!("name:{name}"), clip["id"].as_str().unwrap());
        if name == "Survey" {
            survey = clip["duration"].as_f64().unwrap();
        }
    }
    (store_graph_as(app, &serde_json::from_str(&text).unwrap(), token).await, survey)
}

#[tokio::test]
async fn the_fox_graph_walks_runs_and_surveys_over_rest() {
    let app = TestApp::start().await;
    let (graph, survey) = fox_graph(&app).await;
    let body = json!({
        "motion": over(&graph), "start": 0, "end": 8, "report": true,
        "inputs": [{"time": 7, "set": {"speed": 0}}, {"time": 1, "set": {"speed": 2.5}},
                   {"time": 2, "set": {"survey": true}}],
    });
    let (status, answer) = send(&app, "/v1/samples", &body).await;
    assert_eq!(status, 200, "{answer}");
    let poses = answer["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 481, "ticks 0..=480 at the default 60 fps");
    let mut states: Vec<(u64, String)> = Vec::new();
    for (k, pose) in poses.iter().enumerate() {
        // serde_json's default parsing may miss an f64 by an ulp.
        assert!((pose["time"].as_f64().unwrap() - k as f64 / 60.0).abs() < 1e-12);
        let state = pose["graph"]["state"].as_str().unwrap();
        if states.last().is_none_or(|(_, s)| s != state) {
            states.push((k as u64, state.to_owned()));
        }
    }
    // The look (Survey once, from tick 120) exits at the first tick where
    // (k − 120)/60 s has played 0.9 of Survey's length (3.4166667 s: 305).
    let back = (121..).find(|&k: &u64| (k - 120) as f64 / 60.0 / survey >= 0.9).unwrap();
    let expected: Vec<(u64, String)> = [(0, "idle"), (60, "move"), (120, "look"), (back, "move"), (420, "idle")]
        .iter()
        .map(|&(k, s)| (k, s.to_owned()))
        .collect();
    assert_eq!(states, expected);
    // At 2.5 the move blend is a quarter walk, three quarters run.
    let weights = &poses[100]["graph"]["weights"]["move"];
    assert_eq!(weights, &json!([0.25, 0.75]), "{}", poses[100]["graph"]);
    // The tick that fires the survey transition reports it at α 0.
    assert_eq!(poses[120]["graph"]["transition"], json!({"from": "move", "to": "look", "alpha": 0.0}));
}

/// A one-second clip on `hips`–`spine` whose hips translate linearly from
/// 0 to `to` on x.
fn mover(name: &str, to: f32) -> String {
    json!({
        "name": name,
        "skeleton": {"joints": [{"name": "hips", "parent": null}, {"name": "spine", "parent": "hips"}]},
        "tracks": [{"joint": "hips", "channel": "translation", "interpolation": "linear",
                    "times": [0, 1], "values": [[0, 0, 0], [to, 0, 0]]}],
    })
    .to_string()
}

/// `slow` (x to 1) and `fast` (x to 3) in a blend on `speed` 1..3, behind
/// an `idle` state (`slow`) left when `go` is true.
async fn two_speed_graph(app: &TestApp) -> String {
    let slow = app.create_id(&mover("slow", 1.0), None).await;
    let fast = app.create_id(&mover("fast", 3.0), None).await;
    store_graph(
        app,
        &json!({
            "name": "two-speed",
            "parameters": {"speed": {"type": "float", "default": 1, "min": 1, "max": 3},
                           "go": {"type": "bool"}},
            "nodes": {
                "idle": {"clip": slow},
                "move": {"blend1d": {"parameter": "speed", "points": [{"clip": slow, "at": 1}, {"clip": fast, "at": 3}]}}},
            "machine": {"initial": "idle",
                "states": {"idle": {"node": "idle"}, "move": {"node": "move"}},
                "transitions": [{"from": "idle", "to": "move", "when": {"parameter": "go", "eq": true}, "duration": 0}]}
        }),
    )
    .await
}

fn hips_x(pose: &Value) -> f64 {
    pose["joints"][0]["translation"][0].as_f64().unwrap()
}

#[tokio::test]
async fn a_graph_plays_its_inputs_at_their_ticks_and_answers_from_start() {
    let app = TestApp::start().await;
    let graph = two_speed_graph(&app).await;
    // go at 0.25 s (tick 5 at 20 fps), speed 2 at 0.5 s (tick 10): from tick
    // 5 the move node's time runs from 0; at speed 2 the blend is half slow,
    // half fast, so the hips are at x = τ·(1 + 3)/2 (each clip loops at 1 s).
    let body = json!({
        "motion": over(&graph), "start": 0.5, "end": 0.8, "fps": 20,
        "inputs": [{"time": 0.5, "set": {"speed": 2}}, {"time": 0.25, "set": {"go": true}}],
    });
    let (status, answer) = send(&app, "/v1/samples", &body).await;
    assert_eq!(status, 200, "{answer}");
    let poses = answer["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 7, "ticks 10..=16");
    for (i, pose) in poses.iter().enumerate() {
        let k = 10 + i as u64;
        assert_eq!(pose["clip"], json!(graph), "a graph's pose names the graph");
        assert!((pose["time"].as_f64().unwrap() - k as f64 / 20.0).abs() < 1e-12);
        assert!(pose.get("graph").is_none(), "no report unless asked");
        // The transition fires on tick 5 (no duration): tick 6 is the move
        // node's first advance of 1/20 s, tick k its (k − 5)/20 s.
        let tau = (k - 5) as f64 / 20.0;
        let expected = 0.5 * tau + 0.5 * 3.0 * tau;
        assert!((hips_x(pose) - expected).abs() < 1e-5, "tick {k}: x {} ≠ {expected}", hips_x(pose));
    }
}

#[tokio::test]
async fn every_tick_played_is_priced_not_only_the_answered_ones() {
    let app = TestApp::builder().configure(|c| c.limits.max_request_work = 2_000_000).start().await;
    let graph = two_speed_graph(&app).await;
    let late = json!({"motion": over(&graph), "start": 3600, "end": 3600, "fps": 240});
    let (status, problem) = send(&app, "/v1/samples", &late).await;
    assert_eq!((status, problem["code"].as_str()), (422, Some("too_much_work")), "{problem}");
    let early = json!({"motion": over(&graph), "start": 0, "end": 0, "fps": 240});
    let (status, answer) = send(&app, "/v1/samples", &early).await;
    assert_eq!(status, 200, "{answer}");
}

#[tokio::test]
async fn bad_graph_requests_are_422_at_their_pointers() {
    let app = TestApp::start().await;
    let graph = two_speed_graph(&app).await;
    let cases = [
        (json!({"motion": over(&graph), "times": [0.1]}), "graph_needs_ticks", "/times"),
        (
            json!({"motion": over(&graph), "start": 0, "end": 1, "inputs": [{"time": 0, "set": {"nope": 1}}]}),
            "unknown_parameter",
            "/inputs/0/set/nope",
        ),
        (
            json!({"motion": over(&graph), "start": 0, "end": 1, "inputs": [{"time": 0.1, "set": {"speed": 9}}]}),
            "parameter_out_of_range",
            "/inputs/0/set/speed",
        ),
        (
            json!({"motion": over(&graph), "start": 0, "end": 1,
                "inputs": [{"time": 0, "set": {}}, {"time": 0, "set": {"go": 1}}]}),
            "parameter_type",
            "/inputs/1/set/go",
        ),
        (
            json!({"motion": over(&graph), "start": 0, "end": 1, "inputs": [{"time": -1, "set": {}}]}),
            "bad_time",
            "/inputs/0/time",
        ),
        (json!({"motion": over(&graph), "start": 0, "end": 1, "fps": 500}), "fps_out_of_range", "/fps"),
        (json!({"motion": over(&graph), "start": 1, "end": 0}), "bad_range", "/end"),
        (json!({"motion": over(&graph)}), "times_or_range", ""),
        (
            json!({"motion": {"layers": [{"graph": graph, "offset": 0.5}]}, "start": 0, "end": 1}),
            "graph_unsupported",
            "/motion/layers/0/offset",
        ),
        (
            json!({"motion": {"layers": [{"graph": graph}, {"graph": graph, "weight": 0.5}]}, "start": 0, "end": 1}),
            "graph_unsupported",
            "/motion/layers/1/graph",
        ),
        (
            json!({"motion": {"layers": [{"graph": graph, "playback": "once"}, {"graph": graph}]}, "start": 0, "end": 1}),
            "graph_unsupported",
            "/motion/layers/1/graph",
        ),
        (
            json!({"motion": {"layers": [{"graph": graph, "mode": "additive"}], "root_motion": {}}, "start": 0, "end": 1}),
            "graph_unsupported",
            "/motion/root_motion",
        ),
        (
            json!({"motion": {"layers": [{"graph": graph}], "root_motion": {"joint": "nope"}}, "start": 0, "end": 1}),
            "unknown_joint",
            "/motion/root_motion/joint",
        ),
        (
            json!({"motion": {"layers": [{"clip": "x"}]}, "start": 0, "end": 1, "fps": 10, "report": true}),
            "graph_unsupported",
            "/report",
        ),
    ];
    for (body, code, pointer) in cases {
        let (status, problem) = send(&app, "/v1/samples", &body).await;
        assert_eq!(
            (status, problem["code"].as_str(), problem["pointer"].as_str()),
            (422, Some(code), Some(pointer)),
            "{body}: {problem}"
        );
    }
    let missing = json!({"motion": over("no-such-graph"), "start": 0, "end": 1});
    let (status, problem) = send(&app, "/v1/samples", &missing).await;
    assert_eq!((status, problem["code"].as_str()), (404, Some("graph_not_found")), "{problem}");
    assert_eq!(problem["pointer"], "/motion/layers/0/graph");
    let no_clip = json!({"motion": {"layers": [{"graph": graph}, {"clip": "no-such-clip"}]}, "start": 0, "end": 1});
    let (status, problem) = send(&app, "/v1/samples", &no_clip).await;
    assert_eq!((status, problem["code"].as_str()), (404, Some("clip_not_found")), "{problem}");
    assert_eq!(problem["pointer"], "/motion/layers/1/clip");
    app.stop().await;
}

/// A pose's numbers (every joint's translation, rotation and scale) in order.
fn numbers(pose: &Value) -> Vec<f64> {
    let joints = pose["joints"].as_array().unwrap();
    let parts = |j: &Value| ["translation", "rotation", "scale"].map(|p| j[p].as_array().unwrap().clone()).concat();
    joints.iter().flat_map(parts).map(|x| x.as_f64().unwrap()).collect()
}

/// `POST /v1/poses` over a graph answers the pose `/v1/samples` answers
/// for the last tick at or before `time`, report included: on a tick, just
/// after one and just before the next, at two grids and both spaces.
#[tokio::test]
async fn a_graph_pose_is_the_samples_pose_of_the_last_tick_at_or_before_its_time() {
    let app = TestApp::start().await;
    let (graph, _) = fox_graph(&app).await;
    let inputs = json!([{"time": 1, "set": {"speed": 2.5}}, {"time": 2, "set": {"survey": true}}]);
    for (fps, space) in [(60.0, "local"), (24.0, "model")] {
        let body = json!({"motion": over(&graph), "start": 0, "end": 3, "fps": fps, "space": space,
                          "inputs": inputs, "report": true});
        let (status, samples) = send(&app, "/v1/samples", &body).await;
        assert_eq!(status, 200, "{samples}");
        let poses = samples["poses"].as_array().unwrap();
        // 0.1 s at 60 fps is tick 6 (0.1 · 60 is 6.000000000000001 in f64).
        for (time, tick) in [
            (0.0, 0),
            (0.1, (0.1 * fps + 1e-9) as usize),
            (1.0, fps as usize),
            (1.0 + 0.4 / fps, fps as usize),
            (2.0 - 0.01 / fps, 2 * fps as usize - 1),
            (2.5, (2.5 * fps) as usize),
            (3.0, 3 * fps as usize),
        ] {
            let body = json!({"motion": over(&graph), "time": time, "fps": fps, "space": space,
                              "inputs": inputs, "report": true});
            let (status, pose) = send(&app, "/v1/poses", &body).await;
            assert_eq!(status, 200, "{pose}");
            let expected = &poses[tick];
            assert_eq!(pose["graph"], expected["graph"], "t {time}: tick {tick}'s report");
            assert!((pose["time"].as_f64().unwrap() - tick as f64 / fps).abs() < 1e-12, "t {time}: {}", pose["time"]);
            let (got, want) = (numbers(&pose), numbers(expected));
            assert_eq!(got.len(), want.len());
            let worst = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(worst <= 1e-6, "t {time} at {fps} fps, {space}: {worst}");
            assert_eq!(&pose, expected, "t {time}: the same writer, the same bytes");
        }
    }
    // The viewer's paused pose: its held settings at 0, the page's fps, a report.
    let body = json!({"motion": over(&graph), "time": 1.5, "space": "local",
                      "inputs": [{"time": 0, "set": {"speed": 2.5}}], "fps": 60, "report": true});
    let (status, pose) = send(&app, "/v1/poses", &body).await;
    assert_eq!(status, 200, "{pose}");
    assert_eq!(pose["clip"], json!(graph));
    assert_eq!(pose["graph"]["state"], "move", "{pose}");
    app.stop().await;
}

#[tokio::test]
async fn a_graph_pose_prices_every_tick_before_it_and_refuses_as_samples_do() {
    let app = TestApp::builder().configure(|c| c.limits.max_request_work = 2_000_000).start().await;
    let graph = two_speed_graph(&app).await;
    let late = json!({"motion": over(&graph), "time": 3600, "fps": 240});
    let (status, problem) = send(&app, "/v1/poses", &late).await;
    assert_eq!((status, problem["code"].as_str()), (422, Some("too_much_work")), "{problem}");
    let early = json!({"motion": over(&graph), "time": 0.5, "fps": 240});
    let (status, pose) = send(&app, "/v1/poses", &early).await;
    assert_eq!(status, 200, "{pose}");
    let clip = json!({"layers": [{"clip": "x"}]});
    let cases = [
        (json!({"motion": over(&graph), "time": -0.5}), "bad_range", "/time"),
        (json!({"motion": over(&graph), "time": 1, "fps": 0}), "fps_out_of_range", "/fps"),
        (json!({"motion": over(&graph), "time": 1, "fps": 241}), "fps_out_of_range", "/fps"),
        (
            json!({"motion": over(&graph), "time": 1, "inputs": [{"time": 0, "set": {"nope": true}}]}),
            "unknown_parameter",
            "/inputs/0/set/nope",
        ),
        (
            json!({"motion": over(&graph), "time": 1, "inputs": [{"time": 0.2, "set": {"speed": 0}}]}),
            "parameter_out_of_range",
            "/inputs/0/set/speed",
        ),
        (json!({"motion": over(&graph), "time": 1, "inputs": [{"time": -1, "set": {}}]}), "bad_time", "/inputs/0/time"),
        (json!({"motion": over(&graph), "time": 1, "parameters": ["p"]}), "graph_unsupported", "/parameters"),
        (
            json!({"motion": {"layers": [{"graph": graph, "speed": 2}]}, "time": 1}),
            "graph_unsupported",
            "/motion/layers/0/speed",
        ),
        (json!({"motion": clip, "time": 1, "report": true}), "graph_unsupported", "/report"),
        (json!({"motion": clip, "time": 1, "inputs": []}), "graph_unsupported", "/inputs"),
        (json!({"motion": clip, "time": 1, "fps": 30}), "graph_unsupported", "/fps"),
    ];
    for (body, code, pointer) in cases {
        let (status, problem) = send(&app, "/v1/poses", &body).await;
        assert_eq!(
            (status, problem["code"].as_str(), problem["pointer"].as_str()),
            (422, Some(code), Some(pointer)),
            "{body}: {problem}"
        );
    }
    let missing = json!({"motion": over("name:nothing"), "time": 0});
    let (status, problem) = send(&app, "/v1/poses", &missing).await;
    assert_eq!((status, problem["code"].as_str()), (404, Some("graph_not_found")), "{problem}");
    assert_eq!(problem["pointer"], "/motion/layers/0/graph");
    app.stop().await;
}
