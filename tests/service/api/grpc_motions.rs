//! gRPC's `Motion` against REST's JSON motion (docs/motion.md, docs/graphs.md):
//! the same motion written both ways — a CMU take retargeted onto
//! CesiumMan, a tail of spring chains with colliders, the Fox's
//! locomotion graph played with timed inputs — answers the same poses over
//! a real tonic client as over HTTP, and the same mistakes are refused with
//! the same codes.

use formats::wire::proto::pb;
use serde_json::{Value, json};

use super::TestApp;
use super::graph_samples::fox_graph;
use super::rigs::{import, import_character};

async fn post(app: &TestApp, path: &str, body: &Value) -> (u16, Value) {
    let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
    (resp.status().as_u16(), resp.json().await.unwrap())
}

async fn rest_ok(app: &TestApp, path: &str, body: &Value) -> Value {
    let (status, answer) = post(app, path, body).await;
    assert_eq!(status, 200, "{path}: {answer}");
    answer
}

/// A JSON pose's numbers, part by part, flattened as the protobuf packs them.
fn flat(pose: &Value, part: &str) -> Vec<f64> {
    let joints = pose["joints"].as_array().unwrap();
    joints.iter().flat_map(|j| j[part].as_array().unwrap().iter().map(|x| x.as_f64().unwrap())).collect()
}

/// The REST pose and the gRPC pose say the same: names (when the gRPC
/// pose carries them), time, and every number within 1e-6 (relative above 1).
fn assert_same_pose(rest: &Value, rpc: &pb::Pose, what: &str) {
    if !rpc.joint_names.is_empty() {
        let names: Vec<&str> = rest["joints"].as_array().unwrap().iter().map(|j| j["name"].as_str().unwrap()).collect();
        assert_eq!(rpc.joint_names, names, "{what}");
    }
    assert!((rpc.time - rest["time"].as_f64().unwrap()).abs() < 1e-9, "{what}: time {} vs {}", rpc.time, rest["time"]);
    for (part, got) in [("translation", &rpc.translations), ("rotation", &rpc.rotations), ("scale", &rpc.scales)] {
        let want = flat(rest, part);
        assert_eq!(got.len(), want.len(), "{what}: {part}s");
        // JSON writes an f32's shortest text, which as an f64 is up to half
        // an f32 step from it: compare relative to the magnitude.
        let off = |(g, w): (&f32, &f64)| (f64::from(*g) - w).abs() / w.abs().max(1.0);
        let worst = got.iter().zip(&want).map(off).fold(0.0, f64::max);
        assert!(worst <= 1e-6, "{what}: {part}s differ by {worst}");
    }
}

/// A JSON `graph` report and a `GraphReport` say the same.
fn assert_same_report(rest: &Value, rpc: Option<&pb::GraphReport>, what: &str) {
    let rpc = rpc.unwrap_or_else(|| panic!("{what}: no report"));
    assert_eq!(rest["state"], rpc.state.as_str(), "{what}");
    match (rest.get("transition"), &rpc.transition) {
        (None, None) => {}
        (Some(t), Some(r)) => {
            assert_eq!((&t["from"], &t["to"]), (&json!(r.from), &json!(r.to)), "{what}");
            assert!((t["alpha"].as_f64().unwrap() - f64::from(r.alpha)).abs() < 1e-6, "{what}");
        }
        (t, r) => panic!("{what}: transition {t:?} vs {r:?}"),
    }
    let weights = rest["weights"].as_object().unwrap();
    assert_eq!(weights.len(), rpc.weights.len(), "{what}: {weights:?} vs {:?}", rpc.weights);
    for (node, list) in weights {
        let got = &rpc.weights[node].weights;
        let want: Vec<f64> = list.as_array().unwrap().iter().map(|w| w.as_f64().unwrap()).collect();
        assert_eq!(got.len(), want.len(), "{what}: {node}");
        assert!(got.iter().zip(&want).all(|(g, w)| (f64::from(*g) - w).abs() < 1e-6), "{what}: {node}");
    }
}

fn quat(x: f32, y: f32, z: f32, w: f32) -> pb::Quaternion {
    pb::Quaternion { x, y, z, w }
}

fn v3(x: f32, y: f32, z: f32) -> Option<pb::Vec3> {
    Some(pb::Vec3 { x, y, z })
}

