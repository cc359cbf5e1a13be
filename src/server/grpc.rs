//! The gRPC API (SPEC §4): service `inbetween.v1.Animation`, plus
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

use futures_util::Stream;
use tokio::sync::oneshot;
use tonic::metadata::MetadataMap;
use tonic::{Request, Response, Status, Streaming};

use crate::anim::{SampleOptions, Sampler};
use crate::server::auth::{Caller, Identity, Scope};
use crate::server::cache::CachedClip;
use crate::server::error::{ApiError, At};
use crate::server::limits::admit_doc;
use crate::server::request::{
    Field, Format, MAX_UNARY_ANSWER_BYTES, Opening, Page, Raw, RawBatch, RawModes, RawPage, RawPose, RawStream,
    Sampling, Wire, evaluate, in_body, in_pose_body,
};
use crate::server::state::AppState;
use crate::store::{ClipMeta, is_clip_id};
use crate::stream::{self, Control, Engine, StreamParams, WireFrame};
use crate::wire::json::{ClipDoc, parse_clip_doc};
use crate::wire::proto::server::animation_server::{Animation, AnimationServer};
use crate::wire::proto::{
    FILE_DESCRIPTOR_SET, clip_from_pb, clip_to_pb, matrices_to_pb, pb, playback_to_pb, pose_to_pb,
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
    let service = AnimationServer::new(GrpcService { state, engine });
    Ok(tonic::service::Routes::new(service)
        .add_service(health)
        .add_service(reflection_v1)
        .add_service(reflection_v1alpha))
}

fn bearer(metadata: &MetadataMap) -> Option<&[u8]> {
    metadata.get("authorization").map(|v| v.as_bytes())
}

impl GrpcService {
    /// A `SampleBatchRequest` checked and bound to its clip (`SampleBatch`
    /// and `SampleStream` alike).
    async fn sampling(&self, req: &pb::SampleBatchRequest) -> Result<(Sampling, Arc<CachedClip>), Status> {
        use pb::sample_batch_request::When;
        let (times, range) = match &req.when {
            Some(When::Times(t)) => (Some(t), None),
            Some(When::Range(r)) => (None, Some(r)),
            None => (None, None),
        };
        let raw = RawBatch::of_message(times, range, modes(req.space, req.playback, req.ease), req.format);
        Ok(raw.resolve(&self.state, &req.clip_id, Wire::Protobuf).await?)
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
            modes: modes(req.space, req.playback, req.ease),
            // gRPC frames are always protobuf `Frame`s.
            encoding: Some(Raw::Text("protobuf")),
            // 0: no limit.
            max_frames: (req.max_frames > 0).then_some(Raw::Number(req.max_frames as f64)),
            paused,
            joints: (!req.joints.is_empty()).then_some(req.joints.as_slice()),
            at: stream_at,
        };
        let opening = match &req.motion {
            None => raw.open(&self.state, &req.clip_id, caller).await?,
            Some(_) if !req.clip_id.is_empty() => {
                let detail = "give `clip_id` or `motion`, not both";
                return Err(ApiError::invalid("clip_or_motion", "/motion", detail).into());
            }
            Some(motion) => {
                let motion = super::grpc_motion::raw_motion(motion)?;
                // Unspecified (0) is no playback; any other is refused as on the WebSocket.
                let playback = (req.playback != 0).then_some(Raw::Enum(req.playback));
                let raw = RawStream { modes: RawModes { playback, ..raw.modes }, ..raw };
                raw.open_motion(&self.state, motion, caller).await?
            }
        };
        let Opening { params, permit } = opening;
        Ok((params, permit.map_err(ApiError::from)?))
    }
}

/// Bytes of poses per `SampleStream` message (at least one pose).
const STREAM_BATCH_BYTES: u64 = 1024 * 1024;

/// The poses `range` of `sampling` as one `PoseBatch`, names if `names`.
fn batch(cached: &CachedClip, sampling: &Sampling, range: std::ops::Range<usize>, names: bool) -> pb::PoseBatch {
    let (mut sampler, mut matrices) = (Sampler::new(), Vec::new());
    let (options, format) = (sampling.options, sampling.format);
    pb::PoseBatch {
        joint_names: if names { cached.clip.skeleton().names().to_vec() } else { Vec::new() },
        poses: sampling.times[range]
            .iter()
            .map(|&t| pose(cached, t, &options, format, false, &mut sampler, &mut matrices))
            .collect(),
    }
}

/// A `SampleStream` answer, evaluated a message at a time: the next
/// message is evaluated (on the blocking pool) only when tonic asks for it,
/// which HTTP/2 flow control holds back while the client does not read; a
/// client that goes away (or a cancelled call) drops the stream and the
/// rest of the work with it (counted as abandoned).
struct Batches {
    state: AppState,
    job: Arc<(Sampling, Arc<CachedClip>)>,
    per_batch: usize,
    next: usize,
    done: bool,
}

