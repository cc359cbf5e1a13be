//! Bad input, table-driven: each request gets its documented status and a
//! problem+json body with a stable code (and pointer where a body field is at
//! fault), and the store is unchanged afterwards.

use reqwest::{Method, RequestBuilder};
use serde_json::{Value, json};

use super::{TestApp, WAVE};

const TOKEN: &str = "write-secret";

/// A clip document: the wave example with `edit` applied.
fn wave_with(edit: impl FnOnce(&mut Value)) -> String {
    let mut doc: Value = serde_json::from_str(WAVE).unwrap();
    edit(&mut doc);
    doc.to_string()
}

/// A root-only clip with one track made of `track` fields.
fn one_track(track: Value) -> String {
    let mut t = json!({"joint": "j", "channel": "translation"});
    t.as_object_mut().unwrap().extend(track.as_object().unwrap().clone());
    json!({"name": "x", "tracks": [t]}).to_string()
}

struct Snapshot {
    list: Vec<Value>,
    seeded: (String, String),
}

async fn snapshot(app: &TestApp, seeded_url: &str) -> Snapshot {
    let resp = app.http.get(seeded_url).send().await.unwrap();
    let etag = resp.headers()["etag"].to_str().unwrap().to_owned();
    Snapshot { list: app.list_all(100, None).await, seeded: (etag, resp.text().await.unwrap()) }
}

/// Sends `req` and checks the status, the problem body and that nothing was stored or changed.
async fn check(
    app: &TestApp,
    seeded_url: &str,
    name: &str,
    req: RequestBuilder,
    status: u16,
    code: &str,
    pointer: Option<&str>,
) {
    let before = snapshot(app, seeded_url).await;
    let resp = req.send().await.unwrap();
    assert_eq!(resp.status().as_u16(), status, "{name}: status");
    let content_type = resp.headers().get("content-type").map(|v| v.to_str().unwrap().to_owned());
    assert_eq!(content_type.as_deref(), Some("application/problem+json"), "{name}: content type");
    if status == 401 {
        assert_eq!(resp.headers()["www-authenticate"], "Bearer", "{name}");
    }
    let body: Value = resp.json().await.unwrap();
    assert_eq!(body["code"], code, "{name}: code in {body}");
    assert_eq!(body["status"], status, "{name}: status in body");
    assert_eq!(body["type"], format!("urn:inbetween:problem:{code}"), "{name}");
    assert!(body["detail"].as_str().is_some_and(|d| !d.is_empty()), "{name}: detail");
    if let Some(p) = pointer {
        assert_eq!(body["pointer"], p, "{name}: pointer in {body}");
    }
    let after = snapshot(app, seeded_url).await;
    assert_eq!(after.list, before.list, "{name}: the clip list changed");
    assert_eq!(after.seeded, before.seeded, "{name}: the seeded clip changed");
}

