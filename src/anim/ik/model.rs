//! Model space along one joint's ancestry, and the rotation tools the
//! solvers share.
//!
//! A solver needs the model transforms of a few joints, not the whole
//! pose: [`walk`] composes SPEC §2.8's rule down one root-to-joint path, so
//! a leg costs its depth, not the skeleton's size. Under that rule a
//! model-space rotation `D` applied at a joint (`q_m := D·q_m`) turns its
//! whole subtree rigidly about the joint's position, scales included, which
//! is what lets every solver here reason about positions with plain
//! rotations; [`to_local`] writes such a `D` back into the local pose.

use glam::{DQuat, DVec3, Quat, Vec3A};

use crate::anim::{Pose, Skeleton};

/// A joint's model transform (SPEC §2.8).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Xform {
    pub t: Vec3A,
    pub q: Quat,
    pub s: Vec3A,
}

impl Xform {
    pub const IDENTITY: Xform = Xform { t: Vec3A::ZERO, q: Quat::IDENTITY, s: Vec3A::ONE };

    /// The model transform of a child with local `(t, q, s)`.
    #[inline]
    pub fn child(&self, t: Vec3A, q: Quat, s: Vec3A) -> Xform {
        Xform { t: self.t + self.q * (self.s * t), q: self.q * q, s: self.s * s }
    }

    /// Where a point fixed in this joint's local frame sits in model space.
    #[inline]
    pub fn point(&self, local: Vec3A) -> Vec3A {
        self.t + self.q * (self.s * local)
    }
}

/// Fills `path` with `joint`'s ancestors and itself, root first, and
/// `model` with their model transforms (`model[i]` is `path[i]`'s, and
/// `path[i - 1]` is `path[i]`'s parent).
///
/// # Panics
/// If `joint` is not a joint of `skeleton`.
pub(crate) fn walk(skeleton: &Skeleton, local: &Pose, joint: usize, path: &mut Vec<usize>, model: &mut Vec<Xform>) {
    path.clear();
    let mut j = Some(joint);
    while let Some(k) = j {
        path.push(k);
        j = skeleton.parent(k);
    }
    path.reverse();
    model.clear();
    let root = path[0];
    let mut m = Xform { t: local.translations[root], q: local.rotations[root], s: local.scales[root] };
    model.push(m);
    for &k in &path[1..] {
        m = m.child(local.translations[k], local.rotations[k], local.scales[k]);
        model.push(m);
    }
}

/// The local rotation that makes a joint's model rotation `delta·model`,
/// given its parent's model rotation: `parent⁻¹·delta·model`.
#[inline]
pub(crate) fn to_local(parent: Quat, delta: Quat, model: Quat) -> Quat {
    (parent.conjugate() * (delta * model)).normalize()
}

/// `v`'s direction, or `None` for the zero vector; huge and tiny finite
/// vectors are scaled first, so they neither overflow nor underflow.
#[inline]
pub(crate) fn unit(v: Vec3A) -> Option<Vec3A> {
    let squared = v.length_squared();
    if squared > 1e-30 && squared < 1e30 { Some(v * squared.sqrt().recip()) } else { unit_scaled(v) }
}

#[cold]
fn unit_scaled(v: Vec3A) -> Option<Vec3A> {
    let m = v.abs().max_element();
    if m > 0.0 && m.is_finite() { Some((v / m).normalize()) } else { None }
}

/// The smallest rotation taking `from`'s direction to `to`'s (both
/// nonzero): `(f × t, |f|·|t| + f·t)` normalised. Below about 150° that is
/// exact to `f32` rounding; nearer antiparallel, where the `f32` sum
/// loses the angle, it is computed in `f64`.
#[inline]
pub(crate) fn arc(from: Vec3A, to: Vec3A) -> Quat {
    let lengths = (from.length_squared() * to.length_squared()).sqrt();
    let w = lengths + from.dot(to);
    if w > 0.1 * lengths && lengths > 1e-30 && lengths < 1e30 {
        let c = from.cross(to);
        return Quat::from_xyzw(c.x, c.y, c.z, w).normalize();
    }
    arc_f64(from, to)
}

#[cold]
fn arc_f64(from: Vec3A, to: Vec3A) -> Quat {
    let (f, t) = (from.as_dvec3(), to.as_dvec3());
    let lengths = (f.length_squared() * t.length_squared()).sqrt();
    let w = lengths + f.dot(t);
    if w <= 1e-12 * lengths {
        // Antiparallel: half a turn about any axis perpendicular to `from`.
        let axis = f.normalize_or(DVec3::X).any_orthonormal_vector();
        return DQuat::from_xyzw(axis.x, axis.y, axis.z, 0.0).as_quat();
    }
    let c = f.cross(t);
    DQuat::from_xyzw(c.x, c.y, c.z, w).normalize().as_quat()
}

