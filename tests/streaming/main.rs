//! gRPC and streaming tests: the real `Application` on 127.0.0.1:0 (HTTP
//! and gRPC ports), driven by the generated tonic client, reqwest and a
//! tokio-tungstenite WebSocket client. One binary, one module per concern.
//!
//! Schedules themselves are tested on a paused clock in `src/stream`; these
//! tests run on real time and real sockets, so their timing checks have
//! tolerances, and every wait is bounded so a bug fails rather than hangs.

mod grpc_api;
mod grpc_streams;
mod limits;
mod seam;
mod websocket;

use std::net::SocketAddr;
use std::time::Duration;

use inbetween::server::{Application, Config};
use inbetween::wire::proto::pb;
use inbetween::wire::proto::pb::animation_client::AnimationClient;
use serde_json::Value;
use tempfile::TempDir;
use tonic::transport::Channel;

/// The SPEC §1 example (`examples/wave.json`): 2 joints, clip time [0, 3].
pub const WAVE: &str = include_str!("../../examples/wave.json");

pub struct TestApp {
    pub addr: SocketAddr,
    pub grpc_addr: SocketAddr,
    pub http: reqwest::Client,
    pub _dir: TempDir,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    server: Option<tokio::task::JoinHandle<anyhow::Result<()>>>,
}

impl TestApp {
    pub fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    pub fn ws_url(&self, path: &str) -> String {
        format!("ws://{}{path}", self.addr)
    }

    pub async fn channel(&self) -> Channel {
        Channel::from_shared(format!("http://{}", self.grpc_addr)).unwrap().connect().await.unwrap()
    }

    pub async fn grpc(&self) -> AnimationClient<Channel> {
        AnimationClient::new(self.channel().await)
    }

    /// Uploads a clip document over REST (with `token` if given); returns its id.
    pub async fn create(&self, body: &str, token: Option<&str>) -> String {
        let mut req = self.http.post(self.url("/v1/clips")).header("content-type", "application/json");
        if let Some(t) = token {
            req = req.bearer_auth(t);
        }
        let resp = req.body(body.to_owned()).send().await.unwrap();
        assert_eq!(resp.status(), 201);
        let v: Value = resp.json().await.unwrap();
        v["id"].as_str().unwrap().to_owned()
    }

    /// Stops the server and waits for it to finish.
    pub async fn stop(mut self) {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        if let Some(server) = self.server.take() {
            server.await.unwrap().unwrap();
        }
    }
}

impl Drop for TestApp {
    fn drop(&mut self) {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
    }
}

pub async fn spawn_app() -> TestApp {
    spawn_app_with(|_| {}).await
}

pub async fn spawn_app_with(configure: impl FnOnce(&mut Config)) -> TestApp {
    let dir = tempfile::tempdir().unwrap();
    let mut config = Config::new(SocketAddr::from(([127, 0, 0, 1], 0)), dir.path());
    config.drain_timeout = Duration::from_secs(5);
    configure(&mut config);
    let app = Application::build(config).await.expect("the server builds");
    let (addr, grpc_addr) = (app.local_addr(), app.grpc_addr());
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(app.run_until_stopped(async move {
        let _ = rx.await;
    }));
    TestApp { addr, grpc_addr, http: reqwest::Client::new(), _dir: dir, shutdown: Some(tx), server: Some(server) }
}

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

/// Bounds a wait: a stream that stops delivering fails the test.
pub async fn within<T>(secs: u64, what: &str, f: impl std::future::Future<Output = T>) -> T {
    tokio::time::timeout(Duration::from_secs(secs), f).await.unwrap_or_else(|_| panic!("timed out: {what}"))
}

pub fn assert_close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol, "{what}: {a} vs {b} (tolerance {tol})");
}
