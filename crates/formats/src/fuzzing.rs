//! The bodies of the fuzz targets in `fuzz/`, here so that `cargo test`
//! replays the committed corpus and every past crash through exactly the
//! code libFuzzer runs (`tests/service/hardening/fuzz_replay.rs`), without libFuzzer.
//!
//! Each function takes arbitrary bytes: errors are fine, a panic is a
//! finding (the assertions state what must hold for any input).

use crate::import::{Format, ImportOptions, import, sniff};
use crate::wire::json::parse_clip;
use anim::{Clip, ClipSpec, Ease, Interpolation, Playback, SampleOptions, Sampler, Space};

/// A fuzz target's body: arbitrary bytes in, a panic is a finding.
pub type Target = fn(&[u8]);

/// The fuzz targets, by the name of their `fuzz/fuzz_targets/<name>.rs`.
pub const TARGETS: &[(&str, Target)] = &[
    ("import_gltf", import_gltf),
    ("import_bvh", import_bvh),
    ("clip_json", clip_json),
    ("import_evaluate", import_evaluate),
    ("motion_json", motion_json),
    ("graph_json", graph_json),
];

/// glTF/GLB import of arbitrary bytes; whatever imports must build.
pub fn import_gltf(data: &[u8]) {
    let format = if data.starts_with(b"glTF") { Format::Glb } else { Format::Gltf };
    if let Ok(imported) = import(data, format, &ImportOptions::default()) {
        for clip in &imported.clips {
            Clip::build(clip).expect("imported clips build");
        }
    }
}

/// BVH import of arbitrary bytes, with linear, Catmull-Rom and B-spline
/// keys (the last byte picks, so all are explored; odd bytes keep the
/// Catmull-Rom they had before B-splines came); whatever imports must build.
pub fn import_bvh(data: &[u8]) {
    let interpolation = match data.last() {
        Some(b) if b % 2 == 1 => Interpolation::CatmullRom,
        Some(b) if b % 4 == 2 => Interpolation::BSpline,
        _ => Interpolation::Linear,
    };
    let options = ImportOptions { bvh_interpolation: interpolation, ..ImportOptions::default() };
    if let Ok(imported) = import(data, Format::Bvh, &options) {
        for clip in &imported.clips {
            Clip::build(clip).expect("imported clips build");
        }
    }
}

/// A clip document: parse → build → sample at arbitrary times in every
/// playback mode and space, and as matrices.
pub fn clip_json(data: &[u8]) {
    let Ok((_, spec)) = parse_clip(data) else { return };
    let Ok(clip) = Clip::build(&spec) else { return };
    evaluate(&clip, data);
}

/// The whole upload path in one: sniff the format (glTF, GLB, BVH, else a
/// JSON clip document) → import or parse → `Clip::build` → sample at times
/// taken from the input. Every local value must be finite and every
/// rotation a unit quaternion, whatever the file held.
pub fn import_evaluate(data: &[u8]) {
    let format = sniff(data, None);
    let specs: Vec<ClipSpec> = match format {
        Some(format) => {
            let interpolation = if data.len() % 2 == 1 { Interpolation::CatmullRom } else { Interpolation::Linear };
            let options = ImportOptions { bvh_interpolation: interpolation, ..ImportOptions::default() };
            match import(data, format, &options) {
                Ok(imported) => imported.clips,
                Err(_) => return,
            }
        }
        None => match parse_clip(data) {
            Ok((_, spec)) => vec![spec],
            Err(_) => return,
        },
    };
    for spec in &specs {
        match Clip::build(spec) {
            Ok(clip) => evaluate(&clip, data),
            // `import` promised that its clips build; a document may break a rule.
            Err(e) => assert!(format.is_none(), "an imported clip does not build: {e}"),
        }
    }
}

