//! `character=` on the clip routes (docs/characters.md, “Clip routes on a
//! character”): `GET …/pose`, `POST …/sample` and `GET …/stream` of the CMU
//! take 131_01 on CesiumMan answer exactly what the one-layer motion
//! `{"layers":[{"clip":take}],"character":…}` answers on `POST /v1/poses`,
//! `POST /v1/samples` and `GET /v1/stream`, and refuse at the route's fields.

use futures_util::StreamExt;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::TestApp;
use crate::common::testdata;

/// `file` imported at `route` (a clip or character import) under `name`; the first summary's id.
pub(crate) async fn import(app: &TestApp, route: &str, file: &str, name: &str) -> String {
    let url = app.url(&format!("{route}?name={name}&replace=true"));
    let resp = app.http.post(url).body(testdata(file)).send().await.unwrap();
    assert_eq!(resp.status(), 201, "{file}");
    let body: Value = resp.json().await.unwrap();
    let list = if route.contains("characters") { "characters" } else { "clips" };
    body[list][0]["id"].as_str().unwrap().to_owned()
}

/// The take 131_01 (a clip) and CesiumMan (a character), imported.
pub(crate) async fn take_and_cesium(app: &TestApp) -> (String, String) {
    let cesium = import(app, "/v1/characters/import", "gltf/CesiumMan/CesiumMan.gltf", "cesium").await;
    let take = import(app, "/v1/clips/import", "bvh/131_01.bvh", "131_01").await;
    (take, cesium)
}

async fn bytes(resp: reqwest::Response) -> (u16, Vec<u8>) {
    (resp.status().as_u16(), resp.bytes().await.unwrap().to_vec())
}

async fn problem(resp: reqwest::Response) -> (u16, Value) {
    (resp.status().as_u16(), resp.json().await.unwrap())
}

#[tokio::test]
async fn a_clip_pose_on_a_character_is_the_one_layer_motion_s_byte_for_byte() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let doc = app.get_json(&format!("/v1/characters/{cesium}")).await;
    let name = |j: usize| doc["skeleton"]["joints"][j]["name"].as_str().unwrap().to_owned();
    let (a, b) = (name(2), name(5));
    let cases = [
        (format!("t=1.5&space=model&character={cesium}"), json!({"time": 1.5, "space": "model"}), None),
        ("t=2.25&character=name:cesium&format=matrix".to_owned(), json!({"time": 2.25, "format": "matrix"}), None),
        (
            format!("t=9.5&character={cesium}&playback=loop&joints={a},{b}"),
            json!({"time": 9.5, "joints": [a, b]}),
            Some("loop"),
        ),
    ];
    for (query, mut body, playback) in cases {
        let got = bytes(app.http.get(app.url(&format!("/v1/clips/{take}/pose?{query}"))).send().await.unwrap()).await;
        let mut layer = json!({"clip": take});
        if let Some(p) = playback {
            layer["playback"] = json!(p);
        }
        let character = if query.contains("name:") { "name:cesium".to_owned() } else { cesium.clone() };
        body["motion"] = json!({"layers": [layer], "character": character});
        let want = bytes(app.http.post(app.url("/v1/poses")).json(&body).send().await.unwrap()).await;
        assert_eq!(got.0, 200, "{query}: {}", String::from_utf8_lossy(&got.1));
        assert_eq!(got, want, "{query}");
    }
    // CesiumMan's joints, not the take's.
    let pose = app.get_json(&format!("/v1/clips/{take}/pose?t=1&character={cesium}")).await;
    assert_eq!(pose["joints"].as_array().unwrap().len(), doc["skeleton"]["joints"].as_array().unwrap().len());
}

#[tokio::test]
async fn a_clip_sample_on_a_character_is_the_one_layer_motion_s_byte_for_byte() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let motion = json!({"layers": [{"clip": take, "playback": "once"}], "character": cesium});
    for request in [
        json!({"times": [0.0, 0.5, 3.25], "space": "model"}),
        json!({"start": 0.0, "end": 2.0, "fps": 30, "format": "skinning", "playback": "once"}),
    ] {
        let mut on_clip = request.clone();
        on_clip["character"] = json!(cesium);
        let got = app.http.post(app.url(&format!("/v1/clips/{take}/sample"))).json(&on_clip).send().await.unwrap();
        let got = bytes(got).await;
        let mut composed = request.clone();
        composed.as_object_mut().unwrap().remove("playback");
        composed["motion"] = if request.get("playback").is_some() {
            motion.clone()
        } else {
            json!({"layers": [{"clip": take}], "character": cesium})
        };
        let want = bytes(app.http.post(app.url("/v1/samples")).json(&composed).send().await.unwrap()).await;
        assert_eq!(got.0, 200, "{}", String::from_utf8_lossy(&got.1));
        assert_eq!(got, want, "{request}");
    }
}

