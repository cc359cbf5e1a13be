//! Layering one joint (docs/motion.md, “How a pose is computed”), bottom to top in local space.
//!
//! A `blend` layer moves the pose toward its own by `w`; an `additive`
//! layer adds `w` times its difference from its reference pose. Weight 0
//! leaves the joint alone and a blend at weight 1 copies the layer exactly,
//! so one full-weight layer gives the clip's pose bit for bit. Results
//! stay finite: additive scale ratios against a zero reference scale count
//! as no change, and every value is clamped to the core's model-space
//! magnitude bound.

use glam::{Quat, Vec3A};

use crate::quat::slerp_fast;

/// The largest coordinate a layered translation or scale may reach (the
/// bound `Clip::build` enforces on every clip's own values).
const BOUND: f32 = 1e36;

/// One joint's local transform.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Joint {
    pub t: Vec3A,
    pub q: Quat,
    pub s: Vec3A,
}

/// Moves `pose` toward `layer` by `w` (`t`, `s` lerp; `q` short-way slerp).
#[inline]
pub(super) fn blend(pose: &mut Joint, layer: &Joint, w: f32) {
    if w >= 1.0 {
        *pose = *layer;
    } else if w > 0.0 {
        pose.t = toward(pose.t, layer.t, w);
        pose.s = toward(pose.s, layer.s, w);
        // The same rotation (either sign) stays exactly as it is.
        if pose.q != layer.q && pose.q != -layer.q {
            pose.q = slerp_fast(pose.q, layer.q, w);
        }
    }
}

/// `a + (b − a)·w`: equal values blend to themselves exactly, so a channel
/// every layer holds constant stays constant (compact frames send it once:
/// docs/compact-frames.md).
#[inline]
fn toward(a: Vec3A, b: Vec3A, w: f32) -> Vec3A {
    a + (b - a) * w
}

/// Adds `w` times `layer`'s difference from `reference`.
#[inline]
pub(super) fn add(pose: &mut Joint, layer: &Joint, reference: &Joint, w: f32) {
    if w <= 0.0 {
        return;
    }
    pose.t = clamp(pose.t + (layer.t - reference.t) * w);
    // A rotation the layer holds at its reference's adds nothing, exactly.
    if layer.q != reference.q && layer.q != -reference.q {
        pose.q = (pose.q * additive_step(layer.q, reference.q, w)).normalize();
    }
    let ratio = Vec3A::select(reference.s.cmpeq(Vec3A::ZERO), Vec3A::ONE, layer.s / reference.s);
    pose.s = clamp(pose.s * (Vec3A::ONE + (ratio - Vec3A::ONE) * w));
}

/// `slerp(I, short(reference⁻¹·layer), w)`: what an additive layer turns by.
fn additive_step(layer: Quat, reference: Quat, w: f32) -> Quat {
    let difference = reference.conjugate() * layer;
    let difference = if difference.w < 0.0 { -difference } else { difference };
    if w >= 1.0 { difference } else { slerp_fast(Quat::IDENTITY, difference, w) }
}

/// A parameter entry's blend: the translation's lerp (a copy at `w ≥ 1`).
#[inline]
pub(super) fn lerp(value: Vec3A, layer: Vec3A, w: f32) -> Vec3A {
    if w >= 1.0 { layer } else { toward(value, layer, w) }
}

/// A parameter entry's additive step: `value + w·difference`, bounded as
/// translations are.
#[inline]
pub(super) fn offset(value: Vec3A, difference: Vec3A, w: f32) -> Vec3A {
    clamp(value + difference * w)
}

fn clamp(v: Vec3A) -> Vec3A {
    // NaN only from inf − inf, which bounded inputs cannot produce.
    v.clamp(Vec3A::splat(-BOUND), Vec3A::splat(BOUND))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn joint(t: [f32; 3], q: Quat, s: [f32; 3]) -> Joint {
        Joint { t: t.into(), q, s: s.into() }
    }

    #[test]
    fn full_weight_blends_copy_and_zero_weight_keeps() {
        let base = joint([0.1, 0.2, 0.3], Quat::from_rotation_y(0.3), [1.0, 1.0, 1.0]);
        let layer = joint([0.7, -0.2, 0.3], Quat::from_rotation_x(1.1), [2.0, 1.0, 0.5]);
        let mut p = base;
        blend(&mut p, &layer, 0.0);
        assert_eq!(p, base);
        blend(&mut p, &layer, 1.0);
        assert_eq!(p, layer);
    }

    #[test]
    fn a_blend_is_the_lerp_and_the_short_slerp() {
        let mut p = joint([0.0, 0.0, 0.0], Quat::IDENTITY, [1.0, 1.0, 1.0]);
        // The same rotation of 90° about z, written in the far hemisphere.
        let far = -Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
        blend(&mut p, &joint([1.0, 2.0, 4.0], far, [3.0, 3.0, 3.0]), 0.5);
        assert!((p.t - Vec3A::new(0.5, 1.0, 2.0)).length() < 1e-6);
        assert!((p.s - Vec3A::splat(2.0)).length() < 1e-6);
        let expected = Quat::from_rotation_z(std::f32::consts::FRAC_PI_4);
        assert!(p.q.dot(expected).abs() > 1.0 - 1e-6, "{:?}", p.q);
    }

    #[test]
    fn an_additive_layer_adds_its_difference_from_the_reference() {
        let reference = joint([1.0, 0.0, 0.0], Quat::from_rotation_y(0.2), [2.0, 2.0, 0.0]);
        let layer = joint([1.5, 1.0, 0.0], Quat::from_rotation_y(0.2) * Quat::from_rotation_x(0.6), [3.0, 1.0, 5.0]);
        let mut p = joint([0.0, 0.0, 2.0], Quat::from_rotation_z(0.4), [1.0, 1.0, 1.0]);
        add(&mut p, &layer, &reference, 0.5);
        assert!((p.t - Vec3A::new(0.25, 0.5, 2.0)).length() < 1e-6);
        let expected = Quat::from_rotation_z(0.4) * Quat::from_rotation_x(0.3);
        assert!(p.q.dot(expected).abs() > 1.0 - 1e-6, "{:?}", p.q);
        // Ratios 1.5 and 0.5 at half weight; a zero reference scale changes nothing.
        assert!((p.s - Vec3A::new(1.25, 0.75, 1.0)).length() < 1e-6, "{:?}", p.s);
    }
}
