//! Numbers that cannot be wrong (issue 15): a frame range too long to count
//! is refused, not answered with no poses; clips whose derived values would
//! overflow f32 are refused at upload (REST and gRPC `PutClip`) with a code
//! and the field; and no answer carries `null` for a number.

use formats::wire::proto::pb;
use serde_json::{Value, json};
use tonic::Code;

use super::{TestApp, WAVE};

/// `depth` joints j0 → j1 → …, each offset by 1 and scaled by 1.1.
fn chain(depth: usize) -> Vec<Value> {
    (0..depth)
        .map(|j| {
            let parent = if j == 0 { Value::Null } else { json!(format!("j{}", j - 1)) };
            json!({"name": format!("j{j}"), "parent": parent, "rest": {"translation": [1, 0, 0], "scale": [1.1, 1.1, 1.1]}})
        })
        .collect()
}

/// The attack clips: (what, document, code, JSON pointer prefix).
fn overflowing_clips() -> Vec<(&'static str, Value, &'static str, &'static str)> {
    let joints = chain(1200);
    let track = |joint: &str, times: Value| json!({"joint": joint, "channel": "translation", "interpolation": "linear", "times": times, "values": [[0,0,0],[1,0,0]]});
    vec![
        (
            "a clip spanning ±3.4e38 s",
            json!({"name": "wide", "tracks": [track("a", json!([-3.4e38, 3.4e38]))]}),
            "time_range_too_large",
            "/tracks/0/times",
        ),
        (
            "a 1,200-deep chain of scale 1.1",
            json!({"name": "deep", "skeleton": {"joints": joints}, "tracks": [track("j0", json!([0, 1]))]}),
            "model_space_overflow",
            "/skeleton/joints/",
        ),
        (
            "a Hermite tangent past f32",
            json!({"name": "steep", "tracks": [{"joint": "a", "channel": "translation", "interpolation": "cubic_hermite",
                "times": [0, 100], "values": [[0,0,0],[0,0,0]], "in_tangents": [[0,0,0],[0,0,0]],
                "out_tangents": [[3e38,3e38,3e38],[0,0,0]]}]}),
            "curve_overflow",
            "/tracks/0/values/0",
        ),
    ]
}

#[tokio::test]
async fn overflowing_clips_are_refused_over_rest_and_grpc() {
    let app = TestApp::start().await;
    let mut grpc = app.grpc().await;
    for (what, doc, code, pointer) in overflowing_clips() {
        let resp = app.http.post(app.url("/v1/clips")).json(&doc).send().await.unwrap();
        assert_eq!(resp.status().as_u16(), 422, "{what}");
        let body: Value = resp.json().await.unwrap();
        assert_eq!(body["code"], code, "{what}: {body}");
        assert!(body["pointer"].as_str().unwrap().starts_with(pointer), "{what}: {body}");

        let spec = formats::wire::json::parse_clip(doc.to_string().as_bytes()).unwrap().1;
        let put = pb::PutClipRequest { clip: Some(formats::wire::proto::clip_to_pb(&spec)), ..Default::default() };
        let err = grpc.put_clip(put).await.unwrap_err();
        assert_eq!(err.code(), Code::InvalidArgument, "{what}");
        assert!(err.message().starts_with(code), "{what}: {}", err.message());
        assert!(err.message().contains(&format!("(at {pointer}")), "{what}: {}", err.message());
    }
    assert!(app.list_all(100, None).await.is_empty(), "nothing was stored");
}

#[tokio::test]
async fn a_range_of_1e20_frames_is_too_many_poses() {
    let app = TestApp::start().await;
    let id = app.create_id(WAVE, None).await;
    let resp = app
        .http
        .post(app.url(&format!("/v1/clips/{id}/sample")))
        .json(&json!({"start": 0, "end": 1e20, "fps": 1}))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status().as_u16(), 422);
    assert_eq!(resp.json::<Value>().await.unwrap()["code"], "too_many_poses");

    let mut grpc = app.grpc().await;
    let range = |end: f64| pb::SampleBatchRequest {
        clip_id: id.clone(),
        when: Some(pb::sample_batch_request::When::Range(pb::FrameRange { start: 0.0, end, fps: 1.0 })),
        ..Default::default()
    };
    let err = grpc.sample_batch(range(1e20)).await.unwrap_err();
    assert_eq!(err.code(), Code::InvalidArgument);
    assert!(err.message().starts_with("too_many_poses"), "{}", err.message());
    // Exactly the default limit of 10,000 poses is still answered.
    assert_eq!(grpc.sample_batch(range(9_999.0)).await.unwrap().into_inner().poses.len(), 10_000);
}

/// Whether `v` holds a `null` anywhere.
fn has_null(v: &Value) -> bool {
    match v {
        Value::Null => true,
        Value::Array(a) => a.iter().any(has_null),
        Value::Object(o) => o.values().any(has_null),
        _ => false,
    }
}

#[tokio::test]
async fn poses_and_summaries_near_the_f32_edges_have_no_nulls() {
    let app = TestApp::start().await;
    // Keys 1e-45 s apart, constant speed over times whose arc-length pieces
    // fall at subnormal spacing, a clip half as wide as f32 allows, and a
    // 300-deep scale chain.
    let joints = chain(300);
    let docs = [
        json!({"name": "subnormal", "tracks": [{"joint": "a", "channel": "translation", "interpolation": "linear",
            "speed": "constant", "times": [0, 1e-45, 3e-45, 1], "values": [[0,0,0],[1,0,0],[1,1,0],[0,0,1]]}]}),
        json!({"name": "tiny", "tracks": [{"joint": "a", "channel": "translation", "interpolation": "catmull_rom",
            "speed": "constant", "times": [0, 1e-37, 2e-37, 4e-37],
            "values": [[0,0,0],[1000,5,0],[-900,0,2],[0,0,0]]}]}),
        json!({"name": "wide", "tracks": [{"joint": "a", "channel": "translation", "interpolation": "linear",
            "times": [-1.7e38, 1.7e38], "values": [[0,0,0],[1,0,0]]}]}),
        json!({"name": "deep", "skeleton": {"joints": joints}, "tracks": [{"joint": "j0", "channel": "translation",
            "interpolation": "linear", "times": [0, 1], "values": [[0,0,0],[1,0,0]]}]}),
    ];
    for doc in docs {
        let summary = app.create(&doc.to_string(), None).await;
        assert!(!has_null(&summary), "{summary}");
        assert!(summary["duration"].as_f64().is_some_and(f64::is_finite), "{summary}");
        let id = summary["id"].as_str().unwrap();
        // The keys and the spans right after them (where 0·∞ was NaN).
        let start = summary["start"].as_f64().unwrap();
        let times: Vec<f64> = [0.0, 1e-45, 3e-45].iter().chain(&[1e-39, 1e-37]).map(|dt| start + dt).collect();
        for (space, format) in [("local", "trs"), ("model", "trs"), ("model", "matrix")] {
            let body = json!({"times": times, "space": space, "format": format});
            let poses = app.post_json(&format!("/v1/clips/{id}/sample"), &body).await;
            assert!(!has_null(&poses), "{} {space} {format}", doc["name"]);
        }
    }
}
