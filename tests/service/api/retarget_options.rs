//! The retarget options of a motion played on a character (docs/motion.md,
//! “Playing a take on a character”), on the CMU take 131_01 and CesiumMan
//! through the real server: `target_pose`, the character's reference pose.

use formats::wire::proto::pb;
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

fn position(pose: &Value, joint: usize) -> glam::DVec3 {
    let t = &pose["joints"][joint]["translation"];
    glam::DVec3::new(t[0].as_f64().unwrap(), t[1].as_f64().unwrap(), t[2].as_f64().unwrap())
}

/// The take on CesiumMan at 60 fps with `feet: "plant"`: while the server
/// says a foot is planted, the planted foot stays where its contact began
/// (mean drift under 1 mm, the take's own feet drift 5 mm × k there), the
/// unplanted one slides (25 mm in the core's figures, crates/formats/tests/formats/feet.rs).
#[tokio::test]
async fn planted_feet_stay_where_their_contact_began_and_unplanted_ones_slide() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let summary = &app.get_json("/v1/characters?name=cesium").await["characters"][0];
    let rest = rest_rotations(&app, &cesium).await;
    let index = |role: &str| {
        let name = summary["roles"][role]["joint"].as_str().unwrap();
        rest.iter().position(|(n, _)| n == name).unwrap()
    };
    let feet = [("left", index("leftFoot")), ("right", index("rightFoot"))];
    let run = |retarget: Value| {
        let motion = json!({"layers": [{"clip": take}], "character": cesium, "retarget": retarget});
        let body = json!({"motion": motion, "start": 0, "end": 8, "fps": 60, "space": "model"});
        let app = &app;
        async move {
            let resp = app.http.post(app.url("/v1/samples")).json(&body).send().await.unwrap();
            assert_eq!(resp.status(), 200);
            let answer: Value = resp.json().await.unwrap();
            answer["poses"].as_array().unwrap().clone()
        }
    };
    let planted = run(json!({"feet": "plant"})).await;
    let free = run(json!({})).await;
    assert!(free[0].get("feet").is_none(), "no report without planting");
    let (mut frames, mut drift_planted, mut drift_free, mut max_slide) = (0u32, 0.0, 0.0, 0.0f64);
    for (side, joint) in feet {
        let mut start: Option<(glam::DVec3, glam::DVec3)> = None;
        for (p, f) in planted.iter().zip(&free) {
            let report = &p["feet"][side];
            max_slide = max_slide.max(report["slide"].as_f64().unwrap());
            if report["planted"] != json!(true) {
                start = None;
                continue;
            }
            let (now_p, now_f) = (position(p, joint), position(f, joint));
            match start {
                None => start = Some((now_p, now_f)),
                Some((p0, f0)) => {
                    frames += 1;
                    drift_planted += now_p.distance(p0);
                    drift_free += now_f.distance(f0);
                }
            }
        }
    }
    let (planted_mm, free_mm) = (drift_planted / f64::from(frames) * 1e3, drift_free / f64::from(frames) * 1e3);
    println!(
        "FIGURE served feet 131_01 on CesiumMan: {frames} contact frames, planted {planted_mm:.3} mm, unplanted {free_mm:.2} mm, max slide {max_slide:e}"
    );
    assert!(frames > 60, "the take has contacts ({frames} frames)");
    assert!(planted_mm < 1.0, "planted feet drift {planted_mm} mm");
    assert!(free_mm > 10.0 * planted_mm.max(0.1), "unplanted feet slide {free_mm} mm");

    // A single pose plants by height alone, the anchor where the foot is.
    let motion =
        json!({"layers": [{"clip": take}], "character": cesium, "retarget": {"feet": "plant", "contact_height": 0.05}});
    let pose = app.post_json("/v1/poses", &json!({"motion": motion, "time": 0.0, "space": "model"})).await;
    for side in ["left", "right"] {
        let slide = pose["feet"][side]["slide"].as_f64().unwrap();
        assert!(slide < 1e-6, "a first frame's anchor is where the foot is: {}", pose["feet"]);
    }
}

#[tokio::test]
async fn planted_feet_show_in_json_frames_and_bad_thresholds_are_refused() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let motion = json!({"layers": [{"clip": take}], "character": cesium, "retarget": {"feet": "plant"}});
    let mut ws = app.ws("/v1/stream").await;
    use futures_util::{SinkExt, StreamExt};
    let open = json!({"op": "open", "motion": motion, "fps": 30, "max_frames": 3});
    ws.send(tokio_tungstenite::tungstenite::Message::Text(open.to_string().into())).await.unwrap();
    let mut seen = 0;
    while seen < 3 {
        let msg = crate::common::within(10, "a frame", ws.next()).await.unwrap().unwrap();
        let tokio_tungstenite::tungstenite::Message::Text(text) = msg else { continue };
        let v: Value = serde_json::from_str(&text).unwrap();
        if let Some(pose) = v.get("pose") {
            seen += 1;
            for side in ["left", "right"] {
                assert!(pose["feet"][side]["planted"].is_boolean(), "{}", pose["feet"]);
            }
        }
    }
    for (retarget, code, pointer) in [
        (json!({"feet": "plant", "contact_height": -1}), "contact_out_of_range", "/motion/retarget/contact_height"),
        (json!({"contact_speed": 0.2}), "feet_not_planted", "/motion/retarget/contact_speed"),
    ] {
        let motion = json!({"layers": [{"clip": take}], "character": cesium, "retarget": retarget});
        let (status, body) = samples(&app, &motion, &[0.0]).await;
        let body: Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(
            (status, body["code"].as_str(), body["pointer"].as_str()),
            (422, Some(code), Some(pointer)),
            "{body}"
        );
    }
}

