//! The raw inputs every transport decodes into (each value as its wire
//! carried it, and where each field sits on that wire), and the decoders
//! and refusal builders the rules share.

use std::sync::Arc;

use serde::Deserialize;
use utoipa::ToSchema;

use crate::cache::CachedClip;
use crate::error::{ApiError, At};
use crate::state::AppState;
use crate::store::is_clip_id;
use anim::{Ease, ParameterLayout, Playback, SampleOptions, Skeleton, Space};
use formats::wire::json::{EaseDoc, PlaybackDoc, SpaceDoc};
use formats::wire::proto::pb;
use formats::wire::proto::{ease_from_pb, playback_from_pb, space_from_pb};

/// A request field, named once for every transport.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Field {
    /// The one request time of a pose.
    Time,
    /// Explicit request times, as a whole (their count).
    Times,
    /// One of them.
    TimeAt(usize),
    /// Range start (samples) or the request time of frame 0 (streams).
    Start,
    End,
    Fps,
    /// Times or range, as a whole: which of them, or how many poses a range makes.
    When,
    Space,
    Playback,
    Ease,
    Format,
    Speed,
    Encoding,
    MaxFrames,
    /// Compact frames' error bound and distance (docs/compact-frames.md).
    MaxError,
    Distance,
    /// A page of the clip list: its size and where it starts.
    Limit,
    Cursor,
    /// The clip-list filters (`request::list`).
    Name,
    NamePrefix,
    NameContains,
    Tag,
    MinDuration,
    MaxDuration,
    CompatibleWith,
    /// One of the joint names of a subset (docs/motion.md).
    JointAt(usize),
    /// One of the parameter names of a subset (docs/clip-format.md §3).
    ParameterAt(usize),
    /// A broadcast's `idle_timeout_secs` (docs/broadcasts.md).
    IdleTimeout,
    /// The character a clip route plays its clip on (docs/characters.md).
    Character,
    /// Whether a clip route runs the clip's spring chains (docs/springs.md).
    Springs,
}

impl Field {
    /// The REST name: the query parameter or body field.
    pub fn name(self) -> &'static str {
        match self {
            Field::Time => "t",
            Field::Times | Field::TimeAt(_) => "times",
            Field::Start => "start",
            Field::End => "end",
            Field::Fps => "fps",
            Field::When => "",
            Field::Space => "space",
            Field::Playback => "playback",
            Field::Ease => "ease",
            Field::Format => "format",
            Field::Speed => "speed",
            Field::Encoding => "encoding",
            Field::MaxFrames => "max_frames",
            Field::MaxError => "max_error",
            Field::Distance => "distance",
            Field::Limit => "limit",
            Field::Cursor => "cursor",
            Field::Name => "name",
            Field::NamePrefix => "name_prefix",
            Field::NameContains => "name_contains",
            Field::Tag => "tag",
            Field::MinDuration => "min_duration",
            Field::MaxDuration => "max_duration",
            Field::CompatibleWith => "compatible_with",
            Field::JointAt(_) => "joints",
            Field::ParameterAt(_) => "parameters",
            Field::IdleTimeout => "idle_timeout_secs",
            Field::Character => "character",
            Field::Springs => "springs",
        }
    }
}

/// Where each field sits on a transport's wire, for the error's location.
pub type Locate = fn(Field) -> At;

/// REST query strings: the parameter by its name.
pub fn in_query(field: Field) -> At {
    At::Parameter(field.name().to_owned())
}

/// JSON bodies (and flat protobuf messages): `/name`, `/times/3`, `""` for
/// the request as a whole.
pub fn in_body(field: Field) -> At {
    match field {
        Field::When => At::Pointer(String::new()),
        Field::TimeAt(i) => At::Pointer(format!("/times/{i}")),
        Field::JointAt(i) => At::Pointer(format!("/joints/{i}")),
        Field::ParameterAt(i) => At::Pointer(format!("/parameters/{i}")),
        other => At::Pointer(format!("/{}", other.name())),
    }
}

/// A one-pose body or message whose time is `time` (REST `POST /v1/poses`,
/// gRPC `Sample` and `SampleMotion`).
pub fn in_pose_body(field: Field) -> At {
    match field {
        Field::Time => At::Pointer("/time".into()),
        other => in_body(other),
    }
}