/// A CMU take on CesiumMan: the motion's retarget (all translations, the
/// take's pose at 0 as reference) and a second layer's own (a rotation
/// replacing the rest's, no translation), at a few times, in both spaces.
#[tokio::test]
async fn a_character_and_its_retargets_play_the_same_over_grpc_as_over_rest() {
    let app = TestApp::start().await;
    let cesium = import_character(&app, "gltf/CesiumMan/CesiumMan.gltf", "cesium").await;
    let take = import(&app, "bvh/131_01.bvh", None).await;
    let motion = json!({
        "layers": [
            {"clip": take},
            {"clip": take, "weight": 0.5, "offset": 0.4,
             "retarget": {"source_pose": {"rotations": {"LeftShoulder": [0, 0, 0.6, 0.8]}}, "translation": "none"}}
        ],
        "character": "name:cesium",
        "retarget": {"source_pose": {"time": 0}, "translation": "all"}
    });
    let rotations = pb::JointRotations { joints: [("LeftShoulder".to_owned(), quat(0.0, 0.0, 0.6, 0.8))].into() };
    let rpc_motion = pb::Motion {
        layers: vec![
            pb::Layer { clip_id: take.clone(), ..Default::default() },
            pb::Layer {
                clip_id: take.clone(),
                weight: Some(0.5),
                offset: 0.4,
                retarget: Some(pb::Retarget {
                    source_pose: Some(pb::SourcePose { pose: Some(pb::source_pose::Pose::Rotations(rotations)) }),
                    translation: pb::RetargetTranslation::None as i32,
                    ..Default::default()
                }),
                ..Default::default()
            },
        ],
        character: "name:cesium".into(),
        retarget: Some(pb::Retarget {
            source_pose: Some(pb::SourcePose { pose: Some(pb::source_pose::Pose::Time(0.0)) }),
            translation: pb::RetargetTranslation::All as i32,
            ..Default::default()
        }),
        ..Default::default()
    };
    let mut grpc = app.grpc().await;
    for (space, rpc_space) in [("local", pb::Space::Local), ("model", pb::Space::Model)] {
        for t in [0.0, 0.75, 1.5] {
            let rest = rest_ok(&app, "/v1/poses", &json!({"motion": motion, "time": t, "space": space})).await;
            let req = pb::SampleMotionRequest {
                motion: Some(rpc_motion.clone()),
                time: t,
                space: rpc_space as i32,
                ..Default::default()
            };
            let rpc = grpc.sample_motion(req).await.unwrap().into_inner();
            assert_same_pose(&rest, &rpc, &format!("{space} at {t}"));
        }
    }
    // The retargets matter: without them, another pose.
    let plain =
        json!({"layers": [{"clip": take}, {"clip": take, "weight": 0.5, "offset": 0.4}], "character": "name:cesium"});
    let with = rest_ok(&app, "/v1/poses", &json!({"motion": motion, "time": 0.75})).await;
    let without = rest_ok(&app, "/v1/poses", &json!({"motion": plain, "time": 0.75})).await;
    assert_ne!(flat(&with, "translation"), flat(&without, "translation"));
    assert_ne!(flat(&with, "rotation"), flat(&without, "rotation"));
    // The poses are CesiumMan's joints, not the take's: the character was read.
    let req = pb::SampleMotionRequest { motion: Some(rpc_motion), time: 0.5, ..Default::default() };
    let names = grpc.sample_motion(req).await.unwrap().into_inner().joint_names;
    let cesium = app.get_json(&format!("/v1/characters/{}", cesium["id"].as_str().unwrap())).await;
    let joints = cesium["skeleton"]["joints"].as_array().unwrap();
    assert_eq!(names, joints.iter().map(|j| j["name"].as_str().unwrap()).collect::<Vec<_>>());
    assert!(!names.iter().any(|n| n == "LeftShoulder"));
    app.stop().await;
}

/// `hips` swinging along x, a tail of three 0.1 m bones behind it.
fn tail_clip() -> String {
    json!({
        "name": "tailed",
        "skeleton": {"joints": [
            {"name": "hips", "parent": null},
            {"name": "tail0", "parent": "hips", "rest": {"translation": [0, 0, -0.1]}},
            {"name": "tail1", "parent": "tail0", "rest": {"translation": [0, 0, -0.1]}},
            {"name": "tail2", "parent": "tail1", "rest": {"translation": [0, 0, -0.1]}},
            {"name": "tail_end", "parent": "tail2", "rest": {"translation": [0, 0, -0.1]}}
        ]},
        "tracks": [{"joint": "hips", "channel": "translation", "interpolation": "linear",
                    "times": [0, 0.5, 1], "values": [[0, 0, 0], [0.3, 0, 0], [0, 0, 0]]}],
        "playback": "loop"
    })
    .to_string()
}

