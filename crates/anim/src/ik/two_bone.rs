//! Analytic two-bone IK (docs/ik.md, “Constraints”, `two_bone`; ozz's IKTwoBoneJob).
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
//!    current bend plane when it is collinear with `a` and `t`); none when
//!    the target is out of reach, where the solved limb lies on that axis.
//!
//! Each step is a model-space rotation; the solver finds it directly in the
//! frame of the turned joint's parent (the upper joint's parent for the
//! swing and roll, the middle joint's for the bend), where it is the
//! joint's local turn, so twist joints between the three ride along
//! rigidly and no model rotation of the limb is ever formed: the limb is
//! measured once, from the upper joint's parent down, in the upper and
//! middle joints' own frames. Lengths and the bend are computed without
//! trigonometry (see [`bend`]), in `f32` except at extreme scales; every
//! degenerate case (zero bones, a target on the upper joint, a straight
//! chain) falls back to the identity for the step it defeats, never to NaN.

use glam::{Mat3A, Quat, Vec3A};

use super::constraint::{IkKind, TwoBone};
use super::model::{Xform, ancestry, arc, blend, extend, model, roll, rotate, unit};
use super::report::IkReport;
use crate::{Pose, Skeleton};

/// docs/ik.md, “Reports”: a reachable target is met within this fraction of `l1 + l2`.
pub const TWO_BONE_TOLERANCE: f32 = 1e-5;

/// The limb before the solve, measured from its upper joint's parent.
struct Limb {
    /// The upper joint's parent's model rotation (identity for a root).
    parent: Quat,
    /// The upper joint's parent's model position.
    origin: Vec3A,
    /// The upper joint's position relative to `origin`, in the parent's
    /// frame.
    a: Vec3A,
    /// The middle joint's position relative to `a`, in the upper joint's
    /// frame (its model rotation undone).
    b: Vec3A,
    /// The middle joint's parent's rotation relative to the upper joint's
    /// (the twist joints between them; identity if none).
    twist: Quat,
    /// The end's position relative to the middle joint, in the middle
    /// joint's frame.
    e: Vec3A,
}

impl Limb {
    /// `path` runs leaf first from the end joint (at 0) to a root;
    /// `0 < im < iu` index the middle and upper joints in it.
    fn measure(local: &Pose, path: &[usize], im: usize, iu: usize) -> Limb {
        let above = model(local, &path[iu + 1..]);
        let upper = path[iu];
        let a = above.s * local.translations[upper];
        let frame = |s: Vec3A| Xform { t: Vec3A::ZERO, q: Quat::IDENTITY, s };
        let to_middle = extend(frame(above.s * local.scales[upper]), local, &path[im + 1..iu]);
        let middle = path[im];
        let b = to_middle.point(local.translations[middle]);
        let to_end = extend(frame(to_middle.s * local.scales[middle]), local, &path[1..im]);
        let e = to_end.point(local.translations[path[0]]);
        Limb { parent: above.q, origin: above.t, a, b, twist: to_middle.q, e }
    }
}

pub(super) fn solve(c: &TwoBone, skeleton: &Skeleton, local: &mut Pose, path: &mut Vec<usize>) -> IkReport {
    let [upper, middle, end] = c.joints;
    ancestry(skeleton, end, path);
    let at = |joint| path.iter().position(|&j| j == joint);
    let (Some(im), Some(iu)) = (at(middle), at(upper)) else { return unsolved(local, path, c.target) };
    if !(0 < im && im < iu) {
        return unsolved(local, path, c.target);
    }
    let Limb { parent, origin, a, b, twist, e } = Limb::measure(local, path, im, iu);
    let (upper_q, middle_q) = (local.rotations[upper], local.rotations[middle]);
    let (l1, l2) = (length(b), length(e));
    // Model points relative to the upper joint, in its parent's frame.
    let inv = parent.conjugate();
    let relative = |p: Vec3A| rotate(inv, p - origin) - a;
    let t = relative(c.target);
    let reach = length(t);

    // The bend, in the middle joint's parent's frame.
    let lower = rotate(middle_q, e);
    let bend = bend(rotate(twist.conjugate(), -b), lower, reach, (l1, l2), middle_q);
    let end_bent = rotate(upper_q, b + rotate(twist, rotate(bend, lower)));
    // Swing and roll, in the upper joint's parent's frame (positions from `a`).
    let aim = if reach > 1e-30 && reach < 1e30 { Some(t * reach.recip()) } else { unit(t) };
    let swing = match (end_bent != Vec3A::ZERO, aim) {
        (true, Some(to)) => arc(end_bent, to),
        _ => Quat::IDENTITY,
    };
    let b_before = rotate(upper_q, b);
    // Stretched straight toward the target, the middle joint lies on the
    // roll's axis, where no roll is defined (only rounding would pick one).
    let straight = l1 > 1e-30 && l2 > 1e-30 && reach >= l1 + l2;
    let turn = match aim {
        Some(_) if straight => swing,
        Some(axis) => {
            let toward = c.pole.map_or(b_before, relative);
            roll(axis, rotate(swing, b_before), toward) * swing
        }
        None => swing,
    };

    let middle_solved = blend(middle_q, (bend * middle_q).normalize(), c.weight);
    let upper_solved = blend(upper_q, (turn * upper_q).normalize(), c.weight);
    local.rotations[middle] = middle_solved;
    local.rotations[upper] = upper_solved;
    let end_after = if c.weight == 1.0 {
        rotate(turn, end_bent)
    } else {
        rotate(upper_solved, b + rotate(twist, rotate(middle_solved, e)))
    };
    let residual = length(end_after - t);
    let converged = residual <= TWO_BONE_TOLERANCE * (l1 + l2);
    IkReport { kind: IkKind::TwoBone, residual: residual.min(f32::MAX), iterations: 0, converged }
}

