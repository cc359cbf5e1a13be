//! [`ServerProcess`]: the real `inbetween` binary serving on free ports.
//!
//! ```ignore
//! let dir = tempfile::tempdir().unwrap();
//! let mut server = ServerProcess::serve().data_dir(dir.path()).args(["--drain-timeout-secs", "3"]).start().await;
//! server.signal("TERM");
//! assert!(server.wait_exit(Duration::from_secs(5)).await.unwrap().success());
//! ```

use std::ffi::OsStr;
use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// How long a started server may take to answer `/readyz` with 200.
const READY_LIMIT: Duration = Duration::from_secs(10);

/// A running `inbetween serve`, killed (SIGKILL) when dropped.
pub struct ServerProcess {
    pub child: Child,
    /// Names the process in failure messages (`node-a`).
    pub name: String,
    pub http: SocketAddr,
    pub grpc: SocketAddr,
    /// Where its stderr (the logs) went.
    pub log: PathBuf,
    /// How long from spawn until `/readyz` answered 200.
    pub ready_after: Duration,
    /// Holds the log file when the test did not choose one.
    _log_dir: Option<tempfile::TempDir>,
    /// Its place among the binary's servers (see [`ProcessBuilder::alone`]).
    _slot: Slot,
}

/// The servers the test binary runs now, and whether one of them runs alone.
struct Machine {
    live: usize,
    alone: bool,
}

static MACHINE: std::sync::Mutex<Machine> = std::sync::Mutex::new(Machine { live: 0, alone: false });

/// A server's place on the machine, given back when dropped (also when a
/// start fails).
struct Slot {
    alone: bool,
}

impl Slot {
    /// Waits until this binary may start a server: an `alone` one when no
    /// other runs, any other while none runs alone.
    async fn take(alone: bool) -> Slot {
        loop {
            {
                let mut m = MACHINE.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
                let free = if alone { m.live == 0 } else { !m.alone };
                if free {
                    m.live += 1;
                    m.alone |= alone;
                    return Slot { alone };
                }
            }
            // Waiting for another test's process to end (no notification to wait on).
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut m = MACHINE.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        m.live -= 1;
        if self.alone {
            m.alone = false;
        }
    }
}

/// What to run: `inbetween serve --listen 127.0.0.1:0 --grpc-listen 127.0.0.1:0`
/// plus the test's arguments and environment. No `INBETWEEN_*` variable
/// leaks in from the caller; logs are at `warn` unless the test sets
/// `INBETWEEN_LOG`.
pub struct ProcessBuilder {
    command: Command,
    name: String,
    log: Option<PathBuf>,
    alone: bool,
}

impl ProcessBuilder {
    /// Runs this server alone: it starts once no other server of this test
    /// binary runs, and none starts until it is dropped. The attacks measure
    /// probe latencies against budgets, which a neighbour's load on a 2-core
    /// machine would decide instead of the server.
    pub fn alone(mut self) -> Self {
        self.alone = true;
        self
    }

    pub fn name(mut self, name: &str) -> Self {
        name.clone_into(&mut self.name);
        self
    }

    pub fn arg(mut self, arg: impl AsRef<OsStr>) -> Self {
        self.command.arg(arg);
        self
    }

    pub fn args<S: AsRef<OsStr>>(mut self, args: impl IntoIterator<Item = S>) -> Self {
        self.command.args(args);
        self
    }

    pub fn env(mut self, key: &str, value: impl AsRef<OsStr>) -> Self {
        self.command.env(key, value);
        self
    }

    /// `--data-dir DIR`.
    pub fn data_dir(self, dir: &Path) -> Self {
        self.arg("--data-dir").arg(dir)
    }

    /// Appends the logs (stderr) to `path` instead of a temporary file.
    pub fn log_to(mut self, path: &Path) -> Self {
        self.log = Some(path.to_owned());
        self
    }

    /// Spawns the process and reads its two address lines, without waiting
    /// for readiness.
    fn spawn(self, slot: Slot) -> ServerProcess {
        let ProcessBuilder { mut command, name, log, alone: _ } = self;
        let (log, log_dir) = match log {
            Some(path) => (path, None),
            None => {
                let dir = tempfile::tempdir().unwrap();
                (dir.path().join("server.log"), Some(dir))
            }
        };
        let file = std::fs::OpenOptions::new().create(true).append(true).open(&log).expect("open the server log");
        let mut child = command.stdout(Stdio::piped()).stderr(file).spawn().expect("the binary starts");
        let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
        let mut addr = |prefix: &str| -> SocketAddr {
            let line = match lines.next() {
                Some(Ok(line)) => line,
                _ => panic!("{name}: exited before printing {prefix:?}; log:\n{}", read_log(&log)),
            };
            let rest = line.strip_prefix(prefix).unwrap_or_else(|| panic!("{name}: expected {prefix:?}, got {line:?}"));
            rest.trim_end_matches('/').parse().unwrap()
        };
        let http = addr("inbetween listening on http://");
        let grpc = addr("inbetween gRPC listening on http://");
        ServerProcess { child, name, http, grpc, log, ready_after: Duration::ZERO, _log_dir: log_dir, _slot: slot }
    }

