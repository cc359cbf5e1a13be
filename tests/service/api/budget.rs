//! Clip builds (issue 15): each clip's build work is bounded for the whole
//! clip (422 `build_budget_exceeded`, the same code on gRPC `PutClip`),
//! builds run off the async workers so probes keep answering during hostile
//! uploads, and the compiled-clip cache is bounded in bytes.

use std::time::{Duration, Instant};

use serde_json::Value;

use anim::Clip;
use formats::wire::json::parse_clip;
use formats::wire::proto::pb;

use super::TestApp;
use crate::common::{looping_hermite, metric};
use crate::security::status_table::grpc_codes_for;

/// The upload: about 50 KB of looping constant-speed tracks.
fn attack_doc(name: &str) -> String {
    let doc = looping_hermite(name, 40, 17, 3000.0);
    assert!((40_000..70_000).contains(&doc.len()), "{} bytes", doc.len());
    doc
}

/// Latencies of `/healthz` and gRPC `Ping`, probed every 5 ms until `stop`.
async fn probe(app: &TestApp, stop: tokio::sync::watch::Receiver<bool>) -> Vec<Duration> {
    let mut grpc = app.grpc().await;
    let mut seen = Vec::new();
    while !*stop.borrow() {
        let started = Instant::now();
        let healthz = app.http.get(app.url("/healthz")).send().await.unwrap();
        assert_eq!(healthz.status(), 200);
        seen.push(started.elapsed());
        let started = Instant::now();
        grpc.ping(pb::PingRequest {}).await.unwrap();
        seen.push(started.elapsed());
        // Pacing the probe: not a wait on anything.
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    seen
}

fn p99(mut latencies: Vec<Duration>) -> Duration {
    latencies.sort();
    latencies[(latencies.len() * 99 / 100).min(latencies.len() - 1)]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_concurrent_hostile_uploads_are_refused_while_the_probes_answer() {
    // A smaller budget than the default 16M units: this is a debug build,
    // ~75 times slower than release (the default's time is in RELIABILITY.md),
    // and other tests in this binary time their frames.
    let app = TestApp::builder().configure(|c| c.limits.max_build_work = 200_000).start().await;
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let probes = probe(&app, stop_rx);
    let uploads = async {
        let upload = |name: &'static str| {
            app.http.post(app.url("/v1/clips")).header("content-type", "application/json").body(attack_doc(name)).send()
        };
        let started = Instant::now();
        let (a, b) = tokio::join!(upload("a"), upload("b"));
        let took = started.elapsed();
        stop_tx.send(true).unwrap();
        (a.unwrap(), b.unwrap(), took)
    };
    let (latencies, (a, b, took)) = tokio::join!(probes, uploads);
    for response in [a, b] {
        assert_eq!(response.status(), 422);
        let problem: Value = response.json().await.unwrap();
        assert_eq!(problem["code"], "build_budget_exceeded", "{problem}");
        let detail = problem["detail"].as_str().unwrap();
        assert!(detail.contains("200000") && detail.contains("--max-build-work"), "{detail}");
    }
    let (n, worst) = (latencies.len(), p99(latencies));
    eprintln!("two hostile uploads refused in {took:?}; {n} probes, p99 {worst:?}");
    assert!(n >= 10, "only {n} probes in {took:?}");
    if crate::common::latency_checked() {
        assert!(worst < Duration::from_millis(100), "probe p99 {worst:?} over {n} probes");
    }
    assert_eq!(app.state.work.meter().held(), 0, "every build gave its price back");
    app.stop().await;
}

/// A clip with arc-length tables (37k units of work), and its cache weight.
fn heavy_clip(name: &str) -> (String, usize) {
    let doc = looping_hermite(name, 1, 2, 1.0);
    let clip = Clip::build(&parse_clip(doc.as_bytes()).unwrap().1).unwrap();
    (doc, clip.heap_bytes())
}

/// A gauge's value on `/metrics`.
async fn gauge(app: &TestApp, name: &str) -> f64 {
    let text = app.http.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
    metric(&text, name).unwrap_or_else(|| panic!("{name} in\n{text}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sixteen_heavy_clips_leave_the_cache_under_its_byte_bound() {
    let (_, one) = heavy_clip("probe");
    assert!(one > 8 * 1024, "a heavy clip weighs {one} B");
    let limit = one * 7 / 2;
    let app = TestApp::builder().configure(|c| c.limits.cache_bytes = limit).start().await;
    let mut ids = Vec::new();
    for k in 0..16 {
        let (doc, _) = heavy_clip(&format!("heavy{k}"));
        ids.push(app.create(&doc, None).await["id"].as_str().unwrap().to_owned());
        let (entries, bytes) = (app.state.cache.len(), app.state.cache.bytes());
        assert!(bytes <= limit, "after {} uploads: {bytes} B cached, over {limit}", k + 1);
        assert!(entries <= 3, "{entries} heavy clips fit in {limit} B");
    }
    assert_eq!(app.state.cache.len(), 3, "the three most recent");
    assert!(app.state.cache.get(&ids[15]).is_some() && app.state.cache.get(&ids[0]).is_none());
    // /metrics reports it (other apps in this process share the gauges, and
    // none of them caches more than this one's bound).
    let reported = gauge(&app, "inbetween_cache_bytes").await;
    assert!(reported > 0.0 && reported <= limit as f64, "inbetween_cache_bytes {reported}, bound {limit}");
    assert!(gauge(&app, "inbetween_cache_limit_bytes").await > 0.0);
    // Evicted clips still answer: the miss rebuilds them through the gate.
    let pose = app.get_json(&format!("/v1/clips/{}/pose?t=1.5", ids[0])).await;
    assert_eq!(pose["joints"].as_array().unwrap().len(), 1);
    assert!(app.state.cache.bytes() <= limit);
    app.stop().await;
}

#[tokio::test]
async fn put_clip_over_the_budget_gets_the_rest_code() {
    let app = TestApp::builder().configure(|c| c.limits.max_build_work = 50_000).start().await;
    let doc = looping_hermite("over", 1, 3, 30.0);
    let rest = app.http.post(app.url("/v1/clips")).header("content-type", "application/json").body(doc.clone());
    let response = rest.send().await.unwrap();
    assert_eq!(response.status(), 422);
    let problem: Value = response.json().await.unwrap();
    assert_eq!(problem["code"], "build_budget_exceeded");
    assert!(problem["detail"].as_str().unwrap().contains("50000"), "{problem}");
    let pointer = problem["pointer"].as_str().unwrap_or_default().to_owned();
    assert!(pointer.starts_with("/tracks/"), "{problem}");

    let spec = parse_clip(doc.as_bytes()).unwrap().1;
    let put = pb::PutClipRequest { clip: Some(formats::wire::proto::clip_to_pb(&spec)), ..Default::default() };
    let refused = app.grpc().await.put_clip(put).await.unwrap_err();
    assert!(grpc_codes_for(422).contains(&refused.code()), "{refused:?}");
    let code = refused.metadata().get("x-error-code").map(|v| v.to_str().unwrap().to_owned());
    assert_eq!(code.as_deref(), Some("build_budget_exceeded"));
    assert!(refused.message().contains(&pointer), "{}", refused.message());

    // Under the budget the same shape is stored, on both protocols.
    let small = looping_hermite("under", 1, 2, 1.0);
    assert_eq!(app.create(&small, None).await["name"], "under");
    let spec = parse_clip(small.as_bytes()).unwrap().1;
    let put =
        pb::PutClipRequest { clip: Some(formats::wire::proto::clip_to_pb(&spec)), replace: true, ..Default::default() };
    assert_eq!(app.grpc().await.put_clip(put).await.unwrap().into_inner().version, 2, "a new version of `under`");
    app.stop().await;
}

#[tokio::test]
async fn a_stored_clip_over_a_lowered_budget_is_refused_not_a_500() {
    let dir = tempfile::tempdir().unwrap();
    let doc = looping_hermite("stored", 1, 2, 1.0);
    let id = {
        let app = TestApp::builder().data_dir(dir.path()).start().await;
        let id = app.create(&doc, None).await["id"].as_str().unwrap().to_owned();
        app.stop().await;
        id
    };
    let app = TestApp::builder().data_dir(dir.path()).configure(|c| c.limits.max_build_work = 100).start().await;
    let response = app.http.get(app.url(&format!("/v1/clips/{id}/pose?t=1"))).send().await.unwrap();
    assert_eq!(response.status(), 422);
    let problem: Value = response.json().await.unwrap();
    assert_eq!(problem["code"], "build_budget_exceeded", "{problem}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_timed_out_upload_stops_its_build_instead_of_finishing_it() {
    // A budget that would take minutes of debug build; a 1 s request timeout.
    let app = TestApp::builder()
        .configure(|c| {
            c.limits.max_build_work = 1_000_000_000;
            c.limits.max_request_work = u64::MAX;
            c.limits.request_timeout = Duration::from_secs(1);
        })
        .start()
        .await;
    let upload = app.http.post(app.url("/v1/clips")).header("content-type", "application/json");
    let response = upload.body(looping_hermite("slow", 40, 17, 3000.0)).send().await.unwrap();
    assert_eq!(response.status(), 503, "the request timed out");
    let started = Instant::now();
    // A build holds its price until its thread lets go of it.
    let stopped = || async { app.state.work.meter().held() == 0 };
    crate::common::eventually(Duration::from_secs(5), "the abandoned build stops", stopped).await;
    eprintln!("the abandoned build stopped {:?} after the 503", started.elapsed());
    app.stop().await;
}
