//! Composed poses (docs/motion.md): `POST /v1/poses` (one pose of a motion) and
//! `POST /v1/samples` (many). Both are reads. The body is decoded here, the
//! rules and the motion come from `server::request` (`RawPose`, `RawBatch`,
//! `RawMotion`), the price charged to the caller and poses written on the
//! work pool (`server::work`) straight from the motion sampler's buffers with
//! the joint subset and the root motion; a large answer is sent in pieces
//! as the client reads.

use std::ops::Range;

use axum::extract::State;
use axum::http::HeaderMap;
use axum::response::Response;
use glam::Mat4;
use serde::Deserialize;
use utoipa::ToSchema;

use crate::auth::{CallerKey, ReadAccess};
use crate::compression::AnswerCoding;
use crate::error::ApiError;
use crate::request::{
    Composed, Field, Format, GraphLayer, GraphSampling, GraphTicks, Raw, RawBatch, RawGraphSampling, RawModes,
    RawMotion, RawPose, Wire, graph_layer, in_body, in_pose_body, no_graph_fields, parse_json,
};
use crate::state::AppState;
use crate::work::Cancel;
use anim::motion::MotionOptions;
use anim::{MotionSampler, Pose, Space};
use formats::wire::graph_inputs::{InputDoc, write_report};
use formats::wire::json::{Extras, MatricesJson, ParameterValues, PoseJson, SpaceDoc};
use formats::wire::motion::MotionDoc;

use super::extract::JsonBody;
use super::pieces::{self, Pieces, PoseWriter, json_response};

/// `POST /v1/poses`: one pose of a motion.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PoseOfMotion {
    pub motion: MotionDoc,
    /// Motion time in seconds.
    pub time: f64,
    #[serde(default)]
    #[schema(value_type = Option<SpaceDoc>)]
    pub space: Option<String>,
    #[serde(default)]
    #[schema(value_type = Option<Format>)]
    pub format: Option<String>,
    /// Only these joints (in skeleton order); model space is still computed through the whole hierarchy.
    #[serde(default)]
    pub joints: Option<Vec<String>>,
    /// Only these parameters (docs/clip-format.md §3), in the first layer's clip's order.
    #[serde(default)]
    pub parameters: Option<Vec<String>>,
    /// A graph's timed settings, `[{"time", "set": {name: value}}]` (docs/graphs.md, “Using a graph”).
    #[serde(default)]
    #[schema(value_type = Option<Vec<Object>>)]
    pub inputs: Option<Vec<InputDoc>>,
    /// A graph's tick grid, 1 to 240 (default 60): the pose is the last tick's at or before `time`.
    #[serde(default)]
    pub fps: Option<f64>,
    /// A graph's pose carries the tick's `graph` report.
    #[serde(default)]
    pub report: bool,
}

/// `POST /v1/samples`: many poses of a motion, at `times` or on a frame range.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SamplesOfMotion {
    pub motion: MotionDoc,
    #[serde(default)]
    pub times: Option<Vec<f64>>,
    #[serde(default)]
    pub start: Option<f64>,
    #[serde(default)]
    pub end: Option<f64>,
    #[serde(default)]
    pub fps: Option<f64>,
    #[serde(default)]
    #[schema(value_type = Option<SpaceDoc>)]
    pub space: Option<String>,
    #[serde(default)]
    #[schema(value_type = Option<Format>)]
    pub format: Option<String>,
    #[serde(default)]
    pub joints: Option<Vec<String>>,
    /// Only these parameters (docs/clip-format.md §3), in the first layer's clip's order.
    #[serde(default)]
    pub parameters: Option<Vec<String>>,
    /// A graph's timed settings, `[{"time", "set": {name: value}}]` (docs/graphs.md, “Using a graph”).
    #[serde(default)]
    #[schema(value_type = Option<Vec<Object>>)]
    pub inputs: Option<Vec<InputDoc>>,
    /// A graph's poses carry the tick's `graph` report.
    #[serde(default)]
    pub report: bool,
}

fn text(v: &Option<String>) -> Option<Raw<'_>> {
    v.as_deref().map(Raw::Text)
}

