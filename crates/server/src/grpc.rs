//! The gRPC API (docs/api.md): service `inbetween.v1.Animation`, plus
//! `grpc.health.v1` and server reflection (v1 and v1alpha).
//!
//! Every RPC runs on the same state as REST: the same store, clip cache,
//! limits, tokens and `ApiError` (mapped to a `tonic::Status` in
//! `server::error`, beside its problem+json mapping). Sample, stream and list
//! requests are only decoded here and checked by `server::request`, so they
//! fail with REST's codes. Writes need a token
//! with the write scope as metadata `authorization: Bearer <token>`; reads the
//! read scope when reads are guarded (`server::auth`). Streams come from the shared streaming engine
//! (`crate::stream`), so gRPC and WebSocket viewers of the same playback
//! share one evaluation per tick.
//!
//! Served on its own port (`--grpc-listen`, default 127.0.0.1:50051) by
//! `tonic::transport::Server`, which keeps tonic's HTTP/2 keepalive and
//! concurrency settings; it shuts down with the HTTP server.

use std::pin::Pin;
use std::sync::Arc;

use futures_util::{Stream, StreamExt};
use tokio::sync::oneshot;
use tonic::metadata::MetadataMap;
use tonic::{Request, Response, Status, Streaming};

use crate::auth::{Caller, Identity, Scope};
use crate::cache::CachedClip;
use crate::compression::{AnswerCoding, grpc_answer};
use crate::error::{ApiError, At};
use crate::grpc_motion::PosesJob;
use crate::request::{
    Field, Format, GraphStages, MAX_UNARY_ANSWER_BYTES, Opening, Page, Raw, RawBatch, RawGraphStream, RawModes,
    RawPage, RawPose, RawStream, Sampling, Wire, clip as request_clip, evaluate, graph_layer, in_body, in_pose_body,
};
use crate::rest::skeleton::ClipSkeleton;
use crate::state::AppState;
use crate::store::{ClipMeta, OnName, is_clip_id};
use crate::stream::{self, Control, ControlError, Engine, StreamParams, WireFrame};
use crate::work::{Cancel, Ticket};
use anim::{SampleOptions, Sampler};
use formats::import::warning::in_document;
use formats::wire::json::{ClipDoc, ParameterValues, parse_clip_doc};
use formats::wire::proto::server::animation_server::{Animation, AnimationServer};
use formats::wire::proto::{
    FILE_DESCRIPTOR_SET, add_parameters, clip_from_pb, clip_to_pb, ik_reports_to_pb, matrices_to_pb, pb,
    playback_to_pb, pose_to_pb,
};

/// The `Animation` service.
#[derive(Clone)]
pub struct GrpcService {
    state: AppState,
    engine: Engine,
}

/// The gRPC routes: the service, health and reflection.
///
/// # Errors
/// The embedded descriptor set does not parse (it always does).
pub async fn routes(state: AppState, engine: Engine) -> anyhow::Result<tonic::service::Routes> {
    let (reporter, health) = tonic_health::server::health_reporter();
    reporter.set_serving::<AnimationServer<GrpcService>>().await;
    let reflection_v1 = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1()?;
    let reflection_v1alpha = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1alpha()?;
    let codings = state.config.compression;
    let service = crate::compression::grpc(AnimationServer::new(GrpcService { state, engine }), codings);
    Ok(tonic::service::Routes::new(service)
        .add_service(health)
        .add_service(reflection_v1)
        .add_service(reflection_v1alpha))
}

fn bearer(metadata: &MetadataMap) -> Option<&[u8]> {
    metadata.get("authorization").map(|v| v.as_bytes())
}

impl GrpcService {
    /// A `SampleBatchRequest` whose route plays the clip itself (no
    /// character, no chains running: `grpc_motion::batch_route`) checked and
    /// bound to its clip (`SampleBatch` and `SampleStream` alike).
    async fn sampling(&self, request: &Request<pb::SampleBatchRequest>) -> Result<(Sampling, Arc<CachedClip>), Status> {
        use pb::sample_batch_request::When;
        let (req, coding) = (request.get_ref(), AnswerCoding::of_grpc(request));
        let (times, range) = match &req.when {
            Some(When::Times(t)) => (Some(t), None),
            Some(When::Range(r)) => (None, Some(r)),
            None => (None, None),
        };
        let raw = RawBatch::of_message(times, range, RawModes::of_enums(req.space, req.playback, req.ease), req.format);
        Ok(raw.resolve(&self.state, &req.clip_id, Wire::Protobuf, coding).await?)
    }

    /// The RPC's caller (worked out once per call, as REST's middleware
    /// does), if it may act with `scope`.
    /// The admission layer (`shed::GrpcLayer`) has identified it already;
    /// without that layer, the peer address alone counts.
    fn caller<T>(&self, request: &Request<T>, scope: Scope) -> Result<Caller, Status> {
        if let Some(identity) = request.extensions().get::<Identity>() {
            return Ok(identity.authorize(scope)?);
        }
        let addr = request.remote_addr().map(|a| a.ip());
        Ok(self.state.auth.identify(bearer(request.metadata()), addr).authorize(scope)?)
    }

