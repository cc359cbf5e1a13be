//! docs/clip-format.md, “Accuracy”: the `f32` core agrees with the independent `f64` reference to
//! within `1e-5` absolute, for every interpolation mode, end condition,
//! speed mode, playback mode, ease and space.
//!
//! Each sweep is deterministic (fixed seeds) and prints its worst error so
//! the figures can be quoted (`cargo test --test core accuracy -- --nocapture`).
//! Rotation keys go up to 179.5° apart: the core switches from polynomial to
//! exact slerp weights at about 91°, and both sides of that switch must hold
//! the bound. (Exactly 180° is excluded: there the short way is undefined
//! and the `f32` rounding of the keys alone decides it.)

use anim::{Channel, Clip, ClipSpec, Cursor, Ease, Ends, Interpolation, Playback, Pose, SampleOptions, Sampler, Space};
use glam::{DQuat, DVec3};

use crate::random::{Kind, Rng, one_track_clip, skeleton_clip, track};
use crate::reference::{RefClip, RefTrack, Trs, quat_err, vec_err};

/// docs/clip-format.md, “Accuracy”.
pub const TOLERANCE: f64 = 1e-5;

fn core_trs(pose: &Pose, j: usize) -> Trs {
    Trs {
        t: DVec3::from(pose.translations[j].to_array().map(f64::from)),
        r: pose.rotations[j].as_dquat(),
        s: DVec3::from(pose.scales[j].to_array().map(f64::from)),
    }
}

/// The worst component error between the core's pose and the reference's.
fn pose_err(core: &Pose, reference: &[Trs]) -> f64 {
    let mut worst = 0.0f64;
    for (j, r) in reference.iter().enumerate() {
        let c = core_trs(core, j);
        worst = worst.max(vec_err(c.t, r.t)).max(vec_err(c.s, r.s)).max(quat_err(c.r, r.r));
    }
    worst
}

/// Samples `clip` at `count` random clip times in its range plus each key
/// time and a little beyond both ends; returns the worst error and where.
fn sweep_local(spec: &ClipSpec, rng: &mut Rng, count: usize) -> (f64, f64) {
    let clip = Clip::build(spec).unwrap_or_else(|e| panic!("generated spec refused: {e}\n{spec:?}"));
    let reference = RefClip::new(spec);
    assert_eq!(clip.start() as f64, reference.start, "start of {spec:?}");
    assert_eq!(clip.end() as f64, reference.end, "end of {spec:?}");
    let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
    let mut times: Vec<f32> = spec.tracks.iter().flat_map(|t| t.times.iter().copied()).collect();
    let (a, b) = (reference.start, reference.end);
    times.extend((0..count).map(|_| rng.range(a - 0.2, b + 0.2) as f32));
    let mut worst = (0.0, f64::NAN);
    for t in times {
        clip.sample_into(t, &mut cursor, &mut pose);
        let e = pose_err(&pose, &reference.local(t as f64));
        if e > worst.0 || e.is_nan() {
            worst = (e, t as f64);
        }
    }
    worst
}

struct Sweep {
    label: String,
    worst: f64,
    /// Constant speed: the worst error relative to the path length.
    worst_rel: Option<f64>,
    spec: Option<ClipSpec>,
    at: f64,
}

fn run(kinds: &[Kind], clips: usize, samples: usize, seed: u64) -> Vec<Sweep> {
    let mut out = Vec::new();
    for (k, &kind) in kinds.iter().enumerate() {
        let mut rng = Rng::new(seed + k as u64);
        let mut sweep = Sweep { label: kind.label(), worst: 0.0, worst_rel: None, spec: None, at: 0.0 };
        for _ in 0..clips {
            let min = if kind.ends == Some(Ends::Phantom) { 4 } else { 2 };
            let n = min + rng.below(6);
            let spec = one_track_clip(track(&mut rng, "j", kind, n));
            let (e, at) = sweep_local(&spec, &mut rng, samples);
            if let Some(length) = RefTrack::new(&spec.tracks[0]).arc_length() {
                sweep.worst_rel = Some(sweep.worst_rel.unwrap_or(0.0).max(e / length));
            }
            if e > sweep.worst || e.is_nan() {
                sweep = Sweep { label: sweep.label, worst: e, spec: Some(spec), at, ..sweep };
            }
        }
        out.push(sweep);
    }
    out
}