/// The rotation about unit `axis` that turns `from`'s component
/// perpendicular to the axis onto `toward`'s, or the identity when either
/// lies within 1e-6 rad of the axis (no roll is defined there). Like
/// [`arc`], in `f64` only near a half turn.
#[inline]
pub(crate) fn roll(axis: Vec3A, from: Vec3A, toward: Vec3A) -> Quat {
    let (u, v) = (from - axis * axis.dot(from), toward - axis * axis.dot(toward));
    let (uu, vv) = (u.length_squared(), v.length_squared());
    let lengths = (uu * vv).sqrt();
    let cos = lengths + u.dot(v);
    let defined = uu > 1e-10 * from.length_squared() && vv > 1e-10 * toward.length_squared();
    if defined && cos > 0.1 * lengths && lengths > 1e-30 && lengths < 1e30 {
        // About `axis` by φ: `(axis·sin φ, 1 + cos φ)`, scaled by `|u|·|v|`.
        let sin = axis.dot(u.cross(v));
        return Quat::from_xyzw(axis.x * sin, axis.y * sin, axis.z * sin, cos).normalize();
    }
    roll_f64(axis, from, toward)
}

#[cold]
fn roll_f64(axis: Vec3A, from: Vec3A, toward: Vec3A) -> Quat {
    let (w, f, t) = (axis.as_dvec3(), from.as_dvec3(), toward.as_dvec3());
    let (u, v) = (f - w * w.dot(f), t - w * w.dot(t));
    let (uu, vv) = (u.length_squared(), v.length_squared());
    if !(uu > 1e-12 * f.length_squared() && vv > 1e-12 * t.length_squared()) {
        return Quat::IDENTITY;
    }
    let lengths = (uu * vv).sqrt();
    let (sin, cos) = (w.dot(u.cross(v)), lengths + u.dot(v));
    if cos <= 1e-12 * lengths {
        return Quat::from_xyzw(axis.x, axis.y, axis.z, 0.0);
    }
    DQuat::from_xyzw(w.x * sin, w.y * sin, w.z * sin, cos).normalize().as_quat()
}

/// The angle between two vectors, accurate near 0 and π; 0 if either is
/// zero. Small angles (the residual of a solved aim) take `asin`'s series
/// instead of `atan2`.
#[inline]
pub(crate) fn angle_between(a: Vec3A, b: Vec3A) -> f32 {
    let lengths = (a.length_squared() * b.length_squared()).sqrt();
    if !(lengths > 1e-30 && lengths < 1e30) {
        return match (unit(a), unit(b)) {
            (Some(a), Some(b)) => angle_between(a, b),
            _ => 0.0,
        };
    }
    let (sin, cos) = (a.cross(b).length(), a.dot(b));
    let s = sin / lengths;
    // asin(s) = s + s³/6 + 3s⁵/40 + …: below 1e-2 the rest is under 1e-11.
    if cos > 0.0 && s < 1e-2 { s + s * s * s * (1.0 / 6.0) } else { sin.atan2(cos) }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    #[test]
    fn arc_is_exact_up_to_antiparallel() {
        let from = Vec3A::new(0.3, -0.5, 0.8).normalize();
        let side = from.any_orthonormal_vector();
        for tilt in [0.0f32, 1e-7, 1e-5, 1e-3, 0.5, 2.0, 3.0, std::f32::consts::PI - 1e-6, std::f32::consts::PI] {
            let to = Quat::from_axis_angle(side.into(), tilt) * from;
            let landed = arc(from, to) * from;
            assert!(angle_between(landed, to) < 1e-6, "tilt {tilt}: {landed:?} vs {to:?}");
            assert!((arc(from, to).length() - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn unit_survives_huge_and_tiny_vectors() {
        for v in [Vec3A::splat(3e38), Vec3A::new(1e-40, 0.0, -1e-40), Vec3A::new(0.0, 2.0, 0.0)] {
            let u = unit(v).expect("a direction");
            assert!((u.length() - 1.0).abs() < 1e-6 && u.dot(v.signum()) > 0.0, "{v:?} → {u:?}");
        }
        assert_eq!(unit(Vec3A::ZERO), None);
    }

    #[test]
    fn roll_turns_about_the_axis_and_only_when_defined() {
        let q = roll(Vec3A::Z, Vec3A::new(1.0, 0.0, 5.0), Vec3A::new(0.0, 2.0, -1.0));
        assert!(angle_between(q * Vec3A::X, Vec3A::Y) < 1e-6, "{q:?}");
        assert_eq!(roll(Vec3A::Z, Vec3A::Z, Vec3A::Y), Quat::IDENTITY);
        assert_eq!(roll(Vec3A::Z, Vec3A::X, Vec3A::ZERO), Quat::IDENTITY);
    }

    #[test]
    fn a_model_space_turn_written_back_turns_the_joint_in_model_space() {
        let (parent, local) = (Quat::from_rotation_y(0.7), Quat::from_rotation_x(-1.2));
        let delta = Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.4);
        let written = to_local(parent, delta, parent * local);
        assert!((parent * written).angle_between(delta * parent * local) < 1e-6);
    }
}
