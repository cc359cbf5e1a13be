//! The load generator against a real server: every mode for about a second
//! against `Application` on 127.0.0.1:0, checking that each report is
//! complete and agrees with what the run must have produced (a 30 fps stream
//! delivers ≈ 30 frames a second, a request budget is spent exactly, an open
//! loop sends at its rate). Timing figures themselves are never asserted
//! beyond sanity: speed is measured by `bench/run.sh`, not tested.

use std::time::Duration;

use load::{self, ClipChoice, Mode, MotionChoice, Options, Report, SetCycle, ramp::RampPlan};

use crate::common::{ServerProcess, TestApp};

async fn spawn_app() -> TestApp {
    TestApp::builder()
        .configure(|c| {
            c.limits.max_streams = 4096;
            c.limits.max_streams_per_client = 4096;
        })
        .start()
        .await
}

fn options(app: &TestApp, mode: Mode) -> Options {
    options_at(app.url(""), app.grpc_url(), mode)
}

fn options_at(http: String, grpc: String, mode: Mode) -> Options {
    Options {
        mode,
        http,
        grpc,
        allow_remote: false,
        concurrency: 4,
        connections: 0,
        duration: Duration::from_secs(1),
        requests: None,
        rate: None,
        clip: ClipChoice::Generate { joints: 20 },
        fps: 30,
        shared: false,
        motion: None,
        motion_file: None,
        set_cycle: None,
        ws_protobuf: false,
        ramp: None,
        server_pid: None,
        floor: None,
    }
}

async fn run(opts: Options) -> Report {
    tokio::time::timeout(Duration::from_secs(60), load::run(opts)).await.expect("the run is bounded").expect("runs")
}

/// What every report must hold, whatever the mode, for a server in this
/// process.
fn check_common(r: &Report, mode: &str) {
    check_common_of(r, mode, std::process::id());
}

/// [`check_common`] for the server process `pid`.
fn check_common_of(r: &Report, mode: &str, pid: u32) {
    assert_eq!(r.mode, mode);
    assert!(r.errors.is_empty(), "{mode}: errors {:?}", r.errors);
    assert!(r.ok > 0 && r.throughput > 0.0, "{mode}: {r:?}");
    assert!((r.throughput - r.ok as f64 / r.elapsed_secs).abs() < 1e-6 * r.throughput.max(1.0));
    // The server is found by its listening port.
    let server = r.server.as_ref().expect("the local server is measured");
    assert_eq!(server.pid, pid);
    assert!(server.rss_end_bytes > 1 << 20 && server.cpu_cores >= 0.0, "{server:?}");
    assert!(r.loadavg.is_some());
    let json: serde_json::Value = serde_json::to_value(r).unwrap();
    for key in ["mode", "throughput", "errors", "server", "elapsed_secs"] {
        assert!(json.get(key).is_some(), "{key} missing from the JSON report");
    }
}

