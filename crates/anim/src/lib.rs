//! The evaluation core of inbetween: keyframes in, poses out.
//!
//! A clip is authored as a [`ClipSpec`] (a skeleton, tracks of keys, events,
//! parameters, IK constraints; unchecked data), and [`Clip::build`] turns it
//! into a [`Clip`]: validated once, quaternions normalised and made
//! hemisphere-continuous, each segment's Bezier control points precomputed in
//! `f64`. A clip that exists is valid, so sampling cannot fail, and once the
//! caller's buffers have their size it does not allocate. The rules and the
//! mathematics are in the project's docs/clip-format.md.
//!
//! The main types:
//!
//! - [`ClipSpec`] → [`Clip`]: the authoring form and the built clip;
//!   [`ClipError`] says which rule a spec broke, at which field.
//! - [`Sampler`] (with [`SampleOptions`]): a request time → a pose in local or
//!   model space; [`Clip::sample_into`] with a [`Cursor`] is the bare kernel.
//! - [`Pose`] and [`Skeleton`]: joint transforms in structure-of-arrays form,
//!   and the hierarchy that turns local poses into model space.
//! - [`Motion`] and [`MotionSampler`]: clips layered (blend or additive),
//!   masked, kept in step by sync groups, with root motion
//!   (docs/motion.md); [`motion::Player`] plays motions live, with crossfades
//!   and weight ramps.
//! - [`ik`]: the `two_bone`, `aim` and `chain` solvers ([`ik::IkSolver`])
//!   applied to local poses, with targets in model space (docs/ik.md).
//! - [`character`]: the humanoid roles of a skeleton ([`character::RoleMap`],
//!   given, read from joint names or from the rest pose's shape) and the
//!   [`character::Retargeter`] that plays one skeleton's poses on another.
//!
//! It is pure: no I/O, no async runtime, no wire format (glam is its only
//! dependency). Servers, importers and wire formats wrap it; they never reach
//! inside.
//!
//! # Build a clip and sample it
//!
//! ```
//! use glam::Vec3;
//! use inbetween_anim::{Channel, Clip, ClipSpec, Interpolation, Keys, SampleOptions, Sampler, TrackSpec};
//!
//! // One joint moving 4 units along x in 2 seconds.
//! let keys = Keys::Vec3(vec![Vec3::ZERO, Vec3::new(4.0, 0.0, 0.0)]);
//! let walk = TrackSpec::new("hips", Channel::Translation, Interpolation::Linear, vec![0.0, 2.0], keys);
//! let clip = Clip::build(&ClipSpec { name: "walk".into(), tracks: vec![walk], ..Default::default() })?;
//! assert_eq!((clip.start(), clip.end()), (0.0, 2.0));
//!
//! let mut sampler = Sampler::new();
//! let clip_time = clip.sample(0.5, &SampleOptions::default(), &mut sampler);
//! assert_eq!(clip_time, 0.5);
//! assert!((sampler.pose().translations[0].x - 1.0).abs() < 1e-6);
//!
//! // Refusals name the field at fault.
//! let empty = ClipSpec { name: "empty".into(), ..Default::default() };
//! let refusal = Clip::build(&empty).unwrap_err();
//! assert_eq!((refusal.path.to_string(), refusal.kind.code()), ("/tracks".to_owned(), "no_tracks"));
//! # Ok::<(), inbetween_anim::ClipError>(())
//! ```
//!
//! # Compose a motion
//!
//! ```
//! use glam::Vec3;
//! use inbetween_anim::motion::{LayerSpec, MotionOptions, MotionSpec};
//! use inbetween_anim::{Channel, Clip, ClipSpec, Interpolation, Keys, Motion, MotionSampler, TrackSpec};
//!
//! // A clip that holds `hips` at `x` on the x axis.
//! let hold = |name: &str, x: f32| {
//!     let keys = Keys::Vec3(vec![Vec3::new(x, 0.0, 0.0)]);
//!     let track = TrackSpec::new("hips", Channel::Translation, Interpolation::Linear, vec![0.0], keys);
//!     Clip::build(&ClipSpec { name: name.into(), tracks: vec![track], ..Default::default() })
//! };
//! let (left, right) = (hold("left", 0.0)?, hold("right", 2.0)?);
//!
//! // `right` blended over `left` at half weight: halfway between them.
//! let layers = vec![LayerSpec::new(&left), LayerSpec { weight: 0.5, ..LayerSpec::new(&right) }];
//! let motion = Motion::build(MotionSpec { layers, ..Default::default() })?;
//! let mut sampler = MotionSampler::new();
//! motion.sample(0.0, &MotionOptions::default(), &mut sampler);
//! assert_eq!(sampler.pose().translations[0].x, 1.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Solve a two-bone IK
//!
//! ```
//! use glam::{Vec3, Vec3A, Vec4};
//! use inbetween_anim::ik::{ChainStart, IkConstraint, IkSolver, TwoBone};
//! use inbetween_anim::{Channel, Clip, ClipSpec, Cursor, Interpolation, JointSpec, Keys, Pose, SkeletonSpec};
//! use inbetween_anim::{TrackSpec, Transform};
//!
//! // An arm along y: shoulder at the origin, elbow at y = 1, hand at y = 2,
//! // with a shoulder rotation track that holds it still.
//! let joint = |name: &str, parent: Option<&str>, y: f32| JointSpec {
//!     name: name.into(),
//!     parent: parent.map(Into::into),
//!     rest: Transform { translation: Vec3::new(0.0, y, 0.0), ..Transform::IDENTITY },
//!     inverse_bind: None,
//! };
//! let joints = vec![joint("shoulder", None, 0.0), joint("elbow", Some("shoulder"), 1.0), joint("hand", Some("elbow"), 1.0)];
//! let still = TrackSpec::new("shoulder", Channel::Rotation, Interpolation::Linear, vec![0.0], Keys::Vec4(vec![Vec4::W]));
//! let skeleton = Some(SkeletonSpec { joints });
//! let clip = Clip::build(&ClipSpec { name: "arm".into(), skeleton, tracks: vec![still], ..Default::default() })?;
//! let mut local = Pose::default();
//! clip.sample_into(0.0, &mut Cursor::default(), &mut local);
//!
//! // Reach for a point the straight arm does not touch.
//! let target = Vec3A::new(1.0, 1.0, 0.0);
//! let constraints = [IkConstraint::TwoBone(TwoBone::new([0, 1, 2], target))];
//! let mut reports = Vec::new();
//! IkSolver::new().solve(clip.skeleton(), &mut local, &constraints, ChainStart::Cold, &mut reports);
//! assert!(reports[0].converged);
//!
//! let mut model = Pose::default();
//! clip.skeleton().to_model(&local, &mut model);
//! assert!(model.translations[2].distance(target) < 1e-4);
//! # Ok::<(), inbetween_anim::ClipError>(())
//! ```

