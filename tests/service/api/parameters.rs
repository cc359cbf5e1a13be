//! Parameters (docs/clip-format.md §3) end to end with real clients: `examples/face.json`
//! uploaded and sampled over REST, gRPC and the WebSocket; the `parameters`
//! filter and its refusal; upload refusals with pointers; a glTF with morph
//! targets built here (LINEAR, STEP and CUBICSPLINE weights) imported and
//! sampled against weights worked out by hand.
//!
//! Expected values come from docs/clip-format.md §2 by hand: `face_mesh` is linear between
//! `[0, 0]` at 0 and `[1, 0.1]` at 0.1; `camera_fov` is Catmull-Rom through
//! 45, 35, 45 at 0, 1, 2 with reflect ends, evaluated here in f64.

use base64::Engine as _;
use formats::wire::proto::pb;
use futures_util::StreamExt;
use prost::Message as _;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::{TestApp, within};

const FACE: &str = include_str!("../../../examples/face.json");

/// `camera_fov` at `t` in [0, 1]: segment 0 of docs/clip-format.md §2.2 with the reflect
/// phantom `c₋₁ = 2·45 − 35 = 55` at `t₋₁ = −1` (unit spacing, k = ½).
fn fov(t: f64) -> f64 {
    let (c0, c1, c2, cm) = (45.0, 35.0, 45.0, 55.0);
    let (d, e) = (c0 + (c1 - cm) / 6.0, c1 - (c2 - c0) / 6.0);
    let v = 1.0 - t;
    v * v * v * c0 + 3.0 * t * v * v * d + 3.0 * t * t * v * e + t * t * t * c1
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap_or_else(|| panic!("not an array: {v}")).iter().map(|x| x.as_f64().unwrap()).collect()
}

fn close(got: &[f64], expected: &[f64], what: &str) {
    assert_eq!(got.len(), expected.len(), "{what}: {got:?}");
    for (g, e) in got.iter().zip(expected) {
        assert!((g - e).abs() <= 1e-5 * e.abs().max(1.0), "{what}: got {got:?}, expected {expected:?}");
    }
}

async fn get(app: &TestApp, path: &str) -> (u16, Value) {
    let resp = app.http.get(app.url(path)).send().await.unwrap();
    (resp.status().as_u16(), resp.json().await.unwrap())
}

async fn post(app: &TestApp, path: &str, body: &Value) -> (u16, Value) {
    let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
    (resp.status().as_u16(), resp.json().await.unwrap())
}

#[tokio::test]
async fn poses_and_samples_carry_parameters_and_the_filter_picks_them() {
    let app = TestApp::start().await;
    let id = app.create_id(FACE, None).await;
    let (status, pose) = get(&app, &format!("/v1/clips/{id}/pose?t=0.05")).await;
    assert_eq!(status, 200, "{pose}");
    close(&floats(&pose["parameters"]["face_mesh"]), &[0.5, 0.05], "face_mesh at 0.05");
    close(&floats(&pose["parameters"]["camera_fov"]), &[fov(0.05)], "camera_fov at 0.05");
    // Model space and matrices carry them too.
    let (_, model) = get(&app, &format!("/v1/clips/{id}/pose?t=0.5&format=matrix")).await;
    close(&floats(&model["parameters"]["camera_fov"]), &[fov(0.5)], "with matrices");

    // The filter: only the names asked for; an unknown one is 422.
    let (_, only) = get(&app, &format!("/v1/clips/{id}/pose?t=0.5&parameters=camera_fov")).await;
    assert_eq!(only["parameters"].as_object().unwrap().len(), 1, "{only}");
    close(&floats(&only["parameters"]["camera_fov"]), &[fov(0.5)], "filtered");
    let (status, problem) = get(&app, &format!("/v1/clips/{id}/pose?t=0.5&parameters=camera_fov,nose")).await;
    assert_eq!((status, problem["code"].as_str()), (422, Some("unknown_parameter")), "{problem}");
    assert_eq!(problem["parameter"], "parameters", "{problem}");

    let body = json!({"times": [0.05, 1.0], "parameters": ["face_mesh"]});
    let (status, samples) = post(&app, &format!("/v1/clips/{id}/sample"), &body).await;
    assert_eq!(status, 200, "{samples}");
    let poses = samples["poses"].as_array().unwrap();
    close(&floats(&poses[1]["parameters"]["face_mesh"]), &[0.0, 1.0], "face_mesh at 1");
    assert!(poses[1]["parameters"].get("camera_fov").is_none(), "filtered out");
    let body = json!({"times": [0.5], "parameters": ["face_mesh", "ears"]});
    let (status, problem) = post(&app, &format!("/v1/clips/{id}/sample"), &body).await;
    assert_eq!(
        (status, &problem["code"], &problem["pointer"]),
        (422, &json!("unknown_parameter"), &json!("/parameters/1"))
    );

    // A motion: the first layer's parameters, blended by weight from 0.
    let motion = json!({"layers": [{"clip": id, "weight": 0.5}]});
    let body = json!({"motion": motion, "time": 1.0, "parameters": ["camera_fov"]});
    let (status, pose) = post(&app, "/v1/poses", &body).await;
    assert_eq!(status, 200, "{pose}");
    close(&floats(&pose["parameters"]["camera_fov"]), &[17.5], "half of 35 over a rest of 0");

    // The stored document and the skeleton route name them.
    let (_, doc) = get(&app, &format!("/v1/clips/{id}")).await;
    assert_eq!(doc["parameters"][0]["name"], "face_mesh");
    let (_, skeleton) = get(&app, &format!("/v1/clips/{id}/skeleton")).await;
    assert_eq!(skeleton["parameters"], json!(["face_mesh", "camera_fov"]));
    app.stop().await;
}

