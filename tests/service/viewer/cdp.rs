//! A minimal Chrome DevTools Protocol client: starts the system Chromium
//! headless with a fresh profile and drives its first page over the
//! DevTools WebSocket (tokio-tungstenite, already a dependency), so the
//! browser test needs no WebDriver crate and no download.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use base64::Engine as _;
use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tempfile::TempDir;
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

use crate::common::eventually_some;

/// How many times longer than on an idle machine a page may take: software
/// WebGL on 2 cores shared with compilers and the rest of the suite is that
/// slow. A wait ends on what it waits for, so this costs nothing when it comes.
pub const PATIENCE: u64 = 4;

/// Set to `1` (CI does) to fail instead of skipping when Chromium is missing.
pub const REQUIRE_ENV: &str = "INBETWEEN_REQUIRE_BROWSER";

/// The Chromium binary: `$INBETWEEN_CHROMIUM`, else the first of the usual
/// names on `PATH`.
pub fn chromium_path() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os("INBETWEEN_CHROMIUM") {
        return Some(PathBuf::from(path));
    }
    let dirs = std::env::var_os("PATH")?;
    ["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .flat_map(|name| std::env::split_paths(&dirs).map(move |d| d.join(name)))
        .find(|p| p.is_file())
}

/// Browsers run side by side (a read turn each), except one that measures
/// how the page keeps up, which runs alone (the write turn): other
/// Chromiums rendering beside it on a 2-core machine would be what it measured.
static TURNS: tokio::sync::RwLock<()> = tokio::sync::RwLock::const_new(());

