//! What must hold for any retarget: bone lengths are the target's; a mapped
//! joint turns in the world as its source does; a retarget onto the
//! source's own rig is the identity; the hips move by `k = h_d/h_s`; rigs
//! without enough roles in common are refused.

use anim::character::{MIN_SHARED_ROLES, RetargetError, RetargetOptions, Retargeter, Rig, Role, RoleMap, Translation};
use anim::{Pose, Skeleton};
use glam::{Quat, Vec3, Vec3A};

use super::names::{SLOT_ROLES, SLOTS};
use super::reference::{random_pose, random_rig};
use super::skeleton_of;
use crate::random::Rng;

fn model(skeleton: &Skeleton, local: &Pose) -> Pose {
    let mut m = Pose::default();
    skeleton.to_model(local, &mut m);
    m
}

/// The angle of the rotation taking `a` to `b` (by `atan2`, which stays
/// accurate near 0 where `acos` of a dot product does not).
fn angle(a: Quat, b: Quat) -> f64 {
    let d = a.as_dquat().conjugate() * b.as_dquat();
    2.0 * d.xyz().length().atan2(d.w.abs())
}

fn retargeter(source: Rig<'_>, target: Rig<'_>, translation: Translation) -> Retargeter {
    Retargeter::new(source, target, RetargetOptions { translation }).unwrap()
}

#[test]
fn bone_lengths_are_the_targets_and_mapped_joints_turn_as_their_sources() {
    let mut rng = Rng::new(2020);
    for case in 0..40 {
        let (source, source_roles) = random_rig(&mut rng, case % 2 == 0);
        let (target, target_roles) = random_rig(&mut rng, true);
        let mut r =
            retargeter(Rig::at_rest(&source, &source_roles), Rig::at_rest(&target, &target_roles), Translation::Hips);
        let (source_rest, target_rest) = (model(&source, source.rest()), model(&target, target.rest()));
        let hips = target_roles.joint(Role::Hips).unwrap();
        let mut out = Pose::default();
        let pose = random_pose(&mut rng, &source, 2.5, false);
        r.retarget(&pose, &mut out);
        let (s, d) = (model(&source, &pose), model(&target, &out));
        for j in (0..target.len()).filter(|&j| j != hips) {
            let Some(p) = target.parent(j) else { continue };
            let (now, rest) = (
                d.translations[j].distance(d.translations[p]),
                target_rest.translations[j].distance(target_rest.translations[p]),
            );
            assert!((now - rest).abs() <= 1e-5 * rest.max(1.0), "case {case}: bone {j} is {now}, rest {rest}");
        }
        for (role, entry) in target_roles.iter() {
            let i = source_roles.joint(role).unwrap();
            let source_change = s.rotations[i] * source_rest.rotations[i].conjugate();
            let target_change = d.rotations[entry.joint] * target_rest.rotations[entry.joint].conjugate();
            let off = angle(source_change, target_change);
            assert!(off < 1e-5, "case {case}: {role:?} turns {off} rad away from its source's change");
        }
    }
}

#[test]
fn a_retarget_onto_the_sources_own_rig_is_the_identity() {
    let mut rng = Rng::new(3030);
    for case in 0..30 {
        // Every joint has a role, so every joint is driven.
        let (rig, roles) = random_rig(&mut rng, false);
        for translation in [Translation::Hips, Translation::All] {
            let mut r = retargeter(Rig::at_rest(&rig, &roles), Rig::at_rest(&rig, &roles), translation);
            assert_eq!(r.k(), 1.0);
            let pose = random_pose(&mut rng, &rig, 3.0, translation == Translation::All);
            let mut out = Pose::default();
            r.retarget(&pose, &mut out);
            for j in 0..rig.len() {
                let off = angle(out.rotations[j], pose.rotations[j]);
                assert!(off < 1e-6, "case {case}: joint {j} turned {off} rad");
                let moved = out.translations[j].distance(pose.translations[j]);
                assert!(moved < 1e-6, "case {case} ({translation:?}): joint {j} moved {moved}");
                assert_eq!(out.scales[j], pose.scales[j]);
            }
        }
    }
}

/// The names tests' humanoid with every offset times `size`, its roles given.
fn scaled_humanoid(size: f32, names: &[&str; 22]) -> (Skeleton, RoleMap) {
    let joints: Vec<_> = SLOTS
        .iter()
        .zip(names)
        .map(|((parent, t), n)| (n.to_string(), parent.map(|p| names[p].to_string()), Vec3::from(*t) * size))
        .collect();
    let skeleton = skeleton_of(&joints);
    let given: Vec<_> = SLOT_ROLES.iter().zip(names).map(|(r, n)| (*r, Some(*n))).collect();
    let roles = RoleMap::given(&skeleton, &given).unwrap();
    (skeleton, roles)
}

const NAMES: [&str; 22] = [
    "h", "s", "c", "u", "n", "hd", "ls", "lu", "ll", "lh", "rs", "ru", "rl", "rh", "lul", "lll", "lf", "lt", "rul",
    "rll", "rf", "rt",
];

