//! The composed-motion RPCs (docs/motion.md): `SampleMotion` and
//! `SampleMotionBatch`, the gRPC mirror of `POST /v1/poses` and
//! `/v1/samples`. The motion message becomes the JSON motion document in
//! `wire::proto_motion` (one conversion, so the wires cannot drift), is
//! checked and priced by `server::request` (`RawPose`, `RawBatch`,
//! `RawMotion`, and `RawGraphSampling` for a graph layer) with the same
//! codes as REST, charged to the caller and run on the work pool
//! (`server::work`), and each pose is packed from the motion sampler's (or
//! the graph player's) buffers with its joint subset, root motion, IK
//! reports (the clips' constraints, then the request's `motion.ik`) and
//! graph report.

use glam::Mat4;

use crate::auth::Caller;
use crate::compression::AnswerCoding;
use crate::error::ApiError;
use crate::error::At;
use crate::request::{
    ClipRoute, Composed, Cost, Field, Format, GraphLayer, GraphSampling, GraphTicks, Locate, MAX_UNARY_ANSWER_BYTES,
    Raw, RawBatch, RawGraphSampling, RawModes, RawMotion, RawPose, Wire, at_clip_route_as, graph_layer,
    in_batch_message, in_pose_body, no_graph_fields,
};

use crate::state::AppState;
use crate::work::Cancel;
use crate::work::Ticket;
use anim::motion::MotionOptions;
use anim::{MotionSampler, Pose, Space};
use std::sync::Arc;

use crate::stream::StreamMotion;
use formats::wire::json::ParameterValues;
use formats::wire::motion::MotionDoc;
use formats::wire::proto::{
    add_parameters, ik_reports_to_pb, matrices_to_pb, pb, pose_to_pb, root_motion_to_pb, select_joints,
};
use formats::wire::proto_graph::report_to_proto;
use formats::wire::proto_motion::{inputs_from_pb, motion_doc_from_pb};

/// A request's motion message as its JSON document (an absent one: no layers).
fn motion_doc(motion: Option<&pb::Motion>) -> Result<MotionDoc, ApiError> {
    Ok(motion_doc_from_pb(motion.unwrap_or(&pb::Motion::default()))?)
}

/// An empty list is the JSON's absent one.
fn subset(names: &[String]) -> Option<&[String]> {
    (!names.is_empty()).then_some(names)
}

/// The request's motion and joints, looked up and built.
async fn compose(
    state: &AppState,
    caller: &Caller,
    doc: &MotionDoc,
    (joints, parameters): (&[String], &[String]),
    format: Format,
) -> Result<Composed, ApiError> {
    let raw = RawMotion::of_doc(doc)?;
    let raw = RawMotion { joints: subset(joints), parameters: subset(parameters), format, ..raw };
    raw.resolve_for(state, &caller.key()).await
}

/// A stream's motion (`StreamRequest.motion`), still to be looked up.
///
/// # Errors
/// The message's enums or numbers out of range, and the document's own
/// refusals, at `/motion/…`.
pub fn raw_motion(motion: &pb::Motion) -> Result<RawMotion<'static>, ApiError> {
    Ok(RawMotion::of_doc(&motion_doc_from_pb(motion)?)?)
}

/// A `Play` crossfade's target, looked up and built; pointers under `/to`.
/// With it, the target as a JSON motion (what a broadcast stores).
///
/// # Errors
/// As [`raw_motion`] and `RawMotion::resolve`, at `/to/…`.
pub async fn crossfade_target(
    state: &AppState,
    to: Option<&pb::Motion>,
) -> Result<(Arc<StreamMotion>, serde_json::Value), ApiError> {
    let built = async {
        let doc = motion_doc(to)?;
        let source = serde_json::to_value(&doc).map_err(ApiError::internal)?;
        Ok((RawMotion::of_doc(&doc)?.resolve(state).await?.motion, source))
    };
    built.await.map_err(|e: ApiError| e.moved("/motion", "/to"))
}

/// `SampleMotion`: one pose, with its names.
///
/// # Errors
/// As `POST /v1/poses`, with the same codes.
pub async fn sample(
    state: &AppState,
    caller: &Caller,
    req: pb::SampleMotionRequest,
    coding: AnswerCoding,
) -> Result<pb::Pose, ApiError> {
    let doc = motion_doc(req.motion.as_ref())?;
    sample_doc(state, caller, doc, req, coding).await
}

