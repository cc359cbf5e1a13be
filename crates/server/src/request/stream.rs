//! Opening a stream (the WebSocket `GET …/stream`, `StreamFrames`, `Play`):
//! the request checked, bound to the clip at its current version, priced
//! per second of playback and charged to its caller (`server::work`), and
//! admitted by the stream caps.
//!
//! The stream rules themselves (docs/api.md: the fps range, a finite start, the
//! speed bound) are the engine's, [`StreamParams::new`]; this maps its
//! refusals onto the stable codes.

use std::sync::{Arc, Mutex};

use anim::ik::IkConstraint;

use super::cost::{Estimate, check_stream, check_stream_work, compact_frame, compact_graph_report, stream_work};
use super::motion::{Composed, ROOT_MOTION_BYTES, RawMotion};
use super::raw::{Field, Locate, Raw, RawModes, choice, finite, joint_subset, parameter_subset, unprocessable, whole};
use crate::auth::{Caller, CallerKey};
use crate::error::ApiError;
use crate::state::AppState;
use crate::stream::{
    AdmitError, Broadcast, CompactLayout, CompactRefusal, CompactRequest, ControlError, Encoding, LayoutRunner,
    MAX_FPS, ParamError, ReachSig, Repricing, StreamMotion, StreamParams, StreamPermit, StreamRequest,
    range_sample_price, range_source,
};
use crate::work::{Ticket, price};

/// A stream's price per second, held against its caller's share and the
/// node's capacity while it is open, and priced again when a control
/// changes what its frames evaluate (a crossfade, an `ik` control): over
/// `max_request_work` the control is refused `too_much_work`, over the
/// caller's share `caller_work_limit`, and the stream goes on as it was.
#[derive(Debug)]
struct StreamCharge {
    ticket: Mutex<Ticket>,
    /// The bound of one frame, in bytes (a control keeps the skeleton).
    frame: u64,
    fps: u32,
    /// `max_request_work`, per second of playback.
    limit: u64,
    /// Whose write budget its controls draw on.
    caller: Caller,
    writes: Arc<crate::ratelimit::WriteLimiter>,
    /// Where a new compact layout is chosen.
    work: Arc<crate::work::Work>,
}

impl Repricing for StreamCharge {
    fn reprice(&self, motions: &[&StreamMotion], ik: &[IkConstraint]) -> Result<(), ControlError> {
        let constraints = motions.first().map_or(0, |m| price::ik(ik, m.skeleton()));
        let per_frame = price::stream_frame(motions, constraints, self.fps);
        let per_sec = stream_work(per_frame, self.frame, self.fps);
        if per_sec > self.limit {
            let detail = format!(
                "this control would make the stream cost {per_sec} work units per second of playback; the limit \
                 (max_request_work, --max-request-work) is {}",
                self.limit
            );
            return Err(ApiError::Relayed { status: 422, code: "too_much_work", detail }.to_control());
        }
        crate::sync::lock(&self.ticket).resize(per_sec).map_err(|e| {
            let detail = format!("this control would make the stream cost {per_sec} work units per second: {e}");
            ApiError::Relayed { status: e.status().as_u16(), code: e.code(), detail }.to_control()
        })
    }

    fn admit(&self) -> Result<(), ControlError> {
        self.writes.admit(&self.caller).map_err(|e| e.to_control())
    }

    fn charge_layout(&self, units: u64) -> Result<LayoutRunner, ControlError> {
        if units > self.limit {
            let detail = format!(
                "choosing this stream's new compact layout costs {units} work units; the limit (max_request_work, \
                 --max-request-work) is {}",
                self.limit
            );
            return Err(ApiError::Relayed { status: 422, code: "too_much_work", detail }.to_control());
        }
        let ticket = crate::sync::lock(&self.ticket).also(units).map_err(|e| {
            let detail = format!("choosing this stream's new compact layout costs {units} work units: {e}");
            ApiError::Relayed { status: e.status().as_u16(), code: e.code(), detail }.to_control()
        })?;
        let work = Arc::clone(&self.work);
        Ok(Box::new(move |job| {
            Box::pin(async move { work.spend_held(ticket, move |_| job()).await.map_err(|e| e.to_control()) })
        }))
    }
}

