//! The lecture's worked examples, exactly, through the public API.
//!
//! Lecture notation `<w; x, y, z>` is glam's `Quat::from_xyzw(x, y, z, w)`.
//! Where a value is a closed form (√3/2, √6/4, …) it is written as one,
//! and rotations are checked by what they do to vectors in model space
//! (Rodrigues' formula worked by hand), so a test cannot pass by agreeing
//! with glam's own conventions.

use anim::internals::{SlerpTier, bezier3, catmull_rom, quat_segment, slerp_bezier};
use anim::quat::{pow, slerp_f64, slerp_fast};
use anim::{
    Channel, Clip, ClipSpec, Ends, Interpolation, JointSpec, Keys, Playback, SampleOptions, Sampler, SkeletonSpec,
    Space, TrackSpec, Transform,
};
use glam::{DQuat, DVec3, Quat, Vec3, Vec3A, Vec4};

/// Closed forms computed in f64 and compared to f64 results.
const F64_EXACT: f64 = 1e-12;
/// f32 results (sampled poses) against closed forms.
const F32_EXACT: f32 = 2e-6;
/// Central differences on f32 samples with step `DELTA`: truncation
/// `δ²·|c'''|/6` inside a cubic, `δ·|Δc''|/4` across a key where only C1
/// holds, plus rounding `ε·|c|/δ`; all well below this.
const DELTA: f32 = 1e-3;
const DERIVATIVE_TOL: f32 = 2e-3;

fn lecture(w: f64, x: f64, y: f64, z: f64) -> DQuat {
    DQuat::from_xyzw(x, y, z, w)
}

fn near_q(a: DQuat, b: DQuat, tol: f64) -> bool {
    (a.x - b.x).abs().max((a.y - b.y).abs()).max((a.z - b.z).abs()).max((a.w - b.w).abs()) <= tol
}

fn near_qf(a: Quat, b: DQuat) -> bool {
    near_q(a.as_dquat(), b, F32_EXACT as f64) || near_q(-a.as_dquat(), b, F32_EXACT as f64)
}

fn near3(a: Vec3A, b: [f64; 3], tol: f32) -> bool {
    (a - Vec3A::from(DVec3::from(b).as_vec3())).abs().max_element() <= tol
}

fn rotation_track(joint: &str, interp: Interpolation, times: Vec<f32>, keys: &[DQuat]) -> TrackSpec {
    let values = keys.iter().map(|q| Vec4::from(q.as_quat())).collect();
    TrackSpec::new(joint, Channel::Rotation, interp, times, Keys::Vec4(values))
}

fn vec3_track(joint: &str, interp: Interpolation, times: Vec<f32>, keys: &[[f32; 3]]) -> TrackSpec {
    TrackSpec::new(
        joint,
        Channel::Translation,
        interp,
        times,
        Keys::Vec3(keys.iter().map(|&k| Vec3::from(k)).collect()),
    )
}

fn clip(tracks: Vec<TrackSpec>, skeleton: Option<SkeletonSpec>) -> Clip {
    Clip::build(&ClipSpec {
        name: "lecture".into(),
        skeleton,
        tracks,
        events: vec![],
        playback: Playback::Once,
        ..Default::default()
    })
    .unwrap()
}

/// A parent joint "p" turned by `q`, and its child "c" at `offset`.
fn parent_and_child(q: DQuat, child_rotation: DQuat, offset: [f32; 3]) -> Clip {
    let joint = |name: &str, parent: Option<&str>, translation: Vec3| JointSpec {
        name: name.into(),
        parent: parent.map(Into::into),
        rest: Transform { translation, ..Transform::IDENTITY },
        inverse_bind: None,
    };
    let skeleton =
        SkeletonSpec { joints: vec![joint("p", None, Vec3::ZERO), joint("c", Some("p"), Vec3::from(offset))] };
    clip(
        vec![
            rotation_track("p", Interpolation::Linear, vec![0.0], &[q]),
            rotation_track("c", Interpolation::Linear, vec![0.0], &[child_rotation]),
        ],
        Some(skeleton),
    )
}

