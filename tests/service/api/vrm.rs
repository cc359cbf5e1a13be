//! The shipped VRM 1.0 sample over REST (docs/characters.md, “Import”): a
//! clip import of `examples/vrm/tiny_humanoid.vrm` makes its looping clip
//! with its two spring chains and a character whose roles are the file's
//! humanoid bones (`given`), and a CMU take retargeted onto that character
//! keeps the character's bone lengths exactly while its hips move.

use serde_json::{Value, json};

use super::TestApp;
use super::rigs::import;
use crate::common::testdata;

async fn post(app: &TestApp, path: &str, body: &Value) -> (u16, Value) {
    let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
    (resp.status().as_u16(), resp.json().await.unwrap())
}

/// The bones `make_vrm.py` names in `humanBones`.
const BONES: [(&str, &str); 17] = [
    ("hips", "J00"),
    ("spine", "J01"),
    ("chest", "J02"),
    ("neck", "J03"),
    ("head", "J04"),
    ("leftUpperArm", "J05"),
    ("leftLowerArm", "J06"),
    ("leftHand", "J07"),
    ("rightUpperArm", "J08"),
    ("rightLowerArm", "J09"),
    ("rightHand", "J10"),
    ("leftUpperLeg", "J11"),
    ("leftLowerLeg", "J12"),
    ("leftFoot", "J13"),
    ("rightUpperLeg", "J14"),
    ("rightLowerLeg", "J15"),
    ("rightFoot", "J16"),
];

#[tokio::test]
async fn a_cmu_take_plays_on_the_vrm_humanoid_with_its_bone_lengths() {
    let app = TestApp::start().await;
    let resp =
        app.http.post(app.url("/v1/clips/import?replace=true")).body(testdata("vrm/tiny_humanoid.vrm")).send().await;
    let resp = resp.unwrap();
    assert_eq!(resp.status(), 201);
    let answer: Value = resp.json().await.unwrap();
    let clip = &answer["clips"][0];
    let doc = app.get_json(&format!("/v1/clips/{}", clip["id"].as_str().unwrap())).await;
    assert_eq!((clip["name"].as_str(), doc["playback"].as_str()), (Some("sway"), Some("loop")), "{answer}");
    let chains: Vec<&str> = doc["springs"].as_array().unwrap().iter().map(|s| s["name"].as_str().unwrap()).collect();
    assert_eq!(chains, ["tail", "hair"]);

    let character = &answer["characters"][0];
    let roles = character["roles"].as_object().unwrap();
    for (role, joint) in BONES {
        assert_eq!(roles[role], json!({"joint": joint, "by": "given"}), "{role}");
    }
    assert_eq!(roles.len(), BONES.len(), "no role is guessed beside the humanoid's: {roles:?}");
    assert!(character["warnings"].as_array().is_none_or(Vec::is_empty), "{character}");
    assert_eq!(character["mesh"], true, "its boxes are a skinned mesh the viewer draws");
    let id = character["id"].as_str().unwrap();
    let skeleton = app.get_json(&format!("/v1/characters/{id}")).await["skeleton"]["joints"].clone();
    let joints = skeleton.as_array().unwrap();

    // The take on it: every joint but the hips at the character's rest translation, to the f32.
    let take = import(&app, "bvh/131_01.bvh", None).await;
    let motion = json!({"layers": [{"clip": take}], "character": id});
    let (status, samples) = post(&app, "/v1/samples", &json!({"motion": motion, "times": [0.2, 1.0, 2.0, 3.5]})).await;
    assert_eq!(status, 200, "{samples}");
    let poses = samples["poses"].as_array().unwrap();
    for pose in poses {
        assert!(pose.get("warnings").is_none(), "{pose}");
        let got = pose["joints"].as_array().unwrap();
        assert_eq!(got.len(), joints.len());
        for (g, j) in got.iter().zip(joints) {
            assert_eq!(g["name"], j["name"]);
            if j["name"] == "J00" {
                continue;
            }
            let rest = j["rest"]["translation"].as_array().cloned().unwrap_or_else(|| vec![json!(0.0); 3]);
            for (a, b) in g["translation"].as_array().unwrap().iter().zip(&rest) {
                assert_eq!(a.as_f64().unwrap() as f32, b.as_f64().unwrap() as f32, "{}", j["name"]);
            }
        }
    }
    // The take moves the hips and turns the upper legs.
    let joint_at = |k: usize, name: &str, part: &str| {
        let joints = poses[k]["joints"].as_array().unwrap();
        joints.iter().find(|j| j["name"] == name).unwrap()[part].clone()
    };
    assert_ne!(joint_at(0, "J00", "translation"), joint_at(2, "J00", "translation"));
    assert_ne!(joint_at(0, "J11", "rotation"), joint_at(2, "J11", "rotation"));
    app.stop().await;
}
