//! Strict query strings on every API and operations route (docs/api.md, "Strict queries"):
//! an unknown or repeated parameter is a 400 naming it, and the request does
//! nothing — in particular a write with an option the route does not have
//! stores nothing.

use reqwest::{Method, RequestBuilder};
use serde_json::Value;

use super::{TestApp, WAVE};

/// A two-frame BVH file, for the import route.
const TINY_BVH: &str = "HIERARCHY\nROOT hip\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition Zposition\n  \
End Site\n  {\n    OFFSET 0 1 0\n  }\n}\nMOTION\nFrames: 2\nFrame Time: 0.5\n0 0 0\n1 0 0\n";

/// Sends `req`; asserts a 400 problem with `code` naming `parameter`.
async fn refused(req: RequestBuilder, code: &str, parameter: &str, what: &str) {
    let resp = req.send().await.unwrap();
    assert_eq!(resp.status(), 400, "{what}");
    let body: Value = resp.json().await.unwrap();
    assert_eq!((body["code"].as_str(), body["parameter"].as_str()), (Some(code), Some(parameter)), "{what}: {body}");
}

fn json_body(req: RequestBuilder, body: &str) -> RequestBuilder {
    req.header("content-type", "application/json").body(body.to_owned())
}

/// (id, version) of every stored clip.
async fn stored(app: &TestApp) -> Vec<(String, u64)> {
    let all = app.list_all(100, None).await;
    all.iter().map(|c| (c["id"].as_str().unwrap().to_owned(), c["version"].as_u64().unwrap())).collect()
}

#[tokio::test]
async fn an_upload_with_an_unknown_option_stores_nothing() {
    let app = TestApp::start().await;
    let c = &app.http;
    refused(json_body(c.post(app.url("/v1/clips?dry_run=1")), WAVE), "unknown_parameter", "dry_run", "dry_run").await;
    let import = c.post(app.url("/v1/clips/import?format=bvh&dry_run=1")).body(TINY_BVH);
    refused(import, "unknown_parameter", "dry_run", "import dry_run").await;
    assert_eq!(stored(&app).await, [], "nothing was stored");
    let import = c.post(app.url("/v1/clips/import?format=bvh")).body(TINY_BVH).send().await.unwrap();
    assert_eq!(import.status(), 201, "the same import without the option");
    let import = c.post(app.url("/v1/clips/import?format=bvh&format=bvh")).body(TINY_BVH);
    refused(import, "repeated_parameter", "format", "import format twice").await;
    // The same upload without the option is stored: the refusal was the option's.
    app.create(WAVE, None).await;
    assert_eq!(stored(&app).await.len(), 2);
    app.stop().await;
}

#[tokio::test]
async fn every_clip_route_refuses_unknown_and_repeated_parameters() {
    let app = TestApp::start().await;
    let id = app.create(WAVE, None).await["id"].as_str().unwrap().to_owned();
    let clip = app.url(&format!("/v1/clips/{id}"));
    let c = &app.http;
    let cases: Vec<(&str, RequestBuilder, &str, &str)> = vec![
        ("get", c.get(format!("{clip}?x=1")), "unknown_parameter", "x"),
        ("replace", json_body(c.put(format!("{clip}?x=1")), WAVE), "unknown_parameter", "x"),
        ("delete", c.delete(format!("{clip}?force=1")), "unknown_parameter", "force"),
        ("list", c.get(app.url("/v1/clips?limit=5&limit=6")), "repeated_parameter", "limit"),
        ("list typo", c.get(app.url("/v1/clips?page=2")), "unknown_parameter", "page"),
        ("pose", c.get(format!("{clip}/pose?t=0&time=1")), "unknown_parameter", "time"),
        ("sample", json_body(c.post(format!("{clip}/sample?fps=30")), r#"{"times":[0]}"#), "unknown_parameter", "fps"),
    ];
    for (what, req, code, parameter) in cases {
        refused(req, code, parameter, what).await;
    }
    // HEAD is GET's: the same parameters (no body to read; the status says it).
    assert_eq!(c.request(Method::HEAD, format!("{clip}?x=1")).send().await.unwrap().status(), 400);
    assert_eq!(stored(&app).await, [(id.clone(), 1)], "the clip is unchanged and still there");
    // Documented parameters still pass.
    let page = c.get(app.url("/v1/clips?limit=5&name=wave")).send().await.unwrap();
    assert_eq!(page.status(), 200);
    app.stop().await;
}

#[tokio::test]
async fn operations_routes_take_no_parameters_but_static_documents_do() {
    let app = TestApp::start().await;
    for path in ["/healthz", "/readyz", "/metrics"] {
        refused(app.http.get(app.url(&format!("{path}?verbose=1"))), "unknown_parameter", "verbose", path).await;
        assert_eq!(app.http.get(app.url(path)).send().await.unwrap().status(), 200, "{path}");
    }
    // Pages and the OpenAPI document are files: a cache-busting query is harmless.
    for path in ["/viewer?v=2", "/openapi.json?v=2"] {
        assert_eq!(app.http.get(app.url(path)).send().await.unwrap().status(), 200, "{path}");
    }
    app.stop().await;
}
