//! Motions with a character (docs/motion.md, “Characters”): a layer of another
//! skeleton is retargeted onto the character once per pose, exactly as the
//! [`Retargeter`] does it on its own; a layer of the character's own
//! skeleton plays as it is; root motion is the retargeted hips'; a rig
//! that shares too few roles is refused with the roles it lacks.

use std::sync::Arc;

use anim::character::{RetargetOptions, Retargeter, Rig, Translation};
use anim::motion::{CharacterSpec, LayerMode, LayerSpec, MotionOptions, MotionSpec, RootMotionSpec};
use anim::{
    Channel, Clip, ClipSpec, Cursor, Interpolation, JointSpec, Keys, Motion, MotionSampler, Playback, Pose, Skeleton,
    SkeletonSpec, Transform,
};
use glam::{Quat, Vec3, Vec4};

use super::inferred;
use super::names::{MIXAMO, UNREAL, humanoid};

/// A take on `skeleton`: the hips walk along z and sway, the left upper
/// arm and right knee swing, over 2 s, looping.
pub(crate) fn take(skeleton: &Skeleton) -> Clip {
    let joints = (0..skeleton.len())
        .map(|j| JointSpec {
            name: skeleton.names()[j].clone(),
            parent: skeleton.parent(j).map(|p| skeleton.names()[p].clone()),
            rest: Transform { translation: skeleton.rest().translations[j].into(), ..Transform::IDENTITY },
            inverse_bind: None,
        })
        .collect();
    let hips = &skeleton.names()[0];
    let rest = Vec3::from(skeleton.rest().translations[0]);
    let times = vec![0.0, 1.0, 2.0];
    let turn = |axis: Vec3, a: f32| Vec4::from(Quat::from_axis_angle(axis.normalize(), a));
    let tracks = vec![
        anim::TrackSpec::new(
            hips,
            Channel::Translation,
            Interpolation::Linear,
            times.clone(),
            Keys::Vec3(vec![rest, rest + Vec3::new(0.1, 0.05, 1.0), rest + Vec3::new(0.0, 0.0, 2.0)]),
        ),
        anim::TrackSpec::new(
            hips,
            Channel::Rotation,
            Interpolation::Linear,
            times.clone(),
            Keys::Vec4(vec![turn(Vec3::Y, 0.0), turn(Vec3::Y, 0.4), turn(Vec3::Y, 0.8)]),
        ),
        anim::TrackSpec::new(
            &skeleton.names()[7],
            Channel::Rotation,
            Interpolation::Linear,
            times.clone(),
            Keys::Vec4(vec![turn(Vec3::X, 0.2), turn(Vec3::new(1.0, 0.0, 1.0), -0.9), turn(Vec3::X, 0.2)]),
        ),
        anim::TrackSpec::new(
            &skeleton.names()[19],
            Channel::Rotation,
            Interpolation::Linear,
            times,
            Keys::Vec4(vec![turn(Vec3::X, 0.0), turn(Vec3::X, 1.1), turn(Vec3::X, 0.0)]),
        ),
    ];
    let spec = ClipSpec {
        name: "take".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks,
        playback: Playback::Loop,
        ..Default::default()
    };
    Clip::build(&spec).unwrap()
}

fn character(skeleton: Skeleton) -> Arc<CharacterSpec> {
    let roles = inferred(&skeleton);
    Arc::new(CharacterSpec { skeleton, roles, reference: None })
}

fn pose_at(motion: &Motion<&Clip>, t: f64) -> Pose {
    let mut sampler = MotionSampler::new();
    motion.sample(t, &MotionOptions::default(), &mut sampler);
    sampler.pose().clone()
}

#[test]
fn a_layer_of_another_skeleton_plays_on_the_character_as_the_retargeter_makes_it() {
    let (source, target) = (humanoid(&MIXAMO), humanoid(&UNREAL));
    let clip = take(&source);
    let on = character(target.clone());
    let spec = MotionSpec { layers: vec![LayerSpec::new(&clip)], character: Some(on.clone()), ..Default::default() };
    let motion = Motion::build(spec).unwrap();
    assert_eq!(motion.skeleton().names(), target.names(), "poses answer in the character's joints");
    assert!(motion.is_retargeted(0));
    // The same retarget by hand: the source's rest as reference (its hips,
    // already off the origin, stay at their rest), the character's rest.
    let roles = inferred(&source);
    let rig = Rig::at_rest(&source, &roles);
    let mut retargeter = Retargeter::new(rig, Rig::at_rest(&target, &on.roles), RetargetOptions::default()).unwrap();
    for t in [0.0, 0.3, 1.0, 1.7] {
        let mut plain = Pose::default();
        clip.sample_into(t as f32, &mut Cursor::default(), &mut plain);
        let mut expected = Pose::default();
        retargeter.retarget(&plain, &mut expected);
        let got = pose_at(&motion, t);
        assert_eq!(got.rotations, expected.rotations, "t = {t}");
        assert_eq!(got.translations, expected.translations, "t = {t}");
    }
}

