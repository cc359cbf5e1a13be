//! The load generator's result: one [`Report`] per run, printed as a human
//! summary or as JSON (`--json`, the form `bench/run.sh` turns into tables).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use super::clock::ClockSync;
use super::floor::sender::Tally;
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
    pub motion: Option<String>,
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

/// The floor beside the server, in the report.
#[derive(Debug, Clone, Serialize)]
pub struct FloorReport {
    /// `ws-json`, `ws-protobuf` or `tcp`.
    pub kind: &'static str,
    /// The server's frame the floor sent, without WebSocket or gRPC framing.
    pub frame_bytes: usize,
    pub streams: usize,
    /// Streams that received at least one frame.
    pub opened: usize,
    pub connections: usize,
    pub elapsed_secs: f64,
    /// Frames received from the floor in its window.
    pub frames: u64,
    pub frames_per_stream_per_sec: f64,
    pub loss_ratio: f64,
    /// On the floor's grid (module doc).
    pub send_lateness: Summary,
    pub receive_lateness: Summary,
    /// The floor process's CPU over its window (1.0 = one core), and per delivered frame (µs).
    pub cpu_cores: f64,
    pub cpu_us_per_frame: f64,
    /// The server's CPU per delivered frame over the floor's; `None` when either was not measured
    /// (or the floor's rounded to zero: `/proc` counts 10 ms ticks).
    pub server_to_floor: Option<f64>,
    /// The load generator's CPU while it received the floor's frames.
    pub client_cpu_cores: Option<f64>,
    /// What the sender counted over its whole life (the opening and settling too).
    pub sent: Option<Tally>,
    pub errors: BTreeMap<String, u64>,
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
        self.write_load(&mut s);
        if let Some(st) = &self.streams {
            st.write_human(&mut s);
        }
        if let Some(u) = &self.server {
            u.write_human(&mut s);
        }
        if let Some(c) = self.client_cpu_cores {
            let _ = writeln!(s, "client    {c:.2} cores");
        }
        if !self.errors.is_empty() {
            let _ = writeln!(s, "errors    {}", error_list(&self.errors));
        }
        if let Some(r) = &self.ramp {
            r.write_human(&mut s);
        }
        if let Some(f) = &self.floor {
            f.write_human(&mut s);
        }
        if let Some(l) = &self.loadavg {
            let _ = writeln!(s, "loadavg   {l}");
        }
        s
    }

    /// What ran and how much got through: the summary's first lines.
    fn write_load(&self, s: &mut String) {
        let playing = match &self.motion {
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
    }
}

/// `kind=count` pairs, space separated.
fn error_list(errors: &BTreeMap<String, u64>) -> String {
    errors.iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(" ")
}

impl StreamStats {
    fn write_human(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "streams   {} of {} opened at {} fps ({}{}), {:.2} frames/s per stream",
            self.opened,
            self.streams,
            self.fps,
            self.encoding,
            if self.shared { ", shared" } else { "" },
            self.frames_per_stream_per_sec
        );
        let _ = writeln!(s, "send late {}", self.send_lateness);
        let _ = writeln!(s, "recv late {}", self.receive_lateness);
        let _ = writeln!(s, "jitter    {}", self.jitter);
        let _ = writeln!(
            s,
            "dropped {}  gaps {}  loss {:.4}%  reconnects {}  drift {}",
            self.dropped,
            self.gaps,
            self.loss_ratio * 100.0,
            self.reconnects,
            human_us(self.drift_p50_us)
        );
        match (&self.broadcast_id, self.playbacks_started, self.ticks_evaluated) {
            (Some(id), Some(p), Some(t)) => {
                let _ = writeln!(s, "server    broadcast {id} ({p} created), {t} ticks evaluated in the window");
            }
            (None, Some(p), Some(t)) => {
                let _ = writeln!(s, "server    {p} playbacks started, {t} ticks evaluated in the window");
            }
            _ => {}
        }
    }
}

impl ServerUsage {
    fn write_human(&self, s: &mut String) {
        let per_stream =
            self.rss_per_stream_bytes.map(|b| format!(", {:.1} KiB per stream", b / 1024.0)).unwrap_or_default();
        let _ = writeln!(
            s,
            "server    pid {}: {:.2} cores, {:.1} µs CPU per op, RSS {:.1} → {:.1} MiB{per_stream}",
            self.pid,
            self.cpu_cores,
            self.cpu_us_per_op,
            self.rss_before_bytes as f64 / 1048576.0,
            self.rss_end_bytes as f64 / 1048576.0
        );
    }
}

