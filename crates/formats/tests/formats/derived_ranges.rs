//! Derived compact-frame ranges (docs/compact-frames.md, “What a compact
//! stream plays”) on real takes: a layer retargeted onto a character (CMU
//! takes on CesiumMan, with each translation rule, planted feet and an
//! additive layer; CesiumMan's walk on the CMU skeleton) and root motion
//! `extract` (the Fox's walk, CesiumMan's, a CMU take, and a retargeted
//! one). Each motion is sampled at every key of its clips, at 240 Hz over
//! two loops and at random times under random layer weights, and no pose
//! leaves the ranges `Ranges::of_motion` derives from the clips' own.

use std::sync::Arc;

use anim::character::{FeetOptions, RoleMap, Translation};
use anim::compact::Ranges;
use anim::motion::{
    CharacterSpec, LayerMode, LayerSpec, MaskSpec, MotionOptions, MotionSpec, RetargetSpec, RootMode, RootMotionSpec,
};
use anim::{Clip, ClipSpec, Motion, MotionSampler, Skeleton};
use formats::import::ImportOptions;
use proptest::prelude::RngExt;
use proptest::test_runner::{RngAlgorithm, TestRng};

use super::feet::CESIUM_MAN_ROLES;
use super::{build, import_file};

/// A clip and its spec (whose tracks' times are the keys).
struct Take {
    clip: Clip,
    spec: ClipSpec,
}

impl Take {
    fn load(rel: &str, options: &ImportOptions, pick: impl Fn(&ClipSpec) -> bool) -> Take {
        let imported = import_file(rel, options);
        let spec = imported.clips.into_iter().find(|c| pick(c)).expect("the clip");
        Take { clip: build(&spec), spec }
    }

    fn keys(&self) -> impl Iterator<Item = f32> + '_ {
        self.spec.tracks.iter().flat_map(|t| t.times.iter().copied())
    }
}

fn cmu(rel: &str) -> Take {
    // CMU lengths are in units of 0.45 inch (the ASF's `length 0.45`).
    Take::load(rel, &ImportOptions { scale: 0.0254 / 0.45, ..ImportOptions::default() }, |_| true)
}

fn cesium_man() -> Take {
    Take::load("gltf/CesiumMan/CesiumMan.gltf", &ImportOptions::default(), |_| true)
}

fn fox_walk() -> Take {
    // The Fox is in centimetres.
    let options = ImportOptions { scale: 0.01, ..ImportOptions::default() };
    Take::load("gltf/Fox/Fox.glb", &options, |c| c.name.ends_with("Walk"))
}

/// CesiumMan as a character (its nodes are unnamed: roles given).
fn cesium_character(cesium: &Clip) -> Arc<CharacterSpec> {
    let skeleton = cesium.skeleton().clone();
    let given: Vec<_> = CESIUM_MAN_ROLES.iter().map(|(r, n)| (*r, Some(*n))).collect();
    let roles = RoleMap::given(&skeleton, &given).unwrap();
    Arc::new(CharacterSpec { skeleton, roles, reference: None })
}

fn inferred_character(skeleton: &Skeleton) -> Arc<CharacterSpec> {
    let roles = RoleMap::infer(skeleton, &[]).unwrap();
    Arc::new(CharacterSpec { skeleton: skeleton.clone(), roles, reference: None })
}

fn extract(joint: Option<&str>) -> Option<RootMotionSpec> {
    Some(RootMotionSpec { joint: joint.map(str::to_owned), mode: RootMode::Extract, ..RootMotionSpec::default() })
}

