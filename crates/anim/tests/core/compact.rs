//! Compact frames' error analysis (docs/compact-frames.md): the widths a
//! layout chooses keep every joint and every virtual point within the
//! bound, measured by an f64 forward kinematics written here from
//! docs/clip-format.md, “Skeleton and spaces”; and one width worked by hand.

use anim::compact::{Layout, Ranges, Rotation};
use anim::{Pose, Skeleton};
use glam::{DQuat, DVec3, Quat, Vec3, Vec3A};

use crate::ik::{J, body};
use crate::random::Rng;

/// Model-space joint positions and the three points `distance` along each
/// joint's axes (`M_j · (distance · axis)`), in f64.
fn points(skeleton: &Skeleton, pose: &Pose, distance: f64) -> Vec<DVec3> {
    let n = pose.len();
    let (mut t, mut q, mut s) = (vec![DVec3::ZERO; n], vec![DQuat::IDENTITY; n], vec![DVec3::ONE; n]);
    let mut out = Vec::with_capacity(4 * n);
    for j in 0..n {
        let (tl, ql, sl) = (
            Vec3::from(pose.translations[j]).as_dvec3(),
            pose.rotations[j].as_dquat(),
            Vec3::from(pose.scales[j]).as_dvec3(),
        );
        (t[j], q[j], s[j]) = match skeleton.parent(j) {
            None => (tl, ql, sl),
            Some(p) => (t[p] + q[p] * (s[p] * tl), q[p] * ql, s[p] * sl),
        };
        out.push(t[j]);
        for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
            out.push(t[j] + q[j] * (s[j] * axis * distance));
        }
    }
    out
}

fn worst_error(skeleton: &Skeleton, layout: &Layout, pose: &Pose) -> f64 {
    let (mut values, mut decoded) = (Vec::new(), Pose::default());
    layout.quantise(pose, &mut values);
    layout.dequantise(&values, &mut decoded);
    let d = f64::from(layout.distance);
    let (a, b) = (points(skeleton, pose, d), points(skeleton, &decoded, d));
    a.iter().zip(&b).map(|(x, y)| x.distance(*y)).fold(0.0, f64::max)
}

/// A random tree: each joint hangs off one of the previous few.
fn tree(rng: &mut Rng, n: usize) -> Vec<J> {
    (0..n)
        .map(|i| J {
            parent: (i > 0).then(|| i - 1 - rng.below(i.min(3))),
            t: rng.vec3(0.3),
            q: Quat::IDENTITY,
            s: 1.0,
        })
        .collect()
}

fn random_pose(rng: &mut Rng, skeleton: &Skeleton, scaled: bool) -> Pose {
    let mut pose = skeleton.rest().clone();
    for j in 0..pose.len() {
        pose.rotations[j] = Quat::from_axis_angle(rng.axis(), rng.range(-3.0, 3.0) as f32);
        pose.translations[j] += Vec3A::from(rng.vec3(0.05));
        if scaled {
            pose.scales[j] =
                Vec3A::new(rng.range(0.9, 1.1) as f32, rng.range(0.9, 1.1) as f32, rng.range(0.9, 1.1) as f32);
        }
    }
    pose
}

#[test]
fn every_joint_and_virtual_point_stays_within_the_bound() {
    let mut rng = Rng::new(32);
    for (case, (joints, scaled, max_error, attainable)) in [
        (12, false, 1e-4f32, true),
        (16, true, 1e-4, true),
        (4, false, 1e-5, true),
        (8, true, 1e-6, false),
        (20, false, 1e-3, true),
    ]
    .into_iter()
    .enumerate()
    {
        let clip = body(&tree(&mut rng, joints));
        let skeleton = clip.skeleton();
        let poses: Vec<Pose> = (0..40).map(|_| random_pose(&mut rng, skeleton, scaled)).collect();
        let mut ranges = Ranges::new(joints);
        poses.iter().for_each(|p| ranges.observe(p));
        let layout = Layout::choose(skeleton, &ranges, max_error, 0.05);
        let worst = poses.iter().map(|p| worst_error(skeleton, &layout, p)).fold(0.0, f64::max);
        assert!(worst <= f64::from(layout.bound), "case {case}: measured {worst} > stated {}", layout.bound);
        if attainable {
            assert!(layout.bound <= max_error, "case {case}: computed bound {} > {max_error}", layout.bound);
        } else {
            // f32 cannot resolve it: the widths stop at 24 bits and say so.
            assert!(layout.bound > max_error, "case {case}: {} claimed", layout.bound);
            continue;
        }
        // The widths are not wasted: the measured error is a fair share of the bound.
        assert!(worst > f64::from(max_error) / 100.0, "case {case}: measured {worst} far below {max_error}");
    }
}

#[test]
fn deeper_chains_get_more_bits_and_still_stay_within_the_bound() {
    // A straight chain: the root carries the whole chain's reach and
    // shares the budget with every joint below it.
    let chain: Vec<J> = (0..10usize)
        .map(|i| J { parent: i.checked_sub(1), t: Vec3::new(0.0, 0.1, 0.0), q: Quat::IDENTITY, s: 1.0 })
        .collect();
    let clip = body(&chain);
    let mut rng = Rng::new(7);
    let poses: Vec<Pose> = (0..40).map(|_| random_pose(&mut rng, clip.skeleton(), false)).collect();
    let mut ranges = Ranges::new(10);
    poses.iter().for_each(|p| ranges.observe(p));
    let layout = Layout::choose(clip.skeleton(), &ranges, 1e-4, 0.05);
    let bits = |j: usize| layout.joints[j].bits();
    assert!(bits(0) > bits(9), "root {} bits, tip {}", bits(0), bits(9));
    let worst = poses.iter().map(|p| worst_error(clip.skeleton(), &layout, p)).fold(0.0, f64::max);
    assert!(worst <= 1e-4, "{worst}");
}

