//! The authoring form of a clip (docs/clip-format.md, “Data model”): what users
//! and importers hand in.
//!
//! These types hold data as given, unchecked. [`crate::Clip::build`]
//! is the only way from here to something that can be sampled, and it
//! validates every rule once. Wire formats (JSON, protobuf) convert into
//! these at the edge; nothing here knows about them.

use glam::{Mat4, Quat, Vec3, Vec4};

use super::ik::IkSpec;

/// Longest accepted clip or event name, in characters.
pub const MAX_NAME_CHARS: usize = 256;

/// A clip as authored: a name, an optional skeleton, tracks, events and IK
/// constraints solved at every sample.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ClipSpec {
    pub name: String,
    pub skeleton: Option<SkeletonSpec>,
    pub tracks: Vec<TrackSpec>,
    pub events: Vec<EventSpec>,
    pub playback: Playback,
    /// IK keyed in the clip (docs/ik.md, “Keyed targets in clips”).
    pub ik: Vec<KeyedIkSpec>,
    /// Named tracks that are not joints (morph weights, a camera's field of
    /// view): docs/clip-format.md, “Parameters: keys that are not joints”.
    pub parameters: Vec<ParameterSpec>,
}

/// A named parameter track (docs/clip-format.md, “Parameters”): keys of one
/// width `1..=256`, interpolated per component as a translation track is
/// (docs/clip-format.md, “Evaluation math”). Rows are kept as given so the core
/// can name the row and component at fault.
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterSpec {
    pub name: String,
    pub interpolation: Interpolation,
    /// Strictly increasing, finite, in seconds.
    pub times: Vec<f32>,
    /// One row per time, every row of the same width.
    pub values: Vec<Vec<f32>>,
    /// `cubic_hermite` only: units per second, one row per key.
    pub in_tangents: Option<Vec<Vec<f32>>>,
    pub out_tangents: Option<Vec<Vec<f32>>>,
    /// `catmull_rom` and `b_spline` only; `None` means [`Ends::Reflect`].
    pub ends: Option<Ends>,
    /// `catmull_rom` only; `None` means 0.5.
    pub tension: Option<f32>,
}

impl ParameterSpec {
    /// A parameter with the documented defaults for everything but its keys
    /// (docs/clip-format.md, “Parameters: keys that are not joints”).
    pub fn new(name: &str, interpolation: Interpolation, times: Vec<f32>, values: Vec<Vec<f32>>) -> Self {
        ParameterSpec {
            name: name.to_owned(),
            interpolation,
            times,
            values,
            in_tangents: None,
            out_tangents: None,
            ends: None,
            tension: None,
        }
    }
}

/// Joints in order; each parent must be an earlier joint.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SkeletonSpec {
    pub joints: Vec<JointSpec>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct JointSpec {
    pub name: String,
    pub parent: Option<String>,
    pub rest: Transform,
    /// The skin's inverse bind matrix (glTF), for `format=skinning`.
    pub inverse_bind: Option<Mat4>,
}

/// A local translation-rotation-scale transform.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    pub translation: Vec3,
    /// `[x, y, z, w]`; normalised by `Clip::build`.
    pub rotation: Quat,
    pub scale: Vec3,
}

impl Transform {
    pub const IDENTITY: Transform = Transform { translation: Vec3::ZERO, rotation: Quat::IDENTITY, scale: Vec3::ONE };
}

impl Default for Transform {
    fn default() -> Self {
        Self::IDENTITY
    }
}

/// One channel of one joint, with its own key times.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackSpec {
    pub joint: String,
    pub channel: Channel,
    pub interpolation: Interpolation,
    /// Strictly increasing, finite, in seconds.
    pub times: Vec<f32>,
    /// One value per time.
    pub values: Keys,
    /// `cubic_hermite` only: units per second, one per key.
    pub in_tangents: Option<Keys>,
    pub out_tangents: Option<Keys>,
    /// `catmull_rom` and `b_spline` only; `None` means [`Ends::Reflect`].
    pub ends: Option<Ends>,
    /// `catmull_rom` only; `None` means 0.5 (Catmull-Rom proper).
    pub tension: Option<f32>,
    pub speed: Speed,
}

impl TrackSpec {
    /// A track with the documented defaults for everything but its keys
    /// (docs/clip-format.md, “Data model”).
    pub fn new(joint: &str, channel: Channel, interpolation: Interpolation, times: Vec<f32>, values: Keys) -> Self {
        TrackSpec {
            joint: joint.to_owned(),
            channel,
            interpolation,
            times,
            values,
            in_tangents: None,
            out_tangents: None,
            ends: None,
            tension: None,
            speed: Speed::Keyed,
        }
    }
}

/// Key values as given: 3-vectors for translation and scale, 4-vectors
/// (`[x, y, z, w]` quaternions) for rotation.
#[derive(Debug, Clone, PartialEq)]
pub enum Keys {
    Vec3(Vec<Vec3>),
    Vec4(Vec<Vec4>),
}

