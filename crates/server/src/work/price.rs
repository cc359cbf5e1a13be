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
//! answer pays per byte of its size bound, more per byte when compressed;
//! a clip build pays per key value it checks and compiles, and a bound on
//! its constant-speed tables; a motion build pays per joint each layer maps
//! by name, and an additive layer the pose it samples for its reference.

use std::sync::Arc;

use anim::ik::IkConstraint;
use anim::motion::{LayerMode, MotionSpec};
use anim::spring::{DEFAULT_WARMUP, SpringsSpec, warmup_start};
use anim::{Clip, ClipSpec, Skeleton, Speed};

use crate::stream::{MAX_CATCH_UP, PinnedClip, StreamMotion};

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
/// Units per key value component a clip build checks and compiles (a
/// rotation key is four, a parameter row its width).
const BUILD_PER_VALUE: u64 = 1;
/// Units per joint and per track of a clip build (names, the skeleton,
/// the track lists), besides its keys.
const BUILD_PER_NAME: u64 = 8;
/// Units per segment of a constant-speed track: its arc-length table, at
/// most `max_build_work` for the whole clip (the core's build unit is
/// about [`CORE_BUILD_NS`] nanoseconds).
const ARC_SEGMENT: u64 = 100_000;
/// Nanoseconds of one unit of the core's build work (`Clip::build_work`).
const CORE_BUILD_NS: u64 = 25;
/// Units per byte of a document read (JSON parsed, checked, converted).
const PARSE_PER_BYTE: u64 = 1;
/// Bytes of an imported file per unit.
const IMPORT_BYTES_PER_UNIT: u64 = 4;
/// Units per turning joint of one spring substep: its Verlet step, length
/// and turn, and its share of placing the free joints above the chains
/// (about 80–100 ns; BENCHMARKS.md, “Springs”).
const SPRING_JOINT: u64 = 10;
/// Units per collider test of one spring substep (each turning joint
/// against each collider of its chain).
const SPRING_TEST: u64 = 1;
/// Joints of a whole pose copied per unit: a joint is 48 bytes, about 5
/// instructions to copy (BENCHMARKS.md, “Springs”), so 4 take well under
/// a unit's 10 ns.
const JOINTS_PER_COPY: u64 = 4;
/// Units per joint of each layer a motion build maps by name, and per
/// output joint its mask resolves.
const MOTION_PER_JOINT: u64 = 6;

/// The work of one pose of `clip` alone: its joints, its keyed IK.
pub fn clip_pose(clip: &Clip) -> u64 {
    (clip.joint_count() as u64 * JOINT).saturating_add(ik(clip.ik_constraints(), clip.skeleton()))
}

/// The work of one pose of a motion: every layer's clip (its joints and
/// its own IK), then the motion's constraints on the output skeleton.
pub fn motion_pose(motion: &StreamMotion) -> u64 {
    let layers = motion.layers().map(|c| clip_pose(c.clip())).fold(0, u64::saturating_add);
    layers.saturating_add(ik(motion.ik(), motion.skeleton())).saturating_add(retargets(motion))
}

/// One substep: the pose at its time, then `joints` integrations and
/// `tests` collider tests.
fn substep(pose: u64, (joints, tests): (usize, usize)) -> u64 {
    let chains =
        (joints as u64).saturating_mul(SPRING_JOINT).saturating_add((tests as u64).saturating_mul(SPRING_TEST));
    pose.saturating_add(chains)
}

/// Substeps one frame at `fps` runs at most.
fn substeps_per_frame(hz: f64, fps: u32) -> u64 {
    (hz / f64::from(fps.max(1))).ceil() as u64
}

/// The work of one stream frame of `motion` at `fps` ([`stream_frame`]).
pub fn motion_frame(motion: &StreamMotion, fps: u32) -> u64 {
    stream_frame(&[motion], 0, fps)
}

