//! The [`Engine`]: where streams are admitted, matched to a playback and
//! shut down.
//!
//! A stream asks for a clip version at a rate, start, speed and options.
//! Its first tick is the next tick of the engine-wide grid for its rate
//! (`schedule::Grid`). Streams asking for the same thing whose first tick
//! is the same grid tick are the same playback: the engine keeps a registry
//! of playbacks that have not produced their first tick yet, and a stream
//! that matches one subscribes to it instead of starting its own. A burst of
//! viewers of one clip thus costs one evaluation and one encoding per tick.
//! A playback leaves the registry just before its first tick, so every
//! subscriber sees frame 0 (with the joint names).
//!
//! Playbacks that take controls (gRPC `Play`, or a WebSocket viewer that
//! sends one) are private: a shared viewer that sends a control forks a
//! private playback that continues from its own last frame.
//!
//! The registry is a std mutex held only to look up or insert, never across
//! an await. Shutdown is a `watch` flag every playback selects on.

use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::net::IpAddr;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::{broadcast, mpsc, oneshot, watch};
use tokio::time::Instant;

use super::encode::Encoding;
use super::hub::{Hub, Item};
use super::limits::{AdmitError, Limits, StreamPermit};
use super::playhead::{Control, MAX_SPEED};
use super::schedule::{Grid, Schedule};
use super::subscription::{Source, Subscription};
use crate::anim::{Clip, Ease, Playback, Space};

/// The highest accepted frame rate.
pub const MAX_FPS: u32 = 240;

/// Tunables of the engine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EngineConfig {
    /// Frames buffered per viewer before the oldest are dropped.
    pub buffer: usize,
    /// Concurrent streams, all clients together.
    pub max_streams: usize,
    /// Concurrent streams per client address.
    pub max_streams_per_client: usize,
    /// Concurrent streams per configured token, by its name (see [`Engine::admit_for`]).
    pub max_streams_per_token: usize,
    /// Wake playbacks with the precise tick timer thread (`ticker`) rather
    /// than tokio's millisecond timer. The server turns it on; the default
    /// is off so that tests can drive the engine with a paused tokio clock.
    pub precise_timer: bool,
}

impl Default for EngineConfig {
    fn default() -> Self {
        EngineConfig {
            buffer: 8,
            max_streams: 1024,
            max_streams_per_client: 64,
            max_streams_per_token: 64,
            precise_timer: false,
        }
    }
}

/// Whatever holds a compiled clip (the server's cache entry, or a bare
/// [`Clip`]), so a stream can keep it alive without copying it.
pub trait ClipSource: Send + Sync + 'static {
    fn clip(&self) -> &Clip;
}

impl ClipSource for Clip {
    fn clip(&self) -> &Clip {
        self
    }
}

/// What a client asked for, before validation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StreamRequest {
    pub fps: u32,
    /// `None`: the clip's start.
    pub start: Option<f64>,
    /// `None`: 1.
    pub speed: Option<f64>,
    /// `None`: the clip's default.
    pub playback: Option<Playback>,
    pub ease: Ease,
    pub space: Space,
    pub encoding: Encoding,
    /// 0: no limit.
    pub max_frames: u64,
    /// Start paused (private playbacks only).
    pub paused: bool,
}

/// A request the engine cannot serve: the field at fault and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {detail}")]
pub struct ParamError {
    pub field: &'static str,
    pub detail: String,
}

/// A validated stream request, bound to the clip version it plays.
#[derive(Clone)]
pub struct StreamParams {
    pub clip_id: Arc<str>,
    pub version: u64,
    /// The compiled clip the stream started on; it keeps playing this
    /// version even if the clip is replaced or deleted meanwhile.
    pub source: Arc<dyn ClipSource>,
    pub fps: u32,
    pub start: f64,
    pub speed: f64,
    pub playback: Playback,
    pub ease: Ease,
    pub space: Space,
    pub encoding: Encoding,
    pub max_frames: Option<u64>,
    pub paused: bool,
}

impl std::fmt::Debug for StreamParams {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StreamParams")
            .field("clip_id", &self.clip_id)
            .field("version", &self.version)
            .field("fps", &self.fps)
            .field("start", &self.start)
            .field("speed", &self.speed)
            .field("playback", &self.playback)
            .field("encoding", &self.encoding)
            .field("max_frames", &self.max_frames)
            .finish_non_exhaustive()
    }
}

