//! What work costs, in work units (docs/api.md, “Work and its price”),
//! worked out from counts a request, clip or motion already holds — joints,
//! layers, constraints, iteration budgets, the answer's size bound — before
//! any of it runs, so refusing is cheaper than a pose.
//!
//! One unit is one joint of one layer sampled: about [`NS_PER_UNIT`]
//! nanoseconds of one core on the machine of BENCHMARKS.md. The other kinds
//! of work are weighted in that unit from their measured cost there (the
//! table in BENCHMARKS.md holds each price against its measured CPU time):
//! an analytic IK solve walks the joint's ancestry; a chain solve pays its
//! whole iteration budget (whether it converges early cannot be known
//! before it runs) over every joint on the chain, for each effector; an
//! answer pays per byte of its size bound, more per byte when compressed.

use anim::ik::IkConstraint;
use anim::{Clip, Skeleton};

use crate::stream::StreamMotion;

/// Nanoseconds of one core a work unit stands for (measured; BENCHMARKS.md).
pub const NS_PER_UNIT: u64 = 10;

/// Units per joint of a layer: sampling it, and its share of layering and
/// of the conversion to the answer's space.
const JOINT: u64 = 1;
/// Units of one analytic solve (two-bone, aim), besides its ancestry.
const ANALYTIC: u64 = 4;
/// Units per joint of the ancestry an analytic solve walks to model space.
const ANALYTIC_PER_JOINT: u64 = 1;
/// Units of one chain iteration, per joint on the chain and per effector.
const CHAIN_STEP: u64 = 15;
/// Bytes of an answer's size bound encoded per unit.
const BYTES_PER_UNIT: u64 = 8;

/// Units of one broadcast tick besides its pose and frame: waking on its
/// timer, filing its controls, publishing (measured on the producers'
/// thread; BENCHMARKS.md). Without it a one-joint broadcast looked free.
pub const BROADCAST_TICK: u64 = 500;

/// The work of one pose of `clip` alone: its joints, its keyed IK.
pub fn clip_pose(clip: &Clip) -> u64 {
    (clip.joint_count() as u64 * JOINT).saturating_add(ik(clip.ik_constraints(), clip.skeleton()))
}

/// The work of one pose of a motion: every layer's clip (its joints and
/// its own IK), then the motion's constraints on the output skeleton.
pub fn motion_pose(motion: &StreamMotion) -> u64 {
    let layers = motion.layers().map(|c| clip_pose(c.clip())).fold(0, u64::saturating_add);
    layers.saturating_add(ik(motion.ik(), motion.skeleton()))
}

/// The work of solving `constraints` once on `skeleton` (validated
/// against it: every joint exists).
pub fn ik(constraints: &[IkConstraint], skeleton: &Skeleton) -> u64 {
    let mut marks = Vec::new();
    let each = constraints.iter().map(|c| match c {
        IkConstraint::TwoBone(c) => ANALYTIC + ANALYTIC_PER_JOINT * depth(skeleton, c.joints[2]),
        IkConstraint::Aim(c) => ANALYTIC + ANALYTIC_PER_JOINT * depth(skeleton, c.joint),
        IkConstraint::Chain(c) => {
            let joints = chain_joints(skeleton, c.effectors.iter().map(|e| e.joint), &mut marks);
            let per_iteration = joints.saturating_mul(c.effectors.len() as u64).saturating_mul(CHAIN_STEP);
            u64::from(c.max_iterations.max(1)).saturating_mul(per_iteration)
        }
    });
    each.fold(0, u64::saturating_add)
}

/// The work of encoding an answer of at most `bytes` bytes.
pub fn encoding(bytes: u64) -> u64 {
    bytes.div_ceil(BYTES_PER_UNIT)
}

/// The work of compressing `bytes` bytes at `level` (0 none; a level costs
/// roughly one more encoding pass per step). For answer and frame
/// compression to charge on top of an answer's price.
#[allow(dead_code)]
pub fn compression(bytes: u64, level: u32) -> u64 {
    encoding(bytes).saturating_mul(u64::from(level))
}

/// Joints from `joint` up to its root, itself included.
fn depth(skeleton: &Skeleton, joint: usize) -> u64 {
    std::iter::successors(Some(joint), |&j| skeleton.parent(j)).count() as u64
}

/// Joints on the paths from the effectors up to the roots, each counted
/// once (a chain solve's forward kinematics runs over them): each walk
/// stops where an earlier one passed.
fn chain_joints(skeleton: &Skeleton, effectors: impl Iterator<Item = usize>, marks: &mut Vec<u64>) -> u64 {
    marks.clear();
    marks.resize(skeleton.len().div_ceil(64), 0);
    let mut count = 0;
    for effector in effectors {
        let mut next = Some(effector);
        while let Some(j) = next {
            let (word, bit) = (j / 64, 1u64 << (j % 64));
            if marks[word] & bit != 0 {
                break;
            }
            marks[word] |= bit;
            count += 1;
            next = skeleton.parent(j);
        }
    }
    count
}
