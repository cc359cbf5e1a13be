//! Import conventions on real files and ones edited from them: FBX refused
//! by name, `up`, `scale`, `playback` and `name_prefix`, and the warnings
//! about conventions (generic animation names, units, Z-up, a Mixamo-style
//! parent scale). Expected values are computed here from the unconverted
//! import, by the similarity the options name, never by the code under test.

use anim::{Clip, Playback, Space};
use formats::import::{ErrorClass, Format, ImportError, ImportOptions, Imported, UpAxis, detect, import};
use formats::wire::mesh;
use glam::{Mat4, Quat, Vec3};
use serde_json::Value;

use super::reference::read;
use super::{import_file, sample};

/// `(x, y, z)` ↦ `(x, z, −y)`: −90° about X, Z-up into Y-up, written out.
fn z_to_y(p: Vec3) -> Vec3 {
    Vec3::new(p.x, p.z, -p.y)
}

/// Every joint's model-space position at `t`.
fn positions(clip: &Clip, t: f64) -> Vec<Vec3> {
    sample(clip, t, Space::Model).pose().translations.iter().map(|&p| Vec3::from(p)).collect()
}

fn codes(imported: &Imported) -> Vec<(&str, &str)> {
    imported.warnings.iter().map(|w| (w.code.as_str(), w.pointer.as_str())).collect()
}

/// A glTF file's JSON edited by `edit` (a `.gltf` with embedded buffers).
fn edited_gltf(rel: &str, edit: impl FnOnce(&mut Value)) -> Vec<u8> {
    let mut json: Value = serde_json::from_slice(&read(rel)).unwrap();
    edit(&mut json);
    serde_json::to_vec(&json).unwrap()
}

