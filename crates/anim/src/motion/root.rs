//! Root motion (docs/motion.md, “Root motion”): the character's travel on the ground, as planar
//! transforms — a ground translation and a heading (yaw) about the up axis.
//!
//! `M(c) = translate(ground(t_root)) · rotate_up(yaw(q_root))` at clip time `c`. A step within one loop
//! cycle has the delta `M(c_{k−1})⁻¹ · M(c_k)`, its yaw wrapped into `(−π, π]`. A step that crosses `n`
//! seams (negative backward) takes `n` whole cycles `C = M(start)⁻¹·M(end)`:
//! `Δ = M(c_{k−1})⁻¹ · M(start) · Cⁿ · M(start)⁻¹ · M(c_k)`, which is
//! `M(c_{k−1})⁻¹·M(end)·C^{n−1}·M(start)⁻¹·M(c_k)` forward and its mirror backward. Its yaw is the root's
//! yaw along the clip, not wrapped ([`Unwrapped`]): from `c_{k−1}` to the seam, `n − 1` whole cycles, and
//! from the seam to `c_k` — the limit of dense sampling, so the total is the same whether the samples are
//! dense or sparse, and a 190° or 360° cycle counts in full. `Cⁿ` has a closed form ([`Planar::pow`]), so
//! a step costs the same however many seams it crosses.

use std::f64::consts::{FRAC_PI_2, PI};

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

    /// `selfⁿ` (`n` may be negative), in closed form: `n` turns of `θ`, and
    /// the translations summed as a geometric series,
    /// `Σ_{j<n} R(jθ)·t = R((n−1)θ/2)·t·sin(nθ/2)/sin(θ/2)`, which is `n·t`
    /// when `θ` is a whole number of turns. The yaw stays unwrapped: `n·θ`.
    pub fn pow(self, n: i64, up: UpAxis) -> Planar {
        let (base, m) = if n < 0 { (self.inverse(up), n.unsigned_abs() as f64) } else { (self, n as f64) };
        // The rotation only depends on θ modulo a turn; the wrapped angle keeps the sines accurate.
        let half = 0.5 * wrap(base.yaw);
        let sum = if half.sin() == 0.0 { m } else { (m * half).sin() / half.sin() };
        Planar { translation: turn(up, (m - 1.0) * half) * (base.translation * sum), yaw: m * base.yaw }
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

/// Where a layer's root is at one sample: its loop cycle, its clip time and `M` there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RootAt {
    pub cycle: i64,
    pub time: f32,
    pub m: Planar,
}

/// The root's yaw along one cycle of its clip, accumulated without wrapping
/// (docs/motion.md, “Root motion”): sampled at the root rotation's keys and
/// segment midpoints, each step between two samples wrapped and summed.
/// Only marks a quarter turn or more apart are kept: between two of them the
/// yaw stays within half a turn of the earlier, which is all [`Unwrapped::at`]
/// needs, so a clip that never turns far keeps one.
#[derive(Debug, Clone, PartialEq)]
pub struct Unwrapped {
    /// `(clip time, unwrapped yaw)` in time order, the first at the clip's start.
    marks: Box<[(f32, f64)]>,
    /// One whole cycle's yaw: at the end minus at the start.
    cycle: f64,
}

impl Unwrapped {
    /// From the yaw at the clip's start and `(clip time, yaw)` samples after
    /// it in time order, the last at the end.
    pub fn new(start: (f32, f64), samples: impl IntoIterator<Item = (f32, f64)>) -> Unwrapped {
        let mut marks = vec![start];
        let mut now = start.1;
        for (time, yaw) in samples {
            now += wrap(yaw - now);
            if marks.last().is_some_and(|m| (now - m.1).abs() >= FRAC_PI_2) {
                marks.push((time, now));
            }
        }
        Unwrapped { marks: marks.into_boxed_slice(), cycle: now - start.1 }
    }

    /// One whole cycle's yaw, unwrapped (a 190° turn is 190°, a full turn 2π).
    pub fn cycle(&self) -> f64 {
        self.cycle
    }

    /// The unwrapped yaw at clip time `time`, where the wrapped yaw is `yaw`:
    /// the one nearest the last mark at or before `time`.
    pub fn at(&self, time: f32, yaw: f64) -> f64 {
        let near = self.marks[self.marks.partition_point(|m| m.0 <= time).saturating_sub(1)].1;
        near + wrap(yaw - near)
    }
}

/// What a layer's clip gives every step of its root motion: `M(start)`, the
/// whole cycle `C` with its yaw unwrapped, and the yaw along the clip.
#[derive(Debug, Clone, PartialEq)]
pub struct Cycle {
    pub start: Planar,
    whole: Planar,
    yaw: Unwrapped,
}

impl Cycle {
    /// The cycle of a clip whose root is at `start` and `end` at its ends.
    pub fn new(start: Planar, end: Planar, yaw: Unwrapped, up: UpAxis) -> Cycle {
        let whole = Planar { yaw: yaw.cycle(), ..start.inverse(up).then(end, up) };
        Cycle { start, whole, yaw }
    }