fn check_unary(r: &Report, mode: &str) {
    check_common(r, mode);
    let l = r.latency.expect("unary reports latency");
    assert_eq!(l.count, r.ok);
    assert!(l.p50_us > 0.0 && l.p50_us <= l.p90_us && l.p90_us <= l.p99_us && l.p99_us <= l.max_us, "{l:?}");
    assert!(r.streams.is_none());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unary_modes_report_latency_and_throughput() {
    let app = spawn_app().await;
    for mode in [Mode::GrpcPing, Mode::GrpcSample, Mode::RestHealth, Mode::RestPose] {
        let r = run(options(&app, mode)).await;
        check_unary(&r, mode.as_str());
        assert_eq!(r.clip_id.is_empty(), matches!(mode, Mode::GrpcPing | Mode::RestHealth));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_request_budget_is_spent_exactly_and_an_open_loop_keeps_its_rate() {
    let app = spawn_app().await;
    let r =
        run(Options { requests: Some(57), duration: Duration::from_secs(30), ..options(&app, Mode::GrpcSample) }).await;
    check_unary(&r, "grpc-sample");
    assert_eq!(r.ok, 57);
    // 100 requests a second for a second: 100 scheduled, each sent (latency
    // from its schedule) or, if the server fell too far behind, counted unsent.
    let mut r = run(Options { rate: Some(100.0), concurrency: 16, ..options(&app, Mode::RestPose) }).await;
    let unsent = r.errors.remove("unsent_past_deadline").unwrap_or(0);
    check_unary(&r, "rest-pose");
    assert!((98..=100).contains(&(r.ok + unsent)), "{} sent + {unsent} unsent at 100/s for 1 s", r.ok);
    assert!(r.ok >= 50, "{} of 100 sent", r.ok);
}

async fn check_stream(opts: Options) -> Report {
    check_stream_of(opts, std::process::id()).await
}

/// [`check_stream`] for the server process `pid`.
async fn check_stream_of(opts: Options, pid: u32) -> Report {
    let (mode, shared) = (opts.mode, opts.shared);
    let motion = match &opts.motion_file {
        Some(path) => Some(path.display().to_string()),
        None => opts.motion.map(|m| m.as_str().to_owned()),
    };
    let r = run(opts).await;
    check_common_of(&r, mode.as_str(), pid);
    assert_eq!(r.motion, motion);
    let s = r.streams.as_ref().expect("stream reports");
    assert_eq!((s.streams, s.opened, s.fps, s.shared), (4, 4, 30, shared));
    // 30 fps for a second: ≈ 30 ticks per stream, each a frame or a counted
    // drop. The window counts frames by arrival, so on a busy machine a burst
    // still in flight at its end is missed: the lower bound is loose, the
    // upper one is not (nothing may be counted twice).
    let ticks = (r.ok + s.gaps) as f64 / 4.0 / r.elapsed_secs;
    assert!(ticks > 0.0 && ticks <= 33.0, "{ticks} ticks/s per stream at 30 fps");
    // The lower bounds are throughput: the slow runs check them.
    if crate::common::latency_checked() {
        assert!(ticks >= 20.0, "{ticks} ticks/s per stream at 30 fps");
        assert!(s.frames_per_stream_per_sec >= 15.0, "{}", s.frames_per_stream_per_sec);
    }
    assert_eq!(s.receive_lateness.count, r.ok);
    // A frame cannot arrive before it is sent, nor be sent before it is due
    // (to within the clock sync's error, a few µs on loopback).
    assert!(s.send_lateness.min_us >= 0.0 && s.receive_lateness.p50_us >= s.send_lateness.p50_us - 50.0, "{s:?}");
    if crate::common::latency_checked() {
        assert!(s.send_lateness.p50_us < 33_333.0, "a frame is sent within its tick: {s:?}");
    }
    assert!(s.clock.rtt_ns > 0);
    assert_eq!(s.dropped, s.gaps, "every missing tick is one the server counted");
    assert!(r.server.as_ref().unwrap().rss_per_stream_bytes.is_some());
    r
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stream_modes_deliver_the_asked_rate_and_measure_lateness() {
    let app = spawn_app().await;
    for (mode, shared, ws_protobuf) in [
        (Mode::GrpcStream, false, false),
        (Mode::GrpcStream, true, false),
        (Mode::WsStream, false, false),
        (Mode::WsStream, true, true),
    ] {
        let r = check_stream(Options { shared, ws_protobuf, ..options(&app, mode) }).await;
        assert_eq!(r.motion, None);
    }
}

/// Streams of the three-layer motion: the load uploads its three clips and
/// every stream opens with the motion (the WebSocket on `/v1/stream` with
/// its phase from the `opened` answer, gRPC in `StreamRequest.motion`,
/// whose `clip_id` is empty: a stream that did not play the motion would
/// have been refused); frames come at the rate and the report says which
/// motion played.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn motion_streams_play_three_layers_at_the_asked_rate() {
    let app = spawn_app().await;
    for (mode, shared, ws_protobuf) in
        [(Mode::GrpcStream, false, false), (Mode::WsStream, false, false), (Mode::WsStream, true, true)]
    {
        let opts = Options { motion: Some(MotionChoice::ThreeLayers), ..options(&app, mode) };
        check_stream(Options { shared, ws_protobuf, ..opts }).await;
    }
    let listed = app.list_all(100, None).await;
    let names: Vec<&str> = listed.iter().filter_map(|c| c["name"].as_str()).collect();
    for name in ["load-chain-20", "load-run-20", "load-upper-20"] {
        assert_eq!(names.iter().filter(|n| **n == name).count(), 1, "{name} held by one clip: {names:?}");
    }
    let versions: Vec<u64> = listed.iter().filter_map(|c| c["version"].as_u64()).collect();
    assert!(versions.iter().all(|&v| v == 3), "each run uploaded a new version of each: {versions:?}");
}

/// Streams of a motion file whose layer is a stored graph (`--motion-file`,
/// `--set`): every stream opens the graph at time 0 and sets `speed` once a
/// second as it plays; the settings are the server's to check, so a value
/// out of the parameter's range ends each stream with its refusal (a
/// `bad_frame`), which shows the sets are sent.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn graph_streams_from_a_motion_file_take_a_set_each_second() {
    let app = spawn_app().await;
    let (graph, _) = crate::api::graph_samples::fox_graph(&app).await;
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("graph.json");
    std::fs::write(&file, serde_json::json!({"layers": [{"graph": graph}]}).to_string()).unwrap();
    let motion_file = Some(file);
    let in_range = SetCycle::parse("speed=0.5,2.5").unwrap();
    let opts = Options { motion_file: motion_file.clone(), set_cycle: Some(in_range), ..options(&app, Mode::WsStream) };
    let r = check_stream(Options { duration: Duration::from_secs(2), ..opts }).await;
    assert_eq!(r.clip_id, graph, "the report names the graph played");
    let out_of_range = SetCycle::parse("speed=99").unwrap();
    let opts = Options { motion_file, set_cycle: Some(out_of_range), ..options(&app, Mode::WsStream) };
    let r = run(Options { duration: Duration::from_secs(2), ..opts }).await;
    assert!(r.errors.get("bad_frame").is_some_and(|&n| n > 0), "a refused set ends its stream: {:?}", r.errors);
}

/// Streams of the foot-ik motion (issue 17): the load uploads its walk and
/// every stream opens with the motion and its two `two_bone` constraints —
/// gRPC in `StreamRequest.motion`, the WebSocket in the `open` message with
/// JSON and protobuf frames (a constraint the server refused would be an
/// `open:` or `grpc:` error) — and frames come at the asked rate.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn foot_ik_streams_play_at_the_asked_rate() {
    let app = spawn_app().await;
    for (mode, ws_protobuf) in [(Mode::GrpcStream, false), (Mode::WsStream, false), (Mode::WsStream, true)] {
        let opts = Options { motion: Some(MotionChoice::FootIk), ..options(&app, mode) };
        check_stream(Options { ws_protobuf, ..opts }).await;
    }
    let listed = app.list_all(100, None).await;
    let names: Vec<&str> = listed.iter().filter_map(|c| c["name"].as_str()).collect();
    assert_eq!(names, ["load-walk-20"], "names identify clips: one walk");
    assert_eq!(listed[0]["version"], 3, "uploaded once per run, each a new version");
}

/// Viewers of one broadcast (docs/broadcasts.md; issue 19): the load creates a
/// broadcast of the clip (or of a motion), opens its viewers on
/// `/v1/broadcasts/{id}/stream` in JSON and protobuf, and measures them
/// like any stream; the server evaluates the broadcast once per tick
/// whatever the number of viewers (≈ 30 ticks in the 1 s window for 4
/// viewers, where 4 independent streams would be ≈ 120), exactly one
/// broadcast is created per run, and it is deleted when the run ends. The
/// counters are the server's `/metrics`, which an in-process server shares
/// with every other test's broadcasts, so this one is a server process.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn broadcast_viewers_get_the_asked_rate_from_one_evaluation_per_tick() {
    let app = ServerProcess::serve().start().await;
    let cases = [(false, None), (true, None), (true, Some(MotionChoice::ThreeLayers))];
    for (ws_protobuf, motion) in cases {
        let at = options_at(app.base(), app.grpc_url(), Mode::WsBroadcast);
        let opts = Options { shared: true, ws_protobuf, motion, ..at };
        let r = check_stream_of(opts, app.pid() as u32).await;
        let s = r.streams.as_ref().unwrap();
        assert_eq!(s.encoding, if ws_protobuf { "protobuf" } else { "json" });
        assert_eq!(s.playbacks_started, Some(1), "one broadcast per run");
        let id = s.broadcast_id.as_deref().expect("the report names its broadcast");
        let ticks = s.ticks_evaluated.expect("the broadcast counters are read") as f64 / r.elapsed_secs;
        assert!((20.0..=33.0).contains(&ticks), "{ticks} evaluated ticks/s for 4 viewers at 30 fps");
        let gone = reqwest::get(app.url(&format!("/v1/broadcasts/{id}"))).await.unwrap();
        assert_eq!(gone.status(), 404, "the run deletes its broadcast");
    }
}

