//! The retarget options of a motion played on a character (docs/motion.md,
//! “Playing a take on a character”), on the CMU take 131_01 and CesiumMan
//! through the real server: `target_pose`, the character's reference pose.

use glam::DQuat;
use serde_json::{Value, json};

use super::TestApp;
use super::character_routes::take_and_cesium;

async fn samples(app: &TestApp, motion: &Value, times: &[f64]) -> (u16, Vec<u8>) {
    let body = json!({"motion": motion, "times": times, "space": "model"});
    let resp = app.http.post(app.url("/v1/samples")).json(&body).send().await.unwrap();
    (resp.status().as_u16(), resp.bytes().await.unwrap().to_vec())
}

fn quat(v: &Value) -> DQuat {
    let f = |i: usize| v[i].as_f64().unwrap();
    DQuat::from_xyzw(f(0), f(1), f(2), f(3))
}

/// The angle between two rotations, in degrees, well conditioned near 0
/// (`acos` of a dot product of f32-rounded quaternions is not).
fn degrees_between(a: DQuat, b: DQuat) -> f64 {
    let d = a.normalize().inverse() * b.normalize();
    (2.0 * glam::DVec3::new(d.x, d.y, d.z).length().atan2(d.w.abs())).to_degrees()
}

/// Each of the character's joints with its rest rotation, from its stored document.
async fn rest_rotations(app: &TestApp, character: &str) -> Vec<(String, Value)> {
    let doc = app.get_json(&format!("/v1/characters/{character}")).await;
    let joints = doc["skeleton"]["joints"].as_array().unwrap();
    let rotation = |j: &Value| j["rest"].get("rotation").cloned().unwrap_or(json!([0.0, 0.0, 0.0, 1.0]));
    joints.iter().map(|j| (j["name"].as_str().unwrap().to_owned(), rotation(j))).collect()
}

#[tokio::test]
async fn a_target_pose_of_the_rest_s_own_rotations_changes_nothing_and_another_turns_the_joint_by_the_rule() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let times = [0.0, 1.25, 4.5];
    let plain = json!({"layers": [{"clip": take}], "character": cesium});
    let (status, want) = samples(&app, &plain, &times).await;
    assert_eq!(status, 200);

    let rest = rest_rotations(&app, &cesium).await;
    let all: serde_json::Map<String, Value> = rest.iter().cloned().collect();
    let same =
        json!({"layers": [{"clip": take}], "character": cesium, "retarget": {"target_pose": {"rotations": all}}});
    let (status, got) = samples(&app, &same, &times).await;
    assert_eq!(status, 200);
    assert!(
        got == want,
        "the rest's own rotations are the rest: {}",
        String::from_utf8_lossy(&got[..got.len().min(600)])
    );

    // The hips given another reference rotation R: G_d' = G_s·(G⁰_s)⁻¹·P·R = G_d·L⁻¹·R (L its rest local rotation, P its parents').
    let roles = app.get_json("/v1/characters?name=cesium").await;
    let hips = roles["characters"][0]["roles"]["hips"]["joint"].as_str().unwrap().to_owned();
    let (hips_index, (_, l)) = rest.iter().enumerate().find(|(_, (n, _))| *n == hips).unwrap();
    let l = quat(l);
    let r = DQuat::from_axis_angle(glam::DVec3::new(0.6, 0.0, 0.8), 0.4) * l;
    let turned = json!({"layers": [{"clip": take, "retarget": {"target_pose": {"rotations": {hips.clone(): [r.x, r.y, r.z, r.w]}}}}], "character": cesium});
    let (status, got) = samples(&app, &turned, &times).await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&got));
    let (want, got): (Value, Value) = (serde_json::from_slice(&want).unwrap(), serde_json::from_slice(&got).unwrap());
    for k in 0..times.len() {
        let g_d = quat(&want["poses"][k]["joints"][hips_index]["rotation"]);
        let expected = g_d * l.inverse() * r;
        let answered = quat(&got["poses"][k]["joints"][hips_index]["rotation"]);
        let angle = degrees_between(expected, answered);
        assert!(angle < 1e-3, "t = {}: the hips {angle}° from G_d·L⁻¹·R", times[k]);
        assert!(degrees_between(g_d, answered) > 5.0, "the new reference turns the hips");
    }
}

#[tokio::test]
async fn a_bad_target_pose_is_refused_with_a_pointer() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let rest = rest_rotations(&app, &cesium).await;
    let joint = rest[3].0.clone();
    let cases = [
        (json!({"time": 0}), "target_pose_needs_rotations", "/motion/retarget/target_pose".to_owned()),
        (
            json!({"rotations": {"nope": [0, 0, 0, 1]}}),
            "unknown_joint",
            "/motion/retarget/target_pose/rotations/nope".to_owned(),
        ),
        (
            json!({"rotations": {joint.clone(): [0, 0, 0, 0]}}),
            "zero_quaternion",
            format!("/motion/retarget/target_pose/rotations/{joint}"),
        ),
    ];
    for (pose, code, pointer) in cases {
        let motion = json!({"layers": [{"clip": take}], "character": cesium, "retarget": {"target_pose": pose}});
        let (status, body) = samples(&app, &motion, &[0.0]).await;
        let body: Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(
            (status, body["code"].as_str(), body["pointer"].as_str()),
            (422, Some(code), Some(pointer.as_str())),
            "{body}"
        );
    }
    // A layer's own options point into the layer.
    let motion = json!({"layers": [{"clip": take, "retarget": {"target_pose": {"time": 1}}}], "character": cesium});
    let (status, body) = samples(&app, &motion, &[0.0]).await;
    let body: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!((status, body["pointer"].as_str()), (422, Some("/motion/layers/0/retarget/target_pose")), "{body}");
}