/// A GLB with its JSON chunk edited by `edit`, the BIN chunk as it was.
fn edited_glb(rel: &str, edit: impl FnOnce(&mut Value)) -> Vec<u8> {
    let bytes = read(rel);
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let mut json: Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    edit(&mut json);
    let mut text = serde_json::to_vec(&json).unwrap();
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let rest = &bytes[20 + json_len..];
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((12 + 8 + text.len() + rest.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(rest);
    out
}

#[test]
fn fbx_files_binary_or_ascii_are_refused_by_name_with_the_conversion() {
    let binary = b"Kaydara FBX Binary  \x00\x1a\x00\xe8\x1c\x00\x00".to_vec();
    let ascii =
        b"; FBX 7.4.0 project file\n; Copyright (C) 1997-2015 Autodesk Inc.\n\nFBXHeaderExtension:  {\n".to_vec();
    let bare = b"\r\n  FBXHeaderExtension:  {\n\tFBXHeaderVersion: 1003\n}".to_vec();
    for body in [binary, ascii, bare] {
        assert!(matches!(detect(&body, None), Err(ImportError::Fbx)), "{:?}", String::from_utf8_lossy(&body));
        // Whatever format the caller claims.
        for format in [Format::Gltf, Format::Glb, Format::Bvh] {
            let e = import(&body, format, &ImportOptions::default()).unwrap_err();
            assert_eq!((e.code(), e.class()), ("fbx_not_supported", ErrorClass::UnsupportedFormat));
            let detail = e.to_string();
            assert!(detail.contains("Blender") && detail.contains("FBX2glTF"), "{detail}");
        }
    }
    assert!(matches!(detect(b"; a comment\nHIERARCHY", None), Err(ImportError::UnknownFormat)));
    assert!(matches!(detect(b"HIERARCHY\nROOT Hips", None), Ok(Format::Bvh)));
}

#[test]
fn up_z_turns_every_joint_by_minus_90_degrees_about_x() {
    let plain = import_file("bvh/131_01.bvh", &ImportOptions::default());
    let turned = import_file("bvh/131_01.bvh", &ImportOptions { up: UpAxis::Z, ..ImportOptions::default() });
    let (a, b) = (Clip::build(&plain.clips[0]).unwrap(), Clip::build(&turned.clips[0]).unwrap());
    for t in [0.0, 1.3, 4.0, 8.0] {
        for (p, q) in positions(&a, t).into_iter().zip(positions(&b, t)) {
            assert!(q.abs_diff_eq(z_to_y(p), 1e-4 * p.length().max(1.0)), "t {t}: {q} vs {p}");
        }
    }
    // A Y-up take turned as if it were Z-up now lies along Z, and says so.
    assert!(codes(&turned).contains(&("looks_z_up", "/HIERARCHY")), "{:?}", turned.warnings);
    assert!(!codes(&plain).iter().any(|(c, _)| *c == "looks_z_up"));
}

#[test]
fn scale_scales_every_position_and_the_skinned_mesh_still_fits_its_bones() {
    let plain = import_file("gltf/Fox/Fox.glb", &ImportOptions::default());
    let options = ImportOptions { scale: 0.01, up: UpAxis::Z, ..ImportOptions::default() };
    let changed = import_file("gltf/Fox/Fox.glb", &options);
    // Centimetres fixed; the fox turned stands on its tail, along Y: nothing lies along Z.
    assert_eq!(codes(&changed), []);
    let fixed = import_file("gltf/Fox/Fox.glb", &ImportOptions { scale: 0.01, ..ImportOptions::default() });
    assert_eq!(codes(&fixed), [], "scale=0.01, as the warning suggests, silences it");
    for (old, new) in plain.clips.iter().zip(&changed.clips) {
        let (a, b) = (Clip::build(old).unwrap(), Clip::build(new).unwrap());
        for t in [0.0, 0.3, 0.7] {
            for (p, q) in positions(&a, t).into_iter().zip(positions(&b, t)) {
                assert!(q.abs_diff_eq(z_to_y(p * 0.01), 1e-5 * p.length().max(1.0)), "{} t {t}", old.name);
            }
        }
    }
    // The mesh: positions C·p, and every palette joint's skinning matrix W·B
    // (bind pose: the rest) becomes C·(W·B)·C⁻¹.
    let (old_mesh, new_mesh) = (mesh_of(&plain), mesh_of(&changed));
    let c = Mat4::from_quat(Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2)) * Mat4::from_scale(Vec3::splat(0.01));
    for (p, q) in old_mesh.positions.chunks_exact(3).zip(new_mesh.positions.chunks_exact(3)) {
        let (p, q) = (Vec3::from_slice(p), Vec3::from_slice(q));
        assert!(q.abs_diff_eq(z_to_y(p * 0.01), 1e-6 * p.length().max(1.0)), "{q} vs {p}");
    }
    let rest_old = rest_world(&plain.clips[0]);
    let rest_new = rest_world(&changed.clips[0]);
    for (k, joint) in old_mesh.joints.iter().enumerate() {
        let skin_old = rest_old(joint) * Mat4::from_cols_array(&old_mesh.inverse_binds[k]);
        let skin_new = rest_new(joint) * Mat4::from_cols_array(&new_mesh.inverse_binds[k]);
        let expected = c * skin_old * c.inverse();
        assert!(skin_new.abs_diff_eq(expected, 1e-4), "{joint}: {skin_new} vs {expected}");
    }
}

fn mesh_of(imported: &Imported) -> mesh::Mesh {
    mesh::decode(imported.meshes[0].as_ref().expect("the fox keeps its mesh")).unwrap()
}

/// A joint's model-space rest matrix, by forward kinematics over the clip's skeleton.
fn rest_world(clip: &anim::ClipSpec) -> impl Fn(&str) -> Mat4 + '_ {
    move |name| {
        let joints = &clip.skeleton.as_ref().unwrap().joints;
        let mut m = Mat4::IDENTITY;
        let mut at = Some(name.to_owned());
        while let Some(n) = at {
            let j = joints.iter().find(|j| j.name == n).unwrap();
            m = Mat4::from_scale_rotation_translation(j.rest.scale, j.rest.rotation, j.rest.translation) * m;
            at = j.parent.clone();
        }
        m
    }
}

#[test]
fn clips_loop_by_default_and_take_the_playback_and_prefix_asked_for() {
    let fox = import_file("gltf/Fox/Fox.glb", &ImportOptions::default());
    assert!(fox.clips.iter().all(|c| c.playback == Playback::Loop));
    let options = ImportOptions {
        playback: Playback::PingPong,
        name_prefix: Some("animals/fox/".into()),
        ..ImportOptions::default()
    };
    let fox = import_file("gltf/Fox/Fox.glb", &options);
    let names: Vec<_> = fox.clips.iter().map(|c| (c.name.as_str(), c.playback)).collect();
    assert_eq!(
        names,
        [
            ("animals/fox/Survey", Playback::PingPong),
            ("animals/fox/Walk", Playback::PingPong),
            ("animals/fox/Run", Playback::PingPong)
        ]
    );
    let bvh = import_file("bvh/131_01.bvh", &ImportOptions { playback: Playback::Once, ..ImportOptions::default() });
    assert_eq!(bvh.clips[0].playback, Playback::Once);
}

