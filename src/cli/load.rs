//! `inbetween load`: the load generator (`load`). Flags in, a human
//! summary or a JSON report out. `inbetween load-floor` (hidden) is the bare
//! sender `load --floor` starts as its own process (`load::floor`).

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use clap::{Args, ValueEnum};

use load::floor::Kind;
use load::ramp::RampPlan;
use load::{ClipChoice, Mode, MotionChoice, Options, SetCycle};

#[derive(Debug, Clone, Copy, ValueEnum)]
enum ModeArg {
    /// gRPC `Sample` of one pose.
    GrpcSample,
    /// gRPC `Ping`: the no-op baseline of `grpc-sample`.
    GrpcPing,
    /// `GET /v1/clips/{id}/pose`.
    RestPose,
    /// `GET /healthz`: the no-op baseline of `rest-pose`.
    RestHealth,
    /// gRPC `StreamFrames` streams.
    GrpcStream,
    /// WebSocket streams (`/v1/clips/{id}/stream`; `/v1/stream` with --motion).
    WsStream,
    /// WebSocket viewers of one broadcast (`POST /v1/broadcasts` of the clip or --motion, then
    /// `/v1/broadcasts/{id}/stream`).
    WsBroadcast,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum MotionArg {
    /// Walk and run (weights 1 and 0.3, one sync group) under an upper-body layer masked to the chain's upper half.
    ThreeLayers,
    /// A walk in place (hips, two legs, a spine) with two two-bone constraints planting the feet; --joints 7 or more.
    FootIk,
}

#[derive(Debug, Args)]
pub struct LoadArgs {
    /// What to load.
    #[arg(value_enum)]
    mode: ModeArg,
    /// The server's REST base URL.
    #[arg(long, default_value = "http://127.0.0.1:8080")]
    http: String,
    /// The server's gRPC URL.
    #[arg(long, default_value = "http://127.0.0.1:50051")]
    grpc: String,
    /// Allow a target that is not a loopback address.
    #[arg(long)]
    allow_remote: bool,
    /// Unary: concurrent workers. Streams: concurrent streams.
    #[arg(long, short = 'c', default_value_t = 32)]
    concurrency: usize,
    /// gRPC HTTP/2 connections shared by the workers or streams [default: one per
    /// worker; one per 100 streams]. REST and WebSocket use one per worker or stream.
    #[arg(long, default_value_t = 0)]
    connections: usize,
    /// Seconds to measure (each ramp stage too).
    #[arg(long, short = 'd', default_value_t = 10.0)]
    duration: f64,
    /// Unary: stop after this many requests (or the duration, whichever first).
    #[arg(long)]
    requests: Option<u64>,
    /// Unary: open loop at this many requests per second (latency from the scheduled time).
    #[arg(long)]
    rate: Option<f64>,
    /// Load this existing clip instead of uploading a generated one.
    #[arg(long, conflicts_with = "joints")]
    clip: Option<String>,
    /// Joints of the generated clip (a chain of Catmull-Rom rotations).
    #[arg(long, default_value_t = 20)]
    joints: usize,
    /// Streams: frames per second.
    #[arg(long, default_value_t = 60)]
    fps: u32,
    /// Streams: play this motion of generated clips (--joints each) instead of one clip.
    #[arg(long, value_enum, conflicts_with = "clip")]
    motion: Option<MotionArg>,
    /// ws-stream: play the motion document of this file instead of a generated clip (a layer may name its clip
    /// `name:X`, looked up as `watch` does; a graph layer streams from time 0).
    #[arg(long, conflicts_with_all = ["clip", "motion"])]
    motion_file: Option<PathBuf>,
    /// With a graph --motion-file: each stream sets this parameter once a second, cycling through the values
    /// (stream i of n at 1 s + i/n s after it opened, then every second: the sets spread over the second).
    #[arg(long = "set", value_name = "NAME=V1,V2,…", value_parser = SetCycle::parse, requires = "motion_file")]
    set_cycle: Option<SetCycle>,
    /// Streams: viewers of one playback instead of independent playbacks.
    #[arg(long)]
    shared: bool,
    /// WebSocket streams: binary protobuf frames instead of JSON text.
    #[arg(long)]
    protobuf: bool,
    /// Step the load up from --concurrency until the p99 target breaks; report the knee.
    #[arg(long)]
    ramp: bool,
    /// Ramp: multiply the load by this after each passing stage.
    #[arg(long, default_value_t = 2.0)]
    ramp_factor: f64,
    /// Ramp: the largest load to try.
    #[arg(long, default_value_t = 20_000)]
    ramp_max: usize,
    /// Ramp: the p99 target in milliseconds (receive lateness for streams, latency otherwise).
    #[arg(long, default_value_t = 2.0)]
    target_p99_ms: f64,
    /// Ramp: the largest share of lost frames or failed requests a stage may have.
    #[arg(long, default_value_t = 0.001)]
    max_loss: f64,
    /// The server's process id for /proc readings [default: the local process listening on --http].
    #[arg(long)]
    server_pid: Option<u32>,
    /// grpc-stream, ws-stream: then run the same streams against a bare sender of one of the server's own
    /// frames (a process of this binary) and report its CPU per frame beside the server's.
    #[arg(long)]
    floor: bool,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(args: LoadArgs) -> anyhow::Result<()> {
    if !(args.duration.is_finite() && args.duration > 0.0) {
        anyhow::bail!("--duration must be a positive number of seconds");
    }
    let opts = Options {
        mode: match args.mode {
            ModeArg::GrpcSample => Mode::GrpcSample,
            ModeArg::GrpcPing => Mode::GrpcPing,
            ModeArg::RestPose => Mode::RestPose,
            ModeArg::RestHealth => Mode::RestHealth,
            ModeArg::GrpcStream => Mode::GrpcStream,
            ModeArg::WsStream => Mode::WsStream,
            ModeArg::WsBroadcast => Mode::WsBroadcast,
        },
        http: args.http,
        grpc: args.grpc,
        allow_remote: args.allow_remote,
        concurrency: args.concurrency,
        connections: args.connections,
        duration: Duration::try_from_secs_f64(args.duration)?,
        requests: args.requests,
        rate: args.rate,
        clip: match args.clip {
            Some(id) => ClipChoice::Existing(id),
            None => ClipChoice::Generate { joints: args.joints },
        },
        fps: args.fps,
        shared: args.shared,
        motion: args.motion.map(|m| match m {
            MotionArg::ThreeLayers => MotionChoice::ThreeLayers,
            MotionArg::FootIk => MotionChoice::FootIk,
        }),
        motion_file: args.motion_file,
        set_cycle: args.set_cycle,
        ws_protobuf: args.protobuf,
        ramp: args.ramp.then_some(RampPlan {
            start: args.concurrency,
            factor: args.ramp_factor,
            max: args.ramp_max,
            target_p99_us: args.target_p99_ms * 1000.0,
            max_loss_ratio: args.max_loss,
        }),
        server_pid: args.server_pid,
        floor: if args.floor { Some(std::env::current_exe()?) } else { None },
    };
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let report = runtime.block_on(load::run(opts))?;
    let mut out = super::results::Results::buffered();
    if args.json {
        writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        write!(out, "{}", report.human())?;
    }
    out.flush()?;
    Ok(())
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum FloorKindArg {
    /// WebSocket text frames (JSON).
    WsJson,
    /// WebSocket binary frames (protobuf).
    WsProtobuf,
    /// gRPC messages on raw TCP, without HTTP/2.
    Tcp,
}

#[derive(Debug, Args)]
pub struct FloorArgs {
    /// What to send.
    #[arg(long, value_enum)]
    kind: FloorKindArg,
    /// Frames per second.
    #[arg(long, default_value_t = 60)]
    fps: u32,
}

/// The floor process: a frame on stdin, `{"port","epoch_unix_ns"}` and at the end its tally on stdout.
pub fn run_floor(args: FloorArgs) -> anyhow::Result<()> {
    let kind = match args.kind {
        FloorKindArg::WsJson => Kind::WsJson,
        FloorKindArg::WsProtobuf => Kind::WsProtobuf,
        FloorKindArg::Tcp => Kind::Tcp,
    };
    load::floor::run_sender(kind, args.fps)
}