/// The body's motion with its joint and parameter subsets, looked up and built.
async fn compose(
    state: &AppState,
    caller: &CallerKey,
    motion: &MotionDoc,
    (joints, parameters): (&Option<Vec<String>>, &Option<Vec<String>>),
    format: Format,
) -> Result<Composed, ApiError> {
    let raw = RawMotion::of_doc(motion)?;
    let raw = RawMotion { joints: joints.as_deref(), parameters: parameters.as_deref(), format, ..raw };
    raw.resolve_for(state, caller).await
}

/// One pose of a motion (`docs/motion.md`).
#[utoipa::path(
    post, path = "/v1/poses", tag = "poses",
    request_body(content = PoseOfMotion, content_type = "application/json"),
    responses(
        (status = 200, description = "The pose (its `clip` the first layer's), with `root_motion` (delta and total 0) when the motion asks for it; over a graph, the pose of the last tick at or before `time` (its `clip` the graph's id, its `time` the tick's), with the tick's `graph` report when `report` is true", body = super::schemas::PoseSchema),
        (status = 400, description = "Not JSON, or a value that does not parse", body = super::schemas::Problem),
        (status = 404, description = "A layer's clip (`clip_not_found`), graph (`graph_not_found`) or the character does not exist", body = super::schemas::Problem),
        (status = 422, description = "A field of the wrong type or unknown (`invalid_field`); a motion rule at `/motion/…` (`weight_out_of_range`, `speed_out_of_range`, `unknown_joint`, `no_layers`, `too_many_layers`, `no_root_joint`, `incompatible_skeleton` (a layer of another rig), …); a joint of `joints` not in the output skeleton (`unknown_joint`); a name of `parameters` the first layer's clip lacks (`unknown_parameter`); layers' parameters of one name and different widths (`parameter_width_mismatch`); `no_inverse_binds`; the cost model's `too_many_poses`, `too_much_work`, `answer_too_large`; over a graph (docs/graphs.md), `bad_range` (`time` below 0), `fps_out_of_range`, the inputs' `bad_time`, `unknown_parameter`, `parameter_type`, `parameter_out_of_range`, a clip of the graph the motion's `character` cannot map (`unmappable_skeleton` at `/motion/character`) or without its `root_motion` joint (`no_root_joint` at `/motion/root_motion`), and `graph_unsupported` (a motion over a graph takes no second layer, no layer field but its defaults, no `parameters` subset; `inputs`, `report` or `fps` without a graph layer)", body = super::schemas::Problem),
        (status = 429, description = "The caller holds its share of the node's work (`caller_work_limit`, with `Retry-After`)", body = super::schemas::Problem),
        (status = 503, description = "The node's work capacity is taken (`overloaded`, with `Retry-After`); the request outlived `request_timeout_secs` (`request_timeout`)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn pose(
    State(state): State<AppState>,
    ReadAccess(caller): ReadAccess,
    headers: HeaderMap,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let req: PoseOfMotion = parse_json(&body)?;
    answer_pose(state, caller.key(), &headers, req).await
}

/// `POST /v1/poses`'s answer to `req` (also a clip's `GET …/pose` with a
/// `character`, which is this request of a one-layer motion).
pub(super) async fn answer_pose(
    state: AppState,
    caller: CallerKey,
    headers: &HeaderMap,
    req: PoseOfMotion,
) -> Result<Response, ApiError> {
    if let Some(layer) = graph_layer(&req.motion)? {
        return graph_pose(state, caller, headers, &req, &layer).await;
    }
    no_graph_fields(req.report, req.inputs.is_some(), req.fps.is_some())?;
    let modes = RawModes { space: text(&req.space), ..RawModes::default() };
    let raw = RawPose { t: Some(Raw::Number(req.time)), modes, format: text(&req.format), at: in_pose_body };
    let checked = raw.check()?;
    let composed = compose(&state, &caller, &req.motion, (&req.joints, &req.parameters), checked.format).await?;
    let cost = composed.cost(&[checked.t], checked.format, Wire::Json);
    let cost = cost.compressed(AnswerCoding::of(headers, state.config.compression.min_bytes).at(cost.bytes));
    cost.check(&state.config.limits, Field::Time, in_pose_body)?;
    let mut writer = MotionPoses::new(composed, vec![checked.t], checked.options.space, checked.format, cost.bytes);
    writer.warn_in_the_pose();
    let capacity = usize::try_from(cost.bytes).unwrap_or(0).min(1 << 20);
    let body = state
        .work
        .spend(&caller, cost.work(), move |cancel| {
            let mut body = Vec::with_capacity(capacity);
            writer.write(&mut body, 0..1, cancel);
            body
        })
        .await?;
    state.counters.poses.increment(1);
    Ok(json_response(body))
}

/// Many poses of a motion (`docs/motion.md`); each carries its root motion since the previous one.
#[utoipa::path(
    post, path = "/v1/samples", tag = "poses",
    request_body(content = SamplesOfMotion, content_type = "application/json"),
    responses(
        (status = 200, description = "`{\"poses\": [pose, ...]}`, each with `root_motion` when the motion asks for it (the first with delta and total 0); sent chunked, as it is evaluated, when the answer may exceed 1 MiB", body = super::schemas::PosesSchema),
        (status = 400, description = "Not JSON, or a value that does not parse", body = super::schemas::Problem),
        (status = 404, description = "As `POST /v1/poses`: a layer's clip, the graph or the character does not exist", body = super::schemas::Problem),
        (status = 422, description = "As `POST /v1/poses`, and `times_or_range`, `fps_out_of_range`, `bad_range`, `too_many_poses`", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn samples(
    State(state): State<AppState>,
    ReadAccess(caller): ReadAccess,
    headers: HeaderMap,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let req: SamplesOfMotion = parse_json(&body)?;
    answer_samples(state, caller.key(), &headers, req).await
}

/// `POST /v1/samples`'s answer to `req` (also a clip's `POST …/sample` with
/// a `character`, which is this request of a one-layer motion).
pub(super) async fn answer_samples(
    state: AppState,
    caller: CallerKey,
    headers: &HeaderMap,
    req: SamplesOfMotion,
) -> Result<Response, ApiError> {
    if let Some(layer) = graph_layer(&req.motion)? {
        return graph_samples(state, caller, headers, &req, &layer).await;
    }
    no_graph_fields(req.report, req.inputs.is_some(), false)?;
    let raw = RawBatch {
        times: req.times.as_deref(),
        start: req.start,
        end: req.end,
        fps: req.fps,
        modes: RawModes { space: text(&req.space), ..RawModes::default() },
        format: text(&req.format),
        at: in_body,
    };
    let sampling = raw.check(state.config.limits.max_poses)?;
    let composed = compose(&state, &caller, &req.motion, (&req.joints, &req.parameters), sampling.format).await?;
    let n = sampling.times.len();
    let cost = composed.cost(&sampling.times, sampling.format, Wire::Json);
    let cost = cost.compressed(AnswerCoding::of(headers, state.config.compression.min_bytes).at(cost.bytes));
    let field = if req.times.is_some() { Field::Times } else { Field::When };
    cost.check(&state.config.limits, field, in_body)?;
    let (space, format) = (sampling.options.space, sampling.format);
    let mut writer = MotionPoses::new(composed, sampling.times, space, format, cost.bytes);
    if cost.bytes > crate::request::STREAM_ABOVE_BYTES {
        let ticket = state.work.charge(&caller, cost.work())?;
        return Ok(Pieces::new(state, Box::new(writer), ticket).into_response());
    }
    let body = state.work.spend(&caller, cost.work(), move |cancel| pieces::whole(&mut writer, cancel)).await?;
    state.counters.poses.increment(n as u64);
    Ok(json_response(body))
}

/// `POST /v1/samples` over a graph: its ticks played on the work pool, the
/// answered ones written as they are played.
async fn graph_samples(
    state: AppState,
    caller: CallerKey,
    headers: &HeaderMap,
    req: &SamplesOfMotion,
    layer: &GraphLayer<'_>,
) -> Result<Response, ApiError> {
    let raw = RawGraphSampling {
        reference: layer.reference,
        stages: &layer.stages,
        inputs: req.inputs.as_deref().unwrap_or_default(),
        time: None,
        times: req.times.as_deref(),
        start: req.start,
        end: req.end,
        fps: req.fps,
        format: text(&req.format),
        space: text(&req.space),
        joints: req.joints.as_deref(),
        parameters: req.parameters.as_deref(),
        report: req.report,
        at: in_body,
        wire: Wire::Json,
    };
    let sampling = raw.resolve(&state, &caller).await?;
    let coding = AnswerCoding::of(headers, state.config.compression.min_bytes);
    let cost = sampling.cost.compressed(coding.at(sampling.cost.bytes));
    cost.check(&state.config.limits, Field::When, in_body)?;
    let n = sampling.range.answered();
    let mut writer = GraphPoses::new(sampling, cost.bytes);
    if cost.bytes > crate::request::STREAM_ABOVE_BYTES {
        let ticket = state.work.charge(&caller, cost.work())?;
        return Ok(Pieces::new(state, Box::new(writer), ticket).into_response());
    }
    let body = state.work.spend(&caller, cost.work(), move |cancel| pieces::whole(&mut writer, cancel)).await?;
    state.counters.poses.increment(n);
    Ok(json_response(body))
}

/// `POST /v1/poses` over a graph: the ticks up to the last at or before
/// `time` played on the work pool, the last one's pose answered (what
/// `/v1/samples` answers for that tick).
async fn graph_pose(
    state: AppState,
    caller: CallerKey,
    headers: &HeaderMap,
    req: &PoseOfMotion,
    layer: &GraphLayer<'_>,
) -> Result<Response, ApiError> {
    let raw = RawGraphSampling {
        reference: layer.reference,
        stages: &layer.stages,
        inputs: req.inputs.as_deref().unwrap_or_default(),
        time: Some(req.time),
        times: None,
        start: None,
        end: None,
        fps: req.fps,
        format: text(&req.format),
        space: text(&req.space),
        joints: req.joints.as_deref(),
        parameters: req.parameters.as_deref(),
        report: req.report,
        at: in_pose_body,
        wire: Wire::Json,
    };
    let sampling = raw.resolve(&state, &caller).await?;
    let coding = AnswerCoding::of(headers, state.config.compression.min_bytes);
    let cost = sampling.cost.compressed(coding.at(sampling.cost.bytes));
    cost.check(&state.config.limits, Field::Time, in_pose_body)?;
    let mut writer = GraphPoses::new(sampling, cost.bytes);
    let body = state
        .work
        .spend(&caller, cost.work(), move |cancel| {
            let mut body = Vec::new();
            writer.write(&mut body, 0..1, cancel);
            body
        })
        .await?;
    state.counters.poses.increment(1);
    Ok(json_response(body))
}

/// A graph's answered ticks, in order (played by [`GraphTicks`]), as JSON.
struct GraphPoses {
    sampling: GraphSampling,
    bound: u64,
    ticks: GraphTicks,
    model: Pose,
    matrices: Vec<Mat4>,
    report: Vec<u8>,
}

impl GraphPoses {
    fn new(sampling: GraphSampling, bound: u64) -> GraphPoses {
        let (model, matrices, report) = (Pose::default(), Vec::new(), Vec::new());
        GraphPoses { sampling, bound, ticks: GraphTicks::default(), model, matrices, report }
    }

    /// Appends answered pose `i` (tick `range.first + i`).
    fn write_one(&mut self, out: &mut Vec<u8>, i: usize) {
        let s = &self.sampling;
        let tick = self.ticks.play(s, i);
        let time = tick.time;
        self.report.clear();
        if s.report {
            write_report(&mut self.report, &tick.player.report());
        }
        let joints = s.joints.as_deref();
        let root_motion = tick.root_motion;
        let extras = Extras { joints, root_motion, ik: tick.ik, parameters: None, tail: &self.report, feet: &[] };
        let (clip, skeleton) = (s.built.meta.id.as_str(), s.skeleton());
        let clip_time = time as f32;
        match s.format {
            Format::Trs => {
                let pose = if s.space == Space::Model {
                    skeleton.to_model(tick.pose, &mut self.model);
                    &self.model
                } else {
                    tick.pose
                };
                PoseJson { clip, time, clip_time, space: s.space, skeleton, pose }.write_with(out, extras);
            }
            Format::Matrix | Format::Skinning => {
                let skinning = s.format == Format::Skinning;
                if skinning {
                    skeleton.skinning_matrices(tick.pose, &mut self.matrices);
                } else {
                    skeleton.model_matrices(tick.pose, &mut self.matrices);
                }
                let format = if skinning { "skinning" } else { "matrix" };
                let doc = MatricesJson { clip, time, clip_time, format, skeleton, matrices: &self.matrices };
                doc.write_with(out, extras);
            }
        }
    }
}

impl PoseWriter for GraphPoses {
    fn count(&self) -> usize {
        usize::try_from(self.sampling.range.answered()).unwrap_or(usize::MAX)
    }

    fn bound(&self) -> u64 {
        self.bound
    }

    fn write(&mut self, out: &mut Vec<u8>, range: Range<usize>, cancel: &Cancel) {
        for i in range {
            if !cancel.proceed() {
                return;
            }
            if i > 0 {
                out.push(b',');
            }
            self.write_one(out, i);
        }
    }
}

/// A motion's poses at a request's times, in order (root motion runs from
/// each pose to the next).
struct MotionPoses {
    composed: Composed,
    times: Vec<f64>,
    space: Space,
    format: Format,
    bound: u64,
    sampler: MotionSampler,
    matrices: Vec<Mat4>,
    /// The motion's `,"warnings":[…]` after the poses (a samples answer)…
    trailer: Vec<u8>,
    /// …or in the pose (a single pose's answer).
    pose_tail: Vec<u8>,
}

impl MotionPoses {
    fn new(composed: Composed, times: Vec<f64>, space: Space, format: Format, bound: u64) -> MotionPoses {
        let (sampler, matrices) = (MotionSampler::new(), Vec::new());
        let trailer = composed.warnings.clone();
        MotionPoses { composed, times, space, format, bound, sampler, matrices, trailer, pose_tail: Vec::new() }
    }

    /// Puts the warnings in the pose (a single pose's answer) rather than
    /// after the poses.
    fn warn_in_the_pose(&mut self) {
        self.pose_tail = std::mem::take(&mut self.trailer);
    }

    /// Appends pose `k`.
    fn write_one(&mut self, out: &mut Vec<u8>, k: usize) {
        let motion = &self.composed.motion;
        let t = self.times[k];
        let space = if self.format == Format::Trs { self.space } else { Space::Local };
        let clip_time = motion.sample(t, &MotionOptions { space, ..MotionOptions::default() }, &mut self.sampler);
        let extras = Extras {
            joints: self.composed.joints.as_deref(),
            root_motion: self.sampler.root_motion(),
            ik: self.sampler.ik_reports(),
            parameters: ParameterValues::of(
                motion.parameters(),
                self.sampler.pose(),
                self.composed.parameters.as_deref(),
            ),
            tail: &self.pose_tail,
            feet: self.sampler.feet().unwrap_or_default(),
        };
        let (clip, skeleton) = (self.composed.clip_id(), motion.skeleton());
        match self.format {
            Format::Trs => {
                let pose = self.sampler.pose();
                PoseJson { clip, time: t, clip_time, space, skeleton, pose }.write_with(out, extras);
            }
            Format::Matrix | Format::Skinning => {
                let skinning = self.format == Format::Skinning;
                if skinning {
                    skeleton.skinning_matrices(self.sampler.local(), &mut self.matrices);
                } else {
                    skeleton.model_matrices(self.sampler.local(), &mut self.matrices);
                }
                let format = if skinning { "skinning" } else { "matrix" };
                let doc = MatricesJson { clip, time: t, clip_time, format, skeleton, matrices: &self.matrices };
                doc.write_with(out, extras);
            }
        }
    }
}

impl PoseWriter for MotionPoses {
    fn count(&self) -> usize {
        self.times.len()
    }

    fn bound(&self) -> u64 {
        self.bound
    }

    fn trailer(&self) -> &[u8] {
        &self.trailer
    }

    fn write(&mut self, out: &mut Vec<u8>, range: Range<usize>, cancel: &Cancel) {
        for k in range {
            if !cancel.proceed() {
                return;
            }
            if k > 0 {
                out.push(b',');
            }
            self.write_one(out, k);
        }
    }
}