/// gRPC's `Retarget` carries `target_pose` and `feet`: a batch over
/// `SampleMotionBatch` is REST's `POST /v1/samples` answer, number for number
/// (the planter runs through the batch in order on both), and a target pose
/// given as a time is refused with REST's code.
#[tokio::test]
async fn grpc_retargets_with_a_target_pose_and_planted_feet_as_rest_does() {
    let app = TestApp::start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let rest_pose = rest_rotations(&app, &cesium).await;
    let (joint, _) = rest_pose[2].clone();
    let q = DQuat::from_axis_angle(glam::DVec3::Y, 0.3);
    let motion = json!({"layers": [{"clip": take}], "character": cesium, "retarget": {
        "target_pose": {"rotations": {joint.clone(): [q.x, q.y, q.z, q.w]}},
        "feet": "plant", "contact_height": 0.03, "contact_speed": 0.2}});
    let times: Vec<f64> = (0..90).map(|k| f64::from(k) / 30.0).collect();
    let body = json!({"motion": motion, "times": times, "space": "model"});
    let rest: Value = app.http.post(app.url("/v1/samples")).json(&body).send().await.unwrap().json().await.unwrap();
    let planted = rest["poses"].as_array().unwrap().iter().filter(|p| p["feet"]["left"]["planted"] == json!(true));
    assert!(planted.count() > 5, "the left foot lands in the first 3 s");

    let pq = pb::Quaternion { x: q.x as f32, y: q.y as f32, z: q.z as f32, w: q.w as f32 };
    let rotations = pb::JointRotations { joints: [(joint, pq)].into() };
    let retarget = pb::Retarget {
        target_pose: Some(pb::SourcePose { pose: Some(pb::source_pose::Pose::Rotations(rotations)) }),
        feet: Some(pb::PlantFeet { contact_height: Some(0.03), contact_speed: Some(0.2) }),
        ..Default::default()
    };
    let rpc_motion = pb::Motion {
        layers: vec![pb::Layer { clip_id: take.clone(), ..Default::default() }],
        character: cesium.clone(),
        retarget: Some(retarget.clone()),
        ..Default::default()
    };
    let when = pb::sample_motion_batch_request::When::Times(pb::Times { values: times.clone() });
    let req = pb::SampleMotionBatchRequest {
        motion: Some(rpc_motion.clone()),
        when: Some(when),
        space: pb::Space::Model as i32,
        ..Default::default()
    };
    let mut grpc = app.grpc().await;
    let batch = grpc.sample_motion_batch(req).await.unwrap().into_inner();
    assert_eq!(batch.poses.len(), times.len());
    for (k, (rest, rpc)) in rest["poses"].as_array().unwrap().iter().zip(&batch.poses).enumerate() {
        let joints = rest["joints"].as_array().unwrap();
        for (part, got) in [("translation", &rpc.translations), ("rotation", &rpc.rotations)] {
            let want: Vec<f32> = joints
                .iter()
                .flat_map(|j| j[part].as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32))
                .collect();
            assert_eq!(got, &want, "pose {k}: {part}");
        }
    }

    let time = pb::SourcePose { pose: Some(pb::source_pose::Pose::Time(0.0)) };
    let motion = pb::Motion { retarget: Some(pb::Retarget { target_pose: Some(time), ..retarget }), ..rpc_motion };
    let req = pb::SampleMotionRequest { motion: Some(motion), time: 0.0, ..Default::default() };
    let status = grpc.sample_motion(req).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument);
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "target_pose_needs_rotations", "{status:?}");
    assert!(status.message().contains("/motion/retarget/target_pose"), "{}", status.message());
}

/// Planted feet are priced before anything runs: each adds a two-bone solve
/// to a pose's price, 4 units and 1 per joint of the character (CesiumMan's
/// 21), so two feet add 50 units a pose (docs/characters.md, “Planted feet”).
#[tokio::test]
async fn each_planted_foot_adds_a_two_bone_solve_to_a_pose_s_price() {
    let app = TestApp::builder().configure(|c| c.limits.max_request_work = 1_000_000).start().await;
    let (take, cesium) = take_and_cesium(&app).await;
    let joints = rest_rotations(&app, &cesium).await.len() as u64;
    let per_pose = |retarget: Value| {
        let motion = json!({"layers": [{"clip": take}], "character": cesium, "retarget": retarget});
        let body = json!({"motion": motion, "times": vec![0.0; 10_000]});
        let app = &app;
        async move {
            let resp = app.http.post(app.url("/v1/samples")).json(&body).send().await.unwrap();
            let (status, problem): (u16, Value) = (resp.status().as_u16(), resp.json().await.unwrap());
            assert_eq!((status, problem["code"].as_str()), (422, Some("too_much_work")), "{problem}");
            let detail = problem["detail"].as_str().unwrap();
            let units = detail.split("poses × ").nth(1).and_then(|s| s.split(' ').next()).unwrap();
            units.parse::<u64>().unwrap()
        }
    };
    let free = per_pose(json!({})).await;
    let planted = per_pose(json!({"feet": "plant"})).await;
    assert_eq!(planted - free, 2 * (4 + joints), "{free} → {planted} units a pose");
}