    /// The whole cycle `C = M(start)⁻¹·M(end)`, its yaw unwrapped.
    pub fn whole(&self) -> Planar {
        self.whole
    }

    /// The delta from one sample to the next (see the module doc).
    pub fn delta(&self, from: RootAt, to: RootAt, up: UpAxis) -> Planar {
        let seams = to.cycle.saturating_sub(from.cycle);
        if seams == 0 {
            return from.m.inverse(up).then(to.m, up).wrapped();
        }
        let along = |r: RootAt| Planar { yaw: self.yaw.at(r.time, r.m.yaw), ..r.m };
        let cycles = self.start.then(self.whole.pow(seams, up), up).then(self.start.inverse(up), up);
        along(from).inverse(up).then(cycles, up).then(along(to), up)
    }
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
        // Turns of none, a little, a quarter, more than half, whole and near-whole turns.
        for yaw in [0.0, 1e-9, 0.3, PI / 2.0, 190f64.to_radians(), 2.0 * PI, 2.0 * PI - 1e-9, -4.0] {
            let step = Planar { translation: DVec3::new(1.0, 0.0, 0.5), yaw };
            let mut by_hand = Planar::IDENTITY;
            for n in 0..=40 {
                let power = step.pow(n, UpAxis::Y);
                assert!(close(power, by_hand), "yaw {yaw}, n {n}: {power:?} vs {by_hand:?}");
                let back = step.pow(-n, UpAxis::Y).then(by_hand, UpAxis::Y);
                assert!(close(back, Planar::IDENTITY), "yaw {yaw}, n −{n}: {back:?}");
                by_hand = by_hand.then(step, UpAxis::Y);
            }
        }
        // A quarter turn four times is a full turn back where it started, yaw 2π unwrapped.
        let quarter = Planar { translation: DVec3::new(1.0, 0.0, 0.0), yaw: PI / 2.0 };
        let square = quarter.pow(4, UpAxis::Y);
        assert!(square.translation.length() < 1e-12 && (square.yaw - 2.0 * PI).abs() < 1e-12);
    }

    /// A clip whose root goes from `start` to `end` (no turn, or `turn`
    /// radians spread evenly over `samples` samples).
    fn cycle(end_x: f64, turn: f64, samples: u32) -> Cycle {
        let at = |x: f64, yaw: f64| Planar { translation: DVec3::new(x, 0.0, 0.0), yaw: wrap(yaw) };
        let along = (1..=samples).map(|i| {
            let u = f64::from(i) / f64::from(samples);
            (u as f32, wrap(turn * u))
        });
        Cycle::new(at(0.0, 0.0), at(end_x, turn), Unwrapped::new((0.0, 0.0), along), UpAxis::Y)
    }

    fn root(cycle: i64, x: f64, time: f32) -> RootAt {
        RootAt { cycle, time, m: Planar { translation: DVec3::new(x, 0.0, 0.0), yaw: 0.0 } }
    }

    #[test]
    fn a_seam_crossed_adds_the_whole_cycle() {
        // A straight walk from x = 0 to x = 2 per cycle, no turn.
        let walk = cycle(2.0, 0.0, 2);
        let x = |x: f64| Planar { translation: DVec3::new(x, 0.0, 0.0), yaw: 0.0 };
        // From 1.5 in cycle 0 to 0.5 in cycle 1: 0.5 + 0.5 = 1.
        assert!(close(walk.delta(root(0, 1.5, 0.75), root(1, 0.5, 0.25), UpAxis::Y), x(1.0)));
        // Three seams at once: 0.5 + 2·2 + 0.5 = 5.
        assert!(close(walk.delta(root(0, 1.5, 0.75), root(3, 0.5, 0.25), UpAxis::Y), x(5.0)));
        // Backward over one seam: −1.
        assert!(close(walk.delta(root(1, 0.5, 0.25), root(0, 1.5, 0.75), UpAxis::Y), x(-1.0)));
    }

    #[test]
    fn the_cycles_yaw_is_not_wrapped_along_the_clip() {
        for degrees in [0.0f64, 90.0, 179.0, 190.0, 360.0, 725.0, -400.0] {
            let turn = degrees.to_radians();
            let c = cycle(0.0, turn, 64);
            assert!((c.whole().yaw - turn).abs() < 1e-12, "{degrees}°: {}", c.whole().yaw);
            // Each sample's wrapped yaw unwraps to the turn so far.
            for i in 0..=64 {
                let u = f64::from(i) / 64.0;
                let unwrapped = c.yaw.at(u as f32, wrap(turn * u));
                assert!((unwrapped - turn * u).abs() < 1e-12, "{degrees}° at {u}: {unwrapped}");
            }
        }
        // A clip that turns little keeps one mark.
        assert_eq!(cycle(0.0, 1.0, 64).yaw.marks.len(), 1);
    }
}