#[test]
fn generic_animation_names_are_replaced_by_the_name_the_file_or_the_scene() {
    let mixamo = |scene: Option<&str>| {
        edited_gltf("gltf/CesiumMan/CesiumMan.gltf", |json| {
            json["animations"][0]["name"] = "mixamo.com".into();
            if let Some(scene) = scene {
                json["scenes"][0]["name"] = scene.into();
            }
        })
    };
    let named = |bytes: &[u8], options: ImportOptions| {
        let imported = import(bytes, Format::Gltf, &options).unwrap();
        (
            imported.clips[0].name.clone(),
            codes(&imported).into_iter().map(|(c, p)| (c.to_owned(), p.to_owned())).collect::<Vec<_>>(),
        )
    };
    let generic = vec![("generic_animation_name".to_owned(), "/animations/0/name".to_owned())];
    let with_file = ImportOptions { file_name: Some("Walking".into()), ..ImportOptions::default() };
    assert_eq!(named(&mixamo(Some("Hero")), with_file.clone()), ("Walking".into(), generic.clone()), "the file first");
    assert_eq!(
        named(&mixamo(Some("Hero")), ImportOptions::default()),
        ("Hero".into(), generic.clone()),
        "then the scene"
    );
    assert_eq!(
        named(&mixamo(Some("Scene")), ImportOptions::default()),
        ("mixamo.com".into(), generic),
        "else as it was"
    );
    let chosen = ImportOptions { name: Some("walk".into()), ..with_file };
    assert_eq!(named(&mixamo(None), chosen), ("walk".into(), vec![]), "a name given: nothing to warn of");
}

#[test]
fn a_skeleton_lying_along_z_is_reported_and_up_z_stands_it_up() {
    // RiggedSimple stands up through its `Z_UP` node: made identity, the file is Z-up.
    let flat = edited_gltf("gltf/RiggedSimple/RiggedSimple.gltf", |json| {
        json["nodes"][0]["matrix"] = serde_json::json!([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]);
    });
    let lying = import(&flat, Format::Gltf, &ImportOptions::default()).unwrap();
    assert!(codes(&lying).contains(&("looks_z_up", "/nodes")), "{:?}", lying.warnings);
    let detail = &lying.warnings.iter().find(|w| w.code == "looks_z_up").unwrap().detail;
    assert!(detail.contains("up=z"), "{detail}");
    let stood = import(&flat, Format::Gltf, &ImportOptions { up: UpAxis::Z, ..ImportOptions::default() }).unwrap();
    assert!(!codes(&stood).iter().any(|(c, _)| *c == "looks_z_up"), "{:?}", stood.warnings);
    let original = import_file("gltf/RiggedSimple/RiggedSimple.gltf", &ImportOptions::default());
    assert!(!codes(&original).iter().any(|(c, _)| *c == "looks_z_up"));
}

#[test]
fn translation_keys_under_a_parent_scaled_by_a_hundredth_are_reported_as_centimetres() {
    // Mixamo through Blender: an armature scaled 0.01 over a pose keyed in centimetres.
    let scaled =
        edited_glb("gltf/Fox/Fox.glb", |json| json["nodes"][0]["scale"] = serde_json::json!([0.01, 0.01, 0.01]));
    let imported = import(&scaled, Format::Glb, &ImportOptions::default()).unwrap();
    let translation = imported.clips[0].tracks.iter().position(|t| t.channel == anim::Channel::Translation).unwrap();
    let found: Vec<_> = codes(&imported);
    assert!(
        found.iter().any(|(c, p)| *c == "units_look_like_centimeters" && p.starts_with("/animations/0/channels/")),
        "{found:?}"
    );
    let w = imported.warnings.iter().find(|w| w.code == "units_look_like_centimeters").unwrap();
    assert!(
        w.detail.contains(&imported.clips[0].tracks[translation].joint) && w.detail.contains("Apply"),
        "{}",
        w.detail
    );
    assert!(!found.contains(&("units_look_like_centimeters", "/nodes")), "the fox itself is now in metres");
}
