//! Spring chains as authored (docs/springs.md): joint names, parameters and
//! colliders, unchecked. [`Springs::build`](super::Springs::build) checks
//! them against a skeleton.

use glam::Vec3;

/// The substep rate when a document names none (`spring_substep_hz`).
pub const DEFAULT_SUBSTEP_HZ: f64 = 120.0;
/// The substep rates accepted: below 30 Hz a fast swing tunnels through its
/// colliders; above 1000 Hz the work buys nothing visible.
pub const SUBSTEP_HZ_RANGE: std::ops::RangeInclusive<f64> = 30.0..=1000.0;
/// Chains of one document at most.
pub const MAX_CHAINS: usize = 256;
/// Colliders of one chain at most (each is tested by each of its joints at
/// each substep).
pub const MAX_COLLIDERS: usize = 64;
/// How long a stateless pose or samples request simulates before its first
/// time, by default (docs/springs.md, “Time”).
pub const DEFAULT_WARMUP: f64 = 1.0;

/// Every spring chain of a motion or clip, and the substep rate.
#[derive(Debug, Clone, PartialEq)]
pub struct SpringsSpec {
    pub chains: Vec<ChainSpec>,
    /// Substeps per second of the clock the simulation runs on.
    pub substep_hz: f64,
}

impl Default for SpringsSpec {
    fn default() -> Self {
        SpringsSpec { chains: Vec::new(), substep_hz: DEFAULT_SUBSTEP_HZ }
    }
}

/// One chain: `joints[i]` turns so that its tail, `joints[i + 1]`, swings;
/// the last joint only marks the tail of the one before.
#[derive(Debug, Clone, PartialEq)]
pub struct ChainSpec {
    pub name: String,
    /// First to last, each a descendant of the one before.
    pub joints: Vec<String>,
    /// The chain's parameters, for every joint without its own.
    pub params: SpringParams,
    /// Per-joint overrides, by the name of a joint that turns.
    pub joint_params: Vec<(String, JointParams)>,
    /// Tested in order by every joint of the chain.
    pub colliders: Vec<ColliderSpec>,
}

impl ChainSpec {
    /// A chain of `joints` with the default parameters and no colliders.
    pub fn new(name: &str, joints: &[&str]) -> Self {
        ChainSpec {
            name: name.to_owned(),
            joints: joints.iter().map(|&j| j.to_owned()).collect(),
            params: SpringParams::default(),
            joint_params: Vec::new(),
            colliders: Vec::new(),
        }
    }
}

/// How one joint's tail moves (docs/springs.md, “Integration”).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpringParams {
    /// Pull back toward the rest direction, per second; `≥ 0`.
    pub stiffness: f32,
    /// The share of the last substep's motion lost, in `[0, 1]`.
    pub drag: f32,
    /// An acceleration in model space, m/s².
    pub gravity: Vec3,
    /// The tail's radius against colliders, m; `≥ 0`.
    pub radius: f32,
}

impl Default for SpringParams {
    fn default() -> Self {
        SpringParams { stiffness: 1.0, drag: 0.4, gravity: Vec3::ZERO, radius: 0.02 }
    }
}

/// A joint's own parameters: each given one replaces the chain's.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct JointParams {
    pub stiffness: Option<f32>,
    pub drag: Option<f32>,
    pub gravity: Option<Vec3>,
    pub radius: Option<f32>,
}

impl JointParams {
    /// `base` with these overrides.
    pub fn over(&self, base: SpringParams) -> SpringParams {
        SpringParams {
            stiffness: self.stiffness.unwrap_or(base.stiffness),
            drag: self.drag.unwrap_or(base.drag),
            gravity: self.gravity.unwrap_or(base.gravity),
            radius: self.radius.unwrap_or(base.radius),
        }
    }
}

/// A shape fixed to a joint that tails are pushed out of.
#[derive(Debug, Clone, PartialEq)]
pub struct ColliderSpec {
    pub joint: String,
    pub shape: ColliderShape,
}

/// Offsets are in the joint's local frame (its scale applies); radii are
/// in model space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ColliderShape {
    Sphere {
        offset: Vec3,
        radius: f32,
    },
    /// The points within `radius` of the segment from `offset` to `tail`.
    Capsule {
        offset: Vec3,
        tail: Vec3,
        radius: f32,
    },
}
