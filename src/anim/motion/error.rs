//! Why a [`MotionSpec`](super::MotionSpec) was refused, and where (a path
//! relative to the motion, e.g. `layers/2/mask/joints/spine`).

use crate::anim::Path;
use crate::anim::ik::IkErrorKind;

/// A refused motion: the place and the rule.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{kind}")]
pub struct MotionError {
    pub path: Path,
    pub kind: MotionErrorKind,
}

impl MotionError {
    pub(crate) fn new(path: Path, kind: MotionErrorKind) -> Self {
        MotionError { path, kind }
    }
}

/// The rules of SPEC §6 a motion can break.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MotionErrorKind {
    #[error("a motion needs at least one layer")]
    NoLayers,
    #[error("a motion has at most {max} layers, got {provided}")]
    TooManyLayers { max: usize, provided: usize },
    #[error("a weight must be in [0, 1], got {weight}")]
    WeightOutOfRange { weight: f32 },
    #[error("value is not a finite number")]
    NonFinite,
    #[error("speed must be within ±{max}, got {speed}")]
    SpeedOutOfRange { speed: f64, max: f64 },
    #[error("joint '{joint}' is not in the output skeleton (the first layer's clip)")]
    UnknownJoint { joint: String },
    #[error("joint '{joint}' is named twice in the mask")]
    DuplicateMaskJoint { joint: String },
    #[error("no root motion joint: the output skeleton has no root joint with a translation track")]
    NoRootJoint,
    /// An `ik` constraint breaks a rule of SPEC §7.
    #[error("{0}")]
    Ik(IkErrorKind),
    #[error("parameter '{name}' has {expected} numbers in the first layer's clip but {provided} in this one")]
    ParameterWidthMismatch { name: String, expected: u32, provided: u32 },
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
