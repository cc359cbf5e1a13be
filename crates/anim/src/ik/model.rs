//! Model space along one joint's ancestry, and the rotation tools the
//! solvers share.
//!
//! A solver needs the model transforms of a few joints, not the whole pose:
//! [`model`] composes the rule of docs/clip-format.md, “Skeleton and spaces”,
//! down one root-to-joint path, so a leg costs its depth, not the skeleton's
//! size. Under that rule a model-space rotation `D` applied at a joint (`q_m :=
//! D·q_m`) turns its whole subtree rigidly about the joint's position, scales
//! included, which is what lets every solver here reason about positions with
//! plain rotations; with `P` the parent's model rotation, the joint's local
//! rotation becomes `P⁻¹·D·P·local`, and `P⁻¹·D·P` is the same turn found from
//! vectors seen in the parent's frame (rotated by `P⁻¹`), so the solvers work
//! there and never form `D` or the joint's model rotation.

use glam::{DQuat, DVec3, Quat, Vec3A, Vec4};

use crate::{Pose, Skeleton};

/// A joint's model transform (docs/clip-format.md, “Skeleton and spaces”).
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
        Xform { t: self.point(t), q: self.q * q, s: self.s * s }
    }

    /// Where a point fixed in this joint's local frame sits in model space.
    #[inline]
    pub fn point(&self, local: Vec3A) -> Vec3A {
        self.t + rotate(self.q, self.s * local)
    }
}

/// `q·v` for a unit `q`, as `v + w·t + u × t` with `t = 2·(u × v)` (`u` the
/// vector part, `w` the scalar): two cross products and no dot product,
/// about half the instructions of glam's general form, which also serves
/// quaternions that are not unit. Every rotation here is unit to rounding.
#[inline]
pub(crate) fn rotate(q: Quat, v: Vec3A) -> Vec3A {
    let u = Vec3A::from_vec4(Vec4::from(q));
    let t = u.cross(v);
    let t = t + t;
    v + t * q.w + u.cross(t)
}

/// Fills `path` with `joint` and its ancestors, leaf first
/// (`path[i + 1]` is `path[i]`'s parent, the last is a root).
///
/// # Panics
/// If `joint` is not a joint of `skeleton`.
pub(crate) fn ancestry(skeleton: &Skeleton, joint: usize, path: &mut Vec<usize>) {
    path.clear();
    let mut j = joint;
    loop {
        path.push(j);
        match skeleton.parent(j) {
            Some(p) => j = p,
            None => return,
        }
    }
}

/// The model transform of the first of `joints`, a leaf-first run up to a
/// root (identity for none): the composition of docs/clip-format.md,
/// “Skeleton and spaces”, down one path, so a leg costs its
/// depth, not the skeleton's size.
#[inline]
pub(crate) fn model(local: &Pose, joints: &[usize]) -> Xform {
    let Some((&root, rest)) = joints.split_last() else { return Xform::IDENTITY };
    let (t, q, s) = tracks(local);
    let m = Xform { t: t[root], q: q[root], s: s[root] };
    extend(m, local, rest)
}

/// `start`, the model transform of the parent of the last of `joints`,
/// carried down the leaf-first run `joints` to the first.
#[inline]
pub(crate) fn extend(start: Xform, local: &Pose, joints: &[usize]) -> Xform {
    let (t, q, s) = tracks(local);
    joints.iter().rev().fold(start, |m, &k| m.child(t[k], q[k], s[k]))
}

/// The pose's translations, rotations and scales cut to one length, so an
/// index checked against one is known good for the others (one bounds
/// check a joint instead of three).
#[inline]
fn tracks(local: &Pose) -> (&[Vec3A], &[Quat], &[Vec3A]) {
    let n = local.translations.len();
    (&local.translations[..n], &local.rotations[..n], &local.scales[..n])
}

/// The local rotation of a joint whose parent has model rotation `parent`
/// after a model-space turn `delta` of it: `parent⁻¹·delta·parent·local`.
/// The solvers compute their turns directly in the parent's frame
/// (`parent⁻¹·delta·parent`, from vectors rotated by `parent⁻¹`), which
/// needs neither product; this is the rule they rely on.
/// `slerp(before, solved, weight)`, exact at the ends.
#[inline]
pub(super) fn blend(before: Quat, solved: Quat, weight: f32) -> Quat {
    if weight >= 1.0 {
        solved
    } else if weight <= 0.0 {
        before
    } else {
        before.slerp(solved, weight).normalize()
    }
}

