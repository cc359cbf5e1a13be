//! Root motion (docs/motion.md, “Root motion”): the character's travel on the ground, as planar
//! transforms — a ground translation and a heading (yaw) about the up axis.
//!
//! `M(c) = translate(ground(t_root)) · rotate_up(yaw(q_root))` at clip time
//! `c`; a frame's delta is `M(c_{k−1})⁻¹ · M(c_k)`, with each loop seam
//! crossed replaced by the whole cycle `W = M(start)⁻¹·M(end)`:
//! `Δ = M(c_{k−1})⁻¹ · M(start) · Wⁿ · M(start)⁻¹ · M(c_k)` for `n` seams
//! crossed (negative backward), which is the documented
//! `M(c_{k−1})⁻¹·M(end)·M(start)⁻¹·M(c_k)` for one seam forward and its
//! mirror backward. `Wⁿ` is taken by squaring, so a fast loop crossing a
//! million seams in one frame costs twenty compositions.

use std::f64::consts::PI;

use glam::{DQuat, DVec3, Quat, Vec3A};

use super::spec::UpAxis;

/// A translation on the ground plane followed by a turn about the up axis.
/// Composition keeps the yaw unwrapped (three turns are `6π`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Planar {
    pub translation: DVec3,
    pub yaw: f64,
}

impl Planar {
    pub const IDENTITY: Planar = Planar { translation: DVec3::ZERO, yaw: 0.0 };

    /// `self · next`: `next` expressed in `self`'s frame.
    pub fn then(self, next: Planar, up: UpAxis) -> Planar {
        Planar { translation: self.translation + turn(up, self.yaw) * next.translation, yaw: self.yaw + next.yaw }
    }

    /// The move that undoes this one: `self.inverse(up).then(self, up)` is the identity.
    pub fn inverse(self, up: UpAxis) -> Planar {
        Planar { translation: -(turn(up, -self.yaw) * self.translation), yaw: -self.yaw }
    }

    /// `selfⁿ` (`n` may be negative).
    pub fn pow(self, n: i64, up: UpAxis) -> Planar {
        let (mut base, mut exp) = if n < 0 { (self.inverse(up), n.unsigned_abs()) } else { (self, n as u64) };
        let mut out = Planar::IDENTITY;
        while exp > 0 {
            if exp & 1 == 1 {
                out = out.then(base, up);
            }
            base = base.then(base, up);
            exp >>= 1;
        }
        out
    }

    /// The same transform with its yaw wrapped into `(−π, π]` (a delta's).
    pub fn wrapped(self) -> Planar {
        Planar { yaw: wrap(self.yaw), ..self }
    }

    /// Componentwise `lerp` toward `other` by `w` (how layers and fades mix deltas).
    pub fn lerp(self, other: Planar, w: f64) -> Planar {
        Planar { translation: self.translation.lerp(other.translation, w), yaw: self.yaw + (other.yaw - self.yaw) * w }
    }

    /// Applies the transform to a local root transform `(t, q)`: the point
    /// moves and turns with it, keeping its height above the ground.
    pub fn apply(self, up: UpAxis, t: Vec3A, q: Quat) -> (Vec3A, Quat) {
        let r = turn(up, self.yaw);
        let t = r * t.as_dvec3() + self.translation;
        let q = (r * q.as_dquat()).normalize();
        (t.as_vec3a(), q.as_quat())
    }
}

/// `M` of a root local transform: its ground position and its heading.
pub fn motion_transform(up: UpAxis, t: Vec3A, q: Quat) -> Planar {
    let t = t.as_dvec3();
    let axis = axis(up);
    Planar { translation: t - axis * t.dot(axis), yaw: yaw(up, q.as_dquat()) }
}

/// The twist of `q` about the up axis: `2·atan2(q_up, q_w)` wrapped into
/// `(−π, π]`, and 0 when both are 0.
pub fn yaw(up: UpAxis, q: DQuat) -> f64 {
    let component = match up {
        UpAxis::Y => q.y,
        UpAxis::Z => q.z,
    };
    if component == 0.0 && q.w == 0.0 { 0.0 } else { wrap(2.0 * component.atan2(q.w)) }
}

