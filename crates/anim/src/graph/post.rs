//! What a motion runs after its layers, run on a graph's pose
//! (docs/graphs.md, “What composes with a graph”): the motion's IK
//! constraints, then its spring chains — built by the motion's own
//! [`post_stages`](crate::motion) and run by the same IK solver and spring
//! solver a motion uses.
//!
//! A graph is played tick by tick, never at an arbitrary time, so two rules
//! differ from a motion's: IK solves each tick from the graph's pose alone
//! (cold), so a stream's tick is a sampling request's; and the spring
//! substeps between two ticks see the later tick's pose (the pose held
//! from one tick to the next), not the motion at the substep's own time.

use super::TickRange;
use super::ticks::due_tick;
use crate::ik::{ChainStart, IkConstraint, IkLimits, IkReport, IkSolver, IkSpec};
use crate::motion::post_stages;
use crate::spring::{DEFAULT_WARMUP, SpringSolver, SpringState, Springs, SpringsSpec, StateMismatch, warmup_start};
use crate::{MotionError, Pose, Skeleton};

/// A graph's post stages as built: IK constraints and spring chains on the
/// graph's skeleton.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GraphPost {
    ik: Vec<IkConstraint>,
    springs: Option<Springs>,
}

impl GraphPost {
    /// The constraints and chains of a motion over a graph, checked against
    /// the graph's `skeleton` as a motion's are against its output skeleton.
    ///
    /// # Errors
    /// As a motion's `ik` and `springs` (paths `ik/0/…`, `springs/0/…`).
    pub fn build(
        ik: &[IkSpec],
        springs: &SpringsSpec,
        skeleton: &Skeleton,
        limits: &IkLimits,
    ) -> Result<GraphPost, MotionError> {
        let (ik, springs) = post_stages(ik, springs, skeleton, limits)?;
        Ok(GraphPost { ik, springs })
    }

    /// Whether there is nothing to run: the graph's pose is the answer.
    pub fn is_empty(&self) -> bool {
        self.ik.is_empty() && self.springs.is_none()
    }

    pub fn ik(&self) -> &[IkConstraint] {
        &self.ik
    }

    pub fn springs(&self) -> Option<&Springs> {
        self.springs.as_ref()
    }

    /// The first tick a sampling request over `range` evaluates and runs
    /// these stages on: its first answered tick, or with springs the tick
    /// their simulation starts at rest on (docs/springs.md, “Time”: `warmup`
    /// before the first answered time, not before 0).
    pub fn first_run(&self, range: &TickRange) -> u64 {
        if self.springs.is_none() {
            return range.first;
        }
        let first = range.time(range.first);
        due_tick(warmup_start(0.0, first, DEFAULT_WARMUP), range.fps).min(range.first)
    }
}

/// The post stages running on a graph's ticks; see the module doc.
#[derive(Debug, Clone, Default)]
pub struct PostRun {
    ik: IkSolver,
    reports: Vec<IkReport>,
    springs: Option<SpringSolver>,
    /// The last tick's pose with IK solved, before the springs (what the
    /// springs' substeps see).
    held: Pose,
    pose: Pose,
}

impl PostRun {
    /// At rest, for `post`.
    pub fn new(post: &GraphPost) -> Self {
        PostRun { springs: post.springs.as_ref().map(SpringSolver::new), ..PostRun::default() }
    }

    /// At a spring state a run of `post` gave (a broadcast checkpoint's).
    ///
    /// # Errors
    /// A state that is not one entry per turning joint, or a state for
    /// springs `post` has not (or none for springs it has).
    pub fn from_state(post: &GraphPost, state: Option<SpringState>) -> Result<Self, StateMismatch> {
        let springs = match (&post.springs, state) {
            (None, None) => None,
            (Some(springs), Some(state)) => Some(SpringSolver::from_state(springs, state)?),
            _ => {
                let expected = post.springs.as_ref().map_or(0, |s| s.substep_work().0);
                return Err(StateMismatch { expected, provided: 0 });
            }
        };
        Ok(PostRun { springs, ..PostRun::default() })
    }

    /// The springs start again at rest at the next tick (`reset_springs`).
    pub fn restart_springs(&mut self) {
        if let Some(solver) = self.springs.as_mut() {
            solver.reset();
        }
    }

    /// The springs' substeps at or before `clock` not run yet are skipped
    /// (`SpringSolver::skip_to`): ticks stepped without their pose.
    pub fn skip_springs_to(&mut self, post: &GraphPost, clock: f64) {
        if let (Some(springs), Some(solver)) = (post.springs.as_ref(), self.springs.as_mut()) {
            solver.skip_to(springs, clock);
        }
    }

    /// The springs' state (none without springs).
    pub fn spring_state(&self) -> Option<SpringState> {
        self.springs.as_ref().map(SpringSolver::state)
    }

    /// Runs the stages on `pose`, the graph's pose of the tick at `clock`
    /// (the springs' time): IK solved from it, then the spring substeps up
    /// to `clock`, each on that pose. A `clock` the springs have passed
    /// runs no substep and shows their last rotations (a restored run).
    pub fn run(&mut self, post: &GraphPost, skeleton: &Skeleton, pose: &Pose, clock: f64) {
        self.held.copy_from(pose);
        self.ik.solve(skeleton, &mut self.held, &post.ik, ChainStart::Cold, &mut self.reports);
        self.settle(post, clock);
    }

    /// The springs run on to `clock` on the last tick's pose (a paused
    /// stream: the pose holds, the chains keep settling).
    pub fn settle(&mut self, post: &GraphPost, clock: f64) {
        self.pose.copy_from(&self.held);
        let (Some(springs), Some(solver)) = (post.springs.as_ref(), self.springs.as_mut()) else { return };
        let held = &self.held;
        solver.frame(springs, clock, &mut self.pose, |_, p| p.copy_from(held));
    }

    /// The last tick's pose after the stages.
    pub fn pose(&self) -> &Pose {
        &self.pose
    }

    /// The last tick's IK reports, one per constraint.
    pub fn ik_reports(&self) -> &[IkReport] {
        &self.reports
    }
}