#[test]
fn the_hips_move_by_the_ratio_of_the_hips_heights() {
    let (small, small_roles) = scaled_humanoid(1.0, &NAMES);
    let (big, big_roles) = scaled_humanoid(2.5, &NAMES);
    // Hips at y = 1, the foot at 1 − 0.05 − 0.45 − 0.42: h = 0.92 at size 1, the toes lower still.
    let mut r = retargeter(Rig::at_rest(&small, &small_roles), Rig::at_rest(&big, &big_roles), Translation::Hips);
    assert!((r.k() - 2.5).abs() < 1e-6, "k = {}", r.k());
    let mut pose = small.rest().clone();
    pose.translations[0] += Vec3A::new(0.4, -0.1, 1.0);
    let mut out = Pose::default();
    r.retarget(&pose, &mut out);
    let expected = big.rest().translations[0] + 2.5 * Vec3A::new(0.4, -0.1, 1.0);
    assert!(out.translations[0].distance(expected) < 1e-5, "{} vs {expected}", out.translations[0]);
    // `none` keeps the hips where they were.
    let mut r = retargeter(Rig::at_rest(&small, &small_roles), Rig::at_rest(&big, &big_roles), Translation::None);
    r.retarget(&pose, &mut out);
    assert_eq!(out.translations[0], big.rest().translations[0]);
}

#[test]
fn without_feet_the_ratio_is_the_leg_chains() {
    let (source, _) = scaled_humanoid(1.0, &NAMES);
    let (target, _) = scaled_humanoid(3.0, &NAMES);
    // Feet left out of both maps: the chain hips → upper → lower leg is 0.05·√5 + 0.45 at size 1.
    let no_feet: Vec<_> = SLOT_ROLES
        .iter()
        .zip(NAMES)
        .filter(|(r, _)| !matches!(r, Role::LeftFoot | Role::RightFoot))
        .map(|(r, n)| (*r, Some(n)))
        .collect();
    let (sr, dr) = (RoleMap::given(&source, &no_feet).unwrap(), RoleMap::given(&target, &no_feet).unwrap());
    let r = retargeter(Rig::at_rest(&source, &sr), Rig::at_rest(&target, &dr), Translation::Hips);
    assert!((r.k() - 3.0).abs() < 1e-5, "k = {}", r.k());
    // With a foot on one side only, the legs decide too.
    let mut one_foot = no_feet.clone();
    one_foot.push((Role::LeftFoot, Some("lf")));
    let sr = RoleMap::given(&source, &one_foot).unwrap();
    let (target_small, _) = scaled_humanoid(0.5, &NAMES);
    let dr = RoleMap::given(&target_small, &no_feet).unwrap();
    let r = retargeter(Rig::at_rest(&source, &sr), Rig::at_rest(&target_small, &dr), Translation::Hips);
    assert!((r.k() - 0.5).abs() < 1e-5, "k = {}", r.k());
}

#[test]
fn rigs_that_share_too_few_roles_are_refused_naming_what_the_source_lacks() {
    let (rig, all_roles) = scaled_humanoid(1.0, &NAMES);
    let first = |n: usize| -> RoleMap {
        let given: Vec<_> = SLOT_ROLES.iter().zip(NAMES).take(n).map(|(r, n)| (*r, Some(n))).collect();
        RoleMap::given(&rig, &given).unwrap()
    };
    let new = |source: &RoleMap| {
        Retargeter::new(Rig::at_rest(&rig, source), Rig::at_rest(&rig, &all_roles), RetargetOptions::default())
    };
    // The hips and seven other roles are enough; the hips and six are not.
    assert!(new(&first(MIN_SHARED_ROLES)).is_ok());
    let refusal = new(&first(MIN_SHARED_ROLES - 1)).unwrap_err();
    assert_eq!(refusal.code(), "unmappable_skeleton");
    let mut missing = SLOT_ROLES[MIN_SHARED_ROLES - 1..].to_vec();
    missing.sort();
    assert_eq!(refusal, RetargetError::UnmappableSkeleton { shared: MIN_SHARED_ROLES - 1, missing });
    // Without hips, whatever else is shared.
    let no_hips: Vec<_> = SLOT_ROLES.iter().zip(NAMES).skip(1).map(|(r, n)| (*r, Some(n))).collect();
    let refusal = new(&RoleMap::given(&rig, &no_hips).unwrap()).unwrap_err();
    assert_eq!(refusal, RetargetError::UnmappableSkeleton { shared: 21, missing: vec![Role::Hips] });
    // A reference pose of the wrong size.
    let short = Pose::identity(3);
    let rig_short = Rig { skeleton: &rig, reference: &short, roles: &all_roles };
    let refusal = Retargeter::new(rig_short, Rig::at_rest(&rig, &all_roles), RetargetOptions::default()).unwrap_err();
    assert_eq!(refusal, RetargetError::ReferenceSize { target: false, expected: 22, provided: 3 });
}
