//! The uniform cubic B-spline (docs/clip-format.md, 2.5; issue 18) through the public API:
//! values against the lecture's basis matrix, C2 at uniform keys, the four
//! end conditions, rotations by association.
//!
//! Expected values come from the lecture's matrix `M_B-spline`, written out
//! below and evaluated here in `f64` on the control polygon the docs
//! describes (never from the core's Bezier conversion), or from closed forms
//! of that matrix: at a key the curve is `(c_{i−1} + 4c_i + c_{i+1})/6`, its
//! velocity `(c_{i+1} − c_{i−1})/2h` and its acceleration
//! `(c_{i−1} − 2c_i + c_{i+1})/h²`.
//!
//! Derivatives are one-sided four-point differences on the sampled `f32`
//! curve. They are exact for a cubic, so on each side of a key they measure
//! that side's polynomial and differ across the key only by the jump plus
//! rounding, about `12·ε_sample/δ²` for the second derivative.

use anim::{Channel, Clip, ClipSpec, Cursor, Ends, Interpolation, Keys, Playback, Pose, TrackSpec};
use glam::{DQuat, DVec3, Quat, Vec3, Vec3A, Vec4};

use crate::random::Rng;

/// The lecture's basis, times 6: `p(u) = [u³ u² u 1] · M/6 · [P0 P1 P2 P3]ᵀ`.
const M_B_SPLINE_X6: [[f64; 4]; 4] =
    [[-1.0, 3.0, -3.0, 1.0], [3.0, -6.0, 3.0, 0.0], [-3.0, 0.0, 3.0, 0.0], [1.0, 4.0, 1.0, 0.0]];

/// One segment of the lecture's B-spline at `u`.
fn basis(p: [DVec3; 4], u: f64) -> DVec3 {
    let powers = [u * u * u, u * u, u, 1.0];
    (0..4).map(|k| p[k] * ((0..4).map(|r| powers[r] * M_B_SPLINE_X6[r][k]).sum::<f64>() / 6.0)).sum()
}

/// The curve over a control polygon `p` (one more point each side of the
/// `knots.len()` keys it spans): segment `i` runs from `knots[i]` to
/// `knots[i+1]` on `p[i..i+4]`, with `u` local to the segment.
fn lecture_curve(p: &[DVec3], knots: &[f64], t: f64) -> DVec3 {
    assert_eq!(p.len(), knots.len() + 2);
    let last = knots.len() - 2;
    let i = (0..=last).rev().find(|&i| knots[i] <= t).unwrap_or(0);
    let u = ((t - knots[i]) / (knots[i + 1] - knots[i])).clamp(0.0, 1.0);
    basis([p[i], p[i + 1], p[i + 2], p[i + 3]], u)
}

fn d3(v: [f64; 3]) -> DVec3 {
    DVec3::from(v)
}

fn translation_clip(interpolation: Interpolation, ends: Option<Ends>, times: &[f32], keys: &[DVec3]) -> Clip {
    let values = Keys::Vec3(keys.iter().map(|k| k.as_vec3()).collect());
    let mut track = TrackSpec::new("j", Channel::Translation, interpolation, times.to_vec(), values);
    track.ends = ends;
    build(track)
}

fn rotation_clip(ends: Option<Ends>, times: &[f32], keys: &[Vec4]) -> Clip {
    let mut track =
        TrackSpec::new("j", Channel::Rotation, Interpolation::BSpline, times.to_vec(), Keys::Vec4(keys.to_vec()));
    track.ends = ends;
    build(track)
}

fn build(track: TrackSpec) -> Clip {
    let spec = ClipSpec {
        name: "b".into(),
        skeleton: None,
        tracks: vec![track],
        events: vec![],
        playback: Playback::Once,
        ..Default::default()
    };
    Clip::build(&spec).unwrap_or_else(|e| panic!("refused: {e}"))
}

/// Samples one joint's translation or rotation at clip times.
struct Probe<'c> {
    clip: &'c Clip,
    cursor: Cursor,
    pose: Pose,
}