impl StreamParams {
    /// Validates `req` against the stream rules (SPEC §5).
    ///
    /// # Errors
    /// `fps` outside 1..=240, a non-finite start, a speed that is not finite
    /// or exceeds ±1000.
    pub fn new(
        clip_id: &str,
        version: u64,
        source: Arc<dyn ClipSource>,
        req: StreamRequest,
    ) -> Result<Self, ParamError> {
        let clip = source.clip();
        if !(1..=MAX_FPS).contains(&req.fps) {
            return Err(ParamError { field: "fps", detail: format!("must be 1..={MAX_FPS}, got {}", req.fps) });
        }
        let start = req.start.unwrap_or(f64::from(clip.start()));
        if !start.is_finite() {
            return Err(ParamError { field: "start", detail: "must be a finite number of seconds".into() });
        }
        let speed = req.speed.unwrap_or(1.0);
        if !speed.is_finite() || speed.abs() > MAX_SPEED {
            return Err(ParamError { field: "speed", detail: format!("must be finite and within ±{MAX_SPEED}") });
        }
        Ok(StreamParams {
            clip_id: clip_id.into(),
            version,
            playback: req.playback.unwrap_or(clip.playback()),
            source,
            fps: req.fps,
            start,
            speed,
            ease: req.ease,
            space: req.space,
            encoding: req.encoding,
            max_frames: (req.max_frames > 0).then_some(req.max_frames),
            paused: req.paused,
        })
    }

    /// The compiled clip.
    pub fn clip(&self) -> &Clip {
        self.source.clip()
    }

