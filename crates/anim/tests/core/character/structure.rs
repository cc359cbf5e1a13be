//! Roles from the rest pose's shape, where names say nothing: CesiumMan
//! (unnamed joints), the CMU skeletons with their names hidden, the Fox's
//! legs, and shapes that are not humanoid.

use anim::Skeleton;
use anim::character::{FoundBy, Role, RoleMap};
use glam::Vec3;

use super::rigs::{CESIUM_MAN, FOX};
use super::{bvh_skeleton, expect, inferred, named, roles_of, skeleton, skeleton_of};
use Role::*;

/// The same joints and rest pose under meaningless names (`j0`, `j1`, …).
fn anonymous(skeleton: &Skeleton) -> Skeleton {
    let name = |j: usize| format!("j{j}");
    let joints: Vec<_> = (0..skeleton.len())
        .map(|j| (name(j), skeleton.parent(j).map(name), Vec3::from(skeleton.rest().translations[j])))
        .collect();
    skeleton_of(&joints)
}

#[test]
fn cesium_man_gets_its_trunk_arms_and_legs_from_its_shape() {
    let skeleton = skeleton(CESIUM_MAN);
    let map = inferred(&skeleton);
    let pairs = [
        (Hips, "node2"),
        (Spine, "node11"),
        (Chest, "node12"),
        (Neck, "node19"),
        (Head, "node20"),
        (LeftUpperArm, "node16"),
        (LeftLowerArm, "node17"),
        (LeftHand, "node18"),
        (RightUpperArm, "node13"),
        (RightLowerArm, "node14"),
        (RightHand, "node15"),
        (LeftUpperLeg, "node7"),
        (LeftLowerLeg, "node8"),
        (LeftFoot, "node9"),
        (LeftToes, "node10"),
        (RightUpperLeg, "node3"),
        (RightLowerLeg, "node4"),
        (RightFoot, "node5"),
        (RightToes, "node6"),
    ];
    assert_eq!(named(&skeleton, &map, &roles_of(&pairs)), expect(&pairs));
    assert!(map.iter().all(|(_, e)| e.by == FoundBy::Structure));
    assert_eq!(map.len(), pairs.len(), "no shoulders, no upper chest: nothing else");
    assert!(map.missing().is_empty());
}

#[test]
fn the_cmu_skeletons_without_their_names_get_the_roles_their_names_give() {
    // The roles structure can see: trunk ends, arms from the upper arm, legs.
    let seen = [
        Hips,
        Head,
        LeftUpperArm,
        LeftLowerArm,
        RightUpperArm,
        RightLowerArm,
        LeftUpperLeg,
        LeftLowerLeg,
        LeftFoot,
        LeftToes,
        RightUpperLeg,
        RightLowerLeg,
        RightFoot,
        RightToes,
    ];
    for file in ["bvh/05_20-mb.bvh", "bvh/131_03.bvh"] {
        let named_skeleton = bvh_skeleton(file);
        let by_name = inferred(&named_skeleton);
        let by_shape = inferred(&anonymous(&named_skeleton));
        for role in seen {
            assert_eq!(by_shape.joint(role), by_name.joint(role), "{file}: {role:?}");
        }
        assert!(by_shape.missing().is_empty(), "{file}: {:?}", by_shape.missing());
    }
}

#[test]
fn the_fox_gets_its_trunk_and_front_legs_by_name_and_its_hind_legs_by_shape() {
    let skeleton = skeleton(FOX);
    let map = inferred(&skeleton);
    let by_name = [
        (Hips, "b_Hip_01"),
        (Spine, "b_Spine01_02"),
        (Chest, "b_Spine02_03"),
        (Neck, "b_Neck_04"),
        (Head, "b_Head_05"),
        (LeftUpperArm, "b_LeftUpperArm_09"),
        (LeftLowerArm, "b_LeftForeArm_010"),
        (LeftHand, "b_LeftHand_011"),
        (RightUpperArm, "b_RightUpperArm_06"),
        (RightLowerArm, "b_RightForeArm_07"),
        (RightHand, "b_RightHand_08"),
    ];
    assert_eq!(named(&skeleton, &map, &roles_of(&by_name)), expect(&by_name));
    assert!(by_name.iter().all(|(r, _)| map.get(*r).unwrap().by == FoundBy::Name));
    let by_shape = [
        (LeftUpperLeg, "b_LeftLeg01_015"),
        (LeftLowerLeg, "b_LeftLeg02_016"),
        (LeftFoot, "b_LeftFoot01_017"),
        (LeftToes, "b_LeftFoot02_018"),
        (RightUpperLeg, "b_RightLeg01_019"),
        (RightLowerLeg, "b_RightLeg02_020"),
        (RightFoot, "b_RightFoot01_021"),
        (RightToes, "b_RightFoot02_022"),
    ];
    assert_eq!(named(&skeleton, &map, &roles_of(&by_shape)), expect(&by_shape));
    assert!(by_shape.iter().all(|(r, _)| map.get(*r).unwrap().by == FoundBy::Structure));
}

#[test]
fn shapes_that_are_not_humanoid_give_no_roles() {
    let j = |name: &str, parent: Option<&str>, t: [f32; 3]| (name.to_owned(), parent.map(str::to_owned), Vec3::from(t));
    // A fork of three one-joint branches: no child chain has two joints.
    let star = skeleton_of(&[
        j("a", None, [0.0, 1.0, 0.0]),
        j("b", Some("a"), [0.1, 0.0, 0.0]),
        j("c", Some("a"), [-0.1, 0.0, 0.0]),
        j("d", Some("a"), [0.0, 0.1, 0.0]),
    ]);
    assert!(inferred(&star).is_empty());
    // Three chains all reaching up: hips, but no legs and so nothing else.
    let up = skeleton_of(&[
        j("a", None, [0.0, 1.0, 0.0]),
        j("b", Some("a"), [0.1, 0.1, 0.0]),
        j("b2", Some("b"), [0.0, 0.1, 0.0]),
        j("c", Some("a"), [-0.1, 0.1, 0.0]),
        j("c2", Some("c"), [0.0, 0.1, 0.0]),
        j("d", Some("a"), [0.0, 0.1, 0.0]),
        j("d2", Some("d"), [0.0, 0.1, 0.0]),
    ]);
    let map = inferred(&up);
    assert_eq!(map.iter().map(|(r, _)| r).collect::<Vec<_>>(), vec![Hips]);
    assert_eq!(map.missing().len(), 5);
}

#[test]
fn structure_fills_only_roles_and_joints_names_left_free() {
    // CesiumMan with its hips and left leg given, one of them elsewhere.
    let skeleton = skeleton(CESIUM_MAN);
    let given = [(Hips, Some("node2")), (LeftFoot, Some("node10")), (LeftToes, None)];
    let map = RoleMap::infer(&skeleton, &given).unwrap();
    let at = |n: &str| skeleton.index_of(n).unwrap();
    assert_eq!(map.get(Hips).unwrap().by, FoundBy::Given);
    assert_eq!(map.joint(LeftFoot), Some(at("node10")));
    assert_eq!(map.joint(LeftToes), None, "given as null");
    // node9 would be the left foot by shape, but that role is taken: it stays free.
    assert_eq!(map.role_of(at("node9")), None);
    assert_eq!(map.joint(LeftLowerLeg), Some(at("node8")));
}