/// Spring chains with every field (per-joint overrides, a sphere and a
/// capsule, a substep rate) swing the same over both wires, in a pose and
/// in a batch whose simulation runs from pose to pose.
#[tokio::test]
async fn spring_chains_swing_the_same_over_grpc_as_over_rest() {
    let app = TestApp::start().await;
    let clip = app.create_id(&tail_clip(), None).await;
    let motion = json!({
        "layers": [{"clip": clip}],
        "springs": [{"name": "tail", "joints": ["tail0", "tail1", "tail2", "tail_end"],
                     "stiffness": 0.8, "drag": 0.3, "gravity": [0, -9.81, 0], "radius": 0.03,
                     "joint_params": {"tail1": {"stiffness": 0.4, "gravity": [0, -4, 0]}},
                     "colliders": [{"joint": "hips", "sphere": {"offset": [0, -0.15, -0.1], "radius": 0.05}},
                                   {"joint": "hips", "capsule": {"tail": [0.1, -0.1, -0.2], "radius": 0.02}}]}],
        "spring_substep_hz": 90
    });
    let params = pb::SpringJointParams { stiffness: Some(0.4), gravity: v3(0.0, -4.0, 0.0), ..Default::default() };
    let sphere = pb::SpringSphere { offset: v3(0.0, -0.15, -0.1), radius: 0.05 };
    let capsule = pb::SpringCapsule { offset: None, tail: v3(0.1, -0.1, -0.2), radius: 0.02 };
    let shape = |s| pb::SpringCollider { joint: "hips".into(), shape: Some(s) };
    let rpc_motion = pb::Motion {
        layers: vec![pb::Layer { clip_id: clip.clone(), ..Default::default() }],
        springs: vec![pb::Spring {
            name: "tail".into(),
            joints: ["tail0", "tail1", "tail2", "tail_end"].map(String::from).to_vec(),
            stiffness: Some(0.8),
            drag: Some(0.3),
            gravity: v3(0.0, -9.81, 0.0),
            radius: Some(0.03),
            joint_params: [("tail1".to_owned(), params)].into(),
            colliders: vec![
                shape(pb::spring_collider::Shape::Sphere(sphere)),
                shape(pb::spring_collider::Shape::Capsule(capsule)),
            ],
        }],
        spring_substep_hz: Some(90.0),
        ..Default::default()
    };
    let mut grpc = app.grpc().await;
    let rest = rest_ok(&app, "/v1/poses", &json!({"motion": motion, "time": 0.7, "space": "model"})).await;
    let req = pb::SampleMotionRequest {
        motion: Some(rpc_motion.clone()),
        time: 0.7,
        space: pb::Space::Model as i32,
        ..Default::default()
    };
    let rpc = grpc.sample_motion(req).await.unwrap().into_inner();
    assert_same_pose(&rest, &rpc, "a pose");
    let tail = &rpc.rotations[4..8];
    assert_ne!(tail, [0.0, 0.0, 0.0, 1.0], "the tail swings");
    let times = [0.1, 0.35, 0.6, 1.3];
    let rest = rest_ok(&app, "/v1/samples", &json!({"motion": motion, "times": times})).await;
    let when = pb::sample_motion_batch_request::When::Times(pb::Times { values: times.to_vec() });
    let req = pb::SampleMotionBatchRequest { motion: Some(rpc_motion), when: Some(when), ..Default::default() };
    let batch = grpc.sample_motion_batch(req).await.unwrap().into_inner();
    assert_eq!(batch.poses.len(), times.len());
    for (k, (rest, rpc)) in rest["poses"].as_array().unwrap().iter().zip(&batch.poses).enumerate() {
        assert_same_pose(rest, rpc, &format!("batch pose {k}"));
    }
    app.stop().await;
}

fn over_graph(graph: &str) -> pb::Motion {
    pb::Motion { layers: vec![pb::Layer { graph: graph.to_owned(), ..Default::default() }], ..Default::default() }
}