/// `SampleMotion` of the motion `doc` (the request's own, or the one-layer
/// motion of a clip on a character).
async fn sample_doc(
    state: &AppState,
    caller: &Caller,
    doc: MotionDoc,
    req: pb::SampleMotionRequest,
    coding: AnswerCoding,
) -> Result<pb::Pose, ApiError> {
    if let Some(layer) = graph_layer(&doc)? {
        return graph_pose(state, caller, &req, &layer, coding).await;
    }
    no_graph_fields(req.report, !req.inputs.is_empty(), req.fps.is_some())?;
    let modes = RawModes { space: Some(Raw::Enum(req.space)), ..RawModes::default() };
    let checked =
        RawPose { t: Some(Raw::Number(req.time)), modes, format: Some(Raw::Enum(req.format)), at: in_pose_body }
            .check()?;
    let composed = compose(state, caller, &doc, (&req.joints, &req.parameters), checked.format).await?;
    let cost = composed.cost(&[checked.t], checked.format, Wire::Protobuf);
    let cost = cost.compressed(coding.at(cost.bytes));
    cost.check(&state.config.limits, Field::Time, in_pose_body)?;
    let pack = move |_: &Cancel| Packer::new(composed, checked.options.space, checked.format).pose(checked.t, true);
    let pose = state.work.spend(&caller.key(), cost.work(), pack).await?;
    state.counters.poses.increment(1);
    Ok(pose)
}

/// `SampleMotionBatch`: many poses, the names once.
///
/// # Errors
/// As `POST /v1/samples`, and `use_sample_stream`-like refusal of an answer
/// over the unary limit (REST's `/v1/samples` sends any size).
pub async fn sample_batch(
    state: &AppState,
    caller: &Caller,
    req: pb::SampleMotionBatchRequest,
    coding: AnswerCoding,
) -> Result<pb::PoseBatch, ApiError> {
    let doc = motion_doc(req.motion.as_ref())?;
    sample_batch_doc(state, caller, doc, req, coding).await
}

/// `SampleMotionBatch` of the motion `doc`, as [`sample_doc`].
async fn sample_batch_doc(
    state: &AppState,
    caller: &Caller,
    doc: MotionDoc,
    req: pb::SampleMotionBatchRequest,
    coding: AnswerCoding,
) -> Result<pb::PoseBatch, ApiError> {
    if let Some(layer) = graph_layer(&doc)? {
        return graph_batch(state, caller, &req, &layer, coding).await;
    }
    let (mut poses, cost) = motion_poses(state, caller, &doc, &req, coding).await?;
    if cost.bytes > MAX_UNARY_ANSWER_BYTES {
        let (bytes, limit) = (cost.bytes, MAX_UNARY_ANSWER_BYTES);
        return Err(ApiError::AnswerTooLargeForUnary { bytes, limit, stream: "REST POST /v1/samples" });
    }
    let n = poses.times.len();
    let pack = move |cancel: &Cancel| poses.batch(0..n, true, cancel);
    let batch = state.work.spend(&caller.key(), cost.work(), pack).await?;
    state.counters.poses.increment(n as u64);
    Ok(batch)
}

/// `SampleStream` of the motion `doc` (a clip route's: no graph), checked
/// and priced as `SampleMotionBatch` is but for the unary limit, its price
/// charged until the answer is sent or dropped.
async fn stream_poses(
    state: &AppState,
    caller: &Caller,
    doc: MotionDoc,
    req: pb::SampleMotionBatchRequest,
    coding: AnswerCoding,
) -> Result<(MotionPoses, Ticket), ApiError> {
    let (poses, cost) = motion_poses(state, caller, &doc, &req, coding).await?;
    Ok((poses, state.work.charge(&caller.key(), cost.work())?))
}

