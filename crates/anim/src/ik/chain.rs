//! The chain solver (docs/ik.md, “Constraints”, `chain`; seed 003's problem): three angles
//! per movable joint, `q = q_anim·Rx(a1)·Ry(a2)·Rz(a3)`, chosen to minimise
//! `E(a) = Σ_b ‖x_b(a) − target_b‖²` inside box limits.
//!
//! The method is projected damped least squares (Levenberg–Marquardt).
//! Each iteration builds the analytic Jacobian — the column of angle `k` of
//! joint `j` for effector `b` is `axis_k × (x_b − p_j)`, with `axis_k` the
//! model-space axis of that angle's elementary rotation — drops the columns
//! of angles at a bound that the descent direction `Jᵀ·e` pushes outward,
//! and solves the small `(J·Jᵀ + λ·I)·y = e` (one row per effector
//! coordinate, `f64`) for the step `Δ = Jᵀ·y`. Angles at a bound that `Δ`
//! itself pushes outward are dropped too and the system solved again:
//! merely clipping them bends the step off its course, and on a body whose
//! arms start straight that left one solve in ten unconverged after 100
//! iterations. The step is projected onto the limits and kept only if `E`
//! decreases; otherwise `λ` grows (Nielsen's rule, see [`Damping`]) and the
//! step is retried within the iteration. An iteration that finds no
//! decrease at any `λ` leaves the iterate where it was and ends the solve
//! (the point is stationary as far as `f32` can tell). So every iterate is
//! inside the limits, `E` never rises, and a budget of `k` iterations
//! returns iterate `k`.
//!
//! The solve starts from `a = 0` (the animated pose) or, warm, from the
//! previous solve's angles, and stops once `√E ≤ tolerance`. Only the
//! joints on effector paths take part (the nodes), in skeleton order, so
//! forward kinematics is one pass over them. Buffers live in [`ChainSolver`]
//! and are reused: a solve of a shape seen before allocates nothing.

use glam::{Quat, Vec3A};

use super::constraint::{Chain, IkKind};
use super::linalg::cholesky_solve;
use super::model::{Xform, blend};
use super::report::IkReport;
use crate::{Pose, Skeleton};

const NONE: u32 = u32::MAX;

/// The default tolerance as a fraction of the chain's length (docs/ik.md, “Constraints”).
pub const DEFAULT_RELATIVE_TOLERANCE: f32 = 1e-4;

/// Damping `λ = μ·s`, `s` the mean diagonal of `J·Jᵀ`: where `μ` starts,
/// the floor it may fall to, and how many tries one iteration gets.
const DAMPING_START: f64 = 1e-3;
const DAMPING_FLOOR: f64 = 1e-12;
const TRIES: usize = 10;
/// How often one try may drop angles its step would push out of the box.
const HOLD_PASSES: usize = 4;

/// Nielsen's rule ("Damping parameter in Marquardt's method", 1999): a
/// step that did what the linear model promised (gain ratio `ρ` near 1)
/// cuts `μ` up to threefold, a poor one raises it smoothly, and refused
/// steps raise it ever faster (`ν` doubles each time).
#[derive(Debug, Clone, Copy)]
struct Damping {
    mu: f64,
    nu: f64,
}

impl Damping {
    fn kept(&mut self, rho: f64) {
        let factor = if rho.is_finite() { (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0) } else { 1.0 / 3.0 };
        self.mu = (self.mu * factor).max(DAMPING_FLOOR);
        self.nu = 2.0;
    }

    fn refused(&mut self) {
        self.mu *= self.nu;
        self.nu *= 2.0;
    }
}

/// A joint on an effector's path: its local transform (rotation as
/// animated) and, when movable, its slot in the angle vector.
#[derive(Debug, Clone, Copy)]
struct Node {
    joint: usize,
    parent: u32,
    t: Vec3A,
    q: Quat,
    s: Vec3A,
    slot: u32,
}

#[derive(Debug, Clone, Copy)]
struct Slot {
    node: u32,
    min: [f32; 3],
    max: [f32; 3],
}

#[derive(Debug, Clone, Copy)]
struct Target {
    node: u32,
    tip: Vec3A,
    target: Vec3A,
}

