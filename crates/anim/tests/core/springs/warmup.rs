//! A stateless pose's warm-up (docs/springs.md, “Time” and “Cost”) samples
//! only the joints its substeps read, yet every frame is bit for bit the
//! one a warm-up sampling the whole motion at every substep makes: on the
//! Fox's walk, on a composed motion (sync, weights, a mask, an additive
//! layer, root motion, three chains), with the motion's own IK, and on a
//! character (a retargeted layer, planted feet).

use std::sync::Arc;

use anim::character::{FeetOptions, Translation};
use anim::ik::{AimSpec, IkSpec};
use anim::motion::{
    CharacterSpec, LayerMode, LayerSpec, MaskSpec, MotionOptions, MotionSpec, RetargetSpec, RootMode, RootMotionSpec,
};
use anim::spring::{ChainSpec, ColliderShape, ColliderSpec, DEFAULT_WARMUP, SpringSolver, SpringsSpec, warmup_start};
use anim::{Clip, Motion, MotionSampler, Pose, Space};
use formats::import::{Format, ImportOptions, import};
use glam::Vec3;

use crate::character::inferred;
use crate::character::motion::take;
use crate::character::names::{MIXAMO, UNREAL, humanoid};

/// Times in request order: from before the motion's start, through a
/// second (a whole warm-up), back (a new simulation) and on.
const TIMES: [f64; 8] = [-0.2, 0.35, 1.25, 1.3, 2.0, 0.4, 0.45, 3.1];

const LOCAL: MotionOptions = MotionOptions { ease: anim::Ease::Linear, space: Space::Local };

/// The Fox's animations (`Survey`, `Walk`, `Run`), as the service imports them.
fn fox() -> Vec<Clip> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/gltf/Fox/Fox.glb");
    let bytes = std::fs::read(path).expect("examples/gltf/Fox/Fox.glb");
    let options = ImportOptions { scale: 0.01, ..ImportOptions::default() };
    let clips = import(&bytes, Format::Glb, &options).expect("the Fox imports").clips;
    ["Survey", "Walk", "Run"]
        .iter()
        .map(|name| Clip::build(clips.iter().find(|c| c.name.ends_with(name)).unwrap()).unwrap())
        .collect()
}

fn capsule(joint: &str, tail: Vec3, radius: f32) -> ColliderSpec {
    ColliderSpec { joint: joint.into(), shape: ColliderShape::Capsule { offset: Vec3::ZERO, tail, radius } }
}

/// examples/motions/fox-tail-springs.json's chain.
fn tail() -> ChainSpec {
    let mut chain = ChainSpec::new("tail", &["b_Tail01_012", "b_Tail02_013", "b_Tail03_014"]);
    (chain.params.stiffness, chain.params.drag, chain.params.radius) = (0.8, 0.3, 0.03);
    chain.params.gravity = Vec3::new(0.0, -9.81, 0.0);
    let leg = Vec3::new(0.19, 0.0, 0.0);
    chain.colliders = vec![capsule("b_LeftLeg01_015", leg, 0.04), capsule("b_RightLeg01_019", leg, 0.04)];
    chain
}

/// A chain of `joints` falling under gravity, against a sphere on `on`.
fn hanging(name: &str, joints: &[&str], on: &str) -> ChainSpec {
    let mut chain = ChainSpec::new(name, joints);
    chain.params.gravity = Vec3::new(0.0, -9.81, 0.0);
    let sphere = ColliderShape::Sphere { offset: Vec3::new(0.0, -0.1, 0.0), radius: 0.08 };
    chain.colliders = vec![ColliderSpec { joint: on.into(), shape: sphere }];
    chain
}

fn springs(chains: Vec<ChainSpec>) -> SpringsSpec {
    SpringsSpec { chains, ..SpringsSpec::default() }
}

/// The frames at `times` as docs/springs.md, “Time”, defines them, every
/// substep on the whole pose of `plain` (the same motion without chains)
/// at its time: the warm-up before it sampled only what the chains read.
fn whole_warmup(plain: &Motion<&Clip>, chained: &Motion<&Clip>, times: &[f64]) -> Vec<Pose> {
    fn local(motion: &Motion<&Clip>, sampler: &mut MotionSampler, t: f64) -> Pose {
        motion.sample(t, &LOCAL, sampler);
        sampler.local().clone()
    }
    let springs = chained.springs().expect("chains");
    let (mut frames, mut substeps) = (MotionSampler::new(), MotionSampler::new());
    let mut solver = SpringSolver::new(springs);
    let mut run: Option<(f64, f64)> = None;
    let mut out = Vec::new();
    for &tau in times {
        let from = match run {
            Some((from, last)) if tau >= last => from,
            _ => {
                let from = warmup_start(tau.min(0.0), tau, DEFAULT_WARMUP);
                solver.start_at(springs, 0.0, &local(plain, &mut substeps, from));
                from
            }
        };
        run = Some((from, tau));
        let mut pose = local(plain, &mut frames, tau);
        solver.frame(springs, tau - from, &mut pose, |u, p| p.copy_from(&local(plain, &mut substeps, from + u)));
        out.push(pose);
    }
    out
}

