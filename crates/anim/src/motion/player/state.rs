//! A [`Player`]'s state as plain values, and a player made again from it
//! (a broadcast checkpoint: the server stores it, and a restarted node
//! steps on from it instead of from tick 0).
//!
//! The state is everything a player carries from one tick to the next —
//! playheads of every deck, sync-group phases, layer weights and ramps,
//! fades and their progress, a pending seek, the root's last positions and
//! running total, the IK constraints and their chains' warm starts, the
//! springs' tails and the last frame's clock — and
//! nothing a tick computes afresh (poses, reports, cursors' search hints).
//! So a player restored from the state of another steps on exactly as that
//! one would, bit for bit.

use std::sync::Arc;

use super::{Deck, Fade, Player, PlayerError, Ramp, StreamIk, StreamSprings};
use crate::ik::{IkConstraint, WarmStart};
use crate::motion::root::RootAt;
use crate::motion::{ClipSource, Motion, MotionSampler, RootMotion, SpringRun, UpAxis};
use crate::spring::SpringState;
use crate::{Ease, Pose, Space};

/// A layer weight on its way to a target (see [`Player::ramp`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RampState {
    pub from: f32,
    pub to: f32,
    pub elapsed: f64,
    pub duration: f64,
}

/// One motion on a player.
#[derive(Debug, Clone)]
pub struct DeckState<C> {
    pub motion: Arc<Motion<C>>,
    /// Stream time of motion time 0 (`None` before its first tick).
    pub origin: Option<f64>,
    /// Sync-group phases (one per group once sampled).
    pub phases: Vec<f64>,
    /// Live layer weights, one per layer.
    pub weights: Vec<f32>,
    pub ramps: Vec<Option<RampState>>,
    /// The next sample starts afresh (first tick or a jump).
    pub fresh: bool,
    /// Each layer's root at the last sample (empty: none, or after a jump).
    pub roots: Vec<Option<RootAt>>,
    /// The last sample's root motion (its total carries on).
    pub root_motion: Option<RootMotion>,
}

/// A fade in progress: the player it fades out of, and how far it is.
#[derive(Debug, Clone)]
pub struct FadeState<C> {
    pub under: PlayerState<C>,
    /// Stream time moved (`Σ|Δs|`) since the fade's first tick.
    pub elapsed: f64,
    pub duration: f64,
    pub ease: Ease,
}

/// Everything a [`Player`] carries from tick to tick; see the module doc.
#[derive(Debug, Clone)]
pub struct PlayerState<C> {
    /// The motion playing now (the latest crossfade's target).
    pub top: DeckState<C>,
    pub fade: Option<Box<FadeState<C>>>,
    /// A seek the next tick shows (motion time of the top motion).
    pub seek: Option<f64>,
    /// The stream time of the last tick.
    pub last_s: Option<f64>,
    pub alpha: f32,
    /// The player's root motion (its running total).
    pub root: Option<RootMotion>,
    pub up: UpAxis,
    /// The stream's IK constraints (empty under a fade).
    pub ik: Vec<IkConstraint>,
    /// Their chains' warm starts, in constraint order.
    pub warm: Vec<WarmStart>,
    /// The current motion's spring simulation: the solver's state and the
    /// last frame's clock and motion time (`None`: no springs).
    pub springs: Option<(SpringState, Option<(f64, f64)>)>,
    /// Whether the next frame's springs start from a jump.
    pub springs_jumped: bool,
}

impl<C: ClipSource> Player<C> {
    /// This player's state (see [`PlayerState`]).
    pub fn state(&self) -> PlayerState<C> {
        PlayerState {
            top: self.top.state(),
            fade: self.fade.as_ref().map(|f| {
                Box::new(FadeState { under: f.under.state(), elapsed: f.elapsed, duration: f.duration, ease: f.ease })
            }),
            seek: self.seek,
            last_s: self.last_s,
            alpha: self.alpha,
            root: self.root,
            up: self.up,
            ik: self.ik.constraints.clone(),
            warm: self.ik.solver.warm_starts(),
            springs: self.springs.run.as_ref().map(|run| run.state()),
            springs_jumped: self.springs.jumped,
        }
    }