/// The chain solver's reusable buffers.
#[derive(Debug, Clone, Default)]
pub(crate) struct ChainSolver {
    /// Per skeleton joint: on a path, an ancestor of an effector, movable.
    flags: Vec<u8>,
    node_of: Vec<u32>,
    nodes: Vec<Node>,
    slots: Vec<Slot>,
    targets: Vec<Target>,
    angles: Vec<f32>,
    trial: Vec<f32>,
    model: Vec<Xform>,
    trial_model: Vec<Xform>,
    /// Three model-space axes per slot.
    axes: Vec<Vec3A>,
    /// Row-major, one row per effector coordinate, one column per angle.
    jacobian: Vec<f64>,
    normal: Vec<f64>,
    factor: Vec<f64>,
    error: Vec<f64>,
    y: Vec<f64>,
    /// The descent direction `Jᵀ·e`, then each try's step `Δ`.
    direction: Vec<f64>,
}

/// A chain's last solved angles, to warm-start the next solve of the
/// same movable joints.
#[derive(Debug, Clone, Default)]
pub(crate) struct WarmChain {
    pub joints: Vec<usize>,
    pub angles: Vec<f32>,
}

const ON_PATH: u8 = 1;
const ANCESTOR: u8 = 2;
const MOVABLE: u8 = 4;

impl ChainSolver {
    /// Solves `c` on `local`, starting from `warm`'s angles when they are
    /// for the same movable joints, and leaves the solved angles in `warm`.
    pub fn solve(
        &mut self,
        c: &Chain,
        skeleton: &Skeleton,
        local: &mut Pose,
        warm: &mut WarmChain,
        use_warm: bool,
    ) -> IkReport {
        self.set_up(c, skeleton, local);
        self.start(warm, use_warm);
        forward(&self.nodes, &self.angles, &mut self.model);
        let tolerance = c.tolerance.unwrap_or_else(|| DEFAULT_RELATIVE_TOLERANCE * self.length());
        let (energy, iterations) = self.descend(c.max_iterations, f64::from(tolerance));
        warm.joints.clear();
        warm.joints.extend(self.slots.iter().map(|s| self.nodes[s.node as usize].joint));
        warm.angles.clone_from(&self.angles);
        let converged = energy.sqrt() <= f64::from(tolerance);
        let residual = self.write(local, c.weight).unwrap_or(energy.sqrt() as f32);
        IkReport { kind: IkKind::Chain, residual, iterations, converged }
    }

    /// Marks the joints on effector paths, then lists them (skeleton order
    /// is parents first) with their slots and limits.
    fn set_up(&mut self, c: &Chain, skeleton: &Skeleton, local: &Pose) {
        let default_joints = c.joints.is_none();
        self.flags.clear();
        self.flags.resize(skeleton.len(), 0);
        for e in &c.effectors {
            self.flags[e.joint] |= ON_PATH | if default_joints && e.tip != Vec3A::ZERO { MOVABLE } else { 0 };
            let mut next = skeleton.parent(e.joint);
            while let Some(p) = next {
                if self.flags[p] & ANCESTOR != 0 {
                    break;
                }
                self.flags[p] |= ON_PATH | ANCESTOR | if default_joints { MOVABLE } else { 0 };
                next = skeleton.parent(p);
            }
        }
        for &j in c.joints.iter().flatten() {
            if self.flags[j] & ON_PATH != 0 {
                self.flags[j] |= MOVABLE;
            }
        }
        self.list_nodes(c, skeleton, local);
        self.targets.clear();
        let node_of = &self.node_of;
        self.targets.extend(c.effectors.iter().map(|e| Target {
            node: node_of[e.joint],
            tip: e.tip,
            target: e.target,
        }));
    }

    fn list_nodes(&mut self, c: &Chain, skeleton: &Skeleton, local: &Pose) {
        self.node_of.clear();
        self.node_of.resize(skeleton.len(), NONE);
        self.nodes.clear();
        self.slots.clear();
        for j in (0..skeleton.len()).filter(|&j| self.flags[j] & ON_PATH != 0) {
            let node = self.nodes.len() as u32;
            self.node_of[j] = node;
            let parent = skeleton.parent(j).map_or(NONE, |p| self.node_of[p]);
            let slot = if self.flags[j] & MOVABLE != 0 {
                let limits = c.limits.iter().find(|l| l.joint == j);
                let (min, max) = limits.map_or(([f32::NEG_INFINITY; 3], [f32::INFINITY; 3]), |l| (l.min, l.max));
                self.slots.push(Slot { node, min, max });
                self.slots.len() as u32 - 1
            } else {
                NONE
            };
            let (t, q, s) = (local.translations[j], local.rotations[j], local.scales[j]);
            self.nodes.push(Node { joint: j, parent, t, q, s, slot });
        }
    }

