//! Inverse kinematics over REST (docs/ik.md) with a real client: IK keyed in
//! clips (targets and weights as tracks, solved at every sample), IK in a
//! request's motion, the reports every pose carries, the document's round
//! trip, and the refusals with their codes and pointers.
//!
//! The leg (`common::ik_leg`) has l1 = l2 = 0.5 under hips that move along
//! x at 1 unit/s, so every expected position is worked out by hand: a keyed
//! target's value by lerp, the thigh's place from the time.

use glam::{DQuat, DVec3};
use serde_json::{Value, json};

use super::TestApp;
use crate::common::ik_leg;

async fn post(app: &TestApp, path: &str, body: &Value) -> (u16, Value) {
    let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
    (resp.status().as_u16(), resp.json().await.unwrap())
}

async fn upload(app: &TestApp, doc: &str) -> (u16, Value) {
    let resp = app.http.post(app.url("/v1/clips")).header("content-type", "application/json").body(doc.to_owned());
    let resp = resp.send().await.unwrap();
    (resp.status().as_u16(), resp.json().await.unwrap())
}

fn joint<'a>(pose: &'a Value, name: &str) -> &'a Value {
    let joints = pose["joints"].as_array().unwrap();
    joints.iter().find(|j| j["name"] == name).unwrap_or_else(|| panic!("no joint {name} in {pose}"))
}

fn vec3(v: &Value) -> DVec3 {
    DVec3::new(v[0].as_f64().unwrap(), v[1].as_f64().unwrap(), v[2].as_f64().unwrap())
}

fn position(pose: &Value, name: &str) -> DVec3 {
    vec3(&joint(pose, name)["translation"])
}

fn rotation(pose: &Value, name: &str) -> DQuat {
    let r = &joint(pose, name)["rotation"];
    let q = |i: usize| r[i].as_f64().unwrap();
    DQuat::from_xyzw(q(0), q(1), q(2), q(3))
}

/// A two-bone constraint on the leg whose target moves linearly from `a`
/// at t = 0 to `b` at t = 2, the knee bent toward a pole ahead (+z).
fn keyed_leg(a: [f64; 3], b: [f64; 3]) -> Value {
    json!([{"kind": "two_bone", "joints": ["thigh", "knee", "foot"], "pole": [0, -0.5, 5],
            "target": {"interpolation": "linear", "times": [0, 2], "values": [a, b]}}])
}

fn lerp(a: [f64; 3], b: [f64; 3], s: f64) -> DVec3 {
    DVec3::from(a).lerp(DVec3::from(b), s)
}

#[tokio::test]
async fn a_keyed_target_is_solved_at_every_sample_and_reported() {
    let app = TestApp::start().await;
    let (a, b) = ([0.1, -0.8, 0.2], [2.1, -0.7, -0.2]);
    let id = app.create_id(&ik_leg("step", 2.0, keyed_leg(a, b)), None).await;
    for t in [0.0, 0.25, 1.0, 1.6, 2.0] {
        let pose = app.get_json(&format!("/v1/clips/{id}/pose?t={t}&space=model")).await;
        let target = lerp(a, b, t / 2.0);
        let foot = position(&pose, "foot");
        assert!(foot.distance(target) <= 1e-5 * 1.0 + 1e-6, "t={t}: foot {foot} target {target}");
        // The knee bends toward the pole (ahead, +z of the thigh-foot line).
        let (thigh, knee) = (position(&pose, "thigh"), position(&pose, "knee"));
        assert!((thigh.x - (t + 0.1)).abs() < 1e-5, "the hips track still moves the leg: {thigh}");
        let line = (foot - thigh).normalize();
        let off_line = (knee - thigh) - line * (knee - thigh).dot(line);
        assert!(off_line.z > 0.0, "t={t}: the knee bends toward the pole: {off_line}");
        let report = &pose["ik"][0];
        assert_eq!((report["kind"].as_str(), report["converged"].as_bool()), (Some("two_bone"), Some(true)));
        assert!(report["residual"].as_f64().unwrap() <= 1e-5, "{report}");
        assert_eq!(pose["ik"].as_array().unwrap().len(), 1);
    }
}

#[tokio::test]
async fn keys_count_toward_the_time_range_and_the_document_round_trips() {
    let app = TestApp::start().await;
    let mut ik = keyed_leg([0.1, -0.8, 0.2], [0.1, -0.7, -0.2]);
    ik[0]["target"]["times"] = json!([0, 3]);
    ik[0]["weight"] = json!({"interpolation": "step", "times": [0, 1], "values": [[1], [0.5]]});
    let doc = ik_leg("range", 2.0, ik.clone());
    let summary = app.create(&doc, None).await;
    assert_eq!((summary["start"].as_f64(), summary["end"].as_f64()), (Some(0.0), Some(3.0)));
    let stored = app.get_json(&format!("/v1/clips/{}", summary["id"].as_str().unwrap())).await;
    let sent: Value = serde_json::from_str(&super::canonical(&doc)).unwrap();
    assert_eq!(stored["ik"], sent["ik"], "the clip's constraints come back as sent");
    assert_eq!(stored["ik"][0]["weight"]["values"], json!([[1.0], [0.5]]), "a weight's keys are one number");
}

