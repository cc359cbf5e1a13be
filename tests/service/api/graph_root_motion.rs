//! Root motion on a graph (docs/graphs.md, “What composes with a graph”),
//! against the real server and a float64 reference written here: a synced
//! 1D blend of two walks at a fixed parameter travels, per tick,
//! `Σ w_k · d_k · Δφ` — each point's travel per cycle `d_k` weighted by
//! its blend weight, over the sync group's phase step `Δφ = dt / Σ w_k D_k`
//! — however many loop seams a tick crosses; `extract` keeps the root in
//! place; a transition crossfades the slots' deltas.

use serde_json::{Value, json};

use super::TestApp;

async fn send(app: &TestApp, path: &str, body: &Value) -> (u16, Value) {
    let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
    let status = resp.status().as_u16();
    (status, resp.json().await.unwrap_or(Value::Null))
}

/// A `duration`-second loop on `hips`–`spine` whose hips walk on x from 0
/// to `distance`.
fn walk(name: &str, duration: f64, distance: f64) -> String {
    json!({
        "name": name,
        "skeleton": {"joints": [{"name": "hips", "parent": null}, {"name": "spine", "parent": "hips"}]},
        "tracks": [{"joint": "hips", "channel": "translation", "interpolation": "linear",
                    "times": [0, duration], "values": [[0, 1, 0], [distance, 1, 0]]}],
    })
    .to_string()
}

/// The two walks `(duration, distance)` and their blend on `pace` (0: the
/// first, 1: the second) at `default`, with a `stop` state (the second walk
/// alone) that `halt` fades to over `fade` seconds. The graph's id.
pub(crate) async fn walks_graph(app: &TestApp, walks: [(f64, f64); 2], default: f64, fade: f64) -> String {
    let short = app.create_id(&walk("short-walk", walks[0].0, walks[0].1), None).await;
    let long = app.create_id(&walk("long-walk", walks[1].0, walks[1].1), None).await;
    let doc = json!({
        "name": "walks",
        "parameters": {"pace": {"type": "float", "default": default, "min": 0, "max": 1}, "halt": {"type": "trigger"}},
        "nodes": {
            "walk": {"blend1d": {"parameter": "pace", "points": [{"clip": short, "at": 0}, {"clip": long, "at": 1}]}},
            "stop": {"clip": long}},
        "machine": {"initial": "walk",
            "states": {"walk": {"node": "walk"}, "stop": {"node": "stop"}},
            "transitions": [{"from": "walk", "to": "stop", "when": {"trigger": "halt"}, "duration": fade}]},
    });
    let created = app.post_json("/v1/graphs", &doc).await;
    created["id"].as_str().unwrap_or_else(|| panic!("{created}")).to_owned()
}

/// The x of a pose's root-motion `delta` or `total`.
fn root_x(pose: &Value, which: &str) -> f64 {
    pose["root_motion"][which]["translation"][0].as_f64().unwrap_or_else(|| panic!("no root motion: {pose}"))
}

/// Samples of the graph from tick 0 to `last` at `fps`, with `root_motion`.
async fn samples(app: &TestApp, graph: &str, mode: &str, (last, fps): (u64, f64), inputs: Value) -> Vec<Value> {
    let motion = json!({"layers": [{"graph": graph}], "root_motion": {"joint": "hips", "mode": mode}});
    let body = json!({"motion": motion, "start": 0, "end": last as f64 / fps, "fps": fps, "inputs": inputs});
    let (status, answer) = send(app, "/v1/samples", &body).await;
    assert_eq!(status, 200, "{answer}");
    answer["poses"].as_array().unwrap().clone()
}

