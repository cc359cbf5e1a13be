//! Root motion across many loop cycles in one step (docs/motion.md, “Root
//! motion”): a sparse step that crosses 1, 2, 10 or 1000 seams reports what
//! dense sampling would have added up, forward and backward, for cycles that
//! turn 0°, 90°, 190° and 360°. The reference is written here in `f64`: the
//! clip's root path in closed form, sampled densely (64 steps a cycle, each
//! seam replaced by the whole cycle, each small step's yaw wrapped) and
//! composed.

use std::f64::consts::{PI, TAU};

use anim::motion::{Planar, RootMode};
use anim::{
    Channel, Clip, ClipSpec, Interpolation, JointSpec, Keys, MotionSampler, Playback, SkeletonSpec, TrackSpec,
    Transform,
};
use glam::{Quat, Vec3, Vec4};

use super::root_motion::{Ground, root_ground, travel, with_root};

/// The cycle's length in seconds.
const D: f64 = 1.0;

/// Where the root goes in one cycle.
const TO: Vec3 = Vec3::new(1.5, 0.0, 0.5);

/// Rotation segments of the test clip: each turns less than half a turn, so
/// a slerp between its keys turns the way the keys say.
const SEGMENTS: usize = 4;

/// The test clip: the root `hips` moves linearly from the origin to `TO` on
/// the ground and turns about y by `turn` radians, evenly over `SEGMENTS`
/// rotation keys.
fn spinner(turn: f64) -> Clip {
    let hips = JointSpec { name: "hips".into(), parent: None, rest: Transform::IDENTITY, inverse_bind: None };
    let times = |n: usize| (0..=n).map(|i| (D * i as f64 / n as f64) as f32).collect::<Vec<_>>();
    let t = TrackSpec::new(
        "hips",
        Channel::Translation,
        Interpolation::Linear,
        times(1),
        Keys::Vec3(vec![Vec3::new(0.0, 0.9, 0.0), TO + Vec3::new(0.0, 0.9, 0.0)]),
    );
    let q = |i: usize| Vec4::from(Quat::from_rotation_y((turn * i as f64 / SEGMENTS as f64) as f32));
    let r = TrackSpec::new(
        "hips",
        Channel::Rotation,
        Interpolation::Linear,
        times(SEGMENTS),
        Keys::Vec4((0..=SEGMENTS).map(q).collect()),
    );
    let spec = ClipSpec {
        name: "spinner".into(),
        skeleton: Some(SkeletonSpec { joints: vec![hips] }),
        tracks: vec![t, r],
        playback: Playback::Loop,
        ..Default::default()
    };
    Clip::build(&spec).unwrap()
}

fn wrap(a: f64) -> f64 {
    let a = a.rem_euclid(TAU);
    if a > PI { a - TAU } else { a }
}

/// The reference's view of a test clip, read from the clip at its rotation
/// keys only: the root's ground position at both ends (linear between) and
/// its yaw at each key, unwrapped here (linear between keys). Reading the
/// keys back, rather than taking the angles the test asked for, leaves out
/// the f32 rounding of the keys, which a thousand cycles would amplify.
struct Model {
    from: Ground,
    to: Ground,
    /// The unwrapped yaw at `D·i/segments`.
    keys: Vec<f64>,
}

impl Model {
    fn of(clip: &Clip, segments: usize) -> Model {
        let at = |i: usize| root_ground(clip, (D * i as f64 / segments as f64) as f32);
        let mut keys = vec![at(0).yaw];
        for i in 1..=segments {
            let last = keys[i - 1];
            keys.push(last + wrap(at(i).yaw - last));
        }
        Model { from: at(0), to: at(segments), keys }
    }

    /// `M(c)`, its yaw wrapped like a pose's.
    fn at(&self, c: f64) -> Ground {
        let segments = self.keys.len() - 1;
        let u = c / D;
        let k = ((u * segments as f64).floor() as usize).min(segments - 1);
        let v = u * segments as f64 - k as f64;
        let yaw = self.keys[k] + (self.keys[k + 1] - self.keys[k]) * v;
        let (from, to) = (self.from, self.to);
        Ground { x: from.x + (to.x - from.x) * u, z: from.z + (to.z - from.z) * u, yaw: wrap(yaw) }
    }
}

