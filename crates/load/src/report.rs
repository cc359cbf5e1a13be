//! The load generator's result: one [`Report`] per run, printed as a human
//! summary or as JSON (`--json`, the form `bench/run.sh` turns into tables).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use super::clock::ClockSync;
use super::floor::FloorReport;
use super::histogram::{Summary, human_us};
use super::ramp::{RampPlan, Stage};

#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub mode: &'static str,
    /// Wall clock at the start, seconds since the Unix epoch.
    pub started_unix: f64,
    pub http: String,
    pub grpc: String,
    /// The clip streamed, or the first layer's clip of the motion.
    pub clip_id: String,
    /// Streams: the motion played instead of the clip (`three-layers`, `foot-ik`).
    pub motion: Option<&'static str>,
    pub joints: Option<usize>,
    /// Unary workers, or streams.
    pub concurrency: usize,
    pub connections: usize,
    /// Requests per second of the open-loop schedule, if one was asked for.
    pub rate: Option<f64>,
    /// The measured window, seconds.
    pub elapsed_secs: f64,
    /// Successful requests, or frames received in the window.
    pub ok: u64,
    /// `ok` per second.
    pub throughput: f64,
    /// Unary: request latency (from the scheduled send time with `--rate`).
    pub latency: Option<Summary>,
    pub streams: Option<StreamStats>,
    /// Failures by kind (`grpc:Unavailable`, `http:503`, `connect`, `timeout`, `closed:1013`, ...).
    pub errors: BTreeMap<String, u64>,
    pub server: Option<ServerUsage>,
    /// The load generator's own CPU over the window (it shares the machine).
    pub client_cpu_cores: Option<f64>,
    /// `/proc/loadavg` at the end of the run.
    pub loadavg: Option<String>,
    pub ramp: Option<RampReport>,
    /// `--floor`: the bare sender measured after the server, and the ratio of their CPU per frame.
    pub floor: Option<FloorReport>,
}

#[derive(Debug, Clone, Serialize)]
pub struct StreamStats {
    pub streams: usize,
    /// Streams that delivered at least one frame.
    pub opened: usize,
    pub fps: u32,
    pub shared: bool,
    pub encoding: &'static str,
    /// Frames per second per stream over the window (≈ fps when healthy).
    pub frames_per_stream_per_sec: f64,
    /// `sent_at` − due time.
    pub send_lateness: Summary,
    /// Receive time (on the server clock) − due time.
    pub receive_lateness: Summary,
    /// |Δreceived − Δseq/fps| between consecutive frames.
    pub jitter: Summary,
    /// Receive lateness p50 in the window's last tenth minus its first tenth (µs): drift.
    pub drift_p50_us: f64,
    /// The sum of the frames' `dropped`.
    pub dropped: u64,
    /// Ticks missing between consecutive frames (should equal `dropped`).
    pub gaps: u64,
    /// (gaps) / (frames + gaps).
    pub loss_ratio: f64,
    pub reconnects: u64,
    pub clock: ClockSync,
    /// Server counters (from `/metrics`): playbacks started since the streams began to
    /// open (how many the viewers shared), and ticks evaluated in the window.
    /// For `ws-broadcast`: broadcasts created (1) and broadcast ticks evaluated.
    pub playbacks_started: Option<u64>,
    pub ticks_evaluated: Option<u64>,
    /// `ws-broadcast`: the id of the broadcast the viewers watched.
    pub broadcast_id: Option<String>,
}

#[derive(Debug, Clone, Serialize)]
pub struct ServerUsage {
    pub pid: u32,
    /// RSS before the load started, and at the end of the window.
    pub rss_before_bytes: u64,
    pub rss_end_bytes: u64,
    /// Streams only: (end − before) / streams opened.
    pub rss_per_stream_bytes: Option<f64>,
    /// CPU seconds per second over the window (1.0 = one core).
    pub cpu_cores: f64,
    /// Server CPU per successful request or frame, µs.
    pub cpu_us_per_op: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct RampReport {
    pub plan: RampPlan,
    pub stages: Vec<Stage>,
    /// The last load that passed.
    pub knee: Option<usize>,
    pub broke_at: Option<usize>,
}

impl Report {
    /// The p99 a ramp judges: receive lateness for streams, latency otherwise.
    pub fn p99_us(&self) -> f64 {
        match (&self.streams, &self.latency) {
            (Some(s), _) => s.receive_lateness.p99_us,
            (None, Some(l)) => l.p99_us,
            (None, None) => f64::INFINITY,
        }
    }

    /// Lost frames (streams) or failed requests, as a share of all.
    pub fn loss_ratio(&self) -> f64 {
        match &self.streams {
            Some(s) => s.loss_ratio,
            None => {
                let failed: u64 = self.errors.values().sum();
                if failed == 0 { 0.0 } else { failed as f64 / (failed + self.ok) as f64 }
            }
        }
    }

    pub fn error_count(&self) -> u64 {
        self.errors.values().sum()
    }