    fn read<T>(&self, request: &Request<T>) -> Result<Caller, Status> {
        self.caller(request, Scope::Read)
    }

    /// Checks the write scope, then the caller's write rate (shared with REST).
    fn write<T>(&self, request: &Request<T>) -> Result<(), Status> {
        let caller = self.caller(request, Scope::Write)?;
        Ok(self.state.writes.admit(&caller)?)
    }

    /// Checks a stream request, binds it to its clip and admits it.
    async fn stream_params(
        &self,
        req: &pb::StreamRequest,
        paused: bool,
        caller: &Caller,
    ) -> Result<(StreamParams, stream::StreamPermit), Status> {
        let raw = RawStream {
            fps: Some(Raw::Number(f64::from(req.fps))),
            start: req.start_time.map(Raw::Number),
            speed: req.speed.map(Raw::Number),
            modes: RawModes::of_enums(req.space, req.playback, req.ease),
            // `Frame`s with a pose, or with compact bytes.
            encoding: Some(Raw::Enum(req.encoding)),
            max_error: req.max_error.map(Raw::Number),
            distance: req.distance.map(Raw::Number),
            // 0: no limit.
            max_frames: (req.max_frames > 0).then_some(Raw::Number(req.max_frames as f64)),
            paused,
            springs: !req.without_springs,
            joints: (!req.joints.is_empty()).then_some(req.joints.as_slice()),
            parameters: (!req.parameters.is_empty()).then_some(req.parameters.as_slice()),
            at: stream_at,
        };
        let graph = req.motion.as_ref().map(graph_of_pb).transpose()?.flatten();
        if req.report && graph.is_none() {
            let detail = "`report` is a graph stream's: the motion's layer names no `graph`";
            return Err(ApiError::invalid("graph_unsupported", "/report", detail).into());
        }
        // Unspecified (0) is no playback; any other is refused as on the WebSocket.
        let playback = (req.playback != 0).then_some(Raw::Enum(req.playback));
        if req.motion.is_some() && req.without_springs {
            let detail = "`without_springs` is a clip stream's: a motion names its own spring chains".to_owned();
            let at = At::Pointer("/without_springs".into());
            return Err(ApiError::BadParameter { code: "unknown_parameter", at, detail }.into());
        }
        let opening = match (&req.motion, graph) {
            (None, _) => raw.open(&self.state, &req.clip_id, caller).await?,
            (Some(_), _) if !req.clip_id.is_empty() => {
                let detail = "give `clip_id` or `motion`, not both";
                return Err(ApiError::invalid("clip_or_motion", "/motion", detail).into());
            }
            (Some(_), Some((reference, stages))) => {
                let raw = RawStream { modes: RawModes { playback, ..raw.modes }, ..raw };
                let graph = RawGraphStream { reference: &reference, stages: &stages, report: req.report };
                raw.open_graph(&self.state, graph, caller).await?
            }
            (Some(motion), None) => {
                let motion = super::grpc_motion::raw_motion(motion)?;
                let raw = RawStream { modes: RawModes { playback, ..raw.modes }, ..raw };
                raw.open_motion(&self.state, motion, caller).await?
            }
        };
        let Opening { params, permit } = opening.map_err(ApiError::from)?;
        Ok((params, permit))
    }
}

/// The graph a stream's motion plays (docs/graphs.md), when a layer names
/// one: checked as a JSON motion's graph layer is (`request::graph_layer`),
/// with the same codes at the same pointers.
///
/// # Errors
/// `graph_unsupported` at the field a graph does not take; the motion's
/// enums out of range.
fn graph_of_pb(motion: &pb::Motion) -> Result<Option<(String, GraphStages)>, ApiError> {
    if motion.layers.iter().all(|l| l.graph.is_empty()) {
        return Ok(None);
    }
    let doc = formats::wire::proto_motion::motion_doc_from_pb(motion)?;
    Ok(graph_layer(&doc)?.map(|layer| (layer.reference.to_owned(), layer.stages)))
}

/// Bytes of poses per `SampleStream` message (at least one pose).
const STREAM_BATCH_BYTES: u64 = 1024 * 1024;

/// The poses `range` of `sampling` as one `PoseBatch`, names if `names`.
/// Stops early (fewer poses) once `cancel` is raised.
fn batch(
    cached: &CachedClip,
    sampling: &Sampling,
    range: std::ops::Range<usize>,
    names: bool,
    cancel: &Cancel,
) -> pb::PoseBatch {
    let (mut sampler, mut matrices) = (Sampler::new(), Vec::new());
    let (options, format) = (sampling.options, sampling.format);
    let layout = cached.clip.parameters();
    pb::PoseBatch {
        joint_names: if names { cached.clip.skeleton().names().to_vec() } else { Vec::new() },
        parameter_names: if names { layout.names().to_vec() } else { Vec::new() },
        parameter_widths: if names { layout.widths().to_vec() } else { Vec::new() },
        poses: sampling.times[range]
            .iter()
            .take_while(|_| cancel.proceed())
            .map(|&t| pose(cached, t, &options, format, false, &mut sampler, &mut matrices))
            .collect(),
    }
}

