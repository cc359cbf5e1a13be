//! What a broadcast plays, as a pure function of its definition, its
//! stamped controls and the tick (docs/broadcasts.md "Many nodes").
//!
//! Every node of a cluster computes a broadcast's frames itself, so frame
//! `k` must come out bit for bit the same wherever it is computed. The
//! player's state is path-dependent (fade and ramp progress count `|Δs|`
//! tick by tick, sync-group phases advance, the root-motion total
//! accumulates, events are those crossed since the previous tick, and the
//! stream's IK chains are warm-started from the previous tick's angles). So
//! the rule is: **the state at tick `k` is the result of stepping every tick
//! `0..=k` in order**, applying before tick `j` the controls stamped `j` in
//! `(seq, id)` order and sampling once per tick, whether anyone watches or
//! not and whether the task woke on time or late (a late wake steps the
//! skipped ticks without encoding them). Nothing else goes in: no wall
//! clock, no viewer count. Given the same binary (the same floating-point
//! operations), two programs fed the same definition and controls produce
//! the same frames, warm starts included: the previous tick a chain starts
//! from is the same everywhere.
//!
//! A control that arrives for a tick already stepped (a node that heard it
//! late) is slotted into the past by going back to the latest state kept
//! from before its stamp — a snapshot (one every [`SNAPSHOT_EVERY`] ticks,
//! the last few kept; the player clones whole, warm starts included), a
//! checkpoint (one every checkpoint interval, the last [`CHECKPOINTS`]
//! kept), or the state the program started from — and stepping again up to
//! now. A node's copy of a broadcast created elsewhere, or resumed after a
//! restart, starts from the newest stored checkpoint (`checkpoint`,
//! [`Program::from_checkpoint`]) and steps from there: its work is bounded
//! by the checkpoint interval, not by the broadcast's age.

use std::collections::VecDeque;
use std::sync::Arc;

use super::broadcast_reach::Reach;
use super::checkpoint::{Checkpoint, CheckpointError, Lookup, Naming, Source};
use super::compact::CompactLayout;
use super::control::{Applied, Control, Refused};
use super::encode::{Encoded, Encoding, FrameEncoder};
use super::graph::GraphDeck;
use super::hub::{Playing, TickStamp, frame_data, sample_tick};
use super::params::StreamParams;
use super::pinned::StreamMotion;
use super::pinned::StreamPlayer;
use super::playhead::Playhead;
use anim::motion::Player;

/// A control with its stamp and its id (what orders the controls of one
/// tick the same way on every node, and tells one heard twice).
#[derive(Debug, Clone)]
pub struct StampedControl {
    /// The broadcast tick it applies from.
    pub seq: u64,
    /// Unique per control (a UUIDv7); controls of one `seq` apply in id order.
    pub id: Arc<str>,
    pub control: Control,
}

impl StampedControl {
    fn key(&self) -> (u64, &str) {
        (self.seq, &self.id)
    }
}

/// A broadcast's controls, kept in application order.
#[derive(Debug, Default, Clone)]
pub struct ControlLog {
    controls: Vec<StampedControl>,
}

impl ControlLog {
    /// Adds `c` in its place; returns whether it was new.
    pub fn insert(&mut self, c: StampedControl) -> bool {
        match self.controls.binary_search_by(|x| x.key().cmp(&c.key())) {
            Ok(_) => false,
            Err(at) => {
                self.controls.insert(at, c);
                true
            }
        }
    }

    /// Removes control `id`; returns its stamp if it was there.
    pub fn remove(&mut self, id: &str) -> Option<u64> {
        let at = self.controls.iter().position(|c| &*c.id == id)?;
        Some(self.controls.remove(at).seq)
    }

    /// The controls stamped `k`, in order.
    pub fn at(&self, k: u64) -> &[StampedControl] {
        let from = self.controls.partition_point(|c| c.seq < k);
        let to = self.controls.partition_point(|c| c.seq <= k);
        &self.controls[from..to]
    }

    /// Control `id`.
    pub fn find(&self, id: &str) -> Option<&StampedControl> {
        self.controls.iter().find(|c| &*c.id == id)
    }

