//! Several real `inbetween` processes on one PostgreSQL schema, as behind a
//! load balancer: a change on any node reaches every other node's cache
//! within a second (LISTEN/NOTIFY), a node killed with `kill -9` leaves the
//! others serving and streaming, and a node whose database connections are
//! terminated recovers without ever serving a stale version afterwards. A
//! composed motion cached on one node follows a clip replaced on another.
//! Broadcasts played by every node alike: `broadcasts.rs`; graphs and
//! characters held built on every node: `documents.rs`.
//!
//! Skips (with a message) without PostgreSQL, unless
//! `INBETWEEN_REQUIRE_POSTGRES=1`.

mod balancer;
mod broadcasts;
mod documents;

use std::time::Duration;

use futures_util::StreamExt;
use serde_json::Value;
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::Message;

use crate::common::pg::Schema;
use crate::common::{ServerProcess, eventually};

/// The bound for a change to reach every node: the second the issue sets in
/// the slow runs (`latency_checked`), ten on a loaded machine, where the
/// default suite checks that the change arrives, not how fast.
fn propagation() -> Duration {
    Duration::from_secs(if crate::common::latency_checked() { 1 } else { 10 })
}

/// A node: one `inbetween serve` process, killed (SIGKILL) when dropped.
type Node = ServerProcess;

/// Starts node `name` on `schema`, ready; its database connections carry
/// `application_name=<name>` so a test can find and cut them.
async fn start(schema: &Schema, name: &str) -> Node {
    ServerProcess::serve()
        .name(name)
        .args(["--db-max-connections", "4", "--database-url"])
        .arg(schema.url(&format!("application_name={name}")))
        .start()
        .await
}

/// Starts the named nodes one after the other.
async fn start_all<const N: usize>(schema: &Schema, names: [&str; N]) -> [Node; N] {
    let mut nodes = Vec::with_capacity(N);
    for name in names {
        nodes.push(start(schema, name).await);
    }
    let Ok(nodes) = nodes.try_into() else { unreachable!("N names, N nodes") };
    nodes
}

/// A clip whose only joint sits at x = `marker` at every time: a pose tells
/// which version a node served.
fn marker_doc(marker: u32) -> String {
    serde_json::json!({"name": "marker", "tracks": [{"joint": "j", "channel": "translation",
        "interpolation": "linear", "times": [0.0, 10.0], "values": [[marker, 0, 0], [marker, 0, 0]]}]})
    .to_string()
}

async fn create(http: &reqwest::Client, node: &Node, marker: u32) -> String {
    let resp = http
        .post(node.url("/v1/clips"))
        .header("content-type", "application/json")
        .body(crate::common::fresh_name(&marker_doc(marker)))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 201, "{}: create", node.name);
    resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned()
}

async fn replace(http: &reqwest::Client, node: &Node, id: &str, marker: u32) {
    let resp = http
        .put(node.url(&format!("/v1/clips/{id}")))
        .header("content-type", "application/json")
        .body(crate::common::fresh_name(&marker_doc(marker)))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200, "{}: replace", node.name);
}

/// What `node` serves for `id`: `Some(marker)` from the pose, `None` on 404.
async fn served(http: &reqwest::Client, node: &Node, id: &str) -> Option<u32> {
    let resp = http.get(node.url(&format!("/v1/clips/{id}/pose?t=1"))).send().await.unwrap();
    match resp.status().as_u16() {
        200 => {
            let pose: Value = resp.json().await.unwrap();
            Some(pose["joints"][0]["translation"][0].as_f64().unwrap().round() as u32)
        }
        404 => None,
        s => panic!("{}: pose answered {s}", node.name),
    }
}