    /// `a = 0`, or the last solve's angles for the same joints; projected.
    fn start(&mut self, warm: &WarmChain, use_warm: bool) {
        let same = use_warm
            && warm.angles.len() == 3 * self.slots.len()
            && warm.joints.iter().eq(self.slots.iter().map(|s| &self.nodes[s.node as usize].joint));
        self.angles.clear();
        if same {
            self.angles.extend_from_slice(&warm.angles);
        } else {
            self.angles.resize(3 * self.slots.len(), 0.0);
        }
        project(&self.slots, &mut self.angles);
    }

    /// The longest sum of bone lengths from a movable joint down to an
    /// effector's tip (lengths do not depend on the angles).
    fn length(&self) -> f32 {
        let mut longest = 0.0f64;
        for target in &self.targets {
            let mut node = target.node as usize;
            let mut sum = f64::from((self.model[node].s * target.tip).length());
            loop {
                if self.nodes[node].slot != NONE {
                    longest = longest.max(sum);
                }
                let parent = self.nodes[node].parent;
                if parent == NONE {
                    break;
                }
                sum += f64::from((self.model[parent as usize].s * self.nodes[node].t).length());
                node = parent as usize;
            }
        }
        longest as f32
    }

    /// Iterates from `self.angles` (with `self.model` its pose) until
    /// `√E ≤ tolerance`, the budget is spent or no step lowers `E`;
    /// returns the final `E` and the iterations taken.
    fn descend(&mut self, max_iterations: u32, tolerance: f64) -> (f64, u32) {
        let mut energy = energy_at(&self.targets, &self.model);
        let mut damping = Damping { mu: DAMPING_START, nu: 2.0 };
        let mut iterations = 0;
        while iterations < max_iterations
            && energy.sqrt() > tolerance
            && !self.slots.is_empty()
            && !super::stop::stopped()
        {
            iterations += 1;
            let scale = self.linearise();
            if scale <= 0.0 {
                break;
            }
            match self.step(energy, scale, &mut damping) {
                Some(lower) => energy = lower,
                None => break,
            }
        }
        (energy, iterations)
    }

    /// Builds `J`, `e = target − x`, drops the columns of angles a bound
    /// holds, and forms `J·Jᵀ`; returns its mean diagonal (the damping's
    /// scale; 0 when no free angle moves any effector).
    fn linearise(&mut self) -> f64 {
        self.axes();
        self.jacobian_and_error();
        self.hold_bounded_angles();
        self.form_normal();
        let rows = 3 * self.targets.len();
        (0..rows).map(|i| self.normal[i * rows + i]).sum::<f64>() / rows as f64
    }

    /// `J·Jᵀ`, one row and column per effector coordinate.
    fn form_normal(&mut self) {
        let rows = 3 * self.targets.len();
        let cols = 3 * self.slots.len();
        self.normal.clear();
        self.normal.resize(rows * rows, 0.0);
        for i in 0..rows {
            for k in 0..=i {
                let (ri, rk) = (&self.jacobian[i * cols..][..cols], &self.jacobian[k * cols..][..cols]);
                let v: f64 = ri.iter().zip(rk).map(|(a, b)| a * b).sum();
                self.normal[i * rows + k] = v;
                self.normal[k * rows + i] = v;
            }
        }
    }

    /// The model-space axes of each movable joint's three elementary
    /// rotations: `B·x̂`, `B·Rx(a1)·ŷ`, `B·Rx(a1)·Ry(a2)·ẑ` with
    /// `B = parent·q_anim`.
    fn axes(&mut self) {
        self.axes.clear();
        for (k, slot) in self.slots.iter().enumerate() {
            let node = &self.nodes[slot.node as usize];
            let parent = if node.parent == NONE { Quat::IDENTITY } else { self.model[node.parent as usize].q };
            let base = parent * node.q;
            let rx = Quat::from_rotation_x(self.angles[3 * k]);
            self.axes.extend([base * Vec3A::X, (base * rx) * Vec3A::Y, self.model[slot.node as usize].q * Vec3A::Z]);
        }
    }

