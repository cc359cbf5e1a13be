//! Inverse kinematics in the core (docs/ik.md, issue 17): `two_bone` and
//! `aim` against their geometric guarantees on random chains, measured by
//! an `f64` forward kinematics written here from docs/clip-format.md, 2.8; refusals with
//! their paths; no allocation once warm. The chain solver's tests, with an
//! independent implementation of the seed's projected gradient descent,
//! are in `ik/chain.rs`.

mod chain;
mod keyed;

use anim::ik::{
    Aim, ChainStart, IkConstraint, IkErrorKind, IkLimits, IkReport, IkSolver, TwoBone, validate_constraints,
};
use anim::ik::{Chain, Effector, JointLimits};
use anim::{
    Channel, Clip, ClipSpec, Interpolation, JointSpec, Keys, Playback, Pose, Skeleton, SkeletonSpec, TrackSpec,
    Transform,
};
use glam::{DQuat, DVec3, Quat, Vec3, Vec3A, Vec4};

use crate::allocations;
use crate::random::Rng;

/// A joint to build: parent index, rest translation, rotation, uniform scale.
pub struct J {
    pub parent: Option<usize>,
    pub t: Vec3,
    pub q: Quat,
    pub s: f32,
}

/// A clip whose skeleton is `joints` (named `j0`, `j1`, …), rest pose as given.
pub fn body(joints: &[J]) -> Clip {
    let joints: Vec<JointSpec> = joints
        .iter()
        .enumerate()
        .map(|(i, j)| JointSpec {
            name: format!("j{i}"),
            parent: j.parent.map(|p| format!("j{p}")),
            rest: Transform { translation: j.t, rotation: j.q, scale: Vec3::splat(j.s) },
            inverse_bind: None,
        })
        .collect();
    let track = TrackSpec::new(
        "j0",
        Channel::Rotation,
        Interpolation::Linear,
        vec![0.0],
        Keys::Vec4(vec![Vec4::from(joints[0].rest.rotation)]),
    );
    let spec = ClipSpec {
        name: "ik".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks: vec![track],
        events: vec![],
        playback: Playback::Once,
        ..Default::default()
    };
    Clip::build(&spec).expect("test skeleton builds")
}

pub fn rotation(rng: &mut Rng, max_angle: f64) -> Quat {
    Quat::from_axis_angle(rng.axis(), rng.range(0.0, max_angle) as f32)
}

/// A bone of length in `[0.3, 1.2]` in a random direction.
pub fn bone(rng: &mut Rng) -> Vec3 {
    rng.axis() * rng.range(0.3, 1.2) as f32
}

/// A random joint under `parent`.
pub fn joint(rng: &mut Rng, parent: Option<usize>) -> J {
    J { parent, t: bone(rng), q: rotation(rng, 2.5), s: rng.range(0.8, 1.25) as f32 }
}

/// A model transform in `f64`.
#[derive(Debug, Clone, Copy)]
pub struct M {
    pub t: DVec3,
    pub q: DQuat,
    pub s: DVec3,
}

/// docs/clip-format.md, 2.8, in `f64`: `t_m = t_p + q_p·(s_p ⊙ t_l)`, `q_m =
/// q_p·q_l`, `s_m = s_p ⊙ s_l`.
pub fn model_f64(skeleton: &Skeleton, pose: &Pose) -> Vec<M> {
    model_with(skeleton, pose, |j| pose.rotations[j].as_dquat())
}

/// The same, with local rotations given by `rotation(joint)`.
pub fn model_with(skeleton: &Skeleton, pose: &Pose, rotation: impl Fn(usize) -> DQuat) -> Vec<M> {
    let mut out: Vec<M> = Vec::with_capacity(pose.len());
    for j in 0..pose.len() {
        let (t, q, s) = (pose.translations[j].as_dvec3(), rotation(j).normalize(), pose.scales[j].as_dvec3());
        out.push(match skeleton.parent(j) {
            None => M { t, q, s },
            Some(p) => {
                let p = out[p];
                M { t: p.t + p.q * (p.s * t), q: p.q * q, s: p.s * s }
            }
        });
    }
    out
}

