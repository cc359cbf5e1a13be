//! [`TestApp`]: the real `Application` served from this process on
//! 127.0.0.1:0 (HTTP and gRPC), with its own data directory.
//!
//! ```ignore
//! let app = TestApp::builder().write_token("w").configure(|c| c.limits.max_poses = 3).start().await;
//! let id = app.create_id(WAVE, Some("w")).await;
//! let pose: Value = app.get_json(&format!("/v1/clips/{id}/pose?t=1")).await;
//! app.stop().await; // joins the server: fails on its error or panic
//! ```

use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

use formats::wire::proto::pb::animation_client::AnimationClient;
use futures_util::FutureExt;
use serde_json::Value;
use server::auth::Token;
use server::config::Secret;
use server::{AppState, Application, Config};
use tempfile::TempDir;
use tokio::net::TcpStream;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};
use tonic::transport::Channel;

/// A WebSocket client connection, as [`TestApp::ws`] opens it.
pub type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// How long `stop()` waits for the server to drain and return.
const STOP_LIMIT: Duration = Duration::from_secs(30);

/// A server under test. Dropping it signals shutdown without waiting; call
/// [`TestApp::stop`] to also see that the server ended cleanly.
pub struct TestApp {
    /// The HTTP listener (REST, WebSocket, viewer).
    pub addr: SocketAddr,
    pub grpc_addr: SocketAddr,
    pub http: reqwest::Client,
    /// The server's shared state, for checks the network surface cannot see.
    pub state: AppState,
    /// The data directory (SQLite file), removed when the app is dropped.
    pub dir: TempDir,
    shutdown: Option<oneshot::Sender<()>>,
    server: Option<JoinHandle<anyhow::Result<()>>>,
}

/// Configuration of a [`TestApp`] before it starts: the defaults of
/// `Config::new` on 127.0.0.1:0, with a 5 s drain so a stuck stream fails
/// `stop()` quickly rather than after the production 10 s.
pub struct Builder {
    dir: TempDir,
    config: Config,
}

impl Builder {
    /// The data directory the server will use (for files a setting names, e.g. TLS keys).
    pub fn dir(&self) -> &Path {
        self.dir.path()
    }

    /// Any change to the configuration.
    pub fn configure(mut self, f: impl FnOnce(&mut Config)) -> Self {
        f(&mut self.config);
        self
    }

    /// A fixed work capacity, about a release build's on two cores, for
    /// tests about something else than prices: a debug build measures about
    /// 4.7 M units/s, which a page's burst of reads or a matrix's broadcasts
    /// held until they idle out can take (429 `caller_work_limit`, 503
    /// `overloaded`), depending on what else runs.
    pub fn release_capacity(self) -> Self {
        self.configure(|c| c.limits.node_work_per_sec = 80_000_000)
    }

    /// Any change that needs the data directory's path.
    pub fn configure_in(mut self, f: impl FnOnce(&mut Config, &Path)) -> Self {
        f(&mut self.config, self.dir.path());
        self
    }

    /// Keeps the store in `dir`, which outlives the app: a second app on the
    /// same `dir` is the server restarted.
    pub fn data_dir(self, dir: &Path) -> Self {
        let store = server::config::StoreConfig::DataDir(dir.to_owned());
        self.configure(|c| c.store = store)
    }

    /// The legacy single write token (`--api-token`).
    pub fn write_token(self, token: &str) -> Self {
        self.configure(|c| c.write_token = Some(Secret::new(token)))
    }

    /// Named, scoped tokens (`[[tokens]]`).
    pub fn tokens(self, tokens: Vec<Token>) -> Self {
        self.configure(|c| c.tokens = tokens)
    }

    /// Builds the application, binds both ports and serves in a task.
    pub async fn start(self) -> TestApp {
        let Builder { dir, config } = self;
        let app = Application::build(config).await.expect("the server builds");
        let (addr, grpc_addr, state) = (app.local_addr(), app.grpc_addr(), app.state().clone());
        let (tx, rx) = oneshot::channel::<()>();
        let server = tokio::spawn(app.run_until_stopped(async move {
            let _ = rx.await;
        }));
        TestApp {
            addr,
            grpc_addr,
            http: crate::common::http_client(),
            state,
            dir,
            shutdown: Some(tx),
            server: Some(server),
        }
    }
}

