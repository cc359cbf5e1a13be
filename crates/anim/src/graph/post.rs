//! What a motion over a graph runs on the graph's pose (docs/graphs.md,
//! “What composes with a graph”): its clip layers, if it has any beside the
//! graph's — an ordinary [`Motion`] whose layer at the graph's place is
//! handed the graph's pose instead of a clip sample, at the tick's motion
//! time — then its IK constraints, then its spring chains, built by the
//! motion's own [`post_stages`](crate::motion) and run by the same IK
//! solver and spring solver a motion uses.
//!
//! A graph is played tick by tick, never at an arbitrary time, so two rules
//! differ from a motion's: IK solves each tick from the graph's pose alone
//! (cold), so a stream's tick is a sampling request's; and the spring
//! substeps between two ticks see the later tick's pose (the pose held
//! from one tick to the next), not the motion at the substep's own time.

use std::sync::Arc;

use super::ticks::due_tick;
use super::{Graph, GraphPlayer, TickRange};
use crate::ik::{ChainStart, IkConstraint, IkLimits, IkReport, IkSolver, IkSpec};
use crate::motion::{ClipSource, External, Motion, MotionSampler, MotionSpec, post_stages};
use crate::spring::{DEFAULT_WARMUP, SpringSolver, SpringState, Springs, SpringsSpec, StateMismatch, warmup_start};
use crate::{MotionError, Path, Pose, Skeleton};

/// A graph's post stages as built: the clip layers around it, and IK
/// constraints and spring chains on the output skeleton.
#[derive(Debug, Clone)]
pub struct GraphPost<C> {
    mix: Option<Arc<Motion<C>>>,
    ik: Vec<IkConstraint>,
    springs: Option<Springs>,
}

impl<C> Default for GraphPost<C> {
    fn default() -> Self {
        GraphPost { mix: None, ik: Vec::new(), springs: None }
    }
}

impl<C: ClipSource + Clone> GraphPost<C> {
    /// The stages of a motion whose layer `at` is `graph` (its clip there
    /// is replaced by the graph's own first clip, which lends the
    /// parameters' layout) beside clip layers: those layers as a motion
    /// whose layer `at` is handed the graph's pose (weight, mask and mode
    /// as a clip of the graph's skeleton; an additive graph layer measured
    /// from the graph's first tick with every parameter at its default),
    /// then the spec's IK and springs on that motion's output skeleton.
    /// The spec's `root_motion` is not read (a caller refuses it: the
    /// graph's nodes carry the root motion).
    ///
    /// # Errors
    /// As [`Motion::build_limited`] (paths `layers/1/…`, `ik/0/…`,
    /// `springs/0/…`; a graph layer's own at `layers/i/graph`).
    pub fn mixed(
        mut spec: MotionSpec<C>,
        at: usize,
        graph: &Arc<Graph<C>>,
        limits: &IkLimits,
    ) -> Result<Self, MotionError> {
        let Some(layer) = spec.layers.get_mut(at) else {
            return Err(MotionError::new(Path::root().field("layers"), crate::motion::MotionErrorKind::NoLayers));
        };
        layer.clip = graph.initial_motion().first_clip().clone();
        let (ik, springs) = (std::mem::take(&mut spec.ik), std::mem::take(&mut spec.springs));
        spec.root_motion = None;
        let reference = reference_pose(graph);
        let external = External { layer: at, skeleton: graph.skeleton(), reference };
        let motion = Motion::build_external(spec, limits, Some(external))?;
        let (ik, springs) = post_stages(&ik, &springs, motion.skeleton(), limits)?;
        Ok(GraphPost { mix: Some(Arc::new(motion)), ik, springs })
    }
}

/// An additive graph layer's reference: the graph's first tick (its initial
/// state's node at node time 0) with every parameter at its default.
fn reference_pose<C: ClipSource>(graph: &Arc<Graph<C>>) -> Pose {
    let mut player = GraphPlayer::new(Arc::clone(graph));
    player.tick(0.0);
    player.pose().clone()
}

impl<C> GraphPost<C> {
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
    ) -> Result<GraphPost<C>, MotionError> {
        let (ik, springs) = post_stages(ik, springs, skeleton, limits)?;
        Ok(GraphPost { mix: None, ik, springs })
    }

    /// Whether there is nothing to run: the graph's pose is the answer.
    pub fn is_empty(&self) -> bool {
        self.mix.is_none() && self.ik.is_empty() && self.springs.is_none()
    }

    /// The clip layers with the graph's among them, if the motion has any
    /// beside it.
    pub fn mix(&self) -> Option<&Arc<Motion<C>>> {
        self.mix.as_ref()
    }

    /// The skeleton the stages' poses are of: the mix's output skeleton
    /// (its first layer's, or the character's), else `graph`'s.
    pub fn skeleton<'a>(&'a self, graph: &'a Skeleton) -> &'a Skeleton
    where
        C: ClipSource,
    {
        self.mix.as_ref().map_or(graph, |m| m.skeleton())
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
    /// The clip layers' sampler and their sync phases at the tick's time.
    mixer: MotionSampler,
    phases: Vec<f64>,
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
    pub fn new<C>(post: &GraphPost<C>) -> Self {
        PostRun { springs: post.springs.as_ref().map(SpringSolver::new), ..PostRun::default() }
    }

    /// At a spring state a run of `post` gave (a broadcast checkpoint's).
    ///
    /// # Errors
    /// A state that is not one entry per turning joint, or a state for
    /// springs `post` has not (or none for springs it has).
    pub fn from_state<C>(post: &GraphPost<C>, state: Option<SpringState>) -> Result<Self, StateMismatch> {
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
    pub fn skip_springs_to<C>(&mut self, post: &GraphPost<C>, clock: f64) {
        if let (Some(springs), Some(solver)) = (post.springs.as_ref(), self.springs.as_mut()) {
            solver.skip_to(springs, clock);
        }
    }

    /// The springs' state (none without springs).
    pub fn spring_state(&self) -> Option<SpringState> {
        self.springs.as_ref().map(SpringSolver::state)
    }

    /// Runs the stages on `pose`, the graph's pose of the tick at motion
    /// time `tau`, with the springs' time at `clock`: the clip layers at
    /// `tau` (their sync phases at the motion's weights, from `tau` alone)
    /// with the graph's pose at its place, IK solved from that, then the
    /// spring substeps up to `clock`, each on that pose. A `clock` the
    /// springs have passed runs no substep and shows their last rotations
    /// (a restored run). `skeleton` is the graph's.
    pub fn run<C: ClipSource>(
        &mut self,
        post: &GraphPost<C>,
        skeleton: &Skeleton,
        pose: &Pose,
        (tau, clock): (f64, f64),
    ) {
        match &post.mix {
            Some(mix) => {
                mix.phases_at(tau, mix.weights(), &mut self.phases);
                mix.sample_external(tau, (&self.phases, mix.weights()), pose, &mut self.mixer);
                self.held.copy_from(self.mixer.local());
            }
            None => self.held.copy_from(pose),
        }
        let skeleton = post.skeleton(skeleton);
        self.ik.solve(skeleton, &mut self.held, &post.ik, ChainStart::Cold, &mut self.reports);
        self.settle(post, clock);
    }

    /// The springs run on to `clock` on the last tick's pose (a paused
    /// stream: the pose holds, the chains keep settling).
    pub fn settle<C>(&mut self, post: &GraphPost<C>, clock: f64) {
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