/// A clip's poses, each evaluated on its own.
struct ClipPoses {
    sampling: Sampling,
    cached: Arc<CachedClip>,
}

impl PosesJob for ClipPoses {
    fn count(&self) -> usize {
        self.sampling.times.len()
    }

    fn answer_bytes(&self) -> u64 {
        self.sampling.answer_bytes
    }

    fn batch(&mut self, range: std::ops::Range<usize>, names: bool, cancel: &Cancel) -> pb::PoseBatch {
        batch(&self.cached, &self.sampling, range, names, cancel)
    }
}

/// A `SampleStream` answer, evaluated a message at a time: the next
/// message is evaluated (on the work pool) only when tonic asks for it,
/// which HTTP/2 flow control holds back while the client does not read; a
/// client that goes away (or a cancelled call) drops the stream and the
/// rest of the work with it (counted as abandoned).
struct Batches {
    state: AppState,
    /// The answer's price, charged until it is sent or dropped.
    _ticket: Ticket,
    /// Away on the pool while a message is evaluated.
    job: Option<Box<dyn PosesJob>>,
    count: usize,
    per_batch: usize,
    next: usize,
    done: bool,
}

impl Batches {
    fn new(state: AppState, job: Box<dyn PosesJob>, ticket: Ticket) -> Batches {
        let count = job.count();
        let per_pose = job.answer_bytes() / count.max(1) as u64;
        let per_batch = (STREAM_BATCH_BYTES / per_pose.max(1)).max(1) as usize;
        Batches { state, _ticket: ticket, job: Some(job), count, per_batch, next: 0, done: false }
    }

    /// The next message, `None` after the last. An empty request is one
    /// message with the names and no poses.
    async fn next(&mut self) -> Option<Result<pb::PoseBatch, Status>> {
        let mut job = self.job.take().filter(|_| !self.done)?;
        let range = self.next..(self.next + self.per_batch).min(self.count);
        let deadline = self.state.config.limits.request_timeout;
        let built = self
            .state
            .work
            .pool()
            .run(deadline, move |cancel| {
                let names = range.start == 0;
                let batch = job.batch(range, names, cancel);
                (job, batch)
            })
            .await;
        Some(match built {
            Ok((job, batch)) => {
                self.state.counters.poses.increment(batch.poses.len() as u64);
                self.next += batch.poses.len();
                self.done = self.next == self.count;
                self.job = Some(job);
                Ok(batch)
            }
            Err(e) => {
                self.done = true;
                Err(Status::from(e))
            }
        })
    }
}

impl Drop for Batches {
    fn drop(&mut self) {
        if !self.done {
            self.state.counters.answers_abandoned.increment(1);
            self.state.counters.poses_abandoned.increment((self.count - self.next) as u64);
        }
    }
}

/// Where the fields of `StreamRequest` sit.
fn stream_at(field: Field) -> At {
    match field {
        Field::Start => At::Pointer("/start_time".into()),
        other => in_body(other),
    }
}

/// `PutClipRequest.metadata_json`: empty for none, else a JSON object.
///
/// # Errors
/// `malformed_json` (not JSON), `bad_metadata` (not an object), both at
/// `/metadata_json`.
fn metadata_from_pb(text: &str) -> Result<Option<serde_json::Map<String, serde_json::Value>>, ApiError> {
    if text.is_empty() {
        return Ok(None);
    }
    let at = "/metadata_json".to_owned();
    match serde_json::from_str(text) {
        Ok(serde_json::Value::Object(m)) => Ok(Some(m)),
        Ok(_) => Err(ApiError::invalid("bad_metadata", at, "metadata_json must be a JSON object")),
        Err(e) => Err(ApiError::MalformedJson { pointer: at, detail: format!("metadata_json is not JSON: {e}") }),
    }
}

/// Summary of a stored clip, as in REST.
fn summary(meta: &ClipMeta) -> pb::ClipSummary {
    let s = &meta.stats;
    pb::ClipSummary {
        id: meta.id.clone(),
        name: meta.name.clone(),
        version: meta.version,
        joints: s.joints,
        tracks: s.tracks,
        start: s.start,
        end: s.end,
        playback: playback_to_pb(s.playback) as i32,
        events: s.events,
        tags: meta.tags.clone(),
        warnings: Vec::new(),
    }
}

/// A clip's skeleton as REST's `GET /v1/clips/{id}/skeleton` has it.
fn skeleton_to_pb(cached: &CachedClip) -> pb::ClipSkeleton {
    let doc = ClipSkeleton::of(cached);
    let part = |v: Option<&[f32]>| v.map(<[f32]>::to_vec).unwrap_or_default();
    let joints = (doc.joints.into_iter())
        .map(|j| pb::Joint {
            name: j.name,
            parent: j.parent,
            rest: Some(pb::Transform {
                translation: part(j.rest.translation.as_ref().map(|a| a.as_slice())),
                rotation: part(j.rest.rotation.as_ref().map(|a| a.as_slice())),
                scale: part(j.rest.scale.as_ref().map(|a| a.as_slice())),
            }),
            inverse_bind: Vec::new(),
        })
        .collect();
    pb::ClipSkeleton {
        summary: Some(summary(&cached.meta)),
        skeleton: Some(pb::Skeleton { joints }),
        parameters: doc.parameters,
        inverse_binds: doc.inverse_binds,
    }
}

