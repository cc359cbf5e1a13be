//! Why a [`ClipSpec`](super::ClipSpec) was refused, and where.
//!
//! Every error names the offending place as a path of field names and
//! indices that mirrors the clip document (`tracks`, 3, `times`, 5), so the edge can
//! render a JSON pointer (`/tracks/3/times/5`) without the core knowing JSON.

use std::fmt;

use super::ik::IkErrorKind;
use super::path::Path;

/// A clip that cannot be built: what is wrong ([`ClipErrorKind`]) and where.
#[derive(Debug, Clone, PartialEq)]
pub struct ClipError {
    pub path: Path,
    pub kind: ClipErrorKind,
}

impl ClipError {
    /// A refusal of the field at `path`.
    pub fn new(path: Path, kind: ClipErrorKind) -> Self {
        ClipError { path, kind }
    }
}

/// Each rule `Clip::build` enforces. `code()` is stable for clients.
#[derive(Debug, Clone, PartialEq)]
pub enum ClipErrorKind {
    BadName {
        max: usize,
    },
    NoTracks,
    EmptyJointName,
    /// Every answer repeats joint names, so their length is part of its cost.
    JointNameTooLong {
        max: usize,
        chars: usize,
    },
    DuplicateJoint {
        name: String,
    },
    UnknownParent {
        parent: String,
    },
    ParentCycle {
        joint: String,
    },
    ParentAfterChild {
        parent: String,
    },
    UnknownJoint {
        joint: String,
    },
    DuplicateTrack {
        joint: String,
        channel: &'static str,
    },
    NoKeys,
    LengthMismatch {
        expected: usize,
        provided: usize,
    },
    TimesNotIncreasing {
        previous: f32,
        current: f32,
    },
    NonFinite,
    WrongWidth {
        channel: &'static str,
        expected: usize,
        provided: usize,
    },
    ZeroQuaternion {
        norm: f32,
    },
    TensionOutOfRange {
        tension: f32,
    },
    /// `ends` outside `catmull_rom` and `b_spline`, `tension` outside
    /// `catmull_rom` (the code predates `b_spline` and stays stable).
    OnlyCatmullRom {
        field: &'static str,
        modes: &'static str,
    },
    OnlyHermite {
        field: &'static str,
    },
    MissingTangents,
    WrapEndsDiffer,
    PhantomTooFewKeys {
        provided: usize,
    },
    SpeedNotApplicable,
    TimeRangeTooLarge {
        start: f32,
        end: f32,
    },
    ModelSpaceOverflow {
        bound: f64,
        limit: f64,
    },
    CurveOverflow,
    BuildBudgetExceeded {
        limit: u64,
        spent: u64,
    },
    BuildCancelled,
    /// An `ik` constraint breaks a rule of docs/ik.md.
    Ik(IkErrorKind),
    BadParameterName {
        max: usize,
    },
    DuplicateParameter {
        name: String,
    },
    ParameterWidth {
        max: usize,
        provided: usize,
    },
}

impl ClipErrorKind {
    /// A stable machine-readable code.
    pub fn code(&self) -> &'static str {
        use ClipErrorKind::*;
        match self {
            BadName { .. } => "bad_name",
            NoTracks => "no_tracks",
            EmptyJointName => "empty_joint_name",
            JointNameTooLong { .. } => "joint_name_too_long",
            DuplicateJoint { .. } => "duplicate_joint",
            UnknownParent { .. } => "unknown_parent",
            ParentCycle { .. } => "parent_cycle",
            ParentAfterChild { .. } => "parent_after_child",
            UnknownJoint { .. } => "unknown_joint",
            DuplicateTrack { .. } => "duplicate_track",
            NoKeys => "no_keys",
            LengthMismatch { .. } => "length_mismatch",
            TimesNotIncreasing { .. } => "times_not_increasing",
            NonFinite => "non_finite",
            WrongWidth { .. } => "wrong_width",
            ZeroQuaternion { .. } => "zero_quaternion",
            TensionOutOfRange { .. } => "tension_out_of_range",
            OnlyCatmullRom { .. } => "only_catmull_rom",
            OnlyHermite { .. } => "only_cubic_hermite",
            MissingTangents => "missing_tangents",
            WrapEndsDiffer => "wrap_ends_differ",
            PhantomTooFewKeys { .. } => "phantom_too_few_keys",
            SpeedNotApplicable => "speed_not_applicable",
            TimeRangeTooLarge { .. } => "time_range_too_large",
            ModelSpaceOverflow { .. } => "model_space_overflow",
            CurveOverflow => "curve_overflow",
            BuildBudgetExceeded { .. } => "build_budget_exceeded",
            BuildCancelled => "build_cancelled",
            Ik(kind) => kind.code(),
            BadParameterName { .. } => "bad_parameter_name",
            DuplicateParameter { .. } => "duplicate_parameter",
            ParameterWidth { .. } => "parameter_width",
        }
    }
}

