//! Analytic two-bone IK (SPEC §7 `two_bone`; ozz's IKTwoBoneJob).
//!
//! With `a`, `b`, `c` the model positions of upper, middle and end,
//! `l1 = |b − a|`, `l2 = |c − b|` and `d = clamp(|t − a|, |l1 − l2|, l1 + l2)`
//! the reachable distance nearest the target's:
//! 1. *bend*: turn the middle joint about the bend plane's normal until the
//!    interior angle at `b` is `acos((l1² + l2² − d²) / (2·l1·l2))`, so the
//!    end sits at distance `d` from `a`;
//! 2. *swing*: turn the upper joint by the arc taking `c − a` to `t − a`;
//! 3. *roll*: turn the upper joint about `t − a` so the middle joint lies in
//!    the plane through `a`, `t` and the pole, on the pole's side (no pole:
//!    the middle joint's own position before the solve, which keeps the
//!    current bend plane when it is collinear with `a` and `t`).
//!
//! Each step is a model-space rotation written back into the local pose by
//! [`to_local`], so twist joints between the three ride along rigidly.
//! Lengths and the bend are computed in `f64` without trigonometry (see
//! [`bend`]); every degenerate case (zero bones, a target on the upper
//! joint, a straight chain) falls back to the identity for the step it
//! defeats, never to NaN.

use glam::{Quat, Vec3A};

use super::model::{Xform, arc, roll, to_local, unit, walk};
use super::{IkKind, IkReport, TwoBone, blend};
use crate::anim::{Pose, Skeleton};

/// SPEC §7: a reachable target is met within this fraction of `l1 + l2`.
pub const TWO_BONE_TOLERANCE: f32 = 1e-5;

pub(super) fn solve(
    c: &TwoBone,
    skeleton: &Skeleton,
    local: &mut Pose,
    path: &mut Vec<usize>,
    model: &mut Vec<Xform>,
) -> IkReport {
    let [upper, middle, end] = c.joints;
    walk(skeleton, local, end, path, model);
    let at = |joint| path.iter().position(|&j| j == joint);
    let last = path.len() - 1;
    let (Some(iu), Some(im)) = (at(upper), at(middle)) else { return unsolved(model[last].t, c.target) };
    if !(iu < im && im < last) {
        return unsolved(model[last].t, c.target);
    }
    let (a, b, end_before) = (model[iu].t, model[im].t, model[last].t);
    let upper_parent = if iu == 0 { Quat::IDENTITY } else { model[iu - 1].q };
    let (upper_q, middle_parent, middle_q) = (model[iu].q, model[im - 1].q, model[im].q);
    let t = c.target;
    let (l1, l2) = (distance(a, b), distance(b, end_before));
    let reach = distance(a, t);

    let bend = bend(a, b, end_before, reach, (l1, l2), middle_q);
    let end_bent = b + bend * (end_before - b);
    let aim = if reach > 1e-30 && reach < 1e30 { Some((t - a) * (1.0 / reach) as f32) } else { unit(t - a) };
    let swing = match (end_bent - a != Vec3A::ZERO, aim) {
        (true, Some(to)) => arc(end_bent - a, to),
        _ => Quat::IDENTITY,
    };
    let turn = match aim {
        Some(axis) => roll(axis, swing * (b - a), c.pole.unwrap_or(b) - a) * swing,
        None => swing,
    };

    let (middle_before, upper_before) = (local.rotations[middle], local.rotations[upper]);
    local.rotations[middle] = blend(middle_before, to_local(middle_parent, bend, middle_q), c.weight);
    local.rotations[upper] = blend(upper_before, to_local(upper_parent, turn, upper_q), c.weight);
    let end_after = if c.weight == 1.0 {
        a + turn * (end_bent - a)
    } else {
        walk(skeleton, local, end, path, model);
        model[last].t
    };
    let residual = distance(end_after, t);
    let converged = residual <= f64::from(TWO_BONE_TOLERANCE) * (l1 + l2);
    IkReport { kind: IkKind::TwoBone, residual: residual.min(f64::from(f32::MAX)) as f32, iterations: 0, converged }
}

fn unsolved(end: Vec3A, target: Vec3A) -> IkReport {
    let residual = distance(end, target).min(f64::from(f32::MAX)) as f32;
    IkReport { kind: IkKind::TwoBone, residual, iterations: 0, converged: false }
}

fn distance(p: Vec3A, q: Vec3A) -> f64 {
    (p.as_dvec3() - q.as_dvec3()).length()
}

/// The model-space rotation of the middle joint (about `b`) that opens the
/// interior angle from its current `θ` to the `θ'` that puts the end at
/// the reachable distance `d` from `a` nearest the target's `reach`.
///
/// No trigonometry: with unit bones `u`, `v` from `b`, `cos(θ/2) = |u + v|/2`
/// and `sin(θ/2) = |u − v|/2`; the law of cosines gives
/// `cos²(θ'/2) = ((l1 + l2)² − d²)/(4·l1·l2)` and
/// `sin²(θ'/2) = (d² − (l1 − l2)²)/(4·l1·l2)`, factored so a straight
/// chain (`d = l1 + l2`) is exact; the turn by `θ' − θ` is their difference.
fn bend(a: Vec3A, b: Vec3A, c: Vec3A, reach: f64, (l1, l2): (f64, f64), middle_q: Quat) -> Quat {
    if !(l1 > 1e-30 && l2 > 1e-30) {
        return Quat::IDENTITY;
    }
    let (u, v) = ((a - b) * (1.0 / l1) as f32, (c - b) * (1.0 / l2) as f32);
    let (long, short) = (l1 + l2, (l1 - l2).abs());
    let d = reach.clamp(short, long);
    let quarter = 4.0 * l1 * l2;
    let goal_cos = ((long - d) * (long + d) / quarter).max(0.0).sqrt();
    let goal_sin = ((d - short) * (d + short) / quarter).max(0.0).sqrt();
    let (now_cos, now_sin) = ((u + v).length() * 0.5, (u - v).length() * 0.5);
    let cos = goal_cos as f32 * now_cos + goal_sin as f32 * now_sin;
    let sin = goal_sin as f32 * now_cos - goal_cos as f32 * now_sin;
    // Unit by construction (cos² + sin² = 1 on both halves), up to rounding.
    let axis = bend_axis(u, v, 2.0 * now_sin * now_cos, middle_q) * sin;
    Quat::from_xyzw(axis.x, axis.y, axis.z, cos)
}

/// The normal of the plane the chain bends in, oriented so a positive turn
/// of `v` opens the angle from `u` (both unit, `sin θ` apart). A straight
/// or folded chain has no plane: then the middle joint's own axis most
/// perpendicular to the lower bone gives one (the roll step moves it
/// where the pole says).
fn bend_axis(u: Vec3A, v: Vec3A, sin: f32, middle_q: Quat) -> Vec3A {
    if sin > 1e-6 {
        return u.cross(v) * sin.recip();
    }
    let candidates = [middle_q * Vec3A::X, middle_q * Vec3A::Y, middle_q * Vec3A::Z];
    let least = candidates.into_iter().min_by(|p, q| p.dot(v).abs().total_cmp(&q.dot(v).abs()));
    least.and_then(|w| unit(v.cross(w))).unwrap_or_else(|| v.any_orthonormal_vector())
}