/// One pose of `cached` at `t`, names included if `names`.
fn pose(
    cached: &CachedClip,
    t: f64,
    options: &SampleOptions,
    format: Format,
    names: bool,
    sampler: &mut Sampler,
    matrices: &mut Vec<glam::Mat4>,
) -> pb::Pose {
    let clip = &cached.clip;
    let names = names.then(|| clip.skeleton().names());
    let clip_time = evaluate(clip, t, options, format, sampler, matrices);
    let mut pose = match format {
        Format::Trs => pose_to_pb(names, sampler.pose(), t, clip_time, options.space),
        Format::Matrix | Format::Skinning => matrices_to_pb(names, matrices, t, clip_time),
    };
    pose.ik = ik_reports_to_pb(sampler.ik_reports());
    add_parameters(&mut pose, ParameterValues::of(clip.parameters(), sampler.pose(), None), names.is_some());
    pose
}

type FrameStream = Pin<Box<dyn Stream<Item = Result<WireFrame, Status>> + Send + 'static>>;

/// A `Play` control; a crossfade's motion is looked up (and pinned) here,
/// its refusals carrying their own codes (`clip_not_found` …) at `/to/…`;
/// an `ik` control's constraints are shaped here (pointers under
/// `/constraints`, as on the WebSocket) and checked against the stream's
/// skeleton by the subscription.
async fn control_from_pb(state: &AppState, op: Option<pb::playback_control::Op>) -> Result<Control, Status> {
    match stream::ParsedControl::from_pb(op).map_err(ApiError::from)? {
        stream::ParsedControl::Ready(control) => Ok(control),
        stream::ParsedControl::Crossfade { to, duration, ease } => {
            let (to, source) = super::grpc_motion::crossfade_target(state, to.as_ref()).await?;
            let source = Some(Arc::new(source));
            Ok(Control::Crossfade(stream::Crossfade { to, duration, ease, source }))
        }
    }
}

/// A `Play` message that cannot be obeyed: `bad_control`, as on the WebSocket.
fn bad_control(detail: impl Into<String>) -> Status {
    ApiError::invalid("bad_control", "", detail).into()
}

/// A control the stream refused, with the code and pointer the WebSocket
/// sends (`bad_control`, or an IK rule's code at `/constraints/…`); a work
/// limit's with its own status (`RESOURCE_EXHAUSTED` for the caller's
/// share, `UNAVAILABLE` for the node's capacity).
fn refused(e: &ControlError) -> Status {
    ApiError::from_control(e).into()
}

#[tonic::async_trait]
impl Animation for GrpcService {
    async fn sample(&self, request: Request<pb::SampleRequest>) -> Result<Response<pb::Pose>, Status> {
        let (caller, coding) = (self.read(&request)?, AnswerCoding::of_grpc(&request));
        let req = request.into_inner();
        if let Some(pose) = super::grpc_motion::sample_route(&self.state, &caller, &req, coding).await? {
            return Ok(grpc_answer(pose));
        }
        let raw = RawPose {
            t: Some(Raw::Number(req.time)),
            modes: RawModes::of_enums(req.space, req.playback, req.ease),
            format: Some(Raw::Enum(req.format)),
            at: in_pose_body,
        };
        let (sample, cached) = raw.resolve(&self.state, &req.clip_id, Wire::Protobuf, coding).await?;
        let (t, options, format) = (sample.t, sample.options, sample.format);
        let evaluate = move |_: &Cancel| pose(&cached, t, &options, format, true, &mut Sampler::new(), &mut Vec::new());
        let pose = self.state.work.spend(&caller.key(), sample.work, evaluate).await?;
        self.state.counters.poses.increment(1);
        Ok(grpc_answer(pose))
    }

    async fn sample_motion(&self, request: Request<pb::SampleMotionRequest>) -> Result<Response<pb::Pose>, Status> {
        let (caller, coding) = (self.read(&request)?, AnswerCoding::of_grpc(&request));
        Ok(grpc_answer(super::grpc_motion::sample(&self.state, &caller, request.into_inner(), coding).await?))
    }

    async fn sample_motion_batch(
        &self,
        request: Request<pb::SampleMotionBatchRequest>,
    ) -> Result<Response<pb::PoseBatch>, Status> {
        let (caller, coding) = (self.read(&request)?, AnswerCoding::of_grpc(&request));
        Ok(grpc_answer(super::grpc_motion::sample_batch(&self.state, &caller, request.into_inner(), coding).await?))
    }