fn model_pose(clip: &Clip, t: f64) -> anim::Pose {
    let mut sampler = Sampler::new();
    clip.sample(t, &SampleOptions { space: Space::Model, ..Default::default() }, &mut sampler);
    sampler.pose().clone()
}

#[test]
fn slerp_from_identity_to_a_half_turn_about_y_at_one_third() {
    let (p, q) = (lecture(1.0, 0.0, 0.0, 0.0), lecture(0.0, 0.0, 1.0, 0.0));
    let expected = lecture(3f64.sqrt() / 2.0, 0.0, 0.5, 0.0);
    assert!(near_q(slerp_f64(p, q, 1.0 / 3.0), expected, F64_EXACT));
    assert!(near_qf(slerp_fast(p.as_quat(), q.as_quat(), 1.0 / 3.0), expected));
    // And as a clip: a linear rotation track sampled a third of the way.
    let c = clip(vec![rotation_track("j", Interpolation::Linear, vec![0.0, 3.0], &[p, q])], None);
    let mut sampler = Sampler::new();
    c.sample(1.0, &SampleOptions::default(), &mut sampler);
    assert!(near_qf(sampler.pose().rotations[0], expected), "{:?}", sampler.pose().rotations[0]);
}

#[test]
fn sixty_degrees_about_one_one_one() {
    let r = 1.0 / (2.0 * 3f64.sqrt());
    let q = lecture(3f64.sqrt() / 2.0, r, r, r);
    assert!((q.length() - 1.0).abs() < F64_EXACT, "a unit quaternion");
    // Cubed, 180° about the same axis: <0; 1/√3, 1/√3, 1/√3>.
    let s = 1.0 / 3f64.sqrt();
    assert!(near_q(pow(q, 3.0), lecture(0.0, s, s, s), F64_EXACT));
    // Rodrigues by hand: x̂ turned 60° about (1,1,1)/√3 is (2/3, 2/3, −1/3).
    let pose = model_pose(&parent_and_child(q, DQuat::IDENTITY, [1.0, 0.0, 0.0]), 0.0);
    assert!(near3(pose.translations[1], [2.0 / 3.0, 2.0 / 3.0, -1.0 / 3.0], F32_EXACT), "{:?}", pose.translations[1]);
    assert!(near_qf(pose.rotations[1], q));
}

#[test]
fn one_hundred_twenty_degrees_about_the_yz_diagonal() {
    let q = lecture(0.5, 0.0, 6f64.sqrt() / 4.0, 6f64.sqrt() / 4.0);
    assert!((q.length() - 1.0).abs() < F64_EXACT);
    // cos(θ/2) = 1/2 → θ = 120°; axis = (0, √6/4, √6/4)/sin 60° = (0, √2/2, √2/2).
    // Half of it is 60° about the same axis: <√3/2; 0, √2/4, √2/4>.
    let half = lecture(3f64.sqrt() / 2.0, 0.0, 2f64.sqrt() / 4.0, 2f64.sqrt() / 4.0);
    assert!(near_q(pow(q, 0.5), half, F64_EXACT));
    assert!(near_q(slerp_f64(DQuat::IDENTITY, q, 0.5), half, F64_EXACT));
    // A point on the axis stays put; x̂ goes to (−1/2, √6/4, −√6/4).
    let on_axis = model_pose(&parent_and_child(q, DQuat::IDENTITY, [0.0, 1.0, 1.0]), 0.0);
    assert!(near3(on_axis.translations[1], [0.0, 1.0, 1.0], F32_EXACT));
    let x = model_pose(&parent_and_child(q, DQuat::IDENTITY, [1.0, 0.0, 0.0]), 0.0);
    let r6 = 6f64.sqrt() / 4.0;
    assert!(near3(x.translations[1], [-0.5, r6, -r6], F32_EXACT), "{:?}", x.translations[1]);
}

