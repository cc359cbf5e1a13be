//! A live playback of motions (docs/motion.md, “Streams”): the motion playing now,
//! the layer-weight ramps on it, and the crossfades in progress beneath it.
//!
//! A [`Player`] is driven by *stream time* `s`, which the stream's playhead
//! computes (pause, speed, reverse); each motion it holds (a `Deck`) shows
//! motion time `τ = s − origin`. The first motion's origin is 0 (stream
//! time is its motion time, as a clip stream's request time is its clip's);
//! a crossfade target's is the stream time at which it started. A crossfade to B puts a new deck on top whose origin is the
//! next tick's `s` (so B starts at motion time 0) and keeps the whole
//! previous player, still advancing, underneath; at `α = ease(elapsed /
//! duration)` every joint is the short-way blend of the two sides' layered
//! local poses. A fade asked for during a fade takes the fade in progress
//! as its A, so the pose never jumps. Fades and weight ramps progress by
//! `|Δs|` per tick: they hold while paused and follow the playback speed.
//!
//! Root motion: each side's delta comes from its own motion's sampler; a
//! fade lerps the two by `α`; the player keeps the total.
//!
//! Nothing here allocates once every buffer has its size, except a
//! crossfade itself (the new deck's buffers).

use std::fmt;
use std::sync::Arc;

mod state;
pub use state::{DeckState, FadeState, PlayerState, RampState};

use super::layering::{self, Joint};
use super::root::Planar;
use super::{ClipSource, Motion, MotionOptions, MotionSampler, RootMotion, SpringRun, UpAxis};
use crate::ik::{ChainStart, IkConstraint, IkReport, IkSolver};
use crate::{Ease, Playback, Pose, Space};

/// Fades in progress at most; a crossfade beyond them finishes the oldest
/// at once (its pose leaves the mix), which bounds the work per tick.
pub const MAX_FADES: usize = 8;

/// Whether a crossfade onto a player with `fades` fades in progress
/// finishes the oldest at once ([`MAX_FADES`]).
pub const fn crossfade_drops_oldest(fades: usize) -> bool {
    fades + 1 > MAX_FADES
}

/// Records a crossfade to `to` on `motions`, the motions a player
/// evaluates, oldest first and the one playing last, as [`Player::crossfade`]
/// changes them: `to` on top, the oldest gone past [`MAX_FADES`] fades. A
/// list that leaves out the motion played before any crossfade keeps the
/// latest `MAX_FADES + 1` targets, all the player can hold.
pub fn push_crossfade<T>(motions: &mut std::collections::VecDeque<T>, to: T) {
    if !motions.is_empty() && crossfade_drops_oldest(motions.len() - 1) {
        motions.pop_front();
    }
    motions.push_back(to);
}

/// A layer weight moving linearly to a target.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Ramp {
    from: f32,
    to: f32,
    elapsed: f64,
    duration: f64,
}

/// One motion on the player.
#[derive(Debug, Clone)]
struct Deck<C> {
    motion: Arc<Motion<C>>,
    /// Stream time of motion time 0; `None` until its first tick.
    origin: Option<f64>,
    phases: Vec<f64>,
    weights: Vec<f32>,
    ramps: Vec<Option<Ramp>>,
    sampler: MotionSampler,
    /// Whether the next sample starts afresh (first tick or a jump).
    fresh: bool,
    /// The spring substeps between the previous tick and this one.
    between: Between,
}

/// Where a deck was at its previous tick, and its pose at a spring substep
/// between that tick and the last (docs/springs.md, “Time”): its motion
/// time moves on by the share `u` of the interval, its sync phases at the
/// rate of the previous tick's weights (as a tick's do), its layer weights
/// from the previous tick's to the last's.
#[derive(Debug, Clone, Default)]
struct Between {
    /// The previous tick's motion time and the stream time moved since;
    /// `None`: no previous tick to start from (a first tick or a jump).
    from: Option<(f64, f64)>,
    phases: Vec<f64>,
    weights: Vec<f32>,
    /// Scratch: the substep's phases and weights, and its pose.
    at_phases: Vec<f64>,
    at_weights: Vec<f32>,
    sampler: MotionSampler,
}

