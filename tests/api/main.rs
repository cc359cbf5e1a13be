//! REST API tests: the real `Application` on 127.0.0.1:0 with its own SQLite
//! file, driven by a real HTTP client (reqwest). One binary for the whole
//! area, one module per concern.

mod bad_inputs;
mod cache;
mod cli;
mod clips;
mod concurrency;
mod durability;
mod import;
mod operations;
mod poses;
mod security;
mod strict;

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::process::{Child, Command, Stdio};

use inbetween::server::{Application, Config};
use serde_json::Value;
use tempfile::TempDir;

/// The SPEC §1 example, as shipped in `examples/wave.json`.
pub const WAVE: &str = include_str!("../../examples/wave.json");

pub struct TestApp {
    pub addr: SocketAddr,
    pub client: reqwest::Client,
    pub dir: TempDir,
    /// The server's shared state, for checks the HTTP surface cannot see.
    pub state: inbetween::server::AppState,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    server: Option<tokio::task::JoinHandle<anyhow::Result<()>>>,
}

impl TestApp {
    pub fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    /// `GET path` without a token, decoded as JSON (panics if the body is not JSON).
    pub async fn get_json(&self, path: &str) -> Value {
        self.client.get(self.url(path)).send().await.unwrap().json().await.unwrap()
    }

    /// Uploads `body` (with `token` if given); panics unless 201. Returns the summary.
    pub async fn create(&self, body: &str, token: Option<&str>) -> Value {
        let mut req = self.client.post(self.url("/v1/clips")).header("content-type", "application/json");
        if let Some(t) = token {
            req = req.bearer_auth(t);
        }
        let resp = req.body(body.to_owned()).send().await.unwrap();
        let status = resp.status();
        let text = resp.text().await.unwrap();
        assert_eq!(status, 201, "create failed: {text}");
        serde_json::from_str(&text).unwrap()
    }

    /// Every clip summary, walking all pages of `page` clips.
    pub async fn list_all(&self, page: u32, token: Option<&str>) -> Vec<Value> {
        let mut all = Vec::new();
        let mut cursor: Option<String> = None;
        loop {
            let mut url = self.url(&format!("/v1/clips?limit={page}"));
            if let Some(c) = &cursor {
                url.push_str(&format!("&cursor={c}"));
            }
            let mut req = self.client.get(url);
            if let Some(t) = token {
                req = req.bearer_auth(t);
            }
            let body: Value = req.send().await.unwrap().json().await.unwrap();
            all.extend(body["clips"].as_array().unwrap().iter().cloned());
            match body["next_cursor"].as_str() {
                Some(c) => cursor = Some(c.to_owned()),
                None => return all,
            }
        }
    }

    /// Stops the server and waits for it to finish draining.
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

/// Starts a server on 127.0.0.1:0 with a fresh data directory, after
/// `configure` adjusted the defaults.
pub async fn spawn_app_with(configure: impl FnOnce(&mut Config)) -> TestApp {
    let dir = tempfile::tempdir().unwrap();
    let mut config = Config::new(SocketAddr::from(([127, 0, 0, 1], 0)), dir.path());
    configure(&mut config);
    let app = Application::build(config).await.expect("the server builds");
    let addr = app.local_addr();
    let state = app.state().clone();
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(app.run_until_stopped(async move {
        let _ = rx.await;
    }));
    TestApp { addr, client: reqwest::Client::new(), dir, state, shutdown: Some(tx), server: Some(server) }
}

/// The canonical form the server stores for a document: parsed, re-serialised.
pub fn canonical(doc: &str) -> String {
    let parsed = inbetween::wire::json::parse_clip_doc(doc.as_bytes()).unwrap();
    serde_json::to_string(&parsed).unwrap()
}

/// A clip with `joints` root joints, each with a linear translation track of
/// `keys` keys whose every value is `[k, k, k]`, named `name`.
pub fn uniform_clip(name: &str, joints: usize, keys: usize, k: f32) -> String {
    let times: Vec<f32> = (0..keys).map(|i| i as f32).collect();
    let tracks: Vec<Value> = (0..joints)
        .map(|j| {
            serde_json::json!({
                "joint": format!("j{j}"), "channel": "translation", "interpolation": "linear",
                "times": times, "values": vec![[k, k, k]; keys],
            })
        })
        .collect();
    serde_json::json!({"name": name, "tracks": tracks}).to_string()
}

pub fn assert_close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol, "{what}: {a} vs {b} (tolerance {tol})");
}

/// The real `inbetween` binary, serving.
pub struct Binary {
    pub child: Child,
    /// `http://127.0.0.1:PORT`, from the line it prints on startup.
    pub base: String,
}

/// Spawns the binary with the arguments `configure` adds (no `INBETWEEN_*`
/// variables leak in from the caller; logs at `warn` to stderr, discarded
/// unless `configure` redirects them) and waits for its listening line.
pub fn spawn_binary(configure: impl FnOnce(&mut Command)) -> Binary {
    let mut command = Command::new(env!("CARGO_BIN_EXE_inbetween"));
    for (name, _) in std::env::vars().filter(|(n, _)| n.starts_with("INBETWEEN_")) {
        command.env_remove(name);
    }
    command.env("INBETWEEN_LOG", "warn").stdout(Stdio::piped()).stderr(Stdio::null());
    // The gRPC port too must not collide between tests running in parallel.
    command.env("INBETWEEN_GRPC_LISTEN", "127.0.0.1:0");
    configure(&mut command);
    let mut child = command.spawn().expect("the binary starts");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
    let base =
        line.trim().strip_prefix("inbetween listening on ").unwrap_or_else(|| panic!("unexpected first line {line:?}"));
    Binary { base: base.to_owned(), child }
}