/// The delta between two layer positions `(cycle, M)`, given the layer's
/// whole-cycle transform `M(start)` and `W`.
pub fn delta(from: (i64, Planar), to: (i64, Planar), start: Planar, whole: Planar, up: UpAxis) -> Planar {
    let seams = to.0.saturating_sub(from.0);
    let path =
        if seams == 0 { to.1 } else { start.then(whole.pow(seams, up), up).then(start.inverse(up), up).then(to.1, up) };
    from.1.inverse(up).then(path, up).wrapped()
}

fn axis(up: UpAxis) -> DVec3 {
    match up {
        UpAxis::Y => DVec3::Y,
        UpAxis::Z => DVec3::Z,
    }
}

fn turn(up: UpAxis, yaw: f64) -> DQuat {
    DQuat::from_axis_angle(axis(up), yaw)
}

fn wrap(angle: f64) -> f64 {
    let a = angle.rem_euclid(2.0 * PI);
    if a > PI { a - 2.0 * PI } else { a }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Planar, b: Planar) -> bool {
        (a.translation - b.translation).length() < 1e-9 && (a.yaw - b.yaw).abs() < 1e-9
    }

    #[test]
    fn yaw_is_the_twist_about_up_whatever_the_swing() {
        let twist = DQuat::from_rotation_y(0.7);
        let swing = DQuat::from_rotation_x(0.4);
        assert!((yaw(UpAxis::Y, twist) - 0.7).abs() < 1e-12);
        // Swing-twist and twist-swing give the same twist.
        assert!((yaw(UpAxis::Y, twist * swing) - 0.7).abs() < 1e-12);
        assert!((yaw(UpAxis::Y, swing * twist) - 0.7).abs() < 1e-12);
        assert!((yaw(UpAxis::Z, DQuat::from_rotation_z(-2.0)) + 2.0).abs() < 1e-12);
        assert_eq!(yaw(UpAxis::Y, DQuat::from_xyzw(1.0, 0.0, 0.0, 0.0)), 0.0);
    }

    #[test]
    fn powers_are_repeated_compositions_and_inverses() {
        let step = Planar { translation: DVec3::new(1.0, 0.0, 0.5), yaw: 0.3 };
        let mut by_hand = Planar::IDENTITY;
        for _ in 0..7 {
            by_hand = by_hand.then(step, UpAxis::Y);
        }
        assert!(close(step.pow(7, UpAxis::Y), by_hand));
        assert!(close(step.pow(-7, UpAxis::Y).then(by_hand, UpAxis::Y), Planar::IDENTITY));
        // A quarter turn four times is a full turn back where it started, yaw 2π unwrapped.
        let quarter = Planar { translation: DVec3::new(1.0, 0.0, 0.0), yaw: PI / 2.0 };
        let square = quarter.pow(4, UpAxis::Y);
        assert!(square.translation.length() < 1e-12 && (square.yaw - 2.0 * PI).abs() < 1e-12);
    }

    #[test]
    fn a_seam_crossed_adds_the_whole_cycle() {
        // A straight walk from x = 0 to x = 2 per cycle, no turn.
        let at = |x: f64| Planar { translation: DVec3::new(x, 0.0, 0.0), yaw: 0.0 };
        let (start, end) = (at(0.0), at(2.0));
        let whole = start.inverse(UpAxis::Y).then(end, UpAxis::Y);
        // From 1.5 in cycle 0 to 0.5 in cycle 1: 0.5 + 0.5 = 1.
        assert!(close(delta((0, at(1.5)), (1, at(0.5)), start, whole, UpAxis::Y), at(1.0)));
        // Three seams at once: 0.5 + 2·2 + 0.5 = 5.
        assert!(close(delta((0, at(1.5)), (3, at(0.5)), start, whole, UpAxis::Y), at(5.0)));
        // Backward over one seam: −1.
        assert!(close(delta((1, at(0.5)), (0, at(1.5)), start, whole, UpAxis::Y), at(-1.0)));
    }
}
