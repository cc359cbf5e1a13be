//! Aim (SPEC §7 `aim`): turn one joint so its local `forward` axis, in
//! model space, points at the target.
//!
//! The turn is the smallest rotation (the arc from the current forward
//! direction to the target's), unless both `up` and `up_direction` are
//! given: then a roll about the aim direction follows, putting the
//! joint's `up` axis in the plane of the aim direction and `up_direction`,
//! on `up_direction`'s side. Axes are directions of the joint's model
//! rotation (its scale does not bend them). A target on the joint itself
//! defines no direction and leaves the pose alone.

use glam::{Quat, Vec3A};

use super::model::{Xform, angle_between, arc, roll, to_local, unit, walk};
use super::{Aim, IkKind, IkReport, blend};
use crate::anim::{Pose, Skeleton};

/// The aim's guarantee (SPEC §7), in radians.
pub const AIM_TOLERANCE: f32 = 1e-5;

pub(super) fn solve(
    c: &Aim,
    skeleton: &Skeleton,
    local: &mut Pose,
    path: &mut Vec<usize>,
    model: &mut Vec<Xform>,
) -> IkReport {
    walk(skeleton, local, c.joint, path, model);
    let last = model.len() - 1;
    let joint = model[last];
    let parent = if last == 0 { Quat::IDENTITY } else { model[last - 1].q };
    let to = c.target - joint.t;
    if to == Vec3A::ZERO {
        return IkReport { kind: IkKind::Aim, residual: 0.0, iterations: 0, converged: true };
    }
    let swing = arc(joint.q * c.forward, to);
    let turn = match (c.up, c.up_direction) {
        (Some(up), Some(direction)) => {
            unit(to).map_or(swing, |axis| roll(axis, swing * (joint.q * up), direction) * swing)
        }
        _ => swing,
    };
    let solved = blend(local.rotations[c.joint], to_local(parent, turn, joint.q), c.weight);
    local.rotations[c.joint] = solved;
    let residual = angle_between(parent * solved * c.forward, to);
    IkReport { kind: IkKind::Aim, residual, iterations: 0, converged: residual <= AIM_TOLERANCE }
}
