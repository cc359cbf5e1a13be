//! Expensive graphs from small bodies: a 2D blend's triangulation tests
//! every triple of its points against every point, so its cost grows as the
//! fourth power of the points — a few kilobytes of blend points would be
//! hours of one core. A blend's points are bounded (`max_blend_points`,
//! checked before anything is built), a graph's nodes too, and what is left
//! is priced before it runs (docs/api.md, "Work and its price"): the node
//! refuses or runs it off the async workers, and keeps answering.

use serde_json::{Value, json};

use super::target;

/// A clip on the `hips`–`spine` chain.
fn chain_clip(name: &str) -> String {
    json!({"name": name,
        "skeleton": {"joints": [{"name": "hips"}, {"name": "spine", "parent": "hips"}]},
        "tracks": [{"joint": "hips", "channel": "rotation", "interpolation": "linear",
                    "times": [0, 1], "values": [[0, 0, 0, 1], [0, 0.2, 0, 0.98]]}]})
    .to_string()
}

/// A graph of `nodes` 2D blends of `points` points each on a grid (every
/// cell cocircular: the hardest triangulation), over `clips` in turn.
fn grid_graph(name: &str, nodes: usize, points: usize, clips: &[String]) -> Value {
    let grid: Vec<Value> =
        (0..points).map(|i| json!({"clip": clips[i % clips.len()], "at": [(i % 8) as f64, (i / 8) as f64]})).collect();
    let blends: serde_json::Map<String, Value> = (0..nodes)
        .map(|n| (format!("b{n:03}"), json!({"blend2d": {"x": "x", "y": "y", "points": grid, "sync": false}})))
        .collect();
    json!({"name": name,
        "parameters": {"x": {"type": "float", "default": 0, "min": 0, "max": 8},
                       "y": {"type": "float", "default": 0, "min": 0, "max": 8}},
        "nodes": blends, "output": "b000"})
}

async fn post(http: &reqwest::Client, url: &str, body: &Value) -> (u16, Value) {
    let resp = http.post(url).json(body).send().await.unwrap();
    let status = resp.status().as_u16();
    (status, resp.json().await.unwrap_or(Value::Null))
}

#[tokio::test(flavor = "multi_thread")]
async fn blend_points_are_bounded_and_priced_and_the_node_keeps_answering() {
    let mut target = target(&["--node-work-per-sec", "1000000000000", "--request-timeout-secs", "300"]).await;
    let http = crate::common::http_client();
    let mut clips = Vec::new();
    for name in ["a", "b", "c"] {
        let resp = http
            .post(target.server.url("/v1/clips"))
            .header("content-type", "application/json")
            .body(chain_clip(name))
            .send()
            .await
            .unwrap();
        assert_eq!(resp.status(), 201);
        clips.push(resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned());
    }
    let url = target.server.url("/v1/graphs");

    // 2,000 points in one blend (~140 KB): 1.6·10¹³ tests if it were triangulated; refused unread.
    let probes = target.probes().await;
    let huge = grid_graph("huge", 1, 2000, &clips);
    let (status, problem) = post(&http, &url, &huge).await;
    let report = probes.finish();
    assert_eq!(
        (status, problem["code"].as_str(), problem["pointer"].as_str()),
        (422, Some("too_many_points"), Some("/nodes/b000/blend2d/points")),
        "{problem}"
    );
    target.assert_survived("a 2,000-point blend space", &report);

    // 128 blends of 32 points (each 32⁴ ≈ 10⁶ units): over max_request_work, refused by its price.
    let probes = target.probes().await;
    let (status, problem) = post(&http, &url, &grid_graph("wide", 128, 32, &clips)).await;
    let report = probes.finish();
    assert_eq!((status, problem["code"].as_str()), (422, Some("too_much_work")), "{problem}");
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.contains("building this graph") && detail.contains("max_request_work"), "{detail}");
    target.assert_survived("128 blends of 32 points", &report);

    // The most the price admits, eight at once: built on the work threads while the probes answer.
    let probes = target.probes().await;
    let uploads = (0..8).map(|i| {
        let (http, url, body) = (http.clone(), url.clone(), grid_graph(&format!("admitted-{i}"), 48, 32, &clips));
        async move { post(&http, &url, &body).await }
    });
    let answers = futures_util::future::join_all(uploads).await;
    let report = probes.finish();
    for (status, problem) in &answers {
        // Admitted, or refused by the caller's or the node's share of the work: never a 5xx but 503.
        assert!(
            *status == 201 || (*status == 429 && problem["code"] == "caller_work_limit") || *status == 503,
            "{status} {problem}"
        );
    }
    assert!(answers.iter().any(|(s, _)| *s == 201), "some graph was admitted: {answers:?}");
    target.assert_survived("eight admitted 48-blend graphs at once", &report);
}
