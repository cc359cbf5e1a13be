//! Layers of other rigs (docs/motion.md, "Layers of another skeleton"): never a
//! silent partial match. With real files: the two-joint `examples/wave.json`
//! over the Fox shares only `root`, so it plays and every answer warns
//! `joints_not_in_skeleton` naming `arm`; a CMU take over the Fox shares no
//! joint and is refused `incompatible_skeleton`; `no_root_joint` names the
//! joints a client could choose.

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::{TestApp, WAVE, within};
use crate::common::testdata;

async fn post(app: &TestApp, path: &str, body: &Value) -> (u16, Value) {
    let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
    (resp.status().as_u16(), resp.json().await.unwrap())
}

/// Imports `file` from the test data; the id of its clip named `name`, or
/// of its first clip.
pub(crate) async fn import(app: &TestApp, file: &str, name: Option<&str>) -> String {
    let url = app.url("/v1/clips/import?replace=true");
    let resp = app.http.post(url).body(testdata(file)).send().await.unwrap();
    assert_eq!(resp.status(), 201, "{file}");
    let answer: Value = resp.json().await.unwrap();
    let clips = answer["clips"].as_array().unwrap();
    let clip = clips.iter().find(|c| name.is_none_or(|n| c["name"] == n)).unwrap_or_else(|| panic!("{answer}"));
    clip["id"].as_str().unwrap().to_owned()
}

/// The one `joints_not_in_skeleton` warning naming `arm` at layer 1's clip.
fn assert_warns_of_the_arm(warnings: &Value, what: &str) {
    let list = warnings.as_array().unwrap_or_else(|| panic!("{what}: no warnings in {warnings}"));
    assert_eq!(list.len(), 1, "{what}: {warnings}");
    assert_eq!(list[0]["code"], "joints_not_in_skeleton", "{what}");
    assert_eq!(list[0]["pointer"], "/motion/layers/1/clip", "{what}");
    let detail = list[0]["detail"].as_str().unwrap();
    assert!(detail.contains("1 joint ") && detail.contains("'arm'") && detail.contains("`character`"), "{detail}");
}

#[tokio::test]
async fn the_wave_over_the_fox_plays_its_shared_joint_and_every_answer_warns_naming_the_arm() {
    let app = TestApp::start().await;
    let fox = import(&app, "gltf/Fox/Fox.glb", Some("Walk")).await;
    let wave = app.create_id(WAVE, None).await;
    let motion = json!({"layers": [{"clip": fox}, {"clip": wave}]});
    let (status, pose) = post(&app, "/v1/poses", &json!({"motion": motion, "time": 1.0})).await;
    assert_eq!(status, 200, "{pose}");
    assert_warns_of_the_arm(&pose["warnings"], "a pose");
    // The shared `root` plays the wave's: at t = 1 its key [1, 0, 0].
    let root = pose["joints"].as_array().unwrap().iter().find(|j| j["name"] == "root").expect("the Fox has a root");
    assert_eq!(root["translation"], json!([1.0, 0.0, 0.0]));
    let body = json!({"motion": motion, "times": [0, 0.5, 1]});
    let (status, samples) = post(&app, "/v1/samples", &body).await;
    assert_eq!(status, 200, "{samples}");
    assert_warns_of_the_arm(&samples["warnings"], "samples");
    assert_eq!(samples["poses"].as_array().unwrap().len(), 3);
    assert!(samples["poses"][2].get("warnings").is_none(), "once per answer, after the poses");
    // One layer, or layers of one rig, warn of nothing: the key is absent.
    let plain = json!({"motion": {"layers": [{"clip": fox}, {"clip": fox, "weight": 0.5}]}, "time": 1.0});
    let (status, pose) = post(&app, "/v1/poses", &plain).await;
    assert!(status == 200 && pose.get("warnings").is_none(), "{pose}");

    let mut ws = app.ws("/v1/stream").await;
    let open = json!({"op": "open", "motion": motion, "fps": 30});
    ws.send(Message::Text(open.to_string().into())).await.unwrap();
    let opened = loop {
        match within(5, "the opened message", ws.next()).await.unwrap().unwrap() {
            Message::Text(t) => break serde_json::from_str::<Value>(&t).unwrap(),
            _ => continue,
        }
    };
    assert_warns_of_the_arm(&opened["opened"]["warnings"], "the stream's opened");
    drop(ws);

    let resp = app.http.post(app.url("/v1/broadcasts")).json(&json!({"motion": motion, "fps": 10})).send().await;
    let resp = resp.unwrap();
    assert_eq!(resp.status(), 201);
    let created: Value = resp.json().await.unwrap();
    assert_warns_of_the_arm(&created["warnings"], "a broadcast's create answer");
    app.stop().await;
}

#[tokio::test]
async fn a_cmu_take_over_the_fox_shares_no_joint_and_is_refused_suggesting_a_character() {
    let app = TestApp::start().await;
    let fox = import(&app, "gltf/Fox/Fox.glb", Some("Walk")).await;
    let take = import(&app, "bvh/131_03.bvh", None).await;
    for (first, second) in [(&fox, &take), (&take, &fox)] {
        let motion = json!({"layers": [{"clip": first}, {"clip": second, "weight": 0.5}]});
        let (status, problem) = post(&app, "/v1/poses", &json!({"motion": motion, "time": 0.5})).await;
        assert_eq!((status, &problem["code"]), (422, &json!("incompatible_skeleton")), "{problem}");
        assert_eq!(problem["pointer"], "/motion/layers/1/clip");
        let detail = problem["detail"].as_str().unwrap();
        assert!(
            detail.contains("`character`") && detail.contains("'Hips'") && detail.contains("'_rootJoint'"),
            "{detail}"
        );
    }
    app.stop().await;
}