/// A fade in progress: the previous player, fading out.
#[derive(Debug, Clone)]
struct Fade<C> {
    under: Player<C>,
    /// Stream time moved (`Σ|Δs|`) since the fade's first tick.
    elapsed: f64,
    /// `elapsed` at the previous tick (the spring substeps' `α`).
    elapsed_before: f64,
    duration: f64,
    ease: Ease,
}

impl<C> Fade<C> {
    /// The fade's `α` at the share `u` of the way from the previous tick
    /// to the last.
    fn alpha_between(&self, u: f64) -> f32 {
        let elapsed = self.elapsed_before + u * (self.elapsed - self.elapsed_before);
        let progress = if self.duration > 0.0 { (elapsed / self.duration).min(1.0) } else { 1.0 };
        self.ease.apply(progress) as f32
    }
}

/// Where the current motion's first layer is in its clip, unwrapped: the
/// position its playback maps to a clip time (for the events crossed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LayerPosition {
    pub x: f64,
    pub playback: Playback,
}

/// A live playback of motions; see the module doc.
/// Cloning copies every piece of state (warm starts included), so a clone
/// stepped on produces what the original would (broadcast snapshots).
#[derive(Debug, Clone)]
pub struct Player<C> {
    top: Deck<C>,
    fade: Option<Box<Fade<C>>>,
    /// A fade that ended at the last tick: the spring substeps before that
    /// tick still see it.
    ended: Option<Box<Fade<C>>>,
    /// The motion time the next tick must show (a seek), if any.
    seek: Option<f64>,
    last_s: Option<f64>,
    alpha: f32,
    local: Pose,
    model: Pose,
    space: Space,
    root: Option<RootMotion>,
    up: UpAxis,
    ik: StreamIk,
    springs: StreamSprings,
}

/// The current motion's spring chains (docs/springs.md, “Time”), run in
/// the clock the caller gives (stream time); a crossfade to a motion with
/// the same chains keeps them going.
#[derive(Debug, Clone, Default)]
struct StreamSprings {
    run: Option<Box<SpringRun>>,
    /// Whether the next frame's substeps cannot follow the last frame's
    /// motion time (a seek or a change of motion).
    jumped: bool,
    /// Whether the player's `local` holds the last tick's sprung pose.
    applied: bool,
    /// The stream's IK solved cold on a substep's pose (the tick's warm
    /// starts untouched).
    ik: IkSolver,
    reports: Vec<IkReport>,
}

/// The stream's request-time IK (docs/ik.md, “Streams”): solved on the
/// mixed pose at every tick, chains warm-started from the previous tick.
#[derive(Debug, Clone, Default)]
struct StreamIk {
    constraints: Vec<IkConstraint>,
    solver: IkSolver,
    solved: Vec<IkReport>,
    /// The current motion's clip reports, then `solved`.
    reports: Vec<IkReport>,
    /// Whether the player's `local` holds the last tick's solved pose.
    applied: bool,
}

