//! Broadcasts (SPEC §9): one named playback of a motion on a fixed tick
//! grid, driven by controllers and watched by any number of viewers who
//! join and leave at any time.
//!
//! A broadcast is its own task. At each tick `k` it takes the controls
//! stamped for it (each control is stamped, when it is accepted, with the
//! first tick not yet taken, which is the `seq` its sender is told), applies
//! them, samples its `anim::motion::Player` once and encodes the frame once
//! per encoding that has viewers, publishing the bytes on that encoding's
//! broadcast channel (as a shared playback does, see `hub`). A viewer
//! subscribes to the channel of its encoding, so its first frame is the
//! next tick after it joined; its [`Subscription`] turns gaps in `seq` into
//! its own `dropped` (0 on its first frame) and patches only that number
//! (and, in protobuf, the joint names of its first frame) into the shared
//! bytes. A slow viewer loses only its own oldest frames.
//!
//! With no viewers the task still wakes on its grid (so stamps stay exact)
//! but evaluates nothing; after `idle_timeout` with no viewers and no
//! controls it ends. It also ends when deleted (viewers get
//! [`EndReason::Ended`]: close 1000 / gRPC OK) and at shutdown.
//!
//! The registry ([`Broadcasts`]) is a std mutex around a map, held for one
//! lookup, insert or removal; the controls desk of each broadcast likewise,
//! never across an await.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, SystemTime};

use tokio::sync::{Notify, broadcast, watch};
use tokio::time::Instant;

use super::encode::{Encoded, Encoding, FrameEncoder};
use super::hub::{EndReason, Item, StreamPlayer, TickStamp, frame_data, sample_tick, unix_nanos};
use super::limits::StreamPermit;
use super::params::StreamParams;
use super::pinned::StreamMotion;
use super::playhead::{Control, Crossfade, Playhead};
use super::schedule::{Grid, Schedule};
use super::subscription::{ControlCheck, ControlError, ControlSink, Source, Subscription};
use crate::anim::motion::Player;

/// Controls accepted but not yet applied, per broadcast, at most.
const PENDING_CONTROLS: usize = 64;

/// Why a broadcast could not be created.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum BroadcastError {
    #[error("{limit} broadcasts are live, the most this server runs at once (max_broadcasts)")]
    TooMany { limit: usize },
    #[error("the server is shutting down")]
    ShuttingDown,
}

/// What a broadcast is, as its creator asked: the stream parameters (motion,
/// fps, space, joint subset) and when it ends unwatched.
#[derive(Debug, Clone)]
pub struct BroadcastSpec {
    pub params: StreamParams,
    pub idle_timeout: Duration,
    /// The request as the server describes it back (`GET`): the motion as
    /// sent, space, joints. Opaque here.
    pub description: serde_json::Value,
}

/// A broadcast's state as `GET /v1/broadcasts/{id}` reports it.
#[derive(Debug, Clone, PartialEq)]
pub struct BroadcastStatus {
    /// The tick the broadcast is at now (0 before its first).
    pub seq: u64,
    /// After every accepted control.
    pub paused: bool,
    pub speed: f64,
    pub viewers: usize,
}

/// The live broadcasts of one engine.
#[derive(Clone)]
pub struct Broadcasts {
    inner: Arc<Registry>,
}

struct Registry {
    live: Mutex<HashMap<Arc<str>, Arc<Broadcast>>>,
    max: usize,
    epoch: Instant,
    buffer: usize,
    precise: bool,
    shutdown: watch::Receiver<bool>,
}

impl std::fmt::Debug for Broadcasts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Broadcasts").field("max", &self.inner.max).finish_non_exhaustive()
    }
}