/// The angle of the rotation between two (nearly unit) quaternions.
pub fn quat_angle(p: DQuat, q: DQuat) -> f64 {
    2.0 * p.normalize().dot(q.normalize()).abs().min(1.0).acos()
}

pub fn d(v: Vec3A) -> DVec3 {
    v.as_dvec3()
}

pub fn angle(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}

/// The component of `v` perpendicular to unit `axis`.
pub fn across(v: DVec3, axis: DVec3) -> DVec3 {
    v - axis * axis.dot(v)
}

pub fn solve(skeleton: &Skeleton, pose: &mut Pose, constraints: &[IkConstraint]) -> Vec<IkReport> {
    let mut reports = Vec::new();
    IkSolver::new().solve(skeleton, pose, constraints, ChainStart::Cold, &mut reports);
    reports
}

fn assert_finite_unit(pose: &Pose) {
    for (j, q) in pose.rotations.iter().enumerate() {
        assert!(q.is_finite() && (q.length() - 1.0).abs() < 1e-5, "joint {j}: {q:?}");
    }
}

/// `root → upper → [twist] → middle → [twist] → end → child`: the upper
/// joint somewhere in space, random bones, rotations and scales.
struct Limb {
    clip: Clip,
    joints: [usize; 3],
}

fn limb(rng: &mut Rng) -> Limb {
    let mut js = vec![joint(rng, None), joint(rng, Some(0))];
    let upper = 1;
    if rng.chance(0.5) {
        js.push(joint(rng, Some(js.len() - 1)));
    }
    js.push(joint(rng, Some(js.len() - 1)));
    let middle = js.len() - 1;
    if rng.chance(0.5) {
        js.push(joint(rng, Some(js.len() - 1)));
    }
    js.push(joint(rng, Some(js.len() - 1)));
    let end = js.len() - 1;
    js.push(joint(rng, Some(end)));
    Limb { clip: body(&js), joints: [upper, middle, end] }
}

struct Geometry {
    a: DVec3,
    b: DVec3,
    c: DVec3,
    l1: f64,
    l2: f64,
}

fn geometry(skeleton: &Skeleton, pose: &Pose, [u, m, e]: [usize; 3]) -> Geometry {
    let model = model_f64(skeleton, pose);
    let (a, b, c) = (model[u].t, model[m].t, model[e].t);
    Geometry { a, b, c, l1: (b - a).length(), l2: (c - b).length() }
}

/// A target at distance `distance` from `a` in a random direction, as `f32`.
fn target_at(rng: &mut Rng, a: DVec3, distance: f64) -> Vec3A {
    Vec3A::from((a + rng.axis().as_dvec3() * distance).as_vec3())
}

/// Only `changed` rotations differ from `before`; translations and scales are untouched.
fn assert_only_rotated(before: &Pose, after: &Pose, changed: &[usize]) {
    assert_eq!(before.translations, after.translations);
    assert_eq!(before.scales, after.scales);
    for j in (0..before.len()).filter(|j| !changed.contains(j)) {
        assert_eq!(before.rotations[j], after.rotations[j], "joint {j} turned");
    }
}