impl TestApp {
    pub fn builder() -> Builder {
        let dir = tempfile::tempdir().unwrap();
        let mut config = Config::new(SocketAddr::from(([127, 0, 0, 1], 0)), dir.path());
        config.drain_timeout = Duration::from_secs(5);
        Builder { dir, config }
    }

    /// A server with the default configuration.
    pub async fn start() -> TestApp {
        TestApp::builder().start().await
    }

    /// `http://ADDR{path}`.
    pub fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    /// `ws://ADDR{path}`.
    pub fn ws_url(&self, path: &str) -> String {
        format!("ws://{}{path}", self.addr)
    }

    /// `http://GRPC_ADDR`, the gRPC endpoint.
    pub fn grpc_url(&self) -> String {
        format!("http://{}", self.grpc_addr)
    }

    pub async fn channel(&self) -> Channel {
        Channel::from_shared(self.grpc_url()).unwrap().connect().await.unwrap()
    }

    /// A generated gRPC client on a fresh connection.
    pub async fn grpc(&self) -> AnimationClient<Channel> {
        AnimationClient::new(self.channel().await)
    }

    /// Opens a WebSocket on `path`; fails unless the upgrade answers 101 within 5 s.
    pub async fn ws(&self, path: &str) -> Ws {
        let connect = tokio_tungstenite::connect_async(self.ws_url(path));
        let (ws, resp) = super::within(5, "the WebSocket upgrade", connect).await.unwrap();
        assert_eq!(resp.status(), 101);
        ws
    }

    /// `GET path` without a token, decoded as JSON (panics if the body is not JSON).
    pub async fn get_json(&self, path: &str) -> Value {
        self.http.get(self.url(path)).send().await.unwrap().json().await.unwrap()
    }

    /// `POST path` with a JSON body and no token, the answer decoded as JSON.
    pub async fn post_json(&self, path: &str, body: &Value) -> Value {
        self.http.post(self.url(path)).json(body).send().await.unwrap().json().await.unwrap()
    }

    /// Uploads a JSON clip document (with `token` if given); panics unless
    /// 201. Returns the clip's summary.
    pub async fn create(&self, body: &str, token: Option<&str>) -> Value {
        let mut req = self.http.post(self.url("/v1/clips")).header("content-type", "application/json");
        if let Some(t) = token {
            req = req.bearer_auth(t);
        }
        let resp = req.body(body.to_owned()).send().await.unwrap();
        let status = resp.status();
        let text = resp.text().await.unwrap();
        assert_eq!(status, 201, "create failed: {text}");
        serde_json::from_str(&text).unwrap()
    }

    /// [`TestApp::create`], returning only the new clip's id.
    pub async fn create_id(&self, body: &str, token: Option<&str>) -> String {
        self.create(body, token).await["id"].as_str().unwrap().to_owned()
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
            let mut req = self.http.get(url);
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

    /// Signals shutdown and joins the server: fails the test if it does not
    /// return within 30 s, returned an error, or panicked.
    pub async fn stop(mut self) {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        let server = self.server.take().expect("the server task");
        match tokio::time::timeout(STOP_LIMIT, server).await {
            Err(_) => panic!("the server did not stop within {STOP_LIMIT:?}"),
            Ok(Err(join)) => panic!("the server task failed: {join}"),
            Ok(Ok(Err(e))) => panic!("the server returned an error: {e:#}"),
            Ok(Ok(Ok(()))) => {}
        }
    }
}

impl Drop for TestApp {
    /// Signals shutdown without waiting; a server that already ended on its
    /// own (an error or a panic while the test ran) still fails the test.
    fn drop(&mut self) {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        let Some(server) = self.server.take() else { return };
        if !server.is_finished() || std::thread::panicking() {
            return;
        }
        match server.now_or_never() {
            Some(Err(join)) => panic!("the server task failed during the test: {join}"),
            Some(Ok(Err(e))) => panic!("the server returned an error during the test: {e:#}"),
            _ => {}
        }
    }
}