/// A broadcast viewer's compact frames (docs/compact-frames.md): the
/// layout at the bound and distance asked for of what `b` has played
/// (`Broadcast::reach`: its definition, and every motion its crossfades
/// faded to and joint its `ik` controls turned), chosen on the work pool
/// and priced by its range samples, and the ticket that holds the encoding's price per
/// second of playback against `caller` while it watches (the broadcast's
/// own price, its creator's, covers its JSON and protobuf frames).
///
/// # Errors
/// As a compact stream's: `bad_number`, `max_error_out_of_range`,
/// `distance_out_of_range`, `compact_unsupported`; `too_much_work`,
/// `caller_work_limit`, `overloaded`.
pub async fn compact_watch(
    state: &AppState,
    b: &Broadcast,
    (max_error, distance): (Option<Raw<'_>>, Option<Raw<'_>>),
    at: Locate,
    caller: &Caller,
) -> Result<((Arc<CompactLayout>, ReachSig), Ticket), ApiError> {
    let params = b.params();
    let raw = RawStream {
        fps: None,
        start: None,
        speed: None,
        modes: RawModes::default(),
        encoding: Some(Raw::Text("compact")),
        max_error,
        distance,
        max_frames: None,
        paused: false,
        springs: true,
        joints: None,
        parameters: None,
        at,
    };
    let request = StreamRequest { space: params.space, encoding: Encoding::Compact, ..StreamRequest::default() };
    let compact = raw.compact(&request)?;
    if params.joints.is_some() {
        let detail = "compact frames carry the whole local pose; this broadcast sends a joint subset".to_owned();
        return Err(unprocessable("compact_unsupported", Field::Encoding, at, detail));
    }
    range_source(&params.motion, params.graph.as_ref()).map_err(|e| raw.compact_refused(e))?;
    let joints = params.motion.skeleton().len();
    let events = params.motion.first_clip().clip().events().len();
    let report = params.graph.as_ref().filter(|g| g.report).map_or(0, |g| compact_graph_report(&g.graph));
    let frame = compact_frame(joints, events).saturating_add(report);
    let per_sec = stream_work(price::compact_frame(joints), frame, params.fps);
    check_stream_work(per_sec, &state.config.limits, at)?;
    let ticket = state.work.charge(&caller.key(), per_sec)?;
    let (max_error, distance) = compact.expect("a compact request has its bound");
    let reach = b.reach();
    let units = price::compact_layout(reach.samples(params), reach.sample_price(params, &price::clip_pose));
    let limit = state.config.limits.max_request_work;
    if units > limit {
        let detail = format!(
            "choosing this broadcast's compact layout costs {units} work units; the limit (max_request_work, \
             --max-request-work) is {limit}"
        );
        return Err(unprocessable("too_much_work", Field::Encoding, at, detail));
    }
    let (params, sig) = (params.clone(), reach.sig());
    let layout = state
        .work
        .spend(&caller.key(), units, move |_| reach.layout(&params, max_error, distance))
        .await?
        .map_err(|e| raw.compact_refused(e))?;
    Ok(((Arc::new(layout), sig), ticket))
}

/// The frame rate of a stream that names none (the WebSocket's default;
/// gRPC's `fps` is always given, 0 included).
pub const DEFAULT_FPS: u32 = 30;

/// A stream request, as a transport decoded it.
#[derive(Debug, Clone, Copy)]
pub struct RawStream<'a> {
    /// `None`: [`DEFAULT_FPS`].
    pub fps: Option<Raw<'a>>,
    /// The request time of frame 0; `None`: the clip's start.
    pub start: Option<Raw<'a>>,
    /// `None`: 1.
    pub speed: Option<Raw<'a>>,
    pub modes: RawModes<'a>,
    /// `json`, `protobuf` or `compact`; `None`: JSON.
    pub encoding: Option<Raw<'a>>,
    /// Compact frames' error bound and distance, metres (docs/compact-frames.md).
    pub max_error: Option<Raw<'a>>,
    pub distance: Option<Raw<'a>>,
    /// `None`: no limit; given, at least 1.
    pub max_frames: Option<Raw<'a>>,
    /// Start paused (private playbacks only).
    pub paused: bool,
    /// A clip stream's spring chains run (docs/springs.md, “Clip routes”);
    /// `false`: its keyed poses. Motion streams play their motion's.
    pub springs: bool,
    /// Only these joints in every frame (docs/motion.md); `None`: all.
    pub joints: Option<&'a [String]>,
    /// Only these parameters in every frame (docs/clip-format.md §3); `None`: all.
    pub parameters: Option<&'a [String]>,
    pub at: Locate,
}