    fn jacobian_and_error(&mut self) {
        let cols = 3 * self.slots.len();
        self.jacobian.clear();
        self.jacobian.resize(3 * self.targets.len() * cols, 0.0);
        self.error.clear();
        for (b, target) in self.targets.iter().enumerate() {
            let x = self.model[target.node as usize].point(target.tip);
            self.error.extend((target.target - x).to_array().map(f64::from));
            let mut node = target.node;
            while node != NONE {
                let n = &self.nodes[node as usize];
                if n.slot != NONE {
                    let lever = x - self.model[node as usize].t;
                    for k in 0..3 {
                        let column = 3 * n.slot as usize + k;
                        let d = self.axes[column].cross(lever);
                        for (r, v) in d.to_array().into_iter().enumerate() {
                            self.jacobian[(3 * b + r) * cols + column] = f64::from(v);
                        }
                    }
                }
                node = n.parent;
            }
        }
    }

    /// An angle at a bound whose descent direction (`Jᵀ·e`) points out of
    /// the box cannot move: its column is zeroed so the step uses the rest.
    fn hold_bounded_angles(&mut self) {
        let cols = 3 * self.slots.len();
        self.direction.clear();
        self.direction.resize(cols, 0.0);
        for (i, e) in self.error.iter().enumerate() {
            for (d, j) in self.direction.iter_mut().zip(&self.jacobian[i * cols..][..cols]) {
                *d += j * e;
            }
        }
        self.hold_outward();
    }

    /// Zeroes the columns of angles at a bound that `self.direction` would
    /// push out of the box; whether any column changed.
    fn hold_outward(&mut self) -> bool {
        let (rows, cols) = (3 * self.targets.len(), 3 * self.slots.len());
        let mut held = false;
        for (k, slot) in self.slots.iter().enumerate() {
            for axis in 0..3 {
                let column = 3 * k + axis;
                let (a, d) = (self.angles[column], self.direction[column]);
                let outward = (a <= slot.min[axis] && d < 0.0) || (a >= slot.max[axis] && d > 0.0);
                if outward && (0..rows).any(|r| self.jacobian[r * cols + column] != 0.0) {
                    (0..rows).for_each(|r| self.jacobian[r * cols + column] = 0.0);
                    held = true;
                }
            }
        }
        held
    }

    /// Tries damped steps until one lowers `E` (returned) or the tries run out.
    fn step(&mut self, energy: f64, scale: f64, damping: &mut Damping) -> Option<f64> {
        for _ in 0..TRIES {
            if self.solve_step(damping.mu * scale) {
                self.trial_angles();
                forward(&self.nodes, &self.trial, &mut self.trial_model);
                let lower = energy_at(&self.targets, &self.trial_model);
                if lower < energy {
                    damping.kept((energy - lower) / self.predicted_decrease(energy));
                    std::mem::swap(&mut self.angles, &mut self.trial);
                    std::mem::swap(&mut self.model, &mut self.trial_model);
                    return Some(lower);
                }
            }
            damping.refused();
        }
        None
    }

    /// Solves `(J·Jᵀ + λ·I)·y = e` for the step `Δ = Jᵀ·y` (in
    /// `self.direction`); while `Δ` pushes angles at a bound outward, holds
    /// them and solves again without them. `false` if the system is not
    /// positive definite (rounding at a tiny `λ`).
    fn solve_step(&mut self, lambda: f64) -> bool {
        let (rows, cols) = (3 * self.targets.len(), 3 * self.slots.len());
        for _ in 0..HOLD_PASSES {
            self.factor.clone_from(&self.normal);
            (0..rows).for_each(|i| self.factor[i * rows + i] += lambda);
            self.y.clone_from(&self.error);
            if !cholesky_solve(&mut self.factor, &mut self.y, rows) {
                return false;
            }
            self.direction.clear();
            self.direction.resize(cols, 0.0);
            for (i, y) in self.y.iter().enumerate() {
                for (d, j) in self.direction.iter_mut().zip(&self.jacobian[i * cols..][..cols]) {
                    *d += j * y;
                }
            }
            if !self.hold_outward() {
                break;
            }
            self.form_normal();
        }
        true
    }

