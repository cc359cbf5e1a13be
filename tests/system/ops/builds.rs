//! Clip builds and the compiled-clip cache in the real binary (issue 15):
//! `/metrics` reports the cache's bytes against its bound while heavy clips
//! stream in, and a hostile upload is refused without the probes stalling.

use std::time::{Duration, Instant};

use crate::common::{looping_hermite, metric};

use super::start;

async fn metrics(server: &super::ServerProcess, http: &reqwest::Client) -> String {
    http.get(server.url("/metrics")).send().await.unwrap().text().await.unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_cache_reports_its_bytes_under_the_bound_on_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    // One heavy clip weighs about 850 KB; the bound holds three.
    let server = start(&data, &["--cache-bytes", "3000000"]).await;
    let http = reqwest::Client::new();
    let mut peak = 0.0f64;
    for k in 0..16 {
        server.create(&http, &looping_hermite(&format!("heavy{k}"), 3, 4, 30.0)).await;
        let text = metrics(&server, &http).await;
        let bytes = metric(&text, "inbetween_cache_bytes").expect("inbetween_cache_bytes");
        let entries = metric(&text, "inbetween_cache_entries").expect("inbetween_cache_entries");
        assert!(bytes <= 3e6, "after {} uploads: {bytes} B cached", k + 1);
        assert!(entries >= 1.0 && entries <= 16.0);
        peak = peak.max(bytes);
    }
    let text = metrics(&server, &http).await;
    assert_eq!(metric(&text, "inbetween_cache_limit_bytes"), Some(3e6));
    assert!(metric(&text, "inbetween_cache_entries").unwrap() < 16.0, "some clips were evicted by bytes");
    assert!(peak > 2e6, "the cache filled towards its bound: peak {peak} B");
    let rss = server.rss_bytes();
    eprintln!("16 heavy clips: cache peak {peak} B, RSS {} MiB", rss >> 20);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hostile_upload_is_refused_and_healthz_keeps_answering() {
    let dir = tempfile::tempdir().unwrap();
    // The debug binary is many times slower than release: a smaller budget.
    let server = start(&dir.path().join("data"), &["--max-build-work", "2000000"]).await;
    let http = reqwest::Client::new();
    let doc = looping_hermite("attack", 40, 17, 3000.0);
    let (done_tx, done_rx) = tokio::sync::watch::channel(false);
    let probe = {
        let (http, url) = (http.clone(), server.url("/healthz"));
        tokio::spawn(async move {
            let mut worst = Duration::ZERO;
            while !*done_rx.borrow() {
                let started = Instant::now();
                assert_eq!(http.get(&url).send().await.unwrap().status(), 200);
                worst = worst.max(started.elapsed());
                tokio::time::sleep(Duration::from_millis(5)).await;
            }
            worst
        })
    };
    let upload = || http.post(server.url("/v1/clips")).header("content-type", "application/json").body(doc.clone());
    let (a, b) = tokio::join!(upload().send(), upload().send());
    done_tx.send(true).unwrap();
    for response in [a.unwrap(), b.unwrap()] {
        assert_eq!(response.status(), 422);
        let problem: serde_json::Value = response.json().await.unwrap();
        assert_eq!(problem["code"], "build_budget_exceeded");
    }
    let worst = probe.await.unwrap();
    eprintln!("two hostile uploads: /healthz worst {worst:?}, RSS {} MiB", server.rss_bytes() >> 20);
    assert!(worst < Duration::from_millis(250), "/healthz took {worst:?}");
}
