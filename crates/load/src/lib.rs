//! The load generator (`inbetween load`): loads a server the way game
//! clients and viewers do and reports throughput, latency percentiles, stream
//! lateness and the server's CPU and memory.
//!
//! Modes: `grpc-sample` and its no-op baseline `grpc-ping`, `rest-pose` and
//! its baseline `rest-health` (unary: closed loop with N workers, or open
//! loop at a fixed `--rate`, where latency is measured from each request's
//! scheduled time so a stalled server cannot hide its queue — no coordinated
//! omission); `grpc-stream` and `ws-stream` (N streams at F fps, independent
//! playbacks or `--shared` viewers of one, measuring per-frame lateness
//! against the server's tick grid after a `Ping` clock sync; with
//! `--motion` every stream plays a composed motion instead of the clip:
//! `three-layers`, or `foot-ik`, a walk with IK-planted feet); `ws-broadcast`
//! (one broadcast of the clip or motion, docs/broadcasts.md, watched by N WebSocket
//! viewers, measured the same way on the broadcast's tick grid). `--ramp`
//! steps the load up until a p99 target breaks and reports the knee.
//! `--floor` (`grpc-stream`, `ws-stream`) then measures the streaming floor
//! in the same invocation: a bare sender process writing one of the server's
//! own frames to as many streams at the same rate, received by the same
//! code, its CPU per delivered frame reported beside the server's (`floor`).
//!
//! Every run is bounded in count and time, and only loopback targets are
//! accepted unless the caller says `allow_remote`: a load generator pointed
//! at someone else's server by a typo is an attack.
//!
//! `histogram`, `clock`, `lateness`, `ramp`, `motion` and `walk` are pure (unit-tested);
//! `unary` and `streams` drive the network (`broadcast` creates the
//! broadcast); `floor` is the bare sender and its run; `procstat` reads `/proc`.

mod broadcast;
mod chain;
mod clock;
pub mod floor;
mod histogram;
mod lateness;
mod motion;
mod procstat;
pub mod ramp;
mod report;
mod setup;
mod streams;
mod unary;
mod walk;
pub mod watch;

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, bail};
use reqwest::Url;

pub use motion::{MotionChoice, SetCycle};
pub use report::FloorReport;
pub use report::Report;

/// What to load.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    GrpcSample,
    GrpcPing,
    RestPose,
    RestHealth,
    GrpcStream,
    WsStream,
    WsBroadcast,
}

impl Mode {
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::GrpcSample => "grpc-sample",
            Mode::GrpcPing => "grpc-ping",
            Mode::RestPose => "rest-pose",
            Mode::RestHealth => "rest-health",
            Mode::GrpcStream => "grpc-stream",
            Mode::WsStream => "ws-stream",
            Mode::WsBroadcast => "ws-broadcast",
        }
    }

    pub fn is_stream(self) -> bool {
        matches!(self, Mode::GrpcStream | Mode::WsStream | Mode::WsBroadcast)
    }
}

/// The most workers or streams one run may open.
pub const MAX_CONCURRENCY: usize = 100_000;
/// The longest window one run (or one ramp stage) may measure.
pub const MAX_DURATION: Duration = Duration::from_secs(3600);

/// Which clip the load uses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ClipChoice {
    /// A clip already on the server.
    Existing(String),
    /// Upload a generated chain of this many joints (see `chain::chain_clip`).
    Generate { joints: usize },
}