#[tokio::test]
async fn uploads_with_broken_parameters_are_refused_with_pointers() {
    let app = TestApp::start().await;
    let clip = |parameters: Value| json!({"name": "p", "tracks": [], "parameters": parameters});
    let cases = [
        (json!([{"name": "a", "times": [0, 1], "values": [[0, 1], [0]]}]), "wrong_width", "/parameters/0/values/1"),
        (json!([{"name": "a", "times": [0, 1], "values": [[], []]}]), "parameter_width", "/parameters/0/values/0"),
        (
            json!([{"name": "a", "times": [0], "values": [[0]]}, {"name": "a", "times": [0], "values": [[1]]}]),
            "duplicate_parameter",
            "/parameters/1/name",
        ),
        (
            json!([{"name": "a", "times": [1, 0], "values": [[0], [1]]}]),
            "times_not_increasing",
            "/parameters/0/times/1",
        ),
        (
            json!([{"name": "a", "times": [0], "values": [[0]], "speed": "constant"}]),
            "invalid_field",
            "/parameters/0/speed",
        ),
    ];
    for (parameters, code, pointer) in cases {
        let (status, problem) = post(&app, "/v1/clips", &clip(parameters.clone())).await;
        assert_eq!(
            (status, problem["code"].as_str(), problem["pointer"].as_str()),
            (422, Some(code), Some(pointer)),
            "{parameters}: {problem}"
        );
    }
    // A clip of parameters alone is a clip.
    let (status, created) =
        post(&app, "/v1/clips", &clip(json!([{"name": "fov", "times": [0, 2], "values": [[40], [60]]}]))).await;
    assert_eq!(status, 201, "{created}");
    assert_eq!((created["start"].as_f64(), created["end"].as_f64()), (Some(0.0), Some(2.0)));
    app.stop().await;
}