    /// `a + Δ`, projected onto the limits.
    fn trial_angles(&mut self) {
        self.trial.clone_from(&self.angles);
        for (a, d) in self.trial.iter_mut().zip(&self.direction) {
            *a += *d as f32;
        }
        project(&self.slots, &mut self.trial);
    }

    /// The decrease of `E` the linear model promises for the trial step:
    /// `‖e‖² − ‖e − J·Δ‖²`.
    fn predicted_decrease(&self, energy: f64) -> f64 {
        let cols = 3 * self.slots.len();
        let mut remaining = 0.0;
        for (i, e) in self.error.iter().enumerate() {
            let row = &self.jacobian[i * cols..][..cols];
            let moved: f64 =
                row.iter().zip(self.trial.iter().zip(&self.angles)).map(|(j, (t, a))| j * f64::from(t - a)).sum();
            remaining += (e - moved) * (e - moved);
        }
        energy - remaining
    }

    /// Writes the solved (and weighted) rotations; with a weight below 1,
    /// returns the residual of the pose actually written.
    fn write(&mut self, local: &mut Pose, weight: f32) -> Option<f32> {
        for (k, slot) in self.slots.iter().enumerate() {
            let node = &self.nodes[slot.node as usize];
            let solved = (node.q * euler(&self.angles[3 * k..3 * k + 3])).normalize();
            local.rotations[node.joint] = blend(node.q, solved, weight);
        }
        if weight == 1.0 {
            return None;
        }
        for node in self.nodes.iter_mut() {
            node.q = local.rotations[node.joint];
            node.slot = NONE;
        }
        forward(&self.nodes, &[], &mut self.trial_model);
        Some(energy_at(&self.targets, &self.trial_model).sqrt() as f32)
    }
}

/// `E = Σ_b ‖x_b − target_b‖²`, summed in `f64`.
fn energy_at(targets: &[Target], model: &[Xform]) -> f64 {
    targets
        .iter()
        .map(|t| {
            let d = model[t.node as usize].point(t.tip) - t.target;
            let d = d.to_array().map(f64::from);
            d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
        })
        .sum()
}

/// Model transforms of the nodes for the angles `a`.
fn forward(nodes: &[Node], angles: &[f32], model: &mut Vec<Xform>) {
    model.clear();
    for node in nodes {
        let q = if node.slot == NONE {
            node.q
        } else {
            let k = 3 * node.slot as usize;
            node.q * euler(&angles[k..k + 3])
        };
        let parent = if node.parent == NONE { Xform::IDENTITY } else { model[node.parent as usize] };
        model.push(parent.child(node.t, q, node.s));
    }
}

/// Clamps every angle into its limits.
fn project(slots: &[Slot], angles: &mut [f32]) {
    for (slot, a) in slots.iter().zip(angles.chunks_exact_mut(3)) {
        for ((a, min), max) in a.iter_mut().zip(slot.min).zip(slot.max) {
            *a = a.max(min).min(max);
        }
    }
}

/// `Rx(a[0])·Ry(a[1])·Rz(a[2])`, multiplied out.
#[inline]
pub(crate) fn euler(a: &[f32]) -> Quat {
    let (sx, cx) = (0.5 * a[0]).sin_cos();
    let (sy, cy) = (0.5 * a[1]).sin_cos();
    let (sz, cz) = (0.5 * a[2]).sin_cos();
    Quat::from_xyzw(
        cz * cy * sx + cx * sy * sz,
        cz * cx * sy - cy * sx * sz,
        cx * cy * sz + cz * sx * sy,
        cx * cy * cz - sx * sy * sz,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_is_the_product_of_the_three_elementary_rotations() {
        for (a, b, c) in [(0.3, -1.1, 2.0), (-2.9, 0.4, 0.01), (1.0, 1.0, 1.0)] {
            let expected = Quat::from_rotation_x(a) * Quat::from_rotation_y(b) * Quat::from_rotation_z(c);
            let got = euler(&[a, b, c]);
            assert!(got.dot(expected).abs() > 1.0 - 1e-6, "{got:?} vs {expected:?}");
        }
    }
}
