//! Graph programs (docs/graphs.md, “Streams and broadcasts”): a broadcast
//! of a graph restored from any checkpoint makes the very bytes of the
//! program that stepped from tick 0 — through settings, a trigger's
//! transition, a fade back interrupted by nothing, a pause — its frames
//! carry the report, and a stream's check resolves `set` against the graph
//! and refuses what a graph stream does not take.

use std::sync::Arc;

use anim::graph::Value;
use anim::graph::{GraphPost, NodeOptions};
use anim::spring::{ChainSpec, SpringsSpec};
use anim::{Channel, Clip, ClipSpec, Interpolation, JointSpec, Keys, Playback, SkeletonSpec, TrackSpec, Transform};
use glam::Vec3;

use super::control::ControlCheck;
use super::tests::pinned;
use super::*;

/// `root` moving from 0 to `to` over `duration`, looping.
fn line(duration: f32, to: Vec3) -> Arc<Clip> {
    let track = TrackSpec::new(
        "root",
        Channel::Translation,
        Interpolation::Linear,
        vec![0.0, duration],
        Keys::Vec3(vec![Vec3::ZERO, to]),
    );
    let joint = |name: &str, parent: Option<&str>, z: f32| JointSpec {
        name: name.into(),
        parent: parent.map(Into::into),
        rest: Transform { translation: Vec3::new(0.0, 0.0, z), ..Transform::IDENTITY },
        inverse_bind: None,
    };
    let joints =
        vec![joint("root", None, 0.0), joint("tail0", Some("root"), -0.1), joint("tail1", Some("tail0"), -0.1)];
    let joints = [joints, vec![joint("tip", Some("tail1"), -0.1)]].concat();
    let spec = ClipSpec {
        name: "line".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks: vec![track],
        playback: Playback::Loop,
        ..Default::default()
    };
    Arc::new(Clip::build(&spec).unwrap())
}

/// `s` blends two lines in one sync group; the trigger `go` fades to the
/// third, and `s` under 0.5 fades back; with `springs`, the motion's tail
/// swings on it.
fn graph_params(springs: bool) -> StreamParams {
    graph_params_with(springs, &NodeOptions::default())
}

/// [`graph_params`], the nodes built with `options`.
fn graph_params_with(springs: bool, options: &NodeOptions) -> StreamParams {
    graph_params_mixed(springs, options, false)
}

/// [`graph_params_with`]; `mixed`: the graph's layer under a line at
/// weight 0.5 and an additive line at weight 0.5 (docs/graphs.md, “What
/// composes with a graph”).
fn graph_params_mixed(springs: bool, options: &NodeOptions, mixed: bool) -> StreamParams {
    let doc = serde_json::json!({"name": "g",
        "parameters": {"s": {"type": "float", "default": 0, "min": 0, "max": 1}, "go": {"type": "trigger"}},
        "nodes": {"mix": {"blend1d": {"parameter": "s", "points": [{"clip": "a", "at": 0}, {"clip": "b", "at": 1}]}},
                  "c": {"clip": "c"}},
        "machine": {"initial": "mix", "states": {"mix": {"node": "mix"}, "c": {"node": "c"}},
            "transitions": [{"from": "mix", "to": "c", "when": {"trigger": "go"}, "duration": 0.3},
                            {"from": "c", "to": "mix", "when": {"parameter": "s", "lt": 0.5}, "duration": 0.4,
                             "ease": "ease_in_out"}]}});
    let clips = [("a", line(1.0, Vec3::X)), ("b", line(0.6, Vec3::new(0.0, 0.0, 2.0))), ("c", line(0.8, Vec3::Y))];
    let doc = formats::wire::graph::parse_graph_doc(doc.to_string().as_bytes()).unwrap();
    let clip = |id: &str, _: &str| Ok(pinned(id, Arc::clone(&clips.iter().find(|(n, _)| *n == id).unwrap().1)));
    let graph = doc.compile_with("", clip, options).unwrap();
    let mut chain = ChainSpec::new("tail", &["tail0", "tail1", "tip"]);
    chain.params.gravity = Vec3::new(0.0, -9.81, 0.0);
    let chains = if springs { vec![chain] } else { Vec::new() };
    let spec = SpringsSpec { chains, ..SpringsSpec::default() };
    let graph = Arc::new(graph);
    let post = if mixed {
        let layer = |id: &str, clip: Arc<Clip>, mode| anim::motion::LayerSpec {
            weight: 0.5,
            mode,
            ..anim::motion::LayerSpec::new(pinned(id, clip))
        };
        let layers = vec![
            layer("g", line(1.0, Vec3::X), anim::motion::LayerMode::Blend),
            layer("d", line(0.7, Vec3::new(0.0, 3.0, 0.0)), anim::motion::LayerMode::Blend),
            layer("e", line(0.9, Vec3::new(-1.0, 0.0, 1.0)), anim::motion::LayerMode::Additive),
        ];
        let spec = anim::motion::MotionSpec { layers, springs: spec, ..Default::default() };
        GraphPost::mixed(spec, 0, &graph, &Default::default()).unwrap()
    } else {
        GraphPost::build(&[], &spec, graph.skeleton(), &Default::default()).unwrap()
    };
    let post = Arc::new(post);
    let program = GraphProgram { graph, post, id: "g".into(), version: 1, report: true };
    let req = StreamRequest { fps: 30, ..Default::default() };
    let motion = Arc::clone(program.post.mix().unwrap_or(program.graph.initial_motion()));
    StreamParams::of_motion(motion, "g".into(), req).unwrap().with_graph(program)
}