/// Why a live change was refused.
#[derive(Debug, Clone, PartialEq)]
pub enum PlayerError {
    NoSuchLayer {
        index: usize,
        layers: usize,
    },
    Weight(f32),
    Duration(f64),
    Skeleton,
    Parameters,
    CrossfadeIk,
    /// A [`PlayerState`] that does not fit its motions (a list of the wrong length).
    State(&'static str),
}

impl<C: ClipSource> Deck<C> {
    fn new(motion: Arc<Motion<C>>) -> Self {
        Deck {
            weights: motion.weights().to_vec(),
            ramps: vec![None; motion.layer_count()],
            phases: Vec::with_capacity(motion.sync_group_count()),
            motion,
            origin: None,
            sampler: MotionSampler::new(),
            fresh: true,
            between: Between::default(),
        }
    }
}

impl<C> Deck<C> {
    /// Moves every ramp on by `progress` seconds.
    fn step_ramps(&mut self, progress: f64) {
        for (weight, slot) in self.weights.iter_mut().zip(&mut self.ramps) {
            let Some(ramp) = slot else { continue };
            ramp.elapsed += progress;
            let done = ramp.duration <= 0.0 || ramp.elapsed >= ramp.duration;
            *weight =
                if done { ramp.to } else { ramp.from + (ramp.to - ramp.from) * (ramp.elapsed / ramp.duration) as f32 };
            if done {
                *slot = None;
            }
        }
    }
}

impl<C: ClipSource> Deck<C> {
    /// Samples the deck at stream time `s` (local space), `ds` after its
    /// previous tick.
    fn sample(&mut self, s: f64, ds: f64, ease: Ease) {
        let origin = *self.origin.get_or_insert(s);
        let tau = s - origin;
        self.between.from = (!self.fresh).then_some((tau - ds, ds));
        self.between.phases.clone_from(&self.phases);
        self.between.weights.clone_from(&self.weights);
        if self.fresh {
            self.motion.phases_at(tau, &self.weights, &mut self.phases);
        } else {
            // The phase carries on at the rate of the weights that held
            // over the interval; then the ramps move on.
            self.motion.advance_phases(&mut self.phases, ds, &self.weights);
        }
        self.step_ramps(if self.fresh { 0.0 } else { ds.abs() });
        let options = MotionOptions { ease, space: Space::Local };
        self.motion.sample_with(tau, &self.phases, &self.weights, &options, &mut self.sampler);
        self.fresh = false;
    }

    fn delta(&self) -> Planar {
        self.sampler.root_motion().map_or(Planar::IDENTITY, |r| r.delta)
    }

    /// The deck's local pose at the share `u` of the way from its previous
    /// tick to its last (see [`Between`]), right at the joints in `only`
    /// (all without); the last tick's own pose when it had no previous one.
    fn sample_between(&mut self, u: f64, ease: Ease, only: Option<&[u64]>) -> &Pose {
        let Some((tau, ds)) = self.between.from else { return self.sampler.local() };
        let b = &mut self.between;
        b.at_phases.clone_from(&b.phases);
        self.motion.advance_phases(&mut b.at_phases, u * ds, &b.weights);
        b.at_weights.clone_from(&b.weights);
        for (w, last) in b.at_weights.iter_mut().zip(&self.weights) {
            *w += (*last - *w) * u as f32;
        }
        let (at, live) = (tau + u * ds, (&b.at_phases[..], &b.at_weights[..]));
        match only {
            Some(only) => self.motion.sample_joints_with(at, live, ease, only, &mut b.sampler),
            None => {
                let options = MotionOptions { ease, space: Space::Local };
                self.motion.sample_with(at, live.0, live.1, &options, &mut b.sampler);
            }
        }
        b.sampler.local()
    }
}

impl<C: ClipSource> Player<C> {
    /// A player of `motion`, whose motion time is the stream time.
    pub fn new(motion: Arc<Motion<C>>) -> Self {
        let up = motion.root_up().unwrap_or_default();
        let ik = StreamIk { constraints: motion.ik().to_vec(), ..StreamIk::default() };
        let springs = StreamSprings { run: motion_springs(&motion), ..StreamSprings::default() };
        Player {
            top: Deck { origin: Some(0.0), ..Deck::new(motion) },
            fade: None,
            ended: None,
            seek: None,
            last_s: None,
            alpha: 1.0,
            local: Pose::default(),
            model: Pose::default(),
            space: Space::Local,
            root: None,
            up,
            ik,
            springs,
        }
    }

    /// The motion playing now (the target of the latest crossfade).
    pub fn motion(&self) -> &Arc<Motion<C>> {
        &self.top.motion
    }

    /// Fades in progress.
    pub fn fades(&self) -> usize {
        self.fade.as_ref().map_or(0, |f| 1 + f.under.fades())
    }

    /// The current motion's time at the last tick.
    pub fn motion_time(&self) -> f64 {
        self.last_s.zip(self.top.origin).map_or(0.0, |(s, o)| s - o)
    }