#[tokio::test]
async fn a_keyed_weight_blends_from_the_unsolved_pose() {
    let app = TestApp::start().await;
    let mut ik = keyed_leg([0.1, -0.6, 0.4], [2.1, -0.6, 0.4]);
    ik[0]["weight"] = json!({"times": [0, 1], "values": [[0], [1]]});
    let solved = app.create_id(&ik_leg("weighted", 2.0, ik), None).await;
    let plain = app.create_id(&ik_leg("plain", 2.0, json!([])), None).await;
    let at = |id: &str, t: f64| format!("/v1/clips/{id}/pose?t={t}&space=model");
    let (zero, rest) = (app.get_json(&at(&solved, 0.0)).await, app.get_json(&at(&plain, 0.0)).await);
    assert_eq!(zero["joints"], rest["joints"], "weight 0 is the unsolved pose exactly");
    assert!(rest.get("ik").is_none(), "a clip without constraints reports none: {rest}");
    let full = app.get_json(&at(&solved, 1.5)).await;
    let target = lerp([0.1, -0.6, 0.4], [2.1, -0.6, 0.4], 0.75);
    assert!(position(&full, "foot").distance(target) <= 1e-5);
    // Halfway, the solved rotations are slerped halfway from the unsolved.
    let local = |id: &str| format!("/v1/clips/{id}/pose?t=0.5&space=local");
    let (half, unsolved) = (app.get_json(&at(&solved, 0.5)).await, app.get_json(&at(&plain, 0.5)).await);
    let (half_local, unsolved_local) = (app.get_json(&local(&solved)).await, app.get_json(&local(&plain)).await);
    let target = lerp([0.1, -0.6, 0.4], [2.1, -0.6, 0.4], 0.25);
    assert!(position(&half, "foot").distance(target) > 1e-3, "half weight does not reach the target");
    assert_eq!(position(&half, "thigh"), position(&unsolved, "thigh"), "only rotations change");
    let angle = rotation(&half_local, "thigh").angle_between(rotation(&unsolved_local, "thigh"));
    assert!(angle > 1e-3, "the thigh turned: {angle}");
}

#[tokio::test]
async fn a_motion_aims_the_head_and_solves_a_chain_after_layering() {
    let app = TestApp::start().await;
    let id = app.create_id(&ik_leg("walk", 10.0, json!([])), None).await;
    let look = [3.0, 2.0, 4.0];
    let reach = [1.05, -0.85, 0.3];
    let motion = json!({"layers": [{"clip": id}], "ik": [
        {"kind": "aim", "joint": "head", "target": look},
        {"kind": "chain", "effectors": [{"joint": "foot", "target": reach}], "joints": ["thigh", "knee"]}
    ]});
    let (status, pose) = post(&app, "/v1/poses", &json!({"motion": motion, "time": 1.0, "space": "model"})).await;
    assert_eq!(status, 200, "{pose}");
    let head = position(&pose, "head");
    let forward = rotation(&pose, "head") * DVec3::Z;
    let to_target = (DVec3::from(look) - head).normalize();
    let angle = forward.cross(to_target).length().atan2(forward.dot(to_target));
    assert!(angle <= 1e-5, "the head's +z points at the target: {angle} rad");
    let reports = pose["ik"].as_array().unwrap();
    assert_eq!(reports.len(), 2, "{pose}");
    assert_eq!((reports[0]["kind"].as_str(), reports[1]["kind"].as_str()), (Some("aim"), Some("chain")));
    let chain = &reports[1];
    assert_eq!(chain["converged"], true, "{chain}");
    // The default tolerance: 1e-4 of the chain's length (thigh → foot, 1.0).
    let miss = position(&pose, "foot").distance(DVec3::from(reach));
    assert!(miss <= 1e-4 + 1e-6, "the foot reaches within the tolerance: {miss}");
    assert!((chain["residual"].as_f64().unwrap() - miss).abs() < 1e-5, "√E is the distance: {chain}");
    assert!(chain["iterations"].as_u64().unwrap() >= 1);
    // Samples carry reports in every pose.
    let (status, samples) =
        post(&app, "/v1/samples", &json!({"motion": motion, "start": 0, "end": 0.5, "fps": 10})).await;
    assert_eq!(status, 200, "{samples}");
    for pose in samples["poses"].as_array().unwrap() {
        assert_eq!(pose["ik"].as_array().unwrap().len(), 2, "{pose}");
    }
}

#[tokio::test]
async fn the_same_request_gets_the_same_answer() {
    let app = TestApp::start().await;
    let id = app.create_id(&ik_leg("walk", 10.0, json!([])), None).await;
    let motion = json!({"layers": [{"clip": id}], "ik": [
        {"kind": "chain", "effectors": [{"joint": "toe", "target": [0.9, -0.7, 0.5]}],
         "limits": {"knee": {"min": [-2, -0.1, -0.1], "max": [0.1, 0.1, 0.1]}}}
    ]});
    let body = json!({"motion": motion, "time": 0.7, "space": "model"});
    let first = post(&app, "/v1/poses", &body).await.1;
    for _ in 0..3 {
        assert_eq!(post(&app, "/v1/poses", &body).await.1, first, "deterministic: no warm start between requests");
    }
}