fn log(params: &StreamParams) -> ControlLog {
    let graph = &params.graph.as_ref().unwrap().graph;
    let (s, go) = (graph.parameter_index("s").unwrap(), graph.parameter_index("go").unwrap());
    let schedule = [
        (5, Control::SetGraph(vec![(s, Value::Float(0.7))])),
        (12, Control::SetGraph(vec![(go, Value::Bool(true))])),
        (20, Control::Pause),
        (26, Control::Play),
        (40, Control::SetGraph(vec![(s, Value::Float(0.2))])),
    ];
    let mut log = ControlLog::default();
    for (seq, control) in schedule {
        log.insert(StampedControl { seq, id: new_control_id(), control });
    }
    log
}

fn frame_at(p: &mut Program, k: u64, log: &ControlLog) -> bytes::Bytes {
    p.step_to(k, log);
    p.encode(Encoding::Json, 0).bytes
}

fn report(bytes: &bytes::Bytes) -> serde_json::Value {
    serde_json::from_slice::<serde_json::Value>(bytes).unwrap()["graph"].clone()
}

/// Frames 0..80 of `params` under `log`, and a checkpoint every `EVERY` ticks.
fn uninterrupted(params: &StreamParams, log: &ControlLog) -> (Vec<bytes::Bytes>, Vec<String>) {
    let mut reference = Program::new(params).checkpointing(EVERY);
    let mut frames = Vec::new();
    let mut texts = Vec::new();
    for k in 0..80 {
        frames.push(frame_at(&mut reference, k, log));
        if (k + 1) % EVERY == 0 {
            texts.push(reference.checkpoint().unwrap().to_text());
        }
    }
    (frames, texts)
}

const EVERY: u64 = 8;

/// Every checkpoint of `texts` restored steps on to `frames`' very bytes.
fn assert_restores(params: &StreamParams, log: &ControlLog, frames: &[bytes::Bytes], texts: &[String]) {
    for (i, text) in texts.iter().enumerate() {
        let checkpoint = Checkpoint::from_text(text).unwrap();
        let c = (i as u64 + 1) * EVERY - 1;
        let mut restored = Program::from_checkpoint(params, &checkpoint, log).unwrap();
        for k in c + 1..80 {
            assert_eq!(frame_at(&mut restored, k, log), frames[k as usize], "tick {k} from the checkpoint of {c}");
        }
    }
}