/// A browser's turn, held while it runs.
enum Turn {
    Shared(#[allow(dead_code)] tokio::sync::RwLockReadGuard<'static, ()>),
    Alone(#[allow(dead_code)] tokio::sync::RwLockWriteGuard<'static, ()>),
}

/// A headless Chromium and the WebSocket of its page; killed on drop.
pub struct Browser {
    child: Child,
    _profile: TempDir,
    _turn: Turn,
    port: u16,
    pub page: Page,
}

impl Browser {
    /// Starts Chromium, or returns `None` (with a message) when it is not
    /// installed and [`REQUIRE_ENV`] is not set.
    pub async fn launch() -> Option<Browser> {
        if chromium_path().is_none() {
            return Self::start(None).await;
        }
        Self::start(Some(Turn::Shared(TURNS.read().await))).await
    }

    /// As [`Browser::launch`], once no other browser of this suite runs, and none starts until it is dropped.
    pub async fn launch_alone() -> Option<Browser> {
        if chromium_path().is_none() {
            return Self::start(None).await;
        }
        Self::start(Some(Turn::Alone(TURNS.write().await))).await
    }

    async fn start(turn: Option<Turn>) -> Option<Browser> {
        let Some(binary) = chromium_path() else {
            let required = std::env::var(REQUIRE_ENV).is_ok_and(|v| v == "1");
            assert!(!required, "{REQUIRE_ENV}=1 but no Chromium found (install Debian `chromium`)");
            eprintln!("SKIPPED: no Chromium on PATH (apt-get install chromium, or set INBETWEEN_CHROMIUM)");
            return None;
        };
        let profile = tempfile::tempdir().unwrap();
        let child = Command::new(&binary)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                // WebGL2 (the viewer's skinned mesh) in software, where the GPU is off or absent.
                "--enable-unsafe-swiftshader",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--disable-dev-shm-usage",
                "--remote-debugging-address=127.0.0.1",
                "--remote-debugging-port=0",
                "--window-size=1280,860",
                "about:blank",
            ])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("starting {}: {e}", binary.display()));
        let mut browser = BrowserGuard(Some(child));
        let port = devtools_port(profile.path()).await;
        let page_url = page_websocket(port).await;
        let page = Page::connect(&page_url).await;
        let _turn = turn.expect("a turn whenever Chromium is found");
        Some(Browser { child: browser.0.take().unwrap(), _profile: profile, _turn, port, page })
    }

    /// Another tab of this browser (its own `sessionStorage`).
    pub async fn new_page(&mut self) -> Page {
        let target: Value = reqwest::Client::new()
            .put(format!("http://127.0.0.1:{}/json/new?about:blank", self.port))
            .send()
            .await
            .expect("DevTools /json/new")
            .json()
            .await
            .unwrap();
        Page::connect(target["webSocketDebuggerUrl"].as_str().expect("a new tab's DevTools URL")).await
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Kills a half-started Chromium if setup panics.
struct BrowserGuard(Option<Child>);

impl Drop for BrowserGuard {
    fn drop(&mut self) {
        if let Some(child) = &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Chromium writes its DevTools port into the profile once it listens.
async fn devtools_port(profile: &Path) -> u16 {
    let file = profile.join("DevToolsActivePort");
    eventually_some(Duration::from_secs(30), "Chromium opened its DevTools port", || async {
        std::fs::read_to_string(&file).ok().and_then(|t| t.lines().next()?.parse().ok())
    })
    .await
}

async fn page_websocket(port: u16) -> String {
    eventually_some(Duration::from_secs(10), "Chromium has a page target", || async {
        let targets: Value = reqwest::get(format!("http://127.0.0.1:{port}/json/list"))
            .await
            .expect("DevTools /json/list")
            .json()
            .await
            .unwrap();
        let page = targets.as_array().into_iter().flatten().find(|t| t["type"] == "page");
        page.and_then(|p| p["webSocketDebuggerUrl"].as_str()).map(str::to_owned)
    })
    .await
}

/// One page, driven by commands; events are read and ignored.
pub struct Page {
    ws: WebSocketStream<MaybeTlsStream<TcpStream>>,
    next_id: u64,
}

impl Page {
    async fn connect(url: &str) -> Page {
        let (ws, _) = tokio_tungstenite::connect_async(url).await.expect("DevTools WebSocket");
        let mut page = Page { ws, next_id: 0 };
        page.set_viewport(1280, 860).await;
        page
    }

    /// Presses the left button at `from`, moves to `to` in `steps` moves and
    /// releases it (CSS pixels of the viewport), as a user's drag would.
    pub async fn drag(&mut self, from: [f64; 2], to: [f64; 2], steps: u32) {
        let mouse = |kind: &str, [x, y]: [f64; 2], buttons: u32| json!({"type": kind, "x": x, "y": y, "button": "left", "buttons": buttons, "clickCount": 1});
        self.call("Input.dispatchMouseEvent", mouse("mouseMoved", from, 0)).await;
        self.call("Input.dispatchMouseEvent", mouse("mousePressed", from, 1)).await;
        for i in 1..=steps {
            let k = f64::from(i) / f64::from(steps);
            let at = [from[0] + k * (to[0] - from[0]), from[1] + k * (to[1] - from[1])];
            self.call("Input.dispatchMouseEvent", mouse("mouseMoved", at, 1)).await;
            // The time is the behaviour here: a drag paced as a hand moves.
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        self.call("Input.dispatchMouseEvent", mouse("mouseReleased", to, 0)).await;
    }

    /// Sends a command and waits (at most 30 s) for its result.
    pub async fn call(&mut self, method: &str, params: Value) -> Value {
        self.next_id += 1;
        let id = self.next_id;
        let command = json!({"id": id, "method": method, "params": params}).to_string();
        self.ws.send(Message::text(command)).await.expect("sending a DevTools command");
        let wait = async {
            while let Some(message) = self.ws.next().await {
                let Ok(Message::Text(text)) = message else { continue };
                let reply: Value = serde_json::from_str(&text).unwrap();
                if reply["id"] == id {
                    assert!(reply.get("error").is_none(), "{method} failed: {}", reply["error"]);
                    return reply["result"].clone();
                }
            }
            panic!("the DevTools connection closed during {method}");
        };
        tokio::time::timeout(Duration::from_secs(30), wait).await.unwrap_or_else(|_| panic!("{method} timed out"))
    }

    /// Evaluates `expression` in the page (awaiting a promise) and returns
    /// its value as JSON; a thrown exception fails the test.
    pub async fn eval(&mut self, expression: &str) -> Value {
        let result = self
            .call("Runtime.evaluate", json!({"expression": expression, "awaitPromise": true, "returnByValue": true}))
            .await;
        if let Some(details) = result.get("exceptionDetails") {
            panic!("`{expression}` threw: {}", details["exception"]["description"].as_str().unwrap_or_default());
        }
        result["result"]["value"].clone()
    }

    /// Polls `expression` until it is truthy; returns its value. `secs` is
    /// what a page on an idle machine needs, stretched by [`PATIENCE`].
    pub async fn wait_for(&mut self, expression: &str, secs: u64) -> Value {
        let deadline = Instant::now() + Duration::from_secs(secs * PATIENCE);
        loop {
            let value = self.eval(expression).await;
            let truthy = match &value {
                Value::Null => false,
                Value::Bool(b) => *b,
                Value::Number(n) => n.as_f64() != Some(0.0),
                Value::String(s) => !s.is_empty(),
                _ => true,
            };
            if truthy {
                return value;
            }
            if Instant::now() > deadline {
                let status = self.eval("document.getElementById('status')?.textContent").await;
                panic!("timed out after {secs} s waiting for `{expression}` (page status: {status})");
            }
            // The page's own `eventually` (it reports the page status on failure).
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// Emulates a screen of `width`×`height` CSS pixels (scale 1).
    pub async fn set_viewport(&mut self, width: u32, height: u32) {
        let metrics = json!({"width": width, "height": height, "deviceScaleFactor": 1, "mobile": false});
        self.call("Emulation.setDeviceMetricsOverride", metrics).await;
    }

    pub async fn navigate(&mut self, url: &str) {
        self.call("Page.navigate", json!({"url": url})).await;
        self.wait_for(&format!("location.href === {} && document.readyState === 'complete'", json!(url)), 20).await;
    }

    /// Puts files into an `<input type=file>` as a user's pick would (fires `change`).
    pub async fn set_files(&mut self, selector: &str, files: &[&Path]) {
        let root = self.call("DOM.getDocument", json!({"depth": 0})).await;
        let node =
            self.call("DOM.querySelector", json!({"nodeId": root["root"]["nodeId"], "selector": selector})).await;
        let files: Vec<String> = files.iter().map(|p| p.display().to_string()).collect();
        self.call("DOM.setFileInputFiles", json!({"files": files, "nodeId": node["nodeId"]})).await;
    }

    /// A PNG of the page, or of the CSS-pixel rectangle `clip`.
    /// Saves the whole page, drawn at `scale`, to the file the environment
    /// variable `var` names, after `settle`: the docs' pictures are retaken
    /// by the tests that reach the state they show. Nothing is checked.
    pub async fn picture(&mut self, var: &str, settle: Duration, scale: f64) {
        let Some(path) = std::env::var_os(var) else { return };
        tokio::time::sleep(settle).await;
        let size = self.eval("[window.innerWidth, window.innerHeight]").await;
        let [width, height]: [f64; 2] = serde_json::from_value(size).unwrap();
        let clip = json!({"x": 0, "y": 0, "width": width, "height": height, "scale": scale});
        let shot = self.call("Page.captureScreenshot", json!({"format": "png", "clip": clip})).await;
        let png = base64::engine::general_purpose::STANDARD.decode(shot["data"].as_str().unwrap()).unwrap();
        std::fs::write(&path, png).unwrap();
        eprintln!("{var}: the page written to {}", path.to_string_lossy());
    }

    pub async fn screenshot(&mut self, clip: Option<[f64; 4]>) -> Vec<u8> {
        let mut params = json!({"format": "png"});
        if let Some([x, y, width, height]) = clip {
            params["clip"] = json!({"x": x, "y": y, "width": width, "height": height, "scale": 1});
        }
        let shot = self.call("Page.captureScreenshot", params).await;
        base64::engine::general_purpose::STANDARD.decode(shot["data"].as_str().unwrap()).unwrap()
    }
}
