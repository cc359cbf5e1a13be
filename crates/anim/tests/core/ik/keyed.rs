//! IK in clips, motions and players (docs/ik.md): keyed targets solved at every
//! sample against hand-computed positions, a clip's solve inside a masked
//! layer equal to the clip's own pose, reports in order, warm starts on a
//! player, no allocation once warm, and a crossfade's motion refused when
//! it carries constraints.

use std::sync::Arc;

use anim::ik::{ChainSpec, EffectorSpec, IkConstraint, IkKind, IkLimits, IkSpec, TwoBoneSpec, build_constraints};
use anim::motion::{LayerSpec, MaskSpec, MotionOptions, MotionSampler, MotionSpec, Player, PlayerError};
use anim::{
    Channel, Clip, ClipSpec, Cursor, Ease, IkTarget, Interpolation, KeyedIkSpec, Keys, Motion, Playback, Pose,
    SkeletonSpec, Space, TrackSpec,
};
use glam::{DVec3, Vec3, Vec3A};

use super::{d, model_f64};
use crate::allocations;

/// hips → thigh (+0.1 x) → knee (−0.5 y) → foot (−0.5 y), hips moving along
/// x at 1 unit/s over [0, 4] s, with `ik`.
fn leg(ik: Vec<KeyedIkSpec>) -> Clip {
    let joint = crate::rest_joint;
    let joints = vec![
        joint("hips", None, [0.0, 0.0, 0.0]),
        joint("thigh", Some("hips"), [0.1, 0.0, 0.0]),
        joint("knee", Some("thigh"), [0.0, -0.5, 0.0]),
        joint("foot", Some("knee"), [0.0, -0.5, 0.0]),
    ];
    let hips = TrackSpec::new(
        "hips",
        Channel::Translation,
        Interpolation::Linear,
        vec![0.0, 4.0],
        Keys::Vec3(vec![Vec3::ZERO, Vec3::new(4.0, 0.0, 0.0)]),
    );
    let spec = ClipSpec {
        name: "leg".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks: vec![hips],
        playback: Playback::Loop,
        ik,
        ..Default::default()
    };
    Clip::build(&spec).expect("the leg builds")
}

fn two_bone(target: Vec3) -> IkSpec {
    IkSpec::TwoBone(TwoBoneSpec {
        joints: ["thigh".into(), "knee".into(), "foot".into()],
        target,
        pole: Some(Vec3::new(0.0, -0.5, 5.0)),
        weight: None,
    })
}

fn keyed_track(times: Vec<f32>, values: Vec<Vec3>) -> TrackSpec {
    TrackSpec::new("", Channel::Translation, Interpolation::Linear, times, Keys::Vec3(values))
}

/// The foot's path: (0.1, −0.8, 0.2) at 0 to (2.1, −0.7, −0.2) at 2 s, linear.
const A: Vec3 = Vec3::new(0.1, -0.8, 0.2);
const B: Vec3 = Vec3::new(2.1, -0.7, -0.2);

fn stepping_leg() -> Clip {
    let target = IkTarget::Keyed(keyed_track(vec![0.0, 2.0], vec![A, B]));
    leg(vec![KeyedIkSpec { constraint: two_bone(Vec3::ZERO), targets: vec![target], weight: None }])
}

fn foot_at(clip: &Clip, pose: &Pose) -> DVec3 {
    model_f64(clip.skeleton(), pose)[3].t
}

#[test]
fn a_keyed_target_is_met_at_every_sample_and_its_keys_set_the_range() {
    let clip = stepping_leg();
    assert_eq!((clip.start(), clip.end()), (0.0, 4.0), "the hips' keys reach further than the target's");
    let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
    for k in 0..=20 {
        let t = k as f32 * 0.1;
        clip.sample_into(t, &mut cursor, &mut pose);
        let target = d(Vec3A::from(A.lerp(B, t / 2.0)));
        assert!(foot_at(&clip, &pose).distance(target) <= 1e-5, "t={t}");
        let report = cursor.ik_reports()[0];
        assert_eq!((report.kind, report.converged, report.iterations), (IkKind::TwoBone, true, 0));
    }
    // Past the last key the target holds, as a track does.
    clip.sample_into(2.05, &mut cursor, &mut pose);
    assert!(foot_at(&clip, &pose).distance(d(Vec3A::from(B))) <= 1e-5);
}

