//! The shipped VRM 1.0 sample (`examples/vrm/tiny_humanoid.vrm`, written by
//! `make_vrm.py` beside it): its character's roles are the file's
//! `VRMC_vrm.humanoid.humanBones`, read here from the GLB's JSON chunk
//! independently of the importer; its `VRMC_springBone` chains come in with
//! their colliders; its one animation imports as a looping clip whose keys
//! are the script's.

use std::collections::BTreeMap;

use anim::character::{FoundBy, Role, RoleMap};
use anim::spring::{ColliderShape, JointParams, SpringParams};
use anim::{Clip, Playback, SampleOptions, Sampler};
use formats::import::{Format, ImportOptions, Imported, import};
use glam::{Quat, Vec3};
use serde_json::Value;

fn file() -> Vec<u8> {
    super::reference::read("vrm/tiny_humanoid.vrm")
}

fn imported() -> Imported {
    import(&file(), Format::Glb, &ImportOptions::default()).unwrap()
}

/// The GLB's JSON chunk, parsed.
fn json_chunk(glb: &[u8]) -> Value {
    assert_eq!(&glb[..4], b"glTF");
    let length = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    assert_eq!(&glb[16..20], b"JSON");
    serde_json::from_slice(&glb[20..20 + length]).unwrap()
}

/// Role name → node name, straight from the file's humanoid.
fn human_bones() -> BTreeMap<String, Option<String>> {
    let doc = json_chunk(&file());
    let node_name = |n: &Value| doc["nodes"][n.as_u64().unwrap() as usize]["name"].as_str().unwrap().to_owned();
    let bones = doc["extensions"]["VRMC_vrm"]["humanoid"]["humanBones"].as_object().unwrap();
    bones.iter().map(|(role, bone)| (role.clone(), Some(node_name(&bone["node"])))).collect()
}

#[test]
fn the_characters_roles_are_the_vrm_humanoids_bones() {
    let imported = imported();
    assert_eq!(imported.characters.len(), 1);
    let character = &imported.characters[0];
    let expected = human_bones();
    assert_eq!(expected.len(), 17, "the script names 17 bones");
    assert_eq!(character.roles, expected);
    assert!(imported.warnings.iter().all(|w| !w.pointer.contains("humanoid")), "{:?}", imported.warnings);

    // Given, they are what the map holds; the names alone say nothing.
    let clip = Clip::build(&imported.clips[0]).unwrap();
    let given: Vec<(Role, Option<&str>)> =
        character.roles.iter().map(|(r, j)| (Role::from_name(r).unwrap(), j.as_deref())).collect();
    let map = RoleMap::infer(clip.skeleton(), &given).unwrap();
    for (role, joint) in &expected {
        let found = map.get(Role::from_name(role).unwrap()).unwrap();
        assert_eq!(
            (clip.skeleton().names()[found.joint].as_str(), found.by),
            (joint.as_deref().unwrap(), FoundBy::Given)
        );
    }
    let by_names = RoleMap::infer(clip.skeleton(), &[]).unwrap();
    assert!(by_names.iter().all(|(_, j)| j.by != FoundBy::Name), "J00… are no family's names");
    assert_eq!(by_names.family(), None);
}

#[test]
fn the_spring_bones_import_as_a_tail_with_its_collider_and_a_hair_strand() {
    let imported = imported();
    let chains = &imported.springs[0];
    let names: Vec<(&str, Vec<&str>)> =
        chains.iter().map(|c| (c.name.as_str(), c.joints.iter().map(String::as_str).collect())).collect();
    assert_eq!(names, [("tail", vec!["T0", "T1", "T2"]), ("hair", vec!["H0", "H1"])]);
    let tail = &chains[0];
    // VRM's gravityPower 0.2 along -y, at 60 updates a second: 12 m/s².
    let params = SpringParams { stiffness: 0.8, drag: 0.4, gravity: Vec3::new(0.0, -12.0, 0.0), radius: 0.02 };
    assert_eq!(tail.params, params);
    assert_eq!(tail.joint_params, [("T1".to_owned(), JointParams { stiffness: Some(0.6), ..JointParams::default() })]);
    let shapes: Vec<(&str, ColliderShape)> = tail.colliders.iter().map(|c| (c.joint.as_str(), c.shape)).collect();
    assert_eq!(shapes, [("J00", ColliderShape::Sphere { offset: Vec3::new(0.0, -0.1, 0.0), radius: 0.12 })]);
    assert!(chains[1].colliders.is_empty());
}

#[test]
fn the_sway_imports_as_a_looping_clip_with_the_scripts_keys() {
    let imported = imported();
    assert_eq!(imported.clips.len(), 1);
    let spec = &imported.clips[0];
    assert_eq!((spec.name.as_str(), spec.playback), ("sway", Playback::Loop));
    let clip = Clip::build(spec).unwrap();
    let hips = clip.skeleton().index_of("J00").unwrap();
    let mut sampler = Sampler::new();
    let mut hips_at = |t: f64| {
        clip.sample(t, &SampleOptions::default(), &mut sampler);
        sampler.pose().rotations[hips]
    };
    // The script's keys: 8° about z at 0.5 s, -8° at 1.5 s; looped, 2.5 s is 0.5 s.
    let about_z = |deg: f64| {
        let h = deg.to_radians() / 2.0;
        Quat::from_xyzw(0.0, 0.0, h.sin() as f32, h.cos() as f32)
    };
    for (t, deg) in [(0.5, 8.0), (1.5, -8.0), (2.5, 8.0), (3.0, 0.0)] {
        let got = hips_at(t);
        assert!(got.dot(about_z(deg)).abs() > 1.0 - 1e-6, "at {t}: {got:?}");
    }
}