    /// Forgets the controls stamped before `seq` (a program no longer
    /// steps them: it never goes back before `seq`).
    pub fn forget_before(&mut self, seq: u64) {
        let before = self.controls.partition_point(|c| c.seq < seq);
        self.controls.drain(..before);
    }

    /// The controls stamped at or before `seq`, in order.
    pub fn through(&self, seq: u64) -> impl Iterator<Item = &StampedControl> {
        self.controls.iter().take_while(move |c| c.seq <= seq)
    }

    /// How many are stamped at or after `seq`.
    pub fn since(&self, seq: u64) -> usize {
        self.controls.len() - self.controls.partition_point(|c| c.seq < seq)
    }

    pub fn len(&self) -> usize {
        self.controls.len()
    }

    pub fn is_empty(&self) -> bool {
        self.controls.is_empty()
    }
}

/// Ticks between snapshots of a program's state.
pub const SNAPSHOT_EVERY: u64 = 64;

/// Snapshots kept (the latest `SNAPSHOTS · SNAPSHOT_EVERY` ticks).
const SNAPSHOTS: usize = 8;

/// Checkpoint states kept in memory: the one being written, the newest
/// stored, and the one before it (a control heard late goes back to it).
pub const CHECKPOINTS: usize = 3;

/// Everything a tick's frame depends on, as of the last tick stepped.
#[derive(Clone)]
struct State {
    playhead: Playhead,
    player: StreamPlayer,
    /// A graph broadcast's graph, played in place of `player`'s motion.
    graph: Option<GraphDeck>,
    /// The current motion's first-layer position at the previous tick (for
    /// the events crossed), and which motion that was.
    prev: Option<(f64, Arc<StreamMotion>)>,
    crossed: Vec<u32>,
    clip_time: f32,
    /// The last tick stepped.
    stepped: Option<u64>,
    /// The latest crossfades applied, with their controls' ids, oldest
    /// first: how a checkpoint names the motions on the player (it holds
    /// at most this many).
    fades: VecDeque<(Arc<StreamMotion>, Arc<str>)>,
    /// The `ik` control whose list the player has (`None`: the definition's).
    ik_from: Option<Arc<str>>,
    /// What it has played since tick 0, which its compact layouts hold.
    reach: Reach,
}

impl State {
    fn new(params: &StreamParams) -> Self {
        State {
            playhead: Playhead::new(params.start, params.speed, params.fps, params.paused),
            player: Player::new(Arc::clone(&params.motion)),
            graph: params.graph.as_ref().map(|g| GraphDeck::new(g, params.space)),
            prev: None,
            crossed: Vec::new(),
            clip_time: 0.0,
            stepped: None,
            fades: VecDeque::new(),
            ik_from: None,
            reach: Reach::new(params),
        }
    }

    /// Where a motion on the player came from.
    fn source_of(&self, motion: &Arc<StreamMotion>) -> Source {
        match self.fades.iter().rev().find(|(m, _)| Arc::ptr_eq(m, motion)) {
            Some((_, id)) => Source::Control(id.to_string()),
            None => Source::Definition,
        }
    }

    fn checkpoint(&self) -> Option<Checkpoint> {
        let tick = self.stepped?;
        let ik = self.ik_from.as_ref().map_or(Source::Definition, |id| Source::Control(id.to_string()));
        let naming = Naming { motion: &|m| self.source_of(m), ik };
        let prev = self.prev.as_ref().map(|(x, _)| *x);
        let playing = Playing { player: &self.player, graph: self.graph.as_ref() };
        let checkpoint = Checkpoint::capture(tick, &self.playhead, playing, prev, self.clip_time, &naming);
        Some(checkpoint.with_reach(self.reach.bits()))
    }