/// A stream frame's share of the ticks frames woken late catch up: `tick`
/// units a late frame runs again for each tick it skipped, at most
/// [`MAX_CATCH_UP`] of them, and each tick once at most, so a second of
/// playback runs at most `fps + MAX_CATCH_UP` ticks' worth: each of its
/// `fps` frames pays `MAX_CATCH_UP / fps` of a tick more.
pub fn catch_up(tick: u64, fps: u32) -> u64 {
    tick.saturating_mul(MAX_CATCH_UP).div_ceil(u64::from(fps.max(1)))
}

/// The work of one frame at `fps` of a stream whose decks play `motions`
/// (the one playing last), with `ik` units of the stream's own IK: a
/// broadcast tick's ([`broadcast_frame`]), and the catch-up of its spring
/// substeps ([`catch_up`]): a frame woken late runs the substeps of the
/// ticks it skipped.
pub fn stream_frame(motions: &[&StreamMotion], ik: u64, fps: u32) -> u64 {
    let (mix, springs) = frame_parts(motions, ik, fps);
    mix.saturating_add(springs).saturating_add(catch_up(springs, fps))
}

/// The work of one broadcast tick at `fps` (every tick stepped once, none
/// caught up) of decks playing `motions`, with `ik` units of its own IK.
pub fn broadcast_frame(motions: &[&StreamMotion], ik: u64, fps: u32) -> u64 {
    let (mix, springs) = frame_parts(motions, ik, fps);
    mix.saturating_add(springs)
}

/// One tick's mix and its spring substeps: every deck's pose and the IK on
/// their mix, then the playing motion's substeps (`⌈hz / fps⌉`), each of
/// which evaluates that whole mix again at its own time (docs/springs.md,
/// “Time”: a crossfade's substeps see every motion fading).
fn frame_parts(motions: &[&StreamMotion], ik: u64, fps: u32) -> (u64, u64) {
    let mix = motions.iter().map(|m| motion_pose(m)).fold(ik, u64::saturating_add);
    let Some(springs) = motions.last().and_then(|top| top.springs()) else { return (mix, 0) };
    let substeps = substeps_per_frame(springs.substep_hz(), fps);
    (mix, substeps.saturating_mul(substep(mix, springs.substep_work())))
}

/// The work of one frame of a clip stream at `fps`: the clip's pose, and
/// its spring chains' substeps (`springs`, checked against its skeleton)
/// with their catch-up ([`catch_up`]).
pub fn clip_frame(clip: &Clip, springs: &SpringsSpec, fps: u32) -> u64 {
    let pose = clip_pose(clip);
    let joints: usize = springs.chains.iter().map(|c| c.joints.len().saturating_sub(1)).sum();
    let tests = springs.chains.iter().map(|c| c.joints.len().saturating_sub(1) * c.colliders.len()).sum();
    let substeps = if joints == 0 { 0 } else { substeps_per_frame(springs.substep_hz, fps) };
    let chains = substeps.saturating_mul(substep(pose, (joints, tests)));
    pose.saturating_add(chains).saturating_add(catch_up(chains, fps))
}

/// The work of one substep of a stateless request (docs/springs.md,
/// “Cost”): the motion sampled at the joints the chains read
/// ([`warmup_pose`]), then the chains' integration and collider tests.
/// 0 without springs.
pub fn warmup_substep(motion: &StreamMotion) -> u64 {
    let Some(springs) = motion.springs() else { return 0 };
    substep(warmup_pose(motion, springs), springs.substep_work())
}

/// The motion's pose as a stateless request's substep samples it: with
/// the motion's own IK (which reads whole chains), the whole pose; else
/// each layer at the joints the chains read (`Springs::reads`), and its
/// root-motion joint, at most its clip's joints (a layer whose clip has
/// keyed IK, or that is retargeted, whole, with its retarget), and per
/// [`JOINTS_PER_COPY`] joints of each clip and of the output one unit: the
/// whole poses copied (a clip's base, the rest under the layers, the
/// substep's input). Never more than the whole pose, whose price covers
/// those copies.
fn warmup_pose(motion: &StreamMotion, springs: &anim::spring::Springs) -> u64 {
    if !motion.ik().is_empty() {
        return motion_pose(motion);
    }
    let reads = springs.reads().iter().map(|w| u64::from(w.count_ones())).sum::<u64>();
    let root = u64::from(motion.has_root_motion());
    let layer = |(i, clip): (usize, &Arc<dyn PinnedClip>)| {
        let clip = clip.clip();
        let joints = clip.joint_count() as u64;
        let sampled = if motion.is_retargeted(i) || clip.ik_count() > 0 {
            clip_pose(clip)
        } else {
            (reads + root).min(joints).saturating_mul(JOINT)
        };
        sampled.saturating_add(joints.div_ceil(JOINTS_PER_COPY))
    };
    let layers = motion.layers().enumerate().map(layer).fold(0, u64::saturating_add);
    let output = (motion.skeleton().len() as u64).div_ceil(JOINTS_PER_COPY);
    let cut = layers.saturating_add(output).saturating_add(retargets(motion));
    cut.min(motion_pose(motion))
}

