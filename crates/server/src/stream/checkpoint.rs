//! Broadcast checkpoints (docs/broadcasts.md "Checkpoints"): a broadcast
//! program's state after one tick, written down exactly, so that a node
//! that starts late, restarts or hears a control for a tick long past steps
//! on from it instead of from tick 0.
//!
//! Exact means: a program restored from the checkpoint of tick `c` makes
//! frames `c + 1, …` bit for bit as the program it was taken from. Every
//! number is kept as its bits (an `f64` printed in decimal and parsed back
//! need not be the same `f64`), and what is not a number — the motions on
//! the player, its IK list — is named by where it came from: the
//! broadcast's definition, or the control (by id) that put it there. The
//! store keeps those controls as long as a checkpoint names them, so a node
//! builds them again as it builds every control.
//!
//! The text is a pure function of the state (fields in a fixed order, no
//! maps), so two nodes that checkpoint the same tick write the same text
//! and either's write may win. Springs, when the motion has them, add
//! their state (bits as well) to the player's; a graph broadcast adds its
//! graph player's (parameter values, ticks, current state, and each state
//! playing with its node time, phases and transition), which a restore
//! checks against the graph.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::broadcast_reach::ReachBits;
use super::graph::GraphDeck;
use super::hub::Playing;
use super::params::StreamParams;
use super::pinned::{StreamMotion, StreamPlayer};
use super::playhead::Playhead;
use anim::Ease;
use anim::graph::{FadeProgress, GraphState, SlotState};
use anim::ik::{IkConstraint, WarmStart};
use anim::motion::root::RootAt;
use anim::motion::{DeckState, FadeState, Planar, Player, PlayerState, RampState, RootMotion, UpAxis};
use anim::spring::SpringState;

/// The checkpoint format; a checkpoint of another is not used (the
/// broadcast replays from an older one or from its start).
const FORMAT: u32 = 1;

/// Where a motion or the IK list on a broadcast's player came from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Source {
    /// The broadcast's definition (its motion, and that motion's IK).
    Definition,
    /// The control with this id (a crossfade's target, an `ik` list).
    Control(String),
}

/// Why a checkpoint could not be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CheckpointError {
    #[error("the checkpoint is not readable: {0}")]
    Unreadable(String),
    #[error("the checkpoint names control {0}, which this node does not have")]
    MissingControl(String),
    #[error("the checkpoint does not fit the broadcast's motion: {0}")]
    Mismatch(String),
}

/// A broadcast program's state after tick [`Checkpoint::tick`]; see the module doc.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checkpoint {
    format: u32,
    /// The last tick stepped.
    pub tick: u64,
    /// The playhead: anchor tick, anchor time, speed (bits), paused.
    playhead: (u64, u64, u64, bool),
    /// The current motion's first-layer position at this tick (bits), for
    /// the events the next tick crosses.
    prev: Option<u64>,
    clip_time: u32,
    player: PlayerBits,
    /// A graph broadcast's graph player.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    graph: Option<GraphBits>,
    /// The springs of a graph broadcast's motion, when it has them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    graph_springs: Option<SpringBits>,
    /// What it has played since tick 0, which its compact layouts hold
    /// (`broadcast_reach`; absent: nothing beyond its definition).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    reach: Option<ReachBits>,
}

/// What a [`Checkpoint`] restores.
pub(super) struct Restored {
    pub playhead: Playhead,
    pub player: StreamPlayer,
    pub graph: Option<GraphDeck>,
    pub prev: Option<f64>,
    pub clip_time: f32,
}

/// A graph player's state (`anim::graph::GraphState`), numbers as bits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct GraphBits {
    values: Vec<u64>,
    ticks: u64,
    current: usize,
    /// Bottom to top.
    chain: Vec<SlotBits>,
    /// The last tick's root motion (absent from checkpoints of graphs without it).
    #[serde(default)]
    root: Option<RootBits>,
}

/// A state playing: the state, its node time, its phases, and (above the
/// bottom) the transition that put it there, the state it came from and its
/// elapsed time.
type SlotBits = (usize, u64, Vec<u64>, Option<(usize, usize, u64)>);

fn graph_bits(g: GraphState) -> GraphBits {
    GraphBits {
        values: g.values.into_iter().map(f64::to_bits).collect(),
        ticks: g.ticks,
        current: g.current,
        chain: g
            .chain
            .into_iter()
            .map(|s| {
                let fade = s.fade.map(|f| (f.transition, f.from, f.elapsed.to_bits()));
                (s.state, s.tau.to_bits(), s.phases.into_iter().map(f64::to_bits).collect(), fade)
            })
            .collect(),
        root: g.root.map(root_bits),
    }
}

