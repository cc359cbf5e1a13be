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
//! late) is slotted into the past by going back to the latest snapshot of
//! the state before its stamp (one every [`SNAPSHOT_EVERY`] ticks, the last
//! few kept; the player clones whole, warm starts included) and stepping
//! again up to now; older than every snapshot, from tick 0. A node's copy
//! of a broadcast created elsewhere, or resumed after a restart, steps from
//! tick 0 likewise ([`Program::replay`]): one sample per tick of its age.

use std::sync::Arc;

use super::control::{Applied, Control, Refused};
use super::encode::{Encoded, Encoding, FrameEncoder};
use super::hub::{TickStamp, frame_data, sample_tick};
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

/// Everything a tick's frame depends on, as of the last tick stepped.
#[derive(Clone)]
struct State {
    playhead: Playhead,
    player: StreamPlayer,
    /// The current motion's first-layer position at the previous tick (for
    /// the events crossed), and which motion that was.
    prev: Option<(f64, Arc<StreamMotion>)>,
    crossed: Vec<u32>,
    clip_time: f32,
    /// The last tick stepped.
    stepped: Option<u64>,
}

impl State {
    fn new(params: &StreamParams) -> Self {
        State {
            playhead: Playhead::new(params.start, params.speed, params.fps, params.paused),
            player: Player::new(Arc::clone(&params.motion)),
            prev: None,
            crossed: Vec::new(),
            clip_time: 0.0,
            stepped: None,
        }
    }

    fn next(&self) -> u64 {
        self.stepped.map_or(0, |k| k + 1)
    }
}

/// A broadcast's playback: its state, snapshots of it every
/// [`SNAPSHOT_EVERY`] ticks (so a control heard late replays from the
/// latest snapshot before its stamp, not from tick 0), and one encoder per
/// encoding (each reused, so a tick allocates only the bytes it sends —
/// and, every [`SNAPSHOT_EVERY`] ticks, a snapshot).
pub struct Program {
    params: StreamParams,
    state: State,
    /// Oldest first; each taken after stepping a multiple of `SNAPSHOT_EVERY` − 1.
    snapshots: std::collections::VecDeque<State>,
    json: FrameEncoder,
    protobuf: FrameEncoder,
}

impl Program {
    /// Before its tick 0.
    pub fn new(params: &StreamParams) -> Self {
        Program {
            state: State::new(params),
            params: params.clone(),
            snapshots: std::collections::VecDeque::new(),
            json: FrameEncoder::new(Encoding::Json),
            protobuf: FrameEncoder::new(Encoding::Protobuf),
        }
    }

    /// The next tick to step.
    pub fn next(&self) -> u64 {
        self.state.next()
    }

    /// Steps every tick from [`Self::next`] to `k` (nothing if `k` is behind).
    pub fn step_to(&mut self, k: u64, log: &ControlLog) {
        for j in self.next()..=k {
            self.step(j, log.at(j));
            if (j + 1) % SNAPSHOT_EVERY == 0 {
                if self.snapshots.len() == SNAPSHOTS {
                    self.snapshots.pop_front();
                }
                self.snapshots.push_back(self.state.clone());
            }
        }
    }

    /// Goes back to a state from before tick `k` (the latest snapshot
    /// before it, or the start), so that a control stamped `k` heard late
    /// is stepped in its place. Returns the ticks to step again.
    pub fn rewind_before(&mut self, k: u64) -> u64 {
        let now = self.next();
        while self.snapshots.back().is_some_and(|s| s.next() > k) {
            self.snapshots.pop_back();
        }
        self.state = match self.snapshots.back() {
            Some(s) => s.clone(),
            None => State::new(&self.params),
        };
        now - self.next()
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
            jumped |= self.apply(c.control.clone(), k);
        }
        let st = &mut self.state;
        let time = st.playhead.time_at(k);
        st.clip_time = sample_tick(&mut st.player, &self.params, time, jumped, &mut st.prev, &mut st.crossed);
        st.stepped = Some(k);
    }

    /// Applies a control stamped for tick `k`; returns whether time jumped.
    /// One the player refuses (a ramp of a layer a crossfade stamped just
    /// before took away) is skipped — the same way on every node.
    fn apply(&mut self, control: Control, k: u64) -> bool {
        let st = &mut self.state;
        match control.apply(&mut st.playhead, &mut st.player, k) {
            Ok(Applied::Jumped) => true,
            // A broadcast refuses `stop` (`Control::refused_on_broadcast`).
            Ok(Applied::Continued | Applied::Stopped) => false,
            Err(Refused { what, error }) => {
                tracing::warn!(%error, "a broadcast {what} skipped");
                false
            }
        }
    }

    /// The last stepped tick in `encoding`: `dropped` 0 and no joint names
    /// (each viewer's patch adds its own, see `encode`).
    pub fn encode(&mut self, encoding: Encoding, sent_at: i64) -> Encoded {
        let st = &self.state;
        let tick = TickStamp { seq: st.stepped.unwrap_or(0), dropped: 0, sent_at, clip_time: st.clip_time };
        let data = frame_data(&st.player, &self.params, &st.crossed, tick, false);
        match encoding {
            Encoding::Json => self.json.encode(&data),
            Encoding::Protobuf => self.protobuf.encode(&data),
        }
    }
}
