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
    // One clip with arc-length tables weighs about 18 KB; the bound holds three.
    let server = start(&data, &["--cache-bytes", "60000"]).await;
    let http = crate::common::http_client();
    let mut peak = 0.0f64;
    for k in 0..16 {
        server.create(&http, &looping_hermite(&format!("heavy{k}"), 1, 2, 1.0)).await;
        let text = metrics(&server, &http).await;
        let bytes = metric(&text, "inbetween_cache_bytes").expect("inbetween_cache_bytes");
        let entries = metric(&text, "inbetween_cache_entries").expect("inbetween_cache_entries");
        assert!(bytes <= 6e4, "after {} uploads: {bytes} B cached", k + 1);
        assert!((1.0..=16.0).contains(&entries));
        peak = peak.max(bytes);
    }
    let text = metrics(&server, &http).await;
    assert_eq!(metric(&text, "inbetween_cache_limit_bytes"), Some(6e4));
    assert!(metric(&text, "inbetween_cache_entries").unwrap() < 16.0, "some clips were evicted by bytes");
    assert!(peak > 4e4, "the cache filled towards its bound: peak {peak} B");
    let rss = server.rss_bytes();
    eprintln!("16 heavy clips: cache peak {peak} B, RSS {} MiB", rss >> 20);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hostile_upload_is_refused_and_healthz_keeps_answering() {
    let dir = tempfile::tempdir().unwrap();
    // The debug binary is many times slower than release: a smaller budget.
    let server = start(&dir.path().join("data"), &["--max-build-work", "200000"]).await;
    let http = crate::common::http_client();
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
                // Pacing the probe: not a wait on anything.
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
    if crate::common::latency_checked() {
        assert!(worst < Duration::from_millis(250), "/healthz took {worst:?}");
    }
}

/// Peak resident set size of the process so far (`VmHWM`), in bytes.
fn peak_rss(server: &super::ServerProcess) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{}/status", server.pid())).unwrap_or_default();
    let kb = status.lines().find_map(|l| l.strip_prefix("VmHWM:")).map(|v| v.trim().trim_end_matches("kB").trim());
    kb.and_then(|v| v.parse::<u64>().ok()).map_or(0, |kb| kb * 1024)
}

fn p99(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[(v.len() * 99 / 100).min(v.len() - 1)]
}

/// Figures for RELIABILITY.md (`scripts/build_budget.sh`: release build,
/// default settings): the two concurrent ~50 KB uploads (time to
/// the 422, `/healthz` and gRPC `Ping` p99, peak RSS), then the most
/// expensive clip the default budget admits (its upload time and peak RSS).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn build_budget_figures() {
    if !crate::common::slow_runs("the build budget figures") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("data"), &[]).await;
    let http = crate::common::http_client();
    let at_start = peak_rss(&server);
    let doc = looping_hermite("attack", 40, 17, 3000.0);
    let (done_tx, done_rx) = tokio::sync::watch::channel(false);
    let probe = {
        let (http, url, grpc_url) = (http.clone(), server.url("/healthz"), server.grpc_url());
        tokio::spawn(async move {
            let mut grpc =
                formats::wire::proto::pb::animation_client::AnimationClient::connect(grpc_url).await.unwrap();
            let (mut healthz, mut ping) = (Vec::new(), Vec::new());
            while !*done_rx.borrow() {
                let started = Instant::now();
                assert_eq!(http.get(&url).send().await.unwrap().status(), 200);
                healthz.push(started.elapsed());
                let started = Instant::now();
                grpc.ping(formats::wire::proto::pb::PingRequest {}).await.unwrap();
                ping.push(started.elapsed());
                // Pacing the probe: not a wait on anything.
                tokio::time::sleep(Duration::from_millis(2)).await;
            }
            (healthz, ping)
        })
    };
    let upload =
        |body: String| http.post(server.url("/v1/clips")).header("content-type", "application/json").body(body).send();
    let started = Instant::now();
    let (a, b) = tokio::join!(upload(doc.clone()), upload(doc.clone()));
    let took = started.elapsed();
    done_tx.send(true).unwrap();
    assert_eq!((a.unwrap().status().as_u16(), b.unwrap().status().as_u16()), (422, 422));
    let (healthz, ping) = probe.await.unwrap();
    let n = healthz.len();
    eprintln!(
        "FIGURE two {} B uploads refused 422 in {took:?}; /healthz p99 {:?}, Ping p99 {:?} over {n} probes; \
         peak RSS {} MiB (at start {} MiB)",
        doc.len(),
        p99(healthz),
        p99(ping),
        peak_rss(&server) >> 20,
        at_start >> 20
    );
    // The most expensive admitted: one looping track, as many keys as fit.
    for keys in (2..=30).rev() {
        let doc = looping_hermite(&format!("max{keys}"), 1, keys, 3000.0);
        let before = peak_rss(&server);
        let started = Instant::now();
        let response = upload(doc.clone()).await.unwrap();
        let took = started.elapsed();
        if response.status() == 201 {
            eprintln!(
                "FIGURE largest admitted: {} keys ({} B), uploaded 201 in {took:?}; peak RSS {} MiB (before {} MiB), \
                 RSS now {} MiB",
                keys,
                doc.len(),
                peak_rss(&server) >> 20,
                before >> 20,
                server.rss_bytes() >> 20
            );
            sixteen_of(&server, &http, keys).await;
            return;
        }
        assert_eq!(response.status(), 422);
    }
    panic!("no clip was admitted");
}

/// The "16 uploads" with the largest admitted clip: the cache's
/// bytes on `/metrics` and the process's RSS after them.
async fn sixteen_of(server: &super::ServerProcess, http: &reqwest::Client, keys: usize) {
    let started = Instant::now();
    for k in 0..15 {
        server.create(http, &looping_hermite(&format!("copy{k}"), 1, keys, 3000.0)).await;
    }
    let text = metrics(server, http).await;
    eprintln!(
        "FIGURE 16 largest admitted clips in {:?}: inbetween_cache_bytes {} of {} ({} entries); RSS {} MiB, peak {} MiB",
        started.elapsed(),
        metric(&text, "inbetween_cache_bytes").unwrap(),
        metric(&text, "inbetween_cache_limit_bytes").unwrap(),
        metric(&text, "inbetween_cache_entries").unwrap(),
        server.rss_bytes() >> 20,
        peak_rss(server) >> 20
    );
}