#[tokio::test]
async fn no_root_joint_names_the_joints_a_client_could_choose() {
    let app = TestApp::start().await;
    let fox = import(&app, "gltf/Fox/Fox.glb", Some("Walk")).await;
    let body = json!({"motion": {"layers": [{"clip": fox}], "root_motion": {}}, "time": 0.5});
    let (status, problem) = post(&app, "/v1/poses", &body).await;
    assert_eq!((status, &problem["code"]), (422, &json!("no_root_joint")), "{problem}");
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.contains("root joints: 'root'") || detail.contains("root joints: '_rootJoint'"), "{detail}");
    assert!(detail.contains("`root_motion.joint`: '"), "names a translated joint: {detail}");
    // The named joint then works.
    let named = detail.split("`root_motion.joint`: '").nth(1).unwrap().split('\'').next().unwrap();
    let body = json!({"motion": {"layers": [{"clip": fox}], "root_motion": {"joint": named}}, "time": 0.5});
    let (status, pose) = post(&app, "/v1/poses", &body).await;
    assert_eq!(status, 200, "{pose}");
    assert!(pose.get("root_motion").is_some());
    app.stop().await;
}

/// The character of `file` imported under `name`; its summary.
pub(crate) async fn import_character(app: &TestApp, file: &str, name: &str) -> Value {
    let url = app.url(&format!("/v1/characters/import?name={name}&replace=true"));
    let resp = app.http.post(url).body(testdata(file)).send().await.unwrap();
    assert!(resp.status().is_success(), "{file}: {}", resp.status());
    let body: Value = resp.json().await.unwrap();
    body["characters"][0].clone()
}

/// A CMU take played on CesiumMan: poses answer in CesiumMan's joints, and
/// every joint but the hips keeps CesiumMan's rest translation (its bone
/// lengths) exactly, whatever the take does; the same by `name:`.
#[tokio::test]
async fn a_cmu_take_plays_on_cesium_man_in_its_joints_with_its_bone_lengths() {
    let app = TestApp::start().await;
    let cesium = import_character(&app, "gltf/CesiumMan/CesiumMan.gltf", "cesium").await;
    let id = cesium["id"].as_str().unwrap().to_owned();
    let hips = cesium["roles"]["hips"]["joint"].as_str().expect("CesiumMan's hips are found").to_owned();
    let doc = app.get_json(&format!("/v1/characters/{id}")).await;
    let joints = doc["skeleton"]["joints"].as_array().unwrap().clone();
    let take = import(&app, "bvh/131_03.bvh", None).await;
    for character in [id.clone(), "name:cesium".to_owned()] {
        let motion = json!({"layers": [{"clip": take}], "character": character});
        let (status, pose) = post(&app, "/v1/poses", &json!({"motion": motion, "time": 1.5})).await;
        assert_eq!(status, 200, "{pose}");
        assert!(pose.get("warnings").is_none(), "{pose}");
        let got = pose["joints"].as_array().unwrap();
        assert_eq!(got.len(), joints.len());
        for (g, j) in got.iter().zip(&joints) {
            assert_eq!(g["name"], j["name"]);
            if j["name"] == hips.as_str() {
                continue;
            }
            let rest = j["rest"]["translation"].as_array().cloned().unwrap_or_else(|| vec![json!(0.0); 3]);
            for (a, b) in g["translation"].as_array().unwrap().iter().zip(&rest) {
                assert_eq!(a.as_f64().unwrap() as f32, b.as_f64().unwrap() as f32, "{}", j["name"]);
            }
        }
    }
    // The take moves: two times give two poses of the hips.
    let motion = json!({"layers": [{"clip": take}], "character": id});
    let (_, samples) = post(&app, "/v1/samples", &json!({"motion": motion, "times": [0.2, 2.0]})).await;
    let hips_at = |k: usize| {
        let joints = samples["poses"][k]["joints"].as_array().unwrap();
        joints.iter().find(|j| j["name"] == hips.as_str()).unwrap()["translation"].clone()
    };
    assert_ne!(hips_at(0), hips_at(1), "{samples}");
    app.stop().await;
}

#[tokio::test]
async fn a_two_joint_clip_is_unmappable_and_an_unknown_character_is_not_found() {
    let app = TestApp::start().await;
    let cesium = import_character(&app, "gltf/CesiumMan/CesiumMan.gltf", "cesium").await;
    let wave = app.create_id(WAVE, None).await;
    let motion = json!({"layers": [{"clip": wave}], "character": cesium["id"]});
    let (status, problem) = post(&app, "/v1/poses", &json!({"motion": motion, "time": 0.5})).await;
    assert_eq!((status, &problem["code"]), (422, &json!("unmappable_skeleton")), "{problem}");
    assert_eq!(problem["pointer"], "/motion/layers/0/clip");
    assert!(problem["detail"].as_str().unwrap().contains("hips"), "{problem}");
    let motion = json!({"layers": [{"clip": wave}], "character": "name:nobody"});
    let (status, problem) = post(&app, "/v1/poses", &json!({"motion": motion, "time": 0.5})).await;
    assert_eq!(
        (status, &problem["code"], &problem["pointer"]),
        (404, &json!("character_not_found"), &json!("/motion/character"))
    );
    app.stop().await;
}
