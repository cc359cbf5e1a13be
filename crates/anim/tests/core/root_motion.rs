//! Root motion (docs/motion.md) against an independent planar reference written
//! here: a straight line, a known turn, fast and backward loops, and the
//! CMU walk of `examples/bvh/131_01.bvh`. After N loops the total
//! is N whole cycles plus the partial one, no frame jumps at a seam, and
//! `extract` keeps the root in place.

use anim::motion::{LayerSpec, MotionOptions, MotionSpec, RootMode, RootMotionSpec};
use anim::{
    Channel, Clip, ClipSpec, Cursor, Interpolation, JointSpec, Keys, Motion, MotionSampler, Playback, Pose,
    SkeletonSpec, TrackSpec, Transform,
};
use formats::import::{Format, ImportOptions, import};
use glam::{Quat, Vec3, Vec4};

/// A planar transform in f64, y up: ground `(x, z)` and yaw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ground {
    pub x: f64,
    pub z: f64,
    pub yaw: f64,
}

impl Ground {
    pub const ID: Ground = Ground { x: 0.0, z: 0.0, yaw: 0.0 };

    /// `self · b`: a rotation about +y by θ maps (x, z) to (x cos θ + z sin θ, −x sin θ + z cos θ).
    pub fn then(self, b: Ground) -> Ground {
        let (s, c) = self.yaw.sin_cos();
        Ground { x: self.x + b.x * c + b.z * s, z: self.z - b.x * s + b.z * c, yaw: self.yaw + b.yaw }
    }

    pub fn inverse(self) -> Ground {
        let (s, c) = self.yaw.sin_cos();
        Ground { x: -(self.x * c - self.z * s), z: -(self.x * s + self.z * c), yaw: -self.yaw }
    }

