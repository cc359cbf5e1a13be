//! The constraints of docs/ik.md as the core takes them (joints by index,
//! targets in model space), and the checks that make them safe to solve.
//!
//! Wire formats resolve joint names to indices and fill the documented
//! defaults (`forward` `[0, 0, 1]`, `weight` 1, `max_iterations` 100) before
//! they get here; [`IkConstraint::validate`] then enforces the rest of the
//! rules once, so a solve never meets a bad joint or a non-finite number.

use glam::Vec3A;

use super::error::{IkError, IkErrorKind as K};
use crate::{Path, Skeleton};

/// The documented default iteration budget of a chain solve.
pub const DEFAULT_MAX_ITERATIONS: u32 = 100;

/// One IK constraint; a list of them applies in order.
#[derive(Debug, Clone, PartialEq)]
pub enum IkConstraint {
    TwoBone(TwoBone),
    Aim(Aim),
    Chain(Chain),
}

/// Which solver a constraint (and its report) belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum IkKind {
    TwoBone,
    Aim,
    Chain,
}

impl IkKind {
    /// The documented name of the kind (`two_bone`, `aim`, `chain`).
    pub fn name(self) -> &'static str {
        match self {
            IkKind::TwoBone => "two_bone",
            IkKind::Aim => "aim",
            IkKind::Chain => "chain",
        }
    }
}

/// Analytic two-bone IK (arms, legs): `joints` are `[upper, middle, end]`,
/// each a descendant of the one before; only `upper` and `middle` rotate.
#[derive(Debug, Clone, PartialEq)]
pub struct TwoBone {
    pub joints: [usize; 3],
    pub target: Vec3A,
    /// A model-space point the middle joint bends toward.
    pub pole: Option<Vec3A>,
    pub weight: f32,
}

impl TwoBone {
    /// Full weight, no pole.
    pub fn new(joints: [usize; 3], target: Vec3A) -> Self {
        TwoBone { joints, target, pole: None, weight: 1.0 }
    }
}

/// Turns one joint so its local `forward` axis points at `target`.
#[derive(Debug, Clone, PartialEq)]
pub struct Aim {
    pub joint: usize,
    pub target: Vec3A,
    /// Joint-local; need not be unit length, must not be zero.
    pub forward: Vec3A,
    /// A joint-local axis whose roll `up_direction` fixes (both or neither).
    pub up: Option<Vec3A>,
    /// A model-space direction.
    pub up_direction: Option<Vec3A>,
    pub weight: f32,
}

impl Aim {
    /// Forward `+z`, no roll constraint, full weight.
    pub fn new(joint: usize, target: Vec3A) -> Self {
        Aim { joint, target, forward: Vec3A::Z, up: None, up_direction: None, weight: 1.0 }
    }
}

/// Seed 003's solver: several effectors, three angles per movable joint.
#[derive(Debug, Clone, PartialEq)]
pub struct Chain {
    pub effectors: Vec<Effector>,
    /// The movable joints; `None` means every ancestor of an effector, plus
    /// each effector whose `tip` is not the origin.
    pub joints: Option<Vec<usize>>,
    /// Per-joint angle limits; joints not listed are unbounded.
    pub limits: Vec<JointLimits>,
    pub max_iterations: u32,
    /// `None` means `1e-4` times the chain's length.
    pub tolerance: Option<f32>,
    pub weight: f32,
}

impl Chain {
    /// Default joints, no limits, the default budget and tolerance, full weight.
    pub fn new(effectors: Vec<Effector>) -> Self {
        Chain {
            effectors,
            joints: None,
            limits: Vec::new(),
            max_iterations: DEFAULT_MAX_ITERATIONS,
            tolerance: None,
            weight: 1.0,
        }
    }
}

/// A point fixed in `joint`'s local frame (`tip`, the seed's `d̂_b`) that
/// should reach `target`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Effector {
    pub joint: usize,
    pub target: Vec3A,
    pub tip: Vec3A,
}

/// Bounds of a joint's three angles (`Rx`, `Ry`, `Rz`), in radians.
/// Infinite bounds are allowed and mean unbounded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    pub joint: usize,
    pub min: [f32; 3],
    pub max: [f32; 3],
}

/// The service's configurable ceilings (docs/ik.md, “Errors”).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IkLimits {
    pub max_constraints: usize,
    pub max_iterations: u32,
    pub max_effectors: usize,
}

impl Default for IkLimits {
    fn default() -> Self {
        IkLimits { max_constraints: 32, max_iterations: 1000, max_effectors: 16 }
    }
}