    /// The state `checkpoint` describes, its motions and IK list found in
    /// `params` and `log`.
    fn restore(params: &StreamParams, checkpoint: &Checkpoint, log: &ControlLog) -> Result<Self, CheckpointError> {
        let motion = |source: &Source| match source {
            Source::Definition => Some(Arc::clone(&params.motion)),
            Source::Control(id) => match &log.find(id)?.control {
                Control::Crossfade(fade) => Some(Arc::clone(&fade.to)),
                _ => None,
            },
        };
        let ik = |source: &Source| match source {
            Source::Definition => Some(params.motion.ik().to_vec()),
            Source::Control(id) => match &log.find(id)?.control {
                Control::SetIk(list) => Some(list.clone()),
                _ => None,
            },
        };
        let restored = checkpoint.restore(params, &Lookup { motion: &motion, ik: &ik })?;
        let named = checkpoint.controls();
        let fades = named
            .iter()
            .filter_map(|id| {
                let c = log.find(id)?;
                let Control::Crossfade(fade) = &c.control else { return None };
                Some(((c.seq, Arc::clone(&c.id)), (Arc::clone(&fade.to), Arc::clone(&c.id))))
            })
            .collect::<std::collections::BTreeMap<_, _>>()
            .into_values()
            .collect();
        let ik_from = named.iter().filter_map(|id| log.find(id)).find(|c| matches!(c.control, Control::SetIk(_)));
        let fade_of = |id: &str| match &log.find(id)?.control {
            Control::Crossfade(fade) => Some(fade.clone()),
            _ => None,
        };
        let reach = Reach::from_bits(params, checkpoint.reach(), &fade_of)
            .ok_or_else(|| CheckpointError::MissingControl("a motion the broadcast played".into()))?;
        let top = Arc::clone(restored.player.motion());
        Ok(State {
            playhead: restored.playhead,
            player: restored.player,
            graph: restored.graph,
            prev: restored.prev.map(|x| (x, top)),
            crossed: Vec::new(),
            clip_time: restored.clip_time,
            stepped: Some(checkpoint.tick),
            fades,
            ik_from: ik_from.map(|c| Arc::clone(&c.id)),
            reach,
        })
    }

    fn next(&self) -> u64 {
        self.stepped.map_or(0, |k| k + 1)
    }
}

/// A broadcast's playback: its state, snapshots of it every
/// [`SNAPSHOT_EVERY`] ticks and checkpoints every checkpoint interval (so a
/// control heard late replays from the latest state kept before its stamp),
/// and one encoder per encoding (each reused, so a tick allocates only the
/// bytes it sends — and, every [`SNAPSHOT_EVERY`] ticks, a snapshot).
pub struct Program {
    params: StreamParams,
    state: State,
    /// Oldest first; each taken after stepping a multiple of `SNAPSHOT_EVERY` − 1.
    snapshots: VecDeque<State>,
    /// Ticks between checkpoints (0: none).
    checkpoint_every: u64,
    /// Oldest first; each taken after stepping a multiple of `checkpoint_every` − 1.
    checkpoints: VecDeque<State>,
    /// The oldest state the program can go back to: its start, then the
    /// oldest checkpoint kept once older ones are let go.
    floor: State,
    json: FrameEncoder,
    protobuf: FrameEncoder,
    /// Compact frames' encoders, one per `max_error` and `distance` its
    /// viewers asked for, with the document of the layout each encodes in.
    compact: Vec<((u32, u32), Arc<str>, FrameEncoder)>,
}

impl Program {
    /// Before its tick 0.
    pub fn new(params: &StreamParams) -> Self {
        Self::starting_at(params, State::new(params))
    }

    fn starting_at(params: &StreamParams, state: State) -> Self {
        Program {
            floor: state.clone(),
            state,
            params: params.clone(),
            snapshots: VecDeque::new(),
            checkpoint_every: 0,
            checkpoints: VecDeque::new(),
            json: FrameEncoder::new(Encoding::Json),
            protobuf: FrameEncoder::new(Encoding::Protobuf),
            compact: Vec::new(),
        }
    }

    /// The program `checkpoint` describes: its next tick is the one after
    /// the checkpoint's, and it never goes back before it. The controls it
    /// names must be in `log`.
    ///
    /// # Errors
    /// The checkpoint is unreadable, names a control `log` lacks, or does
    /// not fit the motions.
    pub fn from_checkpoint(
        params: &StreamParams,
        checkpoint: &Checkpoint,
        log: &ControlLog,
    ) -> Result<Self, CheckpointError> {
        Ok(Self::starting_at(params, State::restore(params, checkpoint, log)?))
    }

    /// Keeps a checkpoint state after every tick `c` with `(c + 1) % every == 0`.
    #[must_use]
    pub fn checkpointing(mut self, every: u64) -> Self {
        self.checkpoint_every = every;
        self
    }