/// A motion batch's poses to pack (its graph layer aside), checked, built
/// and priced, the price within `max_request_work`.
async fn motion_poses(
    state: &AppState,
    caller: &Caller,
    doc: &MotionDoc,
    req: &pb::SampleMotionBatchRequest,
    coding: AnswerCoding,
) -> Result<(MotionPoses, Cost), ApiError> {
    use pb::sample_motion_batch_request::When;
    no_graph_fields(req.report, !req.inputs.is_empty(), false)?;
    let (times, range) = match &req.when {
        Some(When::Times(t)) => (Some(t), None),
        Some(When::Range(r)) => (None, Some(r)),
        None => (None, None),
    };
    let modes = RawModes { space: Some(Raw::Enum(req.space)), ..RawModes::default() };
    let raw = RawBatch::of_message(times, range, modes, req.format);
    let sampling = raw.check(state.config.limits.max_poses)?;
    let composed = compose(state, caller, doc, (&req.joints, &req.parameters), sampling.format).await?;
    let cost = composed.cost(&sampling.times, sampling.format, Wire::Protobuf);
    let cost = cost.compressed(coding.at(cost.bytes));
    let field = if matches!(req.when, Some(When::Times(_))) { Field::Times } else { Field::When };
    cost.check(&state.config.limits, field, in_batch_message)?;
    let packer = Packer::new(composed, sampling.options.space, sampling.format);
    Ok((MotionPoses { packer, times: sampling.times, answer_bytes: cost.bytes }, cost))
}

/// The poses of a `SampleStream` answer, packed a message at a time.
pub trait PosesJob: Send + 'static {
    /// How many poses the answer holds.
    fn count(&self) -> usize;
    /// The answer's size bound, in bytes.
    fn answer_bytes(&self) -> u64;
    /// The poses `range` (after the last call's), with the names when
    /// `names`; fewer once `cancel` is raised.
    fn batch(&mut self, range: std::ops::Range<usize>, names: bool, cancel: &Cancel) -> pb::PoseBatch;
}

/// A motion's poses at a batch's times, packed in order: root motion runs
/// from each to the next, and its springs are one simulation through them
/// (docs/springs.md, “Time”), however many messages carry them.
pub struct MotionPoses {
    packer: Packer,
    times: Vec<f64>,
    answer_bytes: u64,
}

impl PosesJob for MotionPoses {
    fn count(&self) -> usize {
        self.times.len()
    }

    fn answer_bytes(&self) -> u64 {
        self.answer_bytes
    }

    /// The poses `range` (the next ones after the last batch's), with the
    /// names when `names`; fewer once `cancel` is raised.
    fn batch(&mut self, range: std::ops::Range<usize>, names: bool, cancel: &Cancel) -> pb::PoseBatch {
        let times = self.times[range].iter().take_while(|_| cancel.proceed());
        let poses: Vec<pb::Pose> = times.map(|&t| self.packer.pose(t, false)).collect();
        if !names {
            return pb::PoseBatch { poses, ..Default::default() };
        }
        let (parameter_names, parameter_widths) = self.packer.parameter_names();
        pb::PoseBatch { joint_names: self.packer.names(), poses, parameter_names, parameter_widths }
    }
}

/// The one-layer motion a gRPC clip route plays instead of its clip, if it
/// plays one: REST's rule ([`ClipRoute::motion`]), `at` locating the
/// request's `ease`.
async fn route_motion(
    state: &AppState,
    clip_id: &str,
    (character, without_springs): (Option<&str>, bool),
    (playback, ease): (Option<anim::Playback>, i32),
    at: Locate,
) -> Result<Option<(MotionDoc, Field)>, ApiError> {
    let route =
        ClipRoute { id: clip_id, character, springs: !without_springs, playback, ease: (ease != 0).then_some(at) };
    route.motion(state).await
}

/// A gRPC clip route's field, located as `locate` says (`in_pose_body`,
/// `in_batch_message`) but for the spring chains' switch, which the
/// message names `/without_springs`.
fn in_route(locate: Locate) -> impl Fn(Field) -> At {
    move |field| match field {
        Field::Springs => At::Pointer("/without_springs".into()),
        other => locate(other),
    }
}