/// Every bit of every joint of `pose`.
fn bits(pose: &Pose) -> Vec<u32> {
    let vectors = pose.translations.iter().chain(&pose.scales).flat_map(|v| v.to_array());
    vectors.chain(pose.rotations.iter().flat_map(|q| q.to_array())).map(f32::to_bits).collect()
}

/// `spec` with `chains` answers at [`TIMES`] bit for bit what the whole
/// warm-up does, and its chains moved (so the check compares something).
fn check(spec: MotionSpec<&Clip>, chains: SpringsSpec) {
    let plain = Motion::build(spec.clone()).unwrap();
    let chained = Motion::build(MotionSpec { springs: chains, ..spec }).unwrap();
    let expected = whole_warmup(&plain, &chained, &TIMES);
    let mut sampler = MotionSampler::new();
    let mut keyed = MotionSampler::new();
    for (&tau, expected) in TIMES.iter().zip(&expected) {
        chained.sample(tau, &LOCAL, &mut sampler);
        assert!(bits(sampler.local()) == bits(expected), "the pose at {tau}");
        plain.sample(tau, &LOCAL, &mut keyed);
        assert!(bits(sampler.local()) != bits(keyed.local()), "the chains turn their joints at {tau}");
    }
}

#[test]
fn the_fox_walk_s_warmup_is_the_whole_pose_s() {
    let clips = fox();
    check(MotionSpec { layers: vec![LayerSpec::new(&clips[1])], ..MotionSpec::default() }, springs(vec![tail()]));
}

#[test]
fn a_composed_motion_s_warmup_is_the_whole_pose_s() {
    let clips = fox();
    let sync = |clip, weight| LayerSpec { weight, sync: Some("gait".into()), ..LayerSpec::new(clip) };
    let mask = MaskSpec { joints: vec![("b_Spine02_03".into(), 0.7)], descendants: true, default: None };
    let survey = LayerSpec { weight: 0.6, mode: LayerMode::Additive, mask: Some(mask), ..LayerSpec::new(&clips[0]) };
    let spec = MotionSpec {
        layers: vec![sync(&clips[1], 1.0), sync(&clips[2], 0.45), survey],
        root_motion: Some(RootMotionSpec {
            joint: Some("b_Hip_01".into()),
            mode: RootMode::Extract,
            ..RootMotionSpec::default()
        }),
        ..MotionSpec::default()
    };
    let arm = hanging("arm", &["b_LeftUpperArm_09", "b_LeftForeArm_010", "b_LeftHand_011"], "b_Spine01_02");
    let head = hanging("head", &["b_Neck_04", "b_Head_05"], "b_Spine01_02");
    check(spec, springs(vec![tail(), arm, head]));
}

#[test]
fn with_the_motion_s_ik_the_warmup_is_the_whole_pose_s() {
    let clips = fox();
    let aim = AimSpec {
        joint: "b_Head_05".into(),
        target: Vec3::new(1.0, 0.6, 1.0),
        forward: Some(Vec3::X),
        up: None,
        up_direction: None,
        weight: Some(0.8),
    };
    let spec =
        MotionSpec { layers: vec![LayerSpec::new(&clips[1])], ik: vec![IkSpec::Aim(aim)], ..MotionSpec::default() };
    check(spec, springs(vec![tail()]));
}

#[test]
fn on_a_character_the_warmup_is_the_whole_pose_s() {
    let (source, target) = (humanoid(&MIXAMO), humanoid(&UNREAL));
    let (other, own) = (take(&source), take(&target));
    let roles = inferred(&target);
    let character = Arc::new(CharacterSpec { skeleton: target, roles, reference: None });
    let retarget =
        RetargetSpec { translation: Translation::Hips, feet: Some(FeetOptions::default()), ..RetargetSpec::default() };
    let mask = MaskSpec { joints: vec![("clavicle_r".into(), 1.0)], descendants: true, default: None };
    let spec = MotionSpec {
        layers: vec![LayerSpec::new(&other), LayerSpec { weight: 0.5, mask: Some(mask), ..LayerSpec::new(&own) }],
        character: Some(character),
        retarget,
        ..MotionSpec::default()
    };
    check(spec, springs(vec![hanging("arm", &["upperarm_l", "lowerarm_l", "hand_l"], "spine_01")]));
}