#[test]
fn two_bone_lands_on_reachable_targets_with_the_middle_on_the_poles_side() {
    let mut rng = Rng::new(1701);
    let (mut worst_miss, mut worst_plane) = (0.0f64, 0.0f64);
    for case in 0..400 {
        let limb = limb(&mut rng);
        let skeleton = limb.clip.skeleton();
        let before = skeleton.rest().clone();
        let g = geometry(skeleton, &before, limb.joints);
        let (lo, hi) = ((g.l1 - g.l2).abs(), g.l1 + g.l2);
        let distance = lo + (hi - lo) * rng.range(0.0, 1.0);
        let target = target_at(&mut rng, g.a, distance);
        let t = d(target);
        // A pole well off the line to the target (a pole on it defines no plane).
        let pole = loop {
            let p = g.a + rng.vec3(2.0).as_dvec3();
            if angle(p - g.a, t - g.a).sin() > 0.1 {
                break p;
            }
        };
        let mut pose = before.clone();
        let c = TwoBone { pole: Some(Vec3A::from(pole.as_vec3())), ..TwoBone::new(limb.joints, target) };
        let report = solve(skeleton, &mut pose, &[IkConstraint::TwoBone(c)])[0];
        assert_only_rotated(&before, &pose, &limb.joints[..2]);
        let after = geometry(skeleton, &pose, limb.joints);
        let reach = 1e-5 * hi;
        let miss = (after.c - t).length();
        assert!(miss <= reach, "case {case}: the end misses by {miss:e} (l1 + l2 = {hi})");
        assert!(report.converged && (f64::from(report.residual) - miss).abs() <= reach, "case {case}: {report:?}");
        // In the plane through upper, target and pole, on the pole's side.
        let normal = (t - g.a).cross(pole - g.a).normalize();
        let off_plane = normal.dot(after.b - g.a).abs();
        assert!(off_plane <= reach, "case {case}: the middle is {off_plane:e} off the pole plane");
        (worst_miss, worst_plane) = (worst_miss.max(miss / hi), worst_plane.max(off_plane / hi));
        let axis = (t - g.a).normalize();
        let (middle, side) = (across(after.b - g.a, axis), across(pole - g.a, axis));
        if middle.length() > 1e-3 * g.l1 {
            assert!(middle.dot(side) > 0.0, "case {case}: the middle bends away from the pole");
        }
    }
    println!(
        "two_bone: worst miss {worst_miss:.1e}·(l1 + l2), worst distance off the pole plane {worst_plane:.1e}·(l1 + l2)"
    );
}

#[test]
fn two_bone_without_a_pole_keeps_the_middle_joints_side() {
    let mut rng = Rng::new(1702);
    for case in 0..200 {
        let limb = limb(&mut rng);
        let skeleton = limb.clip.skeleton();
        let mut pose = skeleton.rest().clone();
        let g = geometry(skeleton, &pose, limb.joints);
        let (lo, hi) = ((g.l1 - g.l2).abs(), g.l1 + g.l2);
        let distance = lo + (hi - lo) * rng.range(0.05, 0.95);
        let target = target_at(&mut rng, g.a, distance);
        let t = d(target);
        solve(skeleton, &mut pose, &[IkConstraint::TwoBone(TwoBone::new(limb.joints, target))]);
        let after = geometry(skeleton, &pose, limb.joints);
        assert!((after.c - t).length() <= 1e-5 * hi, "case {case}");
        let normal = (t - g.a).cross(g.b - g.a).normalize();
        assert!(normal.dot(after.b - g.a).abs() <= 1e-5 * hi, "case {case}: off the plane of the old middle");
        let axis = (t - g.a).normalize();
        assert!(across(after.b - g.a, axis).dot(across(g.b - g.a, axis)) > 0.0, "case {case}: flipped side");
    }
}

#[test]
fn two_bone_keeps_the_bend_plane_when_the_middle_is_on_the_line_to_the_target() {
    let mut rng = Rng::new(1703);
    for case in 0..100 {
        let limb = limb(&mut rng);
        let skeleton = limb.clip.skeleton();
        let mut pose = skeleton.rest().clone();
        let g = geometry(skeleton, &pose, limb.joints);
        let plane = (g.b - g.a).cross(g.c - g.b).normalize();
        // The target on the ray from the upper joint through the middle joint.
        let (lo, hi) = ((g.l1 - g.l2).abs(), g.l1 + g.l2);
        let distance = lo + (hi - lo) * rng.range(0.1, 0.9);
        let target = Vec3A::from((g.a + (g.b - g.a).normalize() * distance).as_vec3());
        solve(skeleton, &mut pose, &[IkConstraint::TwoBone(TwoBone::new(limb.joints, target))]);
        let after = geometry(skeleton, &pose, limb.joints);
        assert!((after.c - d(target)).length() <= 1e-5 * hi, "case {case}");
        for (name, p) in [("middle", after.b), ("end", after.c)] {
            let off = plane.dot(p - g.a).abs();
            assert!(off <= 1e-5 * hi, "case {case}: the {name} left the bend plane by {off:e}");
        }
    }
}