impl Keys {
    /// The number of keys.
    pub fn len(&self) -> usize {
        match self {
            Keys::Vec3(v) => v.len(),
            Keys::Vec4(v) => v.len(),
        }
    }

    /// Whether there are no keys.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Numbers per key (3 or 4).
    pub fn width(&self) -> usize {
        match self {
            Keys::Vec3(_) => 3,
            Keys::Vec4(_) => 4,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Channel {
    Translation,
    Rotation,
    Scale,
}

impl Channel {
    pub const ALL: [Channel; 3] = [Channel::Translation, Channel::Rotation, Channel::Scale];

    /// The name documents and requests use.
    pub fn as_str(self) -> &'static str {
        match self {
            Channel::Translation => "translation",
            Channel::Rotation => "rotation",
            Channel::Scale => "scale",
        }
    }

    /// How many numbers one key of this channel has.
    pub fn width(self) -> usize {
        match self {
            Channel::Rotation => 4,
            _ => 3,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interpolation {
    Step,
    Linear,
    CatmullRom,
    CubicHermite,
    /// The lecture's uniform cubic B-spline (docs/clip-format.md, “Other
    /// interpolation modes”): approximating and C2, for smoothing motion
    /// capture; stored as Bezier segments like Catmull-Rom, so it samples at
    /// the same cost.
    BSpline,
}

impl Interpolation {
    /// The name documents and requests use.
    pub fn as_str(self) -> &'static str {
        match self {
            Interpolation::Step => "step",
            Interpolation::Linear => "linear",
            Interpolation::CatmullRom => "catmull_rom",
            Interpolation::CubicHermite => "cubic_hermite",
            Interpolation::BSpline => "b_spline",
        }
    }
}

/// End conditions of a Catmull-Rom or B-spline track (docs/clip-format.md, “End
/// conditions”, “Other interpolation modes”).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Ends {
    #[default]
    Reflect,
    ZeroSlope,
    Wrap,
    Phantom,
}

impl Ends {
    /// The name documents and requests use.
    pub fn as_str(self) -> &'static str {
        match self {
            Ends::Reflect => "reflect",
            Ends::ZeroSlope => "zero_slope",
            Ends::Wrap => "wrap",
            Ends::Phantom => "phantom",
        }
    }
}

/// How a translation track moves along its path (docs/clip-format.md, “Speed control”).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Speed {
    /// Keys are reached at their times.
    #[default]
    Keyed,
    /// Arc-length reparameterised: the same path at constant speed.
    Constant,
}

#[derive(Debug, Clone, PartialEq)]
pub struct EventSpec {
    pub time: f32,
    pub name: String,
}

/// What happens outside the clip's time range (docs/clip-format.md, “Playback modes and time”).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Playback {
    #[default]
    Once,
    Loop,
    PingPong,
}

impl Playback {
    /// The name documents and requests use.
    pub fn as_str(self) -> &'static str {
        match self {
            Playback::Once => "once",
            Playback::Loop => "loop",
            Playback::PingPong => "ping_pong",
        }
    }
}

/// Request-level time warp over normalised clip time (docs/clip-format.md, “Speed control”).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Ease {
    #[default]
    Linear,
    EaseIn,
    EaseOut,
    EaseInOut,
}

impl Ease {
    /// The name documents and requests use.
    pub fn as_str(self) -> &'static str {
        match self {
            Ease::Linear => "linear",
            Ease::EaseIn => "ease_in",
            Ease::EaseOut => "ease_out",
            Ease::EaseInOut => "ease_in_out",
        }
    }

    /// The warp of normalised time `x ∈ [0, 1]`.
    #[inline]
    pub fn apply(self, x: f64) -> f64 {
        match self {
            Ease::Linear => x,
            Ease::EaseIn => x * x,
            Ease::EaseOut => 1.0 - (1.0 - x) * (1.0 - x),
            Ease::EaseInOut => x * x * (3.0 - 2.0 * x),
        }
    }
}

/// Local joint transforms or transforms composed down the hierarchy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Space {
    #[default]
    Local,
    Model,
}

impl Space {
    /// The name documents and requests use.
    pub fn as_str(self) -> &'static str {
        match self {
            Space::Local => "local",
            Space::Model => "model",
        }
    }
}

/// One constraint of a clip: its targets (one per target, in
/// [`IkSpec::target_count`]'s order) fixed or keyed, and optionally its
/// weight keyed. The constraint's own targets are ignored, and its weight
/// too when `weight` is keyed.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyedIkSpec {
    pub constraint: IkSpec,
    pub targets: Vec<IkTarget>,
    /// Keys `[w, 0, 0]`: the weight is the first component, in [0, 1].
    pub weight: Option<TrackSpec>,
}

/// A target in model space: a point, or a track of points (whose keys
/// count toward the clip's time range; a point does not).
#[derive(Debug, Clone, PartialEq)]
pub enum IkTarget {
    Fixed(Vec3),
    Keyed(TrackSpec),
}