/// The dense limit from clip position `x0` to `x1` (seconds along the
/// looping clip, either way).
fn dense(model: &Model, x0: f64, x1: f64) -> Ground {
    let at = |x: f64| {
        let cycle = (x / D).floor();
        (cycle as i64, model.at(x - cycle * D))
    };
    let (start, end) = (model.at(0.0), model.at(D));
    let steps = ((x1 - x0).abs() / D * 64.0).ceil().max(1.0) as u64;
    let mut total = Ground::ID;
    let mut from = at(x0);
    for i in 1..=steps {
        let to_here = at(x0 + (x1 - x0) * i as f64 / steps as f64);
        let seam = match to_here.0 - from.0 {
            0 => Ground::ID,
            1 => end.then(start.inverse()),
            -1 => start.then(end.inverse()),
            n => unreachable!("a dense step crosses {n} seams"),
        };
        let step = from.1.inverse().then(seam).then(to_here.1);
        total = total.then(Ground { yaw: wrap(step.yaw), ..step });
        from = to_here;
    }
    total
}

/// The total after sampling `clip` at motion times `tau0` then `tau1`, at
/// layer speed `speed`: one step.
fn sparse(clip: &Clip, speed: f64, tau0: f64, tau1: f64) -> Planar {
    let motion = with_root(clip, speed, RootMode::Report);
    let mut sampler = MotionSampler::new();
    let options = anim::motion::MotionOptions::default();
    motion.sample(tau0, &options, &mut sampler);
    motion.sample(tau1, &options, &mut sampler);
    let root = sampler.root_motion().unwrap();
    assert_eq!(root.delta, root.total, "one step: the delta is the total");
    root.total
}

fn assert_near(got: Planar, expected: Ground, tol: f64, what: &str) {
    let err = (got.translation.x - expected.x)
        .abs()
        .max((got.translation.z - expected.z).abs())
        .max((got.yaw - expected.yaw).abs());
    assert!(
        err < tol,
        "{what}: got ({}, {}, yaw {}), dense {expected:?}",
        got.translation.x,
        got.translation.z,
        got.yaw
    );
}

#[test]
fn a_step_across_many_seams_adds_up_what_dense_sampling_would() {
    for degrees in [0.0f64, 90.0, 190.0, 360.0] {
        let turn = degrees.to_radians();
        let clip = spinner(turn);
        let model = Model::of(&clip, SEGMENTS);
        for seams in [1i64, 2, 10, 1000] {
            // Tolerance: f32 keys, and a whole cycle's error taken `seams` times.
            let tol = 1e-5 * (10.0 + seams as f64);
            // From phase 0.3 to 0.75 (the step's ends inside their cycles
            // turn less than half a turn), from 0.6 to 0.2, and whole cycles.
            for (a, b) in [(0.3, 0.75), (0.6, 0.2), (0.0, 0.0)] {
                for speed in [1.0, -1.0] {
                    let x0 = (3.0 + a) * D;
                    let x1 = (3.0 + speed * seams as f64 + b) * D;
                    let expected = dense(&model, x0, x1);
                    let what = format!("{degrees}° cycle, {seams} seams, phase {a} → {b}, speed {speed}");
                    assert_near(sparse(&clip, speed, x0 / speed, x1 / speed), expected, tol, &what);
                }
            }
        }
    }
}

#[test]
fn whole_cycles_count_their_yaw_in_full() {
    // The dense reference itself: n cycles of a 190° or 360° turn are n
    // times the turn, not the wrapped difference of its ends.
    for degrees in [190.0f64, 360.0] {
        let turn = degrees.to_radians();
        let clip = spinner(turn);
        let expected = dense(&Model::of(&clip, SEGMENTS), 0.0, 7.0 * D).yaw;
        assert!((expected - 7.0 * turn).abs() < 1e-5, "{degrees}°: the reference turns {expected}");
        let got = sparse(&clip, 1.0, 0.0, 7.0 * D).yaw;
        assert!((got - 7.0 * turn).abs() < 1e-4, "{degrees}°: 7 cycles in one step turn {got}");
    }
}

#[test]
fn twenty_one_quarter_turns_in_one_step_are_ten_and_a_half_pi() {
    // The report: 21 cycles of a quarter-turn walk sampled at 0 and 21 s
    // turned 1.571 (the step's yaw wrapped), where dense sampling turns 10.5π.
    let quarter = std::f32::consts::FRAC_PI_2;
    let clip = travel(1.0, Vec3::new(1.0, 0.0, 0.0), quarter);
    let expected = dense(&Model::of(&clip, 1), 0.0, 21.0);
    assert!((expected.yaw - 10.5 * PI).abs() < 1e-5, "the reference: {expected:?}");
    let got = sparse(&clip, 1.0, 0.0, 21.0);
    assert_near(got, expected, 1e-4, "21 quarter-turn cycles in one step");
    println!(
        "FIGURE root motion, 21 quarter-turn cycles in one step: total yaw {:.3} (dense {:.3})",
        got.yaw, expected.yaw
    );
}
