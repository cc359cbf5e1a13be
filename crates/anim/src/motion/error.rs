//! Why a [`MotionSpec`](super::MotionSpec) was refused, and where (a path
//! relative to the motion, e.g. `layers/2/mask/joints/spine`).

use std::fmt;

use crate::Path;
use crate::ik::IkErrorKind;

/// A refused motion: the place and the rule.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionError {
    pub path: Path,
    pub kind: MotionErrorKind,
}

impl MotionError {
    pub(crate) fn new(path: Path, kind: MotionErrorKind) -> Self {
        MotionError { path, kind }
    }
}

/// The rules of docs/motion.md a motion can break.
#[derive(Debug, Clone, PartialEq)]
pub enum MotionErrorKind {
    NoLayers,
    TooManyLayers {
        max: usize,
        provided: usize,
    },
    WeightOutOfRange {
        weight: f32,
    },
    NonFinite,
    SpeedOutOfRange {
        speed: f64,
        max: f64,
    },
    UnknownJoint {
        joint: String,
    },
    DuplicateMaskJoint {
        joint: String,
    },
    NoRootJoint,
    /// An `ik` constraint breaks a rule of docs/ik.md.
    Ik(IkErrorKind),
    ParameterWidthMismatch {
        name: String,
        expected: u32,
        provided: u32,
    },
}

impl MotionErrorKind {
    /// A stable machine-readable code.
    pub fn code(&self) -> &'static str {
        use MotionErrorKind::*;
        match self {
            NoLayers => "no_layers",
            TooManyLayers { .. } => "too_many_layers",
            WeightOutOfRange { .. } => "weight_out_of_range",
            NonFinite => "non_finite",
            SpeedOutOfRange { .. } => "speed_out_of_range",
            UnknownJoint { .. } => "unknown_joint",
            DuplicateMaskJoint { .. } => "duplicate_mask_joint",
            NoRootJoint => "no_root_joint",
            Ik(kind) => kind.code(),
            ParameterWidthMismatch { .. } => "parameter_width_mismatch",
        }
    }
}

impl fmt::Display for MotionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let MotionError { kind, .. } = self;
        write!(f, "{kind}")
    }
}

impl std::error::Error for MotionError {}

impl fmt::Display for MotionErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MotionErrorKind::NoLayers => write!(f, "a motion needs at least one layer"),
            MotionErrorKind::TooManyLayers { max, provided } => {
                write!(f, "a motion has at most {max} layers, got {provided}")
            }
            MotionErrorKind::WeightOutOfRange { weight } => write!(f, "a weight must be in [0, 1], got {weight}"),
            MotionErrorKind::NonFinite => write!(f, "value is not a finite number"),
            MotionErrorKind::SpeedOutOfRange { speed, max } => write!(f, "speed must be within ±{max}, got {speed}"),
            MotionErrorKind::UnknownJoint { joint } => {
                write!(f, "joint '{joint}' is not in the output skeleton (the first layer's clip)")
            }
            MotionErrorKind::DuplicateMaskJoint { joint } => write!(f, "joint '{joint}' is named twice in the mask"),
            MotionErrorKind::NoRootJoint => {
                write!(f, "no root motion joint: the output skeleton has no root joint with a translation track")
            }
            MotionErrorKind::Ik(v0) => write!(f, "{0}", v0),
            MotionErrorKind::ParameterWidthMismatch { name, expected, provided } => write!(
                f,
                "parameter '{name}' has {expected} numbers in the first layer's clip but {provided} in this one"
            ),
        }
    }
}

impl std::error::Error for MotionErrorKind {}
