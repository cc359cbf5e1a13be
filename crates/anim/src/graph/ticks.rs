//! A graph played on a tick grid with timed inputs (docs/graphs.md, “Using
//! a graph”): ticks at `k/fps` of motion time from 0, each input due at the
//! first tick at or after its time, the poses of the ticks from `start` to
//! `end` answered. A sampling request is this; a stream is the same player
//! ticked live with `set` controls, so both give the same poses for the same
//! settings at the same ticks.
//!
//! Ticks before the first answered one are stepped without evaluating a
//! pose (transitions depend on parameters and node times, never on poses).

use super::{GraphPlayer, SetError, Value};
use crate::motion::ClipSource;

/// A time within this many ticks of a tick counts as on it, so that e.g.
/// 0.1 s at 60 fps is tick 6 (0.1 · 60 is 6.000000000000001 in f64).
const ON_TICK: f64 = 1e-9;

/// The grid `k/fps` and the ticks whose poses are answered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickRange {
    pub fps: f64,
    /// The first tick at or after `start`.
    pub first: u64,
    /// The last tick at or before `end`.
    pub last: u64,
}

impl TickRange {
    /// The ticks of the grid at `fps` within `[start, end]`; `None` when
    /// there are none or the numbers are not finite, positive and ordered.
    pub fn new(start: f64, end: f64, fps: f64) -> Option<TickRange> {
        let valid = start.is_finite() && end.is_finite() && fps.is_finite() && fps > 0.0 && start >= 0.0;
        if !valid || end < start {
            return None;
        }
        let first = due_tick(start, fps);
        let last = (end * fps + ON_TICK).floor();
        if last >= u64::MAX as f64 || (last as u64) < first {
            return None;
        }
        Some(TickRange { fps, first, last: last as u64 })
    }

    /// How many poses are answered.
    pub fn answered(&self) -> u64 {
        self.last - self.first + 1
    }

    /// Tick `k`'s motion time.
    pub fn time(&self, k: u64) -> f64 {
        k as f64 / self.fps
    }
}

/// The first tick of the grid at `fps` at or after `time` (0 for a time at
/// or before 0); saturates for a time past the grid's reach.
pub fn due_tick(time: f64, fps: f64) -> u64 {
    let k = (time * fps - ON_TICK).ceil();
    if k.is_nan() || k <= 0.0 { 0 } else { k as u64 }
}

/// Parameter settings by the tick they are due at, in the order given
/// within a tick (a later setting of the same parameter wins).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Inputs {
    /// `(tick, parameter, value)`, sorted by tick, stable.
    sets: Vec<(u64, usize, Value)>,
}

impl Inputs {
    /// Inputs from `(time, parameter, value)` settings on the grid at `fps`.
    pub fn new(fps: f64, settings: impl IntoIterator<Item = (f64, usize, Value)>) -> Inputs {
        let mut sets: Vec<(u64, usize, Value)> =
            settings.into_iter().map(|(time, p, v)| (due_tick(time, fps), p, v)).collect();
        sets.sort_by_key(|s| s.0);
        Inputs { sets }
    }

    /// The settings, `(tick, parameter, value)`, in the order they apply.
    pub fn settings(&self) -> &[(u64, usize, Value)] {
        &self.sets
    }
}

impl<C: ClipSource> GraphPlayer<C> {
    /// Plays a new player's ticks `0..=range.last`, applying each input at
    /// its tick, and calls `each` with every answered tick once its pose is
    /// evaluated.
    ///
    /// # Errors
    /// The first input that does not fit the graph (see [`GraphPlayer::set`]);
    /// ticks before it have been played.
    pub fn play(
        &mut self,
        range: &TickRange,
        inputs: &Inputs,
        mut each: impl FnMut(u64, &Self),
    ) -> Result<(), SetError> {
        let mut next = 0;
        for k in range.first..=range.last {
            self.play_to(k, range, inputs, &mut next)?;
            each(k, self);
        }
        Ok(())
    }

    /// Plays the ticks from the next one to `k` (none when `k` is played),
    /// applying each input at its tick; `next` is the first input not yet
    /// applied (0 for a new player), so an answer written a piece at a time
    /// plays as [`GraphPlayer::play`] does. Ticks before `range.first` are
    /// stepped without a pose.
    ///
    /// # Errors
    /// As [`GraphPlayer::play`].
    pub fn play_to(&mut self, k: u64, range: &TickRange, inputs: &Inputs, next: &mut usize) -> Result<(), SetError> {
        self.play_through(k, (range, range.first), inputs, next, |_, _| {})
    }

    /// [`GraphPlayer::play_to`] evaluating the ticks from `evaluated` on
    /// (a motion's springs warm up before the first answered tick), and
    /// calling `each` with every tick evaluated.
    ///
    /// # Errors
    /// As [`GraphPlayer::play`].
    pub fn play_through(
        &mut self,
        k: u64,
        (range, evaluated): (&TickRange, u64),
        inputs: &Inputs,
        next: &mut usize,
        mut each: impl FnMut(u64, &Self),
    ) -> Result<(), SetError> {
        let dt = 1.0 / range.fps;
        while self.ticks() <= k {
            let tick = self.ticks();
            while let Some(&(_, parameter, value)) = inputs.sets.get(*next).filter(|s| s.0 <= tick) {
                self.set(parameter, value)?;
                *next += 1;
            }
            if tick < evaluated {
                self.step(dt);
            } else {
                self.tick(dt);
                each(tick, self);
            }
        }
        Ok(())
    }
}
