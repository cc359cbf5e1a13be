//! What the JSON documents share: the names of the core's enums on the
//! wire, and the [`DocError`] every document parser returns. Apart from
//! `json` so the IK and motion documents need not import the clip document.

use serde::{Deserialize, Serialize};

use anim::{Channel, ClipError, Ease, Ends, Interpolation, Playback, Space, Speed};

macro_rules! wire_enum {
    ($(#[$m:meta])* $doc:ident => $core:ident { $($(#[$vm:meta])* $variant:ident = $name:literal),+ $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
        // Every wire name is its variant in snake_case; said once here so the OpenAPI schema
        // (utoipa cannot read the per-variant renames through the macro) spells them the same.
        #[serde(rename_all = "snake_case")]
        pub enum $doc { $($(#[$vm])* #[serde(rename = $name)] $variant),+ }
        impl From<$doc> for $core {
            fn from(d: $doc) -> $core { match d { $($doc::$variant => $core::$variant),+ } }
        }
        impl From<$core> for $doc {
            fn from(c: $core) -> $doc { match c { $($core::$variant => $doc::$variant),+ } }
        }
        impl std::str::FromStr for $doc {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, String> {
                match s {
                    $($name => Ok($doc::$variant),)+
                    _ => Err(format!("expected one of: {}", [$($name),+].join(", "))),
                }
            }
        }
    };
}

wire_enum!(ChannelDoc => Channel { Translation = "translation", Rotation = "rotation", Scale = "scale" });
wire_enum!(
    #[derive(Default)]
    InterpolationDoc => Interpolation {
        Step = "step", #[default] Linear = "linear", CatmullRom = "catmull_rom", CubicHermite = "cubic_hermite",
        BSpline = "b_spline"
    }
);
wire_enum!(EndsDoc => Ends { Reflect = "reflect", ZeroSlope = "zero_slope", Wrap = "wrap", Phantom = "phantom" });
wire_enum!(SpeedDoc => Speed { Keyed = "keyed", Constant = "constant" });
wire_enum!(#[derive(Default)] PlaybackDoc => Playback { #[default] Once = "once", Loop = "loop", PingPong = "ping_pong" });
wire_enum!(EaseDoc => Ease { Linear = "linear", EaseIn = "ease_in", EaseOut = "ease_out", EaseInOut = "ease_in_out" });
wire_enum!(SpaceDoc => Space { Local = "local", Model = "model" });

/// A clip document that cannot be accepted: a stable `code`, the JSON
/// pointer of the offending field (empty for the whole body) and a message.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{pointer}: {detail}")]
pub struct DocError {
    pub code: &'static str,
    pub pointer: String,
    pub detail: String,
}

impl From<ClipError> for DocError {
    fn from(e: ClipError) -> Self {
        DocError { code: e.kind.code(), pointer: e.path.to_pointer(), detail: e.kind.to_string() }
    }
}