fn report(sweeps: &[Sweep]) {
    let mut failures = Vec::new();
    for s in sweeps {
        match s.worst_rel {
            None => println!("accuracy: {:<55} max error {:.3e}", s.label, s.worst),
            Some(r) => println!("accuracy: {:<55} max error {:.3e} ({:.2e}·L)", s.label, s.worst, r),
        }
        if s.worst.is_nan() || s.worst > TOLERANCE {
            failures.push(format!("{}: error {:.3e} at t = {} in {:?}", s.label, s.worst, s.at, s.spec));
        }
    }
    assert!(failures.is_empty(), "beyond {TOLERANCE:e}:\n{}", failures.join("\n"));
}

const ALL_ENDS: [Ends; 4] = [Ends::Reflect, Ends::ZeroSlope, Ends::Wrap, Ends::Phantom];

#[test]
fn vector_modes_match_the_reference() {
    let mut kinds = vec![];
    for channel in [Channel::Translation, Channel::Scale] {
        kinds.push(Kind::new(channel, Interpolation::Step));
        kinds.push(Kind::new(channel, Interpolation::Linear));
        kinds.push(Kind::new(channel, Interpolation::CubicHermite));
        kinds.extend(ALL_ENDS.map(|e| Kind::new(channel, Interpolation::CatmullRom).ends(e)));
        kinds.extend(ALL_ENDS.map(|e| Kind::new(channel, Interpolation::BSpline).ends(e)));
    }
    report(&run(&kinds, 40, 100, 100));
}

#[test]
fn constant_speed_matches_the_reference() {
    let mut kinds = vec![
        Kind::new(Channel::Translation, Interpolation::Linear).constant_speed(),
        Kind::new(Channel::Translation, Interpolation::CubicHermite).constant_speed(),
    ];
    kinds.extend(ALL_ENDS.map(|e| Kind::new(Channel::Translation, Interpolation::CatmullRom).ends(e).constant_speed()));
    kinds.extend(ALL_ENDS.map(|e| Kind::new(Channel::Translation, Interpolation::BSpline).ends(e).constant_speed()));
    report(&run(&kinds, 8, 250, 200));
}

#[test]
fn rotation_modes_match_the_reference() {
    let mut kinds = vec![];
    for max_deg in [40.0, 179.5] {
        kinds.push(Kind::new(Channel::Rotation, Interpolation::Step).max_deg(max_deg));
        kinds.push(Kind::new(Channel::Rotation, Interpolation::Linear).max_deg(max_deg));
        kinds.push(Kind::new(Channel::Rotation, Interpolation::CubicHermite).max_deg(max_deg));
        kinds
            .extend(ALL_ENDS.map(|e| Kind::new(Channel::Rotation, Interpolation::CatmullRom).ends(e).max_deg(max_deg)));
        kinds.extend(ALL_ENDS.map(|e| Kind::new(Channel::Rotation, Interpolation::BSpline).ends(e).max_deg(max_deg)));
    }
    report(&run(&kinds, 40, 100, 300));
}

/// Whole clips with hierarchies, through `Clip::sample` with every
/// playback mode, ease and space, at request times well outside the range.
/// The pose is compared at the clip time the core returned, so that this
/// measures evaluation and composition; the time mapping itself is held to
/// the reference in `clip_time_matches_the_reference`.
#[test]
fn playback_ease_and_spaces_match_the_reference() {
    let mut rng = Rng::new(400);
    let mut worst = [0.0f64; 2];
    let mut sampler = Sampler::new();
    for _ in 0..30 {
        let joints = 1 + rng.below(6);
        let spec = skeleton_clip(&mut rng, joints);
        let clip = Clip::build(&spec).unwrap_or_else(|e| panic!("generated spec refused: {e}\n{spec:?}"));
        let reference = RefClip::new(&spec);
        let (a, b) = (reference.start, reference.end);
        let d = (b - a).max(0.1);
        for playback in [None, Some(Playback::Once), Some(Playback::Loop), Some(Playback::PingPong)] {
            for ease in [Ease::Linear, Ease::EaseIn, Ease::EaseOut, Ease::EaseInOut] {
                for space in [Space::Local, Space::Model] {
                    let options = SampleOptions { playback, ease, space };
                    for _ in 0..8 {
                        let t = rng.range(a - 2.5 * d, b + 2.5 * d);
                        let ct = clip.sample(t, &options, &mut sampler);
                        assert!((a..=b).contains(&(ct as f64)), "clip time {ct} outside [{a}, {b}]");
                        let local = reference.local(ct as f64);
                        let expected = if space == Space::Model { reference.model(&local) } else { local };
                        let e = pose_err(sampler.pose(), &expected);
                        let slot = &mut worst[(space == Space::Model) as usize];
                        *slot = slot.max(e);
                        assert!(
                            e <= TOLERANCE,
                            "error {e:e} at t = {t} ({playback:?}, {ease:?}, {space:?}), clip time {ct}\n{spec:?}"
                        );
                    }
                }
            }
        }
    }
    println!("accuracy: whole clips, local space                              max error {:.3e}", worst[0]);
    println!("accuracy: whole clips, model space                              max error {:.3e}", worst[1]);
}

