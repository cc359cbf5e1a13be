//! Why a [`MotionSpec`](super::MotionSpec) was refused, and where (a path
//! relative to the motion, e.g. `layers/2/mask/joints/spine`).

use std::fmt;

use crate::Path;
use crate::character::RetargetError;
use crate::ik::IkErrorKind;
use crate::spring::SpringErrorKind;

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
    /// No joint named and no root joint with a translation track: the
    /// root joints and the joints with translation tracks, the first few
    /// of each, to name one as `root_motion.joint`.
    NoRootJoint {
        roots: Vec<String>,
        translated: Vec<String>,
    },
    /// A layer's clip shares no joint name with the output skeleton (it is
    /// another rig): the first few joints of each, the layer's first.
    IncompatibleSkeleton {
        layer: Vec<String>,
        output: Vec<String>,
    },
    /// An `ik` constraint breaks a rule of docs/ik.md.
    Ik(IkErrorKind),
    /// A layer's clip cannot be retargeted onto the character
    /// (`unmappable_skeleton`: the roles it lacks).
    Retarget(RetargetError),
    ParameterWidthMismatch {
        name: String,
        expected: u32,
        provided: u32,
    },
    /// A spring chain breaks a rule of docs/springs.md.
    Spring(SpringErrorKind),
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
            NoRootJoint { .. } => "no_root_joint",
            IncompatibleSkeleton { .. } => "incompatible_skeleton",
            Ik(kind) => kind.code(),
            Retarget(e) => e.code(),
            ParameterWidthMismatch { .. } => "parameter_width_mismatch",
            Spring(kind) => kind.code(),
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
            MotionErrorKind::NoRootJoint { roots, translated } => {
                write!(f, "no root motion joint: the output skeleton has no root joint with a translation track ")?;
                write!(f, "(root joints: {}); ", listed(roots))?;
                if translated.is_empty() {
                    write!(f, "no joint has a translation track")
                } else {
                    write!(f, "name one of the joints with one as `root_motion.joint`: {}", listed(translated))
                }
            }
            MotionErrorKind::IncompatibleSkeleton { layer, output } => write!(
                f,
                "this layer's clip shares no joint name with the output skeleton (the first layer's clip): \
                 it has {}, the output {}; it is another rig, so nothing of it would play. To play it on \
                 that rig, give the motion a `character` (docs/motion.md, “Characters”)",
                listed(layer),
                listed(output)
            ),
            MotionErrorKind::Ik(v0) => write!(f, "{0}", v0),
            MotionErrorKind::Retarget(e) => write!(f, "this layer's clip cannot play on the character: {e}"),
            MotionErrorKind::ParameterWidthMismatch { name, expected, provided } => write!(
                f,
                "parameter '{name}' has {expected} numbers in the first layer's clip but {provided} in this one"
            ),
            MotionErrorKind::Spring(kind) => write!(f, "{kind}"),
        }
    }
}

impl std::error::Error for MotionErrorKind {}

/// Joint names a detail shows: this many, then how many more.
pub(super) const NAMES_SHOWN: usize = 5;

/// The first [`NAMES_SHOWN`] of `names` (which holds at most that many
/// plus one when there are more), quoted.
pub(super) fn listed(names: &[String]) -> String {
    let shown: Vec<String> = names.iter().take(NAMES_SHOWN).map(|n| format!("'{n}'")).collect();
    match names.len() {
        0 => "none".to_owned(),
        n if n > NAMES_SHOWN => format!("{}, …", shown.join(", ")),
        _ => shown.join(", "),
    }
}
