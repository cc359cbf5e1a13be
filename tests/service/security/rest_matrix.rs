//! Every REST operation of the OpenAPI document × {none, invalid, read,
//! write, admin}: allowed calls succeed, the rest get 401/403 with a problem
//! body, and no refused write changes the store.

use std::collections::BTreeSet;

use reqwest::Method;
use serde_json::Value;
use server::auth::Scope;
use server::routes::{Class, ROUTES, Route};
use tokio_tungstenite::tungstenite;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

use super::{ADMIN, Need, Outcome, Role, TINY_BVH, TestApp, expected, fresh_wave, scoped_tokens, snapshot};

/// The REST routes of the route table (`server::routes`): method, path,
/// what each needs and the status it answers when allowed. A route added to
/// the OpenAPI document but not to the table fails the test.
fn routes() -> Vec<(&'static str, &'static str, Need, u16)> {
    let rest =
        |r: &Route| r.rest.map(|(method, path)| (method, path, Need::of(r.scope), allowed_status(r, method, path)));
    ROUTES.iter().filter_map(rest).collect()
}

/// What an allowed call of the operation answers.
fn allowed_status(route: &Route, method: &str, path: &str) -> u16 {
    match (method, path) {
        // Checked at the upgrade (for `/v1/stream`, the motion comes in the first message).
        _ if route.class == Class::FrameStream => 101,
        (
            "post",
            "/v1/clips"
            | "/v1/clips/import"
            | "/v1/broadcasts"
            | "/v1/characters"
            | "/v1/characters/import"
            | "/v1/graphs",
        ) => 201,
        ("delete", _) => 204,
        // The clip `call` makes is JSON, without a mesh: allowed is `404 no_mesh` (tests/service/api/mesh.rs: 200).
        ("get", "/v1/clips/{id}/mesh" | "/v1/characters/{id}/mesh") => 404,
        // The viewer page is public; it asks for a token only when an upload answers 401.
        _ => 200,
    }
}

/// The (method, path) of every operation in `/openapi.json`, with whether it
/// declares the bearer scheme.
async fn documented_operations(app: &TestApp) -> Vec<(String, String, bool)> {
    let doc: Value = app.http.get(app.url("/openapi.json")).send().await.unwrap().json().await.unwrap();
    let mut ops = Vec::new();
    for (path, item) in doc["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            if !["get", "put", "post", "delete", "patch", "head", "options"].contains(&method.as_str()) {
                continue;
            }
            let secured = op["security"].as_array().is_some_and(|s| s.iter().any(|r| r.get("bearer").is_some()));
            if secured {
                for status in ["401", "403"] {
                    assert!(op["responses"].get(status).is_some(), "{method} {path} does not document {status}");
                }
            }
            ops.push((method.clone(), path.clone(), secured));
        }
    }
    ops
}

