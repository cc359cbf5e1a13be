//! Secondary motion (docs/springs.md): spring chains — tails, ears, hair,
//! cloth strips — swinging on top of the animated pose, with VRM 1.0's
//! spring bone integration run on a fixed substep grid.
//!
//! [`SpringsSpec`] (chains by joint name, unchecked) → [`Springs::build`]
//! against a skeleton (every rule checked once) → a [`SpringSolver`] that
//! carries the simulation from frame to frame. A frame hands the solver
//! the animated local pose of its time (after layering, root motion and
//! IK) and a way to evaluate the motion at any other time; the solver runs
//! every substep `k·h` (`h = 1/substep_hz`) the frame's time has passed,
//! each on the motion evaluated at that substep's own time, and writes the
//! turning joints' local rotations into the frame's pose (their own
//! rotation keys are ignored, as in VRM). So a frame's pose depends on the
//! substep grid and the motion only, never on the frame rate.
//!
//! Nothing here allocates once the solver's buffers have their size (its
//! state is sized by [`SpringSolver::new`]; the pose buffer on first use).
//! The state is plain values ([`SpringState`]); a solver made again from
//! it steps on bit for bit as the one it was taken from.
//!
//! Module map: `spec` the authoring form and its defaults; `error` why a
//! chain is refused; `build` the checks and the layout of the substep loop;
//! `step` one substep.

mod build;
mod error;
mod spec;
mod step;

use glam::{Quat, Vec3A};

pub use self::build::Springs;
pub use self::error::{SpringError, SpringErrorKind};
pub use self::spec::{
    ChainSpec, ColliderShape, ColliderSpec, DEFAULT_SUBSTEP_HZ, DEFAULT_WARMUP, JointParams, MAX_CHAINS, MAX_COLLIDERS,
    SUBSTEP_HZ_RANGE, SpringParams, SpringsSpec,
};

use self::step::{Pass, Placed, Tails};
use crate::Pose;
use crate::ik::model::Xform;

/// A substep's grid time counts as passed by a frame up to this long after
/// the frame's time, so a frame time computed with rounding (`n / fps`)
/// still takes the substep it lands on.
pub const GRID_TOLERANCE: f64 = 1e-9;

/// Everything a [`SpringSolver`] carries from one frame to the next, as
/// plain values (a broadcast checkpoint). Per turning joint, in joint order.
#[derive(Debug, Clone, PartialEq)]
pub struct SpringState {
    /// The index `k` of the next substep to run (grid time `k / hz`);
    /// `None`: at rest, and the next frame starts the chains from it.
    pub next: Option<i64>,
    /// The tail points now and one substep before, in model space.
    pub current: Vec<Vec3A>,
    pub previous: Vec<Vec3A>,
    /// The local rotations the last substep gave the turning joints.
    pub rotations: Vec<Quat>,
}

/// Why a [`SpringState`] does not fit the springs it was given to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StateMismatch {
    pub expected: usize,
    pub provided: usize,
}

impl std::fmt::Display for StateMismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "a spring state of {} joints for springs of {}", self.provided, self.expected)
    }
}

impl std::error::Error for StateMismatch {}

/// Runs one [`Springs`] from frame to frame; see the module doc.
#[derive(Debug, Clone)]
pub struct SpringSolver {
    state: SpringState,
    model: Vec<Xform>,
    placed: Vec<Placed>,
    /// The motion at a substep's time.
    input: Pose,
}

impl SpringSolver {
    /// A solver at rest for `springs`, its buffers sized.
    pub fn new(springs: &Springs) -> Self {
        let bones = springs.bones.len();
        let state = SpringState {
            next: None,
            current: vec![Vec3A::ZERO; bones],
            previous: vec![Vec3A::ZERO; bones],
            rotations: springs.bones.iter().map(|b| b.rest).collect(),
        };
        SpringSolver {
            state,
            model: vec![Xform::IDENTITY; springs.links.len()],
            placed: vec![Placed::NOWHERE; springs.colliders.len()],
            input: Pose::identity(springs.joints),
        }
    }

    /// Back to rest: the next frame shows the rest pose of the turning
    /// joints and the simulation starts from it (a seek, `reset_springs`).
    pub fn reset(&mut self) {
        self.state.next = None;
    }

    /// The state, to hand to [`SpringSolver::from_state`].
    pub fn state(&self) -> SpringState {
        self.state.clone()
    }

    /// A solver in `state`: its next frame is the one the solver the
    /// state was taken from would have made.
    ///
    /// # Errors
    /// The state's lists are not one entry per turning joint of `springs`.
    pub fn from_state(springs: &Springs, state: SpringState) -> Result<Self, StateMismatch> {
        let expected = springs.bones.len();
        for provided in [state.current.len(), state.previous.len(), state.rotations.len()] {
            if provided != expected {
                return Err(StateMismatch { expected, provided });
            }
        }
        Ok(SpringSolver { state, ..SpringSolver::new(springs) })
    }