impl<'c> Probe<'c> {
    fn new(clip: &'c Clip) -> Self {
        Probe { clip, cursor: Cursor::default(), pose: Pose::default() }
    }

    fn at(&mut self, t: f32) -> Vec3A {
        self.clip.sample_into(t, &mut self.cursor, &mut self.pose);
        self.pose.translations[0]
    }

    fn rotation(&mut self, t: f32) -> Quat {
        self.clip.sample_into(t, &mut self.cursor, &mut self.pose);
        self.pose.rotations[0]
    }

    /// First and second derivatives at `t` from the side `dir` (±1), from
    /// the samples at `t + dir·kδ`, k = 0..3 (exact for a cubic).
    fn derivatives(&mut self, t: f32, dir: f32, delta: f32) -> (Vec3A, Vec3A) {
        let f: Vec<Vec3A> = (0..4).map(|k| self.at(t + dir * k as f32 * delta)).collect();
        let first = (f[0] * -11.0 + f[1] * 18.0 - f[2] * 9.0 + f[3] * 2.0) / (6.0 * delta) * dir;
        let second = (f[0] * 2.0 - f[1] * 5.0 + f[2] * 4.0 - f[3]) / (delta * delta);
        (first, second)
    }
}

fn near(a: Vec3A, b: DVec3, tol: f64) -> bool {
    (a.as_dvec3() - b).abs().max_element() <= tol * b.abs().max_element().max(1.0)
}

/// Six keys that go somewhere in 3D, irregularly.
fn keys() -> Vec<DVec3> {
    [[0.0, 0.0, 0.0], [1.0, 2.0, -1.0], [3.0, 2.5, 0.5], [2.0, -1.0, 2.0], [4.0, 0.5, 1.0], [5.0, 3.0, -2.0]]
        .into_iter()
        .map(d3)
        .collect()
}

/// The control polygon of docs/clip-format.md, 2.5, for `ends` (phantom: the keys themselves).
fn polygon(c: &[DVec3], ends: Ends) -> Vec<DVec3> {
    let n = c.len() - 1;
    let (first, last) = match ends {
        Ends::Reflect => (2.0 * c[0] - c[1], 2.0 * c[n] - c[n - 1]),
        Ends::ZeroSlope => (c[1], c[n - 1]),
        Ends::Wrap => (c[n - 1], c[1]),
        Ends::Phantom => return c.to_vec(),
    };
    [&[first], c, &[last]].concat()
}

#[test]
fn values_follow_the_lecture_basis_matrix() {
    let uniform: Vec<f32> = (0..6).map(|i| 0.5 * i as f32).collect();
    let irregular = vec![-1.0, -0.25, 0.5, 2.0, 2.25, 4.0];
    for times in [uniform, irregular] {
        for ends in [Ends::Reflect, Ends::ZeroSlope, Ends::Wrap, Ends::Phantom] {
            let mut c = keys();
            if ends == Ends::Wrap {
                c[5] = c[0];
            }
            let clip = translation_clip(Interpolation::BSpline, Some(ends), &times, &c);
            let t: Vec<f64> = times.iter().map(|&x| x as f64).collect();
            let knots = if ends == Ends::Phantom { &t[1..5] } else { &t[..] };
            assert_eq!((clip.start() as f64, clip.end() as f64), (knots[0], knots[knots.len() - 1]), "{ends:?}");
            let p = polygon(&c, ends);
            let mut probe = Probe::new(&clip);
            let (a, b) = (knots[0], knots[knots.len() - 1]);
            for k in 0..=200 {
                let time = (a + (b - a) * k as f64 / 200.0) as f32;
                let expected = lecture_curve(&p, knots, time as f64);
                let got = probe.at(time);
                assert!(near(got, expected, 2e-6), "{ends:?} at t = {time}: {got} vs {expected} (keys at {times:?})");
            }
        }
    }
}

