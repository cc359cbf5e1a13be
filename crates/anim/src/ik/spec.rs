//! IK constraints as authored (docs/ik.md): joints by name, documented defaults
//! still unfilled. [`IkSpec::resolve`] maps names onto a skeleton and fills
//! the defaults; [`build_constraints`] then validates the whole list, so
//! every wire format and the clip and motion builders share one way in.

use glam::{Vec3, Vec3A};

use super::constraint::{Aim, Chain, DEFAULT_MAX_ITERATIONS, Effector, IkConstraint, IkLimits, JointLimits, TwoBone};
use super::error::{IkError, IkErrorKind as K};
use super::validate_constraints;
use crate::{Path, Skeleton};

/// One constraint as a request or a clip names it.
#[derive(Debug, Clone, PartialEq)]
pub enum IkSpec {
    TwoBone(TwoBoneSpec),
    Aim(AimSpec),
    Chain(ChainSpec),
}

#[derive(Debug, Clone, PartialEq)]
pub struct TwoBoneSpec {
    /// `[upper, middle, end]`.
    pub joints: [String; 3],
    pub target: Vec3,
    pub pole: Option<Vec3>,
    /// `None`: 1.
    pub weight: Option<f32>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct AimSpec {
    pub joint: String,
    pub target: Vec3,
    /// `None`: `[0, 0, 1]`.
    pub forward: Option<Vec3>,
    pub up: Option<Vec3>,
    pub up_direction: Option<Vec3>,
    pub weight: Option<f32>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ChainSpec {
    pub effectors: Vec<EffectorSpec>,
    /// `None`: every ancestor of an effector (and the effector itself when
    /// its tip is not the origin).
    pub joints: Option<Vec<String>>,
    pub limits: Vec<LimitSpec>,
    pub max_iterations: Option<u32>,
    pub tolerance: Option<f32>,
    pub weight: Option<f32>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct EffectorSpec {
    pub joint: String,
    pub target: Vec3,
    /// `None`: the joint's origin.
    pub tip: Option<Vec3>,
}

/// Angle bounds of one joint (`Rx`, `Ry`, `Rz`), in radians.
#[derive(Debug, Clone, PartialEq)]
pub struct LimitSpec {
    pub joint: String,
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl IkSpec {
    /// The documented name of this constraint's kind.
    pub fn kind_name(&self) -> &'static str {
        match self {
            IkSpec::TwoBone(_) => "two_bone",
            IkSpec::Aim(_) => "aim",
            IkSpec::Chain(_) => "chain",
        }
    }

    /// How many targets the constraint has: one, or one per effector (the
    /// order [`IkConstraint::set_target`] numbers them in).
    pub fn target_count(&self) -> usize {
        match self {
            IkSpec::Chain(c) => c.effectors.len(),
            _ => 1,
        }
    }

    /// Moves target `slot` (0, or an effector's index).
    pub fn set_target(&mut self, slot: usize, target: Vec3) {
        match self {
            IkSpec::TwoBone(c) if slot == 0 => c.target = target,
            IkSpec::Aim(c) if slot == 0 => c.target = target,
            IkSpec::Chain(c) => {
                if let Some(e) = c.effectors.get_mut(slot) {
                    e.target = target;
                }
            }
            _ => {}
        }
    }

    /// Maps joint names onto `skeleton` and fills the documented defaults.
    ///
    /// # Errors
    /// An unknown joint name, or an `up` without `up_direction` (or the
    /// reverse), with its path relative to the constraint.
    pub fn resolve(&self, skeleton: &Skeleton) -> Result<IkConstraint, IkError> {
        let joint = |name: &str, at: Path| {
            skeleton.index_of(name).ok_or_else(|| IkError::new(at, K::NoSuchJoint { joint: name.to_owned() }))
        };
        Ok(match self {
            IkSpec::TwoBone(c) => {
                let at = |i: usize| Path::root().field("joints").index(i);
                let joints = [joint(&c.joints[0], at(0))?, joint(&c.joints[1], at(1))?, joint(&c.joints[2], at(2))?];
                IkConstraint::TwoBone(TwoBone {
                    joints,
                    target: c.target.into(),
                    pole: c.pole.map(Vec3A::from),
                    weight: c.weight.unwrap_or(1.0),
                })
            }
            IkSpec::Aim(c) => {
                if c.up.is_some() != c.up_direction.is_some() {
                    let field = if c.up.is_some() { "up_direction" } else { "up" };
                    return Err(IkError::new(Path::root().field(field), K::UpNeedsDirection));
                }
                IkConstraint::Aim(Aim {
                    joint: joint(&c.joint, Path::root().field("joint"))?,
                    target: c.target.into(),
                    forward: c.forward.map_or(Vec3A::Z, Vec3A::from),
                    up: c.up.map(Vec3A::from),
                    up_direction: c.up_direction.map(Vec3A::from),
                    weight: c.weight.unwrap_or(1.0),
                })
            }
            IkSpec::Chain(c) => IkConstraint::Chain(resolve_chain(c, &joint)?),
        })
    }
}

fn resolve_chain(c: &ChainSpec, joint: &impl Fn(&str, Path) -> Result<usize, IkError>) -> Result<Chain, IkError> {
    let mut effectors = Vec::with_capacity(c.effectors.len());
    for (i, e) in c.effectors.iter().enumerate() {
        let at = Path::root().field("effectors").index(i).field("joint");
        let tip = e.tip.map_or(Vec3A::ZERO, Vec3A::from);
        effectors.push(Effector { joint: joint(&e.joint, at)?, target: e.target.into(), tip });
    }
    let joints = match &c.joints {
        None => None,
        Some(names) => Some(
            names
                .iter()
                .enumerate()
                .map(|(i, name)| joint(name, Path::root().field("joints").index(i)))
                .collect::<Result<Vec<_>, _>>()?,
        ),
    };
    let mut limits = Vec::with_capacity(c.limits.len());
    for l in &c.limits {
        let at = Path::root().field("limits").key(&l.joint);
        limits.push(JointLimits { joint: joint(&l.joint, at)?, min: l.min, max: l.max });
    }
    Ok(Chain {
        effectors,
        joints,
        limits,
        max_iterations: c.max_iterations.unwrap_or(DEFAULT_MAX_ITERATIONS),
        tolerance: c.tolerance,
        weight: c.weight.unwrap_or(1.0),
    })
}

/// Resolves and validates a list against `skeleton` (the rules of docs/ik.md and
/// the service's `limits`).
///
/// # Errors
/// The first rule broken, with its path relative to the list (`1/joints/2`).
pub fn build_constraints(
    specs: &[IkSpec],
    skeleton: &Skeleton,
    limits: &IkLimits,
) -> Result<Vec<IkConstraint>, IkError> {
    if specs.len() > limits.max_constraints {
        let kind = K::TooManyConstraints { max: limits.max_constraints, provided: specs.len() };
        return Err(IkError::new(Path::root(), kind));
    }
    let constraints = specs
        .iter()
        .enumerate()
        .map(|(i, s)| s.resolve(skeleton).map_err(|e| e.under(Path::root().index(i))))
        .collect::<Result<Vec<_>, _>>()?;
    validate_constraints(&constraints, skeleton, limits)?;
    Ok(constraints)
}
