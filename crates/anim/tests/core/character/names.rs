//! Roles from names: the real BVH conversions in `shared/testdata`, and one
//! synthetic rig per naming family on a common 22-joint humanoid, with
//! given roles winning.

use anim::character::{FoundBy, Role, RoleError, RoleMap};
use glam::Vec3;

use super::{bvh_skeleton, expect, inferred, named, roles_of, skeleton_of};
use Role::*;

/// The roles a humanoid's limbs and trunk must get, left and right.
fn body(
    trunk: [(Role, &'static str); 6],
    left: [&'static str; 8],
    right: [&'static str; 8],
) -> Vec<(Role, &'static str)> {
    let limb = [LeftShoulder, LeftUpperArm, LeftLowerArm, LeftHand, LeftUpperLeg, LeftLowerLeg, LeftFoot, LeftToes];
    let mut out = trunk.to_vec();
    out.extend(limb.iter().zip(left).map(|(r, n)| (*r, n)));
    out.extend(limb.iter().zip(right).map(|(r, n)| (r.mirror(), n)));
    out
}

fn check_bvh(file: &str, family: &str, pairs: &[(Role, &str)]) {
    let skeleton = bvh_skeleton(file);
    let map = inferred(&skeleton);
    assert_eq!(named(&skeleton, &map, &roles_of(pairs)), expect(pairs), "{file}");
    assert_eq!(map.family(), Some(family), "{file}");
    for (role, entry) in map.iter().filter(|(r, _)| roles_of(pairs).contains(r)) {
        assert_eq!(entry.by, FoundBy::Name, "{file}: {role:?}");
    }
    assert_eq!(map.missing(), Vec::<Role>::new(), "{file}");
}

#[test]
fn cmu_motionbuilder_bvh_reads_lowerback_as_the_spine_and_spine_as_the_chest() {
    let trunk = [
        (Hips, "Hips"),
        (Spine, "LowerBack"),
        (Chest, "Spine"),
        (UpperChest, "Spine1"),
        (Neck, "Neck"),
        (Head, "Head"),
    ];
    let left =
        ["LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"];
    let right = [
        "RightShoulder",
        "RightArm",
        "RightForeArm",
        "RightHand",
        "RightUpLeg",
        "RightLeg",
        "RightFoot",
        "RightToeBase",
    ];
    check_bvh("bvh/05_20-mb.bvh", "motionbuilder", &body(trunk, left, right));
}

#[test]
fn cmu_asf_bvh_reads_the_shoulder_as_the_upper_arm_and_the_collar_as_the_shoulder() {
    let trunk = [(Hips, "Hips"), (Spine, "lowerback"), (Chest, "Chest"), (UpperChest, "Chest2"), (Neck, "lowerneck")];
    let trunk = [trunk[0], trunk[1], trunk[2], trunk[3], trunk[4], (Head, "Head")];
    let left = ["LeftCollar", "LeftShoulder", "LeftElbow", "LeftWrist", "LeftHip", "LeftKnee", "LeftAnkle", "LeftToe"];
    let right =
        ["RightCollar", "RightShoulder", "RightElbow", "RightWrist", "RightHip", "RightKnee", "RightAnkle", "RightToe"];
    for file in ["bvh/131_01.bvh", "bvh/131_03.bvh"] {
        check_bvh(file, "cmu_asf", &body(trunk, left, right));
        // `Neck` sits above `lowerneck` and `lhand` below `LeftWrist`: no role of their own.
        let skeleton = bvh_skeleton(file);
        let map = inferred(&skeleton);
        for joint in ["Neck", "lhand", "rhand", "LHipJoint"] {
            assert_eq!(map.role_of(skeleton.index_of(joint).unwrap()), None, "{file}: {joint}");
        }
    }
}

#[test]
fn daz_bvh_reads_side_letters_in_front_of_capitals_and_the_fingers() {
    let trunk =
        [(Hips, "hip"), (Spine, "abdomen"), (Chest, "chest"), (Neck, "neck"), (Head, "head"), (LeftEye, "leftEye")];
    let left = ["lCollar", "lShldr", "lForeArm", "lHand", "lThigh", "lShin", "lFoot"];
    let right = ["rCollar", "rShldr", "rForeArm", "rHand", "rThigh", "rShin", "rFoot"];
    let mut pairs = trunk.to_vec();
    let limb = [LeftShoulder, LeftUpperArm, LeftLowerArm, LeftHand, LeftUpperLeg, LeftLowerLeg, LeftFoot];
    pairs.extend(limb.iter().zip(left).map(|(r, n)| (*r, n)));
    pairs.extend(limb.iter().zip(right).map(|(r, n)| (r.mirror(), n)));
    pairs.extend([
        (LeftThumbMetacarpal, "lThumb1"),
        (LeftThumbProximal, "lThumb2"),
        (LeftIndexProximal, "lIndex1"),
        (LeftIndexIntermediate, "lIndex2"),
        (LeftMiddleIntermediate, "lMid2"),
        (RightRingProximal, "rRing1"),
        (RightLittleIntermediate, "rPinky2"),
        (RightEye, "rightEye"),
    ]);
    check_bvh("bvh/05_20-daz.bvh", "daz", &pairs);
}

/// The 22 joints of a synthetic humanoid: parent slot and offset (Y up,
/// its left at +X), in slot order: hips, the four trunk joints, head, then
/// each arm (shoulder, upper, lower, hand) and each leg (upper, lower, foot, toes).
pub const SLOTS: [(Option<usize>, [f32; 3]); 22] = [
    (None, [0.0, 1.0, 0.0]),
    (Some(0), [0.0, 0.1, 0.0]),
    (Some(1), [0.0, 0.1, 0.0]),
    (Some(2), [0.0, 0.1, 0.0]),
    (Some(3), [0.0, 0.2, 0.0]),
    (Some(4), [0.0, 0.1, 0.0]),
    (Some(3), [0.05, 0.15, 0.0]),
    (Some(6), [0.1, 0.0, 0.0]),
    (Some(7), [0.3, 0.0, 0.0]),
    (Some(8), [0.25, 0.0, 0.0]),
    (Some(3), [-0.05, 0.15, 0.0]),
    (Some(10), [-0.1, 0.0, 0.0]),
    (Some(11), [-0.3, 0.0, 0.0]),
    (Some(12), [-0.25, 0.0, 0.0]),
    (Some(0), [0.1, -0.05, 0.0]),
    (Some(14), [0.0, -0.45, 0.0]),
    (Some(15), [0.0, -0.42, 0.0]),
    (Some(16), [0.0, -0.06, 0.12]),
    (Some(0), [-0.1, -0.05, 0.0]),
    (Some(18), [0.0, -0.45, 0.0]),
    (Some(19), [0.0, -0.42, 0.0]),
    (Some(20), [0.0, -0.06, 0.12]),
];

/// The roles of the slots, in slot order.
pub const SLOT_ROLES: [Role; 22] = [
    Hips,
    Spine,
    Chest,
    UpperChest,
    Neck,
    Head,
    LeftShoulder,
    LeftUpperArm,
    LeftLowerArm,
    LeftHand,
    RightShoulder,
    RightUpperArm,
    RightLowerArm,
    RightHand,
    LeftUpperLeg,
    LeftLowerLeg,
    LeftFoot,
    LeftToes,
    RightUpperLeg,
    RightLowerLeg,
    RightFoot,
    RightToes,
];

/// The synthetic humanoid with these joint names.
pub fn humanoid(names: &[&str; 22]) -> anim::Skeleton {
    let joints: Vec<_> = SLOTS
        .iter()
        .zip(names)
        .map(|((parent, t), name)| (name.to_string(), parent.map(|p| names[p].to_string()), Vec3::from(*t)))
        .collect();
    skeleton_of(&joints)
}

/// Names the slots, then checks each slot's role (`None`: no role), found
/// by name unless the slot is one of `by_shape`.
fn check_family(family: &str, names: [&str; 22], roles: [Option<Role>; 22], by_shape: &[usize]) {
    let skeleton = humanoid(&names);
    let map = inferred(&skeleton);
    for (slot, (name, role)) in names.iter().zip(roles).enumerate() {
        assert_eq!(map.role_of(slot), role, "{family}: joint {name}");
        if let Some(role) = role {
            let by = if by_shape.contains(&slot) { FoundBy::Structure } else { FoundBy::Name };
            assert_eq!(map.get(role).unwrap().by, by, "{family}: joint {name}");
        }
    }
    assert_eq!(map.family(), Some(family));
}

/// A Mixamo rig's names in the slot order of the family tests (without its
/// `mixamorig:` namespace); the motion tests retarget between it and [`UNREAL`].
pub(crate) const MIXAMO: [&str; 22] = [
    "Hips",
    "Spine",
    "Spine1",
    "Spine2",
    "Neck",
    "Head",
    "LeftShoulder",
    "LeftArm",
    "LeftForeArm",
    "LeftHand",
    "RightShoulder",
    "RightArm",
    "RightForeArm",
    "RightHand",
    "LeftUpLeg",
    "LeftLeg",
    "LeftFoot",
    "LeftToeBase",
    "RightUpLeg",
    "RightLeg",
    "RightFoot",
    "RightToeBase",
];

/// An Unreal mannequin's names in the same slot order.
pub(crate) const UNREAL: [&str; 22] = [
    "pelvis",
    "spine_01",
    "spine_02",
    "spine_03",
    "neck_01",
    "head",
    "clavicle_l",
    "upperarm_l",
    "lowerarm_l",
    "hand_l",
    "clavicle_r",
    "upperarm_r",
    "lowerarm_r",
    "hand_r",
    "thigh_l",
    "calf_l",
    "foot_l",
    "ball_l",
    "thigh_r",
    "calf_r",
    "foot_r",
    "ball_r",
];

fn all_roles() -> [Option<Role>; 22] {
    SLOT_ROLES.map(Some)
}

#[test]
fn mixamo_names_with_either_namespace_and_spine2() {
    for ns in ["mixamorig:", "mixamorig1:", ""] {
        let names = MIXAMO.map(|n| format!("{ns}{n}"));
        check_family("mixamo", names.each_ref().map(String::as_str), all_roles(), &[]);
    }
}

#[test]
fn spine_is_the_spine_unless_a_lowerback_makes_the_rig_motionbuilder() {
    // Without `LowerBack` or `Spine2`, the tie goes to Mixamo: `Spine` is the spine.
    let names = [
        "Hips",
        "Spine",
        "Spine1",
        "Neck1",
        "Neck",
        "Head",
        "LeftShoulder",
        "LeftArm",
        "LeftForeArm",
        "LeftHand",
        "RightShoulder",
        "RightArm",
        "RightForeArm",
        "RightHand",
        "LeftUpLeg",
        "LeftLeg",
        "LeftFoot",
        "LeftToeBase",
        "RightUpLeg",
        "RightLeg",
        "RightFoot",
        "RightToeBase",
    ];
    // `Neck1` carries the shoulders: the upper chest by shape.
    check_family("mixamo", names, all_roles(), &[3]);
    // With it, the same names shift up one: MotionBuilder's reading.
    let names = [
        "Hips",
        "LowerBack",
        "Spine",
        "Spine1",
        "Neck",
        "Head",
        "LeftShoulder",
        "LeftArm",
        "LeftForeArm",
        "LeftHand",
        "RightShoulder",
        "RightArm",
        "RightForeArm",
        "RightHand",
        "LeftUpLeg",
        "LeftLeg",
        "LeftFoot",
        "LeftToeBase",
        "RightUpLeg",
        "RightLeg",
        "RightFoot",
        "RightToeBase",
    ];
    check_family("motionbuilder", names, all_roles(), &[]);
}

#[test]
fn unreal_names() {
    check_family("unreal", UNREAL, all_roles(), &[]);
}

#[test]
fn vrm_names_and_vroid_names() {
    let names = [
        "hips",
        "spine",
        "chest",
        "upperChest",
        "neck",
        "head",
        "leftShoulder",
        "leftUpperArm",
        "leftLowerArm",
        "leftHand",
        "rightShoulder",
        "rightUpperArm",
        "rightLowerArm",
        "rightHand",
        "leftUpperLeg",
        "leftLowerLeg",
        "leftFoot",
        "leftToes",
        "rightUpperLeg",
        "rightLowerLeg",
        "rightFoot",
        "rightToes",
    ];
    check_family("vrm", names, all_roles(), &[]);
    let names = [
        "J_Bip_C_Hips",
        "J_Bip_C_Spine",
        "J_Bip_C_Chest",
        "J_Bip_C_UpperChest",
        "J_Bip_C_Neck",
        "J_Bip_C_Head",
        "J_Bip_L_Shoulder",
        "J_Bip_L_UpperArm",
        "J_Bip_L_LowerArm",
        "J_Bip_L_Hand",
        "J_Bip_R_Shoulder",
        "J_Bip_R_UpperArm",
        "J_Bip_R_LowerArm",
        "J_Bip_R_Hand",
        "J_Bip_L_UpperLeg",
        "J_Bip_L_LowerLeg",
        "J_Bip_L_Foot",
        "J_Bip_L_ToeBase",
        "J_Bip_R_UpperLeg",
        "J_Bip_R_LowerLeg",
        "J_Bip_R_Foot",
        "J_Bip_R_ToeBase",
    ];
    check_family("vrm", names, all_roles(), &[]);
}

#[test]
fn blender_names_with_each_way_of_writing_the_side() {
    let sides: [(&str, &str, &str, &str); 3] = [("", ".L", "", ".R"), ("", "_L", "", "_R"), ("Left", "", "Right", "")];
    for (lp, ls, rp, rs) in sides {
        let l = |n: &str| format!("{lp}{n}{ls}");
        let r = |n: &str| format!("{rp}{n}{rs}");
        let limb = ["shoulder", "upper_arm", "forearm", "hand"];
        let leg = ["thigh", "shin", "foot", "toe"];
        let mut names: Vec<String> =
            ["pelvis", "spine", "chest", "upper_chest", "neck", "head"].map(String::from).to_vec();
        names.extend(limb.iter().map(|n| l(n)));
        names.extend(limb.iter().map(|n| r(n)));
        names.extend(leg.iter().map(|n| l(n)));
        names.extend(leg.iter().map(|n| r(n)));
        let names: [&str; 22] = std::array::from_fn(|i| names[i].as_str());
        // `upper_chest` is not Blender's: VRM's table fills it.
        check_family("blender", names, all_roles(), &[]);
    }
}

#[test]
fn daz_names_leave_a_second_abdomen_unmapped() {
    let names = [
        "hip", "abdomen", "abdomen2", "chest", "neck", "head", "lCollar", "lShldr", "lForeArm", "lHand", "rCollar",
        "rShldr", "rForeArm", "rHand", "lThigh", "lShin", "lFoot", "lToe", "rThigh", "rShin", "rFoot", "rToe",
    ];
    let mut roles = all_roles();
    roles[2] = None;
    roles[3] = Some(Chest);
    check_family("daz", names, roles, &[]);
}

fn mixamo() -> anim::Skeleton {
    humanoid(&MIXAMO)
}

#[test]
fn given_roles_win_and_a_given_none_stays_unmapped() {
    let skeleton = mixamo();
    let given = [(Hips, Some("Spine")), (Head, None), (LeftHand, Some("LeftHand"))];
    let map = RoleMap::infer(&skeleton, &given).unwrap();
    let at = |name: &str| skeleton.index_of(name).unwrap();
    assert_eq!(map.get(Hips).map(|e| (e.joint, e.by)), Some((at("Spine"), FoundBy::Given)));
    assert_eq!(map.get(LeftHand).map(|e| (e.joint, e.by)), Some((at("LeftHand"), FoundBy::Given)));
    assert_eq!(map.joint(Head), None, "given as null");
    // `Spine` is taken, so the spine role gets nothing from the names, nor does `Hips` get a role.
    assert_eq!(map.joint(Spine), None);
    assert_eq!(map.role_of(at("Hips")), None);
    assert_eq!(map.get(Chest).map(|e| (e.joint, e.by)), Some((at("Spine1"), FoundBy::Name)));
    assert_eq!(map.missing(), vec![Spine]);
}

#[test]
fn given_roles_are_checked() {
    let skeleton = mixamo();
    let refusal = |given: &[(Role, Option<&str>)]| RoleMap::infer(&skeleton, given).unwrap_err();
    assert_eq!(refusal(&[(Hips, Some("pelvis"))]), RoleError::UnknownJoint { role: Hips, joint: "pelvis".into() });
    assert_eq!(refusal(&[(Hips, None), (Hips, Some("Hips"))]), RoleError::DuplicateRole { role: Hips });
    let twice = refusal(&[(Hips, Some("Hips")), (Spine, Some("Hips"))]);
    assert_eq!(twice, RoleError::JointHasTwoRoles { joint: "Hips".into(), roles: [Hips, Spine] });
    assert_eq!((twice.code(), twice.role()), ("joint_has_two_roles", Spine));
}

#[test]
fn names_that_say_nothing_give_no_roles_and_the_essentials_are_reported_missing() {
    let names: [String; 22] = std::array::from_fn(|i| format!("bone{i}"));
    let skeleton = humanoid(&names.each_ref().map(String::as_str));
    let (by_name, family) = anim::character::roles_from_names(skeleton.names());
    assert_eq!((by_name.iter().flatten().count(), family), (0, None));
    // A lone chain has no hips, legs or spine by any reading.
    let chain = skeleton_of(&[
        ("a".into(), None, Vec3::ZERO),
        ("b".into(), Some("a".into()), Vec3::Y),
        ("c".into(), Some("b".into()), Vec3::Y),
    ]);
    let map = inferred(&chain);
    assert!(map.is_empty());
    assert_eq!(map.missing(), anim::character::ESSENTIAL_ROLES.to_vec());
}