#[test]
fn ninety_then_sixty_about_the_same_axis_compose_to_one_fifty() {
    let axis = DVec3::new(3.0 / 5.0, 0.0, 4.0 / 5.0);
    let about = |deg: f64| {
        let (s, c) = (deg.to_radians() / 2.0).sin_cos();
        lecture(c, s * axis.x, s * axis.y, s * axis.z)
    };
    // cos 45° = √2/2: the 90° key by hand.
    let r2 = 2f64.sqrt() / 2.0;
    assert!(near_q(about(90.0), lecture(r2, r2 * 0.6, 0.0, r2 * 0.8), F64_EXACT));
    // Parent turned 90°, child 60° more: the child's model rotation is 150°.
    let pose = model_pose(&parent_and_child(about(90.0), about(60.0), [0.0, 0.0, 0.0]), 0.0);
    assert!(near_qf(pose.rotations[1], about(150.0)), "{:?}", pose.rotations[1]);
    // And slerp from the 90° key to the 150° one at 1/2 is 120°.
    assert!(near_q(slerp_f64(about(90.0), about(150.0), 0.5), about(120.0), F64_EXACT));
}

#[test]
fn bezier_endpoints_tangents_and_partition_of_unity() {
    let p =
        [Vec3A::new(0.0, 0.0, 0.0), Vec3A::new(1.0, 2.0, 0.0), Vec3A::new(3.0, 2.0, 1.0), Vec3A::new(4.0, 0.0, 2.0)];
    assert_eq!(bezier3(&p, 0.0), p[0], "c(0) = c_0");
    assert_eq!(bezier3(&p, 1.0), p[3], "c(1) = c_1");
    let derivative = |u: f32| (bezier3(&p, u + DELTA) - bezier3(&p, u - DELTA)) / (2.0 * DELTA);
    assert!((derivative(0.0) - 3.0 * (p[1] - p[0])).abs().max_element() <= DERIVATIVE_TOL, "c'(0) = 3(d_0 − c_0)");
    assert!((derivative(1.0) - 3.0 * (p[3] - p[2])).abs().max_element() <= DERIVATIVE_TOL, "c'(1) = 3(c_1 − e_0)");
    // Each Bernstein weight read off through unit control points, and
    // their sum is one.
    let first = [Vec3A::X, Vec3A::Y, Vec3A::Z, Vec3A::ZERO];
    let last = [Vec3A::ZERO, Vec3A::ZERO, Vec3A::ZERO, Vec3A::X];
    for k in 0..=20 {
        let u = k as f32 / 20.0;
        let (b012, b3) = (bezier3(&first, u), bezier3(&last, u).x);
        let v = 1.0 - u;
        let hand = [v * v * v, 3.0 * u * v * v, 3.0 * u * u * v, u * u * u];
        let got = [b012.x, b012.y, b012.z, b3];
        for (g, h) in got.iter().zip(hand) {
            assert!((g - h).abs() <= 1e-6, "weight at u = {u}: {got:?} vs {hand:?}");
        }
        assert!((got.iter().sum::<f32>() - 1.0).abs() <= 1e-6, "partition of unity at u = {u}");
        let same = [Vec3A::splat(2.5); 4];
        assert!((bezier3(&same, u) - Vec3A::splat(2.5)).abs().max_element() <= 1e-6);
    }
}

