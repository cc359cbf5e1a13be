//! Why a [`ClipSpec`](super::ClipSpec) was refused, and where.
//!
//! Every error names the offending place as a path of field names and
//! indices that mirrors SPEC §1 (`tracks`, 3, `times`, 5), so the edge can
//! render a JSON pointer (`/tracks/3/times/5`) without the core knowing JSON.

use std::fmt;

/// One step of a path into a clip document.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step {
    Field(&'static str),
    Index(usize),
    /// A key of a JSON object given by the user (a mask's joint name).
    Key(String),
}

/// A place in a clip document, outermost first.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Path(pub Vec<Step>);

impl Path {
    pub fn root() -> Self {
        Path(Vec::new())
    }

    pub fn field(mut self, name: &'static str) -> Self {
        self.0.push(Step::Field(name));
        self
    }

    pub fn index(mut self, i: usize) -> Self {
        self.0.push(Step::Index(i));
        self
    }

    pub fn key(mut self, key: &str) -> Self {
        self.0.push(Step::Key(key.to_owned()));
        self
    }

    /// `/tracks/3/times/5` (RFC 6901).
    pub fn to_pointer(&self) -> String {
        let mut s = String::new();
        for step in &self.0 {
            s.push('/');
            match step {
                Step::Field(f) => s.push_str(f),
                Step::Index(i) => s.push_str(&i.to_string()),
                // RFC 6901: `~` is `~0`, `/` is `~1`.
                Step::Key(k) => s.push_str(&k.replace('~', "~0").replace('/', "~1")),
            }
        }
        s
    }
}

impl fmt::Display for Path {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_empty() { f.write_str("/") } else { f.write_str(&self.to_pointer()) }
    }
}

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
    #[error("a clip needs at least one track")]
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
    #[error("'{field}' applies only to catmull_rom tracks")]
    OnlyCatmullRom { field: &'static str },
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
        }
    }
}
