//! Broadcasts (docs/broadcasts.md): one named playback of a motion on a fixed tick
//! grid, driven by controllers and watched by any number of viewers who
//! join and leave at any time, on one node or on every node of a cluster.
//!
//! A broadcast is its own task (with the precise timer, on the
//! producers' thread, so it never waits behind its viewers: `producer`). Tick `k` falls at `created_at + k/fps` by
//! the wall clock (mapped onto the monotonic clock once, when the node
//! starts the broadcast), so every node ticks on the same grid. At each
//! tick the task files the controls accepted since the last one and steps
//! its [`Program`] through tick `k` (every tick, watched or not: frame `k`
//! is a pure function of the definition, the controls and `k`, see
//! `broadcast_program`), then encodes the frame once per encoding that has
//! viewers and publishes the bytes on that encoding's broadcast channel (as
//! a shared playback does, see `hub`). A viewer subscribes to the channel
//! of its encoding, so its first frame is the next tick after it joined;
//! its [`Subscription`] turns gaps in `seq` into its own `dropped` (0 on its
//! first frame) and patches only that number (and, in protobuf, the joint
//! names of its first frame) into the shared bytes. A slow viewer loses
//! only its own oldest frames.
//!
//! A control is stamped, when accepted, with the first tick not yet taken —
//! or, with a control lead (many nodes), the tick due at now + lead, so the
//! other nodes hear of it before its tick — and that `seq` is what its
//! sender is told. Controls come from this node ([`Broadcast::prepare`] +
//! [`Broadcast::accept`], or [`Broadcast::control`]) or from the store
//! ([`Broadcasts::adopt`], [`Broadcast::heard`]); one heard for a tick
//! already stepped makes the task step again from the latest state it kept
//! before that tick. A copy adopted from the store starts from the newest
//! stored checkpoint (`checkpoint`); the task stores one every checkpoint
//! interval, a second plus the control lead after its tick (so that every
//! control stamped before it has been heard; the store keeps it only if it
//! holds exactly the stored controls of its ticks, and refuses a control
//! for a tick a stored checkpoint has passed: [`Journal::checkpoint`]), and
//! forgets the controls before the oldest state it keeps. A long catch-up stops between ticks when the broadcast
//! is deleted or the server shuts down.
//!
//! Its work is priced and charged to its creator for its life, re-priced
//! by the controls that change it, and each tick's CPU is metered against
//! that price: one that overruns it ends alone ([`EndReason::TooMuchWork`];
//! `broadcast_budget`). A control takes a place in its bounded store queue
//! ([`STORE_QUEUE`]) before it is applied, and is withdrawn if the store
//! refuses it, so every control applied is stored.
//!
//! Compact viewers are encoded once per layout (`max_error`, `distance`);
//! each layout follows what the program has played (`broadcast_reach`):
//! a control that widens it has the layouts of that reach chosen on the
//! work pool ([`LayoutWork`], charged before any work), kept in a small
//! book, and each tick puts every channel in the layout of the reach it
//! stepped (a channel whose layout is not chosen yet skips the tick).
//!
//! After `idle_timeout` with no viewers and no controls it ends (with a
//! [`Journal`], only when no node had viewers either). It also ends when
//! deleted (viewers get [`EndReason::Ended`]: close 1000 / gRPC OK) and at
//! shutdown.
//!
//! The registry ([`Broadcasts`]) is a std mutex around a map, held for one
//! lookup, insert or removal; the controls desk of each broadcast likewise,
//! never across an await.

use std::collections::{HashMap, HashSet};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use futures_util::future::BoxFuture;
use tokio::sync::{Notify, OwnedSemaphorePermit, Semaphore, broadcast, oneshot, watch};
use tokio::time::Instant;

use super::broadcast_budget::{BroadcastCharge, Budget, Overrun, thread_cpu_ns};
use super::broadcast_program::{ControlLog, Program, StampedControl};
use super::broadcast_reach::{Reach, ReachSig};
use super::checkpoint::Checkpoint;
use super::compact::{CompactLayout, CompactRefusal};
use super::control::{Control, ControlCheck, ControlError};
use super::encode::Encoding;
use super::fanout::Fanout;
use super::hub::{EndReason, Item, unix_nanos};
use super::limits::StreamPermit;
use super::params::StreamParams;
use super::pinned::StreamMotion;
use super::schedule::{Grid, Schedule};
use super::subscription::{ControlSink, Source, StoreOutcome, Subscription};

/// Controls accepted but not yet applied, per broadcast, at most.
const PENDING_CONTROLS: usize = 64;

/// Store writes of one broadcast's controls under way, at most: a control
/// beyond is refused (`unavailable`, 503 with `Retry-After`), never applied.
pub const STORE_QUEUE: usize = 64;

/// What a controlling viewer's controls must pass before they reach the
/// broadcast (the server's write budget); `None` in [`Broadcast::watch`]:
/// a read-only viewer.
pub type ControlGate = Arc<dyn Fn() -> Result<(), ControlError> + Send + Sync>;

/// A catch-up longer than this many ticks runs on a blocking thread.
const BLOCKING_CATCH_UP: u64 = 256;

/// How long after its tick (beyond the control lead) a checkpoint is
/// stored: every control stamped before it has been heard by then.
const SETTLE: Duration = Duration::from_secs(1);

/// Why a broadcast could not be created.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum BroadcastError {
    #[error("{limit} broadcasts are live, the most this server runs at once (max_broadcasts)")]
    TooMany { limit: usize },
    #[error("the server is shutting down")]
    ShuttingDown,
}

/// Where broadcasts are kept beyond this process (the server's store): a
/// viewer socket's controls, the viewers' liveness and the idle end, which
/// with many nodes are decided across all of them. Implemented by the
/// server; without one a broadcast lives in this process alone.
pub trait Journal: Send + Sync + 'static {
    /// Stores a control a viewer's socket sent (`json` is its message;
    /// `fade_to`, a crossfade's motion, whose clips' versions go with it),
    /// already applied here; the other nodes hear of it from the store.
    /// A refusal is what its sender is told (the control is withdrawn).
    fn record(
        &self,
        broadcast: &str,
        seq: u64,
        id: &str,
        json: serde_json::Value,
        fade_to: Option<&StreamMotion>,
    ) -> BoxFuture<'static, Result<(), ControlError>>;
    /// The broadcast ended here for a reason every node shares (its work
    /// overran its price): ends it everywhere.
    fn ended(&self, broadcast: &str) -> BoxFuture<'static, ()>;
    /// The broadcast has viewers on this node now.
    fn touch(&self, broadcast: &str) -> BoxFuture<'static, ()>;
    /// Ends the broadcast everywhere if no node has had viewers and nobody
    /// a control for `idle`; returns whether it did.
    fn expire(&self, broadcast: &str, idle: Duration) -> BoxFuture<'static, bool>;
    /// Stores `checkpoint`, whose state has applied `controls` (id, seq:
    /// every one this node heard stamped from `from` to its tick), and lets go of the controls it makes unnecessary. The
    /// store keeps it only if the controls stored for its ticks are
    /// exactly those (a node that has not heard one, or applied one not
    /// stored, writes nothing), and refuses a control for a tick a stored
    /// checkpoint has passed: a node restoring it plays what every node
    /// plays.
    fn checkpoint(
        &self,
        broadcast: &str,
        checkpoint: &Checkpoint,
        from: u64,
        controls: Vec<(String, u64)>,
    ) -> BoxFuture<'static, ()> {
        let _ = (broadcast, checkpoint, from, controls);
        Box::pin(async {})
    }
}