/// Approximating, not interpolating: at an inner key the curve is the
/// key's weighted average with its neighbours, and halfway through a
/// segment `(c_{i−1} + 23c_i + 23c_{i+1} + c_{i+2})/48`.
#[test]
fn the_curve_passes_near_but_not_through_inner_keys() {
    let c = keys();
    let times: Vec<f32> = (0..6).map(|i| i as f32).collect();
    let clip = translation_clip(Interpolation::BSpline, None, &times, &c);
    let mut probe = Probe::new(&clip);
    for i in 1..5 {
        let at_key = (c[i - 1] + 4.0 * c[i] + c[i + 1]) / 6.0;
        assert!(near(probe.at(i as f32), at_key, 2e-6), "key {i}");
        assert!((probe.at(i as f32).as_dvec3() - c[i]).length() > 0.1, "key {i} is not interpolated");
    }
    for i in 1..4 {
        let half = (c[i - 1] + 23.0 * c[i] + 23.0 * c[i + 1] + c[i + 2]) / 48.0;
        assert!(near(probe.at(i as f32 + 0.5), half, 2e-6), "middle of segment {i}");
    }
    // Two keys with reflect ends: the B-spline reproduces a straight line.
    let line = translation_clip(Interpolation::BSpline, None, &[1.0, 3.0], &[c[1], c[3]]);
    let mut probe = Probe::new(&line);
    for k in 0..=10 {
        let u = k as f64 / 10.0;
        assert!(near(probe.at(1.0 + 2.0 * u as f32), c[1] + (c[3] - c[1]) * u, 2e-6), "u = {u}");
    }
}

#[test]
fn uniform_keys_are_c2_where_catmull_rom_is_only_c1() {
    let mut rng = Rng::new(18);
    for h in [1.0f32, 0.25] {
        let c: Vec<DVec3> = (0..8).map(|_| rng.vec3(2.0).as_dvec3()).collect();
        let times: Vec<f32> = (0..8).map(|i| i as f32 * h).collect();
        let delta = h / 16.0; // a power of two: every sample time is exact
        let spline = translation_clip(Interpolation::BSpline, None, &times, &c);
        let catmull = translation_clip(Interpolation::CatmullRom, None, &times, &c);
        let (mut b, mut cr) = (Probe::new(&spline), Probe::new(&catmull));
        let mut catmull_jump = 0.0f32;
        for i in 1..7 {
            let t = times[i];
            let (v_left, a_left) = b.derivatives(t, -1.0, delta);
            let (v_right, a_right) = b.derivatives(t, 1.0, delta);
            let hh = h as f64;
            let velocity = (c[i + 1] - c[i - 1]) / (2.0 * hh);
            let acceleration = (c[i - 1] - 2.0 * c[i] + c[i + 1]) / (hh * hh);
            // Rounding of ~4e-7 samples through the difference weights.
            let (tol_v, tol_a) = (40.0 * 4e-7 / (6.0 * delta as f64), 12.0 * 4e-7 / (delta as f64).powi(2));
            for (side, v, a) in [("left", v_left, a_left), ("right", v_right, a_right)] {
                assert!(near(v, velocity, tol_v), "h = {h}, key {i}, {side}: velocity {v} vs {velocity}");
                assert!(near(a, acceleration, tol_a), "h = {h}, key {i}, {side}: acceleration {a} vs {acceleration}");
            }
            let (_, cl) = cr.derivatives(t, -1.0, delta);
            let (_, cr_right) = cr.derivatives(t, 1.0, delta);
            catmull_jump = catmull_jump.max((cl - cr_right).abs().max_element() / (tol_a as f32));
        }
        assert!(
            catmull_jump > 100.0,
            "the same check sees Catmull-Rom's second-derivative jumps ({catmull_jump}× tol)"
        );
    }
}

