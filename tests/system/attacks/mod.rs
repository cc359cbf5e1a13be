//! Attacks (issue 15): every request, file and client behaviour that once
//! took the server past its memory or stalled its probes, replayed against
//! the real binary with the default limits inside a memory cage equal to the
//! shipped Kubernetes limit (1 GiB), while a prober measures what an
//! orchestrator would see.
//!
//! Each attack asserts that the server survives (still running, never
//! OOM-killed in its cage), answers the documented error, keeps `/healthz`
//! and a gRPC `Ping` answering within 100 ms at the 99th percentile over the
//! attack, and keeps its peak RSS (`VmHWM`) under the cap. With `--nocapture`
//! each prints a `FIGURE` line; RELIABILITY.md records them.
//!
//! The cage is a memory cgroup (v1 `memory.limit_in_bytes` or v2
//! `memory.max`) made under the test's own; where cgroups are not writable
//! the peak-RSS assertion still holds the line. The attacks run one at a
//! time (a lock), so one attack's load never shows up in another's probes.

mod answers;
mod broadcasts;
mod builds;
mod compact;
mod connections;
mod graphs;
mod imports;
mod memory;
mod springs;
mod viewers;
mod work;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use formats::wire::proto::pb;
use formats::wire::proto::pb::animation_client::AnimationClient;

pub use crate::common::ServerProcess;

/// The memory limit of the shipped Kubernetes manifest (`deploy/`).
pub const CAP_BYTES: u64 = 1 << 30;

/// The probe budget: p99 of `/healthz` and of gRPC `Ping` during an attack.
pub const PROBE_P99: Duration = Duration::from_millis(100);

/// How often the prober asks.
const PROBE_EVERY: Duration = Duration::from_millis(20);

/// The fewest probes of each kind an attack is judged on: the prober goes
/// on after the attack until it has them.
const MIN_PROBES: usize = 25;

/// One attack at a time.
static SERIAL: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// The server under attack, in its cage; killed, then its cage removed, on drop.
pub struct Target {
    pub server: ServerProcess,
    cage: Option<Cage>,
    _dir: tempfile::TempDir,
    _serial: Arc<tokio::sync::MutexGuard<'static, ()>>,
}

/// Starts `inbetween serve` with default limits plus `extra`, caged.
pub async fn target(extra: &[&str]) -> Target {
    let serial = Arc::new(SERIAL.lock().await);
    let dir = tempfile::tempdir().unwrap();
    let server = ServerProcess::serve().alone().data_dir(&dir.path().join("data"));
    caged(server.args(extra), dir, serial).await
}

/// Starts the named nodes on one PostgreSQL `schema` with default limits
/// plus `extra`, each in a cage of its own: an attack on many nodes. They
/// do not run alone (each would wait for the others), so their probes'
/// latency is judged in the slow runs only, as every attack's is.
pub async fn nodes<const N: usize>(
    schema: &crate::common::pg::Schema,
    names: [&str; N],
    extra: &[&str],
) -> [Target; N] {
    let serial = Arc::new(SERIAL.lock().await);
    let mut nodes = Vec::with_capacity(N);
    for name in names {
        let server = ServerProcess::serve()
            .name(name)
            .arg("--database-url")
            .arg(schema.url(&format!("application_name={name}")));
        nodes.push(caged(server.args(extra), tempfile::tempdir().unwrap(), Arc::clone(&serial)).await);
    }
    let Ok(nodes) = nodes.try_into() else { unreachable!("N names, N nodes") };
    nodes
}

/// Starts `server`, logging to `dir`, and moves it into a cage.
async fn caged(
    server: crate::common::process::ProcessBuilder,
    dir: tempfile::TempDir,
    serial: Arc<tokio::sync::MutexGuard<'static, ()>>,
) -> Target {
    let server = server.log_to(&dir.path().join("server.log")).start().await;
    let cage = Cage::new(CAP_BYTES);
    match &cage {
        Some(cage) => cage.add(server.pid()),
        None => eprintln!("attacks: no writable memory cgroup here; checking peak RSS only"),
    }
    Target { server, cage, _dir: dir, _serial: serial }
}

impl Target {
    /// The server's `--data-dir` (its SQLite store is `inbetween.db` there).
    pub fn data_dir(&self) -> PathBuf {
        self._dir.path().join("data")
    }

    /// Peak resident set size so far (`VmHWM`).
    pub fn peak_rss(&self) -> u64 {
        proc_status_kib(self.server.pid(), "VmHWM:") * 1024
    }

    /// Starts measuring `/healthz` and `Ping` on a thread of its own.
    pub async fn probes(&self) -> Probes {
        Probes::start(self.server.url("/healthz"), self.server.grpc_url()).await
    }

