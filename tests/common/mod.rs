//! The one integration-test harness, shared by the `service` and `system`
//! test binaries (each says `mod common;`).
//!
//! - [`TestApp`]: the real `Application` in this process on 127.0.0.1:0,
//!   with ready-made HTTP, gRPC and WebSocket clients; `stop()` joins the
//!   server and fails the test if it returned an error or panicked.
//! - [`ServerProcess`]: the real `inbetween` binary, for what only a process
//!   can show (signals, `kill -9`, flags and environment, several nodes).
//! - [`pg`]: a fresh PostgreSQL schema per test.
//!
//! Each binary uses a different part of it, hence the allowances below.
#![allow(dead_code, unused_imports)]

pub mod app;
pub mod glb;
pub mod pg;
pub mod process;

use std::path::{Path, PathBuf};
use std::time::Duration;

pub use app::TestApp;
pub use process::ServerProcess;

/// The docs/clip-format.md §1 example (`examples/wave.json`): joints `root` and `arm`, clip time [0, 3].
pub const WAVE: &str = include_str!("../../examples/wave.json");

/// Where `text` cites the project's internal contract by section (its name,
/// a space, then `§`). Users and contributors have `docs/`, not that
/// contract, so the documents, the code and the OpenAPI text must cite
/// `docs/` instead. The name is spelled apart from the `§` so this file does
/// not cite it itself.
pub fn internal_contract_citations(text: &str) -> Vec<usize> {
    const NAME: &str = "SPEC ";
    text.match_indices('§').map(|(at, _)| at).filter(|&at| text[..at].ends_with(NAME)).collect()
}

/// A real third-party test file, `rel` as in `../shared/testdata` (e.g.
/// `gltf/Fox/Fox.glb`): the repository's own copy in `examples/` when it
/// ships one (the Fox, InterpolationTest, CMU 131_01, byte for byte the
/// same), else the file in `INBETWEEN_TESTDATA` (default `../shared/testdata`
/// beside the clone; README, "The two commands").
pub fn testdata_path(rel: &str) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let shipped = root.join("examples").join(rel);
    if shipped.is_file() { shipped } else { corpus_dir(root).join(rel) }
}

/// [`testdata_path`]'s bytes; a missing file fails the test with its path.
pub fn testdata(rel: &str) -> Vec<u8> {
    let path = testdata_path(rel);
    std::fs::read(&path).unwrap_or_else(|e| {
        panic!("{}: {e} (third-party test files: set INBETWEEN_TESTDATA, README \"The two commands\")", path.display())
    })
}

/// An HTTP client that asks for answers as they are (no `Accept-Encoding`).
/// The test build turns reqwest's gzip, br and zstd decoders on (for the
/// compression tests, which build their own clients), and with them on a
/// plain `reqwest::Client` would negotiate compression with every server a
/// test starts.
pub fn http_client() -> reqwest::Client {
    http_builder().build().expect("a plain client builds")
}

/// [`http_client`]'s builder, for tests that set more.
pub fn http_builder() -> reqwest::ClientBuilder {
    reqwest::Client::builder().no_gzip().no_brotli().no_zstd().no_deflate()
}

/// Bounds a wait: a server that stops answering fails the test instead of hanging it.
pub async fn within<T>(secs: u64, what: &str, f: impl std::future::Future<Output = T>) -> T {
    tokio::time::timeout(Duration::from_secs(secs), f).await.unwrap_or_else(|_| panic!("timed out: {what}"))
}

/// Whether latency bounds (a p99 under N ms and the like) are checked: only
/// in the slow runs (`INBETWEEN_SLOW=1`), beside the benches. On a loaded
/// machine every answer is slower without anything being wrong, so the
/// default suite reports the figures and checks what was answered.
pub fn latency_checked() -> bool {
    std::env::var("INBETWEEN_SLOW").is_ok_and(|v| v == "1")
}

/// Polls `check` every 20 ms until it answers `Some`, and returns that; fails
/// the test naming `what` if it never does within `deadline`. Tests wait on
/// the event they need (a frame, a status, a metric), not on the clock, so a
/// loaded machine makes them slower rather than red.
pub async fn eventually_some<T, F, Fut>(deadline: Duration, what: &str, mut check: F) -> T
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Option<T>>,
{
    let started = tokio::time::Instant::now();
    loop {
        if let Some(done) = check().await {
            return done;
        }
        assert!(started.elapsed() < deadline, "never happened within {deadline:?}: {what}");
        tokio::time::sleep(POLL).await;
    }
}

/// [`eventually_some`] for a yes/no condition.
pub async fn eventually<F, Fut>(deadline: Duration, what: &str, mut check: F)
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = bool>,
{
    eventually_some(deadline, what, || {
        let done = check();
        async move { done.await.then_some(()) }
    })
    .await
}

/// How often [`eventually`] looks again.
const POLL: Duration = Duration::from_millis(20);

pub fn assert_close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol, "{what}: {a} vs {b} (tolerance {tol})");
}

/// Whether the slow runs (soak, overload measurement, the full crash test,
/// figures for BENCHMARKS.md) are asked for: `INBETWEEN_SLOW=1`. Without it
/// they return at once after saying how to run them.
pub fn slow_runs(what: &str) -> bool {
    let on = std::env::var("INBETWEEN_SLOW").is_ok_and(|v| v == "1");
    if !on {
        eprintln!("SKIPPED: {what} is a slow run; set INBETWEEN_SLOW=1 to run it");
    }
    on
}

