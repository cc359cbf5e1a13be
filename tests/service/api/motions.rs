//! Composed poses over REST (docs/motion.md): `POST /v1/poses` and `/v1/samples`.
//! A one-layer motion answers exactly what the clip routes answer; blends,
//! subsets and root motion against hand-computed values; refusals with
//! their codes and pointers.

use formats::wire::proto::pb;
use serde_json::{Value, json};

use super::{TestApp, WAVE, assert_close};

/// `hips` (moving along x from 0 to `to` over 1 s, looping) with `arm` under it.
fn walk(name: &str, to: f32) -> String {
    json!({
        "name": name,
        "skeleton": {"joints": [
            {"name": "hips", "parent": null},
            {"name": "arm", "parent": "hips", "rest": {"translation": [0, 1, 0]}}
        ]},
        "tracks": [{"joint": "hips", "channel": "translation", "interpolation": "linear",
                    "times": [0, 1], "values": [[0, 0, 0], [to, 0, 0]]}],
        "playback": "loop"
    })
    .to_string()
}

async fn post(app: &TestApp, path: &str, body: &Value) -> (u16, Value) {
    let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
    (resp.status().as_u16(), resp.json().await.unwrap())
}

#[tokio::test]
async fn a_one_layer_motion_answers_exactly_what_the_clip_routes_answer() {
    let app = TestApp::start().await;
    let id = app.create_id(WAVE, None).await;
    for (space, format) in [("local", "trs"), ("model", "trs"), ("model", "matrix")] {
        for t in [0.0, 0.37, 1.25, 2.9, 7.5] {
            let clip = app.get_json(&format!("/v1/clips/{id}/pose?t={t}&space={space}&format={format}")).await;
            let body = json!({"motion": {"layers": [{"clip": id}]}, "time": t, "space": space, "format": format});
            let (status, composed) = post(&app, "/v1/poses", &body).await;
            assert_eq!(status, 200, "{composed}");
            assert_eq!(composed, clip, "t = {t}, {space}, {format}");
        }
    }
    let times = json!([0.0, 0.5, 1.0, 2.75]);
    let (_, clip) = post(&app, &format!("/v1/clips/{id}/sample"), &json!({"times": times, "space": "model"})).await;
    let body = json!({"motion": {"layers": [{"clip": id}]}, "times": times, "space": "model"});
    let (status, composed) = post(&app, "/v1/samples", &body).await;
    assert_eq!((status, composed), (200, clip));
    app.stop().await;
}

#[tokio::test]
async fn layers_blend_by_weight_and_a_subset_returns_only_its_joints() {
    let app = TestApp::start().await;
    let (walk_id, run_id) =
        (app.create_id(&walk("walk", 2.0), None).await, app.create_id(&walk("run", 6.0), None).await);
    let motion = json!({"layers": [{"clip": walk_id}, {"clip": run_id, "weight": 0.3}]});
    let (status, pose) = post(&app, "/v1/poses", &json!({"motion": motion, "time": 0.5, "space": "model"})).await;
    assert_eq!(status, 200, "{pose}");
    assert_eq!(pose["clip"], walk_id, "a composed pose names the first layer's clip");
    // hips: walk at x = 1, run at x = 3 → 0.7·1 + 0.3·3 = 1.6; arm one unit above it in model space.
    assert_close(pose["joints"][0]["translation"][0].as_f64().unwrap(), 1.6, 1e-6, "hips x");
    assert_close(pose["joints"][1]["translation"][0].as_f64().unwrap(), 1.6, 1e-6, "arm x");
    assert_close(pose["joints"][1]["translation"][1].as_f64().unwrap(), 1.0, 1e-6, "arm y");
    let subset = json!({"motion": motion, "time": 0.5, "space": "model", "joints": ["arm"]});
    let (status, only) = post(&app, "/v1/poses", &subset).await;
    assert_eq!(status, 200);
    assert_eq!(only["joints"].as_array().unwrap().len(), 1);
    assert_eq!(only["joints"][0], pose["joints"][1], "model space still goes through the hips");
    app.stop().await;
}