#[tokio::test]
async fn a_blend_travels_its_weighted_walks_over_the_synced_phase_however_many_seams_a_tick_crosses() {
    let app = TestApp::start().await;
    let walks = [(0.25, 1.0), (0.5, 4.0)];
    let pace = 0.25;
    let graph = walks_graph(&app, walks, pace, 0.0).await;
    // The reference, in f64: weights (1 − pace, pace); the group's cycle Σ w_k D_k.
    let w = [1.0 - pace, pace];
    let cycle: f64 = (0..2).map(|k| w[k] * walks[k].0).sum();
    let per_cycle: f64 = (0..2).map(|k| w[k] * walks[k].1).sum();
    // At 60 fps a tick is a small step; at 1 fps it crosses 3 or 4 seams of each walk.
    for fps in [60.0, 7.0, 1.0] {
        let last = (3.0 * fps) as u64;
        let poses = samples(&app, &graph, "report", (last, fps), json!([])).await;
        assert_eq!((root_x(&poses[0], "delta"), root_x(&poses[0], "total")), (0.0, 0.0), "the first pose");
        let step = per_cycle * (1.0 / fps) / cycle;
        for (k, pose) in poses.iter().enumerate().skip(1) {
            let (delta, total) = (root_x(pose, "delta"), root_x(pose, "total"));
            assert!((delta - step).abs() < 1e-4 * step.max(1.0), "{fps} fps, tick {k}: delta {delta}, not {step}");
            let want = step * k as f64;
            assert!((total - want).abs() < 1e-4 * want.max(1.0), "{fps} fps, tick {k}: total {total}, not {want}");
        }
    }
    // A samples request from a later tick starts its totals there, at the same deltas.
    let motion = json!({"layers": [{"graph": graph}], "root_motion": {"joint": "hips"}});
    let body = json!({"motion": motion, "start": 1, "end": 2, "fps": 10});
    let (status, later) = send(&app, "/v1/samples", &body).await;
    assert_eq!(status, 200, "{later}");
    let later = later["poses"].as_array().unwrap();
    assert_eq!(root_x(&later[0], "total"), 0.0);
    let step = per_cycle * 0.1 / cycle;
    assert!((root_x(&later[10], "total") - 10.0 * step).abs() < 1e-4 * 10.0 * step);
    app.stop().await;
}

#[tokio::test]
async fn extract_keeps_the_root_in_place_and_a_transition_crossfades_the_deltas() {
    let app = TestApp::start().await;
    let walks = [(1.0, 1.0), (2.0, 4.0)];
    let graph = walks_graph(&app, walks, 0.0, 0.5).await;
    let fps = 10.0;
    let report = samples(&app, &graph, "report", (20, fps), json!([{"time": 1.0, "set": {"halt": true}}])).await;
    let extract = samples(&app, &graph, "extract", (20, fps), json!([{"time": 1.0, "set": {"halt": true}}])).await;
    let hips = |pose: &Value| pose["joints"][0]["translation"][0].as_f64().unwrap();
    for (k, (r, e)) in report.iter().zip(&extract).enumerate() {
        assert!(hips(e).abs() < 1e-6, "tick {k}: extracted hips at {}", hips(e));
        assert_eq!(r["root_motion"], e["root_motion"], "tick {k}: the same travel either way");
    }
    for (k, r) in report.iter().enumerate().take(10) {
        assert!((hips(r) - k as f64 / fps).abs() < 1e-5, "tick {k}: reported hips at {}", hips(r));
    }
    // pace 0: the short walk, 1 per second (0.1 a tick), until `halt` at
    // tick 10 fades to the long walk, 2 per second (0.2 a tick), over 0.5 s:
    // at α = (k − 10)/5 the deltas mix as (1 − α)·0.1 + α·0.2 (on the tick it
    // fires the new slot is at rest and α is 0), then the long walk's alone.
    for (k, pose) in report.iter().enumerate().skip(1) {
        let alpha = ((k as f64 - 10.0) / 5.0).clamp(0.0, 1.0);
        let want = (1.0 - alpha) * 0.1 + alpha * 0.2;
        let delta = root_x(pose, "delta");
        assert!((delta - want).abs() < 1e-5, "tick {k}: {delta}, not {want}");
    }
    app.stop().await;
}