impl Batches {
    fn new(state: AppState, sampling: Sampling, cached: Arc<CachedClip>) -> Batches {
        let per_pose = sampling.answer_bytes / sampling.times.len().max(1) as u64;
        let per_batch = (STREAM_BATCH_BYTES / per_pose.max(1)).max(1) as usize;
        Batches { state, job: Arc::new((sampling, cached)), per_batch, next: 0, done: false }
    }

    /// The next message, `None` after the last. An empty request is one
    /// message with the names and no poses.
    async fn next(&mut self) -> Option<Result<pb::PoseBatch, Status>> {
        if self.done {
            return None;
        }
        let n = self.job.0.times.len();
        let range = self.next..(self.next + self.per_batch).min(n);
        let job = Arc::clone(&self.job);
        let built = tokio::task::spawn_blocking(move || {
            let names = range.start == 0;
            batch(&job.1, &job.0, range, names)
        })
        .await;
        Some(match built {
            Ok(batch) => {
                self.state.counters.poses.increment(batch.poses.len() as u64);
                self.next += batch.poses.len();
                self.done = self.next == n;
                Ok(batch)
            }
            Err(e) => {
                self.done = true;
                Err(Status::from(crate::server::metrics::join_failed(e)))
            }
        })
    }
}

impl Drop for Batches {
    fn drop(&mut self) {
        if !self.done {
            self.state.counters.answers_abandoned.increment(1);
            self.state.counters.poses_abandoned.increment((self.job.0.times.len() - self.next) as u64);
        }
    }
}

/// The modes of a request message, for the request layer.
fn modes(space: i32, playback: i32, ease: i32) -> RawModes<'static> {
    RawModes { space: Some(Raw::Enum(space)), playback: Some(Raw::Enum(playback)), ease: Some(Raw::Enum(ease)) }
}

