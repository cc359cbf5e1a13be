//! Large answers (issue 15): a ~200 MB `/sample` answer read slowly by its
//! client costs the real server a few pieces of memory, not the answer,
//! because it is evaluated piece by piece as the client reads.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use serde_json::json;

use super::{ServerProcess, start};

/// `joints` root joints, each with a linear translation track.
fn wide_clip(joints: usize) -> String {
    let tracks: Vec<_> = (0..joints)
        .map(|j| json!({"joint": format!("j{j}"), "channel": "translation", "times": [0, 1], "values": [[0, 0, 0], [1, 2, 3]]}))
        .collect();
    json!({"name": "wide", "tracks": tracks}).to_string()
}

/// Samples the server's RSS every 20 ms until `stop`; the peak.
fn watch_rss(server: &ServerProcess, stop: Arc<AtomicBool>) -> (tokio::task::JoinHandle<()>, Arc<AtomicU64>) {
    let peak = Arc::new(AtomicU64::new(server.rss_bytes()));
    let pid = server.pid();
    let seen = Arc::clone(&peak);
    let task = tokio::spawn(async move {
        while !stop.load(Ordering::Relaxed) {
            let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
            let kb =
                status.lines().find_map(|l| l.strip_prefix("VmRSS:")).map(|v| v.trim().trim_end_matches("kB").trim());
            if let Some(kb) = kb.and_then(|v| v.parse::<u64>().ok()) {
                seen.fetch_max(kb * 1024, Ordering::Relaxed);
            }
            // Sampling the server's memory: a measurement interval.
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    });
    (task, peak)
}

#[tokio::test]
async fn a_200_mb_answer_read_slowly_holds_pieces_not_the_answer() {
    const JOINTS: usize = 1000;
    const POSES: usize = 2000;
    /// The client's reading pace.
    const BYTES_PER_SEC: f64 = 40e6;
    let dir = tempfile::tempdir().unwrap();
    let flags = ["--max-poses", "100000", "--max-answer-bytes", "1073741824"];
    let server = start(&dir.path().join("data"), &flags).await;
    let http = crate::common::http_client();
    let id = server.create(&http, &wide_clip(JOINTS)).await;
    // Warm: the clip compiled and cached, the allocator's arenas in use.
    let body = json!({"start": 0, "end": 1, "fps": 100});
    let warm = http.post(server.url(&format!("/v1/clips/{id}/sample"))).json(&body).send().await.unwrap();
    assert_eq!(warm.status(), 200);
    warm.bytes().await.unwrap();
    let baseline = server.rss_bytes();

    let stop = Arc::new(AtomicBool::new(false));
    let (watcher, peak) = watch_rss(&server, Arc::clone(&stop));
    let started = Instant::now();
    let body = json!({"start": 0, "end": (POSES - 1) as f64 / 240.0, "fps": 240});
    let mut resp = http.post(server.url(&format!("/v1/clips/{id}/sample"))).json(&body).send().await.unwrap();
    assert_eq!(resp.status(), 200);
    let (mut bytes, mut tail) = (0u64, Vec::new());
    while let Some(chunk) = resp.chunk().await.unwrap() {
        bytes += chunk.len() as u64;
        tail = chunk.slice(chunk.len().saturating_sub(2)..).to_vec();
        let due = Duration::from_secs_f64(bytes as f64 / BYTES_PER_SEC);
        if let Some(wait) = due.checked_sub(started.elapsed()) {
            // The time is the behaviour here: a slow reader, paced.
            tokio::time::sleep(wait).await;
        }
    }
    let took = started.elapsed();
    stop.store(true, Ordering::Relaxed);
    watcher.await.unwrap();
    let peak = peak.load(Ordering::Relaxed);
    let growth = peak.saturating_sub(baseline);
    eprintln!(
        "answer {bytes} bytes in {took:?}; server RSS baseline {} MiB, peak {} MiB (+{} MiB)",
        baseline >> 20,
        peak >> 20,
        growth >> 20
    );
    assert!(bytes > 150_000_000, "a ~200 MB answer, got {bytes} bytes");
    assert_eq!(tail, b"]}", "the document is whole");
    assert!(growth < 64 << 20, "the server grew {} MiB for a {} MB answer", growth >> 20, bytes / 1_000_000);
}