/// A run, as the CLI (or a test) describes it.
#[derive(Debug, Clone)]
pub struct Options {
    pub mode: Mode,
    /// The REST base URL, e.g. `http://127.0.0.1:8080`.
    pub http: String,
    /// The gRPC URL, e.g. `http://127.0.0.1:50051`.
    pub grpc: String,
    pub allow_remote: bool,
    /// Unary workers, or streams.
    pub concurrency: usize,
    /// gRPC: HTTP/2 connections the workers or streams share (0: one per
    /// 100 streams, one per worker for unary). REST: one per worker.
    pub connections: usize,
    pub duration: Duration,
    /// Unary: stop after this many requests (or the duration, whichever first).
    pub requests: Option<u64>,
    /// Unary: requests per second, open loop.
    pub rate: Option<f64>,
    pub clip: ClipChoice,
    pub fps: u32,
    pub shared: bool,
    /// Streams: play this motion of generated clips instead of the clip.
    pub motion: Option<MotionChoice>,
    /// WebSocket streams: play the motion document of this file (its
    /// `"clip": "name:X"` looked up) instead of a generated clip.
    pub motion_file: Option<PathBuf>,
    /// With a graph motion file: a parameter each stream sets once a second.
    pub set_cycle: Option<motion::SetCycle>,
    /// WebSocket frames as protobuf instead of JSON.
    pub ws_protobuf: bool,
    pub ramp: Option<ramp::RampPlan>,
    /// The server process for `/proc` readings; `None`: found by its
    /// listening port when it runs on this machine.
    pub server_pid: Option<u32>,
    /// Streams: after the server, measure the floor (`floor`), run as this
    /// `inbetween` binary's hidden `load-floor` subcommand.
    pub floor: Option<PathBuf>,
}

/// Runs the load and returns its report.
///
/// # Errors
/// A non-loopback target without `allow_remote`, out-of-bounds options, a
/// server that cannot be reached or refuses the clip upload.
pub async fn run(opts: Options) -> anyhow::Result<Report> {
    check_options(&opts)?;
    let http = checked_url(&opts.http, opts.allow_remote).context("--http")?;
    let grpc = checked_url(&opts.grpc, opts.allow_remote).context("--grpc")?;
    let server_pid = opts.server_pid.or_else(|| local_listener(&http));
    let (clip_id, motion) = match (&opts.clip, opts.mode, opts.motion, &opts.motion_file) {
        (_, Mode::GrpcPing | Mode::RestHealth, _, _) => (String::new(), None),
        (_, _, _, Some(path)) => {
            let doc = watch::Names::new(http.as_str(), None).resolve(watch::read_json(path)?).await?;
            let playable = motion::Playable::from_json(doc);
            (playable.first(), Some(playable))
        }
        (ClipChoice::Generate { joints }, _, Some(choice), None) => {
            let clips = setup::upload_motion_clips(&http, choice, *joints).await?;
            (clips.first().to_owned(), Some(motion::Playable::new(&clips, *joints)))
        }
        (ClipChoice::Existing(id), _, _, None) => (id.clone(), None),
        (ClipChoice::Generate { joints }, _, None, None) => (setup::upload_chain(&http, *joints).await?, None),
    };
    let env = Env { http, grpc, clip_id, motion, server_pid };
    let Some(plan) = opts.ramp else {
        return run_once(&opts, &env, opts.concurrency).await;
    };
    let mut ramp = ramp::Ramp::new(plan);
    let mut last = None;
    while let Some(n) = ramp.current() {
        let report = run_once(&opts, &env, n).await?;
        ramp.record(report.p99_us(), report.loss_ratio(), report.error_count());
        last = Some(report);
    }
    let mut report = last.context("the ramp ran no stage: its start must be within 1..=max")?;
    report.ramp =
        Some(report::RampReport { plan, stages: ramp.stages().to_vec(), knee: ramp.knee(), broke_at: ramp.broke_at() });
    Ok(report)
}

/// What every stage of a run shares.
pub struct Env {
    pub http: Url,
    pub grpc: Url,
    /// The first layer's clip when streams play a motion.
    pub clip_id: String,
    pub motion: Option<motion::Playable>,
    pub server_pid: Option<u32>,
}