/// Where the fields of `StreamRequest` sit.
fn stream_at(field: Field) -> At {
    match field {
        Field::Start => At::Pointer("/start_time".into()),
        other => in_body(other),
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
    match format {
        Format::Trs => pose_to_pb(names, sampler.pose(), t, clip_time, options.space),
        Format::Matrix | Format::Skinning => matrices_to_pb(names, matrices, t, clip_time),
    }
}

type FrameStream = Pin<Box<dyn Stream<Item = Result<WireFrame, Status>> + Send + 'static>>;

/// A `Play` control; a crossfade's motion is looked up (and pinned) here,
/// its refusals carrying their own codes (`clip_not_found` …) at `/to/…`.
async fn control_from_pb(state: &AppState, op: Option<pb::playback_control::Op>) -> Result<Control, Status> {
    use pb::playback_control::Op;
    match op {
        Some(Op::Play(_)) => Ok(Control::Play),
        Some(Op::Pause(_)) => Ok(Control::Pause),
        Some(Op::Seek(s)) => Ok(Control::Seek(s.time)),
        Some(Op::Speed(s)) => Ok(Control::Speed(s.speed)),
        Some(Op::Stop(_)) => Ok(Control::Stop),
        Some(Op::Layer(l)) => Ok(Control::Layer { index: l.index as usize, weight: l.weight, duration: l.duration }),
        Some(Op::Crossfade(fade)) => {
            let ease =
                crate::wire::proto::ease_from_pb(fade.ease, "/ease").map_err(ApiError::from)?.unwrap_or_default();
            let to = super::grpc_motion::crossfade_target(state, fade.to.as_ref()).await?;
            Ok(Control::Crossfade(stream::Crossfade { to, duration: fade.duration, ease }))
        }
        Some(Op::Open(_)) => Err(bad_control("`open` is only valid as the first message")),
        None => Err(bad_control("a PlaybackControl needs an op")),
    }
}

/// A `Play` message that cannot be obeyed: `bad_control`, as on the WebSocket.
fn bad_control(detail: impl Into<String>) -> Status {
    ApiError::invalid("bad_control", "", detail).into()
}

#[tonic::async_trait]
impl Animation for GrpcService {
    async fn sample(&self, request: Request<pb::SampleRequest>) -> Result<Response<pb::Pose>, Status> {
        self.read(&request)?;
        let req = request.into_inner();
        let raw = RawPose {
            t: Some(Raw::Number(req.time)),
            modes: modes(req.space, req.playback, req.ease),
            format: Some(Raw::Enum(req.format)),
            at: in_pose_body,
        };
        let (sample, cached) = raw.resolve(&self.state, &req.clip_id, Wire::Protobuf).await?;
        let (t, options, format) = (sample.t, sample.options, sample.format);
        let pose = pose(&cached, t, &options, format, true, &mut Sampler::new(), &mut Vec::new());
        self.state.counters.poses.increment(1);
        Ok(Response::new(pose))
    }

    async fn sample_motion(&self, request: Request<pb::SampleMotionRequest>) -> Result<Response<pb::Pose>, Status> {
        self.read(&request)?;
        Ok(Response::new(super::grpc_motion::sample(&self.state, request.into_inner()).await?))
    }

    async fn sample_motion_batch(
        &self,
        request: Request<pb::SampleMotionBatchRequest>,
    ) -> Result<Response<pb::PoseBatch>, Status> {
        self.read(&request)?;
        Ok(Response::new(super::grpc_motion::sample_batch(&self.state, request.into_inner()).await?))
    }

    async fn sample_batch(&self, request: Request<pb::SampleBatchRequest>) -> Result<Response<pb::PoseBatch>, Status> {
        self.read(&request)?;
        let (sampling, cached) = self.sampling(&request.into_inner()).await?;
        if sampling.answer_bytes > MAX_UNARY_ANSWER_BYTES {
            let (bytes, limit) = (sampling.answer_bytes, MAX_UNARY_ANSWER_BYTES);
            return Err(ApiError::AnswerTooLargeForUnary { bytes, limit, stream: "SampleStream" }.into());
        }
        let n = sampling.times.len();
        let blocking = sampling.is_blocking();
        let build = move || batch(&cached, &sampling, 0..n, true);
        let batch = if blocking {
            tokio::task::spawn_blocking(build)
                .await
                .map_err(|e| Status::from(crate::server::metrics::join_failed(e)))?
        } else {
            build()
        };
        self.state.counters.poses.increment(n as u64);
        Ok(Response::new(batch))
    }

    type SampleStreamStream = Pin<Box<dyn Stream<Item = Result<pb::PoseBatch, Status>> + Send + 'static>>;

    async fn sample_stream(
        &self,
        request: Request<pb::SampleBatchRequest>,
    ) -> Result<Response<Self::SampleStreamStream>, Status> {
        self.read(&request)?;
        let (sampling, cached) = self.sampling(&request.into_inner()).await?;
        let batches = Batches::new(self.state.clone(), sampling, cached);
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
        let mut inbound = request.into_inner();
        let open = match inbound.message().await? {
            Some(pb::PlaybackControl { op: Some(pb::playback_control::Op::Open(open)) }) => open,
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
                        let sent = control_from_pb(&state, msg.op)
                            .await
                            .and_then(|c| controller.send(c).map_err(|e| bad_control(e.to_string())));
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
        Ok(Response::new(pb::ClipRecord { summary: Some(summary(&stored.meta)), clip: Some(clip_to_pb(&spec)) }))
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
            at: in_body,
        };
        let Page { clips, next_cursor } = raw.read(&self.state).await?;
        let clips = clips.iter().map(summary).collect();
        Ok(Response::new(pb::ListClipsResponse { clips, next_cursor: next_cursor.unwrap_or_default() }))
    }

    async fn put_clip(&self, request: Request<pb::PutClipRequest>) -> Result<Response<pb::ClipSummary>, Status> {
        self.write(&request)?;
        let req = request.into_inner();
        let clip = req.clip.ok_or_else(|| ApiError::invalid("missing_clip", "/clip", "a PutClip needs a clip"))?;
        let spec = clip_from_pb(&clip).map_err(ApiError::from)?;
        let limits = self.state.config.limits.clone();
        let admitted =
            self.state.builds.run(move |cancel| admit_doc(ClipDoc::from_spec(&spec), &limits, cancel)).await?;
        let meta = if req.clip_id.is_empty() {
            self.state.store.create(admitted.new_clip).await.map_err(ApiError::from)?
        } else {
            if !is_clip_id(&req.clip_id) {
                return Err(ApiError::NotFound { what: "clip" }.into());
            }
            self.state.store.replace(&req.clip_id, admitted.new_clip, req.if_version).await.map_err(ApiError::from)?
        };
        tracing::info!(id = %meta.id, version = meta.version, "clip written over gRPC");
        let reply = summary(&meta);
        self.state.cache_written(Arc::new(CachedClip { meta, clip: admitted.clip }));
        Ok(Response::new(reply))
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
        Ok(Response::new(pb::DeleteClipResponse {}))
    }

    async fn ping(&self, _request: Request<pb::PingRequest>) -> Result<Response<pb::PingResponse>, Status> {
        Ok(Response::new(pb::PingResponse {
            server_unix_nanos: stream::unix_nanos(),
            server_monotonic_nanos: self.engine.uptime().as_nanos() as u64,
        }))
    }
}

/// `frames`, ended early with the status sent on `abort` (a bad control).
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