#[test]
fn a_layer_of_the_characters_own_skeleton_plays_as_it_is_and_blends_with_a_retargeted_one() {
    let (source, target) = (humanoid(&MIXAMO), humanoid(&UNREAL));
    let (other, own) = (take(&source), take(&target));
    let on = character(target.clone());
    let plain = Motion::build(MotionSpec { layers: vec![LayerSpec::new(&own)], ..Default::default() }).unwrap();
    let spec = MotionSpec { layers: vec![LayerSpec::new(&own)], character: Some(on.clone()), ..Default::default() };
    let motion = Motion::build(spec).unwrap();
    assert!(!motion.is_retargeted(0));
    assert_eq!(pose_at(&motion, 0.6).rotations, pose_at(&plain, 0.6).rotations);
    // Both takes are the same motion on rigs of the same shape, so their
    // blend is either one (within rounding).
    let layers = vec![LayerSpec::new(&own), LayerSpec { weight: 0.5, ..LayerSpec::new(&other) }];
    let both = Motion::build(MotionSpec { layers, character: Some(on), ..Default::default() }).unwrap();
    assert!(both.is_retargeted(1) && both.warnings().is_empty());
    let (a, b) = (pose_at(&both, 0.6), pose_at(&plain, 0.6));
    for j in 0..target.len() {
        assert!(a.rotations[j].dot(b.rotations[j]).abs() > 1.0 - 1e-6, "joint {j}");
        assert!((a.translations[j] - b.translations[j]).length() < 1e-5, "joint {j}");
    }
}

#[test]
fn root_motion_is_the_retargeted_hips_and_additive_references_are_retargeted_too() {
    let (source, target) = (humanoid(&MIXAMO), humanoid(&UNREAL));
    let clip = take(&source);
    let on = character(target);
    let root = Some(RootMotionSpec::default());
    let spec = MotionSpec {
        layers: vec![LayerSpec::new(&clip)],
        character: Some(on.clone()),
        root_motion: root,
        ..Default::default()
    };
    let motion = Motion::build(spec).unwrap();
    let mut sampler = MotionSampler::new();
    motion.sample(0.0, &MotionOptions::default(), &mut sampler);
    motion.sample(1.0, &MotionOptions::default(), &mut sampler);
    // k = 1 (same proportions): the hips travel 1 along z and 0.1 along x, turning 0.4.
    let delta = sampler.root_motion().unwrap().delta;
    assert!((delta.translation - glam::DVec3::new(0.1, 0.0, 1.0)).length() < 1e-5, "{delta:?}");
    assert!((delta.yaw - 0.4).abs() < 1e-5, "{delta:?}");
    // An additive layer of the take over itself at its reference time adds nothing.
    let layers = vec![
        LayerSpec::new(&clip),
        LayerSpec { mode: LayerMode::Additive, reference_time: Some(0.5), ..LayerSpec::new(&clip) },
    ];
    let added = Motion::build(MotionSpec { layers, character: Some(on.clone()), ..Default::default() }).unwrap();
    let alone =
        Motion::build(MotionSpec { layers: vec![LayerSpec::new(&clip)], character: Some(on), ..Default::default() })
            .unwrap();
    let (a, b) = (pose_at(&added, 0.5), pose_at(&alone, 0.5));
    for j in 0..a.rotations.len() {
        assert!(a.rotations[j].dot(b.rotations[j]).abs() > 1.0 - 1e-6, "joint {j}");
    }
}

#[test]
fn a_clip_that_shares_too_few_roles_is_unmappable_naming_them_and_translation_none_holds_the_hips() {
    let (source, target) = (humanoid(&MIXAMO), humanoid(&UNREAL));
    let on = character(target.clone());
    let hips = anim::TrackSpec::new(
        "Hips",
        Channel::Translation,
        Interpolation::Linear,
        vec![0.0, 1.0],
        Keys::Vec3(vec![Vec3::ZERO, Vec3::X]),
    );
    let arm =
        anim::TrackSpec::new("arm", Channel::Translation, Interpolation::Linear, vec![0.0], Keys::Vec3(vec![Vec3::Y]));
    let two = Clip::build(&ClipSpec { name: "two".into(), tracks: vec![hips, arm], ..Default::default() }).unwrap();
    let spec = MotionSpec { layers: vec![LayerSpec::new(&two)], character: Some(on.clone()), ..Default::default() };
    let err = Motion::build(spec).unwrap_err();
    assert_eq!((err.path.to_pointer().as_str(), err.kind.code()), ("/layers/0/clip", "unmappable_skeleton"));
    assert!(err.kind.to_string().contains("leftUpperLeg"), "{}", err.kind);
    // `translation: none` keeps the hips at the character's reference.
    let clip = take(&source);
    let retarget = anim::motion::RetargetSpec { translation: Translation::None, ..Default::default() };
    let layers = vec![LayerSpec { retarget: Some(retarget), ..LayerSpec::new(&clip) }];
    let motion = Motion::build(MotionSpec { layers, character: Some(on), ..Default::default() }).unwrap();
    assert_eq!(pose_at(&motion, 1.0).translations[0], target.rest().translations[0]);
}