#[test]
fn slerp_bezier_interpolates_its_end_keys_and_is_constant_on_equal_points() {
    let a = Vec4::from(Quat::from_rotation_y(0.4));
    let b = Vec4::from(Quat::from_rotation_y(0.9));
    let d = Vec4::from(Quat::from_rotation_y(1.3));
    let c1 = Vec4::from(Quat::from_rotation_y(1.5));
    let d64 = |q: Vec4| Quat::from_vec4(q).as_dquat();
    // Every evaluation tier gives the same curve (the turn here, 0.55 rad, is
    // small enough for even the 3-term series to stay within 1e-7).
    for tier in [SlerpTier::Tiny, SlerpTier::Narrow, SlerpTier::Wide, SlerpTier::Exact] {
        let mut seg = quat_segment(&[d64(a), d64(b), d64(d), d64(c1)]);
        seg.tier = tier;
        assert!((Vec4::from(slerp_bezier(&seg, 0.0)) - a).abs().max_element() <= 1e-6);
        assert!((Vec4::from(slerp_bezier(&seg, 1.0)) - c1).abs().max_element() <= 1e-6);
        // On one axis the pyramid is the scalar Bezier of the angles.
        for k in 0..=8 {
            let u = k as f32 / 8.0;
            let v = 1.0 - u;
            let angle = 0.4 * v * v * v + 0.9 * 3.0 * u * v * v + 1.3 * 3.0 * u * u * v + 1.5 * u * u * u;
            let expected = Vec4::from(Quat::from_rotation_y(angle));
            let got = Vec4::from(slerp_bezier(&seg, u));
            assert!((got - expected).abs().max_element() <= 1e-6, "tier = {tier:?}, u = {u}: {got} vs {expected}");
        }
        let mut same = quat_segment(&[d64(b); 4]);
        same.tier = tier;
        assert!((Vec4::from(slerp_bezier(&same, 0.37)) - b).abs().max_element() <= 1e-6);
    }
}

#[test]
fn uniform_catmull_rom_uses_one_sixth() {
    let c: Vec<DVec3> = [[0.0, 0.0, 0.0], [1.0, 2.0, 0.0], [3.0, 3.0, 1.0], [4.0, 1.0, 2.0], [6.0, 0.0, 0.0]]
        .iter()
        .map(|&v| DVec3::from(v))
        .collect();
    let t: Vec<f64> = (0..c.len()).map(|i| i as f64).collect();
    let segs = catmull_rom(&c, &t, Ends::Reflect, 0.5);
    assert_eq!(segs.len(), c.len() - 1);
    for i in 1..c.len() - 2 {
        let [ci, d, e, cn] = segs[i];
        assert_eq!((ci, cn), (c[i], c[i + 1]));
        assert!((d - (c[i] + (c[i + 1] - c[i - 1]) / 6.0)).abs().max_element() <= F64_EXACT, "d_{i}");
        assert!((e - (c[i + 1] - (c[i + 2] - c[i]) / 6.0)).abs().max_element() <= F64_EXACT, "e_{i}");
    }
    // Reflect: c_{-1} = 2c_0 − c_1, so d_0 = c_0 + (c_1 − c_0)/3.
    assert!((segs[0][1] - (c[0] + (c[1] - c[0]) / 3.0)).abs().max_element() <= F64_EXACT);

    // Sampled: the velocity at an interior key is (c_{i+1} − c_{i−1})/2.
    let keys: Vec<[f32; 3]> = c.iter().map(|v| v.as_vec3().to_array()).collect();
    let times: Vec<f32> = t.iter().map(|&x| x as f32).collect();
    let clip = clip(vec![vec3_track("j", Interpolation::CatmullRom, times, &keys)], None);
    let mut sampler = Sampler::new();
    let mut at = |t: f32| {
        clip.sample(t as f64, &SampleOptions::default(), &mut sampler);
        sampler.pose().translations[0]
    };
    for i in 1..c.len() - 1 {
        let ti = i as f32;
        let v = (at(ti + DELTA) - at(ti - DELTA)) / (2.0 * DELTA);
        let expected = ((c[i + 1] - c[i - 1]) / 2.0).as_vec3();
        assert!(
            (v - Vec3A::from(expected)).abs().max_element() <= DERIVATIVE_TOL,
            "c'({i}) = {v}, expected {expected}"
        );
    }
}