#[cold]
fn unsolved(local: &Pose, path: &[usize], target: Vec3A) -> IkReport {
    let residual = length(model(local, path).t - target).min(f32::MAX);
    IkReport { kind: IkKind::TwoBone, residual, iterations: 0, converged: false }
}

/// `|v|`, in `f64` when `f32` squares would overflow or underflow.
#[inline]
fn length(v: Vec3A) -> f32 {
    let squared = v.length_squared();
    if squared > 1e-30 && squared < 1e30 { squared.sqrt() } else { length_f64(v) }
}

#[cold]
fn length_f64(v: Vec3A) -> f32 {
    v.as_dvec3().length() as f32
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
fn bend(u: Vec3A, v: Vec3A, reach: f32, (l1, l2): (f32, f32), middle_q: Quat) -> Quat {
    if !(l1 > 1e-30 && l2 > 1e-30) {
        return Quat::IDENTITY;
    }
    let (u, v) = (u * l1.recip(), v * l2.recip());
    let (goal_cos, goal_sin) = goal(reach, l1, l2);
    let (now_cos, now_sin) = ((u + v).length() * 0.5, (u - v).length() * 0.5);
    let cos = goal_cos * now_cos + goal_sin * now_sin;
    let sin = goal_sin * now_cos - goal_cos * now_sin;
    // Unit by construction (cos² + sin² = 1 on both halves), up to rounding.
    let axis = bend_axis(u, v, 2.0 * now_sin * now_cos, middle_q) * sin;
    Quat::from_xyzw(axis.x, axis.y, axis.z, cos)
}

/// `(cos(θ'/2), sin(θ'/2))` of the interior angle `θ'` that puts the end at
/// the reachable distance nearest `reach`. In `f32` (its relative rounding,
/// about 1e-7 of `l1 + l2` in the end's position, is far inside the
/// tolerance) unless the lengths are extreme enough for its squares to
/// overflow or underflow.
#[inline]
fn goal(reach: f32, l1: f32, l2: f32) -> (f32, f32) {
    let (long, short) = (l1 + l2, (l1 - l2).abs());
    if !(l1 > 1e-12 && l2 > 1e-12 && long < 1e12) {
        return goal_f64(f64::from(reach), f64::from(l1), f64::from(l2));
    }
    let d = reach.clamp(short, long);
    let quarter = (4.0 * l1 * l2).recip();
    let cos = ((long - d) * (long + d) * quarter).max(0.0).sqrt();
    let sin = ((d - short) * (d + short) * quarter).max(0.0).sqrt();
    (cos, sin)
}

#[cold]
fn goal_f64(reach: f64, l1: f64, l2: f64) -> (f32, f32) {
    let (long, short) = (l1 + l2, (l1 - l2).abs());
    let d = reach.clamp(short, long);
    let quarter = 4.0 * l1 * l2;
    let cos = ((long - d) * (long + d) / quarter).max(0.0).sqrt();
    let sin = ((d - short) * (d + short) / quarter).max(0.0).sqrt();
    (cos as f32, sin as f32)
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
    let axes = Mat3A::from_quat(middle_q);
    let candidates = [axes.x_axis, axes.y_axis, axes.z_axis];
    let least = candidates.into_iter().min_by(|p, q| p.dot(v).abs().total_cmp(&q.dot(v).abs()));
    least.and_then(|w| unit(v.cross(w))).unwrap_or_else(|| v.any_orthonormal_vector())
}