fn graph_state(b: &GraphBits) -> GraphState {
    GraphState {
        values: b.values.iter().copied().map(f64::from_bits).collect(),
        ticks: b.ticks,
        current: b.current,
        chain: b
            .chain
            .iter()
            .map(|(state, tau, phases, fade)| SlotState {
                state: *state,
                tau: f64::from_bits(*tau),
                phases: phases.iter().copied().map(f64::from_bits).collect(),
                fade: fade.map(|(transition, from, elapsed)| FadeProgress {
                    transition,
                    from,
                    elapsed: f64::from_bits(elapsed),
                }),
            })
            .collect(),
        root: b.root.map(root),
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlayerBits {
    top: DeckBits,
    fade: Option<Box<FadeBits>>,
    seek: Option<u64>,
    last_s: Option<u64>,
    alpha: u32,
    root: Option<RootBits>,
    up_z: bool,
    /// `None`: no IK list.
    ik: Option<Source>,
    /// Per constraint: joints and angle bits.
    warm: Vec<(Vec<usize>, Vec<u32>)>,
    /// The current motion's spring simulation, when it has springs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    springs: Option<SpringBits>,
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    springs_jumped: bool,
}

/// A spring simulation (docs/springs.md, “Determinism and its limits”):
/// the next substep, per turning joint its tail now and one substep
/// before and its rotation, and the last frame's clock and motion time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SpringBits {
    next: Option<i64>,
    current: Vec<[u32; 3]>,
    previous: Vec<[u32; 3]>,
    rotations: Vec<[u32; 4]>,
    frame: Option<(u64, u64)>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FadeBits {
    under: PlayerBits,
    elapsed: u64,
    duration: u64,
    ease: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct DeckBits {
    motion: Source,
    origin: Option<u64>,
    phases: Vec<u64>,
    weights: Vec<u32>,
    /// from, to (f32 bits), elapsed, duration (f64 bits).
    ramps: Vec<Option<(u32, u32, u64, u64)>>,
    fresh: bool,
    roots: Vec<Option<RootAtBits>>,
    root_motion: Option<RootBits>,
}

/// A planar transform: translation x, y, z and yaw, as bits.
type PlanarBits = [u64; 4];

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RootBits {
    delta: PlanarBits,
    total: PlanarBits,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RootAtBits {
    cycle: i64,
    time: u32,
    m: PlanarBits,
}

/// How a checkpoint names the player's motions and IK list.
pub(super) struct Naming<'a> {
    /// A motion on the player → where it came from.
    pub motion: &'a dyn Fn(&Arc<StreamMotion>) -> Source,
    /// Where the top player's IK list came from.
    pub ik: Source,
}

/// How a restore finds what a checkpoint names.
pub(super) struct Lookup<'a> {
    pub motion: &'a dyn Fn(&Source) -> Option<Arc<StreamMotion>>,
    pub ik: &'a dyn Fn(&Source) -> Option<Vec<IkConstraint>>,
}

impl Checkpoint {
    /// The state after tick `tick`.
    pub(super) fn capture(
        tick: u64,
        playhead: &Playhead,
        playing: Playing<'_>,
        prev: Option<f64>,
        clip_time: f32,
        naming: &Naming<'_>,
    ) -> Self {
        let (anchor_k, anchor_t, speed, paused) = playhead.parts();
        Checkpoint {
            format: FORMAT,
            tick,
            playhead: (anchor_k, anchor_t.to_bits(), speed.to_bits(), paused),
            prev: prev.map(f64::to_bits),
            clip_time: clip_time.to_bits(),
            player: player_bits(playing.player.state(), naming, true),
            graph: playing.graph.map(|g| graph_bits(g.state().0)),
            graph_springs: playing.graph.and_then(|g| g.state().1).map(|s| spring_bits((s, None))),
            reach: None,
        }
    }

    /// The same checkpoint carrying what the broadcast played (`reach`).
    pub(super) fn with_reach(self, reach: Option<ReachBits>) -> Self {
        Checkpoint { reach, ..self }
    }

    /// What the broadcast had played through its tick.
    pub(super) fn reach(&self) -> Option<&ReachBits> {
        self.reach.as_ref()
    }

    /// A program state again, its motions and IK list found by `lookup`.
    ///
    /// # Errors
    /// Another format, a control it names missing, a state that does not
    /// fit the motions.
    pub(super) fn restore(&self, params: &StreamParams, lookup: &Lookup<'_>) -> Result<Restored, CheckpointError> {
        if self.format != FORMAT {
            return Err(CheckpointError::Unreadable(format!("format {} (this server reads {FORMAT})", self.format)));
        }
        let (anchor_k, anchor_t, speed, paused) = self.playhead;
        let state = player_state(&self.player, lookup)?;
        let player = Player::from_state(state).map_err(|e| CheckpointError::Mismatch(e.to_string()))?;
        let graph = match (&params.graph, &self.graph) {
            (None, None) => None,
            (Some(program), Some(bits)) => Some(
                GraphDeck::from_state(
                    program,
                    params.space,
                    (graph_state(bits), self.graph_springs.as_ref().map(|b| spring_state(b).0)),
                    (super::hub::stream_clock(params, self.tick), params.fps),
                )
                .map_err(|e| CheckpointError::Mismatch(e.to_string()))?,
            ),
            _ => return Err(CheckpointError::Mismatch("a graph's state for a motion, or none for a graph".into())),
        };
        let fps = params.fps;
        Ok(Restored {
            playhead: Playhead::from_parts(fps, (anchor_k, f64::from_bits(anchor_t), f64::from_bits(speed), paused)),
            player,
            graph,
            prev: self.prev.map(f64::from_bits),
            clip_time: f32::from_bits(self.clip_time),
        })
    }

    /// The controls it names (the store keeps them while it is the newest):
    /// the motions and IK list on the player, and every motion the
    /// broadcast has played (`broadcast_reach`, at most `MAX_PLAYED`).
    pub fn controls(&self) -> Vec<String> {
        let mut ids = Vec::new();
        named(&self.player, &mut ids);
        ids.extend(self.reach.iter().flat_map(|r| r.motions.iter().cloned()));
        ids.sort();
        ids.dedup();
        ids
    }

    /// The stored text: the same for the same state on every node.
    pub fn to_text(&self) -> String {
        serde_json::to_string(self).expect("a checkpoint is JSON")
    }

    /// # Errors
    /// Not a checkpoint's text.
    pub fn from_text(text: &str) -> Result<Self, CheckpointError> {
        serde_json::from_str(text).map_err(|e| CheckpointError::Unreadable(e.to_string()))
    }
}

fn named(p: &PlayerBits, ids: &mut Vec<String>) {
    for source in [Some(&p.top.motion), p.ik.as_ref()].into_iter().flatten() {
        if let Source::Control(id) = source {
            ids.push(id.clone());
        }
    }
    if let Some(fade) = &p.fade {
        named(&fade.under, ids);
    }
}

fn planar_bits(p: Planar) -> PlanarBits {
    [p.translation.x.to_bits(), p.translation.y.to_bits(), p.translation.z.to_bits(), p.yaw.to_bits()]
}

fn planar(b: PlanarBits) -> Planar {
    let [x, y, z, yaw] = b.map(f64::from_bits);
    Planar { translation: glam::DVec3::new(x, y, z), yaw }
}

fn root_bits(r: RootMotion) -> RootBits {
    RootBits { delta: planar_bits(r.delta), total: planar_bits(r.total) }
}

fn root(r: RootBits) -> RootMotion {
    RootMotion { delta: planar(r.delta), total: planar(r.total) }
}

/// `top`: the outermost player (the only one with an IK list).
fn player_bits(
    s: PlayerState<std::sync::Arc<dyn super::pinned::PinnedClip>>,
    naming: &Naming<'_>,
    top: bool,
) -> PlayerBits {
    PlayerBits {
        top: deck_bits(s.top, naming),
        fade: s.fade.map(|f| {
            let FadeState { under, elapsed, duration, ease } = *f;
            Box::new(FadeBits {
                under: player_bits(under, naming, false),
                elapsed: elapsed.to_bits(),
                duration: duration.to_bits(),
                ease: ease.as_str().to_owned(),
            })
        }),
        seek: s.seek.map(f64::to_bits),
        last_s: s.last_s.map(f64::to_bits),
        alpha: s.alpha.to_bits(),
        root: s.root.map(root_bits),
        up_z: s.up == UpAxis::Z,
        ik: (top && !s.ik.is_empty()).then(|| naming.ik.clone()),
        warm: s.warm.into_iter().map(|w| (w.joints, w.angles.into_iter().map(f32::to_bits).collect())).collect(),
        springs: s.springs.map(spring_bits),
        springs_jumped: s.springs_jumped,
    }
}

fn spring_bits((state, frame): (SpringState, Option<(f64, f64)>)) -> SpringBits {
    let point = |v: &glam::Vec3A| v.to_array().map(f32::to_bits);
    SpringBits {
        next: state.next,
        current: state.current.iter().map(point).collect(),
        previous: state.previous.iter().map(point).collect(),
        rotations: state.rotations.iter().map(|q| q.to_array().map(f32::to_bits)).collect(),
        frame: frame.map(|(clock, tau)| (clock.to_bits(), tau.to_bits())),
    }
}

fn spring_state(b: &SpringBits) -> (SpringState, Option<(f64, f64)>) {
    let point = |v: &[u32; 3]| glam::Vec3A::from_array(v.map(f32::from_bits));
    let state = SpringState {
        next: b.next,
        current: b.current.iter().map(point).collect(),
        previous: b.previous.iter().map(point).collect(),
        rotations: b.rotations.iter().map(|q| glam::Quat::from_array(q.map(f32::from_bits))).collect(),
    };
    (state, b.frame.map(|(clock, tau)| (f64::from_bits(clock), f64::from_bits(tau))))
}

fn deck_bits(d: DeckState<std::sync::Arc<dyn super::pinned::PinnedClip>>, naming: &Naming<'_>) -> DeckBits {
    DeckBits {
        motion: (naming.motion)(&d.motion),
        origin: d.origin.map(f64::to_bits),
        phases: d.phases.into_iter().map(f64::to_bits).collect(),
        weights: d.weights.into_iter().map(f32::to_bits).collect(),
        ramps: d
            .ramps
            .into_iter()
            .map(|r| r.map(|r| (r.from.to_bits(), r.to.to_bits(), r.elapsed.to_bits(), r.duration.to_bits())))
            .collect(),
        fresh: d.fresh,
        roots: d
            .roots
            .into_iter()
            .map(|r| r.map(|r| RootAtBits { cycle: r.cycle, time: r.time.to_bits(), m: planar_bits(r.m) }))
            .collect(),
        root_motion: d.root_motion.map(root_bits),
    }
}

fn player_state(
    p: &PlayerBits,
    lookup: &Lookup<'_>,
) -> Result<PlayerState<std::sync::Arc<dyn super::pinned::PinnedClip>>, CheckpointError> {
    let fade = match &p.fade {
        None => None,
        Some(f) => Some(Box::new(FadeState {
            under: player_state(&f.under, lookup)?,
            elapsed: f64::from_bits(f.elapsed),
            duration: f64::from_bits(f.duration),
            ease: ease(&f.ease)?,
        })),
    };
    let ik = match &p.ik {
        None => Vec::new(),
        Some(source) => (lookup.ik)(source).ok_or_else(|| missing(source))?,
    };
    Ok(PlayerState {
        top: deck_state(&p.top, lookup)?,
        fade,
        seek: p.seek.map(f64::from_bits),
        last_s: p.last_s.map(f64::from_bits),
        alpha: f32::from_bits(p.alpha),
        root: p.root.map(root),
        up: if p.up_z { UpAxis::Z } else { UpAxis::Y },
        ik,
        warm: p
            .warm
            .iter()
            .map(|(joints, angles)| WarmStart {
                joints: joints.clone(),
                angles: angles.iter().copied().map(f32::from_bits).collect(),
            })
            .collect(),
        springs: p.springs.as_ref().map(spring_state),
        springs_jumped: p.springs_jumped,
    })
}

fn deck_state(
    d: &DeckBits,
    lookup: &Lookup<'_>,
) -> Result<DeckState<std::sync::Arc<dyn super::pinned::PinnedClip>>, CheckpointError> {
    Ok(DeckState {
        motion: (lookup.motion)(&d.motion).ok_or_else(|| missing(&d.motion))?,
        origin: d.origin.map(f64::from_bits),
        phases: d.phases.iter().copied().map(f64::from_bits).collect(),
        weights: d.weights.iter().copied().map(f32::from_bits).collect(),
        ramps: d
            .ramps
            .iter()
            .map(|r| {
                r.map(|(from, to, elapsed, duration)| RampState {
                    from: f32::from_bits(from),
                    to: f32::from_bits(to),
                    elapsed: f64::from_bits(elapsed),
                    duration: f64::from_bits(duration),
                })
            })
            .collect(),
        fresh: d.fresh,
        roots: d
            .roots
            .iter()
            .map(|r| r.map(|r| RootAt { cycle: r.cycle, time: f32::from_bits(r.time), m: planar(r.m) }))
            .collect(),
        root_motion: d.root_motion.map(root),
    })
}

fn missing(source: &Source) -> CheckpointError {
    match source {
        Source::Control(id) => CheckpointError::MissingControl(id.clone()),
        Source::Definition => CheckpointError::Mismatch("the definition has no IK list".into()),
    }
}

fn ease(name: &str) -> Result<Ease, CheckpointError> {
    [Ease::Linear, Ease::EaseIn, Ease::EaseOut, Ease::EaseInOut]
        .into_iter()
        .find(|e| e.as_str() == name)
        .ok_or_else(|| CheckpointError::Unreadable(format!("no ease {name:?}")))
}