/// `Sample` of a clip route that plays a motion (on a `character`, or the
/// clip's spring chains: docs/springs.md, “Clip routes”): `SampleMotion`
/// of that motion, as REST's `GET …/pose`, its refusals at the request's
/// field names. `None`: the route plays the clip itself.
///
/// # Errors
/// As `SampleMotion`; `unknown_parameter` for an `ease`.
pub async fn sample_route(
    state: &AppState,
    caller: &Caller,
    req: &pb::SampleRequest,
    coding: AnswerCoding,
) -> Result<Option<pb::Pose>, ApiError> {
    let modes = RawModes::of_enums(req.space, req.playback, req.ease);
    let raw = RawPose { t: Some(Raw::Number(req.time)), modes, format: Some(Raw::Enum(req.format)), at: in_pose_body };
    let modes = (raw.check()?.options.playback, req.ease);
    let on = (req.character.as_deref(), req.without_springs);
    let Some((doc, field)) = route_motion(state, &req.clip_id, on, modes, in_pose_body).await? else {
        return Ok(None);
    };
    let motion = pb::SampleMotionRequest { time: req.time, space: req.space, format: req.format, ..Default::default() };
    let pose = sample_doc(state, caller, doc, motion, coding).await;
    Ok(Some(pose.map_err(|e| at_clip_route_as(e, in_route(in_pose_body), field))?))
}

/// A clip's `SampleBatch` or `SampleStream` as the `SampleMotionBatch` of
/// the motion its route plays, with the route's field that motion's
/// refusals point at. `None`: the route plays the clip itself.
async fn batch_route(
    state: &AppState,
    req: &pb::SampleBatchRequest,
) -> Result<Option<(MotionDoc, pb::SampleMotionBatchRequest, Field)>, ApiError> {
    use pb::sample_batch_request::When as ClipWhen;
    use pb::sample_motion_batch_request::When;
    let (times, range) = match &req.when {
        Some(ClipWhen::Times(t)) => (Some(t), None),
        Some(ClipWhen::Range(r)) => (None, Some(r)),
        None => (None, None),
    };
    let raw = RawBatch::of_message(times, range, RawModes::of_enums(req.space, req.playback, req.ease), req.format);
    let modes = (raw.check(state.config.limits.max_poses)?.options.playback, req.ease);
    let on = (req.character.as_deref(), req.without_springs);
    let Some((doc, field)) = route_motion(state, &req.clip_id, on, modes, in_batch_message).await? else {
        return Ok(None);
    };
    let when = req.when.clone().map(|when| match when {
        ClipWhen::Times(times) => When::Times(times),
        ClipWhen::Range(range) => When::Range(range),
    });
    let motion = pb::SampleMotionBatchRequest { when, space: req.space, format: req.format, ..Default::default() };
    Ok(Some((doc, motion, field)))
}

/// `SampleBatch` of a clip route that plays a motion: `SampleMotionBatch`
/// of it, as REST's `POST …/sample`. `None`: the clip itself.
///
/// # Errors
/// As `SampleMotionBatch`; `unknown_parameter` for an `ease`.
pub async fn sample_batch_route(
    state: &AppState,
    caller: &Caller,
    req: &pb::SampleBatchRequest,
    coding: AnswerCoding,
) -> Result<Option<pb::PoseBatch>, ApiError> {
    let Some((doc, motion, field)) = batch_route(state, req).await? else { return Ok(None) };
    let batch = sample_batch_doc(state, caller, doc, motion, coding).await;
    Ok(Some(batch.map_err(|e| at_clip_route_as(e, in_route(in_batch_message), field))?))
}

/// `SampleStream` of a clip route that plays a motion: that motion's poses
/// in order (one spring simulation through them), priced as
/// `SampleMotionBatch` prices them and charged. `None`: the clip itself.
///
/// # Errors
/// As `SampleMotionBatch` but `use_sample_stream`; `unknown_parameter`
/// for an `ease`.
pub async fn stream_route(
    state: &AppState,
    caller: &Caller,
    req: &pb::SampleBatchRequest,
    coding: AnswerCoding,
) -> Result<Option<(MotionPoses, Ticket)>, ApiError> {
    let Some((doc, motion, field)) = batch_route(state, req).await? else { return Ok(None) };
    let poses = stream_poses(state, caller, doc, motion, coding).await;
    Ok(Some(poses.map_err(|e| at_clip_route_as(e, in_route(in_batch_message), field))?))
}