fn rpc_inputs() -> Vec<pb::GraphInput> {
    use pb::graph_value::Value::{Flag, Number};
    let input = |time: f64, name: &str, value| pb::GraphInput {
        time,
        set: [(name.to_owned(), pb::GraphValue { value: Some(value) })].into(),
    };
    vec![input(1.0, "speed", Number(2.5)), input(2.0, "survey", Flag(true)), input(2.6, "speed", Number(0.0))]
}

fn rest_inputs() -> Value {
    json!([{"time": 1, "set": {"speed": 2.5}}, {"time": 2, "set": {"survey": true}},
           {"time": 2.6, "set": {"speed": 0}}])
}

/// The Fox's graph over gRPC: a batch with inputs and reports is REST's
/// `/v1/samples` tick for tick (states, transitions, blend weights), and
/// `SampleMotion` is REST's `/v1/poses` at the last tick at or before its time.
#[tokio::test]
async fn a_graph_plays_the_same_over_grpc_as_over_rest() {
    let app = TestApp::start().await;
    let (graph, _) = fox_graph(&app).await;
    let body = json!({"motion": {"layers": [{"graph": graph}]}, "start": 0.5, "end": 5.5, "fps": 30,
                      "space": "model", "inputs": rest_inputs(), "report": true});
    let rest = rest_ok(&app, "/v1/samples", &body).await;
    let rest = rest["poses"].as_array().unwrap();
    let mut grpc = app.grpc().await;
    let range = pb::FrameRange { start: 0.5, end: 5.5, fps: 30.0 };
    let req = pb::SampleMotionBatchRequest {
        motion: Some(over_graph(&graph)),
        when: Some(pb::sample_motion_batch_request::When::Range(range)),
        space: pb::Space::Model as i32,
        inputs: rpc_inputs(),
        report: true,
        ..Default::default()
    };
    let batch = grpc.sample_motion_batch(req).await.unwrap().into_inner();
    assert_eq!((rest.len(), batch.poses.len()), (151, 151), "ticks 15..=165");
    let names: Vec<&str> = rest[0]["joints"].as_array().unwrap().iter().map(|j| j["name"].as_str().unwrap()).collect();
    assert_eq!(batch.joint_names, names);
    let mut states = Vec::new();
    for (k, (rest, rpc)) in rest.iter().zip(&batch.poses).enumerate() {
        let what = format!("tick {}", 15 + k);
        assert_same_pose(rest, rpc, &what);
        assert_same_report(&rest["graph"], rpc.graph.as_ref(), &what);
        if states.last() != Some(&rpc.graph.as_ref().unwrap().state) {
            states.push(rpc.graph.as_ref().unwrap().state.clone());
        }
    }
    // Survey's 90 % (3.08 s) after the look began at 2 s, back to move, and at
    // speed 0 (since 2.6 s) on to idle: the inputs were played.
    assert_eq!(&states[..3], ["idle", "move", "look"], "{states:?}");
    assert_eq!(states.last().unwrap(), "idle", "{states:?}");
    // One pose: REST's /v1/poses (the samples' tick), with its names.
    for time in [0.0, 1.0, 2.04, 2.9] {
        let body = json!({"motion": {"layers": [{"graph": graph}]}, "time": time, "fps": 30,
                          "inputs": rest_inputs(), "report": true});
        let rest = rest_ok(&app, "/v1/poses", &body).await;
        let req = pb::SampleMotionRequest {
            motion: Some(over_graph(&graph)),
            time,
            inputs: rpc_inputs(),
            report: true,
            fps: Some(30),
            ..Default::default()
        };
        let rpc = grpc.sample_motion(req).await.unwrap().into_inner();
        assert_same_pose(&rest, &rpc, &format!("the pose at {time}"));
        assert_same_report(&rest["graph"], rpc.graph.as_ref(), &format!("the pose at {time}"));
        assert!(!rpc.joint_names.is_empty());
    }
    // Without `report`, no report.
    let req = pb::SampleMotionRequest { motion: Some(over_graph(&graph)), time: 1.0, ..Default::default() };
    assert_eq!(grpc.sample_motion(req).await.unwrap().into_inner().graph, None);
    app.stop().await;
}