/// A many-pose message whose range sits in `range` (gRPC `SampleBatch`,
/// `SampleStream`, `SampleMotionBatch`).
pub fn in_batch_message(field: Field) -> At {
    match field {
        Field::Start | Field::End | Field::Fps => At::Pointer(format!("/range/{}", field.name())),
        other => in_body(other),
    }
}

/// How each pose is rendered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Format {
    /// Translation, rotation `[x,y,z,w]`, scale per joint, in the requested space.
    #[default]
    Trs,
    /// Column-major 4×4 model matrices (model space).
    Matrix,
    /// `M_j · invBind_j`, for clips with inverse bind matrices.
    Skinning,
}

impl std::str::FromStr for Format {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "trs" => Ok(Format::Trs),
            "matrix" => Ok(Format::Matrix),
            "skinning" => Ok(Format::Skinning),
            _ => Err("expected one of: trs, matrix, skinning".into()),
        }
    }
}

impl Format {
    /// # Errors
    /// `bad_parameter`.
    pub(super) fn decode(raw: Option<Raw<'_>>, at: Locate) -> Result<Format, ApiError> {
        let by_number = |n: i32| match pb::Format::try_from(n) {
            Ok(pb::Format::Unspecified) => Ok(None),
            Ok(pb::Format::Trs) => Ok(Some(Format::Trs)),
            Ok(pb::Format::Matrix) => Ok(Some(Format::Matrix)),
            Ok(pb::Format::Skinning) => Ok(Some(Format::Skinning)),
            Err(_) => Err(format!("{n} is not a valid Format")),
        };
        Ok(choice(raw, Field::Format, at, str::parse, by_number)?.unwrap_or_default())
    }
}

/// A value as its wire carried it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Raw<'a> {
    /// Query-string or JSON text.
    Text(&'a str),
    /// A number from JSON or protobuf (protobuf carries any double, NaN too).
    Number(f64),
    /// A protobuf enum number: open, any `i32` may arrive; 0 is the default.
    Enum(i32),
}

/// `playback`, `ease` and `space`, the modes every sample and stream takes.
#[derive(Debug, Clone, Copy, Default)]
pub struct RawModes<'a> {
    pub space: Option<Raw<'a>>,
    pub playback: Option<Raw<'a>>,
    pub ease: Option<Raw<'a>>,
}

impl RawModes<'static> {
    /// A gRPC clip request's space, playback and ease enum numbers, to be checked.
    pub fn of_enums(space: i32, playback: i32, ease: i32) -> Self {
        RawModes { space: Some(Raw::Enum(space)), playback: Some(Raw::Enum(playback)), ease: Some(Raw::Enum(ease)) }
    }
}

impl RawModes<'_> {
    /// # Errors
    /// `bad_parameter` for a name or number outside an enum.
    pub(crate) fn check(&self, at: Locate) -> Result<SampleOptions, ApiError> {
        let name = |text: &str| text.parse::<PlaybackDoc>().map(Playback::from);
        let playback =
            choice(self.playback, Field::Playback, at, name, |n| playback_from_pb(n, "").map_err(|e| e.detail))?;
        let name = |text: &str| text.parse::<EaseDoc>().map(Ease::from);
        let ease = choice(self.ease, Field::Ease, at, name, |n| ease_from_pb(n, "").map_err(|e| e.detail))?;
        let name = |text: &str| text.parse::<SpaceDoc>().map(Space::from);
        let space = choice(self.space, Field::Space, at, name, |n| space_from_pb(n, "").map_err(|e| e.detail))?;
        Ok(SampleOptions { playback, ease: ease.unwrap_or_default(), space: space.unwrap_or_default() })
    }
}

/// The clip `id` at its current version (the cache entry, not a copy).
///
/// # Errors
/// `clip_not_found` (an id that cannot be one is not looked up), or the
/// store's failure.
pub async fn clip(state: &AppState, id: &str) -> Result<Arc<CachedClip>, ApiError> {
    if !is_clip_id(id) {
        return Err(ApiError::NotFound { what: "clip" });
    }
    state.clip(id).await
}