#[test]
fn two_bone_stretches_straight_toward_targets_out_of_reach() {
    let mut rng = Rng::new(1704);
    for case in 0..200 {
        let limb = limb(&mut rng);
        let skeleton = limb.clip.skeleton();
        let mut pose = skeleton.rest().clone();
        let g = geometry(skeleton, &pose, limb.joints);
        let hi = g.l1 + g.l2;
        let distance = hi * rng.range(1.01, 4.0);
        let target = target_at(&mut rng, g.a, distance);
        let t = d(target);
        let report = solve(skeleton, &mut pose, &[IkConstraint::TwoBone(TwoBone::new(limb.joints, target))])[0];
        let after = geometry(skeleton, &pose, limb.joints);
        let (upper, lower) = (angle(after.b - g.a, t - g.a), angle(after.c - after.b, t - g.a));
        assert!(upper <= 1e-4 && lower <= 1e-4, "case {case}: bones off the line by {upper:e}, {lower:e} rad");
        let nearest = (t - g.a).length() - hi;
        assert!(((after.c - t).length() - nearest).abs() <= 1e-5 * hi, "case {case}");
        assert!(!report.converged && (f64::from(report.residual) - nearest).abs() <= 1e-5 * hi, "{report:?}");
    }
}

#[test]
fn two_bone_folds_toward_targets_too_close_to_reach() {
    let mut rng = Rng::new(1705);
    let mut cases = 0;
    while cases < 100 {
        let limb = limb(&mut rng);
        let skeleton = limb.clip.skeleton();
        let mut pose = skeleton.rest().clone();
        let g = geometry(skeleton, &pose, limb.joints);
        let lo = (g.l1 - g.l2).abs();
        if lo < 0.2 * (g.l1 + g.l2) {
            continue;
        }
        cases += 1;
        let distance = lo * rng.range(0.05, 0.95);
        let target = target_at(&mut rng, g.a, distance);
        solve(skeleton, &mut pose, &[IkConstraint::TwoBone(TwoBone::new(limb.joints, target))]);
        let after = geometry(skeleton, &pose, limb.joints);
        let nearest = g.a + (d(target) - g.a).normalize() * lo;
        assert!((after.c - nearest).length() <= 1e-5 * (g.l1 + g.l2), "case {cases}");
    }
}

#[test]
fn two_bone_gives_finite_poses_on_degenerate_input() {
    let straight = |l1: f32, l2: f32| {
        body(&[
            J { parent: None, t: Vec3::ZERO, q: Quat::IDENTITY, s: 1.0 },
            J { parent: Some(0), t: Vec3::new(0.0, l1, 0.0), q: Quat::IDENTITY, s: 1.0 },
            J { parent: Some(1), t: Vec3::new(0.0, l2, 0.0), q: Quat::IDENTITY, s: 1.0 },
        ])
    };
    let y = |v: f32| Vec3A::new(0.0, v, 0.0);
    let cases = [
        // (l1, l2, target, pole): zero bones, the target on the upper joint, a straight chain
        // toward, along and away from its own line, poles on that line, far away and on the target.
        (0.0, 0.0, y(1.0), None),
        (0.0, 1.0, Vec3A::new(0.3, 0.2, 0.1), None),
        (1.0, 0.0, Vec3A::new(0.3, 0.2, 0.1), Some(Vec3A::X)),
        (1.0, 1.0, Vec3A::ZERO, None),
        (1.0, 1.0, Vec3A::ZERO, Some(Vec3A::Z)),
        (1.0, 0.5, y(1.2), None),
        (1.0, 0.5, y(1.2), Some(y(5.0))),
        (1.0, 1.0, y(-1.0), None),
        (1.0, 1.0, y(3.0), Some(Vec3A::X)),
        (1.0, 1.0, Vec3A::splat(1e30), Some(Vec3A::splat(-1e30))),
        (1.0, 1.0, Vec3A::new(0.5, 0.5, 0.0), Some(Vec3A::new(0.5, 0.5, 0.0))),
        (1e-30, 1e-30, Vec3A::X, None),
    ];
    for (i, &(l1, l2, target, pole)) in cases.iter().enumerate() {
        let clip = straight(l1, l2);
        let mut pose = clip.skeleton().rest().clone();
        let c = TwoBone { pole, ..TwoBone::new([0, 1, 2], target) };
        let report = solve(clip.skeleton(), &mut pose, &[IkConstraint::TwoBone(c)])[0];
        assert_finite_unit(&pose);
        assert!(report.residual.is_finite(), "case {i}: {report:?}");
        let model = model_f64(clip.skeleton(), &pose);
        assert!(model.iter().all(|m| m.t.is_finite()), "case {i}");
    }
}