/// The work of the spring substeps of a stateless request at `times` (in
/// the order given): a simulation from rest `warmup` before its first time,
/// run through the times, started again wherever a time goes back; each
/// substep a [`warmup_substep`].
pub fn spring_run(motion: &StreamMotion, times: &[f64]) -> u64 {
    let Some(springs) = motion.springs() else { return 0 };
    let hz = springs.substep_hz();
    let mut seconds = 0.0f64;
    let mut last: Option<f64> = None;
    for &t in times {
        seconds += match last {
            Some(l) if t >= l => t - l,
            _ => t - warmup_start(t.min(0.0), t, DEFAULT_WARMUP),
        };
        last = Some(t);
    }
    let substeps = (seconds * hz).ceil() as u64 + times.len() as u64;
    substeps.saturating_mul(warmup_substep(motion))
}

/// The work of the retargets of one pose (docs/motion.md, “Characters”): per
/// retargeted layer, one model-space pass over its clip's skeleton and one
/// over the character's; per planted foot (docs/characters.md, “Planted
/// feet”), a two-bone solve as an IK constraint's, its chain as deep as the
/// character.
fn retargets(motion: &StreamMotion) -> u64 {
    let output = motion.skeleton().len() as u64;
    let each = motion.layers().enumerate().filter(|(i, _)| motion.is_retargeted(*i));
    let passes =
        each.map(|(_, c)| (c.clip().joint_count() as u64 + output).saturating_mul(JOINT)).fold(0, u64::saturating_add);
    let feet = (motion.planted_feet() as u64).saturating_mul(ANALYTIC + ANALYTIC_PER_JOINT * output);
    passes.saturating_add(feet)
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

/// The work of building the clip `spec` says, within `max_build_work`
/// units of the core's table work: every key value, every name, and for
/// constant-speed tracks their arc-length tables at their bound (how
/// soon a table converges cannot be known before it is built).
pub fn clip_build(spec: &ClipSpec, max_build_work: u64) -> u64 {
    let values = |keys: &anim::Keys| keys.len() as u64 * if matches!(keys, anim::Keys::Vec4(_)) { 4 } else { 3 };
    let tracks = spec.tracks.iter().map(|t| {
        let tangents = [&t.in_tangents, &t.out_tangents].into_iter().flatten().map(values).sum::<u64>();
        values(&t.values) + tangents
    });
    let parameters = spec.parameters.iter().map(|p| p.values.iter().map(|row| row.len() as u64).sum::<u64>());
    let values = tracks.chain(parameters).fold(0, u64::saturating_add);
    let segments = (spec.tracks.iter())
        .filter(|t| t.speed == Speed::Constant)
        .map(|t| t.times.len().saturating_sub(1) as u64)
        .fold(0, u64::saturating_add);
    let arc_ns = segments.saturating_mul(ARC_SEGMENT).min(max_build_work).saturating_mul(CORE_BUILD_NS);
    let joints = spec.skeleton.as_ref().map_or(0, |s| s.joints.len() as u64);
    let names = (joints + spec.tracks.len() as u64 + spec.ik.len() as u64).saturating_mul(BUILD_PER_NAME);
    values.saturating_mul(BUILD_PER_VALUE).saturating_add(names).saturating_add(arc_ns / NS_PER_UNIT)
}

/// The work of building the motion `spec` says over its pinned clips:
/// each layer's joints mapped by name onto the output's, its mask
/// resolved, an additive layer's reference pose sampled, and its spring
/// chains compiled.
pub fn motion_build(spec: &MotionSpec<Arc<dyn PinnedClip>>) -> u64 {
    let Some(first) = spec.layers.first() else { return 0 };
    let output = spec.character.as_ref().map_or(first.clip.clip().joint_count(), |c| c.skeleton.len()) as u64;
    let each = spec.layers.iter().map(|layer| {
        let clip = layer.clip.clip();
        let map = (output + clip.joint_count() as u64 + clip.parameters().total_width() as u64) * MOTION_PER_JOINT;
        let reference = if layer.mode == LayerMode::Additive { clip.joint_count() as u64 * JOINT } else { 0 };
        let retarget = if spec.character.is_some() {
            let plants = layer.retarget.as_ref().unwrap_or(&spec.retarget).feet.is_some();
            retarget_setup(clip.joint_count() as u64, output, (plants, spec.root_motion.is_some()))
        } else {
            0
        };
        map + reference + retarget
    });
    // Spring chains compiled on the output skeleton: its names indexed, then
    // each chain joint and collider looked up and laid out.
    let chains = &spec.springs.chains;
    let springs = if chains.is_empty() {
        0
    } else {
        let named: u64 = chains.iter().map(|c| (c.joints.len() + c.colliders.len()) as u64).sum();
        (output + named) * MOTION_PER_JOINT
    };
    each.fold(springs, u64::saturating_add)
}

/// The work of reading a clip document of `bytes` bytes (JSON parsed,
/// checked and converted), before its build is priced.
pub fn parse(bytes: u64) -> u64 {
    bytes.saturating_mul(PARSE_PER_BYTE)
}

/// Units per test of a 2D blend's triangulation: one triple of points
/// against one point (its empty-circle test, a few products).
const TRIANGULATE_TEST: u64 = 1;

/// The work of building a graph (docs/graphs.md), once its clips are
/// found: every node built as a motion, each of its `layers` mapping the
/// `joints` of the graph's largest clip by name (a node naming another
/// counts that one's layers again, at most its bound), and every 2D blend
/// of `n` points triangulated by testing each of its `n³` triples against
/// each point, so a blend's price grows as `n⁴` (a 32-point one is about a
/// million units).
pub fn graph_build(
    node_layers: impl Iterator<Item = u64>,
    blend2d_points: impl Iterator<Item = u64>,
    joints: u64,
) -> u64 {
    let per_layer = joints.saturating_mul(2).saturating_mul(MOTION_PER_JOINT);
    let motions = node_layers.map(|layers| layers.saturating_mul(per_layer)).fold(0, u64::saturating_add);
    let triangulations =
        blend2d_points.map(|n| n.saturating_pow(4).saturating_mul(TRIANGULATE_TEST)).fold(0, u64::saturating_add);
    motions.saturating_add(triangulations)
}

/// The work of one tick of `graph` (docs/graphs.md, “Using a graph”): its
/// costliest tick's joint samples ([`anim::graph::Graph::tick_joint_samples`]),
/// whether or not the tick's pose is answered, since every tick is priced
/// at the bound.
/// On a character, each slot also pays its state's retargets as a clip
/// motion's pose does (the costliest state's, in every slot).
pub fn graph_tick(graph: &anim::graph::Graph<Arc<dyn PinnedClip>>) -> u64 {
    let retargets = graph.state_motions().map(|m| retargets(m)).max().unwrap_or(0);
    let slots = graph.max_slots() as u64;
    graph.tick_joint_samples().saturating_mul(JOINT).saturating_add(retargets.saturating_mul(slots))
}

/// The work of building a graph on a character of `output` joints, beyond
/// [`graph_build`]: each layer's retargeter set up as a clip motion's is
/// ([`retarget_setup`]), every layer over the graph's largest clip of
/// `joints`.
pub fn graph_retarget_setup(
    node_layers: impl Iterator<Item = u64>,
    joints: u64,
    output: u64,
    (feet, root): (bool, bool),
) -> u64 {
    let per_layer = retarget_setup(joints, output, (feet, root));
    node_layers.map(|layers| layers.saturating_mul(per_layer)).fold(0, u64::saturating_add)
}

/// The setup of one layer's retargeter from a clip of `joints` onto a
/// character of `output` joints: both references in model space and, with
/// `root` motion, the root's cycle at up to 4096 poses; with planted `feet`,
/// each source foot's lowest over up to 4096 poses.
fn retarget_setup(joints: u64, output: u64, (feet, root): (bool, bool)) -> u64 {
    let poses = if root { 4100 } else { 3 };
    let planted = if feet { 4100u64.saturating_mul(joints).saturating_mul(JOINT) } else { 0 };
    (joints + output).saturating_mul(poses * JOINT).saturating_add(planted)
}

/// The work a motion's clip layers, IK and springs add to one tick of a
/// graph played at `fps` (docs/graphs.md, “What composes with a graph”):
/// its clip layers' pose (each clip's joints, the graph's layer mixed in
/// as one of its first clip's), its constraints solved once on `skeleton`
/// (the output's), and the spring substeps a tick runs at most, each on the
/// tick's pose (a substep evaluates no pose of its own).
pub fn graph_post(post: &crate::built::PinnedPost, skeleton: &Skeleton, fps: f64) -> u64 {
    let layers = post.mix().map_or(0, |m| motion_pose(m));
    let solve = ik(post.ik(), skeleton).saturating_add(layers);
    let Some(springs) = post.springs() else { return solve };
    let substeps = (springs.substep_hz() / fps.max(1.0)).ceil() as u64;
    solve.saturating_add(substeps.saturating_mul(substep(0, springs.substep_work())))
}

/// The work of importing a file of `bytes` bytes (glTF, BVH): its reading
/// and the builds of the clips in it, whose sizes the file only tells once
/// read. Per byte of the file, less than a document's: an importer skips
/// what is not animation (meshes, images).
pub fn import(bytes: u64) -> u64 {
    bytes.div_ceil(IMPORT_BYTES_PER_UNIT)
}

/// Units per joint of a compact frame (docs/compact-frames.md): its
/// quantisation (the smallest-three rotation, ten channels) and its bits.
const COMPACT_PER_JOINT: u64 = 2;

/// The work of one compact frame of `joints` joints, besides the encoding
/// of its bytes.
pub fn compact_frame(joints: usize) -> u64 {
    (joints as u64).saturating_mul(COMPACT_PER_JOINT)
}

/// The work of choosing a compact layout: `samples` poses of a clip whose
/// pose costs `pose` units, each also widening the ranges.
pub fn compact_layout(samples: u64, pose: u64) -> u64 {
    samples.saturating_mul(pose.saturating_add(1))
}

/// The work of encoding an answer of at most `bytes` bytes.
pub fn encoding(bytes: u64) -> u64 {
    bytes.div_ceil(BYTES_PER_UNIT)
}

/// A content coding an answer is compressed in (`server::compression`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coding {
    Zstd,
    Br,
    Gzip,
}

/// How an answer is compressed: its coding at a level.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Compression {
    pub coding: Coding,
    pub level: i32,
}

/// The work of compressing `bytes` bytes as `compression` says (`None`:
/// sent as it is, free), from the nanoseconds per byte each coding and
/// level took in BENCHMARKS.md, “Compression”.
pub fn compression(compression: Option<Compression>, bytes: u64) -> u64 {
    let Some(Compression { coding, level }) = compression else { return 0 };
    // Nanoseconds per byte, rounded up.
    let ns_per_byte: u64 = match (coding, level) {
        (Coding::Zstd, ..=1) => 8,
        (Coding::Zstd, _) => 13,
        (Coding::Br, ..=1) => 14,
        (Coding::Br, 2..=4) => 90,
        (Coding::Br, _) => 5500,
        (Coding::Gzip, ..=1) => 10,
        (Coding::Gzip, _) => 39,
    };
    bytes.saturating_mul(ns_per_byte).div_ceil(NS_PER_UNIT)
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