/// The indices of the joints `names` in `skeleton`, in skeleton order
/// (a subset's joints; docs/motion.md).
///
/// # Errors
/// `unknown_joint` at the first name the skeleton lacks.
pub fn joint_subset<S: AsRef<str>>(skeleton: &Skeleton, names: &[S], at: Locate) -> Result<Vec<usize>, ApiError> {
    let mut indices = Vec::with_capacity(names.len());
    for (i, name) in names.iter().enumerate() {
        let name = name.as_ref();
        let j = skeleton.index_of(name).ok_or_else(|| {
            let detail = format!("joint '{name}' is not in the skeleton");
            unprocessable("unknown_joint", Field::JointAt(i), at, detail)
        })?;
        indices.push(j);
    }
    indices.sort_unstable();
    indices.dedup();
    Ok(indices)
}

/// The indices of the parameters `names` in `layout`, in the clip's order
/// (a subset's parameters; docs/clip-format.md §3), as [`joint_subset`] for joints.
///
/// # Errors
/// `unknown_parameter` at the first name the clip lacks.
pub fn parameter_subset<S: AsRef<str>>(
    layout: &ParameterLayout,
    names: &[S],
    at: Locate,
) -> Result<Vec<usize>, ApiError> {
    let mut indices = Vec::with_capacity(names.len());
    for (i, name) in names.iter().enumerate() {
        let name = name.as_ref();
        let p = layout.index_of(name).ok_or_else(|| {
            let detail = format!("parameter '{name}' is not one of the clip's");
            unprocessable("unknown_parameter", Field::ParameterAt(i), at, detail)
        })?;
        indices.push(p);
    }
    indices.sort_unstable();
    indices.dedup();
    Ok(indices)
}

pub(super) fn malformed(code: &'static str, field: Field, at: Locate, detail: String) -> ApiError {
    ApiError::BadParameter { code, at: at(field), detail }
}

pub(super) fn unprocessable(code: &'static str, field: Field, at: Locate, detail: String) -> ApiError {
    ApiError::Invalid { code, at: at(field), detail }
}

/// A finite number.
///
/// # Errors
/// `bad_number`: text that is not a number, or NaN, ±∞, an overflow.
pub(super) fn finite(raw: Raw<'_>, field: Field, at: Locate) -> Result<f64, ApiError> {
    let value = match raw {
        Raw::Text(text) => text.trim().parse::<f64>().ok(),
        Raw::Number(n) => Some(n),
        Raw::Enum(_) => None,
    };
    value.filter(|v| v.is_finite()).ok_or_else(|| {
        let shown = match raw {
            Raw::Text(text) => text.to_owned(),
            Raw::Number(n) => n.to_string(),
            Raw::Enum(n) => n.to_string(),
        };
        malformed("bad_number", field, at, format!("`{}` must be a finite number, got `{shown}`", field.name()))
    })
}

/// A whole number (a frame rate or count), as `f64` so that the range check
/// sees values no integer type holds (`fps=-1`, `fps=1e30`).
///
/// # Errors
/// `bad_number`: not a finite number, or not a whole one.
pub(super) fn whole(raw: Raw<'_>, field: Field, at: Locate) -> Result<f64, ApiError> {
    let value = finite(raw, field, at)?;
    if value.fract() != 0.0 {
        let detail = format!("`{}` must be a whole number, got {value}", field.name());
        return Err(malformed("bad_number", field, at, detail));
    }
    Ok(value)
}

/// One of an enum's values: by name (text) or by protobuf number, where a
/// number's `Ok(None)` is `*_UNSPECIFIED`, the default.
///
/// # Errors
/// `bad_parameter` naming what is accepted.
pub(super) fn choice<T>(
    raw: Option<Raw<'_>>,
    field: Field,
    at: Locate,
    by_name: impl Fn(&str) -> Result<T, String>,
    by_number: impl Fn(i32) -> Result<Option<T>, String>,
) -> Result<Option<T>, ApiError> {
    let decoded = match raw {
        None => Ok(None),
        Some(Raw::Text(text)) => by_name(text).map(Some),
        Some(Raw::Enum(n)) => by_number(n),
        Some(Raw::Number(n)) => Err(format!("expected a name, got the number {n}")),
    };
    decoded.map_err(|e| malformed("bad_parameter", field, at, format!("`{}`: {e}", field.name())))
}