/// The streaming floor (issue 19): after the server's streams, the same
/// run starts the real binary's bare sender (`inbetween load-floor`), which
/// sends a frame the server sent — as raw gRPC messages for `grpc-stream`
/// (the 4 streams sharing one connection as they shared one HTTP/2
/// connection), as WebSocket text or binary frames for `ws-stream` — and
/// the same receive code measures it: every stream opens, frames arrive at
/// the asked rate on the floor's grid, the sender's own tally agrees, and
/// its CPU is read from its own process.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_floor_sends_the_servers_frame_at_the_same_rate_and_is_measured() {
    let app = spawn_app().await;
    let bin = std::path::PathBuf::from(env!("CARGO_BIN_EXE_inbetween"));
    for (mode, ws_protobuf, kind, connections) in [
        (Mode::GrpcStream, false, "tcp", 1),
        (Mode::WsStream, false, "ws-json", 4),
        (Mode::WsStream, true, "ws-protobuf", 4),
    ] {
        let r = run(Options { ws_protobuf, floor: Some(bin.clone()), ..options(&app, mode) }).await;
        check_common(&r, mode.as_str());
        let f = r.floor.as_ref().expect("a floor report");
        assert_eq!((f.kind, f.streams, f.opened, f.connections), (kind, 4, 4, connections), "{f:?}");
        assert!(f.errors.is_empty(), "{kind}: {:?}", f.errors);
        // A 20-joint pose is 20 × 10 floats in protobuf, more in JSON.
        assert!(f.frame_bytes > 800, "{kind}: a {}-byte frame", f.frame_bytes);
        let ticks = f.frames as f64 / 4.0 / f.elapsed_secs / (1.0 - f.loss_ratio);
        assert!(ticks > 0.0 && ticks <= 33.0, "{kind}: {ticks} ticks/s per stream at 30 fps");
        // The lower bounds are throughput: the slow runs check them.
        if crate::common::latency_checked() {
            assert!(ticks >= 20.0, "{kind}: {ticks} ticks/s per stream at 30 fps");
            assert!(f.frames_per_stream_per_sec >= 15.0, "{kind}: {f:?}");
        }
        assert_eq!(f.receive_lateness.count, f.frames);
        assert!(f.send_lateness.min_us >= 0.0, "{kind}: {f:?}");
        if crate::common::latency_checked() {
            assert!(f.send_lateness.p50_us < 33_333.0, "{kind}: {f:?}");
        }
        assert!(f.cpu_cores >= 0.0 && f.cpu_us_per_frame >= 0.0, "{kind}: {f:?}");
        let sent = f.sent.expect("the sender's tally");
        assert_eq!(sent.connections, connections as u64, "{kind}: {sent:?}");
        assert!(sent.frames >= f.frames, "{kind}: the sender wrote {} frames, {} arrived", sent.frames, f.frames);
        let json = serde_json::to_value(&r).unwrap();
        for key in ["cpu_us_per_frame", "server_to_floor", "frames", "loss_ratio", "receive_lateness"] {
            assert!(json["floor"].get(key).is_some(), "floor.{key} missing from the JSON report");
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_ramp_climbs_to_its_cap_or_stops_at_the_first_failing_stage() {
    let app = spawn_app().await;
    let plan = RampPlan { start: 1, factor: 2.0, max: 4, target_p99_us: 1e9, max_loss_ratio: 0.01 };
    let opts = Options { ramp: Some(plan), duration: Duration::from_millis(300), ..options(&app, Mode::GrpcPing) };
    let r = run(opts.clone()).await;
    let ramp = r.ramp.as_ref().expect("a ramp report");
    assert_eq!(ramp.stages.iter().map(|s| s.n).collect::<Vec<_>>(), [1, 2, 4]);
    assert_eq!((ramp.knee, ramp.broke_at), (Some(4), None));
    assert_eq!(r.concurrency, 4, "the report's body is the last stage");
    // No ping answers within a nanosecond: the first stage fails and the ramp stops.
    let strict = RampPlan { target_p99_us: 0.001, ..plan };
    let r = run(Options { ramp: Some(strict), ..opts }).await;
    let ramp = r.ramp.as_ref().unwrap();
    assert_eq!((ramp.stages.len(), ramp.knee, ramp.broke_at), (1, None, Some(1)));
}

#[tokio::test]
async fn remote_targets_are_refused_without_allow_remote() {
    let app = spawn_app().await;
    let opts = Options { http: "http://192.0.2.1:8080".into(), ..options(&app, Mode::RestHealth) };
    let err = load::run(opts).await.unwrap_err();
    assert!(format!("{err:#}").contains("--allow-remote"), "{err:#}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_cli_prints_a_json_report() {
    let app = spawn_app().await;
    let bin = env!("CARGO_BIN_EXE_inbetween");
    let (http, grpc) = (app.url(""), app.grpc_url());
    let args = ["load", "grpc-ping", "-c", "2", "-d", "0.5", "--json", "--http", &http, "--grpc", &grpc];
    let out = tokio::process::Command::new(bin).args(args).output().await.unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    assert_eq!(v["mode"], "grpc-ping");
    // Half a second on a loaded machine may answer no ping at all: that count is throughput, for the slow runs.
    let ok = v["ok"].as_u64().expect("an ok count");
    assert!(v["latency"]["p99_us"].as_f64().is_some(), "{v}");
    if crate::common::latency_checked() {
        assert!(ok > 0 && v["latency"]["p99_us"].as_f64().unwrap() > 0.0, "{v}");
    }
    let human = tokio::process::Command::new(bin)
        .args(&args[..args.len() - 4])
        .arg("--http")
        .arg("http://example.com")
        .output()
        .await
        .unwrap();
    assert!(!human.status.success());
    assert!(String::from_utf8_lossy(&human.stderr).contains("--allow-remote"));
}