#[cfg(test)]
fn to_local(parent: Quat, delta: Quat, local: Quat) -> Quat {
    (parent.conjugate() * delta * parent * local).normalize()
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

/// [`arc`] before its normalisation (its length is between about 0.45 and
/// 2 times `|from|·|to|`), for a caller that normalises a product with it
/// anyway; `None` where [`arc`] would go to `f64` or a square of the
/// length could leave `f32`'s range. `from_squared` is `|from|²`, which a
/// caller may know before `from` (a unit rotation keeps it), so the square
/// root need not wait for `from`.
#[inline]
pub(crate) fn arc_unnormalized(from: Vec3A, from_squared: f32, to: Vec3A) -> Option<Quat> {
    let lengths = (from_squared * to.length_squared()).sqrt();
    let w = lengths + from.dot(to);
    if w > 0.1 * lengths && lengths > 1e-15 && lengths < 1e15 {
        let c = from.cross(to);
        return Some(Quat::from_xyzw(c.x, c.y, c.z, w));
    }
    None
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
/// lies within 1e-6 rad of the axis (no roll is defined there). In `f32`
/// at any angle (near a half turn by the half-turn form below); in `f64`
/// only near the axis or at extreme scales.
#[inline]
pub(crate) fn roll(axis: Vec3A, from: Vec3A, toward: Vec3A) -> Quat {
    let (u, v) = (from - axis * axis.dot(from), toward - axis * axis.dot(toward));
    let (uu, vv) = (u.length_squared(), v.length_squared());
    let lengths = (uu * vv).sqrt();
    let defined = uu > 1e-10 * from.length_squared() && vv > 1e-10 * toward.length_squared();
    if defined && lengths > 1e-30 && lengths < 1e30 {
        // About `axis` by φ: `(axis·sin φ, 1 + cos φ)`, scaled by `|u|·|v|`;
        // past a quarter turn, where `1 + cos φ` loses φ, the same rotation
        // scaled by `(1 − cos φ)/|sin φ|`: `(axis·(1 − cos φ)·sign, |sin φ|)`.
        let (sin, cos) = (axis.dot(u.cross(v)), u.dot(v));
        let (s, w) = if cos >= 0.0 {
            (sin, lengths + cos)
        } else if sin < 0.0 {
            (cos - lengths, -sin)
        } else {
            (lengths - cos, sin)
        };
        return Quat::from_xyzw(axis.x * s, axis.y * s, axis.z * s, w).normalize();
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
/// instead of `atan2`, from `sin²` (one square root).
#[inline]
pub(crate) fn angle_between(a: Vec3A, b: Vec3A) -> f32 {
    let squares = a.length_squared() * b.length_squared();
    if !(squares > 1e-30 && squares < 1e30) {
        return angle_between_scaled(a, b);
    }
    let (cross, cos) = (a.cross(b), a.dot(b));
    let sin_squared = cross.length_squared() / squares;
    // asin(s) = s + s³/6 + 3s⁵/40 + …: below 1e-2 the rest is under 1e-11.
    if cos > 0.0 && sin_squared < 1e-4 {
        let s = sin_squared.sqrt();
        s + s * sin_squared * (1.0 / 6.0)
    } else {
        cross.length().atan2(cos)
    }
}

#[cold]
fn angle_between_scaled(a: Vec3A, b: Vec3A) -> f32 {
    match (unit(a), unit(b)) {
        (Some(a), Some(b)) => angle_between(a, b),
        _ => 0.0,
    }
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
        // Near and at a half turn, in both directions.
        for tilt in [0.0f32, 1e-6, -1e-6, 1e-3, -0.5, 0.5] {
            let toward = Quat::from_rotation_z(std::f32::consts::PI + tilt) * Vec3A::new(2.0, 1.0, 0.3);
            let q = roll(Vec3A::Z, Vec3A::new(2.0, 1.0, -4.0), toward);
            let landed = q * Vec3A::new(2.0, 1.0, 0.0);
            assert!(angle_between(landed, toward * Vec3A::new(1.0, 1.0, 0.0)) < 1e-6, "{tilt}: {q:?}");
            assert!(q.w >= 0.0 && (q.length() - 1.0).abs() < 1e-6);
        }
        assert_eq!(roll(Vec3A::Z, Vec3A::X, Vec3A::ZERO), Quat::IDENTITY);
    }

    #[test]
    fn rotate_matches_glam() {
        let q = Quat::from_axis_angle(Vec3::new(-0.4, 2.0, 0.3).normalize(), 2.2);
        for v in [Vec3A::X, Vec3A::new(1.5, -3.0, 0.25), Vec3A::ZERO] {
            assert!((rotate(q, v) - q * v).length() < 1e-6 * (1.0 + v.length()), "{v:?}");
        }
    }

    #[test]
    fn a_turn_in_the_parents_frame_is_the_model_space_turn() {
        let (parent, local) = (Quat::from_rotation_y(0.7), Quat::from_rotation_x(-1.2));
        let axis = Vec3::new(1.0, 2.0, 3.0).normalize();
        let delta = Quat::from_axis_angle(axis, 0.4);
        let written = to_local(parent, delta, local);
        assert!((parent * written).angle_between(delta * parent * local) < 1e-6);
        // The same turn found from vectors seen in the parent's frame (an
        // arc, so from a vector perpendicular to the turn's axis).
        let from = Vec3A::from(axis.cross(Vec3::X));
        let to = delta * from;
        let inv = parent.conjugate();
        assert!(arc(inv * from, inv * to).angle_between(inv * delta * parent) < 1e-6);
    }
}