    async fn sample_batch(&self, request: Request<pb::SampleBatchRequest>) -> Result<Response<pb::PoseBatch>, Status> {
        let (caller, coding) = (self.read(&request)?, AnswerCoding::of_grpc(&request));
        let route = super::grpc_motion::sample_batch_route(&self.state, &caller, request.get_ref(), coding);
        if let Some(batch) = route.await? {
            return Ok(grpc_answer(batch));
        }
        let (sampling, cached) = self.sampling(&request).await?;
        if sampling.answer_bytes > MAX_UNARY_ANSWER_BYTES {
            let (bytes, limit) = (sampling.answer_bytes, MAX_UNARY_ANSWER_BYTES);
            return Err(ApiError::AnswerTooLargeForUnary { bytes, limit, stream: "SampleStream" }.into());
        }
        let (n, work) = (sampling.times.len(), sampling.work);
        let build = move |cancel: &Cancel| batch(&cached, &sampling, 0..n, true, cancel);
        let batch = self.state.work.spend(&caller.key(), work, build).await?;
        if batch.poses.len() < n {
            // Cancelled: the call is gone, nobody reads this.
            return Err(Status::cancelled("the call was cancelled"));
        }
        self.state.counters.poses.increment(n as u64);
        Ok(grpc_answer(batch))
    }

    type SampleStreamStream = Pin<Box<dyn Stream<Item = Result<pb::PoseBatch, Status>> + Send + 'static>>;

    async fn sample_stream(
        &self,
        request: Request<pb::SampleBatchRequest>,
    ) -> Result<Response<Self::SampleStreamStream>, Status> {
        let (caller, coding) = (self.read(&request)?, AnswerCoding::of_grpc(&request));
        let route = super::grpc_motion::stream_route(&self.state, &caller, request.get_ref(), coding).await?;
        let (job, ticket): (Box<dyn PosesJob>, Ticket) = match route {
            Some((poses, ticket)) => (Box::new(poses), ticket),
            None => {
                let (sampling, cached) = self.sampling(&request).await?;
                let ticket = self.state.work.charge(&caller.key(), sampling.work)?;
                (Box::new(ClipPoses { sampling, cached }), ticket)
            }
        };
        let batches = Batches::new(self.state.clone(), job, ticket);
        let stream = futures_util::stream::unfold(batches, |mut batches| async move {
            let next = batches.next().await?;
            Some((next, batches))
        });
        Ok(Response::new(Box::pin(stream)))
    }

    type StreamFramesStream = FrameStream;

    async fn stream_frames(
        &self,
        request: Request<pb::StreamRequest>,
    ) -> Result<Response<Self::StreamFramesStream>, Status> {
        let caller = self.read(&request)?;
        let lane = lane(&request);
        let (params, permit) = self.stream_params(request.get_ref(), false, &caller).await?;
        let sub = self.engine.watch(params, permit, lane);
        let phase_ms = sub.grid().phase_ms;
        Ok(with_phase(Response::new(Box::pin(stream::grpc::frames(sub))), phase_ms))
    }

    type PlayStream = FrameStream;

    async fn play(
        &self,
        request: Request<Streaming<pb::PlaybackControl>>,
    ) -> Result<Response<Self::PlayStream>, Status> {
        let caller = self.read(&request)?;
        let lane = lane(&request);
        let may_write = self.caller(&request, Scope::Write);
        let mut inbound = request.into_inner();
        let open = match inbound.message().await? {
            Some(pb::PlaybackControl { op: Some(pb::playback_control::Op::Open(open)) }) => open,
            Some(pb::PlaybackControl { op: Some(pb::playback_control::Op::Broadcast(bind)) }) => {
                return self.play_broadcast(&bind.broadcast_id, may_write?, inbound).await;
            }
            Some(_) => return Err(bad_control("the first message of Play must be `open`")),
            None => return Err(bad_control("Play needs an `open` message first")),
        };
        let stream_req = open.stream.ok_or_else(|| bad_control("`open` needs a `stream`"))?;
        let (params, permit) = self.stream_params(&stream_req, open.paused, &caller).await?;
        let sub = self.engine.play(params, permit, lane);
        let phase_ms = sub.grid().phase_ms;
        let mut controller = sub.controller().expect("a Play subscription is private");
        let (abort_tx, abort_rx) = oneshot::channel::<Status>();
        let state = self.state.clone();
        // Reads the client's controls until it half-closes, errs, or the
        // playback ends (then `closed` resolves); never outlives the stream.
        crate::panics::spawn_guarded("grpc_play_controls", async move {
            loop {
                let message = tokio::select! {
                    m = inbound.message() => m,
                    _ = controller.closed() => return,
                };
                match message {
                    Ok(Some(msg)) => {
                        let sent = match control_from_pb(&state, msg.op).await {
                            Ok(c) => controller.send(c).await.map_err(|e| refused(&e)),
                            Err(status) => Err(status),
                        };
                        match sent {
                            Ok(true) => {}
                            Ok(false) => return,
                            Err(status) => {
                                let _ = abort_tx.send(status);
                                return;
                            }
                        }
                    }
                    Ok(None) | Err(_) => return,
                }
            }
        });
        Ok(with_phase(Response::new(Box::pin(with_abort(stream::grpc::frames(sub), abort_rx))), phase_ms))
    }

    type WatchStream = FrameStream;