    /// Asserts the server is alive, was never OOM-killed, and stayed under
    /// the cap; prints the attack's figure line.
    pub fn assert_survived(&mut self, attack: &str, probes: &ProbeReport) {
        let exited = self.server.child.try_wait().unwrap();
        assert!(exited.is_none(), "{attack}: the server died ({exited:?})");
        let ooms = self.cage.as_ref().map_or(0, Cage::oom_kills);
        assert_eq!(ooms, 0, "{attack}: the cage OOM-killed the server");
        let peak = self.peak_rss();
        println!(
            "FIGURE {attack}: peak RSS {:.0} MiB, /healthz p99 {:.1} ms, Ping p99 {:.1} ms ({} probes each)",
            mib(peak),
            millis(probes.healthz_p99()),
            millis(probes.ping_p99()),
            probes.healthz.len(),
        );
        assert!(peak < CAP_BYTES, "{attack}: peak RSS {:.0} MiB reached the cap", mib(peak));
        probes.assert_within_budget(attack);
    }

    /// A `/metrics` sample's value (the first line starting with `name`).
    pub async fn metric(&self, name: &str) -> Option<f64> {
        let text = reqwest::get(self.server.url("/metrics")).await.ok()?.text().await.ok()?;
        text.lines().find(|l| l.starts_with(name)).and_then(|l| l.rsplit(' ').next()?.parse().ok())
    }
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / f64::from(1 << 20)
}

fn millis(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// A `kB` field of `/proc/PID/status`.
fn proc_status_kib(pid: i32, field: &str) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix(field))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0)
}

/// A memory cgroup under this process's own, removed on drop.
struct Cage {
    dir: PathBuf,
    v2: bool,
}

impl Cage {
    /// A new cage limited to `limit` bytes, or `None` where the cgroup
    /// filesystem is not writable.
    fn new(limit: u64) -> Option<Cage> {
        let own = std::fs::read_to_string("/proc/self/cgroup").ok()?;
        static CAGES: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let name = format!("inbetween-attack-{}-{}", std::process::id(), CAGES.fetch_add(1, Ordering::Relaxed));
        // cgroup v1: "N:memory:/path"; v2: "0::/path".
        let (dir, v2) = if let Some(path) = own.lines().find_map(|l| l.split_once(":memory:").map(|(_, p)| p)) {
            (PathBuf::from(format!("/sys/fs/cgroup/memory{path}")).join(name), false)
        } else {
            let path = own.lines().find_map(|l| l.strip_prefix("0::"))?;
            (PathBuf::from(format!("/sys/fs/cgroup{path}")).join(name), true)
        };
        std::fs::create_dir_all(&dir).ok()?;
        let cage = Cage { dir, v2 };
        let limit_file = if v2 { "memory.max" } else { "memory.limit_in_bytes" };
        std::fs::write(cage.dir.join(limit_file), limit.to_string()).ok()?;
        Some(cage)
    }

    fn add(&self, pid: i32) {
        std::fs::write(self.dir.join("cgroup.procs"), pid.to_string()).expect("moving the server into its cage");
    }

    /// OOM kills inside the cage.
    fn oom_kills(&self) -> u64 {
        if self.v2 {
            let events = std::fs::read_to_string(self.dir.join("memory.events")).unwrap_or_default();
            events.lines().find_map(|l| l.strip_prefix("oom_kill ")).and_then(|n| n.trim().parse().ok()).unwrap_or(0)
        } else {
            // v1 counts hits of the limit; an OOM kill needs one.
            let oom = std::fs::read_to_string(self.dir.join("memory.oom_control")).unwrap_or_default();
            oom.lines().find_map(|l| l.strip_prefix("oom_kill ")).and_then(|n| n.trim().parse().ok()).unwrap_or(0)
        }
    }
}

impl Drop for Cage {
    fn drop(&mut self) {
        // The server (killed first: `Target` declares it before the cage) has left.
        let _ = std::fs::remove_dir(&self.dir);
    }
}

/// The prober: a thread with its own runtime, so the attack's client tasks
/// never delay a probe. Each `/healthz` uses a new connection, as a kubelet
/// does; `Ping` uses one channel opened before the attack.
pub struct Probes {
    stop: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<ProbeReport>,
}

/// What the prober saw: latencies (a failure counts as its time to fail).
#[derive(Debug, Default)]
pub struct ProbeReport {
    pub healthz: Vec<Duration>,
    pub ping: Vec<Duration>,
    pub failures: Vec<String>,
}