#[test]
fn two_bone_weight_slerps_from_the_unsolved_rotations() {
    let mut rng = Rng::new(1706);
    for _ in 0..50 {
        let limb = limb(&mut rng);
        let skeleton = limb.clip.skeleton();
        let before = skeleton.rest().clone();
        let g = geometry(skeleton, &before, limb.joints);
        let target = target_at(&mut rng, g.a, 0.5 * (g.l1 + g.l2));
        let mut full = before.clone();
        solve(skeleton, &mut full, &[IkConstraint::TwoBone(TwoBone::new(limb.joints, target))]);
        let mut none = before.clone();
        let c = TwoBone { weight: 0.0, ..TwoBone::new(limb.joints, target) };
        solve(skeleton, &mut none, &[IkConstraint::TwoBone(c)]);
        assert_eq!(none, before);
        let w = rng.range(0.1, 0.9) as f32;
        let mut part = before.clone();
        let c = TwoBone { weight: w, ..TwoBone::new(limb.joints, target) };
        let report = solve(skeleton, &mut part, &[IkConstraint::TwoBone(c)])[0];
        for &j in &limb.joints[..2] {
            let expected = slerp_f64(before.rotations[j].as_dquat(), full.rotations[j].as_dquat(), f64::from(w));
            let gap = quat_angle(expected, part.rotations[j].as_dquat());
            assert!(gap <= 2e-6, "joint {j}: {gap:e} rad from the slerp");
        }
        let end = model_f64(skeleton, &part)[limb.joints[2]].t;
        assert!((f64::from(report.residual) - (end - d(target)).length()).abs() < 1e-5, "{report:?}");
    }
}

/// Short-way slerp in `f64`, from its definition.
fn slerp_f64(p: DQuat, q: DQuat, u: f64) -> DQuat {
    let q = if p.dot(q) < 0.0 { -q } else { q };
    let theta = p.dot(q).clamp(-1.0, 1.0).acos();
    if theta < 1e-12 {
        return p;
    }
    ((p * ((1.0 - u) * theta).sin() + q * (u * theta).sin()) * (1.0 / theta.sin())).normalize()
}

/// `root → j1 → … → j5` with random bones; one of them aims.
fn aim_case(rng: &mut Rng) -> (Clip, usize, Vec3A, Vec3A) {
    let mut js = vec![joint(rng, None)];
    for i in 1..6 {
        js.push(joint(rng, Some(i - 1)));
    }
    let clip = body(&js);
    let j = rng.below(6);
    let forward = Vec3A::from(rng.axis() * rng.range(0.2, 3.0) as f32);
    let target = Vec3A::from(rng.vec3(4.0));
    (clip, j, forward, target)
}

