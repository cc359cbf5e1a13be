//! Expensive builds from small bodies: two concurrent 50 KB uploads of
//! constant-speed Hermite tracks once froze `/healthz` and gRPC `Ping` for
//! 12 s (arc-length tables were capped per track, not per clip, and small
//! bodies were compiled on the async workers), and 16 of them left 546 MB in
//! a cache bounded by entry count. Now builds have a per-clip budget and a
//! price, run on the work threads, and the cache is bounded in bytes.
//!
//! A debug build does a unit of build work about 75 times slower than the
//! shipped release build, so this test scales the budget and the cache down
//! by the same order (`--max-build-work 1000000`, `--cache-bytes 4000000`)
//! to exercise both mechanisms in seconds; `scripts/build_budget.sh`
//! measures the release defaults.

use serde_json::Value;

use super::target;
use crate::common::looping_hermite;

/// Uploads `body`; returns the status, asserting a refusal is the budget's.
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
    // Both builds admitted from one address (each is priced about 2.5M
    // units, over the share of a debug build's measured capacity): this
    // attack is on the probes while two builds run.
    // A long request timeout: on a machine loaded by other builds a debug
    // build of an admitted clip may take longer than 30 s, and this attack
    // is on the probes and the cache, not on the timeout (attacks::work).
    let args = [
        "--max-build-work",
        "1000000",
        "--cache-bytes",
        "4000000",
        "--node-work-per-sec",
        "1000000000000",
        "--request-timeout-secs",
        "300",
    ];
    let mut target = target(&args).await;
    let http = crate::common::http_client();
    let url = target.server.url("/v1/clips");
    let hostile = looping_hermite("loops", 40, 25, 900.0);
    assert!((30_000..80_000).contains(&hostile.len()), "a ~50 KB body: {}", hostile.len());

    let probes = target.probes().await;
    let two = futures_util::future::join(upload(&http, &url, hostile.clone()), upload(&http, &url, hostile)).await;
    let report = probes.finish();
    assert_eq!(two, (422, 422), "both refused by the budget");
    target.assert_survived("two concurrent 50 KB constant-speed Hermite uploads", &report);

    // The most expensive kind the budget admits, sixteen times: the cache keeps to its bytes.
    let probes = target.probes().await;
    let uploads = (0..16).map(|i| upload(&http, &url, looping_hermite(&format!("admitted-{i}"), 1, 2, 900.0)));
    let statuses = futures_util::future::join_all(uploads).await;
    let report = probes.finish();
    assert!(statuses.iter().all(|s| *s == 201), "{statuses:?}");
    let cached = target.metric("inbetween_cache_bytes").await.expect("/metrics reports the cache's bytes");
    let limit = target.metric("inbetween_cache_limit_bytes").await.expect("/metrics reports the cache's limit");
    println!("FIGURE sixteen admitted looping clips: cache {cached} bytes of {limit}");
    assert_eq!(limit, 4_000_000.0);
    assert!(cached > 0.0 && cached <= limit, "cache holds {cached} bytes, limit {limit}");
    target.assert_survived("sixteen admitted constant-speed Hermite uploads", &report);
}
