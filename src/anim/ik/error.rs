//! Why an IK constraint was refused, and where (a path relative to the
//! constraint list, e.g. `2/effectors/0/target`; the edge prefixes the
//! document's own place, such as `ik`).

use crate::anim::Path;

/// A refused constraint: the place and the rule.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {kind}")]
pub struct IkError {
    pub path: Path,
    pub kind: IkErrorKind,
}

impl IkError {
    pub(crate) fn new(path: Path, kind: IkErrorKind) -> Self {
        IkError { path, kind }
    }

    /// The same error placed under `head` (a list index, a document's
    /// `ik` field).
    pub fn under(self, mut head: Path) -> Self {
        head.0.extend(self.path.0);
        IkError { path: head, kind: self.kind }
    }
}

/// The rules of SPEC §7 a constraint can break.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IkErrorKind {
    #[error("at most {max} IK constraints, got {provided}")]
    TooManyConstraints { max: usize, provided: usize },
    #[error("joint {joint} is not in the skeleton ({joints} joints)")]
    UnknownJoint { joint: usize, joints: usize },
    #[error("joint '{joint}' is not in the skeleton")]
    NoSuchJoint { joint: String },
    #[error("`up` and `up_direction` go together: the roll is fixed by both or by neither")]
    UpNeedsDirection,
    #[error("joint '{joint}' is not a descendant of '{ancestor}': two_bone joints must form a descendant chain")]
    NotDescendant { joint: String, ancestor: String },
    #[error("value is not a finite number")]
    NonFinite,
    #[error("a weight must be in [0, 1], got {weight}")]
    WeightOutOfRange { weight: f32 },
    #[error("an axis must not be the zero vector")]
    ZeroAxis,
    #[error("a chain needs at least one effector")]
    NoEffectors,
    #[error("at most {max} effectors per chain, got {provided}")]
    TooManyEffectors { max: usize, provided: usize },
    #[error("joint '{joint}' is listed twice")]
    DuplicateJoint { joint: String },
    #[error("limit min {min} is above max {max}")]
    LimitsOutOfOrder { min: f32, max: f32 },
    #[error("max_iterations is at most {max}, got {provided}")]
    TooManyIterations { max: u32, provided: u32 },
    #[error("tolerance must be a finite number ≥ 0, got {tolerance}")]
    BadTolerance { tolerance: f32 },
}

impl IkErrorKind {
    /// A stable machine-readable code.
    pub fn code(&self) -> &'static str {
        use IkErrorKind::*;
        match self {
            TooManyConstraints { .. } => "too_many_constraints",
            UnknownJoint { .. } | NoSuchJoint { .. } => "unknown_joint",
            UpNeedsDirection => "incomplete_up",
            NotDescendant { .. } => "not_descendant",
            NonFinite => "non_finite",
            WeightOutOfRange { .. } => "weight_out_of_range",
            ZeroAxis => "zero_axis",
            NoEffectors => "no_effectors",
            TooManyEffectors { .. } => "too_many_effectors",
            DuplicateJoint { .. } => "duplicate_joint",
            LimitsOutOfOrder { .. } => "limits_out_of_order",
            TooManyIterations { .. } => "too_many_iterations",
            BadTolerance { .. } => "bad_tolerance",
        }
    }
}