/// Samples `motion` at every key of `takes`, at 240 Hz over two loops and at
/// 600 random times (random weights when it has several layers), in that
/// order (a planted foot carries state from frame to frame); every pose is
/// within its derived ranges. Returns how many poses were checked.
fn stays_within(name: &str, motion: &Motion<&Clip>, takes: &[&Take]) -> usize {
    let ranges = Ranges::of_motion(motion, 240.0).unwrap_or_else(|u| panic!("{name}: refused: {}", u.0));
    let layers = motion.layers().count();
    let longest = takes.iter().map(|t| f64::from(t.clip.duration())).fold(0.0, f64::max);
    // Times and weights from proptest's deterministic generator: the same every run.
    let mut rng = TestRng::deterministic_rng(RngAlgorithm::ChaCha);
    let keys = takes.iter().flat_map(|t| t.keys().map(|k| (f64::from(k), vec![1.0; layers])));
    let grid_steps = (2.0 * longest * 240.0).ceil() as usize;
    let grid = (0..=grid_steps).map(|i| (i as f64 / 240.0, vec![1.0; layers]));
    let random: Vec<(f64, Vec<f32>)> = (0..600)
        .map(|_| {
            let tau = -1.0 + rng.random::<f64>() * (2.0 * longest + 2.0);
            let weights = (0..layers).map(|l| if l == 0 { 1.0 } else { rng.random::<f32>() }).collect();
            (tau, weights)
        })
        .collect();
    let (mut sampler, mut phases, mut checked) = (MotionSampler::new(), Vec::new(), 0);
    for (tau, weights) in keys.chain(grid).chain(random) {
        motion.phases_at(tau, &weights, &mut phases);
        motion.sample_with(tau, &phases, &weights, &MotionOptions::default(), &mut sampler);
        let outside = ranges.outside(sampler.pose());
        assert_eq!(outside, None, "{name}: τ {tau}, weights {weights:?}");
        checked += 1;
    }
    checked
}

fn retarget(translation: Translation, feet: bool) -> RetargetSpec {
    RetargetSpec { translation, feet: feet.then(FeetOptions::default), ..RetargetSpec::default() }
}

#[test]
fn retargeted_takes_stay_within_their_derived_ranges() {
    let (walk, hop, cesium) = (cmu("bvh/131_01.bvh"), cmu("bvh/131_03.bvh"), cesium_man());
    let character = cesium_character(&cesium.clip);
    for (translation, feet) in [(Translation::Hips, false), (Translation::All, true), (Translation::None, false)] {
        let spec = MotionSpec {
            layers: vec![LayerSpec::new(&walk.clip)],
            character: Some(Arc::clone(&character)),
            retarget: retarget(translation, feet),
            ..MotionSpec::default()
        };
        let motion = Motion::build(spec).unwrap();
        let n = stays_within(&format!("131_01 on CesiumMan, {translation:?}, feet {feet}"), &motion, &[&walk]);
        println!("131_01 on CesiumMan ({translation:?}, feet {feet}): {n} poses within the ranges");
    }
    // Two retargeted takes blended under a mask, and one added on top.
    let mask = MaskSpec { joints: vec![("node12".to_owned(), 0.8)], descendants: true, default: None };
    let layers = vec![
        LayerSpec::new(&walk.clip),
        LayerSpec { mask: Some(mask), weight: 0.6, ..LayerSpec::new(&hop.clip) },
        LayerSpec { mode: LayerMode::Additive, reference_time: Some(0.5), ..LayerSpec::new(&hop.clip) },
    ];
    let spec = MotionSpec { layers, character: Some(character), ..MotionSpec::default() };
    stays_within("131_01 under 131_03 on CesiumMan", &Motion::build(spec).unwrap(), &[&walk, &hop]);
    // The other way: CesiumMan's walk on the CMU skeleton.
    let spec = MotionSpec {
        layers: vec![LayerSpec::new(&cesium.clip)],
        character: Some(inferred_character(walk.clip.skeleton())),
        ..MotionSpec::default()
    };
    stays_within("CesiumMan on the CMU skeleton", &Motion::build(spec).unwrap(), &[&cesium]);
}

#[test]
fn extracted_roots_stay_within_their_derived_ranges() {
    let (fox, cesium, walk) = (fox_walk(), cesium_man(), cmu("bvh/131_01.bvh"));
    stays_within("the Fox's walk", &Motion::build(own(&fox, Some("b_Hip_01"))).unwrap(), &[&fox]);
    stays_within("CesiumMan's walk", &Motion::build(own(&cesium, Some("node2"))).unwrap(), &[&cesium]);
    stays_within("131_01", &Motion::build(own(&walk, None)).unwrap(), &[&walk]);
    let spec = MotionSpec {
        layers: vec![LayerSpec::new(&walk.clip)],
        root_motion: extract(None),
        character: Some(cesium_character(&cesium.clip)),
        retarget: retarget(Translation::Hips, true),
        ..MotionSpec::default()
    };
    stays_within("131_01 on CesiumMan", &Motion::build(spec).unwrap(), &[&walk]);
}

/// A motion of `take` alone on its own rig, its root (`joint`, else the
/// first root with a translation track) extracted.
fn own<'a>(take: &'a Take, joint: Option<&str>) -> MotionSpec<&'a Clip> {
    MotionSpec { layers: vec![LayerSpec::new(&take.clip)], root_motion: extract(joint), ..MotionSpec::default() }
}
