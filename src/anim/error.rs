//! Why a [`ClipSpec`](super::ClipSpec) was refused, and where.
//!
//! Every error names the offending place as a path of field names and
//! indices that mirrors SPEC §1 (`tracks`, 3, `times`, 5), so the edge can
//! render a JSON pointer (`/tracks/3/times/5`) without the core knowing JSON.

use super::ik::IkErrorKind;
use super::path::Path;

/// A clip that cannot be built: what is wrong ([`ClipErrorKind`]) and where.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {kind}")]
pub struct ClipError {
    pub path: Path,
    pub kind: ClipErrorKind,
}

impl ClipError {
    pub fn new(path: Path, kind: ClipErrorKind) -> Self {
        ClipError { path, kind }
    }
}

/// Each rule `Clip::build` enforces. `code()` is stable for clients.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ClipErrorKind {
    #[error("the clip name must be 1 to {max} characters")]
    BadName { max: usize },
    #[error("a clip needs at least one track or parameter")]
    NoTracks,
    #[error("joint name must not be empty")]
    EmptyJointName,
    /// Every answer repeats joint names, so their length is part of its cost.
    #[error("a joint name may have at most {max} characters, this one has {chars}")]
    JointNameTooLong { max: usize, chars: usize },
    #[error("joint '{name}' is defined twice")]
    DuplicateJoint { name: String },
    #[error("parent '{parent}' is not a joint of the skeleton")]
    UnknownParent { parent: String },
    #[error("joint '{joint}' is its own ancestor (parent cycle)")]
    ParentCycle { joint: String },
    #[error("parent '{parent}' must be listed before its child")]
    ParentAfterChild { parent: String },
    #[error("track animates joint '{joint}', which the skeleton does not have")]
    UnknownJoint { joint: String },
    #[error("joint '{joint}' already has a {channel} track")]
    DuplicateTrack { joint: String, channel: &'static str },
    #[error("a track needs at least one key")]
    NoKeys,
    #[error("expected {expected} entries (one per time), got {provided}")]
    LengthMismatch { expected: usize, provided: usize },
    #[error("key times must be strictly increasing: {current} follows {previous}")]
    TimesNotIncreasing { previous: f32, current: f32 },
    #[error("value is not a finite number")]
    NonFinite,
    #[error("a {channel} key has {expected} numbers, got {provided}")]
    WrongWidth { channel: &'static str, expected: usize, provided: usize },
    #[error("quaternion has norm {norm:e}, below 1e-6")]
    ZeroQuaternion { norm: f32 },
    #[error("tension must be in [0, 1], got {tension}")]
    TensionOutOfRange { tension: f32 },
    /// `ends` outside `catmull_rom` and `b_spline`, `tension` outside
    /// `catmull_rom` (the code predates `b_spline` and stays stable).
    #[error("'{field}' applies only to {modes} tracks")]
    OnlyCatmullRom { field: &'static str, modes: &'static str },
    #[error("'{field}' applies only to cubic_hermite tracks")]
    OnlyHermite { field: &'static str },
    #[error("cubic_hermite tracks need in_tangents and out_tangents")]
    MissingTangents,
    #[error("wrap ends need equal first and last values")]
    WrapEndsDiffer,
    #[error("phantom ends need at least 4 keys, got {provided}")]
    PhantomTooFewKeys { provided: usize },
    #[error("constant speed applies only to translation tracks that are not step")]
    SpeedNotApplicable,
    #[error("the clip's duration, from {start:e} to {end:e}, overflows f32")]
    TimeRangeTooLarge { start: f32, end: f32 },
    #[error("scales and translations down the joint chain reach {bound:e} in model space, over {limit:e}")]
    ModelSpaceOverflow { bound: f64, limit: f64 },
    #[error("a curve control point overflows f32")]
    CurveOverflow,
    #[error(
        "building the clip's constant-speed tables takes more than {limit} units of work (arc-length pieces plus \
         quadrature evaluations, over the whole clip): {spent} were spent by this track"
    )]
    BuildBudgetExceeded { limit: u64, spent: u64 },
    #[error("the build was abandoned by its caller")]
    BuildCancelled,
    /// An `ik` constraint breaks a rule of SPEC §7.
    #[error("{0}")]
    Ik(IkErrorKind),
    #[error("a parameter name must be 1 to {max} characters")]
    BadParameterName { max: usize },
    #[error("parameter '{name}' is defined twice")]
    DuplicateParameter { name: String },
    #[error("a parameter's keys have 1 to {max} numbers each, got {provided}")]
    ParameterWidth { max: usize, provided: usize },
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