/// The REST problem's code and pointer, and the gRPC status's code
/// (`x-error-code`) and pointer (the message's `(at …)`).
async fn refusals(app: &TestApp, rest: (&str, &Value), rpc: Result<tonic::Response<impl Sized>, tonic::Status>) {
    let (status, problem) = post(app, rest.0, rest.1).await;
    assert!(status == 422 || status == 404, "{}: {problem}", rest.1);
    let rpc = rpc.err().unwrap_or_else(|| panic!("gRPC took what REST refused: {problem}"));
    let expected = if status == 404 { tonic::Code::NotFound } else { tonic::Code::InvalidArgument };
    assert_eq!(rpc.code(), expected, "{rpc:?}");
    assert_eq!(rpc.metadata().get("x-error-code").unwrap().to_str().unwrap(), problem["code"], "{rpc:?}");
    let pointer = problem["pointer"].as_str().unwrap();
    assert!(rpc.message().contains(&format!("(at {pointer})")), "{pointer}: {}", rpc.message());
}

#[tokio::test]
async fn the_same_mistakes_are_refused_with_the_same_codes_on_both_wires() {
    let app = TestApp::start().await;
    let (graph, _) = fox_graph(&app).await;
    let clip = app.create_id(&tail_clip(), None).await;
    let mut grpc = app.grpc().await;
    let graph_pose = |time: f64, fps: Option<u32>, inputs: Vec<pb::GraphInput>| pb::SampleMotionRequest {
        motion: Some(over_graph(&graph)),
        time,
        fps,
        inputs,
        ..Default::default()
    };
    let over = json!({"layers": [{"graph": graph}]});
    let bad_input = pb::GraphInput {
        time: 0.0,
        set: [("nope".to_owned(), pb::GraphValue { value: Some(pb::graph_value::Value::Flag(true)) })].into(),
    };
    let cases: Vec<(Value, pb::SampleMotionRequest)> = vec![
        (json!({"motion": over, "time": -1}), graph_pose(-1.0, None, Vec::new())),
        (json!({"motion": over, "time": 1, "fps": 0}), graph_pose(1.0, Some(0), Vec::new())),
        (json!({"motion": over, "time": 1, "fps": 500}), graph_pose(1.0, Some(500), Vec::new())),
        (
            json!({"motion": over, "time": 1, "inputs": [{"time": 0, "set": {"nope": true}}]}),
            graph_pose(1.0, None, vec![bad_input]),
        ),
        (
            json!({"motion": {"layers": [{"graph": graph, "retarget": {}}]}, "time": 1}),
            pb::SampleMotionRequest {
                motion: Some(pb::Motion {
                    layers: vec![pb::Layer {
                        graph: graph.clone(),
                        retarget: Some(pb::Retarget::default()),
                        ..Default::default()
                    }],
                    ..Default::default()
                }),
                time: 1.0,
                ..Default::default()
            },
        ),
        (
            json!({"motion": {"layers": [{"graph": graph}], "character": "name:x"}, "time": 1}),
            pb::SampleMotionRequest {
                motion: Some(pb::Motion { character: "name:x".into(), ..over_graph(&graph) }),
                time: 1.0,
                ..Default::default()
            },
        ),
        (
            json!({"motion": {"layers": [{"clip": clip}]}, "time": 1, "report": true}),
            pb::SampleMotionRequest {
                motion: Some(pb::Motion {
                    layers: vec![pb::Layer { clip_id: clip.clone(), ..Default::default() }],
                    ..Default::default()
                }),
                time: 1.0,
                report: true,
                ..Default::default()
            },
        ),
        (
            json!({"motion": {"layers": [{"clip": clip}], "character": "name:nobody"}, "time": 1}),
            pb::SampleMotionRequest {
                motion: Some(pb::Motion {
                    layers: vec![pb::Layer { clip_id: clip.clone(), ..Default::default() }],
                    character: "name:nobody".into(),
                    ..Default::default()
                }),
                time: 1.0,
                ..Default::default()
            },
        ),
        (
            json!({"motion": {"layers": [{"clip": clip}], "springs": [{"name": "t", "joints": ["tail0", "nose"]}]},
                   "time": 1}),
            pb::SampleMotionRequest {
                motion: Some(pb::Motion {
                    layers: vec![pb::Layer { clip_id: clip.clone(), ..Default::default() }],
                    springs: vec![pb::Spring {
                        name: "t".into(),
                        joints: vec!["tail0".into(), "nose".into()],
                        ..Default::default()
                    }],
                    ..Default::default()
                }),
                time: 1.0,
                ..Default::default()
            },
        ),
        (
            json!({"motion": {"layers": [{"clip": clip}], "spring_substep_hz": 0}, "time": 1}),
            pb::SampleMotionRequest {
                motion: Some(pb::Motion {
                    layers: vec![pb::Layer { clip_id: clip.clone(), ..Default::default() }],
                    spring_substep_hz: Some(0.0),
                    ..Default::default()
                }),
                time: 1.0,
                ..Default::default()
            },
        ),
    ];
    for (body, req) in cases {
        refusals(&app, ("/v1/poses", &body), grpc.sample_motion(req).await).await;
    }
    // A batch over a graph takes a range, and refuses a report without one.
    let body = json!({"motion": over, "times": [0.5]});
    let req = pb::SampleMotionBatchRequest {
        motion: Some(over_graph(&graph)),
        when: Some(pb::sample_motion_batch_request::When::Times(pb::Times { values: vec![0.5] })),
        ..Default::default()
    };
    refusals(&app, ("/v1/samples", &body), grpc.sample_motion_batch(req).await).await;
    let body = json!({"motion": {"layers": [{"clip": clip}]}, "start": 0, "end": 1, "fps": 10, "inputs": []});
    let req = pb::SampleMotionBatchRequest {
        motion: Some(pb::Motion {
            layers: vec![pb::Layer { clip_id: clip.clone(), ..Default::default() }],
            ..Default::default()
        }),
        when: Some(pb::sample_motion_batch_request::When::Range(pb::FrameRange { start: 0.0, end: 1.0, fps: 10.0 })),
        inputs: vec![pb::GraphInput::default()],
        ..Default::default()
    };
    refusals(&app, ("/v1/samples", &body), grpc.sample_motion_batch(req).await).await;
    // A time JSON cannot send is `bad_number`, as for a pose of clips.
    let status = grpc.sample_motion(graph_pose(f64::NAN, None, Vec::new())).await.unwrap_err();
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "bad_number", "{status:?}");
    assert!(status.message().contains("(at /time)"), "{}", status.message());
    // A range's fields sit in `range` on gRPC: the same code at `/range/…`.
    let req = pb::SampleMotionBatchRequest {
        motion: Some(over_graph(&graph)),
        when: Some(pb::sample_motion_batch_request::When::Range(pb::FrameRange { start: 2.0, end: 1.0, fps: 30.0 })),
        ..Default::default()
    };
    let status = grpc.sample_motion_batch(req).await.unwrap_err();
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "bad_range", "{status:?}");
    assert!(status.message().contains("(at /range/end)"), "{}", status.message());
    app.stop().await;
}