    /// A player in `state`: its next tick is the one the player the state
    /// was taken from would have made.
    ///
    /// # Errors
    /// A deck's lists do not fit its motion (weights or ramps not one per
    /// layer, phases not one per sync group, roots not one per layer), or
    /// there are more fades than [`super::MAX_FADES`].
    pub fn from_state(state: PlayerState<C>) -> Result<Self, PlayerError> {
        let fade = match state.fade {
            None => None,
            Some(f) => {
                let FadeState { under, elapsed, duration, ease } = *f;
                let under = Player::from_state(under)?;
                Some(Box::new(Fade { under, elapsed, elapsed_before: elapsed, duration, ease }))
            }
        };
        let mut ik = StreamIk { constraints: state.ik, ..StreamIk::default() };
        ik.solver.set_warm_starts(state.warm);
        let top = Deck::from_state(state.top)?;
        let run = match (state.springs, top.motion.springs()) {
            // A faded-out player's springs no longer run.
            (None, _) => None,
            (Some((solver, previous)), Some(springs)) => Some(Box::new(
                SpringRun::from_state(springs, solver, previous)
                    .map_err(|_| PlayerError::State("a spring state that does not fit the motion's springs"))?,
            )),
            (Some(_), None) => return Err(PlayerError::State("a spring state for a motion without springs")),
        };
        let springs = StreamSprings { run, jumped: state.springs_jumped, ..StreamSprings::default() };
        let player = Player {
            top,
            fade,
            ended: None,
            seek: state.seek,
            last_s: state.last_s,
            alpha: state.alpha,
            local: Pose::default(),
            model: Pose::default(),
            space: Space::Local,
            root: state.root,
            up: state.up,
            ik,
            springs,
        };
        if player.fades() > super::MAX_FADES {
            return Err(PlayerError::State("more fades than a player keeps"));
        }
        Ok(player)
    }
}

impl<C: ClipSource> Deck<C> {
    fn state(&self) -> DeckState<C> {
        let (roots, root_motion) = self.sampler.root_state();
        DeckState {
            motion: Arc::clone(&self.motion),
            origin: self.origin,
            phases: self.phases.clone(),
            weights: self.weights.clone(),
            ramps: self
                .ramps
                .iter()
                .map(|r| r.map(|r| RampState { from: r.from, to: r.to, elapsed: r.elapsed, duration: r.duration }))
                .collect(),
            fresh: self.fresh,
            roots,
            root_motion,
        }
    }

    fn from_state(s: DeckState<C>) -> Result<Self, PlayerError> {
        let layers = s.motion.layer_count();
        if s.weights.len() != layers || s.ramps.len() != layers {
            return Err(PlayerError::State("a deck's weights and ramps are one per layer"));
        }
        if !s.roots.is_empty() && s.roots.len() != layers {
            return Err(PlayerError::State("a deck's roots are one per layer"));
        }
        if !s.fresh && s.phases.len() != s.motion.sync_group_count() {
            return Err(PlayerError::State("a deck's phases are one per sync group"));
        }
        let mut sampler = MotionSampler::new();
        sampler.set_root_state(s.roots, s.root_motion);
        let ramps = s
            .ramps
            .into_iter()
            .map(|r| r.map(|r| Ramp { from: r.from, to: r.to, elapsed: r.elapsed, duration: r.duration }))
            .collect();
        Ok(Deck {
            motion: s.motion,
            origin: s.origin,
            phases: s.phases,
            weights: s.weights,
            ramps,
            sampler,
            fresh: s.fresh,
            between: super::Between::default(),
        })
    }
}