impl RampReport {
    fn write_human(&self, s: &mut String) {
        for st in &self.stages {
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
        let knee = self.knee.map_or("none".into(), |k| k.to_string());
        let broke = self.broke_at.map_or("not reached".into(), |k| k.to_string());
        let _ = writeln!(s, "knee      {knee} (target broke at {broke})");
    }
}

impl FloorReport {
    fn write_human(&self, s: &mut String) {
        let ratio = self.server_to_floor.map_or("unmeasured".into(), |r| format!("{r:.2}×"));
        let _ = writeln!(
            s,
            "floor     {} ({} B frames), {} of {} opened, {} connection(s): {} frames, {:.2}/s per stream, loss {:.4}%",
            self.kind,
            self.frame_bytes,
            self.opened,
            self.streams,
            self.connections,
            self.frames,
            self.frames_per_stream_per_sec,
            self.loss_ratio * 100.0
        );
        let _ = writeln!(s, "floor     recv late {}", self.receive_lateness);
        let _ = writeln!(
            s,
            "floor     {:.2} cores, {:.2} µs CPU per frame; server per frame / floor per frame = {ratio}",
            self.cpu_cores, self.cpu_us_per_frame
        );
        if !self.errors.is_empty() {
            let _ = writeln!(s, "floor     errors {}", error_list(&self.errors));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(p50_us: f64) -> Summary {
        Summary {
            count: 100,
            min_us: p50_us / 2.0,
            mean_us: p50_us,
            p50_us,
            p90_us: p50_us * 2.0,
            p99_us: p50_us * 4.0,
            p999_us: p50_us * 8.0,
            max_us: p50_us * 16.0,
        }
    }

    /// A stream run with every section the summary can print.
    fn stream_report() -> Report {
        let streams = StreamStats {
            streams: 64,
            opened: 63,
            fps: 60,
            shared: true,
            encoding: "json",
            frames_per_stream_per_sec: 59.87,
            send_lateness: summary(120.0),
            receive_lateness: summary(450.0),
            jitter: summary(30.0),
            drift_p50_us: 12.5,
            dropped: 3,
            gaps: 4,
            loss_ratio: 0.000_123,
            reconnects: 1,
            clock: ClockSync { offset_ns: 5, rtt_ns: 40_000, grid_epoch_unix_ns: 1 },
            playbacks_started: Some(1),
            ticks_evaluated: Some(600),
            broadcast_id: Some("b1".into()),
        };
        let floor = FloorReport {
            kind: "ws-json",
            frame_bytes: 2048,
            streams: 64,
            opened: 64,
            connections: 64,
            elapsed_secs: 10.0,
            frames: 38_400,
            frames_per_stream_per_sec: 60.0,
            loss_ratio: 0.0,
            send_lateness: summary(20.0),
            receive_lateness: summary(80.0),
            cpu_cores: 0.05,
            cpu_us_per_frame: 1.3,
            server_to_floor: Some(7.25),
            client_cpu_cores: Some(0.4),
            sent: Some(Tally::default()),
            errors: BTreeMap::from([("connect".into(), 2)]),
        };
        let stage = |n, passed| Stage { n, p99_us: 1800.0, loss_ratio: 0.001, errors: 0, passed };
        let plan = RampPlan { start: 16, factor: 2.0, max: 64, target_p99_us: 2000.0, max_loss_ratio: 0.01 };
        Report {
            mode: "ws-broadcast",
            started_unix: 1.7e9,
            http: "http://127.0.0.1:8080".into(),
            grpc: "http://127.0.0.1:50051".into(),
            clip_id: "c1".into(),
            motion: Some("three-layers".into()),
            joints: Some(64),
            concurrency: 64,
            connections: 64,
            rate: Some(500.0),
            elapsed_secs: 10.04,
            ok: 37_950,
            throughput: 3779.9,
            latency: None,
            streams: Some(streams),
            errors: BTreeMap::from([("closed:1013".into(), 1), ("timeout".into(), 3)]),
            server: Some(ServerUsage {
                pid: 4242,
                rss_before_bytes: 50 << 20,
                rss_end_bytes: 60 << 20,
                rss_per_stream_bytes: Some(163_840.0),
                cpu_cores: 0.75,
                cpu_us_per_op: 19.8,
            }),
            client_cpu_cores: Some(0.33),
            loadavg: Some("1.00 0.50 0.25 2/300 12345".into()),
            ramp: Some(RampReport {
                plan,
                stages: vec![stage(16, true), stage(32, true), stage(64, false)],
                knee: Some(32),
                broke_at: Some(64),
            }),
            floor: Some(floor),
        }
    }

    #[test]
    fn the_human_summary_of_a_stream_run_names_every_section() {
        let expected = concat!(
            "mode ws-broadcast  motion three-layers (first clip c1)  http http://127.0.0.1:8080  grpc http://127.0.0.1:50051\n",
            "load 64 streams, 64 connection(s)  open loop at 500/s, 10.0 s measured\n",
            "37950 frames ok, 3780/s\n",
            "streams   63 of 64 opened at 60 fps (json, shared), 59.87 frames/s per stream\n",
            "send late p50 120 µs p90 240 µs p99 480 µs p99.9 960 µs max 1.92 ms (n=100)\n",
            "recv late p50 450 µs p90 900 µs p99 1.80 ms p99.9 3.60 ms max 7.20 ms (n=100)\n",
            "jitter    p50 30 µs p90 60 µs p99 120 µs p99.9 240 µs max 480 µs (n=100)\n",
            "dropped 3  gaps 4  loss 0.0123%  reconnects 1  drift 12 µs\n",
            "server    broadcast b1 (1 created), 600 ticks evaluated in the window\n",
            "server    pid 4242: 0.75 cores, 19.8 µs CPU per op, RSS 50.0 → 60.0 MiB, 160.0 KiB per stream\n",
            "client    0.33 cores\n",
            "errors    closed:1013=1 timeout=3\n",
            "ramp      n=16     p99    1.80 ms  loss 0.1000%  errors 0  pass\n",
            "ramp      n=32     p99    1.80 ms  loss 0.1000%  errors 0  pass\n",
            "ramp      n=64     p99    1.80 ms  loss 0.1000%  errors 0  FAIL\n",
            "knee      32 (target broke at 64)\n",
            "floor     ws-json (2048 B frames), 64 of 64 opened, 64 connection(s): 38400 frames, 60.00/s per stream, loss 0.0000%\n",
            "floor     recv late p50 80 µs p90 160 µs p99 320 µs p99.9 640 µs max 1.28 ms (n=100)\n",
            "floor     0.05 cores, 1.30 µs CPU per frame; server per frame / floor per frame = 7.25×\n",
            "floor     errors connect=2\n",
            "loadavg   1.00 0.50 0.25 2/300 12345\n",
        );
        assert_eq!(stream_report().human(), expected);
    }

    #[test]
    fn the_human_summary_of_a_unary_run_has_its_latency_and_no_stream_lines() {
        let report = Report {
            mode: "rest-pose",
            motion: None,
            rate: None,
            latency: Some(summary(250.0)),
            streams: None,
            server: None,
            client_cpu_cores: None,
            errors: BTreeMap::new(),
            loadavg: None,
            ramp: Some(RampReport { knee: None, broke_at: None, ..stream_report().ramp.unwrap() }),
            floor: None,
            ..stream_report()
        };
        let expected = concat!(
            "mode rest-pose  clip c1  http http://127.0.0.1:8080  grpc http://127.0.0.1:50051\n",
            "load 64 workers, 64 connection(s), 10.0 s measured\n",
            "37950 requests ok, 3780/s\n",
            "latency   p50 250 µs p90 500 µs p99 1.00 ms p99.9 2.00 ms max 4.00 ms (n=100)\n",
            "ramp      n=16     p99    1.80 ms  loss 0.1000%  errors 0  pass\n",
            "ramp      n=32     p99    1.80 ms  loss 0.1000%  errors 0  pass\n",
            "ramp      n=64     p99    1.80 ms  loss 0.1000%  errors 0  FAIL\n",
            "knee      none (target broke at not reached)\n",
        );
        assert_eq!(report.human(), expected);
    }

    #[test]
    fn the_human_summary_of_per_viewer_streams_counts_their_playbacks() {
        let mut report = stream_report();
        let streams = report.streams.as_mut().unwrap();
        streams.broadcast_id = None;
        streams.playbacks_started = Some(63);
        report.server.as_mut().unwrap().rss_per_stream_bytes = None;
        let floor = report.floor.as_mut().unwrap();
        floor.server_to_floor = None;
        floor.errors.clear();
        let human = report.human();
        assert!(human.contains("server    63 playbacks started, 600 ticks evaluated in the window\n"), "{human}");
        assert!(human.contains("= unmeasured\n") && !human.contains("floor     errors"), "{human}");
        report.streams.as_mut().unwrap().ticks_evaluated = None;
        assert!(!report.human().contains("ticks evaluated"));
    }
}