/// A motion document (docs/motion.md, with §7's `ik`) over three fixed clips (two
/// of one skeleton, one of another; layer `clip` names pick them by their
/// length), built and
/// sampled at times from the input, then played as a stream would: weight
/// ramps and crossfades (nested) at input-chosen durations. Every local
/// value must stay finite and every rotation a unit quaternion.
pub fn motion_json(data: &[u8]) {
    use anim::motion::{MotionOptions, MotionSampler, Player};
    use std::sync::Arc;
    let Ok(doc) = serde_json::from_slice::<crate::wire::motion::MotionDoc>(data) else { return };
    let clips = motion_clips();
    let Ok(spec) = doc.to_spec("/motion") else { return };
    let spec = spec.try_map(|_, id: String| Ok::<_, ()>(&clips[id.len() % clips.len()]));
    let Ok(spec) = spec else { return };
    let Ok(motion) = anim::Motion::build(spec) else { return };
    let motion = Arc::new(motion);
    let times = chosen_times(data, 0.0, 2.0);
    let mut sampler = MotionSampler::new();
    for (i, &t) in times.iter().enumerate() {
        let space = if i % 2 == 0 { Space::Local } else { Space::Model };
        motion.sample(t, &MotionOptions { ease: Ease::Linear, space }, &mut sampler);
        check_local(sampler.local(), t);
        assert!(sampler.ik_reports().iter().all(|r| r.residual.is_finite()), "an IK residual is not finite at {t}");
    }
    let mut player = Player::new(Arc::clone(&motion));
    for (k, &b) in data.iter().rev().take(24).enumerate() {
        let duration = f64::from(b % 16) / 8.0;
        match b % 4 {
            0 => drop(player.crossfade(Arc::clone(&motion), duration, Ease::EaseInOut)),
            1 => drop(player.ramp(usize::from(b) % motion.layer_count(), f32::from(b) / 255.0, duration)),
            2 => player.seek(f64::from(b) / 10.0),
            _ => {}
        }
        player.sample(k as f64 / 30.0, &MotionOptions::default());
        check_local(player.pose(), k as f64);
    }
}

/// A graph document (docs/graphs.md) over the clips of [`motion_json`]
/// (clip ids pick them by their length), within the server's default
/// shape limits (256 nodes, 32 points a blend), built, then played tick by
/// tick with parameters set from the input's bytes (either type, in and out
/// of range, not finite) at input-chosen steps. Every local value stays
/// finite and every rotation a unit quaternion; a blend's weights are
/// finite, in [0, 1] and sum to 1; a player rebuilt from its state (a
/// broadcast checkpoint) plays on exactly as the original.
pub fn graph_json(data: &[u8]) {
    use anim::graph::{GraphPlayer, Value};
    use std::sync::Arc;
    let Ok(doc) = crate::wire::graph::parse_graph_doc(data) else { return };
    let points = |n: &crate::wire::graph::NodeDoc| {
        let one = n.blend1d.as_ref().map_or(0, |b| b.points.len());
        one.max(n.blend2d.as_ref().map_or(0, |b| b.points.len()))
    };
    if doc.nodes.len() > 256 || doc.nodes.values().any(|n| points(n) > 32) {
        return;
    }
    let clips = motion_clips();
    let Ok(graph) = doc.compile("", |id, _| Ok(&clips[id.len() % clips.len()])) else { return };
    let graph = Arc::new(graph);
    let mut player = GraphPlayer::new(Arc::clone(&graph));
    let parameters = graph.parameters().len();
    let steps = [1.0 / 60.0, 0.0, -1.0, f64::NAN, 0.5, 1e-9];
    for (k, &b) in data.iter().rev().take(48).enumerate() {
        if parameters > 0 {
            let value = match b % 5 {
                0 => Value::Bool(b & 8 != 0),
                1 => Value::Float(f64::NAN),
                2 => Value::Float(if b & 8 != 0 { 1e30 } else { -1e30 }),
                _ => Value::Float(f64::from(b) / 25.0 - 2.0),
            };
            let _ = player.set(usize::from(b) % parameters, value);
        }
        player.tick(steps[usize::from(b / 5) % steps.len()]);
        check_local(player.pose(), k as f64);
        check_report(&player);
    }
    let mut copy = GraphPlayer::from_state(Arc::clone(&graph), player.state()).expect("a player's own state fits");
    for dt in [1.0 / 60.0, 0.25] {
        player.tick(dt);
        copy.tick(dt);
        assert_eq!(copy.state(), player.state(), "a rebuilt player's state drifts");
        assert!(copy.pose() == player.pose(), "a rebuilt player's pose differs");
    }
}

/// A graph player's report: its state is the graph's, and each blend's
/// weights are finite, in [0, 1] and sum to 1.
fn check_report<C: anim::ClipSource>(player: &anim::graph::GraphPlayer<C>) {
    let report = player.report();
    assert!(player.graph().state_names().any(|s| s == report.state()), "no state {}", report.state());
    for (node, weights) in report.weights() {
        let sum: f64 = weights.iter().sum();
        assert!(weights.iter().all(|w| (-1e-9..=1.0 + 1e-9).contains(w)), "{node}'s weights {weights:?}");
        assert!((sum - 1.0).abs() < 1e-6, "{node}'s weights {weights:?} sum to {sum}");
    }
}

