//! What a solve says about itself: one [`IkReport`] per constraint.

use super::constraint::IkKind;

/// How one constraint's solve went (docs/ik.md, “Reports”: `{kind,
/// residual, iterations, converged}`), measured on the pose written, weight
/// included (except `aim` by the smallest rotation at full weight, whose
/// `f32` arc is exact to rounding: it reports 0). Analytic solvers report 0 iterations; `two_bone` converges
/// when the end meets the target within [`TWO_BONE_TOLERANCE`](super::TWO_BONE_TOLERANCE)·(l1 + l2),
/// `aim` within [`AIM_TOLERANCE`](super::AIM_TOLERANCE) rad, `chain` when `√E ≤ tolerance`
/// before weighting.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkReport {
    pub kind: IkKind,
    pub residual: f32,
    pub iterations: u32,
    pub converged: bool,
}