mod arc;
pub mod character;
mod clip;
pub mod compact;
mod compile;
mod curve;
mod error;
pub mod graph;
mod heap;
pub mod ik;
pub mod lint;
pub mod motion;
mod parameters;
mod path;
pub mod quat;
mod skeleton;
mod soa;
mod spec;
pub mod spring;
mod time;
mod timeline;
mod tracks;

pub use clip::{Clip, Cursor, DEFAULT_BUILD_WORK, Event, SampleOptions, Sampler, frame_count, frame_times};
pub use error::{ClipError, ClipErrorKind};
pub use motion::{ClipSource, Motion, MotionError, MotionSampler};
pub use parameters::{MAX_PARAMETER_WIDTH, ParameterLayout};
pub use path::{Path, Step};
pub use skeleton::{Pose, Skeleton};
pub use spec::{
    Channel, ClipSpec, Ease, Ends, EventSpec, IkTarget, Interpolation, JointSpec, KeyedIkSpec, Keys, MAX_NAME_CHARS,
    ParameterSpec, Playback, SkeletonSpec, Space, Speed, TrackSpec, Transform,
};
pub use time::TimeRange;
pub use timeline::{Span, Timeline};

/// Internals exposed for benchmarks and reference tests only.
#[doc(hidden)]
pub mod internals {
    pub use super::compile::{Key, b_spline, catmull_rom, quat_segment};
    pub use super::curve::{QuatSegment, SlerpTier, bezier3, slerp_bezier};
}

/// The README's example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