#[test]
fn a_graph_program_restored_from_any_checkpoint_makes_the_same_bytes() {
    let params = graph_params(false);
    let log = log(&params);
    let (frames, texts) = uninterrupted(&params, &log);
    let weights = |k: usize| -> Vec<f64> {
        report(&frames[k])["weights"]["mix"].as_array().unwrap().iter().map(|w| w.as_f64().unwrap()).collect()
    };
    assert_eq!(weights(4), [1.0, 0.0]);
    assert_eq!(weights(5), [1.0 - 0.7, 0.7], "the setting from its tick");
    assert_eq!(report(&frames[12])["transition"]["to"], "c", "the trigger fires at its tick");
    let shown = |k: usize| {
        let v = serde_json::from_slice::<serde_json::Value>(&frames[k]).unwrap();
        (v["pose"].clone(), v["graph"].clone())
    };
    assert_eq!(shown(21), shown(25), "paused frames repeat the pose and the report");
    assert_ne!(shown(26), shown(25), "play goes on");
    assert_eq!(report(&frames[40])["transition"]["to"], "mix", "s under 0.5 fades back");
    assert_restores(&params, &log, &frames, &texts);
}

#[test]
fn a_graph_among_clip_layers_restored_from_any_checkpoint_makes_the_same_bytes() {
    for springs in [false, true] {
        let (alone, mixed) = (graph_params(springs), graph_params_mixed(springs, &NodeOptions::default(), true));
        let log = log(&mixed);
        let (frames, texts) = uninterrupted(&mixed, &log);
        let (graph_alone, _) = uninterrupted(&alone, &log);
        let shown = |bytes: &bytes::Bytes| {
            let v = serde_json::from_slice::<serde_json::Value>(bytes).unwrap();
            (v["pose"]["joints"].clone(), v["graph"].clone())
        };
        for k in 0..80 {
            let ((mixed_pose, mixed_report), (alone_pose, alone_report)) = (shown(&frames[k]), shown(&graph_alone[k]));
            assert_eq!(mixed_report, alone_report, "the report is the graph's, tick {k}");
            // Every line starts at the origin: from tick 1 on the clip layers move the root.
            assert!(k == 0 || mixed_pose != alone_pose, "the clip layers move the root, tick {k}");
        }
        let (a, b) = (shown(&frames[21]), shown(&frames[25]));
        assert_eq!((&a.0[0], &a.1), (&b.0[0], &b.1), "paused, the mixed root holds with the graph's (springs settle)");
        assert_restores(&mixed, &log, &frames, &texts);
    }
}

#[test]
fn springs_on_a_graph_swing_and_a_restored_program_makes_the_same_bytes() {
    let (plain, sprung) = (graph_params(false), graph_params(true));
    let log = log(&sprung);
    let (frames, texts) = uninterrupted(&sprung, &log);
    let (unsprung, _) = uninterrupted(&plain, &log);
    let pose = |bytes: &bytes::Bytes| serde_json::from_slice::<serde_json::Value>(bytes).unwrap()["pose"].clone();
    assert_eq!(pose(&frames[0]), pose(&unsprung[0]), "the chains start at rest: the first frame is the graph's");
    let turned = (1..80).filter(|&k| pose(&frames[k]) != pose(&unsprung[k])).count();
    assert!(turned >= 70, "the tail swings on {turned} of 79 ticks");
    let (a, b) = (pose(&frames[22]), pose(&frames[24]));
    assert_ne!(a, b, "paused, the graph's pose holds and the chains go on settling");
    assert_eq!(a["joints"][0], b["joints"][0], "…the graph's own joints held");
    assert_restores(&sprung, &log, &frames, &texts);
}