#[tokio::test]
async fn samples_carry_root_motion_across_loop_seams_and_extract_keeps_the_root_in_place() {
    let app = TestApp::start().await;
    let id = app.create_id(&walk("walk", 2.0), None).await;
    let body = |mode: &str| json!({"motion": {"layers": [{"clip": id}], "root_motion": {"mode": mode}}, "start": 0, "end": 2.5, "fps": 10});
    let (status, answer) = post(&app, "/v1/samples", &body("report")).await;
    assert_eq!(status, 200, "{answer}");
    let poses = answer["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 26);
    assert_eq!(poses[0]["root_motion"]["delta"], json!({"translation": [0.0, 0.0, 0.0], "yaw": 0.0}));
    for (k, pose) in poses.iter().enumerate().skip(1) {
        let dx = pose["root_motion"]["delta"]["translation"][0].as_f64().unwrap();
        assert_close(dx, 0.2, 1e-5, &format!("frame {k}'s delta, across the seams too"));
    }
    let total = poses[25]["root_motion"]["total"]["translation"][0].as_f64().unwrap();
    assert_close(total, 5.0, 1e-4, "two and a half cycles of 2 m");
    let (_, extracted) = post(&app, "/v1/samples", &body("extract")).await;
    for pose in extracted["poses"].as_array().unwrap() {
        assert_close(pose["joints"][0]["translation"][0].as_f64().unwrap(), 0.0, 1e-6, "hips in place");
    }
    app.stop().await;
}

#[tokio::test]
async fn bad_motions_are_refused_with_their_codes_and_pointers() {
    let app = TestApp::start().await;
    let id = app.create_id(&walk("walk", 2.0), None).await;
    let layer = json!({"clip": id});
    let cases = [
        (
            json!({"layers": [layer, {"clip": id, "weight": 2}]}),
            None,
            422,
            "weight_out_of_range",
            "/motion/layers/1/weight",
        ),
        (
            json!({"layers": [layer, {"clip": id, "mask": {"joints": {"tail": 1}}}]}),
            None,
            422,
            "unknown_joint",
            "/motion/layers/1/mask/joints/tail",
        ),
        (json!({"layers": [layer]}), Some(json!(["arm", "tail"])), 422, "unknown_joint", "/joints/1"),
        (json!({"layers": []}), None, 422, "no_layers", "/motion/layers"),
        (json!({"layers": [{"clip": id, "wieght": 1}]}), None, 422, "invalid_field", "/motion/layers/0"),
    ];
    for (motion, joints, status, code, pointer) in cases {
        let mut body = json!({"motion": motion, "time": 0.5});
        if let Some(joints) = joints {
            body["joints"] = joints;
        }
        let (got, problem) = post(&app, "/v1/poses", &body).await;
        assert_eq!((got, problem["code"].as_str()), (status, Some(code)), "{problem}");
        assert!(problem["pointer"].as_str().unwrap_or("").starts_with(pointer), "{problem}");
    }
    let missing =
        json!({"motion": {"layers": [{"clip": id}, {"clip": "0190f0c2-0000-7000-8000-000000000000"}]}, "time": 0});
    let (status, problem) = post(&app, "/v1/poses", &missing).await;
    assert_eq!((status, problem["code"].as_str()), (404, Some("clip_not_found")), "{problem}");
    assert_eq!(problem["pointer"], "/motion/layers/1/clip", "the 404 names the layer");
    app.stop().await;
}

fn one_layer(id: &str) -> pb::Motion {
    pb::Motion { layers: vec![pb::Layer { clip_id: id.to_owned(), ..Default::default() }], ..Default::default() }
}

#[tokio::test]
async fn grpc_sample_motion_mirrors_the_clip_rpcs_and_the_rest_routes() {
    let app = TestApp::start().await;
    let id = app.create_id(WAVE, None).await;
    let mut grpc = app.grpc().await;
    for (space, format) in [(pb::Space::Local, pb::Format::Trs), (pb::Space::Model, pb::Format::Matrix)] {
        for t in [0.0, 0.37, 2.9] {
            let (space, format) = (space as i32, format as i32);
            let clip = pb::SampleRequest { clip_id: id.clone(), time: t, space, format, ..Default::default() };
            let clip = grpc.sample(clip).await.unwrap().into_inner();
            let req =
                pb::SampleMotionRequest { motion: Some(one_layer(&id)), time: t, space, format, ..Default::default() };
            assert_eq!(grpc.sample_motion(req).await.unwrap().into_inner(), clip, "t = {t}");
        }
    }
    // Root motion and a subset, as REST answers them.
    let walk_id = app.create_id(&walk("walk", 2.0), None).await;
    let root = pb::RootMotionOptions::default();
    let motion = pb::Motion { root_motion: Some(root), ..one_layer(&walk_id) };
    let when = pb::sample_motion_batch_request::When::Range(pb::FrameRange { start: 0.0, end: 2.5, fps: 10.0 });
    let req = pb::SampleMotionBatchRequest {
        motion: Some(motion),
        when: Some(when),
        joints: vec!["hips".into()],
        ..Default::default()
    };
    let batch = grpc.sample_motion_batch(req).await.unwrap().into_inner();
    assert_eq!(batch.joint_names, ["hips"]);
    assert_eq!(batch.poses.len(), 26);
    assert_eq!(batch.poses[1].translations.len(), 3, "one joint");
    let total = batch.poses[25].root_motion.as_ref().unwrap().total.as_ref().unwrap();
    assert_close(total.x, 5.0, 1e-4, "two and a half cycles of 2 m");
    // The same refusals and codes as REST.
    let bad = pb::Motion {
        layers: vec![pb::Layer { clip_id: id.clone(), weight: Some(2.0), ..Default::default() }],
        ..Default::default()
    };
    let req = pb::SampleMotionRequest { motion: Some(bad), time: 0.0, ..Default::default() };
    let status = grpc.sample_motion(req).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "weight_out_of_range");
    assert!(status.message().contains("/motion/layers/0/weight"), "{}", status.message());
    let missing = one_layer("0190f0c2-0000-7000-8000-000000000000");
    let req = pb::SampleMotionRequest { motion: Some(missing), time: 0.0, ..Default::default() };
    assert_eq!(grpc.sample_motion(req).await.unwrap_err().code(), tonic::Code::NotFound);
    app.stop().await;
}