/// Where a broadcast's new compact layouts are priced and chosen (the
/// server's work pool, docs/compact-frames.md "A broadcast's layouts");
/// without one they are chosen on a blocking thread, unpriced.
pub trait LayoutWork: Send + Sync + 'static {
    /// Charges `units` for choosing new layouts, before any work.
    ///
    /// # Errors
    /// `too_much_work` over `max_request_work`, `caller_work_limit`,
    /// `overloaded`.
    fn charge(&self, units: u64) -> Result<Held, ControlError>;
    /// Charges `units` without refusing: the layouts of controls already
    /// applied (heard from another node, or stepped before a viewer came).
    fn hold(&self, units: u64) -> Held;
    /// Runs `job` on the work pool, holding `held` until it ends; yields
    /// whether it ran (not past the request timeout).
    fn run(&self, held: Held, job: Box<dyn FnOnce() + Send>) -> BoxFuture<'static, bool>;
}

/// A charge held while layouts are chosen.
pub type Held = Box<dyn std::any::Any + Send>;

/// How often broadcasts are checkpointed, and how many controls one may
/// hold between checkpoints (docs/broadcasts.md "Checkpoints").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Checkpointing {
    /// Broadcast time between checkpoints.
    pub every: Duration,
    /// Controls a broadcast keeps since its newest checkpoint, at most.
    pub max_journal: usize,
}

impl Default for Checkpointing {
    fn default() -> Self {
        Checkpointing { every: Duration::from_secs(10), max_journal: 1024 }
    }
}

impl Checkpointing {
    /// Ticks between checkpoints at `fps` (at least one).
    fn ticks(&self, fps: u32) -> u64 {
        ((self.every.as_nanos() * u128::from(fps) / 1_000_000_000) as u64).max(1)
    }
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
    /// Its price per second of playback as created, in work units.
    pub work_per_sec: u64,
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
    /// How far ahead of now a control is stamped (with many nodes, so the
    /// others hear of it before its tick).
    lead: Duration,
    checkpointing: Checkpointing,
    journal: OnceLock<Arc<dyn Journal>>,
    layout_work: OnceLock<Arc<dyn LayoutWork>>,
    shutdown: watch::Receiver<bool>,
}

impl std::fmt::Debug for Broadcasts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Broadcasts").field("max", &self.inner.max).finish_non_exhaustive()
    }
}

/// What a broadcast started here has behind it: the controls so far, and
/// the newest stored checkpoint (whose controls are among them).
struct Past {
    controls: Vec<StampedControl>,
    checkpoint: Option<Checkpoint>,
}

/// Where a broadcast's ticks fall on this node: its tick `base + k` is
/// grid tick `first + k` of `grid`.
#[derive(Debug, Clone, Copy)]
struct Placement {
    grid: Grid,
    first: u64,
    base: u64,
    /// The grid's phase against the engine's epoch, whole ms (what a
    /// client measuring lateness is told).
    phase_ms: u32,
}

impl Broadcasts {
    /// At most `max` live broadcasts on the engine's clock `epoch`, each
    /// viewer buffering `buffer` frames, controls stamped `lead` ahead.
    pub(crate) fn new(
        max: usize,
        epoch: Instant,
        buffer: usize,
        precise: bool,
        lead: Duration,
        checkpointing: Checkpointing,
        shutdown: watch::Receiver<bool>,
    ) -> Self {
        let journal = OnceLock::new();
        let live = Mutex::default();
        let layout_work = OnceLock::new();
        let registry =
            Registry { live, max, epoch, buffer, precise, lead, checkpointing, journal, layout_work, shutdown };
        Broadcasts { inner: Arc::new(registry) }
    }

    /// Prices and chooses broadcasts' new compact layouts with `work` from
    /// now on (set once, at startup).
    pub fn set_layout_work(&self, work: Arc<dyn LayoutWork>) {
        let _ = self.inner.layout_work.set(work);
    }

    /// Keeps broadcasts in `journal` from now on (set once, at startup).
    pub fn set_journal(&self, journal: Arc<dyn Journal>) {
        let _ = self.inner.journal.set(journal);
    }