    fn of(t: Vec3, q: Quat) -> Ground {
        let (qy, qw) = (f64::from(q.y), f64::from(q.w));
        let yaw = if qy == 0.0 && qw == 0.0 { 0.0 } else { 2.0 * qy.atan2(qw) };
        let yaw = (yaw + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
        Ground { x: f64::from(t.x), z: f64::from(t.z), yaw }
    }
}

pub fn assert_ground(total: anim::motion::Planar, expected: Ground, tol: f64, what: &str) {
    let got = (total.translation.x, total.translation.z, total.yaw);
    let err = (got.0 - expected.x).abs().max((got.1 - expected.z).abs()).max((got.2 - expected.yaw).abs());
    assert!(err < tol, "{what}: got {got:?}, expected {expected:?}");
    assert_eq!(total.translation.y, 0.0, "{what}: a ground translation has no height");
}

/// The root `hips` over one cycle of `duration`: linear from `from` to
/// `to`, turning about y from 0 to `turn` radians.
pub fn travel(duration: f32, to: Vec3, turn: f32) -> Clip {
    let hips = JointSpec { name: "hips".into(), parent: None, rest: Transform::IDENTITY, inverse_bind: None };
    let leg = JointSpec { name: "leg".into(), parent: Some("hips".into()), ..hips.clone() };
    let t = TrackSpec::new(
        "hips",
        Channel::Translation,
        Interpolation::Linear,
        vec![0.0, duration],
        Keys::Vec3(vec![Vec3::new(0.0, 0.9, 0.0), to + Vec3::new(0.0, 0.9, 0.0)]),
    );
    let q = |a: f32| Vec4::from(Quat::from_rotation_y(a));
    let r = TrackSpec::new(
        "hips",
        Channel::Rotation,
        Interpolation::Linear,
        vec![0.0, duration],
        Keys::Vec4(vec![q(0.0), q(turn)]),
    );
    let spec = ClipSpec {
        name: "travel".into(),
        skeleton: Some(SkeletonSpec { joints: vec![hips, leg] }),
        tracks: vec![t, r],
        events: vec![],
        playback: Playback::Loop,
        ..Default::default()
    };
    Clip::build(&spec).unwrap()
}

pub fn with_root(clip: &Clip, speed: f64, mode: RootMode) -> Motion<&Clip> {
    let root = RootMotionSpec { mode, ..RootMotionSpec::default() };
    let layer = LayerSpec { speed, playback: Some(Playback::Loop), ..LayerSpec::new(clip) };
    Motion::build(MotionSpec { layers: vec![layer], root_motion: Some(root), ..Default::default() }).unwrap()
}

/// Samples `motion` at `k / fps` for `k = 0..=frames`; returns each sample's delta and the last total.
fn run(motion: &Motion<&Clip>, fps: f64, frames: u32) -> (Vec<anim::motion::Planar>, anim::motion::Planar) {
    let mut sampler = MotionSampler::new();
    let mut deltas = Vec::new();
    for k in 0..=frames {
        motion.sample(f64::from(k) / fps, &MotionOptions::default(), &mut sampler);
        deltas.push(sampler.root_motion().unwrap().delta);
    }
    (deltas, sampler.root_motion().unwrap().total)
}

#[test]
fn a_straight_walk_travels_two_metres_a_cycle_across_seams() {
    let clip = travel(1.0, Vec3::new(2.0, 0.0, 0.0), 0.0);
    let (deltas, total) = run(&with_root(&clip, 1.0, RootMode::Report), 10.0, 35);
    assert_eq!(deltas[0], Default::default(), "the first sample has delta 0");
    for (k, d) in deltas.iter().enumerate().skip(1) {
        assert!((d.translation.x - 0.2).abs() < 1e-5, "frame {k}: {d:?} (no jump at the seams)");
    }
    assert_ground(total, Ground { x: 7.0, z: 0.0, yaw: 0.0 }, 1e-4, "3.5 cycles");
}

#[test]
fn many_seams_in_one_frame_and_backward_loops_count_whole_cycles() {
    let clip = travel(1.0, Vec3::new(2.0, 0.0, 0.0), 0.0);
    // 37 cycles per second sampled at 10 fps: 3.7 seams a frame; 1 s is 37 whole cycles.
    let (_, total) = run(&with_root(&clip, 37.0, RootMode::Report), 10.0, 10);
    assert_ground(total, Ground { x: 74.0, z: 0.0, yaw: 0.0 }, 1e-3, "37 cycles");
    let (deltas, total) = run(&with_root(&clip, -1.0, RootMode::Report), 10.0, 25);
    assert!(deltas.iter().skip(1).all(|d| (d.translation.x + 0.2).abs() < 1e-5), "{deltas:?}");
    assert_ground(total, Ground { x: -5.0, z: 0.0, yaw: 0.0 }, 1e-4, "2.5 cycles backward");
}

#[test]
fn a_turning_walk_closes_a_square_in_four_cycles_with_yaw_unwrapped() {
    let quarter = std::f32::consts::FRAC_PI_2;
    let clip = travel(1.0, Vec3::new(1.0, 0.0, 0.0), quarter);
    let (deltas, total) = run(&with_root(&clip, 1.0, RootMode::Report), 20.0, 80);
    // Each frame turns by a twentieth of a quarter turn.
    for d in deltas.iter().skip(1) {
        assert!((d.yaw - f64::from(quarter) / 20.0).abs() < 1e-5, "{d:?}");
    }
    let whole =
        Ground::of(Vec3::ZERO, Quat::IDENTITY).inverse().then(Ground::of(Vec3::X, Quat::from_rotation_y(quarter)));
    let expected = (0..4).fold(Ground::ID, |a, _| a.then(whole));
    assert!(expected.x.abs() < 1e-6 && expected.z.abs() < 1e-6, "the reference closes the square: {expected:?}");
    assert_ground(total, expected, 1e-4, "four quarter turns");
    assert!((total.yaw - std::f64::consts::TAU).abs() < 1e-4, "a full turn is 2π, not 0: {}", total.yaw);
}

#[test]
fn extract_keeps_the_root_at_its_start_while_the_deltas_carry_the_travel() {
    let clip = travel(1.0, Vec3::new(2.0, 0.0, 1.0), 0.8);
    let motion = with_root(&clip, 1.0, RootMode::Extract);
    let mut sampler = MotionSampler::new();
    for k in 0..=45 {
        motion.sample(f64::from(k) * 0.05, &MotionOptions::default(), &mut sampler);
        let (t, q) = (sampler.local().translations[0], sampler.local().rotations[0]);
        assert!(t.x.abs() < 1e-5 && t.z.abs() < 1e-5 && (t.y - 0.9).abs() < 1e-5, "frame {k}: {t:?} (height kept)");
        assert!(q.dot(Quat::IDENTITY).abs() > 1.0 - 1e-6, "frame {k}: heading of the start: {q:?}");
    }
    let total = sampler.root_motion().unwrap().total;
    assert!(total.translation.length() > 1.0, "the travel is in the deltas: {total:?}");
}

pub fn root_ground(clip: &Clip, t: f32) -> Ground {
    let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
    clip.sample_into(t, &mut cursor, &mut pose);
    Ground::of(pose.translations[0].into(), pose.rotations[0])
}

#[test]
fn the_cmu_walk_loops_three_and_a_half_times_without_a_jump() {
    let imported = import(
        &std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/bvh/131_01.bvh")).unwrap(),
        Format::Bvh,
        &ImportOptions::default(),
    )
    .unwrap();
    let clip = Clip::build(&imported.clips[0]).unwrap();
    let (start, end) = (clip.start(), clip.end());
    let duration = f64::from(end) - f64::from(start);
    let motion = with_root(&clip, 1.0, RootMode::Report);
    let fps = 30.0;
    let frames = (3.5 * duration * fps).floor() as u32;
    let (deltas, total) = run(&motion, fps, frames);

    // The reference: whole cycles W = M(start)⁻¹·M(end), then the partial one.
    let m_start = root_ground(&clip, start);
    let whole = m_start.inverse().then(root_ground(&clip, end));
    let last = f64::from(frames) / fps;
    let partial_time = f64::from(start) + last.rem_euclid(duration);
    let partial = m_start.inverse().then(root_ground(&clip, partial_time as f32));
    let expected = (0..3).fold(Ground::ID, |a, _| a.then(whole)).then(partial);
    assert_ground(total, expected, 2e-3, "3.5 loops of the CMU walk");

    // No jump: a frame across a seam moves about as far as its neighbours.
    let step = |d: &anim::motion::Planar| d.translation.length();
    for seam in 1..=3 {
        let k = (f64::from(seam) * duration * fps).ceil() as usize;
        let around = (k - 3..k + 3).filter(|&i| i != k).map(|i| step(&deltas[i])).fold(0.0, f64::max);
        assert!(step(&deltas[k]) <= 2.0 * around + 1e-3, "seam {seam}: {} vs {around}", step(&deltas[k]));
    }
}
