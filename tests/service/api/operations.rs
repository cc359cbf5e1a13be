//! Health, readiness, metrics, the OpenAPI document and graceful shutdown.

use serde_json::Value;

use super::{TestApp, WAVE, within};
use crate::common::internal_contract_citations;

#[tokio::test]
async fn health_readiness_and_metrics_report() {
    let app = TestApp::start().await;
    let health: Value = app.get_json("/healthz").await;
    assert_eq!(health["status"], "ok");
    let ready: Value = app.get_json("/readyz").await;
    assert_eq!(ready["status"], "ready");

    let id = app.create(WAVE, None).await["id"].as_str().unwrap().to_owned();
    for _ in 0..3 {
        let r = app.http.get(app.url(&format!("/v1/clips/{id}/pose?t=1"))).send().await.unwrap();
        assert_eq!(r.status(), 200);
    }
    let text = app.http.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
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
    let app = TestApp::start().await;
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
    let docs = app.http.get(app.url("/docs/")).send().await.unwrap();
    assert_eq!(docs.status(), 200);
    assert!(docs.text().await.unwrap().contains("swagger"));
    app.stop().await;
}

/// The OpenAPI descriptions stand alone: they cite no contract users do not
/// have (`common::internal_contract_citations`) and point at the repository's own docs, which exist: the
/// clip document at docs/clip-format.md, motions at docs/motion.md.
#[tokio::test]
async fn the_openapi_document_links_the_docs_and_cites_no_spec() {
    let app = TestApp::start().await;
    let text = app.http.get(app.url("/openapi.json")).send().await.unwrap().text().await.unwrap();
    let cited: Vec<&str> = internal_contract_citations(&text)
        .into_iter()
        .map(|i| &text[text.floor_char_boundary(i.saturating_sub(80))..text.ceil_char_boundary(i + 12)])
        .collect();
    assert!(cited.is_empty(), "the OpenAPI document cites the internal contract: {cited:#?}");
    let doc: Value = serde_json::from_str(&text).unwrap();
    let description = |v: &Value| v["description"].as_str().unwrap_or_default().to_owned();
    let schemas = &doc["components"]["schemas"];
    assert!(description(&schemas["ClipDoc"]).contains("docs/clip-format.md"), "{}", schemas["ClipDoc"]);
    assert!(description(&schemas["MotionDoc"]).contains("docs/motion.md"), "{}", schemas["MotionDoc"]);
    let info = description(&doc["info"]);
    for page in ["api", "configuration", "clip-format", "motion", "ik", "broadcasts", "import", "warnings"] {
        assert!(info.contains(&format!("docs/{page}.md")), "{info}");
    }
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut named = 0;
    for piece in text.split("docs/").skip(1) {
        let name: String = piece.chars().take_while(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '.')).collect();
        let name = name.trim_end_matches('.');
        if name.ends_with(".md") {
            assert!(root.join("docs").join(name).is_file(), "the OpenAPI document names docs/{name}");
            named += 1;
        }
    }
    assert!(named >= 10, "{named} links to docs/");
    app.stop().await;
}

/// Shutdown drains: readiness flips, a stream gets its documented end
/// (close 1001), a request already in flight is still answered, the server
/// returns cleanly, and only then does the listener refuse connections.
#[tokio::test]
async fn shutdown_drains_in_flight_work_then_closes_the_listener() {
    use futures_util::StreamExt;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    use tokio_tungstenite::tungstenite::Message;

    let app = TestApp::start().await;
    let (addr, state) = (app.addr, app.state.clone());
    let id = app.create_id(WAVE, None).await;
    let mut ws = app.ws(&format!("/v1/clips/{id}/stream?fps=30")).await;
    // An upload whose body is half sent when the shutdown comes.
    let mut upload = tokio::net::TcpStream::connect(addr).await.unwrap();
    let head = format!(
        "POST /v1/clips?replace=true HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\
         Connection: close\r\n\r\n",
        WAVE.len()
    );
    let (first, rest) = WAVE.split_at(WAVE.len() / 2);
    upload.write_all(format!("{head}{first}").as_bytes()).await.unwrap();
    let five = std::time::Duration::from_secs(5);
    crate::common::eventually(five, "the half body held", || async { state.arrivals.held() > 0 }).await;

    let stop = tokio::spawn(app.stop());
    crate::common::eventually(five, "readiness flips", || async { !state.is_ready() }).await;
    let close = within(5, "the stream's close", async {
        loop {
            match ws.next().await {
                Some(Ok(Message::Close(frame))) => return frame.map(|f| u16::from(f.code)),
                Some(Ok(_)) => {}
                other => panic!("the stream ended without a close frame: {other:?}"),
            }
        }
    })
    .await;
    assert_eq!(close, Some(1001), "going away");
    upload.write_all(rest.as_bytes()).await.unwrap();
    let mut reply = Vec::new();
    within(5, "the upload's answer", upload.read_to_end(&mut reply)).await.unwrap();
    let reply = String::from_utf8_lossy(&reply);
    // A new version of the wave stored earlier.
    assert!(reply.starts_with("HTTP/1.1 200 "), "the in-flight upload is answered: {reply}");
    within(10, "the server stops", stop).await.unwrap();
    assert!(reqwest::get(format!("http://{addr}/healthz")).await.is_err(), "still accepting after shutdown");
}

#[tokio::test]
async fn readiness_fails_when_the_store_is_gone_but_liveness_holds() {
    let app = TestApp::start().await;
    app.state.store.close().await;
    let resp = app.http.get(app.url("/readyz")).send().await.unwrap();
    assert_eq!(resp.status(), 503);
    let problem: Value = resp.json().await.unwrap();
    assert_eq!(problem["code"], "unavailable");
    assert!(!problem["detail"].as_str().unwrap().to_lowercase().contains("pool"), "internals leaked: {problem}");
    assert_eq!(app.http.get(app.url("/healthz")).send().await.unwrap().status(), 200);
    // A request that needs the store gets a clean 503 too, not a 500 with a database message.
    let resp = app.http.get(app.url("/v1/clips")).send().await.unwrap();
    assert_eq!(resp.status(), 503);
    app.stop().await;
}