    fn lock(&self) -> MutexGuard<'_, HashMap<Arc<str>, Arc<Broadcast>>> {
        crate::sync::lock(&self.inner.live)
    }

    /// Starts a broadcast of `spec`; its first tick is the next of its grid
    /// (its `created_at`).
    ///
    /// # Errors
    /// `max` broadcasts are live, or the engine is shutting down.
    pub fn create(&self, spec: BroadcastSpec, charge: BroadcastCharge) -> Result<Arc<Broadcast>, BroadcastError> {
        let id: Arc<str> = uuid::Uuid::now_v7().hyphenated().to_string().into();
        let fps = spec.params.fps;
        // Spread broadcasts over the period like playbacks (see `schedule`).
        let phase_ms = (uuid_low(&id) % u64::from(Grid::phases(fps))) as u32;
        let grid = Grid { epoch: self.inner.epoch, fps, phase_ms };
        let (now, now_unix) = (Instant::now(), unix_nanos());
        let first = grid.next_at_or_after(now);
        let created_at = now_unix + grid.at(first).saturating_duration_since(now).as_nanos() as i64;
        let placement = Placement { grid, first, base: 0, phase_ms };
        self.start(id, spec, created_at, placement, charge, Past { controls: Vec::new(), checkpoint: None })
    }

    /// Runs here a broadcast created elsewhere (another node, or this one
    /// before a restart): `id`, created at `created_at` (Unix ns, its tick
    /// 0), with its `controls` so far and its newest stored `checkpoint`
    /// (the controls it names among `controls`). Its frames are computed
    /// from them (`broadcast_program`), stepping from the checkpoint (else
    /// from tick 0) to the tick the wall clock says. Already live: the
    /// controls are added to it (and `charge` dropped).
    ///
    /// # Errors
    /// As [`Broadcasts::create`].
    pub fn adopt(
        &self,
        id: &str,
        spec: BroadcastSpec,
        created_at: i64,
        controls: Vec<StampedControl>,
        charge: BroadcastCharge,
        checkpoint: Option<Checkpoint>,
    ) -> Result<Arc<Broadcast>, BroadcastError> {
        if let Some(live) = self.get(id) {
            for c in controls {
                live.heard(c);
            }
            return Ok(live);
        }
        let placement = self.placement(spec.params.fps, created_at);
        self.start(id.into(), spec, created_at, placement, charge, Past { controls, checkpoint })
    }

    /// Where the ticks of a broadcast created at `created_at` (Unix ns) fall
    /// on this node: tick `k` at `created_at + ⌊k·10⁹/fps⌋` ns by the wall
    /// clock, mapped onto the monotonic clock once, here. The grid starts
    /// at the latest tick due (`base`), so it never needs an instant before
    /// this machine booted.
    fn placement(&self, fps: u32, created_at: i64) -> Placement {
        let (now, now_unix) = (Instant::now(), unix_nanos());
        let nanos = |k: u64| (u128::from(k) * 1_000_000_000 / u128::from(fps)) as i64;
        let elapsed = now_unix - created_at;
        let (base, origin) = if elapsed < 0 {
            (0, now + Duration::from_nanos(elapsed.unsigned_abs()))
        } else {
            let k = (i128::from(elapsed) * i128::from(fps) / 1_000_000_000) as u64;
            let behind = now_unix - (created_at + nanos(k));
            (k, now.checked_sub(Duration::from_nanos(behind.max(0) as u64)).unwrap_or(now))
        };
        let period = 1_000_000_000 / i128::from(fps);
        let offset = if origin >= self.inner.epoch {
            origin.duration_since(self.inner.epoch).as_nanos() as i128
        } else {
            -(self.inner.epoch.duration_since(origin).as_nanos() as i128)
        };
        let phase_ms = (offset.rem_euclid(period) / 1_000_000) as u32;
        Placement { grid: Grid { epoch: origin, fps, phase_ms: 0 }, first: 0, base, phase_ms }
    }

    fn start(
        &self,
        id: Arc<str>,
        spec: BroadcastSpec,
        created_at: i64,
        placement: Placement,
        charge: BroadcastCharge,
        Past { controls, checkpoint }: Past,
    ) -> Result<Arc<Broadcast>, BroadcastError> {
        if *self.inner.shutdown.borrow() {
            return Err(BroadcastError::ShuttingDown);
        }
        let schedule = Schedule::new(placement.grid, placement.first, 0).precise(self.inner.precise);
        let broadcast = Arc::new(Broadcast {
            id: Arc::clone(&id),
            created_at,
            json: Channel::new(self.inner.buffer),
            protobuf: Channel::new(self.inner.buffer),
            compact: Mutex::new(Vec::new()),
            layouts: Arc::new(Mutex::new(Book::default())),
            layout_work: self.inner.layout_work.get().cloned(),
            runtime: tokio::runtime::Handle::current(),
            buffer: self.inner.buffer,
            desk: Arc::new(Mutex::new(Desk {
                budget: Budget::new(charge, &spec.params.motion, spec.params.fps),
                next: placement.base,
                inbox: Vec::new(),
                revoked: Vec::new(),
                known: HashSet::new(),
                check: ControlCheck::new(&spec.params),
                reach: Reach::new(&spec.params),
                paused: spec.params.paused,
                speed: spec.params.speed,
                last_control: Instant::now(),
            })),
            store_slots: Arc::new(Semaphore::new(STORE_QUEUE)),
            stop: Arc::new(AtomicBool::new(false)),
            deleted: Notify::new(),
            ended: AtomicBool::new(false),
            journal_len: AtomicUsize::new(0),
            max_journal: self.inner.checkpointing.max_journal,
            placement,
            schedule: schedule.clone(),
            lead: self.inner.lead,
            journal: self.inner.journal.get().cloned(),
            spec,
        });
        let already = {
            let mut live = self.lock();
            match live.get(&id) {
                // Adopted meanwhile (an announcement and a viewer's lookup at once): that copy takes the controls.
                Some(already) => Some(Arc::clone(already)),
                None if live.len() >= self.inner.max => return Err(BroadcastError::TooMany { limit: self.inner.max }),
                None => {
                    live.insert(id, Arc::clone(&broadcast));
                    None
                }
            }
        };
        if let Some(already) = already {
            for c in controls {
                already.heard(c);
            }
            return Ok(already);
        }
        let program = self.program(&broadcast, checkpoint.as_ref(), &controls);
        // Restored from a checkpoint, it plays as its state says (the controls that paused it may be gone).
        {
            let mut desk = broadcast.desk();
            (desk.paused, desk.speed) = program.playing();
            desk.reach = program.reach().clone();
        }
        for c in controls {
            broadcast.heard(c);
        }
        metrics::gauge!("inbetween_broadcasts").increment(1.0);
        metrics::counter!("inbetween_broadcasts_total").increment(1);
        let task = Task::new(Arc::clone(&broadcast), self.clone(), schedule, self.inner.shutdown.clone(), program);
        let run = async move {
            crate::panics::guarded("broadcast", task.run()).await;
        };
        // With the precise timer (the server), off the workers its viewers
        // run on, so that no tick waits behind their fan-out (`producer`).
        if self.inner.precise {
            super::producer::spawn(run);
        } else {
            tokio::spawn(run);
        }
        Ok(broadcast)
    }

    /// The program a broadcast starts with: restored from `checkpoint`
    /// (whose controls are among `controls`), else before its tick 0.
    fn program(&self, b: &Broadcast, checkpoint: Option<&Checkpoint>, controls: &[StampedControl]) -> Box<Program> {
        let params = &b.spec.params;
        let every = self.inner.checkpointing.ticks(params.fps);
        let Some(checkpoint) = checkpoint else { return Box::new(Program::new(params).checkpointing(every)) };
        let mut log = ControlLog::default();
        for c in controls {
            log.insert(c.clone());
        }
        match Program::from_checkpoint(params, checkpoint, &log) {
            Ok(program) => Box::new(program.checkpointing(every)),
            Err(error) => {
                tracing::warn!(broadcast = %b.id, %error, "a broadcast checkpoint not used: replaying from tick 0");
                Box::new(Program::new(params).checkpointing(every))
            }
        }
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

    /// Ends broadcast `id` here (its viewers get [`EndReason::Ended`]).
    /// Returns whether it was live.
    pub fn delete(&self, id: &str) -> bool {
        let Some(broadcast) = self.lock().remove(id) else { return false };
        // Stops a long solve of its tick under way (`anim::ik::stoppable`).
        broadcast.stop.store(true, Ordering::Release);
        broadcast.desk().budget.release();
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

/// A fresh control id: UUIDv7 (what orders the controls of one tick).
pub fn new_control_id() -> Arc<str> {
    uuid::Uuid::now_v7().hyphenated().to_string().into()
}

/// Controls accepted and not yet taken by the task, and what they leave playing.
struct Desk {
    /// The first tick the task has not taken: no control is stamped before it.
    next: u64,
    inbox: Vec<StampedControl>,
    /// Ids of controls accepted and then withdrawn (their store write failed).
    revoked: Vec<Arc<str>>,
    /// Ids of every control accepted (one heard twice is taken once).
    known: HashSet<Arc<str>>,
    check: ControlCheck,
    /// What it will have played once the controls accepted apply.
    reach: Reach,
    /// Its price, raised or lowered by the controls that change it.
    budget: Budget,
    paused: bool,
    speed: f64,
    last_control: Instant,
}

/// Layouts of compact frames one broadcast encodes at once.
pub const MAX_COMPACT_LAYOUTS: usize = 4;

/// The viewers of one compact `max_error` and `distance`, and the layout
/// they are sent now: the one of the reach it was chosen for.
struct CompactChannel {
    layout: Arc<CompactLayout>,
    sig: ReachSig,
    tx: Channel,
}

/// The viewers of one encoding (or compact layout): the channel their tasks
/// read, and the fan-out that writes the frames of those whose lanes are
/// parked (`fanout`, `lane`).
struct Channel {
    tx: broadcast::Sender<Item>,
    fanout: Arc<Fanout>,
}

impl Channel {
    fn new(buffer: usize) -> Self {
        Channel { tx: broadcast::channel(buffer).0, fanout: Arc::new(Fanout::new(buffer)) }
    }

    fn receiver_count(&self) -> usize {
        self.tx.receiver_count()
    }

    /// A new viewer's frames from the next tick on, and its fan-out.
    fn subscribe(&self) -> (broadcast::Receiver<Item>, Option<Arc<Fanout>>) {
        (self.tx.subscribe(), Some(Arc::clone(&self.fanout)))
    }

    /// Sends `item` to the viewers' tasks, then to the fan-out: in that
    /// order, as a lane parks only while its channel holds nothing it has
    /// not seen (`lane`). Never waits.
    fn send(&self, item: Item) {
        // An error only means no task reads the channel now.
        let _ = self.tx.send(item.clone());
        self.fanout.publish(&item);
    }
}

/// Layouts of one `max_error` and `distance` kept for reaches, at most.
const BOOK: usize = 32;

/// The compact layouts chosen (or being chosen) for the reaches the
/// broadcast played or is about to, per `max_error` and `distance`.
#[derive(Default)]
struct Book {
    entries: std::collections::VecDeque<((u32, u32), ReachSig, Chosen)>,
}

#[derive(Clone)]
enum Chosen {
    Pending,
    Ready(Arc<CompactLayout>),
    /// Its work was refused or failed: its viewers are ended.
    Failed,
}

impl Book {
    fn get(&self, key: (u32, u32), sig: &ReachSig) -> Option<Chosen> {
        self.entries.iter().find(|(k, s, _)| *k == key && s == sig).map(|(_, _, c)| c.clone())
    }

    fn put(&mut self, key: (u32, u32), sig: &ReachSig, chosen: Chosen) {
        match self.entries.iter_mut().find(|(k, s, _)| *k == key && s == sig) {
            Some(entry) => entry.2 = chosen,
            None => {
                if self.entries.len() >= BOOK * MAX_COMPACT_LAYOUTS {
                    self.entries.pop_front();
                }
                self.entries.push_back((key, sig.clone(), chosen));
            }
        }
    }
}

/// One live broadcast.
pub struct Broadcast {
    id: Arc<str>,
    spec: BroadcastSpec,
    /// Unix ns of its tick 0.
    created_at: i64,
    placement: Placement,
    schedule: Schedule,
    lead: Duration,
    journal: Option<Arc<dyn Journal>>,
    json: Channel,
    protobuf: Channel,
    /// Compact viewers' channels, one per layout (at most [`MAX_COMPACT_LAYOUTS`]).
    compact: Mutex<Vec<CompactChannel>>,
    /// Their layouts for each reach (locked after `compact`, never before).
    layouts: Arc<Mutex<Book>>,
    layout_work: Option<Arc<dyn LayoutWork>>,
    /// Where the choosing of layouts is started from.
    runtime: tokio::runtime::Handle,
    /// Frames a viewer's channel holds.
    buffer: usize,
    desk: Arc<Mutex<Desk>>,
    /// Its controls' store writes under way ([`STORE_QUEUE`]).
    store_slots: Arc<Semaphore>,
    /// Raised when it is deleted: a chain solve under way stops, and a
    /// catch-up stops between ticks.
    stop: Arc<AtomicBool>,
    deleted: Notify,
    ended: AtomicBool,
    /// Controls it holds since its newest checkpoint (kept by its task).
    journal_len: AtomicUsize,
    max_journal: usize,
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
        UNIX_EPOCH + Duration::from_nanos(self.created_at.max(0) as u64)
    }

    /// Unix nanoseconds of tick 0: the grid every node puts its ticks on.
    pub fn created_at_unix_nanos(&self) -> i64 {
        self.created_at
    }

    /// The phase of its grid against the engine's epoch, whole ms.
    pub fn phase_ms(&self) -> u32 {
        self.placement.phase_ms
    }

    /// The channel of JSON or protobuf frames (compact frames have one per layout).
    fn channel(&self, encoding: Encoding) -> &Channel {
        match encoding {
            Encoding::Json => &self.json,
            Encoding::Protobuf | Encoding::Compact => &self.protobuf,
        }
    }

    fn viewers(&self) -> usize {
        let compact: usize = crate::sync::lock(&self.compact).iter().map(|c| c.tx.receiver_count()).sum();
        self.json.receiver_count() + self.protobuf.receiver_count() + compact
    }

    /// What it will have played once the controls accepted apply: what a
    /// compact watch opened now chooses its layout for.
    pub fn reach(&self) -> Reach {
        self.desk().reach.clone()
    }

    /// A viewer of compact frames of `layout` (chosen for `reach`) from
    /// the next tick on, as [`Broadcast::watch`]; a viewer of a `max_error`
    /// and `distance` already watched joins its channel, in the layout it
    /// is sent. Refused beyond [`MAX_COMPACT_LAYOUTS`] layouts at once.
    ///
    /// # Errors
    /// `too_many_compact_layouts`.
    pub fn watch_compact(
        self: &Arc<Self>,
        (layout, reach): (Arc<CompactLayout>, ReachSig),
        permit: StreamPermit,
        controls: Option<ControlGate>,
    ) -> Result<Subscription, CompactRefusal> {
        let (rx, fanout) = {
            let mut channels = crate::sync::lock(&self.compact);
            if self.ended.load(Ordering::Acquire) {
                let (tx, rx) = broadcast::channel(1);
                let _ = tx.send(Item::End(EndReason::Ended));
                drop(channels);
                return Ok(self.subscription(Encoding::Compact, (rx, None), None, permit));
            }
            channels.retain(|c| c.tx.receiver_count() > 0);
            crate::sync::lock(&self.layouts).put(layout.key(), &reach, Chosen::Ready(Arc::clone(&layout)));
            match channels.iter().find(|c| c.layout.key() == layout.key()) {
                Some(c) => c.tx.subscribe(),
                None if channels.len() >= MAX_COMPACT_LAYOUTS => {
                    return Err(CompactRefusal {
                        code: "too_many_compact_layouts",
                        field: "max_error",
                        detail: format!(
                            "this broadcast already sends compact frames of {MAX_COMPACT_LAYOUTS} layouts; ask for \
                             the `max_error` and `distance` of one of them"
                        ),
                    });
                }
                None => {
                    let tx = Channel::new(self.buffer);
                    let rx = tx.subscribe();
                    channels.push(CompactChannel { layout: Arc::clone(&layout), sig: reach, tx });
                    rx
                }
            }
        };
        metrics::counter!("inbetween_broadcast_viewers_total").increment(1);
        let sink = controls.map(|gate| Arc::new(Gated { broadcast: Arc::clone(self), gate }) as Arc<dyn ControlSink>);
        let params = StreamParams { max_frames: None, ..self.spec.params.clone() }.with_compact(layout);
        let shutdown = watch::Sender::new(false).subscribe();
        let source = Source::Broadcast { rx, controls: sink, fanout };
        Ok(Subscription::new(params, self.schedule.clone(), source, shutdown, permit))
    }

    /// Puts each channel in its layout for `reach` (what the tick just
    /// stepped has played); returns the keys of those whose layout is not
    /// chosen yet (they skip this tick). A channel whose layout could not
    /// be chosen ends.
    fn follow_reach(&self, channels: &mut Vec<CompactChannel>, reach: &Reach) -> Vec<(u32, u32)> {
        let sig = reach.sig();
        let book = crate::sync::lock(&self.layouts);
        let mut missing = Vec::new();
        channels.retain_mut(|c| {
            if c.sig == sig {
                return true;
            }
            match book.get(c.layout.key(), &sig) {
                Some(Chosen::Ready(layout)) => (c.layout, c.sig) = (layout, sig.clone()),
                Some(Chosen::Failed) => {
                    c.tx.send(Item::End(EndReason::Failed));
                    return false;
                }
                Some(Chosen::Pending) => missing.push(c.layout.key()),
                None => missing.push(c.layout.key()),
            }
            true
        });
        missing
    }

    /// The `max_error` and `distance` of the compact layouts watched now.
    fn watched_keys(&self) -> Vec<(u32, u32)> {
        let channels = crate::sync::lock(&self.compact);
        channels.iter().filter(|c| c.tx.receiver_count() > 0).map(|c| c.layout.key()).collect()
    }

    /// What choosing the layouts of `keys` for `reach` costs: its range
    /// samples (each a pose of the costliest clip they read) and one
    /// choice per layout.
    fn layouts_price(&self, reach: &Reach, keys: usize) -> u64 {
        let params = &self.spec.params;
        let samples = reach.samples(params).saturating_add(keys as u64);
        crate::work::price::compact_layout(samples, reach.sample_price(params, &crate::work::price::clip_pose))
    }

    /// Chooses the layouts of `keys` for `reach` on the work pool (those
    /// not chosen or being chosen yet), holding `held` (`None`: charged
    /// now, without refusing).
    fn choose_layouts(&self, reach: &Reach, keys: Vec<(u32, u32)>, held: Option<Held>) {
        let sig = reach.sig();
        let keys: Vec<_> = {
            let mut book = crate::sync::lock(&self.layouts);
            let missing: Vec<_> = keys.into_iter().filter(|k| book.get(*k, &sig).is_none()).collect();
            missing.iter().for_each(|k| book.put(*k, &sig, Chosen::Pending));
            missing
        };
        if keys.is_empty() {
            return;
        }
        let units = self.layouts_price(reach, keys.len());
        let (params, reach, book) = (self.spec.params.clone(), reach.clone(), Arc::clone(&self.layouts));
        let (failed, book_again, sig_again) = (keys.clone(), Arc::clone(&book), sig.clone());
        let job = move || {
            for key in keys {
                let (max_error, distance) = (f32::from_bits(key.0), Some(f32::from_bits(key.1)));
                let chosen = match reach.layout(&params, max_error, distance) {
                    Ok(layout) => Chosen::Ready(Arc::new(layout)),
                    Err(e) => {
                        tracing::warn!(error = %e, "a broadcast's compact layout could not be chosen");
                        Chosen::Failed
                    }
                };
                crate::sync::lock(&book).put(key, &sig, chosen);
            }
        };
        let Some(work) = &self.layout_work else {
            drop(self.runtime.spawn_blocking(job));
            return;
        };
        let held = held.unwrap_or_else(|| work.hold(units));
        let run = work.run(held, Box::new(job));
        drop(self.runtime.spawn(async move {
            if !run.await {
                let mut book = crate::sync::lock(&book_again);
                for k in failed {
                    if matches!(book.get(k, &sig_again), Some(Chosen::Pending)) {
                        book.put(k, &sig_again, Chosen::Failed);
                    }
                }
            }
        }));
    }

    fn desk(&self) -> MutexGuard<'_, Desk> {
        crate::sync::lock(&self.desk)
    }

    /// The broadcast tick due at or before `at` (0 before its first).
    fn tick_at_or_before(&self, at: Instant) -> u64 {
        let p = &self.placement;
        p.base + p.grid.latest_at_or_before(at).saturating_sub(p.first)
    }

    /// Where it is now: its tick by the clock, and the playhead its
    /// accepted controls leave.
    pub fn status(&self) -> BroadcastStatus {
        let seq = self.tick_at_or_before(Instant::now());
        let desk = self.desk();
        BroadcastStatus { seq, paused: desk.paused, speed: desk.speed, viewers: self.viewers() }
    }

    /// A viewer of `encoding` from the next tick on; `controls`: its
    /// controls reach the broadcast once they pass the gate (the transport
    /// checked the write scope), `None`: they are refused.
    pub fn watch(
        self: &Arc<Self>,
        encoding: Encoding,
        permit: StreamPermit,
        controls: Option<ControlGate>,
    ) -> Subscription {
        let (rx, fanout) = self.channel(encoding).subscribe();
        if self.ended.load(Ordering::Acquire) {
            // It ended between the lookup and the subscription: say so at once.
            let (tx, rx) = broadcast::channel(1);
            let _ = tx.send(Item::End(EndReason::Ended));
            return self.subscription(encoding, (rx, None), None, permit);
        }
        metrics::counter!("inbetween_broadcast_viewers_total").increment(1);
        let sink = controls.map(|gate| Arc::new(Gated { broadcast: Arc::clone(self), gate }) as Arc<dyn ControlSink>);
        self.subscription(encoding, (rx, fanout), sink, permit)
    }

    fn subscription(
        &self,
        encoding: Encoding,
        (rx, fanout): (broadcast::Receiver<Item>, Option<Arc<Fanout>>),
        controls: Option<Arc<dyn ControlSink>>,
        permit: StreamPermit,
    ) -> Subscription {
        let params = StreamParams { encoding, max_frames: None, ..self.spec.params.clone() };
        let shutdown = watch::Sender::new(false).subscribe();
        Subscription::new(params, self.schedule.clone(), Source::Broadcast { rx, controls, fanout }, shutdown, permit)
    }

    /// Checks `control` like a stream's (`stop` is refused: delete the
    /// broadcast) and stamps it: the first tick not yet produced, or with
    /// a control lead the tick due at now + lead, whichever is later. It is
    /// not applied until [`Broadcast::accept`], which the caller does at
    /// once (so it is never late here), before storing it.
    ///
    /// # Errors
    /// An invalid control, too many pending, or the broadcast has ended.
    pub fn prepare(&self, control: Control) -> Result<(u64, Control), ControlError> {
        self.admissible(&control)?;
        let ahead = self.ahead();
        self.stamp(&mut self.desk(), control, ahead).map(|(seq, control, _)| (seq, control))
    }

    /// [`Broadcast::prepare`] and [`Broadcast::accept`] under one lock (so
    /// the task cannot take the stamped tick in between), as control `id`.
    ///
    /// # Errors
    /// As [`Broadcast::prepare`].
    pub fn take(&self, control: Control, id: Arc<str>) -> Result<u64, ControlError> {
        self.admissible(&control)?;
        let ahead = self.ahead();
        let mut desk = self.desk();
        let (seq, control, held) = self.stamp(&mut desk, control, ahead)?;
        self.file(&mut desk, StampedControl { seq, id, control }, held);
        Ok(seq)
    }

    fn admissible(&self, control: &Control) -> Result<(), ControlError> {
        if let Some(refusal) = control.refused_on_broadcast() {
            return Err(ControlError::Invalid(refusal));
        }
        if let Control::Crossfade(fade) = control
            && anim::compact::Ranges::boundable(&fade.to).is_err()
            && !self.watched_keys().is_empty()
        {
            return Err(ControlError::Invalid(
                "compact viewers watch this broadcast: it cannot crossfade to a motion whose poses no range bounds \
                 (a layer retargeted onto a character, root motion `extract`)",
            ));
        }
        if self.ended.load(Ordering::Acquire) {
            return Err(ControlError::Invalid("the broadcast has ended"));
        }
        if self.journal_len.load(Ordering::Relaxed) >= self.max_journal {
            return Err(ControlError::JournalFull);
        }
        Ok(())
    }

    /// With a control lead, the tick due at now + lead.
    fn ahead(&self) -> Option<u64> {
        (!self.lead.is_zero()).then(|| {
            let p = &self.placement;
            p.base + p.grid.next_at_or_after(Instant::now() + self.lead).saturating_sub(p.first)
        })
    }

    /// Checks and prices `control` (nothing changes if either refuses it)
    /// and stamps it; with the charge for the compact layouts it makes the
    /// broadcast choose, if it leaves the watched ones.
    fn stamp(
        &self,
        desk: &mut Desk,
        control: Control,
        ahead: Option<u64>,
    ) -> Result<(u64, Control, Option<Held>), ControlError> {
        if desk.inbox.len() >= PENDING_CONTROLS {
            return Err(ControlError::Busy);
        }
        let mut check = desk.check.clone();
        let control = check.check(control)?;
        if desk.reach.full_for(&control) {
            let detail = format!(
                "this broadcast has crossfaded to {} distinct motions, the most its compact layouts keep track of; \
                 crossfade to one of those",
                super::broadcast_reach::MAX_PLAYED
            );
            return Err(
                crate::error::ApiError::Relayed { status: 422, code: "broadcast_motions_full", detail }.to_control()
            );
        }
        let held = self.charge_layouts(desk, &control)?;
        desk.budget.reprice(&control, check.motion())?;
        desk.check = check;
        Ok((ahead.unwrap_or(0).max(desk.next), control, held))
    }

    /// Charges choosing the new layouts `control` makes the watched ones
    /// need (docs/compact-frames.md "A broadcast's layouts"), before any
    /// work; `None`: it needs none.
    fn charge_layouts(&self, desk: &Desk, control: &Control) -> Result<Option<Held>, ControlError> {
        let (Some(work), keys) = (&self.layout_work, self.watched_keys()) else { return Ok(None) };
        let mut next = desk.reach.clone();
        next.apply(control, &new_control_id(), self.spec.params.motion.skeleton());
        if keys.is_empty() || next.sig() == desk.reach.sig() {
            return Ok(None);
        }
        let units = self.layouts_price(&next, keys.len());
        let limit = desk.budget.limit();
        if units > limit {
            let detail = format!(
                "choosing this broadcast's new compact layouts costs {units} work units; the limit \
                 (max_request_work, --max-request-work) is {limit}"
            );
            return Err(crate::error::ApiError::Relayed { status: 422, code: "too_much_work", detail }.to_control());
        }
        work.charge(units).map(Some)
    }

    /// Applies a prepared control from its stamp on, for every viewer.
    pub fn accept(&self, control: StampedControl) {
        self.file(&mut self.desk(), control, None);
    }

    /// Files `control` for the task; if it changes what the broadcast will
    /// have played, chooses the watched layouts for that (holding `held`,
    /// its charge, if it was charged).
    fn file(&self, desk: &mut Desk, control: StampedControl, held: Option<Held>) {
        if !desk.known.insert(Arc::clone(&control.id)) {
            return;
        }
        let before = desk.reach.sig();
        desk.reach.apply(&control.control, &control.id, self.spec.params.motion.skeleton());
        let keys = self.watched_keys();
        if desk.reach.sig() != before && !keys.is_empty() {
            self.choose_layouts(&desk.reach, keys, held);
        }
        (desk.paused, desk.speed) = control.control.status_after(desk.paused, desk.speed);
        desk.inbox.push(control);
        desk.last_control = Instant::now();
        metrics::counter!("inbetween_broadcast_controls_total").increment(1);
    }

    /// Takes a control another node stamped (or this one, before a restart),
    /// checked like a local one (an `ik` control's names resolved); one it
    /// already has is ignored. Applied from its stamp, even a past one
    /// (the task then replays, see `broadcast_program`).
    pub fn heard(&self, control: StampedControl) {
        if self.desk().known.contains(&control.id) {
            return;
        }
        let checked = self.desk().check.check(control.control);
        match checked {
            Ok(c) => self.accept(StampedControl { control: c, ..control }),
            Err(e) => {
                tracing::warn!(broadcast = %self.id, control = %control.id, error = %e, "a stored control skipped")
            }
        }
    }

    /// Withdraws a control [`Broadcast::accept`]ed here whose store write
    /// failed (its sender is told so): the frames from its stamp on are
    /// computed again without it, as every other node computes them.
    pub fn revoke(&self, id: &Arc<str>) {
        revoke(&self.desk, id);
    }

    /// A place in its store queue, held until the control's write ends.
    ///
    /// # Errors
    /// [`STORE_QUEUE`] writes are under way: `unavailable`, never applied.
    pub fn store_slot(&self) -> Result<OwnedSemaphorePermit, ControlError> {
        Arc::clone(&self.store_slots).try_acquire_owned().map_err(|_| {
            metrics::counter!("inbetween_broadcast_controls_refused_total", "reason" => "store_queue").increment(1);
            crate::error::ApiError::StoreQueueFull { limit: STORE_QUEUE, retry_after: 1 }.to_control()
        })
    }

    /// Work units of one tick now (its price).
    pub fn tick_price(&self) -> u64 {
        self.desk().budget.per_tick()
    }

    /// The ids of every control it has accepted.
    pub fn control_ids(&self) -> HashSet<String> {
        self.desk().known.iter().map(|id| id.to_string()).collect()
    }

    /// Accepts `control` for every viewer at once (a viewer socket's, or
    /// without a journal); returns its stamp. With a journal it is stored
    /// as well, as the message that says it again (`Control::to_json`),
    /// through the store queue: the outcome yields the refusal its sender
    /// is told if the write fails (the control is then withdrawn here and
    /// no other node ever hears of it).
    ///
    /// # Errors
    /// As [`Broadcast::prepare`]; the store queue is full; a control no
    /// message says again (a crossfade whose motion was not written down)
    /// cannot be stored.
    pub fn control(&self, control: Control) -> Result<(u64, Option<StoreOutcome>), ControlError> {
        let json = match &self.journal {
            Some(_) => Some(control.to_json().ok_or(ControlError::Invalid(
                "this control cannot be stored for the broadcast's other nodes; send it with POST /v1/broadcasts/{id}/controls",
            ))?),
            None => None,
        };
        let fade_to = match &control {
            Control::Crossfade(fade) => Some(Arc::clone(&fade.to)),
            _ => None,
        };
        let slot = json.as_ref().map(|_| self.store_slot()).transpose()?;
        let id = new_control_id();
        let seq = self.take(control, Arc::clone(&id))?;
        let (Some(journal), Some(json), Some(slot)) = (&self.journal, json, slot) else { return Ok((seq, None)) };
        let (tx, outcome) = oneshot::channel();
        let (write, desk) = (journal.record(&self.id, seq, &id, json, fade_to.as_deref()), Arc::clone(&self.desk));
        tokio::spawn(async move {
            let _slot = slot;
            if let Err(refusal) = write.await {
                metrics::counter!("inbetween_broadcast_controls_refused_total", "reason" => "store").increment(1);
                revoke(&desk, &id);
                let _ = tx.send(refusal);
            }
        });
        Ok((seq, Some(outcome)))
    }
}