    /// Starts a crossfade to `to` over `duration` seconds at the next tick.
    ///
    /// # Errors
    /// A negative or non-finite duration, or a motion whose skeleton is not
    /// the player's.
    pub fn crossfade(&mut self, to: Arc<Motion<C>>, duration: f64, ease: Ease) -> Result<(), PlayerError> {
        if !(duration.is_finite() && duration >= 0.0) {
            return Err(PlayerError::Duration(duration));
        }
        if !to.skeleton().same_joints(self.top.motion.skeleton()) {
            return Err(PlayerError::Skeleton);
        }
        if to.parameters().names() != self.top.motion.parameters().names()
            || to.parameters().widths() != self.top.motion.parameters().widths()
        {
            return Err(PlayerError::Parameters);
        }
        if !to.ik().is_empty() {
            return Err(PlayerError::CrossfadeIk);
        }
        if crossfade_drops_oldest(self.fades()) {
            self.drop_oldest_fade();
        }
        let under = Player {
            top: std::mem::replace(&mut self.top, Deck::new(to)),
            fade: self.fade.take(),
            ended: None,
            seek: None,
            last_s: self.last_s,
            alpha: self.alpha,
            local: Pose::default(),
            model: Pose::default(),
            space: Space::Local,
            root: None,
            up: self.up,
            ik: StreamIk::default(),
            springs: StreamSprings::default(),
        };
        self.up = self.top.motion.root_up().unwrap_or(self.up);
        if self.top.motion.springs() != under.top.motion.springs() {
            self.springs.run = motion_springs(&self.top.motion);
        }
        self.fade = Some(Box::new(Fade { under, elapsed: 0.0, elapsed_before: 0.0, duration, ease }));
        Ok(())
    }

    /// Ramps layer `index` of the current motion to `weight` over `duration`
    /// seconds, from its weight at the last tick and counted from that tick
    /// (the next tick already shows that interval's progress).
    ///
    /// # Errors
    /// No such layer, a weight outside `[0, 1]`, a bad duration.
    pub fn ramp(&mut self, index: usize, weight: f32, duration: f64) -> Result<(), PlayerError> {
        let layers = self.top.motion.layer_count();
        if index >= layers {
            return Err(PlayerError::NoSuchLayer { index, layers });
        }
        if !(0.0..=1.0).contains(&weight) {
            return Err(PlayerError::Weight(weight));
        }
        if !(duration.is_finite() && duration >= 0.0) {
            return Err(PlayerError::Duration(duration));
        }
        let from = self.top.weights[index];
        self.top.ramps[index] = Some(Ramp { from, to: weight, elapsed: 0.0, duration });
        if duration == 0.0 {
            self.top.step_ramps(0.0);
        }
        Ok(())
    }

    /// Replaces the stream's IK constraints from the next tick on (docs/ik.md
    /// "In streams"); they must have been validated against the player's
    /// skeleton. A chain at the same place over the same joints carries
    /// its angles on.
    pub fn set_ik(&mut self, constraints: Vec<IkConstraint>) {
        self.ik.constraints = constraints;
    }

    /// The stream's IK constraints.
    pub fn ik(&self) -> &[IkConstraint] {
        &self.ik.constraints
    }

    /// The last tick's IK reports: the current motion's clip constraints,
    /// then the stream's.
    pub fn ik_reports(&self) -> &[IkReport] {
        &self.ik.reports
    }

    /// The last tick's planted feet (the current motion's; empty when it
    /// plants none).
    pub fn feet(&self) -> &[crate::character::FootReport] {
        self.top.sampler.feet().unwrap_or_default()
    }

    /// The next tick shows the current motion at motion time `tau`; every
    /// motion beneath jumps by as much, and root motion has no delta.
    pub fn seek(&mut self, tau: f64) {
        self.seek = Some(tau);
    }

    /// Samples every motion at stream time `s` and mixes them; returns the
    /// current motion's first layer's clip time.
    pub fn sample(&mut self, s: f64, options: &MotionOptions) -> f32 {
        self.sample_clocked(s, s, options)
    }