impl Broadcasts {
    /// At most `max` live broadcasts on the engine's clock `epoch`, each
    /// viewer buffering `buffer` frames.
    pub(crate) fn new(
        max: usize,
        epoch: Instant,
        buffer: usize,
        precise: bool,
        shutdown: watch::Receiver<bool>,
    ) -> Self {
        Broadcasts { inner: Arc::new(Registry { live: Mutex::default(), max, epoch, buffer, precise, shutdown }) }
    }

    fn lock(&self) -> MutexGuard<'_, HashMap<Arc<str>, Arc<Broadcast>>> {
        crate::sync::lock(&self.inner.live)
    }

    /// Starts a broadcast of `spec`; its first tick is the next of its grid.
    ///
    /// # Errors
    /// `max` broadcasts are live, or the engine is shutting down.
    pub fn create(&self, spec: BroadcastSpec) -> Result<Arc<Broadcast>, BroadcastError> {
        if *self.inner.shutdown.borrow() {
            return Err(BroadcastError::ShuttingDown);
        }
        let id: Arc<str> = uuid::Uuid::now_v7().hyphenated().to_string().into();
        let fps = spec.params.fps;
        // Spread broadcasts over the period like playbacks (see `schedule`).
        let phase_ms = (uuid_low(&id) % u64::from(Grid::phases(fps))) as u32;
        let grid = Grid { epoch: self.inner.epoch, fps, phase_ms };
        let schedule = Schedule::new(grid, grid.next_at_or_after(Instant::now()), 0).precise(self.inner.precise);
        let broadcast = Arc::new(Broadcast {
            id: Arc::clone(&id),
            created_at: SystemTime::now(),
            json: broadcast::channel(self.inner.buffer).0,
            protobuf: broadcast::channel(self.inner.buffer).0,
            desk: Mutex::new(Desk {
                next: 0,
                pending: Vec::new(),
                check: ControlCheck::new(&spec.params),
                paused: spec.params.paused,
                speed: spec.params.speed,
                last_control: Instant::now(),
            }),
            deleted: Notify::new(),
            ended: AtomicBool::new(false),
            schedule: schedule.clone(),
            spec,
        });
        {
            let mut live = self.lock();
            if live.len() >= self.inner.max {
                return Err(BroadcastError::TooMany { limit: self.inner.max });
            }
            live.insert(id, Arc::clone(&broadcast));
        }
        metrics::gauge!("inbetween_broadcasts").increment(1.0);
        metrics::counter!("inbetween_broadcasts_total").increment(1);
        let task = Task::new(Arc::clone(&broadcast), self.clone(), schedule, self.inner.shutdown.clone());
        crate::panics::spawn_guarded("broadcast", task.run());
        Ok(broadcast)
    }

    /// The live broadcast `id`.
    pub fn get(&self, id: &str) -> Option<Arc<Broadcast>> {
        self.lock().get(id).cloned()
    }

    /// Every live broadcast, oldest first.
    pub fn list(&self) -> Vec<Arc<Broadcast>> {
        let mut all: Vec<_> = self.lock().values().cloned().collect();
        all.sort_by(|a, b| a.id.cmp(&b.id));
        all
    }

    /// Ends broadcast `id` (its viewers get [`EndReason::Ended`]). Returns
    /// whether it was live.
    pub fn delete(&self, id: &str) -> bool {
        let Some(broadcast) = self.lock().remove(id) else { return false };
        broadcast.deleted.notify_one();
        true
    }

    /// Unlists `broadcast` if it is still the one listed under its id.
    fn unlist(&self, broadcast: &Arc<Broadcast>) {
        let mut live = self.lock();
        if live.get(&broadcast.id).is_some_and(|b| Arc::ptr_eq(b, broadcast)) {
            live.remove(&broadcast.id);
        }
    }

    /// Live broadcasts now.
    pub fn len(&self) -> usize {
        self.lock().len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The low 64 bits of a UUID's text, for the grid phase (v7's are random).
fn uuid_low(id: &str) -> u64 {
    uuid::Uuid::try_parse(id).map_or(0, |u| u.as_u64_pair().1)
}

