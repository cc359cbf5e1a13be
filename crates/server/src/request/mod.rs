//! The request layer: what a sample, a stream or a page of the clip list
//! may ask for, checked once for every transport.
//!
//! REST and gRPC only decode and render. Each decodes its wire form (a query
//! string, a JSON body, a protobuf message) into the raw inputs here — every
//! value as its wire carried it ([`Raw`]) and a [`Locate`] that says where
//! each field sits on that wire — and renders what comes back. The rules and
//! every refusal's stable code and class live here, so the same mistake gets
//! the same `code` on both protocols:
//!
//! - 400 (`ApiError::BadParameter`), the value does not parse: `bad_number`
//!   (not a finite number, or not a whole one where a count is asked),
//!   `bad_parameter` (outside an enum's names or numbers), `missing_parameter`,
//!   and the list's `bad_limit`, `bad_cursor`;
//! - 422 (`ApiError::Invalid`), it parses but breaks a rule:
//!   `fps_out_of_range`, `speed_out_of_range`, `max_frames_out_of_range`,
//!   `times_or_range`, `bad_range`, `too_many_poses`, `no_inverse_binds`, `unknown_joint` and
//!   `unknown_parameter` (a subset's name the clip lacks);
//!   and the cost model's (`cost`, checked once the clip is known, before
//!   anything is evaluated): `too_many_poses` (over `max_joint_poses`),
//!   `too_much_work` (the price over `max_request_work`, for a stream per
//!   second), `answer_too_large`, `frame_too_large`, `stream_rate_too_high`.
//!
//! Composed requests (`motion`, docs/motion.md) look up every layer's clip, build
//! the motion (its refusals pointed at `/motion/…`) and price the answer the
//! same way.
//!
//! Broadcasts (docs/broadcasts.md, `broadcast`) take a stream's rules for their motion,
//! fps, space and joints, plus `format_not_streamable` and
//! `idle_timeout_out_of_range` (422).
//!
//! Malformed values are reported before broken rules, and both before the
//! clip is looked up (`clip_not_found`), except the stream rules that need
//! the clip (its start is the default start).

mod body;
mod broadcast;
mod cost;
mod graph;
mod graph_stream;
mod list;
mod motion;
mod raw;
mod sample;
mod stream;

pub use body::parse_json;
pub use broadcast::RawBroadcast;
#[cfg(test)]
pub use cost::Estimate;
pub use cost::{Cost, MAX_UNARY_ANSWER_BYTES, Wire};
pub use graph::{GraphLayer, GraphSampling, GraphStages, GraphTicks, RawGraphSampling, graph_layer, no_graph_fields};
pub use graph_stream::RawGraphStream;
pub use list::{Page, RawPage};
pub use motion::{
    ClipRoute, Composed, RawMotion, at_clip_route, at_clip_route_as, crossfade_target, on_character, warnings,
};
pub use raw::{
    Field, Format, Locate, Raw, RawModes, clip, in_batch_message, in_body, in_pose_body, in_query, joint_subset,
    parameter_subset,
};
pub use sample::{RawBatch, RawPose, STREAM_ABOVE_BYTES, Sampling, evaluate};
pub use stream::{Opening, RawStream, compact_watch};

#[cfg(test)]
mod tests;