#[test]
fn aim_points_the_forward_axis_at_the_target_by_the_smallest_rotation() {
    let mut rng = Rng::new(1707);
    for case in 0..400 {
        let (clip, j, forward, mut target) = aim_case(&mut rng);
        let skeleton = clip.skeleton();
        let before = skeleton.rest().clone();
        let old = model_f64(skeleton, &before)[j];
        let f = d(forward).normalize();
        if case % 4 == 0 {
            // Straight behind the joint: the arc's hardest case.
            let behind = old.t - (old.q * f) * rng.range(0.5, 3.0);
            target = Vec3A::from(behind.as_vec3());
        }
        let mut pose = before.clone();
        let c = Aim { forward, ..Aim::new(j, target) };
        let report = solve(skeleton, &mut pose, &[IkConstraint::Aim(c)])[0];
        assert_only_rotated(&before, &pose, &[j]);
        let new = model_f64(skeleton, &pose)[j];
        let to = d(target) - old.t;
        let error = angle(new.q * f, to);
        assert!(error <= 1e-5, "case {case}: forward misses by {error:e} rad");
        assert!(report.converged && (f64::from(report.residual) - error).abs() <= 1e-6, "{report:?}");
        // The model-space turn is exactly the angle between the old forward and the target.
        let turn = 2.0 * (new.q * old.q.conjugate()).w.abs().min(1.0).acos();
        let needed = angle(old.q * f, to);
        assert!((turn - needed).abs() <= 2e-5, "case {case}: turned {turn} for an arc of {needed}");
    }
}

#[test]
fn aim_with_an_up_axis_rolls_it_toward_up_direction() {
    let mut rng = Rng::new(1708);
    let mut cases = 0;
    while cases < 300 {
        let (clip, j, forward, target) = aim_case(&mut rng);
        let skeleton = clip.skeleton();
        let mut pose = skeleton.rest().clone();
        let (up, direction) = (Vec3A::from(rng.axis()), Vec3A::from(rng.vec3(2.0)));
        let joint_at = model_f64(skeleton, &pose)[j].t;
        let to = (d(target) - joint_at).normalize();
        // Skip rolls no plane defines: `up` along forward, `up_direction` along the aim.
        if angle(d(up), d(forward)).sin() < 0.1 || angle(d(direction), to).sin() < 0.1 {
            continue;
        }
        cases += 1;
        let c = Aim { forward, up: Some(up), up_direction: Some(direction), ..Aim::new(j, target) };
        solve(skeleton, &mut pose, &[IkConstraint::Aim(c)]);
        let new = model_f64(skeleton, &pose)[j];
        assert!(angle(new.q * d(forward), to) <= 1e-5, "case {cases}: lost the aim");
        let roll = angle(across(new.q * d(up), to), across(d(direction), to));
        assert!(roll <= 1e-5, "case {cases}: up is {roll:e} rad off up_direction's half-plane");
    }
}

#[test]
fn aim_at_the_joint_itself_leaves_the_pose() {
    let mut rng = Rng::new(1709);
    let (clip, j, forward, _) = aim_case(&mut rng);
    let mut pose = clip.skeleton().rest().clone();
    let at = Vec3A::from(model_f64(clip.skeleton(), &pose)[j].t.as_vec3());
    let report = solve(clip.skeleton(), &mut pose, &[IkConstraint::Aim(Aim { forward, ..Aim::new(j, at) })])[0];
    assert_finite_unit(&pose);
    assert!(report.residual.is_finite());
}

#[test]
fn constraints_apply_in_order() {
    // A leg then an aim of its end joint: the aim sees the solved leg.
    let mut rng = Rng::new(1710);
    let limb = limb(&mut rng);
    let skeleton = limb.clip.skeleton();
    let mut pose = skeleton.rest().clone();
    let g = geometry(skeleton, &pose, limb.joints);
    let target = target_at(&mut rng, g.a, 0.7 * (g.l1 + g.l2));
    let look = Vec3A::new(5.0, 1.0, -2.0);
    let constraints =
        [IkConstraint::TwoBone(TwoBone::new(limb.joints, target)), IkConstraint::Aim(Aim::new(limb.joints[2], look))];
    let reports = solve(skeleton, &mut pose, &constraints);
    assert!(reports.iter().all(|r| r.converged), "{reports:?}");
    let end = model_f64(skeleton, &pose)[limb.joints[2]];
    assert!((end.t - d(target)).length() <= 1e-5 * (g.l1 + g.l2));
    assert!(angle(end.q * DVec3::Z, d(look) - end.t) <= 1e-5);
}