    /// What it has played through the last tick stepped (its compact
    /// layouts hold it: `broadcast_reach`).
    pub fn reach(&self) -> &Reach {
        &self.state.reach
    }

    /// Whether it is paused, and its speed, as of the last tick stepped.
    pub fn playing(&self) -> (bool, f64) {
        (self.state.playhead.paused(), self.state.playhead.speed())
    }

    /// The next tick to step.
    pub fn next(&self) -> u64 {
        self.state.next()
    }

    /// The first tick the program can step again (see [`Self::rewind_before`]):
    /// controls stamped before it are no longer needed.
    pub fn floor(&self) -> u64 {
        self.floor.next()
    }

    /// Steps every tick from [`Self::next`] to `k` (nothing if `k` is behind).
    pub fn step_to(&mut self, k: u64, log: &ControlLog) {
        self.step_to_unless(k, log, &|| false);
    }

    /// As [`Self::step_to`], asking `cancelled` between ticks; returns
    /// whether it reached `k`.
    pub fn step_to_unless(&mut self, k: u64, log: &ControlLog, cancelled: &dyn Fn() -> bool) -> bool {
        for j in self.next()..=k {
            if j.is_multiple_of(64) && cancelled() {
                return false;
            }
            self.step(j, log.at(j));
            self.keep(j);
        }
        true
    }

    /// Keeps the snapshot or checkpoint state due after tick `j`.
    fn keep(&mut self, j: u64) {
        if (j + 1).is_multiple_of(SNAPSHOT_EVERY) {
            if self.snapshots.len() == SNAPSHOTS {
                self.snapshots.pop_front();
            }
            self.snapshots.push_back(self.state.clone());
        }
        if self.checkpoint_every > 0 && (j + 1).is_multiple_of(self.checkpoint_every) {
            if self.checkpoints.len() == CHECKPOINTS
                && let Some(oldest) = self.checkpoints.pop_front()
            {
                self.floor = oldest;
            }
            self.checkpoints.push_back(self.state.clone());
        }
    }

    /// The checkpoint of tick `c`, if the program kept that state.
    pub fn checkpoint_of(&self, c: u64) -> Option<Checkpoint> {
        let kept = self.checkpoints.iter().chain([&self.floor, &self.state]);
        kept.filter(|s| s.stepped == Some(c)).find_map(State::checkpoint)
    }

    /// The first tick after the newest checkpoint state kept (or the floor).
    pub fn newest_checkpoint(&self) -> u64 {
        self.checkpoints.back().unwrap_or(&self.floor).next()
    }

    /// The tick of the newest checkpoint kept at least `margin` ticks
    /// before the last tick stepped: the one to store (see `broadcast`).
    pub fn settled_checkpoint(&self, margin: u64) -> Option<u64> {
        let now = self.state.stepped?;
        let kept = self.checkpoints.iter().rev().chain([&self.floor]);
        kept.filter_map(|s| s.stepped).find(|&c| c + margin <= now)
    }

    /// The checkpoint of the last tick stepped.
    pub fn checkpoint(&self) -> Option<Checkpoint> {
        self.state.checkpoint()
    }

    /// Goes back to a state from before tick `k` (the latest snapshot or
    /// checkpoint before it, or the floor), so that a control stamped `k`
    /// heard late is stepped in its place. Returns the ticks to step again;
    /// `None` if `k` is before the floor (the program cannot go back there:
    /// nothing changes).
    pub fn rewind_before(&mut self, k: u64) -> Option<u64> {
        if k < self.floor.next() {
            return None;
        }
        let now = self.next();
        while self.snapshots.back().is_some_and(|s| s.next() > k) {
            self.snapshots.pop_back();
        }
        while self.checkpoints.back().is_some_and(|s| s.next() > k) {
            self.checkpoints.pop_back();
        }
        let latest = [self.snapshots.back(), self.checkpoints.back()].into_iter().flatten().max_by_key(|s| s.next());
        self.state = latest.unwrap_or(&self.floor).clone();
        Some(now - self.next())
    }

    /// A fresh program of `params` stepped through tick `k` (none if `k` is
    /// `None`): what a node computes when it starts late or hears a control
    /// for a tick it has already stepped.
    pub fn replay(params: &StreamParams, log: &ControlLog, k: Option<u64>) -> Self {
        let mut program = Program::new(params);
        if let Some(k) = k {
            program.step_to(k, log);
        }
        program
    }