    /// [`Player::sample`] with the springs run in `clock` (the stream's
    /// time, which pause and speed do not change; docs/springs.md, “Time”).
    pub fn sample_clocked(&mut self, s: f64, clock: f64, options: &MotionOptions) -> f32 {
        let jump = self.take_seek(s);
        if jump {
            self.reset_springs();
        }
        let ds = if jump { 0.0 } else { self.last_s.map_or(0.0, |last| s - last) };
        self.advance(s, ds, options.ease);
        self.solve_ik();
        self.run_springs(clock, options.ease);
        let delta = self.delta();
        if self.has_root_motion() {
            let total = self.root.map_or(Planar::IDENTITY, |r| r.total).then(delta, self.up);
            self.root = Some(RootMotion { delta, total });
        }
        self.space = options.space;
        if options.space == Space::Model {
            let local = if self.mixed_in_local() { &self.local } else { self.top.sampler.local() };
            self.top.motion.skeleton().to_model(local, &mut self.model);
        }
        self.top.sampler.clip_times()[0]
    }

    /// Solves the stream's constraints on the mixed pose (into `local`) and
    /// gathers the reports.
    fn solve_ik(&mut self) {
        let ik = &mut self.ik;
        ik.reports.clear();
        ik.reports.extend_from_slice(self.top.sampler.ik_reports());
        ik.applied = !ik.constraints.is_empty();
        if !ik.applied {
            return;
        }
        if self.fade.is_none() {
            self.local.copy_from(self.top.sampler.local());
        }
        let skeleton = self.top.motion.skeleton();
        ik.solver.solve(skeleton, &mut self.local, &ik.constraints, ChainStart::Warm, &mut ik.solved);
        ik.reports.extend_from_slice(&ik.solved);
    }

    /// Turns a pending seek into origins moved so that the current motion
    /// shows it at `s`; returns whether there was one.
    fn take_seek(&mut self, s: f64) -> bool {
        let Some(tau) = self.seek.take() else { return false };
        let shift = match self.top.origin {
            Some(origin) => (s - tau) - origin,
            None => 0.0,
        };
        self.top.origin = Some(self.top.origin.map_or(s - tau, |o| o + shift));
        self.for_each_under(&mut |deck| {
            if let Some(o) = deck.origin.as_mut() {
                *o += shift;
            }
        });
        self.for_each_deck(&mut |deck| {
            deck.fresh = true;
            deck.sampler.rebase_root();
        });
        true
    }

    /// Samples the decks at `s`, then mixes the fade into `local`.
    fn advance(&mut self, s: f64, ds: f64, ease: Ease) {
        self.last_s = Some(s);
        self.ended = None;
        // A fade starts at its target's first tick (B at motion time 0,
        // α = 0, the pose still A's): the interval before it is not part
        // of it.
        let fade_starts = self.top.origin.is_none();
        self.top.sample(s, ds, ease);
        let Some(fade) = self.fade.as_mut() else {
            self.alpha = 1.0;
            return;
        };
        fade.under.advance(s, ds, ease);
        fade.elapsed_before = fade.elapsed;
        if !fade_starts {
            fade.elapsed += ds.abs();
        }
        let progress = if fade.duration > 0.0 { (fade.elapsed / fade.duration).min(1.0) } else { 1.0 };
        self.alpha = fade.ease.apply(progress) as f32;
        if progress >= 1.0 {
            self.ended = self.fade.take();
            self.alpha = 1.0;
            return;
        }
        let under = fade.under.local_pose();
        mix(under, self.top.sampler.local(), self.alpha, &mut self.local);
    }

    /// The mixed local pose of the last tick.
    fn local_pose(&self) -> &Pose {
        if self.mixed_in_local() { &self.local } else { self.top.sampler.local() }
    }

    /// Whether the last tick's pose is in `local` rather than the top
    /// deck's sampler (a fade mixed it, IK or springs changed it).
    fn mixed_in_local(&self) -> bool {
        self.fade.is_some() || self.ik.applied || self.springs.applied
    }