/// Non-uniform keys: each segment is the uniform basis in its own `u`
/// (docs/clip-format.md, “Other interpolation modes”), so what is continuous at
/// a key is the derivative in `u`: the velocity in seconds times the segment's
/// length agrees on both sides.
#[test]
fn non_uniform_keys_are_smooth_in_the_segment_parameter() {
    let c = keys();
    let times = [0.0f32, 0.5, 2.5, 3.0, 3.25, 5.25];
    let clip = translation_clip(Interpolation::BSpline, None, &times, &c);
    let mut probe = Probe::new(&clip);
    for i in 1..5 {
        let (h_left, h_right) = (times[i] - times[i - 1], times[i + 1] - times[i]);
        let delta = h_left.min(h_right) / 64.0;
        let (v_left, _) = probe.derivatives(times[i], -1.0, delta);
        let (v_right, _) = probe.derivatives(times[i], 1.0, delta);
        let (du_left, du_right) = (v_left * h_left, v_right * h_right);
        let expected = (c[i + 1] - c[i - 1]) / 2.0;
        assert!(near(du_left, expected, 2e-3) && near(du_right, expected, 2e-3), "key {i}: {du_left} {du_right}");
    }
}

/// `reflect` (the default) starts exactly at the first key and ends exactly
/// at the last, for vectors and rotations; the track holds them outside.
#[test]
fn reflect_ends_start_at_the_first_key_and_end_at_the_last() {
    let c = keys();
    let times = [0.0f32, 0.3, 1.0, 1.2, 2.0, 2.7];
    let clip = translation_clip(Interpolation::BSpline, None, &times, &c);
    let mut probe = Probe::new(&clip);
    for t in [-1.0, 0.0] {
        assert_eq!(probe.at(t), Vec3A::from(c[0].as_vec3()), "t = {t}");
    }
    for t in [2.7, 5.0] {
        assert_eq!(probe.at(t), Vec3A::from(c[5].as_vec3()), "t = {t}");
    }
    let mut rng = Rng::new(181);
    let q = crate::random::quats(&mut rng, 6, 70.0);
    let clip = rotation_clip(None, &times, &q);
    let mut probe = Probe::new(&clip);
    for (t, key) in [(0.0, q[0]), (2.7, q[5])] {
        let got = Vec4::from(probe.rotation(t));
        let key = key.normalize();
        let err = (got - key).abs().max_element().min((got + key).abs().max_element());
        assert!(err <= 2e-6, "t = {t}: {got} vs {key}");
    }
}

/// `zero_slope` mirrors (`c_{−1} = c_1`): the curve starts at
/// `(2c_0 + c_1)/3` with zero velocity, and ends likewise.
#[test]
fn zero_slope_ends_start_and_stop_at_rest() {
    let c = keys();
    let times: Vec<f32> = (0..6).map(|i| i as f32).collect();
    let clip = translation_clip(Interpolation::BSpline, Some(Ends::ZeroSlope), &times, &c);
    let mut probe = Probe::new(&clip);
    assert!(near(probe.at(0.0), (2.0 * c[0] + c[1]) / 3.0, 2e-6));
    assert!(near(probe.at(5.0), (2.0 * c[5] + c[4]) / 3.0, 2e-6));
    let (start, _) = probe.derivatives(0.0, 1.0, 1.0 / 64.0);
    let (end, _) = probe.derivatives(5.0, -1.0, 1.0 / 64.0);
    assert!(start.abs().max_element() < 2e-3 && end.abs().max_element() < 2e-3, "{start} {end}");
}

/// `wrap` with uniform keys loops with C2 at the seam: the end's left
/// derivatives equal the start's right ones.
#[test]
fn wrap_loops_c2_across_the_seam() {
    let mut c = keys();
    c[5] = c[0];
    let times: Vec<f32> = (0..6).map(|i| i as f32).collect();
    let clip = translation_clip(Interpolation::BSpline, Some(Ends::Wrap), &times, &c);
    let mut probe = Probe::new(&clip);
    assert!(near(probe.at(0.0), probe.at(5.0).as_dvec3(), 1e-6));
    let delta = 1.0 / 16.0;
    let (v_end, a_end) = probe.derivatives(5.0, -1.0, delta);
    let (v_start, a_start) = probe.derivatives(0.0, 1.0, delta);
    assert!(near(v_end, v_start.as_dvec3(), 2e-3), "velocity {v_end} vs {v_start}");
    assert!(near(a_end, a_start.as_dvec3(), 5e-2), "acceleration {a_end} vs {a_start}");
}