#[test]
fn a_graph_streams_check_resolves_set_and_refuses_what_a_graph_does_not_take() {
    let params = graph_params(false);
    let mut check = ControlCheck::new(&params);
    let set = |doc: serde_json::Value| Control::Set(serde_json::from_value(doc).unwrap());
    let s = params.graph.as_ref().unwrap().graph.parameter_index("s").unwrap();
    assert_eq!(check.check(set(serde_json::json!({"s": 0.5}))), Ok(Control::SetGraph(vec![(s, Value::Float(0.5))])));
    for (doc, code, pointer) in [
        (serde_json::json!({"x": 1}), "unknown_parameter", "/parameters/x"),
        (serde_json::json!({"s": 2}), "parameter_out_of_range", "/parameters/s"),
        (serde_json::json!({"go": 0.5}), "parameter_type", "/parameters/go"),
    ] {
        let e = check.check(set(doc)).unwrap_err();
        assert_eq!((e.code(), e.pointer().as_deref()), (code, Some(pointer)));
    }
    for control in [Control::Seek(1.0), Control::Speed(2.0), Control::Ik(Vec::new())] {
        assert_eq!(check.check(control).unwrap_err().code(), "graph_unsupported");
    }
    assert_eq!(check.check(Control::ResetSprings), Ok(Control::ResetSprings), "a motion's springs on a graph restart");
    assert_eq!(check.check(Control::Pause), Ok(Control::Pause));
    let plain = StreamParams::new(pinned("a", line(1.0, Vec3::X)), StreamRequest { fps: 30, ..Default::default() });
    let e = ControlCheck::new(&plain.unwrap()).check(set(serde_json::json!({"s": 0.5}))).unwrap_err();
    assert_eq!(e.code(), "graph_unsupported");
}

#[test]
fn root_motion_on_a_graph_rides_its_frames_and_a_restored_program_makes_the_same_bytes() {
    let root = anim::motion::RootMotionSpec { joint: Some("root".into()), ..Default::default() };
    let params = graph_params_with(false, &NodeOptions { root_motion: Some(root), ..Default::default() });
    let log = log(&params);
    let (frames, texts) = uninterrupted(&params, &log);
    let root_motion =
        |k: usize| serde_json::from_slice::<serde_json::Value>(&frames[k]).unwrap()["pose"]["root_motion"].clone();
    let x = |k: usize, which: &str| root_motion(k)[which]["translation"][0].as_f64().unwrap();
    // Line a walks 1 on x a second: 1/30 a tick at 30 fps, until `s` brings in b (which walks on z).
    assert_eq!((x(0, "delta"), x(0, "total")), (0.0, 0.0));
    assert!((x(3, "delta") - 1.0 / 30.0).abs() < 1e-6 && (x(3, "total") - 0.1).abs() < 1e-6, "{}", root_motion(3));
    // Paused from tick 20 to 26: the root holds, its deltas 0.
    for k in 21..=25 {
        assert_eq!(x(k, "delta"), 0.0, "tick {k}: {}", root_motion(k));
        assert_eq!(root_motion(k)["total"], root_motion(20)["total"], "tick {k}");
    }
    // Line c moves up, not on the ground; `s` at 0.2 fades back to the mix of a (on x) and b (on z).
    assert!(x(50, "delta") > 0.0, "play goes on: {}", root_motion(50));
    assert_restores(&params, &log, &frames, &texts);
}

#[test]
fn a_frame_woken_late_runs_the_substeps_of_its_latest_skipped_ticks_only() {
    // The graph's tail at the default 120 Hz, on a 60 fps stream: 2 substeps a tick.
    let params = graph_params(true);
    let springs = params.graph.as_ref().unwrap().post.springs().unwrap();
    let mut solver = anim::spring::SpringSolver::new(springs);
    solver.skip_to(springs, 0.5);
    assert_eq!(solver.pending(springs, 1.0), 0, "at rest: the next frame starts there");
    solver.start_at(springs, 0.0, &anim::Pose::identity(4));
    assert_eq!(solver.pending(springs, 1.0), 120, "a frame at 1 s after one at 0 runs a second of substeps");
    // Tick 60 woken late: the substeps after tick 60 − MAX_CATCH_UP − 1 only.
    let fps = 60.0;
    solver.skip_to(springs, (60 - MAX_CATCH_UP - 1) as f64 / fps);
    assert_eq!(solver.pending(springs, 1.0), 2 * (MAX_CATCH_UP + 1));
    solver.skip_to(springs, 0.25);
    assert_eq!(solver.pending(springs, 1.0), 2 * (MAX_CATCH_UP + 1), "never back");
}

