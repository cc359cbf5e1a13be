//! Why spring chains were refused, and where (a path from the document that
//! carries them: `springs/2/joints/1`).

use std::fmt;

use crate::Path;

/// A refused set of spring chains: the place and the rule.
#[derive(Debug, Clone, PartialEq)]
pub struct SpringError {
    pub path: Path,
    pub kind: SpringErrorKind,
}

impl SpringError {
    pub(crate) fn new(path: Path, kind: SpringErrorKind) -> Self {
        SpringError { path, kind }
    }
}

/// The rules of docs/springs.md a set of chains can break.
#[derive(Debug, Clone, PartialEq)]
pub enum SpringErrorKind {
    NonFinite,
    SubstepHzOutOfRange {
        hz: f64,
    },
    TooManyChains {
        max: usize,
        provided: usize,
    },
    TooManyColliders {
        max: usize,
        provided: usize,
    },
    DuplicateName {
        name: String,
    },
    /// A chain needs a joint that turns and its tail.
    TooShort {
        joints: usize,
    },
    UnknownJoint {
        joint: String,
    },
    /// `joints[i + 1]` is not below `joints[i]`.
    NotAChain {
        joint: String,
        after: String,
    },
    /// A joint turns in two chains.
    JointInTwoChains {
        joint: String,
    },
    /// A bone whose tail sits on its joint at rest has no direction.
    ZeroLength {
        joint: String,
    },
    StiffnessOutOfRange {
        stiffness: f32,
    },
    DragOutOfRange {
        drag: f32,
    },
    RadiusOutOfRange {
        radius: f32,
    },
    /// `joint_params` names a joint that does not turn in the chain.
    NotASpringJoint {
        joint: String,
    },
    /// A collider rides on a joint that springs move.
    ColliderOnSpring {
        joint: String,
    },
}

impl SpringErrorKind {
    /// A stable machine-readable code.
    pub fn code(&self) -> &'static str {
        use SpringErrorKind::*;
        match self {
            NonFinite => "non_finite",
            SubstepHzOutOfRange { .. } => "substep_hz_out_of_range",
            TooManyChains { .. } => "too_many_springs",
            TooManyColliders { .. } => "too_many_colliders",
            DuplicateName { .. } => "duplicate_spring",
            TooShort { .. } => "spring_too_short",
            UnknownJoint { .. } => "unknown_joint",
            NotAChain { .. } => "not_a_chain",
            JointInTwoChains { .. } => "joint_in_two_springs",
            ZeroLength { .. } => "zero_length_bone",
            StiffnessOutOfRange { .. } => "stiffness_out_of_range",
            DragOutOfRange { .. } => "drag_out_of_range",
            RadiusOutOfRange { .. } => "radius_out_of_range",
            NotASpringJoint { .. } => "not_a_spring_joint",
            ColliderOnSpring { .. } => "collider_on_spring",
        }
    }
}

impl fmt::Display for SpringError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.kind)
    }
}

impl std::error::Error for SpringError {}

impl fmt::Display for SpringErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use SpringErrorKind::*;
        match self {
            NonFinite => write!(f, "value is not a finite number"),
            SubstepHzOutOfRange { hz } => {
                let range = super::spec::SUBSTEP_HZ_RANGE;
                write!(f, "spring_substep_hz must be within {} to {}, got {hz}", range.start(), range.end())
            }
            TooManyChains { max, provided } => write!(f, "at most {max} spring chains, got {provided}"),
            TooManyColliders { max, provided } => {
                write!(f, "a spring chain has at most {max} colliders, got {provided}")
            }
            DuplicateName { name } => write!(f, "spring chain '{name}' is named twice"),
            TooShort { joints } => {
                write!(f, "a spring chain needs at least 2 joints (a joint and its tail), got {joints}")
            }
            UnknownJoint { joint } => write!(f, "joint '{joint}' is not in the skeleton"),
            NotAChain { joint, after } => {
                write!(f, "joint '{joint}' is not a descendant of '{after}', the joint before it")
            }
            JointInTwoChains { joint } => write!(f, "joint '{joint}' turns in two spring chains"),
            ZeroLength { joint } => write!(f, "joint '{joint}' and its tail are at the same place in the rest pose"),
            StiffnessOutOfRange { stiffness } => write!(f, "stiffness must be at least 0, got {stiffness}"),
            DragOutOfRange { drag } => write!(f, "drag must be in [0, 1], got {drag}"),
            RadiusOutOfRange { radius } => write!(f, "a radius must be at least 0, got {radius}"),
            NotASpringJoint { joint } => {
                write!(f, "joint '{joint}' does not turn in this chain (its last joint only marks a tail)")
            }
            ColliderOnSpring { joint } => {
                write!(
                    f,
                    "joint '{joint}' carries a collider but is moved by a spring chain (a collider rides on the animated body)"
                )
            }
        }
    }
}