async fn run_once(opts: &Options, env: &Env, n: usize) -> anyhow::Result<Report> {
    let mut report =
        if opts.mode.is_stream() { streams::run(opts, env, n, None).await? } else { unary::run(opts, env, n).await? };
    if let Some(bin) = &opts.floor {
        report.floor = Some(floor::measure(opts, env, n, bin, &report).await?);
    }
    report.joints = match opts.clip {
        ClipChoice::Generate { joints } => Some(joints),
        ClipChoice::Existing(_) => None,
    };
    report.motion = match &opts.motion_file {
        Some(path) => Some(path.display().to_string()),
        None => opts.motion.map(|m| m.as_str().to_owned()),
    };
    report.loadavg = std::fs::read_to_string("/proc/loadavg").ok().map(|s| s.trim().to_owned());
    Ok(report)
}

fn check_options(o: &Options) -> anyhow::Result<()> {
    if o.motion_file.is_some() && (o.mode != Mode::WsStream || o.motion.is_some() || o.floor.is_some()) {
        bail!("--motion-file plays on ws-stream only, without --motion or --floor");
    }
    if o.set_cycle.is_some() && o.motion_file.is_none() {
        bail!("--set needs a --motion-file whose layer is a graph");
    }
    if !(1..=MAX_CONCURRENCY).contains(&o.concurrency) {
        bail!("--concurrency must be 1..={MAX_CONCURRENCY}");
    }
    if o.connections > MAX_CONCURRENCY {
        bail!("--connections must be at most {MAX_CONCURRENCY}");
    }
    if o.duration.is_zero() || o.duration > MAX_DURATION {
        bail!("--duration must be more than 0 and at most an hour");
    }
    if let Some(r) = o.rate
        && !(r.is_finite() && r > 0.0 && r <= 10_000_000.0)
    {
        bail!("--rate must be a positive number of requests per second (at most 10 000 000)");
    }
    if !(1..=240).contains(&o.fps) {
        bail!("--fps must be 1..=240");
    }
    if let ClipChoice::Generate { joints } = o.clip
        && !(1..=4096).contains(&joints)
    {
        bail!("--joints must be 1..=4096");
    }
    if o.motion.is_some() && !o.mode.is_stream() {
        bail!("--motion is for the stream modes (grpc-stream, ws-stream, ws-broadcast)");
    }
    if o.motion.is_some() && matches!(o.clip, ClipChoice::Existing(_)) {
        bail!("--motion plays generated clips: it cannot be given with --clip");
    }
    if let (Some(m), ClipChoice::Generate { joints }) = (o.motion, &o.clip)
        && *joints < m.min_joints()
    {
        bail!("--motion {} needs --joints {} or more", m.as_str(), m.min_joints());
    }
    if let Some(p) = &o.ramp
        && !(p.start >= 1 && p.start <= p.max && p.max <= MAX_CONCURRENCY && p.factor >= 1.0)
    {
        bail!("--ramp needs 1 <= start <= max <= {MAX_CONCURRENCY} and a factor >= 1");
    }
    if o.floor.is_some() && !matches!(o.mode, Mode::GrpcStream | Mode::WsStream) {
        bail!("--floor is for grpc-stream and ws-stream");
    }
    if o.floor.is_some() && o.ramp.is_some() {
        bail!("--floor measures one load: it cannot be given with --ramp");
    }
    Ok(())
}

/// Parses `url` and refuses a host that is not loopback unless allowed.
/// Host names other than `localhost` are refused too: what they resolve
/// to is not known here.
pub fn checked_url(url: &str, allow_remote: bool) -> anyhow::Result<Url> {
    let parsed = Url::parse(url).with_context(|| format!("`{url}` is not a URL"))?;
    if parsed.scheme() != "http" {
        bail!("`{url}`: only http:// targets are supported");
    }
    let host = parsed.host_str().unwrap_or_default();
    let loopback = host.eq_ignore_ascii_case("localhost")
        || host
            .trim_start_matches('[')
            .trim_end_matches(']')
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback());
    if !loopback && !allow_remote {
        bail!("`{url}` is not a loopback address; pass --allow-remote to load a server on another machine");
    }
    Ok(parsed)
}