/// `j0 → j1 → j2 → j3`, and `j4` under `j0`.
fn small_body() -> Clip {
    let j = |parent, y| J { parent, t: Vec3::new(0.0, y, 0.0), q: Quat::IDENTITY, s: 1.0 };
    body(&[j(None, 0.0), j(Some(0), 1.0), j(Some(1), 1.0), j(Some(2), 1.0), j(Some(0), 1.0)])
}

fn check_refusal(c: IkConstraint, code: &str, pointer: &str) {
    let clip = small_body();
    let err = c.validate(clip.skeleton(), &IkLimits::default()).expect_err(code);
    assert_eq!((err.kind.code(), err.path.to_pointer().as_str()), (code, pointer), "{err}");
}

#[test]
fn refusals_name_the_rule_and_the_place() {
    let two = |joints| IkConstraint::TwoBone(TwoBone::new(joints, Vec3A::X));
    check_refusal(two([0, 1, 9]), "unknown_joint", "/joints/2");
    check_refusal(two([0, 4, 3]), "not_descendant", "/joints/2");
    check_refusal(two([1, 1, 3]), "not_descendant", "/joints/1");
    check_refusal(two([2, 1, 3]), "not_descendant", "/joints/1");
    let nan = Vec3A::new(0.0, f32::NAN, 0.0);
    check_refusal(IkConstraint::TwoBone(TwoBone::new([0, 1, 3], nan)), "non_finite", "/target/1");
    let pole = TwoBone { pole: Some(Vec3A::splat(f32::INFINITY)), ..TwoBone::new([0, 1, 3], Vec3A::X) };
    check_refusal(IkConstraint::TwoBone(pole), "non_finite", "/pole/0");
    let heavy = TwoBone { weight: 1.5, ..TwoBone::new([0, 1, 3], Vec3A::X) };
    check_refusal(IkConstraint::TwoBone(heavy), "weight_out_of_range", "/weight");
    let aim = |c: Aim| IkConstraint::Aim(c);
    check_refusal(aim(Aim { forward: Vec3A::ZERO, ..Aim::new(2, Vec3A::X) }), "zero_axis", "/forward");
    check_refusal(aim(Aim { up: Some(Vec3A::ZERO), ..Aim::new(2, Vec3A::X) }), "zero_axis", "/up");
    check_refusal(aim(Aim { weight: f32::NAN, ..Aim::new(2, Vec3A::X) }), "weight_out_of_range", "/weight");
    check_refusal(aim(Aim::new(5, Vec3A::X)), "unknown_joint", "/joint");
    let effector = |joint| Effector { joint, target: Vec3A::X, tip: Vec3A::ZERO };
    let chain = |f: &dyn Fn(&mut Chain)| {
        let mut c = Chain::new(vec![effector(3), effector(4)]);
        f(&mut c);
        IkConstraint::Chain(c)
    };
    check_refusal(chain(&|c| c.effectors.clear()), "no_effectors", "/effectors");
    check_refusal(chain(&|c| c.effectors[1].joint = 7), "unknown_joint", "/effectors/1/joint");
    check_refusal(chain(&|c| c.effectors[0].tip.z = f32::NAN), "non_finite", "/effectors/0/tip/2");
    check_refusal(chain(&|c| c.joints = Some(vec![1, 2, 1])), "duplicate_joint", "/joints/2");
    let limits = |min, max| JointLimits { joint: 2, min, max };
    check_refusal(
        chain(&|c| c.limits = vec![limits([0.0, 1.0, 0.0], [1.0, 0.5, 1.0])]),
        "limits_out_of_order",
        "/limits/j2/min/1",
    );
    check_refusal(chain(&|c| c.limits = vec![limits([f32::NAN; 3], [1.0; 3])]), "non_finite", "/limits/j2/min/0");
    check_refusal(
        chain(&|c| c.limits = vec![limits([0.0; 3], [f32::NEG_INFINITY; 3])]),
        "non_finite",
        "/limits/j2/max/0",
    );
    check_refusal(chain(&|c| c.limits = vec![limits([0.0; 3], [1.0; 3]); 2]), "duplicate_joint", "/limits/j2");
    check_refusal(chain(&|c| c.max_iterations = 1001), "too_many_iterations", "/max_iterations");
    check_refusal(chain(&|c| c.tolerance = Some(-1.0)), "bad_tolerance", "/tolerance");
    check_refusal(chain(&|c| c.effectors = vec![effector(3); 17]), "too_many_effectors", "/effectors");
    // Unbounded limits are limits too.
    let open = chain(&|c| c.limits = vec![limits([f32::NEG_INFINITY; 3], [f32::INFINITY; 3])]);
    assert_eq!(open.validate(small_body().skeleton(), &IkLimits::default()), Ok(()));
}