    /// The springs start again at rest at the next tick, whose frame shows
    /// their joints' rest rotations (a seek, `reset_springs`).
    pub fn reset_springs(&mut self) {
        if let Some(run) = self.springs.run.as_mut() {
            run.restart();
        }
        self.springs.jumped = true;
    }

    /// The current motion's spring substeps at or before stream time
    /// `clock` not run yet are skipped: the next tick runs those after it
    /// only (a frame woken late catches up a bounded span).
    pub fn skip_springs_to(&mut self, clock: f64) {
        if let (Some(run), Some(springs)) = (self.springs.run.as_mut(), self.top.motion.springs()) {
            run.skip_to(springs, clock);
        }
    }

    /// Runs the current motion's springs for the tick at `clock` on the
    /// mixed pose (into `local`); the substeps before it see the mix
    /// between the ticks ([`Player::pose_between`]).
    fn run_springs(&mut self, clock: f64, ease: Ease) {
        let motion = Arc::clone(&self.top.motion);
        let (Some(mut run), Some(springs)) = (self.springs.run.take(), motion.springs()) else {
            self.springs.applied = false;
            return;
        };
        if !(self.fade.is_some() || self.ik.applied) {
            self.local.copy_from(self.top.sampler.local());
        }
        let tau = self.motion_time();
        let same = !std::mem::take(&mut self.springs.jumped);
        let mut local = std::mem::take(&mut self.local);
        // The substeps read only the chains' joints and their ancestors,
        // unless the stream's IK, which reads whole chains, runs first.
        let only = self.ik.constraints.is_empty().then(|| springs.reads());
        run.clocked_frame(springs, (clock, tau, same), &mut local, |u, pose| {
            self.pose_between(u, (ease, only), pose);
            self.solve_ik_between(pose);
        });
        (self.local, self.springs.run) = (local, Some(run));
        self.springs.applied = true;
    }

    /// The mixed local pose at the share `u` of the way from the previous
    /// tick to the last, into `out`: every deck at its time and weights
    /// then, every fade (one that ended at the last tick included) at its
    /// `α` then (docs/springs.md, “Time”); right at the joints in `only`
    /// (all without), which are what they would be in the whole pose.
    fn pose_between(&mut self, u: f64, (ease, only): (Ease, Option<&[u64]>), out: &mut Pose) {
        let top = self.top.sample_between(u, ease, only);
        match self.fade.as_deref_mut().or(self.ended.as_deref_mut()) {
            None => out.copy_from(top),
            Some(fade) => {
                let alpha = fade.alpha_between(u);
                fade.under.pose_between(u, (ease, only), out);
                if alpha > 0.0 {
                    blend_into(out, top, alpha);
                }
            }
        }
    }

    /// The stream's IK on a substep's pose, solved cold by a solver of its
    /// own.
    fn solve_ik_between(&mut self, pose: &mut Pose) {
        if self.ik.constraints.is_empty() {
            return;
        }
        let StreamSprings { ik, reports, .. } = &mut self.springs;
        ik.solve(self.top.motion.skeleton(), pose, &self.ik.constraints, ChainStart::Cold, reports);
    }

    /// The last tick's layered root delta: the fade's sides lerped by `α`.
    fn delta(&self) -> Planar {
        match &self.fade {
            None => self.top.delta(),
            Some(fade) => fade.under.delta().lerp(self.top.delta(), f64::from(self.alpha)),
        }
    }

    /// The pose of the last tick, in the space it asked for.
    pub fn pose(&self) -> &Pose {
        match self.space {
            Space::Local => self.local_pose(),
            Space::Model => &self.model,
        }
    }

    /// The last tick's root motion, when any motion on the player has it.
    pub fn root_motion(&self) -> Option<RootMotion> {
        self.root
    }

    /// Whether any motion on the player reports root motion.
    pub fn has_root_motion(&self) -> bool {
        self.top.motion.has_root_motion() || self.fade.as_ref().is_some_and(|f| f.under.has_root_motion())
    }

    /// The current motion's first layer's unwrapped clip position at the
    /// last tick (see [`LayerPosition`]).
    pub fn first_layer_position(&self) -> LayerPosition {
        let (x, playback) = self.top.motion.layer_position(0, self.motion_time(), &self.top.phases);
        LayerPosition { x, playback }
    }