/// Controls accepted and not yet applied, and what they leave playing.
struct Desk {
    /// The first tick the task has not taken: the stamp of a control now.
    next: u64,
    pending: Vec<(u64, Control)>,
    check: ControlCheck,
    paused: bool,
    speed: f64,
    last_control: Instant,
}

/// One live broadcast.
pub struct Broadcast {
    id: Arc<str>,
    spec: BroadcastSpec,
    created_at: SystemTime,
    schedule: Schedule,
    json: broadcast::Sender<Item>,
    protobuf: broadcast::Sender<Item>,
    desk: Mutex<Desk>,
    deleted: Notify,
    ended: AtomicBool,
}

impl std::fmt::Debug for Broadcast {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Broadcast").field("id", &self.id).finish_non_exhaustive()
    }
}

impl Broadcast {
    pub fn id(&self) -> &str {
        &self.id
    }

    pub fn spec(&self) -> &BroadcastSpec {
        &self.spec
    }

    pub fn params(&self) -> &StreamParams {
        &self.spec.params
    }

    pub fn created_at(&self) -> SystemTime {
        self.created_at
    }

    /// The grid its ticks sit on, and the grid tick of its tick 0.
    pub fn grid(&self) -> (Grid, u64) {
        (self.schedule.grid(), self.schedule.first())
    }

    fn channel(&self, encoding: Encoding) -> &broadcast::Sender<Item> {
        match encoding {
            Encoding::Json => &self.json,
            Encoding::Protobuf => &self.protobuf,
        }
    }

    fn viewers(&self) -> usize {
        self.json.receiver_count() + self.protobuf.receiver_count()
    }

    fn desk(&self) -> MutexGuard<'_, Desk> {
        crate::sync::lock(&self.desk)
    }

    /// Where it is now: its tick by the clock, and the playhead its
    /// accepted controls leave.
    pub fn status(&self) -> BroadcastStatus {
        let (grid, first) = self.grid();
        let seq = grid.latest_at_or_before(Instant::now()).saturating_sub(first);
        let desk = self.desk();
        BroadcastStatus { seq, paused: desk.paused, speed: desk.speed, viewers: self.viewers() }
    }

    /// A viewer of `encoding` from the next tick on; `controls`: its
    /// controls reach the broadcast (the transport checked the write
    /// scope), else they are refused.
    pub fn watch(self: &Arc<Self>, encoding: Encoding, permit: StreamPermit, controls: bool) -> Subscription {
        let rx = self.channel(encoding).subscribe();
        if self.ended.load(Ordering::Acquire) {
            // It ended between the lookup and the subscription: say so at once.
            let (tx, rx) = broadcast::channel(1);
            let _ = tx.send(Item::End(EndReason::Ended));
            return self.subscription(encoding, rx, None, permit);
        }
        metrics::counter!("inbetween_broadcast_viewers_total").increment(1);
        let sink = controls.then(|| Arc::clone(self) as Arc<dyn ControlSink>);
        self.subscription(encoding, rx, sink, permit)
    }

    fn subscription(
        &self,
        encoding: Encoding,
        rx: broadcast::Receiver<Item>,
        controls: Option<Arc<dyn ControlSink>>,
        permit: StreamPermit,
    ) -> Subscription {
        let params = StreamParams { encoding, max_frames: None, ..self.spec.params.clone() };
        let shutdown = watch::Sender::new(false).subscribe();
        Subscription::new(params, self.schedule.clone(), Source::Broadcast { rx, controls }, shutdown, permit)
    }

    /// Accepts `control` for every viewer: checked like a stream's
    /// (`stop` is refused: delete the broadcast), stamped with the first
    /// tick not yet produced, which it returns.
    ///
    /// # Errors
    /// An invalid control, too many pending, or the broadcast has ended.
    pub fn control(&self, control: Control) -> Result<u64, ControlError> {
        if control == Control::Stop {
            return Err(ControlError::Invalid("a broadcast has no `stop`: DELETE it to end it for every viewer"));
        }
        if self.ended.load(Ordering::Acquire) {
            return Err(ControlError::Invalid("the broadcast has ended"));
        }
        let mut desk = self.desk();
        let control = desk.check.check(control)?;
        if desk.pending.len() >= PENDING_CONTROLS {
            return Err(ControlError::Busy);
        }
        match control {
            Control::Play => desk.paused = false,
            Control::Pause => desk.paused = true,
            Control::Speed(v) => desk.speed = v,
            _ => {}
        }
        let k = desk.next;
        desk.pending.push((k, control));
        desk.last_control = Instant::now();
        metrics::counter!("inbetween_broadcast_controls_total").increment(1);
        Ok(k)
    }
}

