//! Expensive builds from small bodies: two concurrent 50 KB uploads of
//! constant-speed Hermite tracks once froze `/healthz` and gRPC `Ping` for
//! 12 s (arc-length tables were capped per track, not per clip, and small
//! bodies were compiled on the async workers), and 16 of them left 546 MB in
//! a cache bounded by entry count. Now builds have a per-clip budget, run
//! on blocking threads with bounded concurrency, and the cache is bounded in
//! bytes.

use serde_json::{Value, json};

use super::target;

/// A ~50 KB clip of `joints` constant-speed cubic Hermite translation
/// tracks whose keys swing between two points with large opposite tangents:
/// every segment is a tight loop, the worst case for arc-length tables.
pub fn looping_hermite(joints: usize, keys: usize) -> String {
    let joint_names: Vec<String> = (0..joints).map(|j| format!("j{j}")).collect();
    let skeleton: Vec<Value> = joint_names
        .iter()
        .enumerate()
        .map(|(j, name)| json!({"name": name, "parent": if j == 0 { Value::Null } else { json!("j0") }}))
        .collect();
    let track = |name: &String| {
        let times: Vec<f64> = (0..keys).map(|k| k as f64 * 0.1).collect();
        let values: Vec<[f64; 3]> = (0..keys).map(|k| [(k % 2) as f64, 0.0, 0.0]).collect();
        let tangents: Vec<[f64; 3]> = (0..keys).map(|k| [0.0, if k % 2 == 0 { 900.0 } else { -900.0 }, 7.0]).collect();
        json!({"joint": name, "channel": "translation", "interpolation": "cubic_hermite", "speed": "constant",
               "times": times, "values": values, "in_tangents": tangents, "out_tangents": tangents})
    };
    json!({
        "name": "loops",
        "skeleton": {"joints": skeleton},
        "tracks": joint_names.iter().map(track).collect::<Vec<_>>(),
        "playback": "loop"
    })
    .to_string()
}

/// One upload's answer: 201 (built within the budget) or 422
/// `build_budget_exceeded`; anything else fails the test.
async fn upload(http: &reqwest::Client, url: &str, body: String) -> u16 {
    let resp = http.post(url).header("content-type", "application/json").body(body).send().await.unwrap();
    let status = resp.status().as_u16();
    if status != 201 {
        let problem: Value = resp.json().await.unwrap();
        assert_eq!((status, problem["code"].as_str()), (422, Some("build_budget_exceeded")), "{problem}");
    }
    status
}

#[tokio::test(flavor = "multi_thread")]
async fn expensive_builds_never_stall_the_probes_and_the_cache_stays_bounded() {
    let mut target = target(&[]).await;
    let http = reqwest::Client::new();
    let url = target.server.url("/v1/clips");
    let body = looping_hermite(16, 60);
    assert!((30_000..80_000).contains(&body.len()), "a ~50 KB body: {}", body.len());

    let probes = target.probes().await;
    let two = futures_util::future::join(upload(&http, &url, body.clone()), upload(&http, &url, body.clone())).await;
    let report = probes.finish();
    println!("two concurrent uploads answered {two:?}");
    target.assert_survived("two concurrent 50 KB constant-speed Hermite uploads", &report);

    let probes = target.probes().await;
    let mut statuses = Vec::new();
    for _ in 0..16 {
        statuses.push(upload(&http, &url, body.clone()).await);
    }
    let report = probes.finish();
    println!("sixteen uploads answered {statuses:?}");
    let cached = target.metric("inbetween_cache_bytes").await.expect("/metrics reports the cache's bytes");
    let limit = target.metric("inbetween_cache_limit_bytes").await.expect("/metrics reports the cache's limit");
    assert!(cached <= limit, "cache holds {cached} bytes over its {limit}");
    target.assert_survived("sixteen 50 KB constant-speed Hermite uploads", &report);
}