/// A clip's `Sample` and `SampleBatch` with `character` answer what REST's
/// clip routes with `character=` answer, number for number: the CMU take on
/// CesiumMan, by id and by `name:`, in both spaces, a clip `playback` carried
/// into the layer.
#[tokio::test]
async fn a_clip_on_a_character_samples_the_same_over_grpc_as_over_rest() {
    let app = TestApp::start().await;
    let cesium = import_character(&app, "gltf/CesiumMan/CesiumMan.gltf", "cesium").await;
    let take = import(&app, "bvh/131_01.bvh", None).await;
    let mut grpc = app.grpc().await;
    for character in [cesium["id"].as_str().unwrap().to_owned(), "name:cesium".to_owned()] {
        for (space, rpc_space) in [("local", pb::Space::Local), ("model", pb::Space::Model)] {
            for t in [0.0, 0.75, 9.5] {
                let url = format!("/v1/clips/{take}/pose?t={t}&space={space}&playback=loop&character={character}");
                let resp = app.http.get(app.url(&url)).send().await.unwrap();
                assert_eq!(resp.status(), 200, "{url}");
                let rest: Value = resp.json().await.unwrap();
                let req = pb::SampleRequest {
                    clip_id: take.clone(),
                    time: t,
                    space: rpc_space as i32,
                    playback: pb::Playback::Loop as i32,
                    character: Some(character.clone()),
                    ..Default::default()
                };
                let rpc = grpc.sample(req).await.unwrap().into_inner();
                assert_same_pose(&rest, &rpc, &format!("{character} {space} at {t}"));
            }
        }
        let times = vec![0.1, 0.5, 1.25, 2.0];
        let body = json!({"times": times, "space": "model", "character": character});
        let rest = rest_ok(&app, &format!("/v1/clips/{take}/sample"), &body).await;
        let req = pb::SampleBatchRequest {
            clip_id: take.clone(),
            when: Some(pb::sample_batch_request::When::Times(pb::Times { values: times.clone() })),
            space: pb::Space::Model as i32,
            character: Some(character.clone()),
            ..Default::default()
        };
        let batch = grpc.sample_batch(req).await.unwrap().into_inner();
        let poses = rest["poses"].as_array().unwrap();
        assert_eq!(batch.poses.len(), poses.len());
        let names: Vec<&str> =
            poses[0]["joints"].as_array().unwrap().iter().map(|j| j["name"].as_str().unwrap()).collect();
        assert_eq!(batch.joint_names, names, "CesiumMan's joints, named once");
        for (k, (rest, rpc)) in poses.iter().zip(&batch.poses).enumerate() {
            assert_same_pose(rest, rpc, &format!("{character} batch pose {k}"));
        }
    }
    // On the take's own skeleton, another pose: the character was played on.
    let own = grpc.sample(own_request(&take)).await.unwrap().into_inner();
    let on = pb::SampleRequest { character: Some("name:cesium".into()), ..own_request(&take) };
    let on = grpc.sample(on).await.unwrap().into_inner();
    assert_ne!(own.joint_names, on.joint_names);
    app.stop().await;
}

