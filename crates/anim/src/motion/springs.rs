//! A motion's spring chains run on its composed pose (docs/springs.md,
//! “Time”): one [`SpringRun`] per simulation, stateless (a request's times
//! in order, from rest `warmup` before the first) or clocked (a stream's
//! ticks in stream time). The substeps between two frames evaluate the
//! motion at their own times with a sampler of their own (a stream's: the
//! player's mix between its ticks, crossfades included), so the frame's
//! root motion and IK warm starts are untouched.

use super::{ClipSource, Motion, MotionSampler};
use crate::spring::{DEFAULT_WARMUP, SpringSolver, SpringState, Springs, StateMismatch, warmup_start};
use crate::{Ease, Pose};

/// One simulation of a motion's springs; see the module doc.
#[derive(Debug, Clone)]
pub struct SpringRun {
    solver: SpringSolver,
    /// The motion at a substep's time.
    scratch: MotionSampler,
    /// Stateless: the motion time the simulation started at rest, and the
    /// last time sampled; `None` until the first sample (or a restart).
    from: Option<f64>,
    last: f64,
    /// Clocked: the previous frame's clock and motion time.
    previous: Option<(f64, f64)>,
}

impl SpringRun {
    /// A run at rest for `springs`.
    pub fn new(springs: &Springs) -> Self {
        SpringRun {
            solver: SpringSolver::new(springs),
            scratch: MotionSampler::new(),
            from: None,
            last: f64::NEG_INFINITY,
            previous: None,
        }
    }

    /// A run in `state` (a broadcast checkpoint's), its previous frame at
    /// `previous` (clock, motion time).
    ///
    /// # Errors
    /// The state is not one entry per turning joint of `springs`.
    pub fn from_state(
        springs: &Springs,
        state: SpringState,
        previous: Option<(f64, f64)>,
    ) -> Result<Self, StateMismatch> {
        Ok(SpringRun { solver: SpringSolver::from_state(springs, state)?, previous, ..SpringRun::new(springs) })
    }

    /// The solver's state and the previous frame (clock, motion time).
    pub fn state(&self) -> (SpringState, Option<(f64, f64)>) {
        (self.solver.state(), self.previous)
    }

    /// Back to rest: the next frame shows the rest rotations of the turning
    /// joints and the simulation starts from it.
    pub fn restart(&mut self) {
        self.solver.reset();
        self.from = None;
        self.previous = None;
    }

    /// The substeps at or before `clock` not run yet are skipped
    /// ([`SpringSolver::skip_to`]).
    pub fn skip_to(&mut self, springs: &Springs, clock: f64) {
        self.solver.skip_to(springs, clock);
    }

    /// Substeps a frame at `clock` would run now (for pricing).
    pub fn pending(&self, springs: &Springs, clock: f64) -> u64 {
        self.solver.pending(springs, clock)
    }

    /// A stateless request's frame at motion time `tau` into `local` (the
    /// motion's layered pose at `tau`): the simulation starts at rest at
    /// `max(min(0, tau), tau − warmup)` on its first time, or when `tau`
    /// goes back; its grid counts from that start.
    pub(super) fn stateless_frame<C: ClipSource>(
        &mut self,
        motion: &Motion<C>,
        springs: &Springs,
        tau: f64,
        ease: Ease,
        local: &mut Pose,
    ) {
        let from = match self.from {
            Some(from) if tau >= self.last => from,
            _ => {
                let from = warmup_start(tau.min(0.0), tau, DEFAULT_WARMUP);
                motion.sample_local(from, ease, Some(springs.reads()), &mut self.scratch);
                self.solver.start_at(springs, 0.0, self.scratch.local());
                self.from = Some(from);
                from
            }
        };
        self.last = tau;
        let SpringRun { solver, scratch, .. } = self;
        solver.frame(springs, tau - from, local, |u, pose| {
            motion.sample_local(from + u, ease, Some(springs.reads()), scratch);
            pose.copy_from(scratch.local());
        });
    }

    /// A stream's frame at stream time `clock` (showing its motion at
    /// motion time `tau`, recorded with the clock) into `local`, its pose
    /// of that tick. A substep between the previous frame and this one
    /// sees `between(u, pose)`: the stream's pose at the share `u` of the
    /// way from the previous tick to this one (its decks' times and
    /// weights, a crossfade's `α`); `same` says whether the previous frame
    /// can be interpolated from (else the substeps see `u = 1`).
    pub fn clocked_frame(
        &mut self,
        springs: &Springs,
        (clock, tau, same): (f64, f64, bool),
        local: &mut Pose,
        mut between: impl FnMut(f64, &mut Pose),
    ) {
        let c0 = match self.previous {
            Some((c0, _)) if same && clock > c0 => c0,
            _ => clock,
        };
        self.solver.frame(springs, clock, local, |c, pose| {
            let u = if clock > c0 { (c - c0) / (clock - c0) } else { 1.0 };
            between(u, pose);
        });
        self.previous = Some((clock, tau));
    }
}