    /// Spawns the process and waits (at most 10 s) until `/readyz` answers 200.
    pub async fn start(self) -> ServerProcess {
        let slot = Slot::take(self.alone).await;
        let started = Instant::now();
        let mut server = tokio::task::spawn_blocking(move || self.spawn(slot)).await.unwrap();
        let client = crate::common::http_client();
        let (readyz, what) = (server.url("/readyz"), format!("{}: /readyz answers 200", server.name));
        let ready = || async { client.get(&readyz).send().await.is_ok_and(|r| r.status() == 200) };
        crate::common::eventually(READY_LIMIT, &what, ready).await;
        server.ready_after = started.elapsed();
        server
    }
}

impl ServerProcess {
    /// `inbetween serve` on free ports; add arguments, then `start()`.
    pub fn serve() -> ProcessBuilder {
        let mut command = ServerProcess::command();
        command.args(["serve", "--listen", "127.0.0.1:0", "--grpc-listen", "127.0.0.1:0"]);
        ProcessBuilder { command, name: "inbetween".to_owned(), log: None, alone: false }
    }

    /// The binary with a clean environment (no `INBETWEEN_*` from the
    /// caller, logs at `warn`), for runs that are not a serving server.
    pub fn command() -> Command {
        let mut command = Command::new(env!("CARGO_BIN_EXE_inbetween"));
        for (name, _) in std::env::vars().filter(|(n, _)| n.starts_with("INBETWEEN_")) {
            command.env_remove(name);
        }
        command.env("INBETWEEN_LOG", "warn");
        command
    }

    /// `http://HTTP_ADDR`.
    pub fn base(&self) -> String {
        format!("http://{}", self.http)
    }

    pub fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.http)
    }

    pub fn ws_url(&self, path: &str) -> String {
        format!("ws://{}{path}", self.http)
    }

    pub fn grpc_url(&self) -> String {
        format!("http://{}", self.grpc)
    }

    pub fn pid(&self) -> i32 {
        i32::try_from(self.child.id()).unwrap()
    }

    /// The logs so far.
    pub fn logs(&self) -> String {
        read_log(&self.log)
    }

    /// Resident set size of the process, from /proc.
    pub fn rss_bytes(&self) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.pid())).unwrap_or_default();
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
            .map_or(0, |kb| kb * 1024)
    }

    /// Sends `signal` (`"TERM"`, `"KILL"`) with kill(1).
    pub fn signal(&self, signal: &str) {
        let ok = Command::new("kill").arg(format!("-{signal}")).arg(self.pid().to_string()).status().unwrap();
        assert!(ok.success(), "kill -{signal} {} failed", self.name);
    }

    /// SIGKILL, and reaps the process.
    pub fn kill(&mut self) {
        self.child.kill().unwrap();
        self.child.wait().unwrap();
    }

    /// Waits up to `limit` for the process to exit; `None` if it did not.
    pub async fn wait_exit(&mut self, limit: Duration) -> Option<ExitStatus> {
        let deadline = Instant::now() + limit;
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return Some(status);
            }
            if Instant::now() >= deadline {
                return None;
            }
            // Polls the child (std's `Child` has no async wait); `None` is an answer here, not a failure.
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// Uploads a JSON clip under a fresh name ([`super::fresh_name`]);
    /// panics unless 201. Returns its id.
    pub async fn create(&self, http: &reqwest::Client, body: &str) -> String {
        let resp = http
            .post(self.url("/v1/clips"))
            .header("content-type", "application/json")
            .body(super::fresh_name(body))
            .send()
            .await
            .unwrap();
        assert_eq!(resp.status(), 201, "{}: create", self.name);
        let v: serde_json::Value = resp.json().await.unwrap();
        v["id"].as_str().unwrap().to_owned()
    }

    /// Waits until its `/metrics` shows `name` at `at_least` or more (e.g.
    /// `inbetween_bodies_awaited`: requests in, their bodies not yet).
    pub async fn until_metric(&self, http: &reqwest::Client, name: &str, at_least: f64) {
        let what = format!("{}: {name} ≥ {at_least}", self.name);
        super::eventually(Duration::from_secs(10), &what, || async {
            let Ok(resp) = http.get(self.url("/metrics")).send().await else { return false };
            let text = resp.text().await.unwrap_or_default();
            super::metric(&text, name).is_some_and(|v| v >= at_least)
        })
        .await;
    }
}

impl Drop for ServerProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        if std::thread::panicking() {
            eprintln!("--- log of {} ({}):\n{}", self.name, self.log.display(), read_log(&self.log));
        }
    }
}

fn read_log(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| format!("(no log: {e})"))
}
