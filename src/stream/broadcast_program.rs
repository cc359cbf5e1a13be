//! What a broadcast plays, as a pure function of its definition, its
//! stamped controls and the tick (SPEC §9 "Many nodes").
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
//! late) cannot be slotted into the past, so the program is rebuilt from the
//! definition and every control and stepped again up to now
//! ([`Program::replay`]); so is a node's copy of a broadcast created
//! elsewhere, or resumed after a restart. Replaying costs one sample per
//! tick of the broadcast's age.

use std::sync::Arc;

use super::encode::{Encoded, Encoding, FrameEncoder};
use super::hub::{StreamPlayer, TickStamp, frame_data, sample_tick};
use super::params::StreamParams;
use super::pinned::StreamMotion;
use super::playhead::{Control, Crossfade, Playhead};
use crate::anim::motion::Player;

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

/// A broadcast's playback: its playhead and player, and one encoder per
/// encoding (each reused, so a tick allocates only the bytes it sends).
pub struct Program {
    params: StreamParams,
    playhead: Playhead,
    player: StreamPlayer,
    /// The current motion's first-layer position at the previous tick (for
    /// the events crossed), and which motion that was.
    prev: Option<(f64, Arc<StreamMotion>)>,
    crossed: Vec<u32>,
    clip_time: f32,
    /// The last tick stepped.
    stepped: Option<u64>,
    json: FrameEncoder,
    protobuf: FrameEncoder,
}

impl Program {
    /// Before its tick 0.
    pub fn new(params: &StreamParams) -> Self {
        Program {
            playhead: Playhead::new(params.start, params.speed, params.fps, params.paused),
            player: Player::new(Arc::clone(&params.motion)),
            params: params.clone(),
            prev: None,
            crossed: Vec::new(),
            clip_time: 0.0,
            stepped: None,
            json: FrameEncoder::new(Encoding::Json),
            protobuf: FrameEncoder::new(Encoding::Protobuf),
        }
    }

    /// The next tick to step.
    pub fn next(&self) -> u64 {
        self.stepped.map_or(0, |k| k + 1)
    }

    /// Steps every tick from [`Self::next`] to `k` (nothing if `k` is behind).
    pub fn step_to(&mut self, k: u64, log: &ControlLog) {
        for j in self.next()..=k {
            self.step(j, log.at(j));
        }
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
        let time = self.playhead.time_at(k);
        self.clip_time = sample_tick(&mut self.player, &self.params, time, jumped, &mut self.prev, &mut self.crossed);
        self.stepped = Some(k);
    }

    /// Applies a control stamped for tick `k`; returns whether time jumped.
    /// One the player refuses (a ramp of a layer a crossfade stamped just
    /// before took away) is skipped — the same way on every node.
    fn apply(&mut self, control: Control, k: u64) -> bool {
        match control {
            Control::Crossfade(Crossfade { to, duration, ease }) => {
                if let Err(e) = self.player.crossfade(to, duration, ease) {
                    tracing::warn!(error = %e, "a broadcast crossfade skipped");
                }
                false
            }
            Control::Layer { index, weight, duration } => {
                if let Err(e) = self.player.ramp(index, weight, duration) {
                    tracing::warn!(error = %e, "a broadcast weight ramp skipped");
                }
                false
            }
            Control::SetIk(constraints) => {
                self.player.set_ik(constraints);
                false
            }
            Control::Seek(tau) => {
                self.player.seek(tau);
                true
            }
            Control::Ik(_) | Control::Stop => false,
            c => self.playhead.apply(c, k),
        }
    }

    /// The last stepped tick in `encoding`: `dropped` 0 and no joint names
    /// (each viewer's patch adds its own, see `encode`).
    pub fn encode(&mut self, encoding: Encoding, sent_at: i64) -> Encoded {
        let tick = TickStamp { seq: self.stepped.unwrap_or(0), dropped: 0, sent_at, clip_time: self.clip_time };
        let data = frame_data(&self.player, &self.params, &self.crossed, tick, false);
        match encoding {
            Encoding::Json => self.json.encode(&data),
            Encoding::Protobuf => self.protobuf.encode(&data),
        }
    }
}
