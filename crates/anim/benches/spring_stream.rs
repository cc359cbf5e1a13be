//! A stream's per-frame cost with and without springs (BENCHMARKS.md,
//! “Springs on a stream”), for counting instructions rather
//! than timing on a shared machine: the Fox's walk (`examples/gltf/Fox`,
//! imported at scale 0.01) played by a stream [`Player`] at 60 fps, plain
//! (`clip`) or with `examples/motions/fox-tail-springs.json`'s tail chain
//! (`springs`: three turning joints, two capsules, 120 Hz substeps, so two
//! substeps a frame, one of them evaluating the walk between the ticks).
//!
//! Prints the frames' time per frame and an FNV-1a hash of every bit of
//! every frame's local pose, so a change to the hot path can be checked to
//! leave the output alone. Not a criterion bench: one process per case.
//!
//! Run: `cargo bench -p inbetween-anim --bench spring_stream -- CASE [FRAMES]`
//! (`CASE`: `clip` or `springs`, or `pose`: that many stateless poses
//! with the tail's chain, each from rest; 600 frames by default); count with
//! `valgrind --tool=callgrind --toggle-collect='*Player*sample_clocked*'
//! target/release/deps/spring_stream-<hash> springs 600`, divided by the frames.

extern crate inbetween_anim as anim;

use std::sync::Arc;
use std::time::Instant;

use anim::motion::{LayerSpec, MotionOptions, MotionSpec, Player};
use anim::spring::{ChainSpec, ColliderShape, ColliderSpec, JointParams, SpringsSpec};
use anim::{Clip, Motion, Pose};
use formats::import::{Format, ImportOptions, import};
use glam::Vec3;

const FPS: u32 = 60;

/// The Fox's `Walk`, as the service imports it (`scale=0.01`).
fn walk() -> Clip {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/gltf/Fox/Fox.glb");
    let bytes = std::fs::read(path).expect("examples/gltf/Fox/Fox.glb");
    let options = ImportOptions { scale: 0.01, ..ImportOptions::default() };
    let spec = import(&bytes, Format::Glb, &options).expect("the Fox imports").clips;
    let walk = spec.into_iter().find(|c| c.name.ends_with("Walk")).expect("a Walk animation");
    Clip::build(&walk).expect("the walk builds")
}

/// `examples/motions/fox-tail-springs.json`'s chain.
fn tail() -> SpringsSpec {
    let capsule = |joint: &str| ColliderSpec {
        joint: joint.into(),
        shape: ColliderShape::Capsule { offset: Vec3::ZERO, tail: Vec3::new(0.19, 0.0, 0.0), radius: 0.04 },
    };
    let mut chain = ChainSpec::new("tail", &["b_Tail01_012", "b_Tail02_013", "b_Tail03_014"]);
    chain.params.stiffness = 0.8;
    chain.params.drag = 0.3;
    chain.params.gravity = Vec3::new(0.0, -9.81, 0.0);
    chain.params.radius = 0.03;
    chain.joint_params = vec![("b_Tail02_013".into(), JointParams { stiffness: Some(0.5), ..JointParams::default() })];
    chain.colliders = vec![capsule("b_LeftLeg01_015"), capsule("b_RightLeg01_019")];
    SpringsSpec { chains: vec![chain], substep_hz: 120.0 }
}

/// FNV-1a over every bit of `pose`.
fn hash(mut h: u64, pose: &Pose) -> u64 {
    let floats = pose.translations.iter().chain(&pose.scales).flat_map(|v| v.to_array());
    let rotations = pose.rotations.iter().flat_map(|q| q.to_array());
    for x in floats.chain(rotations) {
        for b in x.to_bits().to_le_bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
        }
    }
    h
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with("--")).collect();
    let case = args.first().map_or("springs", String::as_str);
    let frames: u64 = args.get(1).map_or(600, |n| n.parse().expect("FRAMES is a count"));
    let clip = walk();
    let springs = match case {
        "clip" => SpringsSpec::default(),
        "springs" | "pose" => tail(),
        other => panic!("unknown case {other} (clip, springs, pose)"),
    };
    let spec = MotionSpec { layers: vec![LayerSpec::new(&clip)], springs, ..MotionSpec::default() };
    let motion = Arc::new(Motion::build(spec).expect("the motion builds"));
    let start = Instant::now();
    let h = if case == "pose" { poses(&motion, frames) } else { stream(motion, frames) };
    let per_frame = start.elapsed().as_nanos() as f64 / frames.max(1) as f64;
    println!("{case}: {frames} frames at {FPS} fps, {per_frame:.0} ns/frame, poses {h:016x}");
}

/// `frames` ticks of a stream at [`FPS`]; the hash of their poses.
fn stream(motion: Arc<Motion<&Clip>>, frames: u64) -> u64 {
    let mut player = Player::new(motion);
    let options = MotionOptions::default();
    let mut h = 0xcbf2_9ce4_8422_2325;
    for k in 0..frames {
        let s = k as f64 / f64::from(FPS);
        player.sample_clocked(s, s, &options);
        h = hash(h, player.pose());
    }
    h
}

/// `count` stateless poses (each its own simulation from rest, a second of
/// warm-up: 121 substeps), at times 1/[`FPS`] apart from 1 s; the hash.
fn poses(motion: &Motion<&Clip>, count: u64) -> u64 {
    let mut sampler = anim::MotionSampler::new();
    let options = MotionOptions::default();
    let mut h = 0xcbf2_9ce4_8422_2325;
    for k in 0..count {
        sampler.restart_springs();
        motion.sample(1.0 + k as f64 / f64::from(FPS), &options, &mut sampler);
        h = hash(h, sampler.local());
    }
    h
}