#[tokio::test]
async fn the_clip_routes_take_a_joint_subset_too() {
    let app = TestApp::start().await;
    let id = app.create_id(WAVE, None).await;
    let full = app.get_json(&format!("/v1/clips/{id}/pose?t=1.2&space=model")).await;
    let only = app.get_json(&format!("/v1/clips/{id}/pose?t=1.2&space=model&joints=arm")).await;
    assert_eq!(only["joints"], json!([full["joints"][1]]), "the arm alone, in model space through the root");
    let matrices = app.get_json(&format!("/v1/clips/{id}/pose?t=1.2&format=matrix&joints=arm,root")).await;
    let names: Vec<&str> = matrices["joints"].as_array().unwrap().iter().map(|j| j["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["root", "arm"], "skeleton order, whatever the order asked");
    let body = json!({"times": [0.5, 1.5], "joints": ["root"]});
    let (status, answer) = post(&app, &format!("/v1/clips/{id}/sample"), &body).await;
    assert_eq!(status, 200);
    assert!(answer["poses"].as_array().unwrap().iter().all(|p| p["joints"].as_array().unwrap().len() == 1));
    let resp = app.http.get(app.url(&format!("/v1/clips/{id}/pose?t=1&joints=tail"))).send().await.unwrap();
    assert_eq!(resp.status(), 422);
    let problem: Value = resp.json().await.unwrap();
    assert_eq!((problem["code"].as_str(), problem["parameter"].as_str()), (Some("unknown_joint"), Some("joints")));
    let (status, problem) =
        post(&app, &format!("/v1/clips/{id}/sample"), &json!({"times": [0], "joints": ["x"]})).await;
    assert_eq!((status, problem["pointer"].as_str()), (422, Some("/joints/0")));
    app.stop().await;
}
