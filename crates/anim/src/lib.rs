//! The evaluation core: keyframes in, poses out (SPEC §1–2).
//!
//! **Architecture invariant:** this module is pure. It knows nothing of the
//! network, storage, async runtimes or wire formats (no tokio, axum, tonic,
//! sqlx, serde or prost), does no I/O, and cannot fail once a [`Clip`] is
//! built. The service layers wrap it; they never reach inside.
//!
//! The flow is `ClipSpec` (authoring data, unchecked) → [`Clip::build`]
//! (validated; quaternions normalised and made hemisphere-continuous; each
//! segment's Bezier control points precomputed in `f64`) → sampling into
//! caller-owned buffers ([`Cursor`], [`Pose`]) with no allocation.
//!
//! Module map: `spec` the authoring types; `error` why a spec is refused;
//! `compile` per-track validation and control points; `curve` the runtime
//! curves and their evaluation; `quat` quaternion tools and fast slerp;
//! `time` request time → clip time (playback, ease, the seams);
//! `timeline` the segment search; `tracks` the per-kind track lists; `soa` tracks sharing key times evaluated four per SIMD group; `arc` constant-speed tables; `skeleton`
//! hierarchy and model space; `clip` the clip and the sampling kernel; `motion` composition (SPEC §6): layers,
//! masks, sync groups, over clips; `ik` inverse kinematics (SPEC §7) on local poses; `parameters` named
//! tracks that are not joints (SPEC §8), compiled as translation-like curves; `lint` warnings about valid
//! clips that are probably not what was meant.

mod arc;
mod clip;
mod compile;
mod curve;
mod error;
pub mod ik;
pub mod lint;
pub mod motion;
mod parameters;
mod path;
pub mod quat;
mod skeleton;
mod soa;
mod spec;
mod time;
mod timeline;
mod tracks;

pub use clip::{
    Clip, Cursor, DEFAULT_BUILD_WORK, Event, MAX_NAME_CHARS, SampleOptions, Sampler, frame_count, frame_times,
};
pub use error::{ClipError, ClipErrorKind};
pub use motion::{ClipSource, Motion, MotionError, MotionSampler};
pub use parameters::{MAX_PARAMETER_WIDTH, ParameterLayout};
pub use path::{Path, Step};
pub use skeleton::{Pose, Skeleton};
pub use spec::{
    Channel, ClipSpec, Ease, Ends, EventSpec, IkTarget, Interpolation, JointSpec, KeyedIkSpec, Keys, ParameterSpec,
    Playback, SkeletonSpec, Space, Speed, TrackSpec, Transform,
};
pub use time::TimeRange;
pub use timeline::{Span, Timeline};

/// Internals exposed for benchmarks and reference tests only.
#[doc(hidden)]
pub mod internals {
    pub use super::compile::{Key, b_spline, catmull_rom, quat_segment};
    pub use super::curve::{QuatSegment, SlerpTier, bezier3, slerp_bezier};
}