/// A stream ready to start: its parameters, bound to the clip version it
/// plays, and the permit the stream caps gave it (holding the stream's
/// price per second, charged to its caller).
#[derive(Debug)]
pub struct Opening {
    pub params: StreamParams,
    pub permit: StreamPermit,
}

/// An opening, or why the stream caps refused it, which each transport
/// reports its own way (gRPC `RESOURCE_EXHAUSTED`, the WebSocket a close
/// frame after the upgrade).
pub type Admitted = Result<Opening, AdmitError>;

impl RawStream<'_> {
    /// # Errors
    /// `bad_number`, `bad_parameter`; `max_frames_out_of_range`.
    pub fn check(&self) -> Result<StreamRequest, ApiError> {
        let at = self.at;
        let fps = self.fps.map(|raw| whole(raw, Field::Fps, at)).transpose()?;
        let start = self.start.map(|raw| finite(raw, Field::Start, at)).transpose()?;
        let speed = self.speed.map(|raw| finite(raw, Field::Speed, at)).transpose()?;
        let max_frames = self.max_frames.map(|raw| whole(raw, Field::MaxFrames, at)).transpose()?;
        let options = self.modes.check(at)?;
        let encoding = Self::encoding(self.encoding, at)?;
        if let Some(n) = max_frames.filter(|n| *n < 1.0) {
            let detail = format!("`max_frames` must be at least 1, got {n}");
            return Err(unprocessable("max_frames_out_of_range", Field::MaxFrames, at, detail));
        }
        Ok(StreamRequest {
            // Out of `u32` is out of range too: 0 and `u32::MAX` say so to the engine.
            fps: fps.map_or(DEFAULT_FPS, |f| f as u32),
            start,
            speed,
            playback: options.playback,
            ease: options.ease,
            space: options.space,
            encoding,
            max_frames: max_frames.map_or(0, |n| n as u64),
            paused: self.paused,
            without_springs: !self.springs,
        })
    }

    /// Checks the request, binds it to the clip `id` at its current
    /// version (the cache entry: the stream keeps it even if the clip is
    /// replaced), prices it and charges its price per second to `caller`,
    /// and asks the caps for a permit. Everything that can refuse it by
    /// counts alone (the price, the caller's share, the caps) comes before
    /// the stream's motion is built, so a refusal costs less than a pose.
    ///
    /// # Errors
    /// As [`RawStream::check`], then `clip_not_found`, `fps_out_of_range`;
    /// the cost model's `frame_too_large`, `stream_rate_too_high`,
    /// `too_much_work`; `caller_work_limit`, `overloaded`; then the
    /// stream rules (`speed_out_of_range`) and the subset's.
    pub async fn open(&self, state: &AppState, id: &str, caller: &Caller) -> Result<Admitted, ApiError> {
        let request = self.check()?;
        let compact = self.compact(&request)?;
        let cached = super::raw::clip(state, id).await?;
        self.check_fps(request.fps)?;
        let (frame, encoding) = match compact {
            Some(_) => {
                let joints = cached.clip.joint_count();
                (compact_frame(joints, cached.clip.events().len()), price::compact_frame(joints))
            }
            None => (Estimate::frame(&cached.clip, &cached.meta.id, request.encoding.into()), 0),
        };
        let keyed = anim::spring::SpringsSpec::default();
        let springs = if request.without_springs { &keyed } else { &cached.springs };
        let per_frame = encoding.saturating_add(price::clip_frame(&cached.clip, springs, request.fps));
        let permit = match self.admit(per_frame, frame, request.fps, state, caller)? {
            Ok(permit) => permit,
            Err(refused) => return Ok(Err(refused)),
        };
        let params = StreamParams::new(cached, request).map_err(|e| self.refused(e))?;
        let params = self.with_layout(self.bind(params, state)?, compact, state, &caller.key()).await?;
        Ok(Ok(Opening { params, permit }))
    }

    /// As [`RawStream::open`] for a composed motion (docs/motion.md): its clips
    /// looked up and pinned, the motion built, the stream bound to it. A
    /// repeated composition is the same built motion (the motion cache), so
    /// its viewers can share a playback like a clip's.
    ///
    /// # Errors
    /// As [`RawStream::check`]; `playback` is refused (each layer has its
    /// own); the motion's refusals at `/motion/…` ([`RawMotion::resolve`]);
    /// then as [`RawStream::open`].
    pub async fn open_motion(
        &self,
        state: &AppState,
        motion: RawMotion<'_>,
        caller: &Caller,
    ) -> Result<Admitted, ApiError> {
        let (composed, request, frame) = self.composed(state, motion, &caller.key()).await?;
        let compact = self.compact(&request)?;
        let per_frame =
            price::motion_frame(&composed.motion, request.fps).saturating_add(self.compact_work(&composed, compact));
        let permit = match self.admit(per_frame, frame, request.fps, state, caller)? {
            Ok(permit) => permit,
            Err(refused) => return Ok(Err(refused)),
        };
        let params = self.motion_stream(composed, request, state)?;
        let params = self.with_layout(params, compact, state, &caller.key()).await?;
        Ok(Ok(Opening { params, permit }))
    }

    /// A composed motion's stream parameters, checked, bound and priced as
    /// [`RawStream::open_motion`] does, without a permit or a charge: a
    /// broadcast's (docs/broadcasts.md), whose viewers are admitted one by
    /// one as they join and whose price (per second, returned) is charged
    /// to its creator by the server.
    ///
    /// # Errors
    /// As [`RawStream::open_motion`], but the caller's share and the caps.
    pub async fn motion_params(
        &self,
        state: &AppState,
        motion: RawMotion<'_>,
    ) -> Result<(StreamParams, u64), ApiError> {
        let (composed, request, frame) = self.composed(state, motion, &CallerKey::Node).await?;
        check_stream(frame, request.fps, &state.config.limits, self.at)?;
        let per_frame =
            price::broadcast_frame(&[&composed.motion], 0, request.fps).saturating_add(price::BROADCAST_TICK);
        let per_sec = stream_work(per_frame, frame, request.fps);
        check_stream_work(per_sec, &state.config.limits, self.at)?;
        Ok((self.motion_stream(composed, request, state)?, per_sec))
    }

    /// The request checked, its motion resolved, and a bound of its frames.
    async fn composed(
        &self,
        state: &AppState,
        motion: RawMotion<'_>,
        caller: &CallerKey,
    ) -> Result<(Composed, StreamRequest, u64), ApiError> {
        if self.modes.playback.is_some() {
            let detail = "a motion stream has no `playback`: each layer of the motion has its own".to_owned();
            return Err(super::raw::malformed("unknown_parameter", Field::Playback, self.at, detail));
        }
        let request = self.check()?;
        let composed = motion.resolve_for(state, caller).await?;
        self.check_fps(request.fps)?;
        let first = composed.motion.first_clip().clip();
        let mut frame = match request.encoding {
            Encoding::Compact => compact_frame(composed.motion.skeleton().len(), first.events().len()),
            _ => Estimate::frame(first, composed.clip_id(), request.encoding.into()),
        };
        if composed.motion.has_root_motion() {
            frame += ROOT_MOTION_BYTES;
        }
        frame += super::motion::feet_bytes(&composed.motion);
        let first_reports = composed.motion.first_clip().clip().ik_count();
        frame += super::cost::ik_reports(
            (composed.motion.ik_report_count() - first_reports) as u64,
            request.encoding.into(),
        ) + 8;
        Ok((composed, request, frame))
    }

    /// A composed motion's stream parameters, its subsets applied.
    fn motion_stream(
        &self,
        composed: Composed,
        request: StreamRequest,
        state: &AppState,
    ) -> Result<StreamParams, ApiError> {
        let identity = format!("motion {:p}", Arc::as_ptr(&composed.motion));
        let params = StreamParams::of_motion(composed.motion, identity.into(), request).map_err(|e| self.refused(e))?;
        self.bind(params, state)
    }

    /// Prices a stream of frames of `per_frame` units and at most `frame`
    /// bytes at `fps`, charges it to `caller` and asks the caps for a
    /// permit holding the charge.
    ///
    /// # Errors
    /// `frame_too_large`, `stream_rate_too_high`, `too_much_work`,
    /// `caller_work_limit`, `overloaded`; the caps' refusal is the inner error.
    pub(super) fn admit(
        &self,
        per_frame: u64,
        frame: u64,
        fps: u32,
        state: &AppState,
        caller: &Caller,
    ) -> Result<Result<StreamPermit, AdmitError>, ApiError> {
        check_stream(frame, fps, &state.config.limits, self.at)?;
        let per_sec = stream_work(per_frame, frame, fps);
        check_stream_work(per_sec, &state.config.limits, self.at)?;
        let ticket = state.work.charge(&caller.key(), per_sec)?;
        let limit = state.config.limits.max_request_work;
        let (writes, payer, work) = (Arc::clone(&state.writes), caller.clone(), Arc::clone(&state.work));
        let ticket = Mutex::new(ticket);
        let charge = Arc::new(StreamCharge { ticket, frame, fps, limit, caller: payer, writes, work });
        Ok(state.streams.admit_for(caller.addr, caller.token.clone()).map(|permit| permit.priced(charge)))
    }

    /// The joint and parameter subsets applied.
    pub(super) fn bind(&self, params: StreamParams, state: &AppState) -> Result<StreamParams, ApiError> {
        let joints = self.joints.map(|names| joint_subset(params.motion.skeleton(), names, self.at)).transpose()?;
        let parameters =
            self.parameters.map(|names| parameter_subset(params.motion.parameters(), names, self.at)).transpose()?;
        Ok(params.with_joints(joints).with_parameters(parameters).with_ik_limits(state.config.limits.ik()))
    }

    /// Compact frames' bound and distance when the stream asks for them
    /// (`None`: another encoding).
    ///
    /// # Errors
    /// `bad_number`; `max_error_out_of_range`, `distance_out_of_range`;
    /// `compact_unsupported` for model space or a joint subset (compact
    /// frames carry the whole local pose); `unknown_parameter` for
    /// `max_error` or `distance` without compact frames.
    pub(super) fn compact(&self, request: &StreamRequest) -> Result<Option<(f32, Option<f32>)>, ApiError> {
        let at = self.at;
        let max_error = self.max_error.map(|raw| finite(raw, Field::MaxError, at)).transpose()?;
        let distance = self.distance.map(|raw| finite(raw, Field::Distance, at)).transpose()?;
        if request.encoding != Encoding::Compact {
            if let Some(field) =
                [(max_error, Field::MaxError), (distance, Field::Distance)].into_iter().find_map(|(v, f)| v.map(|_| f))
            {
                let detail = format!("`{}` applies to `encoding=compact` only", field.name());
                return Err(super::raw::malformed("unknown_parameter", field, at, detail));
            }
            return Ok(None);
        }
        let unsupported = |field: Field, what: &str| {
            let detail = format!("compact frames carry the whole local pose; this stream asks for {what}");
            unprocessable("compact_unsupported", field, at, detail)
        };
        if request.space != anim::Space::Local {
            return Err(unsupported(Field::Space, "model space"));
        }
        if self.joints.is_some() {
            return Err(unsupported(Field::JointAt(0), "a joint subset"));
        }
        let checked = CompactRequest { max_error, distance }.check().map_err(|e| self.compact_refused(e))?;
        Ok(Some(checked))
    }

    pub(super) fn compact_refused(&self, e: CompactRefusal) -> ApiError {
        let field = match e.field {
            "max_error" => Field::MaxError,
            "distance" => Field::Distance,
            _ => Field::Encoding,
        };
        unprocessable(e.code, field, self.at, e.detail)
    }

    /// A compact frame's work on `composed`'s output skeleton (0 for other encodings).
    fn compact_work(&self, composed: &Composed, compact: Option<(f32, Option<f32>)>) -> u64 {
        compact.map_or(0, |_| price::compact_frame(composed.motion.skeleton().len()))
    }

    /// The stream in compact frames, when asked: its layout chosen from
    /// ranges that hold its poses (docs/compact-frames.md), priced (a pose of
    /// its costliest clip per range sample) and charged to `caller` and run
    /// as work.
    ///
    /// # Errors
    /// `compact_unsupported` (poses no range bounds: a character whose
    /// hips sit below a joint of another role); `too_much_work`, `caller_work_limit`,
    /// `overloaded`, `request_timeout`.
    pub(super) async fn with_layout(
        &self,
        params: StreamParams,
        compact: Option<(f32, Option<f32>)>,
        state: &AppState,
        caller: &CallerKey,
    ) -> Result<StreamParams, ApiError> {
        let Some((max_error, distance)) = compact else { return Ok(params) };
        let (motion, graph) = (&params.motion, params.graph.as_ref());
        let (_, samples) = range_source(motion, graph).map_err(|e| self.compact_refused(e))?;
        let units = price::compact_layout(samples, range_sample_price(motion, graph, price::clip_pose));
        if units > state.config.limits.max_request_work {
            let detail = format!(
                "choosing this stream's compact layout costs {units} work units; the limit (max_request_work, \
                 --max-request-work) is {}",
                state.config.limits.max_request_work
            );
            return Err(unprocessable("too_much_work", Field::Encoding, self.at, detail));
        }
        let (motion, graph, fps) = (Arc::clone(&params.motion), params.graph.clone(), params.fps);
        let layout = state
            .work
            .spend(caller, units, move |_| {
                CompactLayout::of_stream((&motion, graph.as_ref()), max_error, distance, fps)
            })
            .await?
            .map_err(|e| self.compact_refused(e))?;
        Ok(params.with_compact(Arc::new(layout)))
    }

    /// The engine's frame-rate rule, checked before anything is built.
    pub(super) fn check_fps(&self, fps: u32) -> Result<(), ApiError> {
        if (1..=MAX_FPS).contains(&fps) {
            return Ok(());
        }
        Err(self.refused(ParamError { field: "fps", detail: String::new() }))
    }

    /// # Errors
    /// `bad_parameter`.
    fn encoding(raw: Option<Raw<'_>>, at: Locate) -> Result<Encoding, ApiError> {
        let by_name = |text: &str| match text {
            "json" => Ok(Encoding::Json),
            "protobuf" => Ok(Encoding::Protobuf),
            "compact" => Ok(Encoding::Compact),
            _ => Err("expected one of: json, protobuf, compact".to_owned()),
        };
        // gRPC's `FrameEncoding`: unspecified and protobuf are `Frame`s, compact their `compact` bytes.
        let by_number = |n: i32| match n {
            0 | 1 => Ok(Some(Encoding::Protobuf)),
            2 => Ok(Some(Encoding::Compact)),
            _ => Err(format!("unknown frame encoding {n}")),
        };
        Ok(choice(raw, Field::Encoding, at, by_name, by_number)?.unwrap_or_default())
    }

    /// The engine's refusal, under its stable code.
    pub(super) fn refused(&self, e: ParamError) -> ApiError {
        let (code, field, detail) = match e.field {
            "fps" => {
                let given = self.fps.map_or(String::new(), |raw| match raw {
                    Raw::Text(text) => format!(", got `{text}`"),
                    Raw::Number(n) => format!(", got {n}"),
                    Raw::Enum(_) => String::new(),
                });
                ("fps_out_of_range", Field::Fps, format!("`fps` must be in 1..={MAX_FPS}{given}"))
            }
            "speed" => ("speed_out_of_range", Field::Speed, format!("`speed` {}", e.detail)),
            // Any rule the engine adds before it has a code of its own.
            _ => ("bad_stream", Field::When, e.to_string()),
        };
        unprocessable(code, field, self.at, detail)
    }
}