#[test]
fn a_list_is_checked_for_length_and_each_refusal_carries_its_index() {
    let clip = small_body();
    let ok = IkConstraint::Aim(Aim::new(2, Vec3A::X));
    let bad = IkConstraint::TwoBone(TwoBone::new([0, 4, 3], Vec3A::X));
    let limits = IkLimits { max_constraints: 3, ..IkLimits::default() };
    let err = validate_constraints(&[ok.clone(), ok.clone(), bad], clip.skeleton(), &limits).unwrap_err();
    assert_eq!((err.kind.code(), err.path.to_pointer()), ("not_descendant", "/2/joints/2".to_owned()));
    let err = validate_constraints(&vec![ok.clone(); 4], clip.skeleton(), &limits).unwrap_err();
    assert_eq!(err.kind, IkErrorKind::TooManyConstraints { max: 3, provided: 4 });
    assert_eq!(validate_constraints(&[ok], clip.skeleton(), &limits), Ok(()));
}

#[test]
fn solving_allocates_nothing_once_warm() {
    let mut rng = Rng::new(1711);
    let limb = limb(&mut rng);
    let skeleton = limb.clip.skeleton();
    let rest = skeleton.rest().clone();
    let g = geometry(skeleton, &rest, limb.joints);
    let target = target_at(&mut rng, g.a, 0.8 * (g.l1 + g.l2));
    let [upper, _, end] = limb.joints;
    let effector = Effector { joint: end, target, tip: Vec3A::new(0.1, 0.0, 0.0) };
    let limited = JointLimits { joint: upper, min: [-1.0; 3], max: [1.0; 3] };
    let constraints = [
        IkConstraint::TwoBone(TwoBone { pole: Some(Vec3A::X), weight: 0.7, ..TwoBone::new(limb.joints, target) }),
        IkConstraint::Aim(Aim { up: Some(Vec3A::Y), up_direction: Some(Vec3A::Z), ..Aim::new(end, Vec3A::ONE) }),
        IkConstraint::Chain(Chain { limits: vec![limited], weight: 0.5, ..Chain::new(vec![effector]) }),
    ];
    let (mut solver, mut reports, mut pose) = (IkSolver::new(), Vec::new(), rest.clone());
    solver.solve(skeleton, &mut pose, &constraints, ChainStart::Cold, &mut reports);
    for start in [ChainStart::Cold, ChainStart::Warm, ChainStart::Cold] {
        pose.copy_from(&rest);
        let before = allocations();
        solver.solve(skeleton, &mut pose, &constraints, start, &mut reports);
        assert_eq!(allocations() - before, 0, "{start:?}");
    }
    assert_eq!(reports.len(), 3);
}