fn own_request(clip: &str) -> pb::SampleRequest {
    pb::SampleRequest { clip_id: clip.to_owned(), time: 0.75, ..Default::default() }
}

/// The refusals of a clip on a character are REST's, with the same codes at
/// `/character`: a character that does not exist, a clip it cannot map; an
/// `ease` is refused with it; `SampleStream` answers as `SampleBatch`.
#[tokio::test]
async fn a_refused_character_is_refused_alike_on_both_wires() {
    let app = TestApp::start().await;
    import_character(&app, "gltf/CesiumMan/CesiumMan.gltf", "cesium").await;
    let tailed = app.create_id(&tail_clip(), None).await;
    let take = import(&app, "bvh/131_01.bvh", None).await;
    let mut grpc = app.grpc().await;
    let when = || Some(pb::sample_batch_request::When::Times(pb::Times { values: vec![0.5] }));
    for (clip, character) in [(&take, "name:nobody"), (&tailed, "name:cesium")] {
        let body = json!({"times": [0.5], "character": character});
        let path = format!("/v1/clips/{clip}/sample");
        let pose = pb::SampleRequest { character: Some(character.into()), ..own_request(clip) };
        refusals(&app, (&path, &body), grpc.sample(pose).await).await;
        let batch = pb::SampleBatchRequest {
            clip_id: clip.clone(),
            when: when(),
            character: Some(character.into()),
            ..Default::default()
        };
        refusals(&app, (&path, &body), grpc.sample_batch(batch).await).await;
    }
    let (status, problem) =
        post(&app, &format!("/v1/clips/{tailed}/sample"), &json!({"times": [0.5], "character": "name:cesium"})).await;
    assert_eq!((status, problem["code"].as_str()), (422, Some("unmappable_skeleton")), "{problem}");
    // `ease` with a character: 400 `unknown_parameter` at `/ease` on both.
    let body = json!({"times": [0.5], "ease": "ease_in", "character": "name:cesium"});
    let (status, problem) = post(&app, &format!("/v1/clips/{take}/sample"), &body).await;
    assert_eq!(
        (status, problem["code"].as_str(), problem["pointer"].as_str()),
        (400, Some("unknown_parameter"), Some("/ease"))
    );
    let pose =
        pb::SampleRequest { ease: pb::Ease::In as i32, character: Some("name:cesium".into()), ..own_request(&take) };
    let status = grpc.sample(pose).await.unwrap_err();
    assert_eq!(
        (status.code(), status.metadata().get("x-error-code").unwrap().to_str().unwrap()),
        (tonic::Code::InvalidArgument, "unknown_parameter")
    );
    assert!(status.message().contains("(at /ease)"), "{}", status.message());
    let stream = pb::SampleBatchRequest {
        clip_id: take.clone(),
        when: when(),
        character: Some("name:cesium".into()),
        ..Default::default()
    };
    let batch = grpc.sample_batch(stream.clone()).await.unwrap().into_inner();
    let mut messages = grpc.sample_stream(stream).await.unwrap().into_inner();
    let streamed = messages.message().await.unwrap().expect("one message");
    assert_eq!(streamed, batch, "SampleStream plays the clip on the character as SampleBatch does");
    app.stop().await;
}
