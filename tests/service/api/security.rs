//! The token matrix: which routes need which token.

use reqwest::StatusCode;
use server::config::{Cors, Secret};

use super::{TestApp, WAVE};

#[tokio::test]
async fn write_and_read_tokens_guard_their_routes() {
    let app = TestApp::builder()
        .configure(|c| {
            c.write_token = Some(Secret::new("w"));
            c.read_token = Some(Secret::new("r"));
        })
        .start()
        .await;
    let id = app.create(WAVE, Some("w")).await["id"].as_str().unwrap().to_owned();
    let clip = app.url(&format!("/v1/clips/{id}"));
    let c = &app.http;

    // Reads: the read token or the write token; nothing else.
    for (token, expected) in [(None, 401), (Some("x"), 401), (Some("r"), 200), (Some("w"), 200)] {
        let with = |r: reqwest::RequestBuilder| match token {
            Some(t) => r.bearer_auth(t),
            None => r,
        };
        let reqs = [
            with(c.get(&clip)),
            with(c.get(app.url("/v1/clips"))),
            with(c.get(format!("{clip}/pose?t=1"))),
            with(c.post(format!("{clip}/sample")).json(&serde_json::json!({"times": [0]}))),
        ];
        for req in reqs {
            assert_eq!(req.send().await.unwrap().status().as_u16(), expected, "read with {token:?}");
        }
    }
    // Writes: only the write token. The read token is known but lacks the scope (403);
    // an unknown token is unauthenticated (401).
    for (token, expected) in [("r", StatusCode::FORBIDDEN), ("x", StatusCode::UNAUTHORIZED)] {
        let create = c.post(app.url("/v1/clips")).bearer_auth(token).header("content-type", "application/json");
        assert_eq!(create.body(WAVE).send().await.unwrap().status(), expected);
        let put = c.put(&clip).bearer_auth(token).header("content-type", "application/json").body(WAVE);
        assert_eq!(put.send().await.unwrap().status(), expected);
        assert_eq!(c.delete(&clip).bearer_auth(token).send().await.unwrap().status(), expected);
    }
    let put = c.put(&clip).bearer_auth("w").header("content-type", "application/json").body(WAVE);
    assert_eq!(put.send().await.unwrap().status(), StatusCode::OK);
    // Operations endpoints stay open (probes and scrapers carry no tokens).
    for path in ["/healthz", "/readyz", "/metrics", "/openapi.json"] {
        assert_eq!(c.get(app.url(path)).send().await.unwrap().status(), StatusCode::OK, "{path}");
    }
    assert_eq!(c.delete(&clip).bearer_auth("w").send().await.unwrap().status(), StatusCode::NO_CONTENT);
    app.stop().await;
}

#[tokio::test]
async fn cors_allows_only_configured_origins() {
    let app =
        TestApp::builder().configure(|c| c.cors = Cors::Origins(vec!["https://viewer.example".into()])).start().await;
    let preflight = |origin: &'static str| {
        app.http
            .request(reqwest::Method::OPTIONS, app.url("/v1/clips"))
            .header("origin", origin)
            .header("access-control-request-method", "POST")
            .header("access-control-request-headers", "content-type,authorization")
            .send()
    };
    let ok = preflight("https://viewer.example").await.unwrap();
    assert_eq!(ok.headers()["access-control-allow-origin"], "https://viewer.example");
    let other = preflight("https://evil.example").await.unwrap();
    assert!(other.headers().get("access-control-allow-origin").is_none());
    app.stop().await;
}

#[tokio::test]
async fn a_client_that_trickles_its_request_head_is_cut_off() {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let app = TestApp::builder()
        .configure(|c| c.limits.header_read_timeout = std::time::Duration::from_secs(1))
        .start()
        .await;
    let mut slow = tokio::net::TcpStream::connect(app.addr).await.unwrap();
    slow.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n").await.unwrap(); // and never the final CRLF
    let started = std::time::Instant::now();
    let mut rest = Vec::new();
    // The server closes the connection; the read ends (bounded, should the guard be missing).
    let read = tokio::time::timeout(std::time::Duration::from_secs(20), slow.read_to_end(&mut rest)).await;
    assert!(read.is_ok(), "the connection was still open after 20 s");
    assert!(started.elapsed() >= std::time::Duration::from_millis(900), "closed before the timeout");
    // Meanwhile a well-behaved client is served.
    assert_eq!(app.http.get(app.url("/healthz")).send().await.unwrap().status(), StatusCode::OK);
    app.stop().await;
}