/// Checks a whole list: its length, then each constraint under its index.
///
/// # Errors
/// The first rule broken, with its path (`2/joints/1`).
pub fn validate_constraints(
    constraints: &[IkConstraint],
    skeleton: &Skeleton,
    limits: &IkLimits,
) -> Result<(), IkError> {
    if constraints.len() > limits.max_constraints {
        let kind = K::TooManyConstraints { max: limits.max_constraints, provided: constraints.len() };
        return Err(IkError::new(Path::root(), kind));
    }
    for (i, c) in constraints.iter().enumerate() {
        c.validate(skeleton, limits).map_err(|e| e.under(Path::root().index(i)))?;
    }
    Ok(())
}

impl IkConstraint {
    /// Bytes a chain's lists hold on the heap (the others hold none).
    pub fn heap_bytes(&self) -> usize {
        match self {
            IkConstraint::Chain(c) => {
                crate::heap::vec_bytes(&c.effectors)
                    + c.joints.as_ref().map_or(0, crate::heap::vec_bytes)
                    + crate::heap::vec_bytes(&c.limits)
            }
            IkConstraint::TwoBone(_) | IkConstraint::Aim(_) => 0,
        }
    }

    /// Which solver takes it.
    pub fn kind(&self) -> IkKind {
        match self {
            IkConstraint::TwoBone(_) => IkKind::TwoBone,
            IkConstraint::Aim(_) => IkKind::Aim,
            IkConstraint::Chain(_) => IkKind::Chain,
        }
    }

    /// Moves target `slot` (0 for `two_bone` and `aim`, the effector's
    /// index for `chain`): how keyed targets and live drags change a
    /// constraint without rebuilding it. Out-of-range slots are ignored.
    pub fn set_target(&mut self, slot: usize, target: Vec3A) {
        match self {
            IkConstraint::TwoBone(c) if slot == 0 => c.target = target,
            IkConstraint::Aim(c) if slot == 0 => c.target = target,
            IkConstraint::Chain(c) => {
                if let Some(e) = c.effectors.get_mut(slot) {
                    e.target = target;
                }
            }
            _ => {}
        }
    }

    /// How much of the solve applies, in `[0, 1]`.
    pub fn weight(&self) -> f32 {
        match self {
            IkConstraint::TwoBone(c) => c.weight,
            IkConstraint::Aim(c) => c.weight,
            IkConstraint::Chain(c) => c.weight,
        }
    }

    /// Sets the weight (see [`IkConstraint::weight`]).
    pub fn set_weight(&mut self, weight: f32) {
        match self {
            IkConstraint::TwoBone(c) => c.weight = weight,
            IkConstraint::Aim(c) => c.weight = weight,
            IkConstraint::Chain(c) => c.weight = weight,
        }
    }

    /// Checks the rules of docs/ik.md against `skeleton`: joints exist, a
    /// `two_bone`'s joints form a descendant chain, every number is finite,
    /// weights lie in [0, 1], axes are not zero, limits are ordered, and
    /// the budgets stay under `limits`.
    ///
    /// # Errors
    /// The first rule broken, with its path relative to the constraint.
    pub fn validate(&self, skeleton: &Skeleton, limits: &IkLimits) -> Result<(), IkError> {
        match self {
            IkConstraint::TwoBone(c) => validate_two_bone(c, skeleton),
            IkConstraint::Aim(c) => validate_aim(c, skeleton),
            IkConstraint::Chain(c) => validate_chain(c, skeleton, limits),
        }
    }
}

fn validate_two_bone(c: &TwoBone, skeleton: &Skeleton) -> Result<(), IkError> {
    for (i, &j) in c.joints.iter().enumerate() {
        joint_exists(j, skeleton, Path::root().field("joints").index(i))?;
    }
    for i in 1..3 {
        let (ancestor, joint) = (c.joints[i - 1], c.joints[i]);
        if !is_strict_descendant(skeleton, joint, ancestor) {
            let names = skeleton.names();
            let kind = K::NotDescendant { joint: names[joint].clone(), ancestor: names[ancestor].clone() };
            return Err(IkError::new(Path::root().field("joints").index(i), kind));
        }
    }
    finite(c.target, Path::root().field("target"))?;
    if let Some(pole) = c.pole {
        finite(pole, Path::root().field("pole"))?;
    }
    weight(c.weight)
}

fn validate_aim(c: &Aim, skeleton: &Skeleton) -> Result<(), IkError> {
    joint_exists(c.joint, skeleton, Path::root().field("joint"))?;
    finite(c.target, Path::root().field("target"))?;
    axis(c.forward, "forward")?;
    if let Some(up) = c.up {
        axis(up, "up")?;
    }
    if let Some(direction) = c.up_direction {
        axis(direction, "up_direction")?;
    }
    weight(c.weight)
}

