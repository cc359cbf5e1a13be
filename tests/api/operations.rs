//! Health, readiness, metrics, the OpenAPI document and graceful shutdown.

use serde_json::Value;

use super::{WAVE, spawn_app};

#[tokio::test]
async fn health_readiness_and_metrics_report() {
    let app = spawn_app().await;
    let health: Value = app.get_json("/healthz").await;
    assert_eq!(health["status"], "ok");
    let ready: Value = app.get_json("/readyz").await;
    assert_eq!(ready["status"], "ready");

    let id = app.create(WAVE, None).await["id"].as_str().unwrap().to_owned();
    for _ in 0..3 {
        let r = app.client.get(app.url(&format!("/v1/clips/{id}/pose?t=1"))).send().await.unwrap();
        assert_eq!(r.status(), 200);
    }
    let text = app.client.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
    // Labelled by route template, never by the raw id.
    assert!(text.contains(r#"route="/v1/clips/{id}/pose""#), "{text}");
    assert!(!text.contains(&id), "a clip id leaked into metric labels");
    for name in [
        "inbetween_http_requests_total",
        "inbetween_http_request_duration_seconds_bucket",
        "inbetween_poses_evaluated_total",
        "inbetween_clip_cache_hits_total",
        "inbetween_store_operation_duration_seconds_bucket",
    ] {
        assert!(text.contains(name), "missing {name}");
    }
    app.stop().await;
}

#[tokio::test]
async fn the_openapi_document_lists_every_route_and_docs_are_served() {
    let app = spawn_app().await;
    let doc: Value = app.get_json("/openapi.json").await;
    assert!(doc["openapi"].as_str().unwrap().starts_with("3."));
    let paths = doc["paths"].as_object().unwrap();
    for path in [
        "/v1/clips",
        "/v1/clips/{id}",
        "/v1/clips/{id}/pose",
        "/v1/clips/{id}/sample",
        "/healthz",
        "/readyz",
        "/metrics",
    ] {
        assert!(paths.contains_key(path), "{path} missing from the OpenAPI document");
    }
    assert!(doc["components"]["schemas"]["ClipDoc"].is_object());
    let docs = app.client.get(app.url("/docs/")).send().await.unwrap();
    assert_eq!(docs.status(), 200);
    assert!(docs.text().await.unwrap().contains("swagger"));
    app.stop().await;
}

#[tokio::test]
async fn shutdown_finishes_and_closes_the_listener() {
    let app = spawn_app().await;
    let addr = app.addr;
    app.create(WAVE, None).await;
    app.stop().await;
    assert!(reqwest::get(format!("http://{addr}/healthz")).await.is_err(), "still accepting after shutdown");
}

#[tokio::test]
async fn readiness_fails_when_the_store_is_gone_but_liveness_holds() {
    let app = spawn_app().await;
    app.state.store.close().await;
    let resp = app.client.get(app.url("/readyz")).send().await.unwrap();
    assert_eq!(resp.status(), 503);
    let problem: Value = resp.json().await.unwrap();
    assert_eq!(problem["code"], "unavailable");
    assert!(!problem["detail"].as_str().unwrap().to_lowercase().contains("pool"), "internals leaked: {problem}");
    assert_eq!(app.client.get(app.url("/healthz")).send().await.unwrap().status(), 200);
    // A request that needs the store gets a clean 503 too, not a 500 with a database message.
    let resp = app.client.get(app.url("/v1/clips")).send().await.unwrap();
    assert_eq!(resp.status(), 503);
    app.stop().await;
}