#[tokio::test]
async fn every_bad_input_gets_its_status_and_code_and_changes_nothing() {
    let app = TestApp::builder()
        .configure(|c| {
            c.write_token = Some(server::config::Secret::new(TOKEN));
            c.limits.max_body_bytes = 64 * 1024;
            c.limits.max_tracks = 8;
            c.limits.max_keys_per_track = 100;
            c.limits.max_poses = 50;
        })
        .start()
        .await;
    let seeded = app.create(WAVE, Some(TOKEN)).await;
    let id = seeded["id"].as_str().unwrap().to_owned();
    let seeded_url = app.url(&format!("/v1/clips/{id}"));
    let missing = "0190a6b5-0000-7000-8000-000000000000";

    let c = &app.http;
    let upload = |body: String| {
        c.post(app.url("/v1/clips")).bearer_auth(TOKEN).header("content-type", "application/json").body(body)
    };
    let sample = |body: Value| {
        c.post(app.url(&format!("/v1/clips/{id}/sample")))
            .header("content-type", "application/json")
            .body(body.to_string())
    };
    let pose = |q: &str| c.get(app.url(&format!("/v1/clips/{id}/pose?{q}")));
    let put = |if_match: &str| {
        c.put(&seeded_url)
            .bearer_auth(TOKEN)
            .header("content-type", "application/json")
            .header("if-match", if_match)
            .body(WAVE)
    };
    let too_big = format!("{{\"name\": \"{}\", \"tracks\": []}}", "x".repeat(70 * 1024));
    let many_tracks = json!({"name": "x", "tracks": (0..9).map(|j| json!({
        "joint": format!("j{j}"), "channel": "translation", "times": [0], "values": [[0, 0, 0]]})).collect::<Vec<_>>()});
    let many_keys = one_track(json!({"times": (0..101).collect::<Vec<_>>(), "values": vec![[0, 0, 0]; 101]}));

    #[rustfmt::skip]
    let cases: Vec<(&str, RequestBuilder, u16, &str, Option<&str>)> = vec![
        ("truncated JSON", upload("{\"name\":".into()), 400, "malformed_json", None),
        ("not JSON", upload("hello".into()), 400, "malformed_json", None),
        ("trailing garbage", upload(format!("{WAVE} x")), 400, "malformed_json", None),
        ("name is a number", upload(wave_with(|d| d["name"] = json!(5))), 422, "invalid_field", Some("/name")),
        ("tracks is an object", upload(wave_with(|d| d["tracks"] = json!({}))), 422, "invalid_field", Some("/tracks")),
        ("misspelt field", upload(wave_with(|d| d["nmae"] = json!("x"))), 422, "invalid_field", None),
        ("unknown channel", upload(one_track(json!({"channel": "position", "times": [0], "values": [[0,0,0]]}))), 422, "invalid_field", Some("/tracks/0/channel")),
        ("time is a string", upload(one_track(json!({"times": ["0"], "values": [[0,0,0]]}))), 422, "invalid_field", Some("/tracks/0/times/0")),
        ("huge number overflows f32", upload(one_track(json!({"times": [0, 1], "values": [[0,0,0],[1e39,0,0]]}))), 422, "non_finite", Some("/tracks/0/values/1")),
        ("number beyond f64", upload(r#"{"name":"x","tracks":[{"joint":"j","channel":"translation","times":[0],"values":[[1e400,0,0]]}]}"#.into()), 400, "malformed_json", None),
        ("times not increasing", upload(one_track(json!({"times": [0, 2, 1], "values": [[0,0,0],[1,0,0],[2,0,0]]}))), 422, "times_not_increasing", Some("/tracks/0/times/2")),
        ("duplicated time", upload(one_track(json!({"times": [0, 1, 1], "values": [[0,0,0],[1,0,0],[2,0,0]]}))), 422, "times_not_increasing", Some("/tracks/0/times/2")),
        ("values shorter than times", upload(one_track(json!({"times": [0, 1, 2], "values": [[0,0,0],[1,0,0]]}))), 422, "length_mismatch", Some("/tracks/0/values")),
        ("translation of width 2", upload(one_track(json!({"times": [0], "values": [[0,0]]}))), 422, "wrong_width", Some("/tracks/0/values/0")),
        ("rotation of width 3", upload(one_track(json!({"channel": "rotation", "times": [0], "values": [[0,0,1]]}))), 422, "wrong_width", Some("/tracks/0/values/0")),
        ("zero quaternion", upload(one_track(json!({"channel": "rotation", "times": [0, 1], "values": [[0,0,0,1],[0,0,0,0]]}))), 422, "zero_quaternion", Some("/tracks/0/values/1")),
        ("unknown parent", upload(wave_with(|d| d["skeleton"]["joints"][1]["parent"] = json!("hip"))), 422, "unknown_parent", Some("/skeleton/joints/1/parent")),
        ("parent cycle", upload(wave_with(|d| d["skeleton"]["joints"][0]["parent"] = json!("arm"))), 422, "parent_cycle", Some("/skeleton/joints/0/parent")),
        ("duplicate joint", upload(wave_with(|d| d["skeleton"]["joints"][1]["name"] = json!("root"))), 422, "duplicate_joint", Some("/skeleton/joints/1/name")),
        ("track on an unknown joint", upload(wave_with(|d| d["tracks"][1]["joint"] = json!("leg"))), 422, "unknown_joint", Some("/tracks/1/joint")),
        ("wrap with unequal ends", upload(one_track(json!({"interpolation": "catmull_rom", "ends": "wrap", "times": [0,1,2], "values": [[0,0,0],[1,0,0],[2,0,0]]}))), 422, "wrap_ends_differ", None),
        ("phantom with 3 keys", upload(one_track(json!({"interpolation": "catmull_rom", "ends": "phantom", "times": [0,1,2], "values": [[0,0,0],[1,0,0],[2,0,0]]}))), 422, "phantom_too_few_keys", None),
        ("tension out of range", upload(one_track(json!({"interpolation": "catmull_rom", "tension": 1.5, "times": [0,1], "values": [[0,0,0],[1,0,0]]}))), 422, "tension_out_of_range", None),
        ("hermite without tangents", upload(one_track(json!({"interpolation": "cubic_hermite", "times": [0,1], "values": [[0,0,0],[1,0,0]]}))), 422, "missing_tangents", None),
        ("inverse bind of 15 numbers", upload(wave_with(|d| d["skeleton"]["joints"][0]["inverse_bind"] = json!(vec![0; 15]))), 422, "invalid_field", Some("/skeleton/joints/0/inverse_bind")),
        ("no tracks", upload(json!({"name": "x", "tracks": []}).to_string()), 422, "no_tracks", Some("/tracks")),
        ("empty name", upload(wave_with(|d| d["name"] = json!(""))), 422, "bad_name", Some("/name")),
        ("too many tracks", upload(many_tracks.to_string()), 422, "too_many_tracks", Some("/tracks")),
        ("too many keys", upload(many_keys), 422, "too_many_keys", Some("/tracks/0/times")),
        ("body over the limit", upload(too_big), 413, "body_too_large", None),
        ("text/plain upload", c.post(app.url("/v1/clips")).bearer_auth(TOKEN).header("content-type", "text/plain").body(WAVE), 415, "unsupported_media_type", None),
        ("upload without content type", c.post(app.url("/v1/clips")).bearer_auth(TOKEN).body(WAVE), 415, "unsupported_media_type", None),
        ("upload without token", c.post(app.url("/v1/clips")).header("content-type", "application/json").body(WAVE), 401, "unauthorized", None),
        ("upload with wrong token", c.post(app.url("/v1/clips")).bearer_auth("nope").header("content-type", "application/json").body(WAVE), 401, "unauthorized", None),
        ("token with the wrong scheme", c.post(app.url("/v1/clips")).header("authorization", format!("Basic {TOKEN}")).header("content-type", "application/json").body(WAVE), 401, "unauthorized", None),
        ("delete without token", c.delete(&seeded_url), 401, "unauthorized", None),
        ("replace with wrong token", c.put(&seeded_url).bearer_auth("nope").header("content-type", "application/json").body(WAVE), 401, "unauthorized", None),
        ("get an unknown clip", c.get(app.url(&format!("/v1/clips/{missing}"))), 404, "clip_not_found", None),
        ("pose of an unknown clip", c.get(app.url(&format!("/v1/clips/{missing}/pose?t=0"))), 404, "clip_not_found", None),
        ("replace an unknown clip", c.put(app.url(&format!("/v1/clips/{missing}"))).bearer_auth(TOKEN).header("content-type", "application/json").body(WAVE), 404, "clip_not_found", None),
        ("delete an unknown clip", c.delete(app.url(&format!("/v1/clips/{missing}"))).bearer_auth(TOKEN), 404, "clip_not_found", None),
        ("If-Match not a tag", put("abc"), 400, "bad_precondition", None),
        ("If-Match unterminated", put("\"1"), 400, "bad_precondition", None),
        ("If-Match stale", put("\"99\""), 412, "version_mismatch", None),
        ("If-Match weak", put("W/\"1\""), 412, "version_mismatch", None),
        ("delete with a stale If-Match", c.delete(&seeded_url).bearer_auth(TOKEN).header("if-match", "\"2\""), 412, "version_mismatch", None),
        ("valid upload to an invalid replace", c.put(&seeded_url).bearer_auth(TOKEN).header("content-type", "application/json").body(one_track(json!({"times": [1, 0], "values": [[0,0,0],[1,0,0]]}))), 422, "times_not_increasing", Some("/tracks/0/times/1")),
        ("t is not a number", pose("t=abc"), 400, "bad_number", None),
        ("t is NaN", pose("t=NaN"), 400, "bad_number", None),
        ("t is inf", pose("t=inf"), 400, "bad_number", None),
        ("t overflows", pose("t=1e400"), 400, "bad_number", None),
        ("t missing", pose("space=local"), 400, "missing_parameter", None),
        ("t given twice", pose("t=1&t=2"), 400, "repeated_parameter", None),
        ("t empty", pose("t="), 400, "bad_number", None),
        ("query not UTF-8", pose("t=%FF"), 400, "bad_query", None),
        ("unknown space", pose("t=0&space=world"), 400, "bad_parameter", None),
        ("unknown playback", pose("t=0&playback=reverse"), 400, "bad_parameter", None),
        ("unknown format", pose("t=0&format=euler"), 400, "bad_parameter", None),
        ("misspelt parameter", pose("time=1"), 400, "unknown_parameter", None),
        ("skinning without inverse binds", pose("t=0&format=skinning"), 422, "no_inverse_binds", None),
        ("sample fps 0", sample(json!({"start": 0, "end": 1, "fps": 0})), 422, "fps_out_of_range", Some("/fps")),
        ("sample fps 10000", sample(json!({"start": 0, "end": 1, "fps": 10000})), 422, "fps_out_of_range", Some("/fps")),
        ("sample end before start", sample(json!({"start": 2, "end": 1, "fps": 30})), 422, "bad_range", Some("/end")),
        ("sample times and range", sample(json!({"times": [0], "start": 0, "end": 1, "fps": 30})), 422, "times_or_range", None),
        ("sample range without fps", sample(json!({"start": 0, "end": 1})), 422, "times_or_range", None),
        ("sample too many times", sample(json!({"times": vec![0.5; 51]})), 422, "too_many_poses", Some("/times")),
        ("sample too many frames", sample(json!({"start": 0, "end": 10, "fps": 30})), 422, "too_many_poses", None),
        ("sample time is a string", sample(json!({"times": [0, "1"]})), 422, "invalid_field", Some("/times/1")),
        ("sample unknown field", sample(json!({"times": [0], "speed": 2})), 422, "invalid_field", None),
        ("sample bad space", sample(json!({"times": [0], "space": "world"})), 400, "bad_parameter", Some("/space")),
        ("list limit 0", c.get(app.url("/v1/clips?limit=0")), 400, "bad_limit", None),
        ("list limit huge", c.get(app.url("/v1/clips?limit=99999999999")), 400, "bad_limit", None),
        ("list cursor garbage", c.get(app.url("/v1/clips?cursor=zzz")), 400, "bad_cursor", None),
        ("id not UTF-8", c.get(app.url("/v1/clips/%FF")), 400, "bad_path", None),
        ("pose of an id with a slash", c.get(app.url("/v1/clips/a%2Fb/pose?t=0")), 404, "clip_not_found", None),
        ("PUT JSON array body", c.put(&seeded_url).bearer_auth(TOKEN).header("content-type", "application/json").body("[]"), 422, "invalid_field", None),
        ("upload as form data", c.post(app.url("/v1/clips")).bearer_auth(TOKEN).header("content-type", "application/x-www-form-urlencoded").body("name=x"), 415, "unsupported_media_type", None),
        ("unknown route", c.get(app.url("/v2/clips")), 404, "route_not_found", None),
        ("wrong method", c.request(Method::PATCH, app.url("/v1/clips")), 405, "method_not_allowed", None),
    ];
    assert!(cases.len() >= 30);
    for (name, req, status, code, pointer) in cases {
        check(&app, &seeded_url, name, req, status, code, pointer).await;
    }
    app.stop().await;
}