impl ControlSink for Broadcast {
    fn send(&self, control: Control) -> Result<u64, ControlError> {
        self.control(control)
    }
}

/// The broadcast's own task: its schedule, its playback and its idle clock.
struct Task {
    broadcast: Arc<Broadcast>,
    registry: Broadcasts,
    schedule: Schedule,
    program: Program,
    shutdown: watch::Receiver<bool>,
    last_watched: Instant,
    /// Viewers counted into `inbetween_broadcast_viewers` at the last tick.
    counted: usize,
}

impl Task {
    fn new(
        broadcast: Arc<Broadcast>,
        registry: Broadcasts,
        schedule: Schedule,
        shutdown: watch::Receiver<bool>,
    ) -> Self {
        let program = Program::new(&broadcast.spec.params);
        Task { broadcast, registry, schedule, program, shutdown, last_watched: Instant::now(), counted: 0 }
    }

    async fn run(mut self) {
        let reason = self.ticks().await;
        self.broadcast.ended.store(true, Ordering::Release);
        self.registry.unlist(&self.broadcast);
        for tx in [&self.broadcast.json, &self.broadcast.protobuf] {
            let _ = tx.send(Item::End(reason));
        }
        self.count_viewers(0);
        metrics::gauge!("inbetween_broadcasts").decrement(1.0);
    }

    /// Ticks until the broadcast ends; returns why.
    async fn ticks(&mut self) -> EndReason {
        let b = Arc::clone(&self.broadcast);
        loop {
            let tick = tokio::select! {
                biased;
                _ = self.shutdown.wait_for(|down| *down) => return EndReason::Shutdown,
                () = b.deleted.notified() => return EndReason::Ended,
                tick = self.schedule.next() => tick,
            };
            let (controls, last_control) = {
                let mut desk = b.desk();
                desk.next = tick.k + 1;
                (std::mem::take(&mut desk.pending), desk.last_control)
            };
            let viewers = b.viewers();
            self.count_viewers(viewers);
            let now = Instant::now();
            if viewers > 0 {
                self.last_watched = now;
            } else if now.saturating_duration_since(self.last_watched.max(last_control)) >= b.spec.idle_timeout {
                metrics::counter!("inbetween_broadcasts_idle_ended_total").increment(1);
                return EndReason::Ended;
            }
            let jumped = self.program.apply_all(controls, tick.k);
            if viewers == 0 {
                continue;
            }
            let clip_time = self.program.evaluate(tick.k, jumped);
            let sent_at = unix_nanos();
            metrics::counter!("inbetween_broadcast_ticks_total").increment(1);
            for encoding in [Encoding::Json, Encoding::Protobuf] {
                let tx = b.channel(encoding);
                if tx.receiver_count() > 0 {
                    let frame = self.program.encode(encoding, tick.k, sent_at, clip_time);
                    let _ = tx.send(Item::Frame(frame));
                }
            }
        }
    }