fn validate_chain(c: &Chain, skeleton: &Skeleton, limits: &IkLimits) -> Result<(), IkError> {
    let effectors = Path::root().field("effectors");
    if c.effectors.is_empty() {
        return Err(IkError::new(effectors, K::NoEffectors));
    }
    if c.effectors.len() > limits.max_effectors {
        let kind = K::TooManyEffectors { max: limits.max_effectors, provided: c.effectors.len() };
        return Err(IkError::new(effectors, kind));
    }
    for (i, e) in c.effectors.iter().enumerate() {
        let at = effectors.clone().index(i);
        joint_exists(e.joint, skeleton, at.clone().field("joint"))?;
        finite(e.target, at.clone().field("target"))?;
        finite(e.tip, at.field("tip"))?;
    }
    if let Some(joints) = &c.joints {
        distinct_joints(joints, skeleton)?;
    }
    let mut limited = vec![false; skeleton.len()];
    for l in &c.limits {
        joint_limits(l, skeleton, &mut limited)?;
    }
    if c.max_iterations > limits.max_iterations {
        let kind = K::TooManyIterations { max: limits.max_iterations, provided: c.max_iterations };
        return Err(IkError::new(Path::root().field("max_iterations"), kind));
    }
    if let Some(tolerance) = c.tolerance
        && !(tolerance.is_finite() && tolerance >= 0.0)
    {
        return Err(IkError::new(Path::root().field("tolerance"), K::BadTolerance { tolerance }));
    }
    weight(c.weight)
}

fn distinct_joints(joints: &[usize], skeleton: &Skeleton) -> Result<(), IkError> {
    let mut seen = vec![false; skeleton.len()];
    for (i, &j) in joints.iter().enumerate() {
        let at = Path::root().field("joints").index(i);
        joint_exists(j, skeleton, at.clone())?;
        if std::mem::replace(&mut seen[j], true) {
            return Err(IkError::new(at, K::DuplicateJoint { joint: skeleton.names()[j].clone() }));
        }
    }
    Ok(())
}

/// A limit's path is keyed by joint name, as the wire's `limits` object is.
fn joint_limits(l: &JointLimits, skeleton: &Skeleton, limited: &mut [bool]) -> Result<(), IkError> {
    let limits = Path::root().field("limits");
    joint_exists(l.joint, skeleton, limits.clone().key(&l.joint.to_string()))?;
    let name = &skeleton.names()[l.joint];
    let at = limits.key(name);
    if std::mem::replace(&mut limited[l.joint], true) {
        return Err(IkError::new(at, K::DuplicateJoint { joint: name.clone() }));
    }
    for axis in 0..3 {
        let (min, max) = (l.min[axis], l.max[axis]);
        let (min_at, max_at) = (at.clone().field("min").index(axis), at.clone().field("max").index(axis));
        // Infinite bounds mean unbounded, but not a bound that excludes everything.
        if min.is_nan() || min == f32::INFINITY {
            return Err(IkError::new(min_at, K::NonFinite));
        }
        if max.is_nan() || max == f32::NEG_INFINITY {
            return Err(IkError::new(max_at, K::NonFinite));
        }
        if min > max {
            return Err(IkError::new(min_at, K::LimitsOutOfOrder { min, max }));
        }
    }
    Ok(())
}

fn joint_exists(joint: usize, skeleton: &Skeleton, at: Path) -> Result<(), IkError> {
    if joint < skeleton.len() {
        Ok(())
    } else {
        Err(IkError::new(at, K::UnknownJoint { joint, joints: skeleton.len() }))
    }
}

/// Whether `ancestor` is a proper ancestor of `joint`.
pub(crate) fn is_strict_descendant(skeleton: &Skeleton, joint: usize, ancestor: usize) -> bool {
    let mut j = joint;
    while let Some(p) = skeleton.parent(j) {
        if p == ancestor {
            return true;
        }
        j = p;
    }
    false
}

fn finite(v: Vec3A, at: Path) -> Result<(), IkError> {
    match v.to_array().iter().position(|x| !x.is_finite()) {
        Some(i) => Err(IkError::new(at.index(i), K::NonFinite)),
        None => Ok(()),
    }
}

fn axis(v: Vec3A, field: &'static str) -> Result<(), IkError> {
    finite(v, Path::root().field(field))?;
    if v == Vec3A::ZERO {
        return Err(IkError::new(Path::root().field(field), K::ZeroAxis));
    }
    Ok(())
}

fn weight(weight: f32) -> Result<(), IkError> {
    if (0.0..=1.0).contains(&weight) {
        Ok(())
    } else {
        Err(IkError::new(Path::root().field("weight"), K::WeightOutOfRange { weight }))
    }
}