#[test]
fn a_late_graph_frame_evaluates_its_latest_skipped_ticks_and_steps_the_older_ones() {
    let params = graph_params(true);
    let program = params.graph.as_ref().unwrap();
    assert!(program.catches_up(), "springs: skipped ticks are evaluated");
    let space = anim::Space::Local;
    let on_time = |last: u64| {
        let mut deck = graph::GraphDeck::new(program, space);
        for k in 0..=last {
            deck.tick(30, false, (k, 0));
        }
        deck
    };
    // Woken late by MAX_CATCH_UP ticks: every one evaluated, the frame a play that never skipped shows.
    let mut late = on_time(20);
    late.tick(30, false, (21 + MAX_CATCH_UP, MAX_CATCH_UP));
    assert_eq!(late.pose(), on_time(21 + MAX_CATCH_UP).pose());
    // Woken 40 ticks late: the graph steps every tick (its state is the same), the chains skip the older
    // ticks' substeps and so swing otherwise.
    let mut later = on_time(20);
    later.tick(30, false, (61, 40));
    let never = on_time(61);
    assert_eq!(later.state().0, never.state().0, "every tick stepped");
    assert_ne!(later.pose(), never.pose(), "the chains caught up 4 ticks of 40");
    assert_eq!(later.state().1.map(|s| s.next), never.state().1.map(|s| s.next), "both at tick 61's substep");
}

/// The local rotations of a JSON frame's joints.
fn frame_rotations(frame: &Delivered) -> Vec<[f32; 4]> {
    let v: serde_json::Value = serde_json::from_slice(&frame.bytes).unwrap();
    let joints = v["pose"]["joints"].as_array().unwrap();
    let quat =
        |j: &serde_json::Value| -> [f32; 4] { std::array::from_fn(|i| j["rotation"][i].as_f64().unwrap() as f32) };
    joints.iter().map(quat).collect()
}

#[tokio::test(start_paused = true)]
async fn a_motion_streams_frame_woken_late_runs_the_substeps_of_its_latest_skipped_ticks_only() {
    use anim::motion::{LayerSpec, MotionOptions, MotionSpec, Player};
    let mut chain = ChainSpec::new("tail", &["tail0", "tail1", "tip"]);
    chain.params.gravity = Vec3::new(0.0, -9.81, 0.0);
    let springs = SpringsSpec { chains: vec![chain], ..SpringsSpec::default() };
    let layers = vec![LayerSpec::new(pinned("a", line(1.0, Vec3::X)))];
    let motion = Arc::new(anim::Motion::build(MotionSpec { layers, springs, ..MotionSpec::default() }).unwrap());
    let e = Engine::new(EngineConfig { max_streams: 10, max_streams_per_client: 10, ..EngineConfig::default() });
    let req = StreamRequest { fps: 30, encoding: Encoding::Json, ..StreamRequest::default() };
    let params = StreamParams::of_motion(Arc::clone(&motion), "m".into(), req).unwrap();
    let mut sub = e.watch(params, e.admit(None).unwrap(), None);
    let Next::Frame(first) = sub.next().await else { panic!("a first frame") };
    assert_eq!(first.seq, 0);
    // Stuck for a second: ticks 1..=30 fall due, 29 skipped.
    tokio::time::advance(std::time::Duration::from_millis(1000)).await;
    let Next::Frame(late) = sub.next().await else { panic!("a late frame") };
    assert_eq!((late.seq, late.dropped), (30, 29));
    // What the player shows at 1 s after 0 s: every substep of the second, or those after tick 25 only.
    let at = |skip: bool| {
        let mut player = Player::new(Arc::clone(&motion));
        player.sample_clocked(0.0, 0.0, &MotionOptions::default());
        if skip {
            player.skip_springs_to((30 - MAX_CATCH_UP - 1) as f64 / 30.0);
        }
        player.sample_clocked(1.0, 1.0, &MotionOptions::default());
        player.pose().rotations.iter().map(|q| q.to_array()).collect::<Vec<_>>()
    };
    assert_eq!(frame_rotations(&late), at(true), "the substeps of the latest 4 skipped ticks and its own");
    assert_ne!(at(true), at(false), "a second of substeps swings the tail otherwise");
}