    async fn watch(&self, request: Request<pb::WatchRequest>) -> Result<Response<Self::WatchStream>, Status> {
        let caller = self.read(&request)?;
        let req = request.get_ref();
        let b = live_broadcast(&self.state, &req.broadcast_id).await?;
        let compact = match req.encoding {
            0 | 1 => None,
            2 => {
                let asked = (req.max_error.map(Raw::Number), req.distance.map(Raw::Number));
                Some(crate::request::compact_watch(&self.state, &b, asked, in_body, &caller).await?)
            }
            n => {
                let detail = format!("`encoding`: unknown frame encoding {n}");
                return Err(ApiError::BadParameter {
                    code: "bad_parameter",
                    at: At::Pointer("/encoding".into()),
                    detail,
                }
                .into());
            }
        };
        let permit = self.engine.admit_for(caller.addr, caller.token.clone()).map_err(ApiError::from)?;
        let Some((layout, ticket)) = compact else {
            let sub = b.watch(stream::Encoding::Protobuf, permit, None);
            return Ok(with_phase(Response::new(Box::pin(stream::grpc::frames(sub))), b.phase_ms()));
        };
        let sub = b.watch_compact(layout, permit, None).map_err(|e| ApiError::Invalid {
            code: e.code,
            at: At::Pointer(format!("/{}", e.field)),
            detail: e.detail,
        })?;
        // The compact encoding's price is held while the viewer watches.
        let frames = stream::grpc::frames(sub).map(move |frame| {
            let _held = &ticket;
            frame
        });
        Ok(with_phase(Response::new(Box::pin(frames)), b.phase_ms()))
    }

    async fn get_clip(&self, request: Request<pb::GetClipRequest>) -> Result<Response<pb::ClipRecord>, Status> {
        self.read(&request)?;
        let id = &request.get_ref().clip_id;
        if !is_clip_id(id) {
            return Err(ApiError::NotFound { what: "clip" }.into());
        }
        let stored =
            self.state.store.get(id).await.map_err(ApiError::from)?.ok_or(ApiError::NotFound { what: "clip" })?;
        let doc: ClipDoc = parse_clip_doc(stored.doc_json.as_bytes())
            .map_err(|e| ApiError::internal(anyhow::anyhow!("stored clip {id} no longer parses: {e}")))?;
        let spec = doc.to_spec().map_err(|e| ApiError::internal(anyhow::anyhow!("stored clip {id}: {e}")))?;
        let metadata_json = doc.metadata.map(|m| serde_json::Value::Object(m).to_string()).unwrap_or_default();
        let (summary, clip) = (Some(summary(&stored.meta)), Some(clip_to_pb(&spec)));
        Ok(grpc_answer(pb::ClipRecord { summary, clip, metadata_json }))
    }

    async fn get_skeleton(&self, request: Request<pb::GetClipRequest>) -> Result<Response<pb::ClipSkeleton>, Status> {
        self.read(&request)?;
        let cached = request_clip(&self.state, &request.get_ref().clip_id).await?;
        Ok(grpc_answer(skeleton_to_pb(&cached)))
    }

    async fn get_mesh(&self, request: Request<pb::GetClipRequest>) -> Result<Response<pb::ClipMesh>, Status> {
        self.read(&request)?;
        let id = &request.get_ref().clip_id;
        if !is_clip_id(id) {
            return Err(ApiError::NotFound { what: "clip" }.into());
        }
        let store = &self.state.store;
        store.mesh_tag(id).await.map_err(ApiError::from)?.ok_or(ApiError::NotFound { what: "clip" })?;
        let mesh = store.mesh(id).await.map_err(ApiError::from)?.ok_or(ApiError::NotFound { what: "mesh" })?;
        Ok(grpc_answer(pb::ClipMesh { data: mesh.bytes.into(), etag: mesh.etag }))
    }

    async fn list_clips(
        &self,
        request: Request<pb::ListClipsRequest>,
    ) -> Result<Response<pb::ListClipsResponse>, Status> {
        self.read(&request)?;
        let req = request.into_inner();
        let raw = RawPage {
            // 0: the default.
            limit: (req.limit > 0).then_some(Raw::Number(f64::from(req.limit))),
            cursor: (!req.cursor.is_empty()).then_some(req.cursor.as_str()),
            name: (!req.name.is_empty()).then_some(req.name.as_str()),
            name_prefix: (!req.name_prefix.is_empty()).then_some(req.name_prefix.as_str()),
            name_contains: (!req.name_contains.is_empty()).then_some(req.name_contains.as_str()),
            tag: (!req.tag.is_empty()).then_some(req.tag.as_str()),
            min_duration: req.min_duration.map(Raw::Number),
            max_duration: req.max_duration.map(Raw::Number),
            compatible_with: (!req.compatible_with.is_empty()).then_some(req.compatible_with.as_str()),
            at: in_body,
        };
        let Page { clips, next_cursor } = raw.read(&self.state).await?;
        let clips = clips.iter().map(summary).collect();
        Ok(grpc_answer(pb::ListClipsResponse { clips, next_cursor: next_cursor.unwrap_or_default() }))
    }