#[test]
fn one_rotating_joint_gets_the_bits_worked_by_hand() {
    // One joint turning about y from 0 to 1 rad: x and z stay 0, w is always
    // the largest (from cos 0.5 = 0.8776 to 1), y spans [0, sin 0.5 = 0.4794].
    // Reach = distance = 0.1 m and a budget of 0.9e-4 m allow 9e-4 rad. With
    // y off by e, the rebuilt w is off by x ≈ e(2 · 0.4794) / (2 · 0.8776)
    // = 0.546e, the chord is e√(1 + 0.546²) = 1.139e and the angle twice
    // that: 2.279e ≤ 9e-4 ⇒ e ≤ 3.95e-4 ⇒ (0.4794 / 2) / (2^b - 1) ≤ 3.95e-4
    // ⇒ 2^b - 1 ≥ 607 ⇒ b = 10 (511 steps are too few).
    let clip = body(&[J { parent: None, t: Vec3::ZERO, q: Quat::IDENTITY, s: 1.0 }]);
    let mut ranges = Ranges::new(1);
    let mut pose = clip.skeleton().rest().clone();
    ranges.observe(&pose);
    pose.rotations[0] = Quat::from_rotation_y(1.0);
    ranges.observe(&pose);
    let layout = Layout::choose(clip.skeleton(), &ranges, 1e-4, 0.1);
    let Rotation::Quantised(r) = layout.joints[0].rotation else { panic!("the rotation changes") };
    assert_eq!(r.largest, Some(3), "w is always the largest: its index is not sent");
    assert_eq!(r.components.map(|a| a.bits), [0, 10, 0, 0]);
    assert_eq!(layout.joints[0].translation.map(|a| a.bits), [0; 3], "constant translation is sent once");
    assert_eq!(layout.key_bits(), 10);
}

#[test]
fn constant_channels_are_detected_and_cost_no_bits() {
    let clip = body(&[
        J { parent: None, t: Vec3::new(0.0, 1.0, 0.0), q: Quat::IDENTITY, s: 1.0 },
        J { parent: Some(0), t: Vec3::new(0.0, 0.5, 0.0), q: Quat::from_rotation_x(0.3), s: 1.0 },
    ]);
    let mut ranges = Ranges::new(2);
    let mut pose = clip.skeleton().rest().clone();
    ranges.observe(&pose);
    pose.translations[0].x = 0.25;
    ranges.observe(&pose);
    let layout = Layout::choose(clip.skeleton(), &ranges, 1e-4, 0.1);
    let root = layout.joints[0];
    assert!(root.translation[0].bits > 0 && root.translation[1].bits == 0 && root.translation[2].bits == 0);
    assert_eq!((root.translation[1].min, root.translation[1].max), (1.0, 1.0));
    assert!(matches!(root.rotation, Rotation::Constant(q) if q == Quat::IDENTITY));
    assert!(!layout.joints[1].is_animated());
    assert!(
        matches!(layout.joints[1].rotation, Rotation::Constant(q) if q.abs_diff_eq(Quat::from_rotation_x(0.3), 1e-7))
    );
}

/// Derived ranges (docs/compact-frames.md, “What a compact stream plays”):
/// a motion of blend layers (one masked) and an additive layer over random
/// clips of one rig, sampled at random times under random layer weights,
/// never leaves the ranges derived from its clips; and the layout chosen
/// from them keeps those poses within its bound.
#[test]
fn composed_poses_stay_within_their_derived_ranges() {
    use anim::motion::{LayerMode, LayerSpec, MaskSpec, MotionOptions, MotionSpec};
    use anim::{Clip, Motion, MotionSampler};

    let mut rng = Rng::new(0xc0ba);
    for case in 0..24 {
        let n = 3 + rng.below(6);
        let base = crate::random::skeleton_clip(&mut rng, n);
        let clips: Vec<Clip> = (0..3)
            .map(|i| {
                let mut spec = if i == 0 { base.clone() } else { crate::random::skeleton_clip(&mut rng, n) };
                spec.skeleton = base.skeleton.clone();
                Clip::build(&spec).unwrap()
            })
            .collect();
        let mask = MaskSpec { joints: vec![("j1".to_owned(), 0.7)], descendants: true, default: None };
        let layers = vec![
            LayerSpec::new(&clips[0]),
            LayerSpec { mask: Some(mask), weight: 0.5, ..LayerSpec::new(&clips[1]) },
            LayerSpec { mode: LayerMode::Additive, reference_time: Some(0.1), ..LayerSpec::new(&clips[2]) },
        ];
        let motion = Motion::build(MotionSpec { layers, root_motion: None, ..Default::default() }).unwrap();
        let ranges = Ranges::of_motion(&motion, 240.0).unwrap();
        let skeleton = motion.skeleton();
        let layout = Layout::choose(skeleton, &ranges, 1e-4, 0.1);
        let (mut sampler, mut phases) = (MotionSampler::new(), Vec::new());
        for _ in 0..200 {
            let weights: Vec<f32> = (0..3).map(|_| rng.unit() as f32).collect();
            let tau = rng.range(-1.0, 4.0);
            motion.phases_at(tau, &weights, &mut phases);
            motion.sample_with(tau, &phases, &weights, &MotionOptions::default(), &mut sampler);
            let pose = sampler.pose();
            assert_eq!(ranges.outside(pose), None, "case {case}, weights {weights:?}, τ {tau}");
            let error = worst_error(skeleton, &layout, pose);
            assert!(error <= 1e-4, "case {case}: {error} > 1e-4");
        }
    }
}