impl fmt::Display for ClipError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ClipError { path, kind } = self;
        write!(f, "{path}: {kind}")
    }
}

impl std::error::Error for ClipError {}

impl fmt::Display for ClipErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ClipErrorKind::BadName { max } => write!(f, "the clip name must be 1 to {max} characters"),
            ClipErrorKind::NoTracks => write!(f, "a clip needs at least one track or parameter"),
            ClipErrorKind::EmptyJointName => write!(f, "joint name must not be empty"),
            ClipErrorKind::JointNameTooLong { max, chars } => {
                write!(f, "a joint name may have at most {max} characters, this one has {chars}")
            }
            ClipErrorKind::DuplicateJoint { name } => write!(f, "joint '{name}' is defined twice"),
            ClipErrorKind::UnknownParent { parent } => write!(f, "parent '{parent}' is not a joint of the skeleton"),
            ClipErrorKind::ParentCycle { joint } => write!(f, "joint '{joint}' is its own ancestor (parent cycle)"),
            ClipErrorKind::ParentAfterChild { parent } => {
                write!(f, "parent '{parent}' must be listed before its child")
            }
            ClipErrorKind::UnknownJoint { joint } => {
                write!(f, "track animates joint '{joint}', which the skeleton does not have")
            }
            ClipErrorKind::DuplicateTrack { joint, channel } => {
                write!(f, "joint '{joint}' already has a {channel} track")
            }
            ClipErrorKind::NoKeys => write!(f, "a track needs at least one key"),
            ClipErrorKind::LengthMismatch { expected, provided } => {
                write!(f, "expected {expected} entries (one per time), got {provided}")
            }
            ClipErrorKind::TimesNotIncreasing { previous, current } => {
                write!(f, "key times must be strictly increasing: {current} follows {previous}")
            }
            ClipErrorKind::NonFinite => write!(f, "value is not a finite number"),
            ClipErrorKind::WrongWidth { channel, expected, provided } => {
                write!(f, "a {channel} key has {expected} numbers, got {provided}")
            }
            ClipErrorKind::ZeroQuaternion { norm } => write!(f, "quaternion has norm {norm:e}, below 1e-6"),
            ClipErrorKind::TensionOutOfRange { tension } => write!(f, "tension must be in [0, 1], got {tension}"),
            ClipErrorKind::OnlyCatmullRom { field, modes } => write!(f, "'{field}' applies only to {modes} tracks"),
            ClipErrorKind::OnlyHermite { field } => write!(f, "'{field}' applies only to cubic_hermite tracks"),
            ClipErrorKind::MissingTangents => write!(f, "cubic_hermite tracks need in_tangents and out_tangents"),
            ClipErrorKind::WrapEndsDiffer => write!(f, "wrap ends need equal first and last values"),
            ClipErrorKind::PhantomTooFewKeys { provided } => {
                write!(f, "phantom ends need at least 4 keys, got {provided}")
            }
            ClipErrorKind::SpeedNotApplicable => {
                write!(f, "constant speed applies only to translation tracks that are not step")
            }
            ClipErrorKind::TimeRangeTooLarge { start, end } => {
                write!(f, "the clip's duration, from {start:e} to {end:e}, overflows f32")
            }
            ClipErrorKind::ModelSpaceOverflow { bound, limit } => {
                write!(f, "scales and translations down the joint chain reach {bound:e} in model space, over {limit:e}")
            }
            ClipErrorKind::CurveOverflow => write!(f, "a curve control point overflows f32"),
            ClipErrorKind::BuildBudgetExceeded { limit, spent } => write!(
                f,
                "building the clip's constant-speed tables takes more than {limit} units of work (arc-length pieces plus quadrature evaluations, over the whole clip): {spent} were spent by this track"
            ),
            ClipErrorKind::BuildCancelled => write!(f, "the build was abandoned by its caller"),
            ClipErrorKind::Ik(v0) => write!(f, "{0}", v0),
            ClipErrorKind::BadParameterName { max } => write!(f, "a parameter name must be 1 to {max} characters"),
            ClipErrorKind::DuplicateParameter { name } => write!(f, "parameter '{name}' is defined twice"),
            ClipErrorKind::ParameterWidth { max, provided } => {
                write!(f, "a parameter's keys have 1 to {max} numbers each, got {provided}")
            }
        }
    }
}

impl std::error::Error for ClipErrorKind {}