impl Probes {
    async fn start(healthz: String, grpc: String) -> Probes {
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = tokio::sync::oneshot::channel();
        let flag = Arc::clone(&stop);
        let thread = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
            rt.block_on(probe_loop(healthz, grpc, flag, ready_tx))
        });
        ready_rx.await.expect("the prober connects");
        Probes { stop, thread }
    }

    /// Stops probing and returns what was seen.
    pub fn finish(self) -> ProbeReport {
        self.stop.store(true, Ordering::Release);
        self.thread.join().expect("the prober does not panic")
    }
}

async fn probe_loop(
    healthz: String,
    grpc: String,
    stop: Arc<AtomicBool>,
    ready: tokio::sync::oneshot::Sender<()>,
) -> ProbeReport {
    let http = crate::common::http_builder().pool_max_idle_per_host(0).timeout(Duration::from_secs(2)).build().unwrap();
    let channel = tonic::transport::Endpoint::from_shared(grpc).unwrap().connect().await.expect("Ping channel");
    let mut ping = AnimationClient::new(channel);
    let _ = ready.send(());
    let mut report = ProbeReport::default();
    let mut every = tokio::time::interval(PROBE_EVERY);
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    while !stop.load(Ordering::Acquire) || report.healthz.len() < MIN_PROBES {
        every.tick().await;
        let started = Instant::now();
        match http.get(&healthz).send().await {
            Ok(r) if r.status() == 200 => {}
            Ok(r) => report.failures.push(format!("/healthz answered {}", r.status())),
            Err(e) => report.failures.push(format!("/healthz: {e}")),
        }
        report.healthz.push(started.elapsed());
        let started = Instant::now();
        let mut request = tonic::Request::new(pb::PingRequest {});
        request.set_timeout(Duration::from_secs(2));
        if let Err(status) = ping.ping(request).await {
            report.failures.push(format!("Ping: {status:?}"));
        }
        report.ping.push(started.elapsed());
    }
    report
}

impl ProbeReport {
    pub fn healthz_p99(&self) -> Duration {
        p99(&self.healthz)
    }

    pub fn ping_p99(&self) -> Duration {
        p99(&self.ping)
    }

    fn assert_within_budget(&self, attack: &str) {
        assert!(
            self.failures.is_empty(),
            "{attack}: probes failed: {:?}",
            &self.failures[..self.failures.len().min(5)]
        );
        eprintln!("{attack}: /healthz p99 {:?}, Ping p99 {:?}", self.healthz_p99(), self.ping_p99());
        if crate::common::latency_checked() {
            assert!(
                self.healthz_p99() <= PROBE_P99,
                "{attack}: /healthz p99 {:?} over {PROBE_P99:?}",
                self.healthz_p99()
            );
            assert!(self.ping_p99() <= PROBE_P99, "{attack}: Ping p99 {:?} over {PROBE_P99:?}", self.ping_p99());
        }
    }
}

fn p99(samples: &[Duration]) -> Duration {
    let mut sorted = samples.to_vec();
    sorted.sort_unstable();
    let rank = (sorted.len() * 99).div_ceil(100).max(1);
    sorted.get(rank - 1).copied().unwrap_or_default()
}

/// The stable `code` of a problem body, or of a gRPC status's `x-error-code`.
pub fn grpc_code(status: &tonic::Status) -> String {
    status.metadata().get("x-error-code").and_then(|v| v.to_str().ok()).unwrap_or_default().to_owned()
}

/// Joint `i`'s name in [`wide_clip`]: `j{i}-` padded with `x` to `chars`.
pub fn joint_name(i: usize, chars: usize) -> String {
    let tag = format!("j{i}-");
    format!("{tag}{}", "x".repeat(chars.saturating_sub(tag.len())))
}

/// A flat skeleton of `joints` joints (each a child of the first) named
/// `name_chars`-character names, with one moving root track: big answers
/// from a small body.
pub fn wide_clip(joints: usize, name_chars: usize) -> String {
    let name = |i: usize| joint_name(i, name_chars);
    let joints: Vec<serde_json::Value> = (0..joints)
        .map(|i| {
            let parent = if i == 0 { serde_json::Value::Null } else { name(0).into() };
            serde_json::json!({"name": name(i), "parent": parent, "rest": {"translation": [0.0, 0.1, 0.0]}})
        })
        .collect();
    serde_json::json!({
        "name": "wide",
        "skeleton": {"joints": joints},
        "tracks": [{"joint": name(0), "channel": "translation", "interpolation": "catmull_rom",
                    "times": [0, 1, 2, 3], "values": [[0,0,0],[1,0,0],[1,1,0],[0,1,0]]}],
        "playback": "loop"
    })
    .to_string()
}