#[tokio::test]
async fn grpc_clips_poses_and_motions_carry_parameters() {
    let app = TestApp::start().await;
    let mut grpc = app.grpc().await;
    let doc = formats::wire::json::parse_clip_doc(FACE.as_bytes()).unwrap();
    let spec = formats::wire::json::parse_clip(FACE.as_bytes()).unwrap().1;
    let clip = formats::wire::proto::clip_to_pb(&spec);
    assert_eq!(clip.parameters[0].width, 2, "the proto clip carries the tracks");
    let put = pb::PutClipRequest { clip: Some(clip), ..Default::default() };
    let id = grpc.put_clip(put).await.unwrap().into_inner().id;
    let record = grpc.get_clip(pb::GetClipRequest { clip_id: id.clone() }).await.unwrap().into_inner();
    assert_eq!(record.clip.unwrap().parameters.len(), doc.parameters.len());

    let req = pb::SampleRequest { clip_id: id.clone(), time: 0.05, ..Default::default() };
    let pose = grpc.sample(req).await.unwrap().into_inner();
    assert_eq!(
        (pose.parameter_names.as_slice(), pose.parameter_widths.as_slice()),
        (&["face_mesh".to_owned(), "camera_fov".to_owned()][..], &[2, 1][..])
    );
    let values: Vec<f64> = pose.parameters.iter().map(|&x| f64::from(x)).collect();
    close(&values, &[0.5, 0.05, fov(0.05)], "packed parameters");

    let batch = pb::SampleBatchRequest {
        clip_id: id.clone(),
        when: Some(pb::sample_batch_request::When::Times(pb::Times { values: vec![0.5, 1.0] })),
        ..Default::default()
    };
    let batch = grpc.sample_batch(batch).await.unwrap().into_inner();
    assert_eq!(batch.parameter_widths, [2, 1]);
    assert!(batch.poses[1].parameter_names.is_empty(), "names once per batch");
    close(&[f64::from(batch.poses[1].parameters[2])], &[35.0], "camera_fov at its key");

    let layer = pb::Layer { clip_id: id.clone(), ..Default::default() };
    let motion = Some(pb::Motion { layers: vec![layer], ..Default::default() });
    let req = pb::SampleMotionRequest {
        motion: motion.clone(),
        time: 0.5,
        parameters: vec!["camera_fov".into()],
        ..Default::default()
    };
    let pose = grpc.sample_motion(req).await.unwrap().into_inner();
    assert_eq!(pose.parameter_names, ["camera_fov"]);
    close(&[f64::from(pose.parameters[0])], &[fov(0.5)], "filtered motion pose");
    let req = pb::SampleMotionRequest { motion, time: 0.5, parameters: vec!["nose".into()], ..Default::default() };
    let status = grpc.sample_motion(req).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    assert!(status.message().contains("nose"), "{}", status.message());

    // A stream: names and widths in the first frame only, values in every one.
    let id2 = id.clone();
    let req = pb::StreamRequest { clip_id: id, fps: 60, max_frames: 2, start_time: Some(0.5), ..Default::default() };
    let mut frames = grpc.stream_frames(req).await.unwrap().into_inner();
    let first = within(5, "a frame", frames.next()).await.unwrap().unwrap().pose.unwrap();
    assert_eq!(first.parameter_widths, [2, 1]);
    close(&[f64::from(first.parameters[2])], &[fov(0.5)], "first frame");
    let second = within(5, "a frame", frames.next()).await.unwrap().unwrap().pose.unwrap();
    assert!(second.parameter_names.is_empty() && second.parameters.len() == 3);
    let req = pb::StreamRequest { clip_id: id2, fps: 60, parameters: vec!["nose".into()], ..Default::default() };
    let status = grpc.stream_frames(req).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    app.stop().await;
}

#[tokio::test]
async fn websocket_frames_carry_parameters_in_json_and_protobuf() {
    let app = TestApp::start().await;
    let id = app.create_id(FACE, None).await;
    let mut ws = app.ws(&format!("/v1/clips/{id}/stream?fps=60&max_frames=2&start=0.05&parameters=face_mesh")).await;
    let frame = loop {
        if let Message::Text(t) = within(5, "a frame", ws.next()).await.unwrap().unwrap() {
            let v: Value = serde_json::from_str(&t).unwrap();
            if v.get("seq").is_some() {
                break v;
            }
        }
    };
    let parameters = frame["pose"]["parameters"].as_object().unwrap();
    assert_eq!(parameters.len(), 1, "{frame}");
    close(&floats(&parameters["face_mesh"]), &[0.5, 0.05], "the first frame's face_mesh");

    let mut ws = app.ws(&format!("/v1/clips/{id}/stream?fps=60&max_frames=1&start=1&encoding=protobuf")).await;
    let frame = loop {
        if let Message::Binary(b) = within(5, "a frame", ws.next()).await.unwrap().unwrap() {
            break pb::Frame::decode(b).unwrap();
        }
    };
    let pose = frame.pose.unwrap();
    assert_eq!(pose.parameter_names, ["face_mesh", "camera_fov"]);
    close(&pose.parameters.iter().map(|&x| f64::from(x)).collect::<Vec<_>>(), &[0.0, 1.0, 35.0], "at t = 1");

    let refused = tokio_tungstenite::connect_async(app.ws_url(&format!("/v1/clips/{id}/stream?parameters=nose"))).await;
    match refused {
        Err(tokio_tungstenite::tungstenite::Error::Http(resp)) => {
            assert_eq!(resp.status(), 422);
            let body = String::from_utf8(resp.body().clone().unwrap_or_default()).unwrap();
            assert!(body.contains("unknown_parameter"), "{body}");
        }
        other => panic!("an unknown parameter must be refused before the upgrade: {other:?}"),
    }
    app.stop().await;
}