    /// The current fade's `α` at the last tick (1 without a fade).
    pub fn alpha(&self) -> f32 {
        self.alpha
    }

    fn drop_oldest_fade(&mut self) {
        let Some(fade) = self.fade.as_mut() else { return };
        if fade.under.fade.is_some() {
            fade.under.drop_oldest_fade();
        } else {
            self.fade = None;
        }
    }

    fn for_each_deck(&mut self, f: &mut impl FnMut(&mut Deck<C>)) {
        f(&mut self.top);
        self.for_each_under(f);
    }

    fn for_each_under(&mut self, f: &mut impl FnMut(&mut Deck<C>)) {
        if let Some(fade) = self.fade.as_mut() {
            fade.under.for_each_deck(f);
        }
    }
}

/// A fresh run of `motion`'s springs, if it has any.
fn motion_springs<C: ClipSource>(motion: &Motion<C>) -> Option<Box<SpringRun>> {
    motion.springs().map(|springs| Box::new(SpringRun::new(springs)))
}

/// `out = blend(a, b, α)` joint by joint (lerp, short-way slerp), written
/// straight into `out` (a crossfade's sides have the same joints; `a`'s
/// are copied first only if they did not).
pub(crate) fn mix(a: &Pose, b: &Pose, alpha: f32, out: &mut Pose) {
    if a.len() != b.len() || out.len() != a.len() {
        out.copy_from(a);
    }
    for j in 0..b.len().min(a.len()) {
        let mut joint = Joint { t: a.translations[j], q: a.rotations[j], s: a.scales[j] };
        let other = Joint { t: b.translations[j], q: b.rotations[j], s: b.scales[j] };
        layering::blend(&mut joint, &other, alpha);
        (out.translations[j], out.rotations[j], out.scales[j]) = (joint.t, joint.q, joint.s);
    }
    // Both sides have the same parameters (`crossfade` checks it).
    out.parameters.clone_from(&a.parameters);
    for (o, b) in out.parameters.iter_mut().zip(&b.parameters) {
        *o = layering::lerp(*o, *b, alpha);
    }
}

/// `out = blend(out, b, α)` joint by joint (lerp, short-way slerp).
fn blend_into(out: &mut Pose, b: &Pose, alpha: f32) {
    for j in 0..b.len().min(out.len()) {
        let mut joint = Joint { t: out.translations[j], q: out.rotations[j], s: out.scales[j] };
        let other = Joint { t: b.translations[j], q: b.rotations[j], s: b.scales[j] };
        layering::blend(&mut joint, &other, alpha);
        (out.translations[j], out.rotations[j], out.scales[j]) = (joint.t, joint.q, joint.s);
    }
    // Both sides have the same parameters (`crossfade` checks it).
    for (o, b) in out.parameters.iter_mut().zip(&b.parameters) {
        *o = layering::lerp(*o, *b, alpha);
    }
}

impl fmt::Display for PlayerError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PlayerError::NoSuchLayer { index, layers } => {
                write!(f, "layer {index} does not exist: the motion playing has {layers} layers")
            }
            PlayerError::Weight(v0) => write!(f, "a layer weight must be in [0, 1], got {0}", v0),
            PlayerError::Duration(v0) => write!(f, "a duration must be a finite number of seconds ≥ 0, got {0}", v0),
            PlayerError::Skeleton => write!(
                f,
                "the motion's skeleton differs from the stream's: a crossfade needs the same joints in the same order"
            ),
            PlayerError::Parameters => write!(
                f,
                "the motion's parameters differ from the stream's: a crossfade needs the same parameter names and widths in the same order"
            ),
            PlayerError::State(what) => write!(f, "a player state that does not fit its motion: {what}"),
            PlayerError::CrossfadeIk => {
                write!(f, "a crossfade's motion carries no `ik`: a stream's constraints change with an `ik` control")
            }
        }
    }
}

impl std::error::Error for PlayerError {}