/// `Clip::clip_time` against docs/clip-format.md, 2.6–2.7, evaluated in `f64`: the result is an
/// `f32`, so it may differ from the exact mapping by its rounding — at most
/// an ulp of the clip's time scale (`ε·max(|start|, |end|)`) — and by
/// nothing that grows with the number of periods played.
#[test]
fn clip_time_matches_the_reference() {
    let mut rng = Rng::new(450);
    let mut worst_ulps = 0.0f64;
    let mut failure = None;
    for _ in 0..200 {
        let n = 2 + rng.below(4);
        let spec = one_track_clip(track(&mut rng, "j", Kind::new(Channel::Translation, Interpolation::Linear), n));
        let clip = Clip::build(&spec).unwrap();
        let reference = RefClip::new(&spec);
        let (a, b) = (reference.start, reference.end);
        for playback in [Playback::Once, Playback::Loop, Playback::PingPong] {
            for ease in [Ease::Linear, Ease::EaseIn, Ease::EaseOut, Ease::EaseInOut] {
                for _ in 0..5 {
                    let t = rng.range(a - 20.0 * (b - a), b + 20.0 * (b - a));
                    let ct = clip.clip_time(t, playback, ease) as f64;
                    let rt = reference.clip_time(t, playback, ease);
                    let scale = a.abs().max(b.abs()).max(f32::MIN_POSITIVE as f64);
                    let ulps = (ct - rt).abs() / (f32::EPSILON as f64 * scale);
                    if ulps > worst_ulps {
                        worst_ulps = ulps;
                        failure = Some(format!(
                            "t = {t}, {playback:?}, {ease:?}: {ct} vs {rt}, keys {:?}",
                            spec.tracks[0].times
                        ));
                    }
                }
            }
        }
    }
    println!("accuracy: clip time                                              max error {worst_ulps:.2} ulp");
    assert!(worst_ulps <= 1.0, "clip time off by {worst_ulps} ulp: {}", failure.unwrap_or_default());
}

/// Model matrices and skinning matrices against the hand composition.
#[test]
fn matrices_match_the_reference() {
    let mut rng = Rng::new(500);
    let mut sampler = Sampler::new();
    let mut out = Vec::new();
    let mut worst = 0.0f64;
    for _ in 0..30 {
        let joints = 1 + rng.below(6);
        let spec = skeleton_clip(&mut rng, joints);
        let clip = Clip::build(&spec).unwrap();
        let reference = RefClip::new(&spec);
        for _ in 0..20 {
            let t = rng.range(reference.start - 0.5, reference.end + 0.5);
            let options = SampleOptions { playback: Some(Playback::Once), ..Default::default() };
            assert!(clip.matrices(t, &options, false, &mut sampler, &mut out));
            assert!(!clip.matrices(t, &options, true, &mut sampler, &mut out), "no inverse binds, no skinning");
            let expected = reference.matrices(&reference.local(reference.clip_time(t, Playback::Once, Ease::Linear)));
            assert_eq!(out.len(), expected.len());
            for (m, e) in out.iter().zip(&expected) {
                let m = m.as_dmat4();
                let scale = e.to_cols_array().iter().fold(1.0f64, |a, x| a.max(x.abs()));
                let err = (m - *e).to_cols_array().iter().fold(0.0f64, |a, x| a.max(x.abs())) / scale;
                worst = worst.max(err);
            }
        }
    }
    println!("accuracy: model matrices (relative to the largest entry)      max error {worst:.3e}");
    assert!(worst <= 1e-5, "matrix error {worst:e}");
}

/// A quaternion's sign is free: the comparison must not depend on it.
#[test]
fn quaternion_comparison_ignores_the_sign() {
    let q = DQuat::from_axis_angle(DVec3::Y, 1.0);
    assert_eq!(quat_err(q, -q), 0.0);
    assert!(quat_err(q, DQuat::IDENTITY) > 0.1);
}