    /// What makes two streams the same playback (if they start together).
    fn key(&self) -> HubKey {
        HubKey {
            clip_id: Arc::clone(&self.clip_id),
            version: self.version,
            fps: self.fps,
            start: self.start.to_bits(),
            speed: self.speed.to_bits(),
            modes: [self.playback.as_str(), self.ease.as_str(), self.space.as_str()],
            encoding: self.encoding,
            paused: self.paused,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(crate) struct HubKey {
    clip_id: Arc<str>,
    version: u64,
    fps: u32,
    start: u64,
    speed: u64,
    modes: [&'static str; 3],
    encoding: Encoding,
    paused: bool,
}

/// A shared playback that has not produced its first tick yet: viewers
/// asking for the same thing join it (on its schedule).
pub(crate) struct Pending {
    tx: broadcast::Sender<Item>,
    schedule: Schedule,
}

pub(crate) struct Inner {
    pub(crate) epoch: Instant,
    pub(crate) config: EngineConfig,
    pub(crate) hubs: Mutex<HashMap<HubKey, Pending>>,
    pub(crate) shutdown: watch::Sender<bool>,
    limits: Arc<Limits>,
    /// Round-robin phases for private playbacks.
    next_phase: AtomicU32,
}

/// The streaming engine: cheap to clone, one per server.
#[derive(Clone)]
pub struct Engine {
    pub(crate) inner: Arc<Inner>,
}

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Engine").field("config", &self.inner.config).finish_non_exhaustive()
    }
}

impl Engine {
    /// A new engine; its tick grid starts now.
    pub fn new(config: EngineConfig) -> Self {
        let config = EngineConfig { buffer: config.buffer.max(1), ..config };
        Engine {
            inner: Arc::new(Inner {
                epoch: Instant::now(),
                limits: Arc::new(
                    Limits::new(config.max_streams, config.max_streams_per_client)
                        .per_token(config.max_streams_per_token),
                ),
                config,
                hubs: Mutex::default(),
                shutdown: watch::Sender::new(false),
                next_phase: AtomicU32::new(0),
            }),
        }
    }

    pub fn config(&self) -> EngineConfig {
        self.inner.config
    }

    /// Reserves a stream slot for `client` (checked before a WebSocket
    /// upgrade or a gRPC stream starts, so refusals are clean).
    ///
    /// # Errors
    /// The global or per-client cap is reached, or the engine shut down.
    pub fn admit(&self, client: Option<IpAddr>) -> Result<StreamPermit, AdmitError> {
        self.inner.limits.admit(client)
    }

    /// As [`Engine::admit`], also counting the stream against `token`: the
    /// name of the configured token that identified the caller, if any.
    ///
    /// # Errors
    /// As [`Engine::admit`], or the per-token cap is reached.
    pub fn admit_for(&self, client: Option<IpAddr>, token: Option<Arc<str>>) -> Result<StreamPermit, AdmitError> {
        self.inner.limits.admit_for(client, token)
    }

    /// Time since the engine started, on the monotonic clock.
    pub fn uptime(&self) -> Duration {
        Instant::now().saturating_duration_since(self.inner.epoch)
    }

    /// Streams currently admitted.
    pub fn active_streams(&self) -> usize {
        self.inner.limits.active()
    }

    /// The phase (ms) of the grid a new playback of `params` plays on.
    ///
    /// Phases spread playbacks over the period (see `schedule`). A stream
    /// that names its `lane` (its connection: the gRPC transport passes the
    /// peer's address) gets the lane's phase, so all streams of one HTTP/2
    /// connection fall due together and the connection writes their frames
    /// with one system call instead of one each. Otherwise the phase is a
    /// hash of the request.
    fn phase_for(params: &StreamParams, lane: Option<u64>) -> u32 {
        let lane = lane.unwrap_or_else(|| {
            let mut h = std::collections::hash_map::DefaultHasher::new();
            params.key().hash(&mut h);
            h.finish()
        });
        (lane % u64::from(Grid::phases(params.fps))) as u32
    }

    /// A viewer of `params` on `lane` (see `Engine::phase_for`): joins
    /// the matching playback if one has not produced its first frame yet,
    /// or starts one on the next tick of its grid. Controls fork it (see
    /// [`Subscription::control`]).
    pub fn watch(&self, params: StreamParams, permit: StreamPermit, lane: Option<u64>) -> Subscription {
        let key = params.key();
        let mut hubs = self.inner.hubs.lock().expect("hub registry poisoned");
        let (schedule, rx, handback) = match hubs.get(&key) {
            Some(pending) => (pending.schedule.clone(), pending.tx.subscribe(), None),
            None => {
                let phase_ms = Self::phase_for(&params, lane);
                let grid = Grid { epoch: self.inner.epoch, fps: params.fps, phase_ms };
                let first = grid.next_at_or_after(Instant::now());
                let schedule = Schedule::new(grid, first, 0).precise(self.inner.config.precise_timer);
                let (tx, rx) = broadcast::channel(self.inner.config.buffer);
                hubs.insert(key.clone(), Pending { tx: tx.clone(), schedule: schedule.clone() });
                let (back_tx, back_rx) = oneshot::channel();
                let mut hub = Hub::new(
                    &params,
                    schedule.clone(),
                    tx,
                    None,
                    Some((Arc::clone(&self.inner), key)),
                    self.inner.shutdown.subscribe(),
                );
                hub.hand_back_to(back_tx);
                crate::panics::spawn_guarded("playback", hub.run());
                (schedule, rx, Some(back_rx))
            }
        };
        drop(hubs);
        Subscription::new(self.clone(), params, schedule, Source::Shared { rx, handback }, permit)
    }

    /// A private, controllable playback of `params` (gRPC `Play`) on
    /// `lane`; without one, private playbacks take the phases in turn.
    pub fn play(&self, params: StreamParams, permit: StreamPermit, lane: Option<u64>) -> Subscription {
        let lane = lane.unwrap_or_else(|| u64::from(self.inner.next_phase.fetch_add(1, Ordering::Relaxed)));
        let phase_ms = Self::phase_for(&params, Some(lane));
        let grid = Grid { epoch: self.inner.epoch, fps: params.fps, phase_ms };
        let first = grid.next_at_or_after(Instant::now());
        let schedule = Schedule::new(grid, first, 0).precise(self.inner.config.precise_timer);
        let (hub, rx, controls) = self.private(&params, schedule.clone(), None, true);
        Subscription::new(self.clone(), params, schedule, Source::Private { hub, rx, controls }, permit)
    }

    /// A private playback on `schedule`, for its one viewer to drive;
    /// `prev_time` is the request time of the viewer's last frame (for
    /// event continuity), `with_names` whether its next frame must carry
    /// the joint names.
    pub(crate) fn private(
        &self,
        params: &StreamParams,
        schedule: Schedule,
        prev_time: Option<f64>,
        with_names: bool,
    ) -> (Box<Hub>, broadcast::Receiver<Item>, mpsc::Sender<Control>) {
        let (tx, rx) = broadcast::channel(1);
        let (ctl_tx, ctl_rx) = mpsc::channel(CONTROL_QUEUE);
        let mut hub = Hub::new(params, schedule, tx, Some(ctl_rx), None, self.inner.shutdown.subscribe());
        hub.resume(prev_time, with_names);
        (Box::new(hub), rx, ctl_tx)
    }

    /// Ends every stream: each playback sends a final "shutting down" end at
    /// once, and no new stream is admitted.
    pub fn shutdown(&self) {
        self.inner.limits.close();
        self.inner.shutdown.send_replace(true);
    }

    /// Resolves once every admitted stream has ended (after
    /// [`Engine::shutdown`], once the transports have delivered their final
    /// status), or after `timeout`. Returns whether all ended.
    pub async fn drained(&self, timeout: Duration) -> bool {
        tokio::time::timeout(timeout, self.inner.limits.idle()).await.is_ok()
    }

    /// Playbacks waiting for their first tick (for tests and metrics).
    pub fn pending_playbacks(&self) -> usize {
        self.inner.hubs.lock().expect("hub registry poisoned").len()
    }
}

/// Controls queued for a playback before the client is told to slow down.
pub(crate) const CONTROL_QUEUE: usize = 32;