#[tokio::test]
async fn bad_constraints_are_refused_with_their_codes_and_pointers() {
    let app = TestApp::builder().configure(|c| c.limits.ik_max_constraints = 2).start().await;
    let two_bone = |joints: Value| json!({"kind": "two_bone", "joints": joints, "target": [0, -1, 0]});
    let leg = || json!(["thigh", "knee", "foot"]);
    let cases: Vec<(Value, &str, &str)> = vec![
        (json!([two_bone(json!(["thigh", "knee", "paw"]))]), "unknown_joint", "/ik/0/joints/2"),
        (json!([two_bone(json!(["thigh", "head", "foot"]))]), "not_descendant", "/ik/0/joints/1"),
        (json!([two_bone(json!(["thigh", "knee"]))]), "wrong_width", "/ik/0/joints"),
        (
            json!([{"kind": "aim", "joint": "head", "target": [0, 0, 1], "pole": [0, 0, 1]}]),
            "field_not_applicable",
            "/ik/0/pole",
        ),
        (json!([{"kind": "aim", "joint": "head"}]), "missing_field", "/ik/0/target"),
        (
            json!([{"kind": "aim", "joint": "head", "target": [0, 0, 1], "up": [0, 1, 0]}]),
            "incomplete_up",
            "/ik/0/up_direction",
        ),
        (
            json!([{"kind": "aim", "joint": "head", "target": [0, 0, 1], "forward": [0, 0, 0]}]),
            "zero_axis",
            "/ik/0/forward",
        ),
        (
            json!([{"kind": "two_bone", "joints": leg(), "target": [0, 0, 0], "weight": 1.5}]),
            "weight_out_of_range",
            "/ik/0/weight",
        ),
        (
            json!([{"kind": "two_bone", "joints": leg(), "target": [0, 0, 0], "weight": {"times": [0, 1], "values": [[0], [2]]}}]),
            "weight_out_of_range",
            "/ik/0/weight/values/1",
        ),
        (
            json!([{"kind": "two_bone", "joints": leg(), "target": {"times": [0, 1], "values": [[0, 0, 0], [0, 0]]}}]),
            "wrong_width",
            "/ik/0/target/values/1",
        ),
        (
            json!([{"kind": "two_bone", "joints": leg(), "target": {"times": [1, 0], "values": [[0, 0, 0], [0, 0, 1]]}}]),
            "times_not_increasing",
            "/ik/0/target/times/1",
        ),
        (
            json!([{"kind": "chain", "effectors": [{"joint": "foot", "target": [0, -1, 0]}],
                    "limits": {"knee": {"min": [0, 1, 0], "max": [0, 0, 0]}}}]),
            "limits_out_of_order",
            "/ik/0/limits/knee/min/1",
        ),
        (
            json!([{"kind": "chain", "effectors": [{"joint": "foot", "target": [0, -1, 0]}], "max_iterations": 5000}]),
            "too_many_iterations",
            "/ik/0/max_iterations",
        ),
        (json!([{"kind": "chain", "effectors": []}]), "no_effectors", "/ik/0/effectors"),
        (json!([two_bone(leg()), two_bone(leg()), two_bone(leg())]), "too_many_constraints", "/ik"),
        (json!([{"kind": "spline_ik"}]), "invalid_field", "/ik/0/kind"),
    ];
    for (ik, code, pointer) in cases {
        let (status, problem) = upload(&app, &ik_leg("bad", 1.0, ik.clone())).await;
        assert_eq!(status, 422, "{ik}: {problem}");
        assert_eq!((problem["code"].as_str(), problem["pointer"].as_str()), (Some(code), Some(pointer)), "{ik}");
    }
    assert!(app.list_all(100, None).await.is_empty(), "nothing was stored");

    // The same rules for a request's motion, pointed into `/motion`; a keyed
    // target belongs in a clip.
    let id = app.create_id(&ik_leg("walk", 10.0, json!([])), None).await;
    let refused = |ik: Value| json!({"motion": {"layers": [{"clip": id}], "ik": ik}, "time": 0.5});
    let keyed = json!([{"kind": "aim", "joint": "head", "target": {"times": [0], "values": [[0, 0, 1]]}}]);
    for (ik, code, pointer) in [
        (keyed, "keys_not_allowed", "/motion/ik/0/target"),
        (json!([two_bone(json!(["thigh", "knee", "paw"]))]), "unknown_joint", "/motion/ik/0/joints/2"),
        (json!([two_bone(leg()), two_bone(leg()), two_bone(leg())]), "too_many_constraints", "/motion/ik"),
    ] {
        let (status, problem) = post(&app, "/v1/poses", &refused(ik.clone())).await;
        assert_eq!(status, 422, "{ik}: {problem}");
        assert_eq!((problem["code"].as_str(), problem["pointer"].as_str()), (Some(code), Some(pointer)), "{ik}");
    }
}
