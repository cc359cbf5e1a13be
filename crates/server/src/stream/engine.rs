//! The [`Engine`]: where streams are admitted, matched to a playback and
//! shut down.
//!
//! A stream asks for a clip version at a rate, start, speed and options.
//! Its first tick is the next tick of the engine-wide grid for its rate
//! (`schedule::Grid`). Streams asking for the same thing whose first tick
//! is the same grid tick are the same playback: the engine keeps a registry
//! (`registry`) of playbacks that have not produced their first tick yet, and a stream
//! that matches one subscribes to it instead of starting its own. A burst of
//! viewers of one clip thus costs one evaluation and one encoding per tick.
//! A playback leaves the registry just before its first tick, so every
//! subscriber sees frame 0 (with the joint names).
//!
//! Playbacks that take controls (gRPC `Play`, or a WebSocket viewer that
//! sends one) are private: a shared viewer that sends a control forks a
//! private playback that continues from its own last frame.
//!
//! Shutdown is a `watch` flag every playback, and every subscription (for
//! the playback it forks), selects on.

use std::hash::{Hash, Hasher};
use std::net::IpAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use tokio::sync::{broadcast, oneshot, watch};
use tokio::time::Instant;

use super::broadcast::Broadcasts;
use super::hub::{self, Hub, Item};
use super::limits::{AdmitError, Limits, StreamPermit};
use super::params::StreamParams;
use super::registry::{Joinable, Joined, PlaybackKey, Registry};
use super::schedule::{Grid, Schedule};
use super::subscription::{Source, Subscription};

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
    /// Live broadcasts at once (docs/broadcasts.md).
    pub max_broadcasts: usize,
    /// How far ahead a broadcast control is stamped (many nodes: so that
    /// the others hear of it before its tick); zero stamps the next tick.
    pub broadcast_lead: std::time::Duration,
    /// Broadcast checkpoints: how often, and the controls held between two.
    pub checkpointing: super::broadcast::Checkpointing,
}

impl Default for EngineConfig {
    fn default() -> Self {
        EngineConfig {
            buffer: 8,
            max_streams: 1024,
            max_streams_per_client: 64,
            max_streams_per_token: 64,
            precise_timer: false,
            max_broadcasts: 64,
            broadcast_lead: std::time::Duration::ZERO,
            checkpointing: super::broadcast::Checkpointing::default(),
        }
    }
}

struct Inner {
    epoch: Instant,
    config: EngineConfig,
    registry: Arc<Registry<Item>>,
    shutdown: watch::Sender<bool>,
    limits: Arc<Limits>,
    /// Round-robin phases for private playbacks.
    next_phase: AtomicU32,
    broadcasts: Broadcasts,
}

/// The streaming engine: cheap to clone, one per server.
#[derive(Clone)]
pub struct Engine {
    inner: Arc<Inner>,
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
        let epoch = Instant::now();
        let shutdown = watch::Sender::new(false);
        let broadcasts = Broadcasts::new(
            config.max_broadcasts,
            epoch,
            config.buffer,
            config.precise_timer,
            config.broadcast_lead,
            config.checkpointing,
            shutdown.subscribe(),
        );
        Engine {
            inner: Arc::new(Inner {
                epoch,
                broadcasts,
                limits: Arc::new(
                    Limits::new(config.max_streams, config.max_streams_per_client)
                        .per_token(config.max_streams_per_token),
                ),
                config,
                registry: Arc::default(),
                shutdown,
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
            PlaybackKey::of(params).hash(&mut h);
            h.finish()
        });
        (lane % u64::from(Grid::phases(params.fps))) as u32
    }

    /// A viewer of `params` on `lane` (see `Engine::phase_for`): joins
    /// the matching playback if one has not produced its first frame yet,
    /// or starts one on the next tick of its grid. Controls fork it (see
    /// [`Subscription::control`]).
    pub fn watch(&self, params: StreamParams, permit: StreamPermit, lane: Option<u64>) -> Subscription {
        let joined = self.inner.registry.join(PlaybackKey::of(&params), || {
            let phase_ms = Self::phase_for(&params, lane);
            let schedule = self.first_schedule(params.fps, phase_ms);
            Joinable { tx: broadcast::channel(self.inner.config.buffer).0, schedule }
        });
        let (schedule, source) = match joined {
            Joined::Existing { schedule, rx } => (schedule, Source::Shared { rx, handback: None }),
            Joined::Opened { joinable: Joinable { tx, schedule }, rx, listing } => {
                let (back_tx, back_rx) = oneshot::channel();
                let mut hub =
                    Hub::new(&params, schedule.clone(), tx, None, Some(listing), self.inner.shutdown.subscribe());
                hub.hand_back_to(back_tx);
                crate::panics::spawn_guarded("playback", hub.run());
                (schedule, Source::Shared { rx, handback: Some(back_rx) })
            }
        };
        Subscription::new(params, schedule, source, self.inner.shutdown.subscribe(), permit)
    }

    /// A private, controllable playback of `params` (gRPC `Play`) on
    /// `lane`; without one, private playbacks take the phases in turn.
    pub fn play(&self, params: StreamParams, permit: StreamPermit, lane: Option<u64>) -> Subscription {
        let lane = lane.unwrap_or_else(|| u64::from(self.inner.next_phase.fetch_add(1, Ordering::Relaxed)));
        let schedule = self.first_schedule(params.fps, Self::phase_for(&params, Some(lane)));
        let (hub, rx, controls) = hub::private(&params, schedule.clone(), self.inner.shutdown.subscribe());
        let source = Source::Private { hub, rx, controls };
        Subscription::new(params, schedule, source, self.inner.shutdown.subscribe(), permit)
    }

    /// A schedule at `fps` on the grid of phase `phase_ms`, from its next tick.
    fn first_schedule(&self, fps: u32, phase_ms: u32) -> Schedule {
        let grid = Grid { epoch: self.inner.epoch, fps, phase_ms };
        let first = grid.next_at_or_after(Instant::now());
        Schedule::new(grid, first, 0).precise(self.inner.config.precise_timer)
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

    /// The live broadcasts (docs/broadcasts.md); viewers are admitted by the same caps.
    pub fn broadcasts(&self) -> &Broadcasts {
        &self.inner.broadcasts
    }

    /// Playbacks waiting for their first tick (for tests and metrics).
    pub fn pending_playbacks(&self) -> usize {
        self.inner.registry.len()
    }
}