/// Withdraws control `id` from the desk (see [`Broadcast::revoke`]).
fn revoke(desk: &Mutex<Desk>, id: &Arc<str>) {
    let mut desk = crate::sync::lock(desk);
    desk.inbox.retain(|c| &c.id != id);
    desk.revoked.push(Arc::clone(id));
}

/// A controlling viewer's way to the broadcast: its gate, then the broadcast.
struct Gated {
    broadcast: Arc<Broadcast>,
    gate: ControlGate,
}

impl ControlSink for Gated {
    fn send(&self, control: Control) -> Result<Option<StoreOutcome>, ControlError> {
        (self.gate)()?;
        self.broadcast.control(control).map(|(_, outcome)| outcome)
    }
}

/// The broadcast's own task: its schedule, its program and its idle clock.
struct Task {
    broadcast: Arc<Broadcast>,
    registry: Broadcasts,
    schedule: Schedule,
    program: Option<Box<Program>>,
    log: ControlLog,
    shutdown: watch::Receiver<bool>,
    last_watched: Instant,
    /// When the journal last heard that this node has viewers, or was
    /// asked to end the broadcast.
    journaled: Instant,
    /// Viewers counted into `inbetween_broadcast_viewers` at the last tick.
    counted: usize,
    /// Its ticks' CPU against their price.
    overrun: Overrun,
    /// The runtime the broadcast was created from: what the task starts
    /// besides its ticks (store writes, long catch-ups) runs there.
    origin: tokio::runtime::Handle,
    /// The newest checkpoint handed to the journal.
    checkpointed: Option<u64>,
}