    /// The substeps at or before `time` not run yet are never run: the
    /// chains go on from where they were, as if that time had not passed
    /// (a stream frame woken late catches up a bounded span only).
    pub fn skip_to(&mut self, springs: &Springs, time: f64) {
        if let Some(k) = self.state.next.as_mut() {
            *k = (*k).max(first_after(springs.hz, time));
        }
    }

    /// How many substeps a frame at `time` would run now (for pricing).
    pub fn pending(&self, springs: &Springs, time: f64) -> u64 {
        match self.state.next {
            None => 0,
            Some(k) => (first_after(springs.hz, time) - k).max(0) as u64,
        }
    }

    /// Starts the chains at rest at `time`, placed on `pose` (the animated
    /// local pose of `time`): a stateless pose or samples request calls it
    /// at [`warmup_start`] with the motion's pose there.
    ///
    /// # Panics
    /// If `pose` has fewer joints than the skeleton `springs` was built on.
    pub fn start_at(&mut self, springs: &Springs, time: f64, pose: &Pose) {
        self.pass(springs, pose, Pass::Rest);
        self.state.next = Some(first_after(springs.hz, time));
    }

    /// The frame at `time`: runs every substep whose grid time is after
    /// the last one run and not after `time` (each on `pose_at(t, buffer)`,
    /// the motion's local pose at `t`, or on `pose` itself when `t` is
    /// `time`), then writes the turning joints' rotations into `pose`, the
    /// animated local pose of `time`. A solver at rest starts at `time`
    /// and the frame shows the rest rotations. A `time` before the last
    /// frame's runs nothing.
    ///
    /// # Panics
    /// If a pose has fewer joints than the skeleton `springs` was built on.
    pub fn frame(&mut self, springs: &Springs, time: f64, pose: &mut Pose, mut pose_at: impl FnMut(f64, &mut Pose)) {
        if springs.bones.is_empty() {
            return;
        }
        match self.state.next {
            None => self.start_at(springs, time, pose),
            Some(mut k) => {
                let last = first_after(springs.hz, time);
                while k < last {
                    let t = grid_time(springs.hz, k);
                    if t == time {
                        self.pass(springs, pose, Pass::Step);
                    } else {
                        let mut input = std::mem::take(&mut self.input);
                        pose_at(t, &mut input);
                        self.pass(springs, &input, Pass::Step);
                        self.input = input;
                    }
                    k += 1;
                }
                self.state.next = Some(k);
            }
        }
        for (&j, &r) in springs.bone_joints.iter().zip(&self.state.rotations) {
            pose.rotations[j as usize] = r;
        }
    }

    /// Stateless frames at `times` (in order): the chains start at rest at
    /// `from` ([`warmup_start`]) and one simulation runs through them;
    /// `each(i, pose)` receives frame `i`. Uses `pose_at` for every pose.
    pub fn run_from_rest(
        &mut self,
        springs: &Springs,
        from: f64,
        times: &[f64],
        mut pose_at: impl FnMut(f64, &mut Pose),
        mut each: impl FnMut(usize, &Pose),
    ) {
        let mut frame = Pose::default();
        pose_at(from, &mut frame);
        self.start_at(springs, from, &frame);
        for (i, &t) in times.iter().enumerate() {
            pose_at(t, &mut frame);
            self.frame(springs, t, &mut frame, &mut pose_at);
            each(i, &frame);
        }
    }

    fn pass(&mut self, springs: &Springs, pose: &Pose, pass: Pass) {
        let s = &mut self.state;
        let tails = Tails { current: &mut s.current, previous: &mut s.previous, rotations: &mut s.rotations };
        step::run(springs, pose, &mut self.model, &mut self.placed, tails, pass);
    }
}

/// Where a stateless request's simulation starts: `warmup` seconds before
/// its first time, but not before the motion's `start`.
pub fn warmup_start(start: f64, first: f64, warmup: f64) -> f64 {
    (first - warmup).max(start)
}

/// Grid time of substep `k`.
#[inline]
fn grid_time(hz: f64, k: i64) -> f64 {
    k as f64 / hz
}

/// The first substep whose grid time is after `time` (beyond the
/// tolerance): the substeps before it are the ones `time` has passed.
fn first_after(hz: f64, time: f64) -> i64 {
    let limit = time + GRID_TOLERANCE;
    let mut k = (limit * hz).floor() as i64;
    while grid_time(hz, k) <= limit {
        k += 1;
    }
    while grid_time(hz, k - 1) > limit {
        k -= 1;
    }
    k
}
