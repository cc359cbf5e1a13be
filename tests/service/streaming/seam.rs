//! Time at the clip's seams (docs/clip-format.md §2.7) over REST `/pose`, gRPC `Sample`
//! and a gRPC stream: a request time copied from the clip's own summary is
//! the start (or end) in every playback mode, although neither end is
//! exactly representable, and `loop` maps the end to the start.
//!
//! The clip is a step track on [0.1, 1.3] with x = 1, 2, 3 at 0.1, 0.7,
//! 1.3, and events at both ends, so every expected value is read off the
//! document: the first key's x at the start, the last key's at the end.

use formats::wire::proto::pb;
use serde_json::Value;

use super::{TestApp, within};

const SEAM: &str = r#"{"name": "seam", "playback": "once",
    "tracks": [{"joint": "j", "channel": "translation", "interpolation": "step",
                "times": [0.1, 0.7, 1.3], "values": [[1, 0, 0], [2, 0, 0], [3, 0, 0]]}],
    "events": [{"time": 0.1, "name": "start"}, {"time": 1.3, "name": "end"}]}"#;

/// (name on REST, enum on gRPC, x and clip time at the end: the last key
/// and the end, or in `loop` the first key and the start).
const MODES: [(&str, pb::Playback, f32, &str); 3] = [
    ("once", pb::Playback::Once, 3.0, "end"),
    ("loop", pb::Playback::Loop, 1.0, "start"),
    ("ping_pong", pb::Playback::PingPong, 3.0, "end"),
];

/// Uploads the clip; its id and the summary's `start` and `end` as sent.
async fn upload(app: &TestApp) -> (String, Value) {
    let resp = app.http.post(app.url("/v1/clips")).header("content-type", "application/json").body(SEAM).send();
    let summary: Value = resp.await.unwrap().json().await.unwrap();
    (summary["id"].as_str().unwrap().to_owned(), summary)
}

/// A JSON number as the `f32` the clip keeps.
fn f32_of(v: &Value) -> f32 {
    v.as_f64().unwrap_or_else(|| panic!("a number: {v}")) as f32
}

#[tokio::test]
async fn rest_and_grpc_poses_at_the_summarys_start_and_end_in_every_mode() {
    let app = TestApp::start().await;
    let (id, summary) = upload(&app).await;
    let (start, end) = (summary["start"].as_f64().unwrap(), summary["end"].as_f64().unwrap());
    assert_eq!((start as f32, end as f32), (0.1, 1.3), "the summary: {summary}");
    assert_ne!(start, f64::from(0.1f32), "the request time is not the f32 start exactly");
    let mut grpc = app.grpc().await;
    for (mode, mode_pb, x_end, at_end) in MODES {
        let clip_time_end = if at_end == "start" { 0.1f32 } else { 1.3 };
        // (request time, expected x, expected clip time): the start, the
        // middle key (step switches exactly there), the end.
        for (t, x, clip_time) in [(start, 1.0, 0.1f32), (0.7, 2.0, 0.7), (end, x_end, clip_time_end)] {
            let what = format!("{mode} t={t}");
            let rest = app.http.get(app.url(&format!("/v1/clips/{id}/pose?t={t}&playback={mode}"))).send();
            let rest: Value = rest.await.unwrap().json().await.unwrap();
            assert_eq!(f32_of(&rest["clip_time"]), clip_time, "REST {what}: {rest}");
            assert_eq!(f32_of(&rest["joints"][0]["translation"][0]), x, "REST {what}: {rest}");

            let req =
                pb::SampleRequest { clip_id: id.clone(), time: t, playback: mode_pb as i32, ..Default::default() };
            let pose = grpc.sample(req).await.unwrap().into_inner();
            assert_eq!(pose.clip_time, clip_time, "gRPC {what}");
            assert_eq!(pose.translations[0], x, "gRPC {what}");
        }
    }
    app.stop().await;
}

#[tokio::test]
async fn a_stream_from_the_summarys_start_shows_the_seams_and_their_events() {
    let app = TestApp::start().await;
    let (id, summary) = upload(&app).await;
    let start = summary["start"].as_f64().unwrap();
    let mut grpc = app.grpc().await;
    for (_, mode_pb, x_end, at_end) in MODES {
        // 10 fps at speed 4: request times start + 0.4·k, so frame 3 is at
        // the end (1.3, as a client adding decimals would compute it).
        let req = pb::StreamRequest {
            clip_id: id.clone(),
            fps: 10,
            start_time: Some(start),
            speed: Some(4.0),
            playback: mode_pb as i32,
            max_frames: 4,
            ..Default::default()
        };
        let mut stream = grpc.stream_frames(req).await.unwrap().into_inner();
        let mut frames = Vec::new();
        while let Some(f) = within(5, "frames", stream.message()).await.unwrap() {
            frames.push(f);
        }
        let seen: Vec<(u64, f32, f32, Vec<String>)> = frames
            .iter()
            .map(|f| {
                let events = f.events.iter().map(|e| e.name.clone()).collect();
                (f.seq, f.clip_time, f.pose.as_ref().unwrap().translations[0], events)
            })
            .collect();
        // A loop's jump delivers both ends' events; the start's event is
        // not delivered again by the frame after the first.
        let end_events: Vec<String> =
            if at_end == "start" { vec!["end".into(), "start".into()] } else { vec!["end".into()] };
        let clip_time_end = if at_end == "start" { 0.1f32 } else { 1.3 };
        let expected = vec![
            (0, 0.1f32, 1.0f32, vec!["start".to_owned()]),
            (1, 0.5, 1.0, vec![]),
            (2, 0.9, 2.0, vec![]),
            (3, clip_time_end, x_end, end_events),
        ];
        assert_eq!(seen, expected, "{mode_pb:?}");
    }
    app.stop().await;
}
