//! gRPC and streaming tests: the real `Application` on 127.0.0.1:0 (HTTP
//! and gRPC ports), driven by the generated tonic client, reqwest and a
//! tokio-tungstenite WebSocket client. One module per concern.
//!
//! Schedules themselves are tested on a paused clock in `src/stream`; these
//! tests run on real time and real sockets, so their timing checks have
//! tolerances, and every wait is bounded so a bug fails rather than hangs.

mod broadcast_budgets;
mod broadcasts;
mod compact;
mod control_budget;
mod graphs;
mod grpc_api;
mod grpc_ik;
mod grpc_streams;
mod ik;
mod limits;
mod motions;
mod priced_controls;
mod seam;
mod springs;
mod websocket;

use formats::wire::proto::pb;
use serde_json::Value;

pub use crate::common::{TestApp, WAVE, assert_close, within};

/// A clip of `joints` root joints, each translating along x from 0 to 10
/// over clip time [0, 10] (so x equals the clip time), playback `once`.
pub fn line_clip(joints: usize) -> String {
    let tracks: Vec<Value> = (0..joints)
        .map(|j| {
            serde_json::json!({"joint": format!("j{j}"), "channel": "translation", "interpolation": "linear",
                "times": [0.0, 10.0], "values": [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]]})
        })
        .collect();
    serde_json::json!({"name": "line", "tracks": tracks, "events": [{"time": 1.0, "name": "one"}]}).to_string()
}

pub fn stream_request(clip_id: &str, fps: u32, speed: f64) -> pb::StreamRequest {
    pb::StreamRequest {
        clip_id: clip_id.to_owned(),
        fps,
        start_time: Some(0.0),
        speed: Some(speed),
        ..Default::default()
    }
}
