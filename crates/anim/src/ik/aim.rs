//! Aim (docs/ik.md, “Constraints”, `aim`): turn one joint so its local `forward` axis, in
//! model space, points at the target.
//!
//! The turn is the smallest rotation (the arc from the current forward
//! direction to the target's), unless both `up` and `up_direction` are
//! given: then a roll about the aim direction follows, putting the
//! joint's `up` axis in the plane of the aim direction and `up_direction`,
//! on `up_direction`'s side. Axes are directions of the joint's model
//! rotation (its scale does not bend them). A target on the joint itself
//! defines no direction and leaves the pose alone.

use glam::Vec3A;

use super::constraint::{Aim, IkKind};
use super::model::{ancestry, angle_between, arc, arc_unnormalized, blend, model, roll, rotate, unit};
use super::report::IkReport;
use crate::{Pose, Skeleton};

/// The aim's guarantee (docs/ik.md, “Reports”), in radians.
pub const AIM_TOLERANCE: f32 = 1e-5;

/// Works in the frame of the joint's parent (vectors rotated by its model
/// rotation's inverse): a turn found there is the joint's local turn, so
/// the joint's own model rotation is never formed and the solved local
/// rotation is one product away.
pub(super) fn solve(c: &Aim, skeleton: &Skeleton, local: &mut Pose, path: &mut Vec<usize>) -> IkReport {
    ancestry(skeleton, c.joint, path);
    let parent = model(local, &path[1..]);
    // From the joint to the target: `P⁻¹·(target − p_t) − p_s·t` with the
    // parent's model `(p_t, P, p_s)` and the joint's local translation `t`.
    let inv = parent.q.conjugate();
    let to = rotate(inv, c.target - parent.t) - parent.s * local.translations[c.joint];
    if to == Vec3A::ZERO {
        return IkReport { kind: IkKind::Aim, residual: 0.0, iterations: 0, converged: true };
    }
    let before = local.rotations[c.joint];
    let from = rotate(before, c.forward);
    let (turned, exact) = match (c.up, c.up_direction) {
        (Some(up), Some(direction)) => {
            let swing = arc(from, to);
            let turn = unit(to)
                .map_or(swing, |axis| roll(axis, rotate(swing, rotate(before, up)), rotate(inv, direction)) * swing);
            ((turn * before).normalize(), false)
        }
        // The smallest rotation alone, normalised once: `|from| = |forward|`
        // (`before` is unit to rounding, and an error of that size turns the
        // arc by a few 1e-7 rad at most), and `|swing·before| =
        // |swing|·|before|`, so neither square root waits for the product.
        _ => match arc_unnormalized(from, c.forward.length_squared(), to) {
            Some(swing) => {
                let scale = (swing.length_squared() * before.length_squared()).sqrt().recip();
                (swing * before * scale, true)
            }
            None => ((arc(from, to) * before).normalize(), false),
        },
    };
    let solved = blend(before, turned, c.weight);
    local.rotations[c.joint] = solved;
    // At full weight the smallest rotation's `f32` arc lands `forward` on
    // `to` exactly but for rounding (a few 1e-7 rad), so its residual is 0
    // without re-measuring; a roll, a partial weight or the `f64` arc is
    // measured on the rotation written.
    let residual = if exact && c.weight >= 1.0 { 0.0 } else { angle_between(rotate(solved, c.forward), to) };
    IkReport { kind: IkKind::Aim, residual, iterations: 0, converged: residual <= AIM_TOLERANCE }
}
