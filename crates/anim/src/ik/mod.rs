//! Inverse kinematics (docs/ik.md): "specify where the character should go,
//! then deduce joint motion" (seed 003).
//!
//! Constraints ([`IkConstraint`]: `two_bone`, `aim`, `chain`) are checked
//! once by [`IkConstraint::validate`]; an [`IkSolver`] then applies a list
//! of them in order to a local pose, with targets in model space. Only
//! rotations change; positions are model positions, scales included
//! (docs/clip-format.md, “Skeleton and spaces”). Each constraint's solved rotations are
//! `slerp`ed from the unsolved ones by its weight, and each writes an
//! [`IkReport`] (`residual`: the end joint's distance to its target, the
//! aim angle, or `√E`).
//!
//! Solves are deterministic and, once an [`IkSolver`] has seen a list of
//! the same shape, allocate nothing. A stream keeps one solver and asks for
//! [`ChainStart::Warm`] so each chain starts from the previous frame's
//! angles.
//!
//! Module map: `spec` constraints as authored (joint names) and their
//! resolution; `constraint` the constraint types and their validation;
//! `error` why one is refused; `keyed` IK keyed in clips (target and
//! weight tracks); `model` model space along one ancestry and
//! the shared rotation tools; `two_bone`, `aim`, `chain` the three solvers;
//! `linalg` the chain's small `f64` systems; `stop` the flag that ends
//! chain solves early when their caller has given up.

mod aim;
mod chain;
mod constraint;
mod error;
mod keyed;
mod linalg;
pub(crate) mod model;
mod report;
mod spec;
mod stop;
mod two_bone;

pub use self::aim::AIM_TOLERANCE;
pub use self::chain::DEFAULT_RELATIVE_TOLERANCE;
pub use self::constraint::{
    Aim, Chain, DEFAULT_MAX_ITERATIONS, Effector, IkConstraint, IkKind, IkLimits, JointLimits, TwoBone,
    validate_constraints,
};
pub use self::error::{IkError, IkErrorKind};
pub(crate) use self::keyed::KeyedIk;
pub use self::keyed::KeyedIkState;
pub use self::report::IkReport;
pub use self::spec::{AimSpec, ChainSpec, EffectorSpec, IkSpec, LimitSpec, TwoBoneSpec, build_constraints};
pub use self::stop::stoppable;
pub use self::two_bone::TWO_BONE_TOLERANCE;

use self::chain::{ChainSolver, WarmChain};
use super::{Pose, Skeleton};

/// Where chain solves start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ChainStart {
    /// From the animated pose (`a = 0`): the same request, the same answer.
    #[default]
    Cold,
    /// From this solver's last angles for the chain at the same place in
    /// the list, when it moved the same joints (else cold).
    Warm,
}

/// Applies constraint lists to poses, keeping its buffers (and each
/// chain's last angles) between calls.
#[derive(Debug, Clone, Default)]
pub struct IkSolver {
    /// The ancestry an analytic solver walks.
    path: Vec<usize>,
    chain: ChainSolver,
    /// Per constraint index: a chain's last angles (empty for other kinds).
    warm: Vec<WarmChain>,
}

impl IkSolver {
    /// A solver with no buffers yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Applies `constraints` in order to `local` and writes one report per
    /// constraint into `reports` (cleared first).
    ///
    /// # Panics
    /// If a constraint names a joint `skeleton` does not have: validate
    /// constraints against the skeleton first ([`validate_constraints`]).
    pub fn solve(
        &mut self,
        skeleton: &Skeleton,
        local: &mut Pose,
        constraints: &[IkConstraint],
        start: ChainStart,
        reports: &mut Vec<IkReport>,
    ) {
        if self.warm.len() < constraints.len() {
            self.warm.resize_with(constraints.len(), WarmChain::default);
        }
        reports.clear();
        for (constraint, warm) in constraints.iter().zip(&mut self.warm) {
            let report = match constraint {
                IkConstraint::TwoBone(c) => two_bone::solve(c, skeleton, local, &mut self.path),
                IkConstraint::Aim(c) => aim::solve(c, skeleton, local, &mut self.path),
                IkConstraint::Chain(c) => self.chain.solve(c, skeleton, local, warm, start == ChainStart::Warm),
            };
            if report.kind != IkKind::Chain {
                warm.joints.clear();
                warm.angles.clear();
            }
            reports.push(report);
        }
    }

    /// The angles the last solve found for the chain at `index` in its
    /// list, with the joints they belong to (three angles per joint, in
    /// radians, before weighting); `None` if that was not a chain or it
    /// moved no joint.
    pub fn chain_angles(&self, index: usize) -> Option<(&[usize], &[f32])> {
        let warm = self.warm.get(index)?;
        (!warm.joints.is_empty() || !warm.angles.is_empty()).then_some((&warm.joints, &warm.angles))
    }

    /// Every constraint's warm start, in list order (empty for one that is
    /// not a chain): what the next [`ChainStart::Warm`] solve starts from.
    pub fn warm_starts(&self) -> Vec<WarmStart> {
        self.warm.iter().map(|w| WarmStart { joints: w.joints.clone(), angles: w.angles.clone() }).collect()
    }

    /// Puts back warm starts [`IkSolver::warm_starts`] took, so the next
    /// warm solve is the one the solver they came from would have made.
    pub fn set_warm_starts(&mut self, starts: Vec<WarmStart>) {
        self.warm = starts.into_iter().map(|w| WarmChain { joints: w.joints, angles: w.angles }).collect();
    }
}

/// A chain's last solved angles (three per joint, radians), with the joints
/// they belong to: what a warm start carries from one solve to the next.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WarmStart {
    pub joints: Vec<usize>,
    pub angles: Vec<f32>,
}