/// `SampleMotion` over a graph: the ticks up to the last at or before
/// `time` played on the work pool, the last one's pose answered (what
/// `SampleMotionBatch` answers for that tick).
async fn graph_pose(
    state: &AppState,
    caller: &Caller,
    req: &pb::SampleMotionRequest,
    layer: &GraphLayer<'_>,
    coding: AnswerCoding,
) -> Result<pb::Pose, ApiError> {
    let inputs = inputs_from_pb(&req.inputs)?;
    let raw = RawGraphSampling {
        reference: layer.reference,
        stages: &layer.stages,
        inputs: &inputs,
        time: Some(req.time),
        times: None,
        start: None,
        end: None,
        fps: req.fps.map(f64::from),
        format: Some(Raw::Enum(req.format)),
        space: Some(Raw::Enum(req.space)),
        joints: subset(&req.joints),
        parameters: subset(&req.parameters),
        report: req.report,
        at: in_pose_body,
        wire: Wire::Protobuf,
    };
    let sampling = raw.resolve(state, &caller.key()).await?;
    let cost = sampling.cost.compressed(coding.at(sampling.cost.bytes));
    cost.check(&state.config.limits, Field::Time, in_pose_body)?;
    let pack = move |_: &Cancel| GraphPacker::new(sampling).pose(0, true);
    let pose = state.work.spend(&caller.key(), cost.work(), pack).await?;
    state.counters.poses.increment(1);
    Ok(pose)
}

/// `SampleMotionBatch` over a graph: its `range` on the tick grid of
/// `range.fps`, as `POST /v1/samples` plays it.
async fn graph_batch(
    state: &AppState,
    caller: &Caller,
    req: &pb::SampleMotionBatchRequest,
    layer: &GraphLayer<'_>,
    coding: AnswerCoding,
) -> Result<pb::PoseBatch, ApiError> {
    use pb::sample_motion_batch_request::When;
    let inputs = inputs_from_pb(&req.inputs)?;
    let (times, range) = match &req.when {
        Some(When::Times(t)) => (Some(t.values.as_slice()), None),
        Some(When::Range(r)) => (None, Some(r)),
        None => (None, None),
    };
    let raw = RawGraphSampling {
        reference: layer.reference,
        stages: &layer.stages,
        inputs: &inputs,
        time: None,
        times,
        start: range.map(|r| r.start),
        end: range.map(|r| r.end),
        fps: range.map(|r| r.fps),
        format: Some(Raw::Enum(req.format)),
        space: Some(Raw::Enum(req.space)),
        joints: subset(&req.joints),
        parameters: subset(&req.parameters),
        report: req.report,
        at: in_batch_message,
        wire: Wire::Protobuf,
    };
    let sampling = raw.resolve(state, &caller.key()).await?;
    let cost = sampling.cost.compressed(coding.at(sampling.cost.bytes));
    cost.check(&state.config.limits, Field::When, in_batch_message)?;
    if cost.bytes > MAX_UNARY_ANSWER_BYTES {
        let (bytes, limit) = (cost.bytes, MAX_UNARY_ANSWER_BYTES);
        return Err(ApiError::AnswerTooLargeForUnary { bytes, limit, stream: "REST POST /v1/samples" });
    }
    let n = sampling.range.answered();
    let pack = move |cancel: &Cancel| {
        let mut packer = GraphPacker::new(sampling);
        let answered = usize::try_from(n).unwrap_or(usize::MAX);
        let poses = (0..answered).take_while(|_| cancel.proceed()).map(|i| packer.pose(i, false)).collect();
        let joint_names = packer.names();
        pb::PoseBatch { joint_names, poses, parameter_names: Vec::new(), parameter_widths: Vec::new() }
    };
    let batch = state.work.spend(&caller.key(), cost.work(), pack).await?;
    state.counters.poses.increment(n);
    Ok(batch)
}

/// Packs a graph's answered ticks in order (played by [`GraphTicks`]).
struct GraphPacker {
    sampling: GraphSampling,
    ticks: GraphTicks,
    model: Pose,
    matrices: Vec<Mat4>,
}

impl GraphPacker {
    fn new(sampling: GraphSampling) -> GraphPacker {
        GraphPacker { sampling, ticks: GraphTicks::default(), model: Pose::default(), matrices: Vec::new() }
    }

