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

/// Declares a document of keys (a joint track, an IK target's or weight's
/// keys): its own fields, then the fields every keyed track shares, said once
/// here (`interpolation`, `times`, `values`, the tangents, `ends`, `tension`,
/// `speed`; docs/clip-format.md §1), with the conversions to and from the
/// core's track, each key list's rows checked and shaped by the caller. The
/// caller imports `InterpolationDoc`, `EndsDoc`, `SpeedDoc` and `DocError`.
macro_rules! keys_doc {
    ($(#[$m:meta])* $doc:ident { $($field:ident: $ty:ident),* $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
        #[serde(deny_unknown_fields)]
        pub struct $doc {
            $(pub $field: $ty,)*
            #[serde(default)]
            pub interpolation: InterpolationDoc,
            pub times: Vec<f32>,
            pub values: Vec<Vec<f32>>,
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub in_tangents: Option<Vec<Vec<f32>>>,
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub out_tangents: Option<Vec<Vec<f32>>>,
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub ends: Option<EndsDoc>,
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub tension: Option<f32>,
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub speed: Option<SpeedDoc>,
        }

        impl $doc {
            /// The core's track of these keys; `rows(list, field)` makes each key list.
            fn keys_to_track(
                &self,
                (joint, channel): (String, anim::Channel),
                rows: impl Fn(&[Vec<f32>], &str) -> Result<anim::Keys, DocError>,
            ) -> Result<anim::TrackSpec, DocError> {
                let tangents = |t: &Option<Vec<Vec<f32>>>, field| t.as_deref().map(|t| rows(t, field)).transpose();
                Ok(anim::TrackSpec {
                    joint,
                    channel,
                    interpolation: self.interpolation.into(),
                    times: self.times.clone(),
                    values: rows(&self.values, "values")?,
                    in_tangents: tangents(&self.in_tangents, "in_tangents")?,
                    out_tangents: tangents(&self.out_tangents, "out_tangents")?,
                    ends: self.ends.map(Into::into),
                    tension: self.tension,
                    speed: self.speed.map_or(anim::Speed::Keyed, Into::into),
                })
            }

            /// The document of `track`'s keys with its own fields; `rows` makes each key list's rows.
            fn keys_of_track(
                track: &anim::TrackSpec,
                rows: impl Fn(&anim::Keys) -> Vec<Vec<f32>>,
                $($field: $ty),*
            ) -> $doc {
                $doc {
                    $($field,)*
                    interpolation: track.interpolation.into(),
                    times: track.times.clone(),
                    values: rows(&track.values),
                    in_tangents: track.in_tangents.as_ref().map(&rows),
                    out_tangents: track.out_tangents.as_ref().map(&rows),
                    ends: track.ends.map(Into::into),
                    tension: track.tension,
                    speed: (track.speed != anim::Speed::Keyed).then_some(track.speed.into()),
                }
            }
        }
    };
}
pub(super) use keys_doc;

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