impl Task {
    fn new(
        broadcast: Arc<Broadcast>,
        registry: Broadcasts,
        schedule: Schedule,
        shutdown: watch::Receiver<bool>,
        program: Box<Program>,
    ) -> Self {
        let checkpointed = program.floor().checked_sub(1);
        let overrun = Overrun::new(broadcast.spec.params.fps);
        let program = Some(program);
        let now = Instant::now();
        Task {
            broadcast,
            registry,
            schedule,
            program,
            log: ControlLog::default(),
            shutdown,
            last_watched: now,
            journaled: now,
            counted: 0,
            overrun,
            origin: tokio::runtime::Handle::current(),
            checkpointed,
        }
    }

    async fn run(mut self) {
        let reason = self.ticks().await;
        self.broadcast.ended.store(true, Ordering::Release);
        self.broadcast.desk().budget.release();
        self.registry.unlist(&self.broadcast);
        for tx in [&self.broadcast.json, &self.broadcast.protobuf] {
            tx.send(Item::End(reason));
        }
        // Under the lock a compact watch checks `ended` under: each viewer hears the end.
        for c in crate::sync::lock(&self.broadcast.compact).iter() {
            c.tx.send(Item::End(reason));
        }
        self.count_viewers(0);
        metrics::gauge!("inbetween_broadcasts").decrement(1.0);
        if reason == EndReason::TooMuchWork
            && let Some(journal) = &self.broadcast.journal
        {
            drop(self.origin.spawn(journal.ended(&self.broadcast.id)));
        }
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
            let k = b.placement.base + tick.k;
            let cpu = thread_cpu_ns();
            let (controls, revoked, last_control, allowed_ns) = {
                let mut desk = b.desk();
                desk.next = k + 1;
                let revoked = std::mem::take(&mut desk.revoked);
                (std::mem::take(&mut desk.inbox), revoked, desk.last_control, desk.budget.tick_allowed_ns())
            };
            let stepped_here = self.program.as_ref().is_some_and(|p| k.saturating_sub(p.next()) <= BLOCKING_CATCH_UP);
            if !self.catch_up(controls, &revoked, k).await {
                return if *self.shutdown.borrow() { EndReason::Shutdown } else { EndReason::Ended };
            }
            let stepped = thread_cpu_ns().saturating_sub(cpu);
            self.checkpoint();
            let viewers = b.viewers();
            self.count_viewers(viewers);
            if let Some(reason) = self.idle(viewers, last_control) {
                return reason;
            }
            let encoded = if viewers > 0 { self.publish() } else { 0 };
            // The tick's own work is stepping and encoding it: a catch-up on
            // a blocking thread is not, nor is waking its viewers' tasks (and
            // the network work the kernel does meanwhile), which grows with
            // viewers — their streams' caps bound that, not this price.
            if stepped_here && self.overrun.over(stepped.saturating_add(encoded), allowed_ns) {
                metrics::counter!("inbetween_broadcasts_overrun_total").increment(1);
                tracing::warn!(broadcast = %b.id, allowed_ns, "a broadcast's ticks overran their price; it ends");
                return EndReason::TooMuchWork;
            }
        }
    }

    /// Encodes the tick stepped, once per encoding with viewers, and sends
    /// it; returns the thread CPU the encoding took (not the sends).
    fn publish(&mut self) -> u64 {
        let b = &self.broadcast;
        let sent_at = unix_nanos();
        metrics::counter!("inbetween_broadcast_ticks_total").increment(1);
        let program = self.program.as_mut().expect("the program is back after each catch-up");
        let mut encoded = 0;
        let mut timed = |encode: &mut dyn FnMut() -> Item| {
            let start = thread_cpu_ns();
            let item = encode();
            encoded += thread_cpu_ns().saturating_sub(start);
            item
        };
        for encoding in [Encoding::Json, Encoding::Protobuf] {
            let tx = b.channel(encoding);
            if tx.receiver_count() > 0 {
                tx.send(timed(&mut || Item::Frame(program.encode(encoding, sent_at))));
            }
        }
        // Once per layout watched, whatever its viewers' number.
        let mut channels = crate::sync::lock(&b.compact);
        channels.retain(|c| c.tx.receiver_count() > 0);
        let missing = b.follow_reach(&mut channels, program.reach());
        for c in channels.iter().filter(|c| !missing.contains(&c.layout.key())) {
            c.tx.send(timed(&mut || Item::Frame(program.encode_compact(&c.layout, sent_at))));
        }
        program.keep_compact(|key| channels.iter().any(|c| c.layout.key() == key));
        drop(channels);
        if !missing.is_empty() {
            b.choose_layouts(program.reach(), missing, None);
        }
        encoded
    }

    /// Files `controls` (and drops the `revoked` ones) and steps the program
    /// through tick `k`: again from the latest state kept before the
    /// earliest stamp if one is for a tick already stepped, on a blocking
    /// thread if that is many ticks (a node that joined late, a restart).
    /// Returns `false` if it was cancelled (deleted, shutting down) first.
    async fn catch_up(&mut self, controls: Vec<StampedControl>, revoked: &[Arc<str>], k: u64) -> bool {
        let mut program = self.program.take().expect("the program is back after each catch-up");
        let rewind = self.file(&program, controls, revoked);
        if let Some(stamp) = rewind
            && program.rewind_before(stamp).is_some()
        {
            metrics::counter!("inbetween_broadcast_replays_total").increment(1);
            // A checkpoint stored from before the control is written again.
            self.checkpointed = self.checkpointed.filter(|&c| c < stamp);
        }
        let behind = k.saturating_sub(program.next());
        if behind > 0 {
            // Ticks stepped besides `k` itself: a late start, a restart, a late wake, a rewind.
            metrics::counter!("inbetween_broadcast_replayed_ticks_total").increment(behind);
        }
        let reached = if behind > BLOCKING_CATCH_UP {
            let (log, stop, shutdown) = (self.log.clone(), Arc::clone(&self.broadcast.stop), self.shutdown.clone());
            let stepped = self
                .origin
                .spawn_blocking(move || {
                    let halted = || stop.load(Ordering::Acquire) || *shutdown.borrow();
                    let reached = anim::ik::stoppable(&stop, || program.step_to_unless(k, &log, &halted));
                    (program, reached)
                })
                .await;
            match stepped {
                Ok((p, reached)) => {
                    program = p;
                    reached
                }
                Err(e) => {
                    tracing::error!(error = %e, broadcast = %self.broadcast.id, "a broadcast catch-up failed");
                    return false;
                }
            }
        } else {
            anim::ik::stoppable(&self.broadcast.stop, || program.step_to(k, &self.log));
            true
        };
        self.log.forget_before(program.floor());
        self.broadcast.journal_len.store(self.log.since(program.newest_checkpoint()), Ordering::Relaxed);
        self.program = Some(program);
        reached
    }

    /// Files `controls` and drops the `revoked` ones; returns the earliest
    /// stamp among them for a tick already stepped that the program can
    /// still go back to. One from before its floor is already in the state
    /// it started from: a stored checkpoint holds every control stored for
    /// its ticks, and the store refuses one for a tick a stored checkpoint
    /// has passed (`Journal::checkpoint`). It is skipped.
    fn file(&mut self, program: &Program, controls: Vec<StampedControl>, revoked: &[Arc<str>]) -> Option<u64> {
        let (next, floor) = (program.next(), program.floor());
        let mut rewind = None::<u64>;
        let mut past = |seq: u64| {
            if (floor..next).contains(&seq) {
                rewind = Some(rewind.map_or(seq, |r: u64| r.min(seq)));
            }
        };
        for c in controls {
            if c.seq < floor {
                tracing::debug!(broadcast = %self.broadcast.id, control = %c.id, "a control from before the oldest kept state skipped");
            }
            past(c.seq);
            self.log.insert(c);
        }
        for id in revoked {
            if let Some(seq) = self.log.remove(id) {
                past(seq);
            }
        }
        rewind
    }

    /// Hands the journal the newest checkpoint the program kept at least
    /// [`SETTLE`] plus the control lead ago, once: by then every control
    /// stamped before it has been heard.
    fn checkpoint(&mut self) {
        let Some(journal) = &self.broadcast.journal else { return };
        let program = self.program.as_ref().expect("the program is back after each catch-up");
        let fps = u128::from(self.broadcast.spec.params.fps);
        let margin = ((SETTLE + self.broadcast.lead).as_nanos() * fps / 1_000_000_000) as u64;
        let Some(tick) = program.settled_checkpoint(margin) else { return };
        if self.checkpointed.is_some_and(|done| done >= tick) {
            return;
        }
        let Some(checkpoint) = program.checkpoint_of(tick) else { return };
        self.checkpointed = Some(tick);
        metrics::counter!("inbetween_broadcast_checkpoints_total").increment(1);
        let controls = self.log.through(tick).map(|c| (c.id.to_string(), c.seq)).collect();
        drop(self.origin.spawn(journal.checkpoint(&self.broadcast.id, &checkpoint, program.floor(), controls)));
    }

    /// Whether the broadcast ends idle now. Without a journal: no viewers
    /// and no controls for the idle timeout. With one (many nodes may have
    /// viewers), it hears while this node has viewers, and decides the end
    /// across every node once this one has been idle that long.
    fn idle(&mut self, viewers: usize, last_control: Instant) -> Option<EndReason> {
        let b = &self.broadcast;
        let now = Instant::now();
        let idle = b.spec.idle_timeout;
        let every = (idle / 4).clamp(Duration::from_millis(250), Duration::from_secs(5));
        if viewers > 0 {
            self.last_watched = now;
            if let Some(journal) = &b.journal
                && now.saturating_duration_since(self.journaled) >= every
            {
                self.journaled = now;
                drop(self.origin.spawn(journal.touch(&b.id)));
            }
            return None;
        }
        if now.saturating_duration_since(self.last_watched.max(last_control)) < idle {
            return None;
        }
        let Some(journal) = &b.journal else {
            metrics::counter!("inbetween_broadcasts_idle_ended_total").increment(1);
            return Some(EndReason::Ended);
        };
        if now.saturating_duration_since(self.journaled) >= every {
            self.journaled = now;
            let (expire, registry, id) = (journal.expire(&b.id, idle), self.registry.clone(), Arc::clone(&b.id));
            drop(self.origin.spawn(async move {
                if expire.await {
                    metrics::counter!("inbetween_broadcasts_idle_ended_total").increment(1);
                    registry.delete(&id);
                }
            }));
        }
        None
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