/// The clips [`motion_json`] composes: the wave example and two synthetic
/// clips, built once.
fn motion_clips() -> &'static [Clip] {
    static CLIPS: std::sync::OnceLock<Vec<Clip>> = std::sync::OnceLock::new();
    CLIPS.get_or_init(|| {
        let wave = include_bytes!("../../../examples/wave.json");
        let build = |doc: &[u8]| Clip::build(&parse_clip(doc).expect("a fixed clip parses").1).expect("and builds");
        let mover = |rate: f32, end: f32| {
            let doc = serde_json::json!({"name": "m", "skeleton": {"joints": [
                    {"name": "root", "parent": null}, {"name": "arm", "parent": "root"},
                    {"name": "forearm", "parent": "arm", "rest": {"translation": [0, 0.5, 0]}},
                    {"name": "hand", "parent": "forearm", "rest": {"translation": [0, 0.5, 0]}}]},
                "tracks": [{"joint": "root", "channel": "translation", "interpolation": "catmull_rom",
                    "times": [0, end / 2.0, end], "values": [[0, 0, 0], [rate, 0.5, 0], [2.0 * rate, 0, 0]]},
                    {"joint": "arm", "channel": "rotation", "times": [0, end],
                    "values": [[0, 0, 0, 1], [0, 0.6, 0, 0.8]]}],
                "playback": "loop"});
            build(doc.to_string().as_bytes())
        };
        vec![build(wave), mover(1.0, 1.0), mover(3.0, 0.6)]
    })
}

/// Times to sample: fixed extremes, the input's last 8 bytes as an `f64`,
/// and its last 16 bytes as fractions of `[start, end]`.
fn chosen_times(data: &[u8], start: f64, end: f64) -> Vec<f64> {
    let span = end - start;
    let tail = data.len().saturating_sub(8);
    let raw = data.get(tail..).and_then(|b| b.try_into().ok()).map_or(0.0, f64::from_le_bytes);
    let mut times = vec![start, end, (start + end) / 2.0, start - 1.0, end + 1.0, -1e30, 1e30, f64::NAN, raw];
    times.extend(data.iter().rev().take(16).map(|&b| start + span * (f64::from(b) / 127.5 - 0.5)));
    times
}

/// A local pose's values are finite and its rotations unit quaternions.
fn check_local(pose: &anim::Pose, t: f64) {
    assert!(pose.translations.iter().all(|v| v.is_finite()), "translation at {t}");
    assert!(pose.scales.iter().all(|v| v.is_finite()), "scale at {t}");
    assert!(pose.parameters.iter().all(|v| v.is_finite()), "parameter at {t}");
    for q in &pose.rotations {
        assert!(q.is_finite() && (q.length() - 1.0).abs() < 1e-3, "rotation {q} at {t}");
    }
}

/// Samples `clip` at its ends, outside them, at extremes and at times the
/// input chose (its last 8 bytes as an `f64`, and each of its last 16 bytes
/// as a fraction of the clip's span), in every playback mode and space.
fn evaluate(clip: &Clip, data: &[u8]) {
    let times = chosen_times(data, clip.start() as f64, clip.end() as f64);
    let mut sampler = Sampler::new();
    let mut matrices = Vec::new();
    for playback in [Playback::Once, Playback::Loop, Playback::PingPong] {
        for (ease, space) in [(Ease::Linear, Space::Local), (Ease::EaseInOut, Space::Model)] {
            let options = SampleOptions { playback: Some(playback), ease, space };
            for &t in &times {
                let clip_time = clip.sample(t, &options, &mut sampler);
                assert!(clip_time.is_finite(), "clip time of {t}");
                let pose = sampler.pose();
                // Local values stay finite; model space may overflow f32 legitimately
                // (a long chain of large finite offsets), which is not a bug.
                if space == Space::Local {
                    check_local(pose, t);
                }
            }
            clip.matrices(times[2], &options, false, &mut sampler, &mut matrices);
            clip.matrices(times[2], &options, true, &mut sampler, &mut matrices);
        }
    }
}