    async fn put_clip(&self, request: Request<pb::PutClipRequest>) -> Result<Response<pb::ClipSummary>, Status> {
        let caller = self.caller(&request, Scope::Write)?;
        self.state.writes.admit(&caller)?;
        let req = request.into_inner();
        let clip = req.clip.ok_or_else(|| ApiError::invalid("missing_clip", "/clip", "a PutClip needs a clip"))?;
        let spec = clip_from_pb(&clip).map_err(ApiError::from)?;
        let mut doc = ClipDoc::from_spec(&spec);
        doc.tags = req.tags;
        doc.metadata = metadata_from_pb(&req.metadata_json)?;
        let limits = &self.state.config.limits;
        let admitted = crate::builds::document(&self.state.work, &caller.key(), limits, doc).await?;
        let meta = if req.clip_id.is_empty() {
            let on_name = if req.replace { OnName::Replace } else { OnName::Refuse };
            self.state.store.create(admitted.new_clip, on_name).await.map_err(ApiError::from)?
        } else {
            if !is_clip_id(&req.clip_id) {
                return Err(ApiError::NotFound { what: "clip" }.into());
            }
            self.state.store.replace(&req.clip_id, admitted.new_clip, req.if_version).await.map_err(ApiError::from)?
        };
        tracing::info!(id = %meta.id, version = meta.version, warnings = admitted.lints.len(), "clip written over gRPC");
        let mut reply = summary(&meta);
        reply.warnings = (in_document(&admitted.lints).into_iter())
            .map(|w| pb::Warning { code: w.code, pointer: w.pointer, detail: w.detail })
            .collect();
        self.state.cache_written(Arc::new(CachedClip { meta, clip: admitted.clip, springs: admitted.springs }));
        Ok(grpc_answer(reply))
    }

    async fn delete_clip(
        &self,
        request: Request<pb::DeleteClipRequest>,
    ) -> Result<Response<pb::DeleteClipResponse>, Status> {
        self.write(&request)?;
        let id = request.into_inner().clip_id;
        if !is_clip_id(&id) {
            return Err(ApiError::NotFound { what: "clip" }.into());
        }
        self.state.store.delete(&id, None).await.map_err(ApiError::from)?;
        self.state.cache_invalidate(&id);
        tracing::info!(%id, "clip deleted over gRPC");
        Ok(grpc_answer(pb::DeleteClipResponse {}))
    }

    async fn create_character(
        &self,
        request: Request<pb::CreateCharacterRequest>,
    ) -> Result<Response<pb::CharacterSummary>, Status> {
        let caller = self.caller(&request, Scope::Write)?;
        self.state.writes.admit(&caller)?;
        Ok(Response::new(super::grpc_character::create(&self.state, &caller, request.into_inner()).await?))
    }

    async fn get_character(
        &self,
        request: Request<pb::GetCharacterRequest>,
    ) -> Result<Response<pb::CharacterRecord>, Status> {
        self.read(&request)?;
        Ok(Response::new(super::grpc_character::get(&self.state, request.into_inner()).await?))
    }

    async fn list_characters(
        &self,
        request: Request<pb::ListCharactersRequest>,
    ) -> Result<Response<pb::ListCharactersResponse>, Status> {
        self.read(&request)?;
        Ok(Response::new(super::grpc_character::list(&self.state, request.into_inner()).await?))
    }

    async fn replace_character(
        &self,
        request: Request<pb::ReplaceCharacterRequest>,
    ) -> Result<Response<pb::CharacterSummary>, Status> {
        let caller = self.caller(&request, Scope::Write)?;
        self.state.writes.admit(&caller)?;
        Ok(Response::new(super::grpc_character::replace(&self.state, &caller, request.into_inner()).await?))
    }

    async fn delete_character(
        &self,
        request: Request<pb::DeleteCharacterRequest>,
    ) -> Result<Response<pb::DeleteCharacterResponse>, Status> {
        self.write(&request)?;
        Ok(Response::new(super::grpc_character::delete(&self.state, request.into_inner()).await?))
    }

    async fn import_character(
        &self,
        request: Request<pb::ImportCharacterRequest>,
    ) -> Result<Response<pb::ImportCharacterResponse>, Status> {
        let caller = self.caller(&request, Scope::Write)?;
        self.state.writes.admit(&caller)?;
        Ok(Response::new(super::grpc_character::import(&self.state, &caller, request.into_inner()).await?))
    }

    async fn create_graph(
        &self,
        request: Request<pb::CreateGraphRequest>,
    ) -> Result<Response<pb::GraphSummary>, Status> {
        let caller = self.caller(&request, Scope::Write)?;
        self.state.writes.admit(&caller)?;
        Ok(Response::new(super::grpc_graph::create(&self.state, &caller, request.into_inner()).await?))
    }

    async fn get_graph(&self, request: Request<pb::GetGraphRequest>) -> Result<Response<pb::GraphRecord>, Status> {
        self.read(&request)?;
        Ok(Response::new(super::grpc_graph::get(&self.state, request.into_inner()).await?))
    }

    async fn list_graphs(
        &self,
        request: Request<pb::ListGraphsRequest>,
    ) -> Result<Response<pb::ListGraphsResponse>, Status> {
        self.read(&request)?;
        Ok(Response::new(super::grpc_graph::list(&self.state, request.into_inner()).await?))
    }

