//! Why an IK constraint was refused, and where (a path relative to the
//! constraint list, e.g. `2/effectors/0/target`; the edge prefixes the
//! document's own place, such as `ik`).

use std::fmt;

use crate::Path;

/// A refused constraint: the place and the rule.
#[derive(Debug, Clone, PartialEq)]
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

/// The rules of docs/ik.md a constraint can break.
#[derive(Debug, Clone, PartialEq)]
pub enum IkErrorKind {
    TooManyConstraints { max: usize, provided: usize },
    UnknownJoint { joint: usize, joints: usize },
    NoSuchJoint { joint: String },
    UpNeedsDirection,
    NotDescendant { joint: String, ancestor: String },
    NonFinite,
    WeightOutOfRange { weight: f32 },
    ZeroAxis,
    NoEffectors,
    TooManyEffectors { max: usize, provided: usize },
    DuplicateJoint { joint: String },
    LimitsOutOfOrder { min: f32, max: f32 },
    TooManyIterations { max: u32, provided: u32 },
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

impl fmt::Display for IkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let IkError { path, kind } = self;
        write!(f, "{path}: {kind}")
    }
}

impl std::error::Error for IkError {}

impl fmt::Display for IkErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            IkErrorKind::TooManyConstraints { max, provided } => {
                write!(f, "at most {max} IK constraints, got {provided}")
            }
            IkErrorKind::UnknownJoint { joint, joints } => {
                write!(f, "joint {joint} is not in the skeleton ({joints} joints)")
            }
            IkErrorKind::NoSuchJoint { joint } => write!(f, "joint '{joint}' is not in the skeleton"),
            IkErrorKind::UpNeedsDirection => {
                write!(f, "`up` and `up_direction` go together: the roll is fixed by both or by neither")
            }
            IkErrorKind::NotDescendant { joint, ancestor } => write!(
                f,
                "joint '{joint}' is not a descendant of '{ancestor}': two_bone joints must form a descendant chain"
            ),
            IkErrorKind::NonFinite => write!(f, "value is not a finite number"),
            IkErrorKind::WeightOutOfRange { weight } => write!(f, "a weight must be in [0, 1], got {weight}"),
            IkErrorKind::ZeroAxis => write!(f, "an axis must not be the zero vector"),
            IkErrorKind::NoEffectors => write!(f, "a chain needs at least one effector"),
            IkErrorKind::TooManyEffectors { max, provided } => {
                write!(f, "at most {max} effectors per chain, got {provided}")
            }
            IkErrorKind::DuplicateJoint { joint } => write!(f, "joint '{joint}' is listed twice"),
            IkErrorKind::LimitsOutOfOrder { min, max } => write!(f, "limit min {min} is above max {max}"),
            IkErrorKind::TooManyIterations { max, provided } => {
                write!(f, "max_iterations is at most {max}, got {provided}")
            }
            IkErrorKind::BadTolerance { tolerance } => {
                write!(f, "tolerance must be a finite number ≥ 0, got {tolerance}")
            }
        }
    }
}

impl std::error::Error for IkErrorKind {}