#[tokio::test]
async fn clip_routes_on_a_character_refuse_at_their_own_fields() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let wave = app.create_id(crate::common::WAVE, None).await;

    // An unknown character: 404 at the query's `character`, or the body's `/character`.
    let url = app.url(&format!("/v1/clips/{take}/pose?t=0&character=name:nobody"));
    let (status, body) = problem(app.http.get(url).send().await.unwrap()).await;
    assert_eq!(
        (status, body["code"].as_str(), body["parameter"].as_str()),
        (404, Some("character_not_found"), Some("character")),
        "{body}"
    );
    let url = app.url(&format!("/v1/clips/{take}/sample"));
    let resp = app.http.post(url).json(&json!({"times": [0], "character": "name:nobody"})).send().await.unwrap();
    let (status, body) = problem(resp).await;
    assert_eq!(
        (status, body["code"].as_str(), body["pointer"].as_str()),
        (404, Some("character_not_found"), Some("/character")),
        "{body}"
    );

    // A clip whose roles CesiumMan cannot map (the two-joint wave): 422 at `character`.
    let url = app.url(&format!("/v1/clips/{wave}/pose?t=0&character={cesium}"));
    let (status, body) = problem(app.http.get(url).send().await.unwrap()).await;
    assert_eq!(
        (status, body["code"].as_str(), body["parameter"].as_str()),
        (422, Some("unmappable_skeleton"), Some("character")),
        "{body}"
    );
    let url = app.url(&format!("/v1/clips/{wave}/sample"));
    let resp = app.http.post(url).json(&json!({"times": [0], "character": cesium})).send().await.unwrap();
    let (status, body) = problem(resp).await;
    assert_eq!(
        (status, body["code"].as_str(), body["pointer"].as_str()),
        (422, Some("unmappable_skeleton"), Some("/character")),
        "{body}"
    );

    // A joint of the take's, not CesiumMan's: the subset's own refusal.
    let url = app.url(&format!("/v1/clips/{take}/pose?t=0&character={cesium}&joints=Hips"));
    let (status, body) = problem(app.http.get(url).send().await.unwrap()).await;
    assert_eq!(
        (status, body["code"].as_str(), body["parameter"].as_str()),
        (422, Some("unknown_joint"), Some("joints")),
        "{body}"
    );

    // The one-layer motion has no ease.
    let url = app.url(&format!("/v1/clips/{take}/pose?t=0&character={cesium}&ease=ease_in"));
    let (status, body) = problem(app.http.get(url).send().await.unwrap()).await;
    assert_eq!(
        (status, body["code"].as_str(), body["parameter"].as_str()),
        (400, Some("unknown_parameter"), Some("ease")),
        "{body}"
    );

    // A stream's refusal comes before the upgrade, as a problem.
    let url = app.url(&format!("/v1/clips/{take}/stream?character=name:nobody"));
    let req = app
        .http
        .get(url)
        .header("connection", "upgrade")
        .header("upgrade", "websocket")
        .header("sec-websocket-version", "13")
        .header("sec-websocket-key", "dGhlIHNhbXBsZSBub25jZQ==");
    let (status, body) = problem(req.send().await.unwrap()).await;
    assert_eq!(
        (status, body["code"].as_str(), body["parameter"].as_str()),
        (404, Some("character_not_found"), Some("character")),
        "{body}"
    );
}

async fn next_json(ws: &mut crate::common::app::Ws) -> Value {
    loop {
        let msg = crate::common::within(10, "a stream message", ws.next()).await.unwrap().unwrap();
        if let Message::Text(text) = msg {
            return serde_json::from_str(&text).unwrap();
        }
    }
}

#[tokio::test]
async fn a_clip_stream_on_a_character_says_what_it_plays_and_sends_the_motion_s_poses() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let mut ws = app
        .ws(&format!("/v1/clips/{take}/stream?character={cesium}&fps=30&max_frames=6&space=model&playback=loop"))
        .await;
    let opened = next_json(&mut ws).await;
    let doc = app.get_json(&format!("/v1/characters/{cesium}")).await;
    let names: Vec<Value> = doc["skeleton"]["joints"].as_array().unwrap().iter().map(|j| j["name"].clone()).collect();
    assert_eq!(opened["opened"]["joints"], Value::Array(names), "{opened}");
    assert_eq!(opened["opened"]["clip"], take.as_str());
    let motion = json!({"layers": [{"clip": take, "playback": "loop"}], "character": cesium});
    for _ in 0..6 {
        let frame = next_json(&mut ws).await;
        let t = frame["pose"]["time"].as_f64().unwrap();
        let pose = app.post_json("/v1/poses", &json!({"motion": motion, "time": t, "space": "model"})).await;
        assert_eq!(frame["pose"], pose, "a frame is the pose POST /v1/poses answers at its time");
    }
}