    async fn replace_graph(
        &self,
        request: Request<pb::ReplaceGraphRequest>,
    ) -> Result<Response<pb::GraphSummary>, Status> {
        let caller = self.caller(&request, Scope::Write)?;
        self.state.writes.admit(&caller)?;
        Ok(Response::new(super::grpc_graph::replace(&self.state, &caller, request.into_inner()).await?))
    }

    async fn delete_graph(
        &self,
        request: Request<pb::DeleteGraphRequest>,
    ) -> Result<Response<pb::DeleteGraphResponse>, Status> {
        self.write(&request)?;
        Ok(Response::new(super::grpc_graph::delete(&self.state, request.into_inner()).await?))
    }

    async fn ping(&self, _request: Request<pb::PingRequest>) -> Result<Response<pb::PingResponse>, Status> {
        Ok(grpc_answer(pb::PingResponse {
            server_unix_nanos: stream::unix_nanos(),
            server_monotonic_nanos: self.engine.uptime().as_nanos() as u64,
        }))
    }
}

/// `frames`, ended early with the status sent on `abort` (a bad control).
/// The live broadcast `id`, or `broadcast_not_found`.
/// (Live here, or stored by another node and started here now.)
async fn live_broadcast(state: &AppState, id: &str) -> Result<Arc<stream::Broadcast>, Status> {
    Ok(super::broadcast_store::find(state, id).await?)
}

impl GrpcService {
    /// `Play` bound to broadcast `id` by a `caller` with the write scope:
    /// the broadcast's frames out, each control in applied to it for every
    /// viewer (a refused one ends the call with its code, as on `Play`).
    async fn play_broadcast(
        &self,
        id: &str,
        caller: Caller,
        mut inbound: Streaming<pb::PlaybackControl>,
    ) -> Result<Response<FrameStream>, Status> {
        let b = live_broadcast(&self.state, id).await?;
        let permit = self.engine.admit_for(caller.addr, caller.token.clone()).map_err(ApiError::from)?;
        // Its controls go to the broadcast from the task below, not through the subscription.
        let sub = b.watch(stream::Encoding::Protobuf, permit, None);
        let phase_ms = b.phase_ms();
        let (abort_tx, abort_rx) = oneshot::channel::<Status>();
        let state = self.state.clone();
        crate::panics::spawn_guarded("grpc_broadcast_controls", async move {
            while let Ok(Some(msg)) = inbound.message().await {
                if let Some(pb::playback_control::Op::Stop(_)) = msg.op {
                    let _ = abort_tx.send(Status::ok("stopped"));
                    return;
                }
                if let Err(status) = broadcast_control(&state, &caller, &b, msg.op).await {
                    let _ = abort_tx.send(status);
                    return;
                }
            }
        });
        Ok(with_phase(Response::new(Box::pin(with_abort(stream::grpc::frames(sub), abort_rx))), phase_ms))
    }
}

/// One control a `Play` bound to broadcast `b` sent: drawn on `caller`'s
/// write budget, applied, and stored before the next is read.
///
/// # Errors
/// Its refusal, or the store's (the control then withdrawn).
async fn broadcast_control(
    state: &AppState,
    caller: &Caller,
    b: &stream::Broadcast,
    op: Option<pb::playback_control::Op>,
) -> Result<(), Status> {
    state.writes.admit(caller)?;
    let control = control_from_pb(state, op).await?;
    let (_, storing) = b.control(control).map_err(|e| refused(&e))?;
    match storing {
        Some(outcome) => outcome.await.map_or(Ok(()), |refusal| Err(refused(&refusal))),
        None => Ok(()),
    }
}

fn with_abort(
    frames: impl Stream<Item = Result<WireFrame, Status>> + Send + 'static,
    abort: oneshot::Receiver<Status>,
) -> impl Stream<Item = Result<WireFrame, Status>> + Send + 'static {
    use futures_util::StreamExt;
    futures_util::stream::unfold(Some((Box::pin(frames), Some(abort))), |state| async move {
        let (mut frames, abort) = state?;
        let Some(mut abort) = abort else {
            return frames.next().await.map(|item| (item, Some((frames, None))));
        };
        tokio::select! {
            item = frames.next() => item.map(|item| (item, Some((frames, Some(abort))))),
            status = &mut abort => match status {
                Ok(status) => Some((Err(status), None)),
                // The control reader ended without complaint: frames go on.
                Err(_) => frames.next().await.map(|item| (item, Some((frames, None)))),
            },
        }
    })
}

/// The stream's lane for the engine (its phase, see `Engine::watch`): the
/// client's port, which tells its HTTP/2 connections apart, so the streams
/// of one connection fall due together.
fn lane<T>(request: &Request<T>) -> Option<u64> {
    request.remote_addr().map(|a| u64::from(a.port()))
}

/// Tells the client its stream's grid phase in the response headers (see
/// [`stream::PHASE_HEADER`]).
fn with_phase<T>(mut response: Response<T>, phase_ms: u32) -> Response<T> {
    response.metadata_mut().insert(stream::PHASE_HEADER, phase_ms.into());
    response
}