    /// The joint names sent (the subset's, in skeleton order).
    fn names(&self) -> Vec<String> {
        let names = self.sampling.skeleton().names();
        match &self.sampling.joints {
            Some(joints) => joints.iter().map(|&j| names[j].clone()).collect(),
            None => names.to_vec(),
        }
    }

    /// Answered tick `i`'s pose, with its names when `named` and its
    /// report when asked for.
    fn pose(&mut self, i: usize, named: bool) -> pb::Pose {
        let s = &self.sampling;
        let tick = self.ticks.play(s, i);
        let time = tick.time;
        let skeleton = s.skeleton();
        let names = named.then(|| skeleton.names());
        let mut pose = match s.format {
            Format::Trs => {
                let local = tick.pose;
                let pose = if s.space == Space::Model {
                    skeleton.to_model(local, &mut self.model);
                    &self.model
                } else {
                    local
                };
                pose_to_pb(names, pose, time, time as f32, s.space)
            }
            Format::Matrix => {
                skeleton.model_matrices(tick.pose, &mut self.matrices);
                matrices_to_pb(names, &self.matrices, time, time as f32)
            }
            Format::Skinning => {
                skeleton.skinning_matrices(tick.pose, &mut self.matrices);
                matrices_to_pb(names, &self.matrices, time, time as f32)
            }
        };
        pose.graph = s.report.then(|| report_to_proto(&tick.player.report()));
        pose.ik = ik_reports_to_pb(tick.ik);
        pose.root_motion = tick.root_motion.map(root_motion_to_pb);
        match &s.joints {
            Some(joints) => select_joints(pose, joints),
            None => pose,
        }
    }
}

/// Packs a motion's poses in order (root motion runs from each to the next).
struct Packer {
    composed: Composed,
    space: Space,
    format: Format,
    sampler: MotionSampler,
    matrices: Vec<Mat4>,
}

impl Packer {
    fn new(composed: Composed, space: Space, format: Format) -> Packer {
        Packer { composed, space, format, sampler: MotionSampler::new(), matrices: Vec::new() }
    }

    /// The joint names sent (the subset's, in skeleton order).
    fn names(&self) -> Vec<String> {
        let names = self.composed.motion.skeleton().names();
        match &self.composed.joints {
            Some(joints) => joints.iter().map(|&j| names[j].clone()).collect(),
            None => names.to_vec(),
        }
    }

    /// The parameter names and widths sent (the subset's, in the clip's order).
    fn parameter_names(&self) -> (Vec<String>, Vec<u32>) {
        let layout = self.composed.motion.parameters();
        let all: Vec<usize> = (0..layout.len()).collect();
        let shown = self.composed.parameters.as_deref().unwrap_or(&all);
        (
            shown.iter().map(|&p| layout.names()[p].clone()).collect(),
            shown.iter().map(|&p| layout.widths()[p]).collect(),
        )
    }

    /// The pose at `t`, with its names when `named`.
    fn pose(&mut self, t: f64, named: bool) -> pb::Pose {
        let motion = &self.composed.motion;
        let skeleton = motion.skeleton();
        let space = if self.format == Format::Trs { self.space } else { Space::Local };
        let clip_time = motion.sample(t, &MotionOptions { space, ..MotionOptions::default() }, &mut self.sampler);
        let names = named.then(|| skeleton.names());
        let mut pose = match self.format {
            Format::Trs => pose_to_pb(names, self.sampler.pose(), t, clip_time, space),
            Format::Matrix => {
                skeleton.model_matrices(self.sampler.local(), &mut self.matrices);
                matrices_to_pb(names, &self.matrices, t, clip_time)
            }
            Format::Skinning => {
                skeleton.skinning_matrices(self.sampler.local(), &mut self.matrices);
                matrices_to_pb(names, &self.matrices, t, clip_time)
            }
        };
        pose.root_motion = self.sampler.root_motion().map(root_motion_to_pb);
        pose.ik = ik_reports_to_pb(self.sampler.ik_reports());
        let subset = self.composed.parameters.as_deref();
        add_parameters(&mut pose, ParameterValues::of(motion.parameters(), self.sampler.pose(), subset), named);
        match &self.composed.joints {
            Some(joints) => select_joints(pose, joints),
            None => pose,
        }
    }
}