    /// Applies the controls stamped `k`, then samples tick `k`.
    fn step(&mut self, k: u64, controls: &[StampedControl]) {
        let mut jumped = false;
        for c in controls {
            jumped |= self.apply(c, k);
        }
        let st = &mut self.state;
        st.clip_time = match &mut st.graph {
            Some(graph) => graph.tick(self.params.fps, st.playhead.paused(), (k, 0)),
            None => {
                let time = (st.playhead.time_at(k), super::hub::stream_clock(&self.params, k));
                sample_tick(&mut st.player, &self.params, time, jumped, &mut st.prev, &mut st.crossed)
            }
        };
        st.stepped = Some(k);
    }

    /// Applies a control stamped for tick `k`; returns whether time jumped.
    /// One the player refuses (a ramp of a layer a crossfade stamped just
    /// before took away) is skipped — the same way on every node.
    fn apply(&mut self, c: &StampedControl, k: u64) -> bool {
        let st = &mut self.state;
        let control = c.control.clone();
        let named = match &control {
            Control::Crossfade(fade) => Some(Some(Arc::clone(&fade.to))),
            Control::SetIk(_) => Some(None),
            _ => None,
        };
        match control.apply(&mut st.playhead, &mut st.player, st.graph.as_mut(), k) {
            Ok(Applied::Jumped) => true,
            // A broadcast refuses `stop` (`Control::refused_on_broadcast`).
            Ok(Applied::Continued | Applied::Stopped) => {
                st.reach.apply(&c.control, &c.id, self.params.motion.skeleton());
                match named {
                    Some(Some(to)) => anim::motion::push_crossfade(&mut st.fades, (to, Arc::clone(&c.id))),
                    Some(None) => st.ik_from = Some(Arc::clone(&c.id)),
                    None => {}
                }
                false
            }
            Err(Refused { what, error }) => {
                tracing::warn!(%error, "a broadcast {what} skipped");
                false
            }
        }
    }

    /// The last stepped tick in `encoding`, JSON or protobuf (compact
    /// frames: [`Program::encode_compact`]): `dropped` 0 and no joint names
    /// (each viewer's patch adds its own, see `encode`).
    pub fn encode(&mut self, encoding: Encoding, sent_at: i64) -> Encoded {
        let st = &self.state;
        let tick = TickStamp { seq: st.stepped.unwrap_or(0), dropped: 0, sent_at, clip_time: st.clip_time };
        let playing = Playing { player: &st.player, graph: st.graph.as_ref() };
        let data = frame_data(playing, &self.params, &st.crossed, tick, false);
        match encoding {
            Encoding::Json => self.json.encode(&data),
            Encoding::Protobuf | Encoding::Compact => self.protobuf.encode(&data),
        }
    }

    /// The last stepped tick as a compact frame of `layout` (a key frame
    /// when this layout's encoder is new, its key interval is up, or the
    /// layout of its `max_error` and `distance` changed: a new layout,
    /// docs/compact-frames.md).
    pub fn encode_compact(&mut self, layout: &CompactLayout, sent_at: i64) -> Encoded {
        let key = layout.key();
        let at = match self.compact.iter().position(|(k, _, _)| *k == key) {
            Some(at) => at,
            None => {
                self.compact.push((key, Arc::clone(&layout.document), FrameEncoder::compact(layout)));
                self.compact.len() - 1
            }
        };
        let (_, document, encoder) = &mut self.compact[at];
        if !Arc::ptr_eq(document, &layout.document) {
            encoder.relayout(layout);
            *document = Arc::clone(&layout.document);
        }
        let st = &self.state;
        let tick = TickStamp { seq: st.stepped.unwrap_or(0), dropped: 0, sent_at, clip_time: st.clip_time };
        let playing = Playing { player: &st.player, graph: st.graph.as_ref() };
        let data = frame_data(playing, &self.params, &st.crossed, tick, false);
        self.compact[at].2.encode(&data)
    }

    /// Drops the compact encoders of layouts nobody watches any more.
    pub fn keep_compact(&mut self, watched: impl Fn((u32, u32)) -> bool) {
        self.compact.retain(|(k, _, _)| watched(*k));
    }
}