/// The "hack by association" on one axis: angles behave like numbers.
#[test]
fn uniform_quaternion_catmull_rom_uses_one_sixth_of_the_angle() {
    let angles = [0.0, 0.5, 0.7, 1.6, 2.0];
    let c: Vec<DQuat> = angles.iter().map(|&a| DQuat::from_axis_angle(DVec3::new(0.0, 0.6, 0.8), a)).collect();
    let t: Vec<f64> = (0..c.len()).map(|i| i as f64).collect();
    let segs = catmull_rom(&c, &t, Ends::Reflect, 0.5);
    for i in 1..c.len() - 2 {
        let d = angles[i] + (angles[i + 1] - angles[i - 1]) / 6.0;
        let e = angles[i + 1] - (angles[i + 2] - angles[i]) / 6.0;
        let axis = DVec3::new(0.0, 0.6, 0.8);
        assert!(near_q(segs[i][1], DQuat::from_axis_angle(axis, d), F64_EXACT), "d_{i}");
        assert!(near_q(segs[i][2], DQuat::from_axis_angle(axis, e), F64_EXACT), "e_{i}");
    }
}

/// `phantom` ends: the lecture's setup, values at −1 and n+1 that shape the
/// ends but are not interpolated; the clip runs over [0, n].
#[test]
fn phantom_ends_reproduce_the_lecture_setup() {
    let keys = [[5.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 0.0, 1.0], [3.0, 1.0, 1.0], [-4.0, 2.0, 0.0]];
    let times: Vec<f32> = (-1..=4).map(|i| i as f32).collect();
    let mut track = vec3_track("j", Interpolation::CatmullRom, times.clone(), &keys);
    track.ends = Some(Ends::Phantom);
    let clip = clip(vec![track], None);
    assert_eq!((clip.start(), clip.end()), (0.0, 3.0));

    let c: Vec<DVec3> = keys.iter().map(|&k| DVec3::from(k.map(f64::from))).collect();
    let t: Vec<f64> = times.iter().map(|&x| x as f64).collect();
    let segs = catmull_rom(&c, &t, Ends::Phantom, 0.5);
    assert_eq!(segs.len(), 3, "segments between the inner keys only");
    // Lecture: with c_{-1} = keys[0], segment i runs c_i → c_{i+1} and
    // d_i = c_i + (c_{i+1} − c_{i−1})/6, e_i = c_{i+1} − (c_{i+2} − c_i)/6.
    let hand: Vec<[DVec3; 4]> = (1..=3)
        .map(|i| [c[i], c[i] + (c[i + 1] - c[i - 1]) / 6.0, c[i + 1] - (c[i + 2] - c[i]) / 6.0, c[i + 1]])
        .collect();
    for (s, h) in segs.iter().zip(&hand) {
        for (a, b) in s.iter().zip(h) {
            assert!((*a - *b).abs().max_element() <= F64_EXACT, "{s:?} vs {h:?}");
        }
    }
    // Sampled: the Bernstein form of the hand control points; held outside.
    let mut sampler = Sampler::new();
    for k in 0..=30 {
        let time = k as f64 / 10.0;
        clip.sample(time, &SampleOptions::default(), &mut sampler);
        let i = ((time as usize).min(2), time - (time as usize).min(2) as f64);
        let (seg, u) = (&hand[i.0], i.1);
        let v = 1.0 - u;
        let p = seg[0] * (v * v * v) + seg[1] * (3.0 * u * v * v) + seg[2] * (3.0 * u * u * v) + seg[3] * (u * u * u);
        assert!(near3(sampler.pose().translations[0], p.to_array(), F32_EXACT), "t = {time}");
    }
    for (outside, key) in [(-1.0, 1), (-0.5, 1), (3.5, 4), (4.0, 4)] {
        clip.sample(outside, &SampleOptions { playback: Some(Playback::Once), ..Default::default() }, &mut sampler);
        assert!(near3(sampler.pose().translations[0], c[key].to_array(), F32_EXACT), "held at t = {outside}");
    }
}