/// Sends one request of the operation as `role`; returns the status and, for
/// refusals, the problem body.
async fn call(app: &TestApp, method: &str, path: &str, role: Role) -> (u16, Option<(String, Value)>) {
    // Each call gets its own clip, so a delete or replace cannot disturb the next one.
    let id = app.create_id(&fresh_wave(), Some(ADMIN)).await;
    let motion = serde_json::json!({"layers": [{"clip": id}]});
    // Broadcast routes get a fresh broadcast of that clip, made by the admin.
    let id = if path.starts_with("/v1/broadcasts/") {
        let created = app.http.post(app.url("/v1/broadcasts")).bearer_auth(ADMIN);
        let created = created.json(&serde_json::json!({"motion": motion, "fps": 30})).send().await.unwrap();
        let status = created.status();
        let created = created.json::<Value>().await.unwrap();
        assert_eq!(status, 201, "{created}");
        created["id"].as_str().unwrap().to_owned()
    } else if path.starts_with("/v1/characters/") {
        // Character routes get a fresh character, made by the admin.
        let created = app.http.post(app.url("/v1/characters")).bearer_auth(ADMIN).json(&fresh_character());
        let created = created.send().await.unwrap();
        assert_eq!(created.status(), 201);
        created.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned()
    } else if path.starts_with("/v1/graphs/") {
        // Graph routes get a fresh graph over the call's clip, made by the admin.
        let created = app.http.post(app.url("/v1/graphs")).bearer_auth(ADMIN).json(&fresh_graph(&id));
        let created = created.send().await.unwrap();
        let status = created.status();
        let created = created.json::<Value>().await.unwrap();
        assert_eq!(status, 201, "{created}");
        created["id"].as_str().unwrap().to_owned()
    } else {
        id
    };
    let clip = motion["layers"][0]["clip"].as_str().unwrap().to_owned();
    let path = path.replace("{id}", &id);
    if path.ends_with("/stream") {
        // A browser's way (the token as a subprotocol) answers as the header does.
        let by_header = websocket(app, &path, role, false).await;
        let by_protocol = websocket(app, &path, role, true).await;
        assert_eq!(by_protocol, by_header, "{path} as {role:?}: subprotocol token vs Authorization");
        return by_header;
    }
    let mut req = app.http.request(method.to_uppercase().parse::<Method>().unwrap(), app.url(&path));
    req = match (method, path.as_str()) {
        ("post", "/v1/characters") => req.json(&fresh_character()),
        ("put", p) if p.starts_with("/v1/characters/") => req.json(&fresh_character()),
        ("post", "/v1/graphs") => req.json(&fresh_graph(&clip)),
        ("put", p) if p.starts_with("/v1/graphs/") => req.json(&fresh_graph(&clip)),
        ("post", "/v1/clips") | ("put", _) => req.header("content-type", "application/json").body(fresh_wave()),
        ("patch", _) => req.header("content-type", "application/merge-patch+json").body(r#"{"tags":["x"]}"#),
        ("post", "/v1/clips/import" | "/v1/characters/import") => {
            let name = server::store::new_clip_id();
            req.query(&[("format", "bvh"), ("name", &name)])
                .header("content-type", "application/octet-stream")
                .body(TINY_BVH)
        }
        ("post", p) if p.ends_with("/sample") => req.json(&serde_json::json!({"times": [0.0, 0.5]})),
        ("post", "/v1/poses") => req.json(&serde_json::json!({"motion": motion, "time": 0.25})),
        ("post", "/v1/broadcasts") => req.json(&serde_json::json!({"motion": motion, "fps": 30})),
        ("post", p) if p.ends_with("/controls") => req.json(&serde_json::json!({"op": "pause"})),
        ("post", "/v1/samples") => req.json(&serde_json::json!({"motion": motion, "times": [0.0, 0.5]})),
        ("get", p) if p.ends_with("/pose") => req.query(&[("t", "0.25")]),
        _ => req,
    };
    if let Some(t) = role.token() {
        req = req.bearer_auth(t);
    }
    let resp = req.send().await.unwrap();
    let status = resp.status().as_u16();
    if resp.status().is_success() {
        return (status, None);
    }
    let ct = resp.headers().get("content-type").map(|v| v.to_str().unwrap().to_owned()).unwrap_or_default();
    let www = resp.headers().get("www-authenticate").map(|v| v.to_str().unwrap().to_owned());
    let body: Value = resp.json().await.unwrap_or(Value::Null);
    if status == 401 {
        assert_eq!(www.as_deref(), Some("Bearer"), "401 without WWW-Authenticate");
    }
    (status, Some((ct, body)))
}

/// A one-joint character under a name no other has.
/// A one-node graph over `clip` under a name no other has.
fn fresh_graph(clip: &str) -> Value {
    serde_json::json!({"name": server::store::new_clip_id(), "nodes": {"a": {"clip": clip}}, "output": "a"})
}

fn fresh_character() -> Value {
    serde_json::json!({"name": server::store::new_clip_id(), "skeleton": {"joints": [{"name": "root"}]}})
}

/// Opens the stream as `role`, its token in `Authorization` or, as a browser
/// sends it, in the subprotocol `inbetween.bearer.<base64url>` (`server::auth`).
async fn websocket(app: &TestApp, path: &str, role: Role, as_protocol: bool) -> (u16, Option<(String, Value)>) {
    use base64::Engine as _;
    let query = if path == "/v1/stream" || path.starts_with("/v1/broadcasts/") { "" } else { "?max_frames=1" };
    let mut req = format!("ws://{}{path}{query}", app.addr).into_client_request().unwrap();
    match (role.token(), as_protocol) {
        (Some(t), false) => {
            req.headers_mut().insert("authorization", format!("Bearer {t}").parse().unwrap());
        }
        (Some(t), true) => {
            let encoded = base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(t);
            let offer = format!("inbetween, inbetween.bearer.{encoded}");
            req.headers_mut().insert("sec-websocket-protocol", offer.parse().unwrap());
        }
        (None, _) => {}
    }
    match tokio_tungstenite::connect_async(req).await {
        Ok((mut ws, resp)) => {
            use futures_util::StreamExt;
            // The server selects `inbetween` (never echoing the token), as a browser requires.
            let selected = resp.headers().get("sec-websocket-protocol").map(|v| v.to_str().unwrap().to_owned());
            let offered = as_protocol && role.token().is_some();
            assert_eq!(selected.as_deref(), offered.then_some("inbetween"), "{path}: selected subprotocol");
            // Allowed: the first frame arrives.
            let first = ws.next().await.expect("a frame").expect("a frame");
            assert!(matches!(first, tungstenite::Message::Text(_)), "{first:?}");
            (resp.status().as_u16(), None)
        }
        Err(tungstenite::Error::Http(resp)) => {
            let ct = resp.headers().get("content-type").map(|v| v.to_str().unwrap().to_owned()).unwrap_or_default();
            let body = resp.body().as_deref().and_then(|b| serde_json::from_slice(b).ok()).unwrap_or(Value::Null);
            (resp.status().as_u16(), Some((ct, body)))
        }
        Err(e) => panic!("websocket {path}: {e}"),
    }
}

#[tokio::test]
async fn every_rest_route_checks_its_scope() {
    // Each call's broadcast holds its price until it idles out.
    let app = TestApp::builder().configure(scoped_tokens).release_capacity().start().await;

    // The matrix covers exactly the documented operations, and the document
    // declares the bearer scheme on exactly the guarded ones.
    let documented = documented_operations(&app).await;
    let routes = routes();
    let listed: BTreeSet<(String, String)> = routes.iter().map(|(m, p, ..)| (m.to_string(), p.to_string())).collect();
    let in_doc: BTreeSet<(String, String)> = documented.iter().map(|(m, p, _)| (m.clone(), p.clone())).collect();
    assert_eq!(in_doc, listed, "every documented operation needs a matrix entry, and only those");
    for (method, path, secured) in &documented {
        let need = routes.iter().find(|(m, p, ..)| m == method && p == path).unwrap().2;
        assert_eq!(*secured, need != Need::Open, "{method} {path}: bearer scheme in the document");
    }

    let mut cells = 0;
    let mut refused_writes = 0;
    for &(method, path, need, ok_status) in &routes {
        for role in Role::ALL {
            let before = snapshot(&app).await;
            let (status, problem) = call(&app, method, path, role).await;
            let after = snapshot(&app).await;
            let what = format!("{method} {path} as {role:?}");
            match expected(need, role) {
                Outcome::Allowed => assert_eq!(status, ok_status, "{what}: {problem:?}"),
                refused => {
                    let (status_wanted, code) = match refused {
                        Outcome::Unauthenticated => (401, "unauthorized"),
                        _ => (403, "insufficient_scope"),
                    };
                    assert_eq!(status, status_wanted, "{what}");
                    let (ct, body) = problem.unwrap();
                    assert_eq!(ct, "application/problem+json", "{what}");
                    assert_eq!(
                        (body["status"].as_u64(), body["code"].as_str()),
                        (Some(u64::from(status_wanted)), Some(code))
                    );
                    // Only the clip `call` created for this request is new; nothing else moved.
                    let created: Vec<_> = after.iter().filter(|c| !before.contains(c)).collect();
                    assert!(created.len() <= 1, "{what} changed the store: {created:?}");
                    assert!(before.iter().all(|c| after.contains(c)), "{what} changed or deleted a clip");
                    if need == Need::Scope(Scope::Write) {
                        refused_writes += 1;
                    }
                }
            }
            cells += 1;
        }
    }
    assert_eq!(cells, routes.len() * Role::ALL.len());
    // write routes × {none, invalid, read}
    let writes = routes.iter().filter(|(_, _, need, _)| *need == Need::Scope(Scope::Write)).count();
    assert_eq!(refused_writes, writes * 3);
    app.stop().await;
}

/// Without any token configured the server is open; with only the plain
/// `--api-token`, reads stay public and `/metrics` stays open.
#[tokio::test]
async fn guards_follow_the_configured_tokens() {
    let routes = routes();
    let open = TestApp::start().await;
    for (method, path, _, ok) in &routes {
        let (status, _) = call(&open, method, path, Role::None).await;
        assert_eq!(status, *ok, "open server: {method} {path}");
    }
    open.stop().await;

    let app = TestApp::builder().write_token(ADMIN).start().await;
    for (method, path, need, ok) in &routes {
        let (status, _) = call(&app, method, path, Role::None).await;
        let guarded = *need == Need::Scope(Scope::Write);
        assert_eq!(status, if guarded { 401 } else { *ok }, "write token only: {method} {path}");
    }
    app.stop().await;
}