/// A clip of `tracks` constant-speed Hermite translation tracks of `keys`
/// keys each, whose tangents (`±reach`) throw every segment into a loop:
/// long arc-length tables from a small document (issue 15's build attack).
pub fn looping_hermite(name: &str, tracks: usize, keys: usize, reach: f32) -> String {
    let tracks: Vec<serde_json::Value> = (0..tracks)
        .map(|j| {
            let values: Vec<[f32; 3]> = (0..keys).map(|k| [k as f32, (k % 2) as f32, 0.0]).collect();
            let tangents: Vec<[f32; 3]> =
                (0..keys).map(|k| if k % 2 == 0 { [reach, -reach, reach] } else { [-reach, reach, reach] }).collect();
            serde_json::json!({
                "joint": format!("j{j}"), "channel": "translation", "interpolation": "cubic_hermite",
                "speed": "constant", "times": (0..keys).map(|k| k as f32).collect::<Vec<_>>(),
                "values": values, "in_tangents": tangents, "out_tangents": tangents,
            })
        })
        .collect();
    serde_json::json!({"name": name, "tracks": tracks}).to_string()
}

/// A gauge's or counter's value in a Prometheus text rendering.
/// A two-joint clip document: `hips` translating along x from 0 to `to`
/// over `duration` seconds with `playback`, and `arm` above it at rest —
/// motion tests compute its poses by hand.
pub fn hips_mover(name: &str, to: f32, duration: f32, playback: &str) -> String {
    serde_json::json!({
        "name": name,
        "skeleton": {"joints": [
            {"name": "hips", "parent": null},
            {"name": "arm", "parent": "hips", "rest": {"translation": [0, 1, 0]}}
        ]},
        "tracks": [{"joint": "hips", "channel": "translation", "interpolation": "linear",
                    "times": [0, duration], "values": [[0, 0, 0], [to, 0, 0]]}],
        "playback": playback
    })
    .to_string()
}

/// A leg under moving hips for IK tests (docs/ik.md): `hips` translates along
/// x from 0 to `duration` over `duration` s (x equals the time), `thigh` at
/// hips + (0.1, 0, 0), `knee` 0.5 below it, `foot` 0.5 below that (so
/// l1 = l2 = 0.5), `toe` 0.2 ahead of the foot (+z), and `head` at hips +
/// (0, 0.8, 0) looking along +z. `ik` is the clip's own constraint list.
pub fn ik_leg(name: &str, duration: f32, ik: serde_json::Value) -> String {
    serde_json::json!({
        "name": name,
        "skeleton": {"joints": [
            {"name": "hips", "parent": null},
            {"name": "thigh", "parent": "hips", "rest": {"translation": [0.1, 0, 0]}},
            {"name": "knee", "parent": "thigh", "rest": {"translation": [0, -0.5, 0]}},
            {"name": "foot", "parent": "knee", "rest": {"translation": [0, -0.5, 0]}},
            {"name": "toe", "parent": "foot", "rest": {"translation": [0, 0, 0.2]}},
            {"name": "head", "parent": "hips", "rest": {"translation": [0, 0.8, 0]}}
        ]},
        "tracks": [{"joint": "hips", "channel": "translation", "interpolation": "linear",
                    "times": [0, duration], "values": [[0, 0, 0], [duration, 0, 0]]}],
        "ik": ik
    })
    .to_string()
}

pub fn metric(text: &str, name: &str) -> Option<f64> {
    text.lines().find(|l| l.split(' ').next() == Some(name))?.split(' ').nth(1)?.parse().ok()
}

/// Where the third-party files the repository does not ship are:
/// `INBETWEEN_TESTDATA`, else `shared/testdata` beside the clone (where CI
/// keeps them).
fn corpus_dir(root: &Path) -> PathBuf {
    std::env::var_os("INBETWEEN_TESTDATA").map(PathBuf::from).unwrap_or_else(|| root.join("../shared/testdata"))
}

/// A chain of `joints` joints, each the child of the one before, with `ik`
/// keyed in the clip: the IK price tests' clip.
pub fn chain_clip(joints: usize, ik: serde_json::Value) -> String {
    let skeleton: Vec<serde_json::Value> = (0..joints)
        .map(|j| {
            let parent = j.checked_sub(1).map(|p| format!("j{p}"));
            serde_json::json!({"name": format!("j{j}"), "parent": parent, "rest": {"translation": [0, 0.01, 0]}})
        })
        .collect();
    serde_json::json!({"name": "chain", "skeleton": {"joints": skeleton}, "ik": ik,
           "tracks": [{"joint": "j0", "channel": "translation", "interpolation": "linear",
                       "times": [0, 1], "values": [[0, 0, 0], [1, 0, 0]]}]})
    .to_string()
}

/// `doc` (a clip document) under a name no other clip of this test process
/// has: names identify clips (docs/import.md), so a test that uploads one
/// document as several clips names each anew (`wave` → `wave-7`).
pub fn fresh_name(doc: &str) -> String {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let mut v: serde_json::Value = serde_json::from_str(doc).expect("a clip document");
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let name = format!("{}-{n}", v["name"].as_str().unwrap_or("clip"));
    v["name"] = name.into();
    v.to_string()
}