    /// Keeps `inbetween_broadcast_viewers` (all broadcasts) up to date.
    fn count_viewers(&mut self, viewers: usize) {
        if viewers != self.counted {
            let gauge = metrics::gauge!("inbetween_broadcast_viewers");
            gauge.increment(viewers as f64 - self.counted as f64);
            self.counted = viewers;
        }
    }
}

/// What a broadcast plays: its playhead and player, and one encoder per
/// encoding (each reused, so a tick allocates only the bytes it sends).
struct Program {
    params: StreamParams,
    playhead: Playhead,
    player: StreamPlayer,
    /// The current motion's first-layer position at the previous evaluated
    /// tick (for the events crossed), and which motion that was.
    prev: Option<(f64, Arc<StreamMotion>)>,
    crossed: Vec<u32>,
    json: FrameEncoder,
    protobuf: FrameEncoder,
}

impl Program {
    fn new(params: &StreamParams) -> Self {
        Program {
            playhead: Playhead::new(params.start, params.speed, params.fps, params.paused),
            player: Player::new(Arc::clone(&params.motion)),
            params: params.clone(),
            prev: None,
            crossed: Vec::new(),
            json: FrameEncoder::new(Encoding::Json),
            protobuf: FrameEncoder::new(Encoding::Protobuf),
        }
    }

    /// Applies `controls` (in stamp order) at tick `k`; returns whether
    /// time jumped. Playhead controls take effect at their stamps exactly;
    /// a seek stamped for a tick the task skipped (it woke late) shows at
    /// `k` the time it would have reached by then, so every frame is as if
    /// it had applied at its stamp.
    fn apply_all(&mut self, controls: Vec<(u64, Control)>, k: u64) -> bool {
        let mut seeks = Vec::new();
        let mut jumped = false;
        for (stamp, control) in controls {
            match control {
                // The stream time at its stamp: later controls only move times after their own stamps.
                Control::Seek(tau) => seeks.push((tau, self.playhead.time_at(stamp))),
                c => jumped |= self.apply(c, stamp),
            }
        }
        let now = self.playhead.time_at(k);
        for (tau, at) in seeks {
            self.player.seek(if now == at { tau } else { tau + (now - at) });
            jumped = true;
        }
        jumped
    }

    /// Applies a control (not a seek) stamped for tick `k`; returns whether time jumped.
    fn apply(&mut self, control: Control, k: u64) -> bool {
        match control {
            Control::Crossfade(Crossfade { to, duration, ease }) => {
                if let Err(e) = self.player.crossfade(to, duration, ease) {
                    tracing::error!(error = %e, "a crossfade the broadcast accepted was refused");
                }
                false
            }
            Control::Layer { index, weight, duration } => {
                if let Err(e) = self.player.ramp(index, weight, duration) {
                    tracing::error!(error = %e, "a weight ramp the broadcast accepted was refused");
                }
                false
            }
            Control::SetIk(constraints) => {
                self.player.set_ik(constraints);
                false
            }
            Control::Seek(_) | Control::Ik(_) | Control::Stop => false,
            c => self.playhead.apply(c, k),
        }
    }

    /// Samples tick `k` once for every encoding; returns its clip time.
    fn evaluate(&mut self, k: u64, jumped: bool) -> f32 {
        let time = self.playhead.time_at(k);
        sample_tick(&mut self.player, &self.params, time, jumped, &mut self.prev, &mut self.crossed)
    }

    /// The evaluated tick `k` in `encoding`: `dropped` 0 and no joint names
    /// (each viewer's patch adds its own, see `encode`).
    fn encode(&mut self, encoding: Encoding, k: u64, sent_at: i64, clip_time: f32) -> Encoded {
        let tick = TickStamp { seq: k, dropped: 0, sent_at, clip_time };
        let data = frame_data(&self.player, &self.params, &self.crossed, tick, false);
        match encoding {
            Encoding::Json => self.json.encode(&data),
            Encoding::Protobuf => self.protobuf.encode(&data),
        }
    }
}