    /// The human summary.
    pub fn human(&self) -> String {
        let mut s = String::new();
        let playing = match self.motion {
            Some(m) => format!("motion {m} (first clip {})", self.clip_id),
            None => format!("clip {}", self.clip_id),
        };
        let _ = writeln!(s, "mode {}  {playing}  http {}  grpc {}", self.mode, self.http, self.grpc);
        let rate = self.rate.map(|r| format!("  open loop at {r:.0}/s")).unwrap_or_default();
        let _ = writeln!(
            s,
            "load {} {}, {} connection(s){rate}, {:.1} s measured",
            self.concurrency,
            if self.streams.is_some() { "streams" } else { "workers" },
            self.connections,
            self.elapsed_secs
        );
        let unit = if self.streams.is_some() { "frames" } else { "requests" };
        let _ = writeln!(s, "{} {unit} ok, {:.0}/s", self.ok, self.throughput);
        if let Some(l) = &self.latency {
            let _ = writeln!(s, "latency   {l}");
        }
        if let Some(st) = &self.streams {
            let _ = writeln!(
                s,
                "streams   {} of {} opened at {} fps ({}{}), {:.2} frames/s per stream",
                st.opened,
                st.streams,
                st.fps,
                st.encoding,
                if st.shared { ", shared" } else { "" },
                st.frames_per_stream_per_sec
            );
            let _ = writeln!(s, "send late {}", st.send_lateness);
            let _ = writeln!(s, "recv late {}", st.receive_lateness);
            let _ = writeln!(s, "jitter    {}", st.jitter);
            let _ = writeln!(
                s,
                "dropped {}  gaps {}  loss {:.4}%  reconnects {}  drift {}",
                st.dropped,
                st.gaps,
                st.loss_ratio * 100.0,
                st.reconnects,
                human_us(st.drift_p50_us)
            );
            match (&st.broadcast_id, st.playbacks_started, st.ticks_evaluated) {
                (Some(id), Some(p), Some(t)) => {
                    let _ = writeln!(s, "server    broadcast {id} ({p} created), {t} ticks evaluated in the window");
                }
                (None, Some(p), Some(t)) => {
                    let _ = writeln!(s, "server    {p} playbacks started, {t} ticks evaluated in the window");
                }
                _ => {}
            }
        }
        if let Some(u) = &self.server {
            let per_stream =
                u.rss_per_stream_bytes.map(|b| format!(", {:.1} KiB per stream", b / 1024.0)).unwrap_or_default();
            let _ = writeln!(
                s,
                "server    pid {}: {:.2} cores, {:.1} µs CPU per op, RSS {:.1} → {:.1} MiB{per_stream}",
                u.pid,
                u.cpu_cores,
                u.cpu_us_per_op,
                u.rss_before_bytes as f64 / 1048576.0,
                u.rss_end_bytes as f64 / 1048576.0
            );
        }
        if let Some(c) = self.client_cpu_cores {
            let _ = writeln!(s, "client    {c:.2} cores");
        }
        if !self.errors.is_empty() {
            let list: Vec<String> = self.errors.iter().map(|(k, v)| format!("{k}={v}")).collect();
            let _ = writeln!(s, "errors    {}", list.join(" "));
        }
        if let Some(r) = &self.ramp {
            for st in &r.stages {
                let _ = writeln!(
                    s,
                    "ramp      n={:<6} p99 {:>10}  loss {:.4}%  errors {}  {}",
                    st.n,
                    human_us(st.p99_us),
                    st.loss_ratio * 100.0,
                    st.errors,
                    if st.passed { "pass" } else { "FAIL" }
                );
            }
            let knee = r.knee.map_or("none".into(), |k| k.to_string());
            let broke = r.broke_at.map_or("not reached".into(), |k| k.to_string());
            let _ = writeln!(s, "knee      {knee} (target broke at {broke})");
        }
        if let Some(f) = &self.floor {
            let ratio = f.server_to_floor.map_or("unmeasured".into(), |r| format!("{r:.2}×"));
            let _ = writeln!(
                s,
                "floor     {} ({} B frames), {} of {} opened, {} connection(s): {} frames, {:.2}/s per stream, loss {:.4}%",
                f.kind,
                f.frame_bytes,
                f.opened,
                f.streams,
                f.connections,
                f.frames,
                f.frames_per_stream_per_sec,
                f.loss_ratio * 100.0
            );
            let _ = writeln!(s, "floor     recv late {}", f.receive_lateness);
            let _ = writeln!(
                s,
                "floor     {:.2} cores, {:.2} µs CPU per frame; server per frame / floor per frame = {ratio}",
                f.cpu_cores, f.cpu_us_per_frame
            );
            if !f.errors.is_empty() {
                let list: Vec<String> = f.errors.iter().map(|(k, v)| format!("{k}={v}")).collect();
                let _ = writeln!(s, "floor     errors {}", list.join(" "));
            }
        }
        if let Some(l) = &self.loadavg {
            let _ = writeln!(s, "loadavg   {l}");
        }
        s
    }
}