/// The pid of the process listening on the REST port, if it is local.
fn local_listener(http: &Url) -> Option<u32> {
    let addr = http.socket_addrs(|| Some(80)).ok()?.into_iter().find(|a| a.ip().is_loopback())?;
    procstat::find_listener(addr)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_loopback_targets_unless_allowed() {
        for ok in ["http://127.0.0.1:8080", "http://127.9.9.9:1", "http://[::1]:50051", "http://localhost:8080"] {
            assert!(checked_url(ok, false).is_ok(), "{ok}");
        }
        for remote in ["http://10.0.0.1:8080", "http://example.com", "http://[2001:db8::1]:80"] {
            let err = checked_url(remote, false).unwrap_err().to_string();
            assert!(err.contains("--allow-remote"), "{remote}: {err}");
            assert!(checked_url(remote, true).is_ok(), "{remote}");
        }
        assert!(checked_url("https://127.0.0.1", false).is_err());
        assert!(checked_url("not a url", true).is_err());
    }

    fn stream_options(mode: Mode, clip: ClipChoice) -> Options {
        Options {
            mode,
            http: String::new(),
            grpc: String::new(),
            allow_remote: false,
            concurrency: 1,
            connections: 0,
            duration: Duration::from_secs(1),
            requests: None,
            rate: None,
            clip,
            fps: 60,
            shared: false,
            motion: Some(MotionChoice::ThreeLayers),
            motion_file: None,
            set_cycle: None,
            ws_protobuf: false,
            ramp: None,
            server_pid: None,
            floor: None,
        }
    }

    #[test]
    fn a_motion_is_for_streams_of_generated_clips() {
        let generated = ClipChoice::Generate { joints: 64 };
        for mode in [Mode::GrpcStream, Mode::WsStream, Mode::WsBroadcast] {
            assert!(check_options(&stream_options(mode, generated.clone())).is_ok(), "{mode:?}");
        }
        let err = check_options(&stream_options(Mode::RestPose, generated)).unwrap_err().to_string();
        assert!(err.contains("stream modes"), "{err}");
        let err = check_options(&stream_options(Mode::WsStream, ClipChoice::Existing("x".into()))).unwrap_err();
        assert!(err.to_string().contains("--clip"), "{err}");
    }

    #[test]
    fn the_floor_is_for_independent_stream_modes_without_a_ramp() {
        let floor = |mode| Options {
            floor: Some("inbetween".into()),
            ..stream_options(mode, ClipChoice::Generate { joints: 20 })
        };
        for mode in [Mode::GrpcStream, Mode::WsStream] {
            assert!(check_options(&floor(mode)).is_ok(), "{mode:?}");
        }
        for mode in [Mode::WsBroadcast, Mode::RestPose] {
            let err = check_options(&Options { motion: None, ..floor(mode) }).unwrap_err().to_string();
            assert!(err.contains("--floor"), "{mode:?}: {err}");
        }
        let plan = ramp::RampPlan { start: 1, factor: 2.0, max: 4, target_p99_us: 1e3, max_loss_ratio: 0.0 };
        let err = check_options(&Options { ramp: Some(plan), ..floor(Mode::GrpcStream) }).unwrap_err();
        assert!(err.to_string().contains("--ramp"), "{err}");
    }

    #[test]
    fn foot_ik_needs_two_legs() {
        let foot_ik = |mode, joints| Options {
            motion: Some(MotionChoice::FootIk),
            ..stream_options(mode, ClipChoice::Generate { joints })
        };
        for mode in [Mode::GrpcStream, Mode::WsStream] {
            assert!(check_options(&foot_ik(mode, 7)).is_ok(), "{mode:?}");
            let err = check_options(&foot_ik(mode, 6)).unwrap_err().to_string();
            assert!(err.contains("foot-ik") && err.contains("--joints 7"), "{err}");
        }
    }
}