/// Rotations about one axis: every slerp of the construction moves the
/// angle linearly, so the rotation is the B-spline of the angles.
#[test]
fn rotations_about_one_axis_follow_the_b_spline_of_their_angles() {
    let axis = DVec3::new(0.0, 0.6, 0.8);
    let angles = [0.3, 1.4, 1.1, 2.6, 3.9, 3.5];
    let q: Vec<Vec4> = angles.iter().map(|&a| Vec4::from(DQuat::from_axis_angle(axis, a).as_quat())).collect();
    let times: Vec<f32> = (0..6).map(|i| 0.5 * i as f32).collect();
    for ends in [Ends::Reflect, Ends::ZeroSlope, Ends::Phantom] {
        let clip = rotation_clip(Some(ends), &times, &q);
        let angle_keys: Vec<DVec3> = angles.iter().map(|&a| DVec3::new(a, 0.0, 0.0)).collect();
        let p = polygon(&angle_keys, ends);
        let t: Vec<f64> = times.iter().map(|&x| x as f64).collect();
        let knots = if ends == Ends::Phantom { &t[1..5] } else { &t[..] };
        let mut probe = Probe::new(&clip);
        for k in 0..=100 {
            let time = knots[0] + (knots[knots.len() - 1] - knots[0]) * k as f64 / 100.0;
            let angle = lecture_curve(&p, knots, time).x;
            let expected = Vec4::from(DQuat::from_axis_angle(axis, angle).as_quat());
            let got = Vec4::from(probe.rotation(time as f32));
            let err = (got - expected).abs().max_element().min((got + expected).abs().max_element());
            assert!(err <= 2e-6, "{ends:?} at t = {time}: {got} vs {expected}");
        }
    }
}

/// Rotations in general: unit quaternions everywhere and C1 at uniform
/// keys (the slerp construction shares each joint and its tangent).
#[test]
fn rotations_are_unit_and_c1() {
    let mut rng = Rng::new(1818);
    for max_deg in [30.0, 120.0] {
        let q = crate::random::quats(&mut rng, 7, max_deg);
        let times: Vec<f32> = (0..7).map(|i| 0.5 * i as f32).collect();
        let clip = rotation_clip(None, &times, &q);
        let mut probe = Probe::new(&clip);
        for k in 0..=300 {
            let r = probe.rotation(3.0 * k as f32 / 300.0);
            assert!((r.length() - 1.0).abs() <= 1e-6, "|q| = {}", r.length());
        }
        let delta = 1.0 / 256.0;
        let mut slope = |t: f32, dir: f32| {
            let f: Vec<Vec4> = (0..3).map(|k| Vec4::from(probe.rotation(t + dir * k as f32 * delta))).collect();
            let align = |v: Vec4| if v.dot(f[0]) < 0.0 { -v } else { v };
            (f[0] * -3.0 + align(f[1]) * 4.0 - align(f[2])) / (2.0 * delta) * dir
        };
        for (i, &t) in times.iter().enumerate().take(6).skip(1) {
            let (left, right) = (slope(t, -1.0), slope(t, 1.0));
            let tol = 1e-2 + 2e-3 * left.length().max(right.length());
            assert!((left - right).abs().max_element() <= tol, "≤{max_deg}°: key {i}: {left} vs {right}");
        }
    }
}

/// A single key is constant, as in every mode.
#[test]
fn a_single_key_is_constant() {
    let clip = translation_clip(Interpolation::BSpline, None, &[1.0], &[DVec3::new(1.0, 2.0, 3.0)]);
    let mut probe = Probe::new(&clip);
    for t in [0.0, 1.0, 2.0] {
        assert_eq!(probe.at(t), Vec3A::from(Vec3::new(1.0, 2.0, 3.0)));
    }
}