/// Polls `node` until it serves `want`; returns how long that took, or
/// panics after `limit`. Polls every 5 ms rather than through
/// [`eventually`]: the delay it returns is a measurement.
async fn until_served(http: &reqwest::Client, node: &Node, id: &str, want: Option<u32>, limit: Duration) -> Duration {
    let started = Instant::now();
    loop {
        let got = served(http, node, id).await;
        if got == want {
            return started.elapsed();
        }
        assert!(started.elapsed() < limit, "{} still serves {got:?}, not {want:?}, after {limit:?}", node.name);
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// Then it keeps serving `want` for `period` (no stale version comes back).
/// The time is the behaviour here: nothing may change over the period.
async fn keeps_serving(http: &reqwest::Client, node: &Node, id: &str, want: Option<u32>, period: Duration) {
    let started = Instant::now();
    while started.elapsed() < period {
        assert_eq!(served(http, node, id).await, want, "{} went back to a stale version", node.name);
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn changes_on_any_node_reach_every_node_within_a_second() {
    let Some(schema) = Schema::create("spread").await else { return };
    let [a, b, c] = start_all(&schema, ["node-a", "node-b", "node-c"]).await;
    let http = crate::common::http_client();

    let id = create(&http, &a, 1).await;
    for node in [&a, &b, &c] {
        assert_eq!(served(&http, node, &id).await, Some(1), "{} serves the upload", node.name);
    }
    // Every node now has version 1 cached. Replace on C: A must drop it.
    replace(&http, &c, &id, 2).await;
    for node in [&a, &b] {
        until_served(&http, node, &id, Some(2), propagation()).await;
    }
    assert_eq!(served(&http, &c, &id).await, Some(2));
    // Delete on B: every node answers 404 within the second.
    let resp = http.delete(b.url(&format!("/v1/clips/{id}"))).send().await.unwrap();
    assert_eq!(resp.status(), 204);
    for node in [&a, &b, &c] {
        until_served(&http, node, &id, None, propagation()).await;
    }
    drop((a, b, c));
    schema.drop_now().await;
}

/// The x of a composed pose on `node`: `base` under `top` at weight ½
/// (`Some(x)`), or `None` on 404.
async fn composed(http: &reqwest::Client, node: &Node, base: &str, top: &str) -> Option<f64> {
    let motion = serde_json::json!({"layers": [{"clip": base}, {"clip": top, "weight": 0.5}]});
    let body = serde_json::json!({"motion": motion, "time": 1});
    let resp = http.post(node.url("/v1/poses")).json(&body).send().await.unwrap();
    match resp.status().as_u16() {
        200 => Some(resp.json::<Value>().await.unwrap()["joints"][0]["translation"][0].as_f64().unwrap()),
        404 => None,
        s => panic!("{}: composed pose answered {s}", node.name),
    }
}

/// A metric of `node`'s own `/metrics` (one process: no other test's counts).
async fn node_metric(http: &reqwest::Client, node: &Node, name: &str) -> f64 {
    let text = http.get(node.url("/metrics")).send().await.unwrap().text().await.unwrap();
    crate::common::metric(&text, name).unwrap_or_else(|| panic!("{}: {name} in\n{text}", node.name))
}

/// Waits until `node` listens for changes (its `inbetween_notify_subscribed` gauge is 1).
async fn until_subscribed(http: &reqwest::Client, node: &Node) {
    let what = format!("{} subscribed to changes", node.name);
    eventually(Duration::from_secs(5), &what, || async {
        node_metric(http, node, "inbetween_notify_subscribed").await >= 1.0
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_motion_cached_on_one_node_follows_a_clip_replaced_on_another() {
    let Some(schema) = Schema::create("motion").await else { return };
    let [a, b] = start_all(&schema, ["node-a", "node-b"]).await;
    let http = crate::common::http_client();
    let (base, top) = (create(&http, &a, 1).await, create(&http, &a, 10).await);
    // B caches nothing until it listens: wait for that, so the motion below is cached.
    until_subscribed(&http, &b).await;
    // lerp(1, 10, ½) = 5.5, built once on B and then found built.
    // The creates' notifications may still reach B after its first load (each
    // evicts the clip B loaded, and a motion is cached only over held
    // clips), so compose until one is found built; from then on every one is.
    let (misses, hits) = ("inbetween_motion_cache_misses_total", "inbetween_motion_cache_hits_total");
    let started = Instant::now();
    while node_metric(&http, &b, hits).await < 1.0 {
        assert!(started.elapsed() < propagation(), "node-b never found the motion built");
        assert_eq!(composed(&http, &b, &base, &top).await, Some(5.5));
    }
    let built = node_metric(&http, &b, misses).await;
    for k in 2..5 {
        assert_eq!(composed(&http, &b, &base, &top).await, Some(5.5));
        assert_eq!((node_metric(&http, &b, misses).await, node_metric(&http, &b, hits).await), (built, f64::from(k)));
    }

    // Replaced on A: B's next composed pose is built on the new version, lerp(1, 20, ½).
    replace(&http, &a, &top, 20).await;
    eventually(propagation(), "node-b composes the new version", || async {
        composed(&http, &b, &base, &top).await == Some(10.5)
    })
    .await;
    assert!(node_metric(&http, &b, misses).await > built, "built again on the new version");
    for _ in 0..5 {
        assert_eq!(composed(&http, &b, &base, &top).await, Some(10.5), "no stale motion comes back");
    }
    // Deleted on A: B answers 404 within the second.
    let resp = http.delete(a.url(&format!("/v1/clips/{top}"))).send().await.unwrap();
    assert_eq!(resp.status(), 204);
    let started = Instant::now();
    eventually(propagation(), "node-b stops composing a deleted clip", || async {
        composed(&http, &b, &base, &top).await.is_none()
    })
    .await;
    // The motion goes with the clip (the gauge is set just after the clip is dropped).
    eventually(
        propagation().saturating_sub(started.elapsed()),
        "node-b drops the motion over a deleted clip",
        || async { node_metric(&http, &b, "inbetween_motion_cache_entries").await == 0.0 },
    )
    .await;
    drop((a, b));
    schema.drop_now().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_killed_node_leaves_the_others_serving_and_streaming() {
    let Some(schema) = Schema::create("kill").await else { return };
    let [mut a, b, c] = start_all(&schema, ["node-a", "node-b", "node-c"]).await;
    let http = crate::common::http_client();
    let id = create(&http, &a, 5).await;
    let mut streams = Vec::new();
    for node in [&b, &c] {
        let url = node.url(&format!("/v1/clips/{id}/stream?fps=30")).replacen("http://", "ws://", 1);
        let (ws, _) = tokio_tungstenite::connect_async(url).await.unwrap();
        streams.push(ws);
    }
    a.kill(); // SIGKILL
    // The survivors stream on (30 more frames each, in order) and serve poses and writes.
    for ws in &mut streams {
        let mut last_seq = None;
        for _ in 0..30 {
            let frame = loop {
                let msg = tokio::time::timeout(Duration::from_secs(5), ws.next()).await.unwrap().unwrap().unwrap();
                if let Message::Text(t) = msg {
                    break serde_json::from_str::<Value>(&t).unwrap();
                }
            };
            let seq = frame["seq"].as_u64().unwrap();
            assert!(last_seq.is_none_or(|l| seq > l));
            let x = frame["pose"]["joints"][0]["translation"][0].as_f64().unwrap();
            assert!((x - 5.0).abs() < 1e-5, "{x}");
            last_seq = Some(seq);
        }
    }
    assert_eq!(served(&http, &b, &id).await, Some(5));
    replace(&http, &c, &id, 6).await;
    until_served(&http, &b, &id, Some(6), propagation()).await;
    drop((a, b, c));
    schema.drop_now().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_whose_connections_are_cut_recovers_and_serves_no_stale_version() {
    let Some(schema) = Schema::create("cut").await else { return };
    let [a, b] = start_all(&schema, ["node-a", "node-b"]).await;
    let http = crate::common::http_client();
    let id = create(&http, &a, 1).await;
    assert_eq!(served(&http, &b, &id).await, Some(1), "B has version 1 cached");
    // Wait for B's listener to be up, so the cut below hits a subscribed node.
    replace(&http, &a, &id, 2).await;
    until_served(&http, &b, &id, Some(2), propagation()).await;

    // Cut every connection of B (pool and listener), and change the clip
    // while B cannot hear it: that notification is lost to B.
    let cut = schema.terminate("node-b").await;
    assert!(cut >= 2, "B's pool and listener connections were found ({cut})");
    replace(&http, &a, &id, 3).await;
    until_served(&http, &b, &id, Some(3), Duration::from_secs(3)).await;
    keeps_serving(&http, &b, &id, Some(3), Duration::from_millis(500)).await;

    // B listens again: later changes reach it within the second.
    until_subscribed(&http, &b).await;
    replace(&http, &a, &id, 4).await;
    until_served(&http, &b, &id, Some(4), propagation()).await;
    let resp = http.get(b.url("/readyz")).send().await.unwrap();
    assert_eq!(resp.status(), 200);
    drop((a, b));
    schema.drop_now().await;
}

/// The figures in BENCHMARKS.md ("Several nodes"): the delay from a
/// replace's `200` on node A to node B serving the new version, over 100
/// updates. `INBETWEEN_SLOW=1 cargo test --release --test system invalidation_delay -- --nocapture`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn invalidation_delay_figures() {
    if !crate::common::slow_runs("the invalidation-delay figures") {
        return;
    }
    let Some(schema) = Schema::create("delay").await else { return };
    let [a, b] = start_all(&schema, ["node-a", "node-b"]).await;
    let http = crate::common::http_client();
    let id = create(&http, &a, 0).await;
    until_served(&http, &b, &id, Some(0), propagation()).await;
    let mut delays = Vec::new();
    for v in 1..=100 {
        replace(&http, &a, &id, v).await;
        let started = Instant::now();
        loop {
            if served(&http, &b, &id).await == Some(v) {
                break;
            }
            assert!(started.elapsed() < Duration::from_secs(5));
        }
        delays.push(started.elapsed());
    }
    delays.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "invalidation delay over {} updates: p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        delays.len(),
        ms(delays[delays.len() / 2]),
        ms(delays[delays.len() * 99 / 100 - 1]),
        ms(delays[delays.len() - 1])
    );
    drop((a, b));
    schema.drop_now().await;
}
