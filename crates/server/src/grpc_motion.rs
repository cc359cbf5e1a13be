//! The composed-motion RPCs (docs/motion.md): `SampleMotion` and
//! `SampleMotionBatch`, the gRPC mirror of `POST /v1/poses` and
//! `/v1/samples`. The motion message is converted in `wire::proto`, checked
//! and priced by `server::request` (`RawPose`, `RawBatch`, `RawMotion`) with
//! the same codes as REST, charged to the caller and run on the work pool
//! (`server::work`), and each pose is packed from the motion
//! sampler's buffers with its joint subset, root motion and IK reports (the
//! clips' constraints, then the request's `motion.ik`).

use glam::Mat4;

use crate::auth::Caller;
use crate::compression::AnswerCoding;
use crate::error::ApiError;
use crate::request::{
    Composed, Field, Format, MAX_UNARY_ANSWER_BYTES, Raw, RawBatch, RawModes, RawMotion, RawPose, Wire,
    in_batch_message, in_body, in_pose_body,
};
use crate::state::AppState;
use crate::work::Cancel;
use anim::motion::MotionOptions;
use anim::{MotionSampler, Space};
use std::sync::Arc;

use crate::stream::StreamMotion;
use formats::wire::json::ParameterValues;
use formats::wire::motion::MotionDoc;
use formats::wire::proto::{
    add_parameters, ik_reports_to_pb, matrices_to_pb, motion_from_pb, pb, pose_to_pb, root_motion_to_pb, select_joints,
};

/// The request's motion and joints, looked up and built.
async fn compose(
    state: &AppState,
    caller: &Caller,
    motion: Option<&pb::Motion>,
    (joints, parameters): (&[String], &[String]),
    format: Format,
) -> Result<Composed, ApiError> {
    let spec = motion_from_pb(motion.unwrap_or(&pb::Motion::default()))?;
    let joints = (!joints.is_empty()).then_some(joints);
    let parameters = (!parameters.is_empty()).then_some(parameters);
    RawMotion { spec, joints, parameters, format, at: in_body, character: None }.resolve_for(state, &caller.key()).await
}

/// A stream's motion (`StreamRequest.motion`), still to be looked up.
///
/// # Errors
/// The message's enums or numbers out of range, at `/motion/…`.
pub fn raw_motion(motion: &pb::Motion) -> Result<RawMotion<'static>, ApiError> {
    Ok(RawMotion::of(motion_from_pb(motion)?))
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
        let raw = raw_motion(to.unwrap_or(&pb::Motion::default()))?;
        let source = serde_json::to_value(MotionDoc::from_spec(&raw.spec)).map_err(ApiError::internal)?;
        Ok((raw.resolve(state).await?.motion, source))
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
    let modes = RawModes { space: Some(Raw::Enum(req.space)), ..RawModes::default() };
    let checked =
        RawPose { t: Some(Raw::Number(req.time)), modes, format: Some(Raw::Enum(req.format)), at: in_pose_body }
            .check()?;
    let composed = compose(state, caller, req.motion.as_ref(), (&req.joints, &req.parameters), checked.format).await?;
    let cost = composed.cost(&[checked.t], checked.format, Wire::Protobuf);
    let cost = cost.compressed(coding.at(cost.bytes));
    cost.check(&state.config.limits, Field::Time, in_pose_body)?;
    let pack = move |_: &Cancel| Packer::new(&composed, checked.options.space, checked.format).pose(checked.t, true);
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
    use pb::sample_motion_batch_request::When;
    let (times, range) = match &req.when {
        Some(When::Times(t)) => (Some(t), None),
        Some(When::Range(r)) => (None, Some(r)),
        None => (None, None),
    };
    let modes = RawModes { space: Some(Raw::Enum(req.space)), ..RawModes::default() };
    let raw = RawBatch::of_message(times, range, modes, req.format);
    let sampling = raw.check(state.config.limits.max_poses)?;
    let composed = compose(state, caller, req.motion.as_ref(), (&req.joints, &req.parameters), sampling.format).await?;
    let n = sampling.times.len();
    let cost = composed.cost(&sampling.times, sampling.format, Wire::Protobuf);
    let cost = cost.compressed(coding.at(cost.bytes));
    let field = if matches!(req.when, Some(When::Times(_))) { Field::Times } else { Field::When };
    cost.check(&state.config.limits, field, in_batch_message)?;
    if cost.bytes > MAX_UNARY_ANSWER_BYTES {
        let (bytes, limit) = (cost.bytes, MAX_UNARY_ANSWER_BYTES);
        return Err(ApiError::AnswerTooLargeForUnary { bytes, limit, stream: "REST POST /v1/samples" });
    }
    let (space, format) = (sampling.options.space, sampling.format);
    let pack = move |cancel: &Cancel| {
        let mut packer = Packer::new(&composed, space, format);
        let times = sampling.times.iter().take_while(|_| cancel.proceed());
        let poses: Vec<pb::Pose> = times.map(|&t| packer.pose(t, false)).collect();
        let (parameter_names, parameter_widths) = packer.parameter_names();
        pb::PoseBatch { joint_names: packer.names(), poses, parameter_names, parameter_widths }
    };
    let batch = state.work.spend(&caller.key(), cost.work(), pack).await?;
    state.counters.poses.increment(n as u64);
    Ok(batch)
}

/// Packs a motion's poses in order (root motion runs from each to the next).
struct Packer<'a> {
    composed: &'a Composed,
    space: Space,
    format: Format,
    sampler: MotionSampler,
    matrices: Vec<Mat4>,
}

impl<'a> Packer<'a> {
    fn new(composed: &'a Composed, space: Space, format: Format) -> Packer<'a> {
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
