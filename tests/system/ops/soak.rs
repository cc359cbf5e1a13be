//! The soak: 200 WebSocket viewers for 30 minutes (`SOAK_SECS`), each
//! reconnecting after a minute of frames so stream start and end are
//! exercised all along, while the server's RSS is sampled. Passes when RSS
//! grows at most 5% from the end of the warm-up (`SOAK_WARMUP_SECS`, default
//! a sixth of the run, at most 5 minutes) to the end of the run.
//!
//! `INBETWEEN_SLOW=1 SOAK_SECS=1800 cargo test --test system soak -- --nocapture` (`scripts/soak.sh`)

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use futures_util::StreamExt;

use super::{WAVE, start};

const VIEWERS: usize = 200;
/// Frame rates in the mix: viewers with one rate share a playback.
const RATES: [u32; 4] = [10, 24, 30, 60];

#[tokio::test(flavor = "multi_thread")]
async fn two_hundred_viewers_for_thirty_minutes_keep_rss_flat() {
    if !crate::common::slow_runs("the soak (scripts/soak.sh)") {
        return;
    }
    let secs: u64 = std::env::var("SOAK_SECS").ok().and_then(|s| s.parse().ok()).unwrap_or(1800);
    // The warm-up covers several reconnect rounds (one a minute), so the
    // allocator's pools have reached their working size before the baseline.
    let warmup = Duration::from_secs(
        std::env::var("SOAK_WARMUP_SECS").ok().and_then(|s| s.parse().ok()).unwrap_or((secs / 6).clamp(10, 300)),
    );
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("data"), &["--max-streams-per-client", "1000"]).await;
    let http = crate::common::http_client();
    let ids = [server.create(&http, WAVE).await, server.create(&http, WAVE).await];
    let frames = Arc::new(AtomicU64::new(0));
    let errors = Arc::new(AtomicU64::new(0));
    let end = Instant::now() + Duration::from_secs(secs);
    let mut viewers = Vec::new();
    for v in 0..VIEWERS {
        let fps = RATES[v % RATES.len()];
        let url = format!("ws://{}/v1/clips/{}/stream?fps={fps}&max_frames={}", server.http, ids[v % 2], fps * 60);
        let (frames, errors) = (frames.clone(), errors.clone());
        viewers.push(tokio::spawn(async move {
            while Instant::now() < end {
                match tokio_tungstenite::connect_async(&url).await {
                    Ok((mut ws, _)) => {
                        while let Some(msg) = ws.next().await {
                            match msg {
                                Ok(m) if m.is_text() => {
                                    frames.fetch_add(1, Ordering::Relaxed);
                                }
                                Ok(_) => {}
                                Err(_) => {
                                    errors.fetch_add(1, Ordering::Relaxed);
                                    break;
                                }
                            }
                            if Instant::now() >= end {
                                break;
                            }
                        }
                    }
                    Err(_) => {
                        errors.fetch_add(1, Ordering::Relaxed);
                        // A viewer's reconnect backoff (the soak is paced by design).
                        tokio::time::sleep(Duration::from_millis(500)).await;
                    }
                }
            }
        }));
    }
    let started = Instant::now();
    // A slow run (INBETWEEN_SLOW): the warm-up and the sampling interval are its design.
    tokio::time::sleep(warmup).await;
    let baseline = server.rss_bytes();
    let mut peak = baseline;
    println!("soak: {VIEWERS} viewers, {secs} s; RSS after {warmup:?} warm-up: {} KiB", baseline / 1024);
    while Instant::now() < end {
        tokio::time::sleep(Duration::from_secs(30).min(end.saturating_duration_since(Instant::now()))).await;
        let rss = server.rss_bytes();
        peak = peak.max(rss);
        println!(
            "soak: t={:>5} s rss={} KiB frames={} errors={}",
            started.elapsed().as_secs(),
            rss / 1024,
            frames.load(Ordering::Relaxed),
            errors.load(Ordering::Relaxed)
        );
    }
    let last = server.rss_bytes();
    for v in viewers {
        v.await.unwrap();
    }
    let growth = (last as f64 - baseline as f64) / baseline as f64 * 100.0;
    println!(
        "soak result: baseline {} KiB, final {} KiB, peak {} KiB, growth {growth:.2}%, frames {}, errors {}",
        baseline / 1024,
        last / 1024,
        peak / 1024,
        frames.load(Ordering::Relaxed),
        errors.load(Ordering::Relaxed)
    );
    assert!(frames.load(Ordering::Relaxed) > 0, "no frames were received");
    assert!(growth <= 5.0, "RSS grew {growth:.2}% (baseline {baseline}, final {last})");
}