/// A glTF (JSON, buffer as a `data:` URI) with one mesh node of two morph
/// targets and three animations of its weights: LINEAR, STEP and
/// CUBICSPLINE, keys at 0, 1, 2.
fn morph_gltf() -> Vec<u8> {
    let times = [0.0f32, 1.0, 2.0];
    let linear = [0.0f32, 1.0, 1.0, 0.5, 0.25, 0.0];
    // Per key: in-tangent (2), value (2), out-tangent (2).
    let cubic = [
        0.0f32, 0.0, 0.0, 1.0, 1.0, 0.0, //
        0.5, -1.0, 1.0, 0.0, 0.0, 0.0, //
        0.0, 0.0, 0.0, 0.5, 0.0, 0.0,
    ];
    let mut bytes: Vec<u8> = Vec::new();
    for x in times.iter().chain(&linear).chain(&cubic) {
        bytes.extend_from_slice(&x.to_le_bytes());
    }
    let uri =
        format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&bytes));
    let view = |offset: usize, len: usize| json!({"buffer": 0, "byteOffset": offset * 4, "byteLength": len * 4});
    let scalar = |view: usize, count: usize| json!({"bufferView": view, "componentType": 5126, "count": count, "type": "SCALAR"});
    let anim = |name: &str, interpolation: &str, output: usize| {
        json!({"name": name, "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
               "samplers": [{"input": 0, "output": output, "interpolation": interpolation}]})
    };
    let doc = json!({
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "face", "mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 4}, "targets": [{"POSITION": 4}, {"POSITION": 4}]}], "weights": [0, 0]}],
        "buffers": [{"byteLength": bytes.len(), "uri": uri}],
        "bufferViews": [view(0, 3), view(3, 6), view(9, 18)],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "SCALAR", "min": [0.0], "max": [2.0]},
            scalar(1, 6), scalar(2, 18), scalar(1, 6),
            {"bufferView": 0, "componentType": 5126, "count": 1, "type": "VEC3", "min": [0, 0, 0], "max": [0, 0, 0]}
        ],
        "animations": [anim("linear", "LINEAR", 1), anim("step", "STEP", 3), anim("cubic", "CUBICSPLINE", 2)],
    });
    serde_json::to_vec(&doc).unwrap()
}

#[tokio::test]
async fn gltf_morph_weights_import_as_a_parameter_per_node() {
    let app = TestApp::start().await;
    let resp =
        app.http.post(app.url("/v1/clips/import?format=gltf&playback=once")).body(morph_gltf()).send().await.unwrap();
    let status = resp.status().as_u16();
    let body: Value = resp.json().await.unwrap();
    assert_eq!(status, 201, "{body}");
    let ids: Vec<(String, String)> = (body["clips"].as_array().unwrap().iter())
        .map(|c| (c["name"].as_str().unwrap().to_owned(), c["id"].as_str().unwrap().to_owned()))
        .collect();
    assert_eq!(ids.len(), 3, "{body}");
    assert_eq!(body["warnings"], serde_json::json!([]), "morph weights are imported, nothing left out: {body}");
    let weights = |pose: &Value| floats(&pose["parameters"]["face"]);
    let id = |name: &str| ids.iter().find(|(n, _)| n.ends_with(name)).unwrap().1.clone();
    // LINEAR: [0, 1] → [1, 0.5] → [0.25, 0]; at 0.5 and 1.5.
    let (_, pose) = get(&app, &format!("/v1/clips/{}/pose?t=0.5", id("linear"))).await;
    close(&weights(&pose), &[0.5, 0.75], "linear at 0.5");
    let (_, pose) = get(&app, &format!("/v1/clips/{}/pose?t=1.5", id("linear"))).await;
    close(&weights(&pose), &[0.625, 0.25], "linear at 1.5");
    // STEP holds the key.
    let (_, pose) = get(&app, &format!("/v1/clips/{}/pose?t=0.99", id("step"))).await;
    close(&weights(&pose), &[0.0, 1.0], "step");
    // CUBICSPLINE, h = 1, u = ½: ½·v₀ + ⅛·b₀ + ½·v₁ − ⅛·a₁.
    // x: ½·0 + ⅛·1 + ½·1 − ⅛·0.5 = 0.5625; y: ½·1 + 0 + 0 − ⅛·(−1) = 0.625.
    let (_, pose) = get(&app, &format!("/v1/clips/{}/pose?t=0.5", id("cubic"))).await;
    close(&weights(&pose), &[0.5625, 0.625], "cubicspline at 0.5");
    let (_, pose) = get(&app, &format!("/v1/clips/{}/pose?t=2", id("cubic"))).await;
    close(&weights(&pose), &[0.0, 0.5], "cubicspline at its last key");
    app.stop().await;
}