#[test]
fn a_clip_solves_inside_a_masked_layer_as_it_does_alone() {
    let ik_clip = stepping_leg();
    let plain = leg(Vec::new());
    let leg_only = MaskSpec { joints: vec![("thigh".into(), 1.0)], descendants: true, default: None };
    let layers = vec![LayerSpec::new(&plain), LayerSpec { mask: Some(leg_only), ..LayerSpec::new(&ik_clip) }];
    let layered = Motion::build(MotionSpec { layers: layers.clone(), ..Default::default() }).unwrap();
    let solved =
        Motion::build(MotionSpec { layers, ik: vec![chain_to(Vec3::new(1.2, -0.8, 0.1))], ..Default::default() })
            .unwrap();
    let (mut sampler, mut alone, mut cursor) = (MotionSampler::new(), Pose::default(), Cursor::default());
    // The chain's target is within reach while the thigh is near x = 1.2.
    for k in 0..10 {
        let t = 0.9 + 0.06 * k as f64;
        layered.sample(t, &MotionOptions::default(), &mut sampler);
        ik_clip.sample_into(t as f32, &mut cursor, &mut alone);
        for j in 1..4 {
            assert_eq!(sampler.local().rotations[j], alone.rotations[j], "t={t} joint {j}: the clip's own solve");
        }
        assert_eq!(sampler.ik_reports().len(), 1);
        solved.sample(t, &MotionOptions::default(), &mut sampler);
        let kinds: Vec<IkKind> = sampler.ik_reports().iter().map(|r| r.kind).collect();
        assert_eq!(kinds, [IkKind::TwoBone, IkKind::Chain], "clip constraints first, then the motion's");
        assert!(sampler.ik_reports()[1].converged);
    }
}

fn chain_to(target: Vec3) -> IkSpec {
    IkSpec::Chain(ChainSpec {
        effectors: vec![EffectorSpec { joint: "foot".into(), target, tip: None }],
        joints: Some(vec!["thigh".into(), "knee".into()]),
        limits: Vec::new(),
        max_iterations: None,
        tolerance: None,
        weight: None,
    })
}

fn resolved(clip: &Clip, specs: &[IkSpec]) -> Vec<IkConstraint> {
    build_constraints(specs, clip.skeleton(), &IkLimits::default()).unwrap()
}

#[test]
fn a_player_warm_starts_its_chains_and_replaces_its_list() {
    let clip = leg(Vec::new());
    let motion =
        Arc::new(Motion::build(MotionSpec { layers: vec![LayerSpec::new(&clip)], ..Default::default() }).unwrap());
    let mut player = Player::new(Arc::clone(&motion));
    player.set_ik(resolved(&clip, &[chain_to(Vec3::new(1.15, -0.8, 0.3))]));
    let options = MotionOptions { ease: Ease::Linear, space: Space::Local };
    player.sample(1.0, &options);
    let cold = player.ik_reports()[0];
    assert!(cold.converged && cold.iterations > 0, "{cold:?}");
    // The same instant again: the warm start is the answer already.
    player.sample(1.0, &options);
    assert_eq!(player.ik_reports()[0].iterations, 0, "warm from the previous frame's angles");
    // A new list replaces the old from the next tick; an empty one lets go.
    player.set_ik(Vec::new());
    player.sample(1.0, &options);
    assert!(player.ik_reports().is_empty());
    let (mut cursor, mut alone) = (Cursor::default(), Pose::default());
    clip.sample_into(1.0, &mut cursor, &mut alone);
    assert_eq!(player.pose().rotations, alone.rotations, "the animated pose back");
}

#[test]
fn a_player_takes_its_first_motions_constraints_and_refuses_a_crossfade_that_carries_some() {
    let clip = leg(Vec::new());
    let layers = || vec![LayerSpec::new(&clip)];
    let with_ik = MotionSpec { layers: layers(), ik: vec![two_bone(Vec3::new(1.2, -0.8, 0.2))], ..Default::default() };
    let motion = Arc::new(Motion::build(with_ik.clone()).unwrap());
    let mut player = Player::new(Arc::clone(&motion));
    assert_eq!(player.ik().len(), 1);
    player.sample(1.0, &MotionOptions { ease: Ease::Linear, space: Space::Model });
    let foot = player.pose().translations[3].as_dvec3();
    assert!(foot.distance(DVec3::new(1.2, -0.8, 0.2)) <= 1e-5, "{foot}");
    let refused = player.crossfade(Arc::new(Motion::build(with_ik).unwrap()), 0.5, Ease::Linear);
    assert_eq!(refused, Err(PlayerError::CrossfadeIk));
    let plain = Arc::new(Motion::build(MotionSpec { layers: layers(), ..Default::default() }).unwrap());
    assert!(player.crossfade(plain, 0.5, Ease::Linear).is_ok());
}

#[test]
fn keyed_clips_and_ik_players_allocate_nothing_once_warm() {
    let clip = stepping_leg();
    let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
    clip.sample_into(0.0, &mut cursor, &mut pose);
    let before = allocations();
    for k in 0..200 {
        clip.sample_into(k as f32 * 0.013, &mut cursor, &mut pose);
    }
    assert_eq!(allocations() - before, 0, "keyed IK samples");

    let motion =
        Arc::new(Motion::build(MotionSpec { layers: vec![LayerSpec::new(&clip)], ..Default::default() }).unwrap());
    let mut player = Player::new(motion);
    player.set_ik(resolved(&clip, &[chain_to(Vec3::new(1.15, -0.8, 0.3))]));
    let options = MotionOptions { ease: Ease::Linear, space: Space::Model };
    player.sample(0.0, &options);
    let before = allocations();
    for k in 1..200 {
        player.sample(f64::from(k) / 60.0, &options);
    }
    assert_eq!(allocations() - before, 0, "a player solving a chain every tick");
}
