//! Spring chains at the edge (docs/springs.md): the `springs` fields of the
//! motion and clip documents, refused at their JSON pointers, and glTF
//! `VRMC_springBone` imported into the same shape (a small file built here).

use anim::spring::{ChainSpec, ColliderShape, JointParams, SpringParams};
use anim::{Channel, Clip, ClipSpec, Interpolation, Keys, SkeletonSpec, TrackSpec};
use base64::Engine as _;
use formats::import::{Format, ImportOptions, import};
use formats::wire::json::{ClipDoc, parse_clip_doc};
use formats::wire::motion::MotionDoc;
use formats::wire::spring::compile_springs;
use glam::Vec3;
use serde_json::json;

/// `root` → `a` → `b` → `c` along x, and `side` under `root`.
fn clip() -> Clip {
    let joint = |name: &str, parent: Option<&str>| anim::JointSpec {
        name: name.into(),
        parent: parent.map(Into::into),
        rest: anim::Transform { translation: Vec3::new(0.2, 0.0, 0.0), ..anim::Transform::IDENTITY },
        inverse_bind: None,
    };
    let joints = vec![
        joint("root", None),
        joint("a", Some("root")),
        joint("b", Some("a")),
        joint("c", Some("b")),
        joint("side", Some("root")),
    ];
    let hold =
        TrackSpec::new("root", Channel::Translation, Interpolation::Linear, vec![0.0], Keys::Vec3(vec![Vec3::ZERO]));
    Clip::build(&ClipSpec {
        name: "rig".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks: vec![hold],
        ..Default::default()
    })
    .unwrap()
}

/// The motion `{layers, …extra}` parsed, its springs checked and compiled.
fn motion_springs(extra: serde_json::Value) -> Result<usize, (String, String)> {
    let mut doc = json!({"layers": [{"clip": "rig"}]});
    doc.as_object_mut().unwrap().extend(extra.as_object().unwrap().clone());
    let doc: MotionDoc = serde_json::from_value(doc).unwrap();
    let spec = doc.springs("/motion").map_err(|e| (e.code.to_owned(), e.pointer))?;
    let springs = compile_springs(&spec, clip().skeleton(), "/motion").map_err(|e| (e.code.to_owned(), e.pointer))?;
    Ok(springs.spring_joints().len())
}

#[track_caller]
fn refused(extra: serde_json::Value, code: &str, pointer: &str) {
    assert_eq!(motion_springs(extra), Err((code.to_owned(), pointer.to_owned())));
}

#[test]
fn a_motion_without_springs_parses_as_before_and_runs_none() {
    let doc: MotionDoc = serde_json::from_str(r#"{"layers": [{"clip": "rig"}]}"#).unwrap();
    let spec = doc.springs("/motion").unwrap();
    assert!(spec.chains.is_empty());
    assert_eq!(spec.substep_hz, 120.0);
    assert!(!serde_json::to_string(&doc).unwrap().contains("spring"), "absent fields stay absent");
}

#[test]
fn a_motion_with_springs_compiles_with_its_defaults_and_round_trips() {
    let springs = json!({"springs": [{"name": "tail", "joints": ["a", "b", "c"], "gravity": [0, -9.81, 0],
        "joint_params": {"b": {"drag": 0.1}}, "colliders": [{"joint": "side", "capsule": {"tail": [0, 1, 0], "radius": 0.05}}]}],
        "spring_substep_hz": 240});
    assert_eq!(motion_springs(springs.clone()), Ok(2));
    let mut doc = json!({"layers": [{"clip": "rig"}]});
    doc.as_object_mut().unwrap().extend(springs.as_object().unwrap().clone());
    let parsed: MotionDoc = serde_json::from_value(doc).unwrap();
    let spec = parsed.springs("").unwrap();
    let chain = &spec.chains[0];
    assert_eq!(spec.substep_hz, 240.0);
    assert_eq!((chain.params.stiffness, chain.params.drag, chain.params.radius), (1.0, 0.4, 0.02));
    assert_eq!(chain.joint_params, vec![("b".to_owned(), JointParams { drag: Some(0.1), ..JointParams::default() })]);
    let again: MotionDoc = serde_json::from_str(&serde_json::to_string(&parsed).unwrap()).unwrap();
    assert_eq!(again, parsed);
}

#[test]
fn bad_springs_are_refused_at_their_pointers() {
    let chain = |extra: serde_json::Value| {
        let mut c = json!({"name": "s", "joints": ["a", "b", "c"]});
        c.as_object_mut().unwrap().extend(extra.as_object().unwrap().clone());
        json!({"springs": [c]})
    };
    refused(chain(json!({"joints": ["nope", "b"]})), "unknown_joint", "/motion/springs/0/joints/0");
    refused(chain(json!({"joints": ["a", "side"]})), "not_a_chain", "/motion/springs/0/joints/1");
    refused(chain(json!({"joints": ["b", "a"]})), "not_a_chain", "/motion/springs/0/joints/1");
    refused(chain(json!({"joints": ["a"]})), "spring_too_short", "/motion/springs/0/joints");
    refused(chain(json!({"drag": 1.5})), "drag_out_of_range", "/motion/springs/0/drag");
    refused(chain(json!({"stiffness": -1})), "stiffness_out_of_range", "/motion/springs/0/stiffness");
    refused(chain(json!({"radius": -0.1})), "radius_out_of_range", "/motion/springs/0/radius");
    refused(
        chain(json!({"joint_params": {"c": {"drag": 0.1}}})),
        "not_a_spring_joint",
        "/motion/springs/0/joint_params/c",
    );
    refused(
        chain(json!({"joint_params": {"a": {"drag": 2}}})),
        "drag_out_of_range",
        "/motion/springs/0/joint_params/a/drag",
    );
    let sphere = |joint: &str| json!({"colliders": [{"joint": joint, "sphere": {"radius": 0.1}}]});
    refused(chain(sphere("nope")), "unknown_joint", "/motion/springs/0/colliders/0/joint");
    refused(chain(sphere("b")), "collider_on_spring", "/motion/springs/0/colliders/0/joint");
    refused(chain(json!({"colliders": [{"joint": "root"}]})), "invalid_collider", "/motion/springs/0/colliders/0");
    let bad_radius = json!({"colliders": [{"joint": "root", "sphere": {"radius": -1}}]});
    refused(chain(bad_radius), "radius_out_of_range", "/motion/springs/0/colliders/0/sphere/radius");
    let two = json!({"springs": [{"name": "x", "joints": ["a", "b"]}, {"name": "y", "joints": ["a", "c"]}]});
    refused(two, "joint_in_two_springs", "/motion/springs/1/joints/0");
    let twins = json!({"springs": [{"name": "x", "joints": ["a", "b"]}, {"name": "x", "joints": ["b", "c"]}]});
    refused(twins, "duplicate_spring", "/motion/springs/1/name");
    refused(json!({"spring_substep_hz": 10}), "substep_hz_out_of_range", "/motion/spring_substep_hz");
    let typo: Result<MotionDoc, _> =
        serde_json::from_value(json!({"layers": [], "springs": [{"name": "s", "joints": [], "dragg": 1}]}));
    assert!(typo.is_err(), "unknown fields are refused");
}

#[test]
fn a_clip_document_carries_springs_at_its_root_pointers() {
    let body = json!({"name": "c", "tracks": [], "springs": [{"name": "s", "joints": ["a", "b"], "drag": -1}]});
    let doc = parse_clip_doc(body.to_string().as_bytes()).unwrap();
    let refusal = doc.springs().unwrap_err();
    assert_eq!((refusal.code, refusal.pointer.as_str()), ("drag_out_of_range", "/springs/0/drag"));
    let plain = ClipDoc::from_spec(&ClipSpec { name: "c".into(), ..Default::default() });
    assert!(plain.springs.is_empty() && plain.springs().unwrap().chains.is_empty());
}

/// A small skinned glTF: `hips` → `head` → `hair1` → `hair2` → `hair_end`
/// (the last no joint of the skin), a two-key rotation of `hips`, and a
/// `VRMC_springBone` extension with two springs, the second impossible (its
/// collider rides on a joint it turns).
fn vrm_gltf() -> Vec<u8> {
    let mut bin = Vec::new();
    for f in [0.0f32, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.3826834, 0.0, 0.9238795] {
        bin.extend_from_slice(&f.to_le_bytes());
    }
    let uri =
        format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&bin));
    let node =
        |name: &str, t: [f32; 3], children: &[usize]| json!({"name": name, "translation": t, "children": children});
    json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [
            node("hips", [0.0, 1.0, 0.0], &[1]),
            node("head", [0.0, 0.5, 0.0], &[2]),
            node("hair1", [0.0, 0.1, -0.1], &[3]),
            node("hair2", [0.0, 0.0, -0.15], &[4]),
            node("hair_end", [0.0, 0.0, -0.15], &[]),
        ],
        "skins": [{"joints": [0, 1, 2, 3]}],
        "buffers": [{"byteLength": 40, "uri": uri}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 8}, {"buffer": 0, "byteOffset": 8, "byteLength": 32}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]},
            {"bufferView": 1, "componentType": 5126, "count": 2, "type": "VEC4"}
        ],
        "animations": [{"name": "turn", "samplers": [{"input": 0, "output": 1}], "channels": [{"sampler": 0, "target": {"node": 0, "path": "rotation"}}]}],
        "extensionsUsed": ["VRMC_springBone"],
        "extensions": {"VRMC_springBone": {
            "specVersion": "1.0",
            "colliders": [
                {"node": 1, "shape": {"sphere": {"offset": [0, 0.1, 0.05], "radius": 0.08}}},
                {"node": 0, "shape": {"capsule": {"offset": [0, 0, 0], "tail": [0, 0.3, 0], "radius": 0.1}}}
            ],
            "colliderGroups": [{"name": "head", "colliders": [0]}, {"name": "body", "colliders": [1, 0]}],
            "springs": [
                {"name": "hair", "colliderGroups": [0, 1], "joints": [
                    {"node": 2, "hitRadius": 0.02, "stiffness": 0.8, "gravityPower": 0.5, "gravityDir": [0, -1, 0], "dragForce": 0.3},
                    {"node": 3, "hitRadius": 0.02, "stiffness": 0.5, "gravityPower": 0.5, "gravityDir": [0, -1, 0], "dragForce": 0.3},
                    {"node": 4}
                ]},
                {"name": "neck", "colliderGroups": [0], "joints": [{"node": 0}, {"node": 1}]}
            ]
        }}
    })
    .to_string()
    .into_bytes()
}

#[test]
fn vrm_spring_bones_import_as_chains_with_their_colliders() {
    let imported = import(&vrm_gltf(), Format::Gltf, &ImportOptions::default()).unwrap();
    let clip = &imported.clips[0];
    let names: Vec<&str> = clip.skeleton.as_ref().unwrap().joints.iter().map(|j| j.name.as_str()).collect();
    assert!(names.contains(&"hair_end"), "a chain's tail node joins the skeleton: {names:?}");
    let chains = &imported.springs[0];
    assert_eq!(chains.len(), 1, "the impossible chain is left out: {chains:?}");
    let hair = &chains[0];
    assert_eq!(hair.joints, ["hair1", "hair2", "hair_end"]);
    // gravityDir·gravityPower·60: VRM's displacement rate as an acceleration.
    let params = SpringParams { stiffness: 0.8, drag: 0.3, gravity: Vec3::new(0.0, -30.0, 0.0), radius: 0.02 };
    assert_eq!(hair.params, params);
    assert_eq!(
        hair.joint_params,
        vec![("hair2".to_owned(), JointParams { stiffness: Some(0.5), ..JointParams::default() })]
    );
    let shapes: Vec<(&str, ColliderShape)> = hair.colliders.iter().map(|c| (c.joint.as_str(), c.shape)).collect();
    assert_eq!(
        shapes,
        [
            ("head", ColliderShape::Sphere { offset: Vec3::new(0.0, 0.1, 0.05), radius: 0.08 }),
            ("hips", ColliderShape::Capsule { offset: Vec3::ZERO, tail: Vec3::new(0.0, 0.3, 0.0), radius: 0.1 }),
        ],
        "groups in order, each collider once"
    );
    let warning = imported.warnings.iter().find(|w| w.pointer == "/extensions/VRMC_springBone/springs/1").unwrap();
    assert!(warning.detail.contains("collider_on_spring"), "{}", warning.detail);

    // The chains go into the clip document and compile on the built clip.
    let mut doc = ClipDoc::from_spec(clip);
    doc.springs = chains.iter().map(formats::wire::spring::SpringDoc::from_spec).collect();
    let reparsed = parse_clip_doc(serde_json::to_string(&doc).unwrap().as_bytes()).unwrap();
    let built = Clip::build(&reparsed.to_spec().unwrap()).unwrap();
    let springs = compile_springs(&reparsed.springs().unwrap(), built.skeleton(), "").unwrap();
    assert_eq!(springs.spring_joints().len(), 2);
}

#[test]
fn vrm_springs_follow_the_import_scale() {
    let options = ImportOptions { scale: 0.01, ..ImportOptions::default() };
    let imported = import(&vrm_gltf(), Format::Gltf, &options).unwrap();
    let hair: &ChainSpec = &imported.springs[0][0];
    assert!((hair.params.radius - 0.0002).abs() < 1e-9);
    assert!((hair.params.gravity.y + 0.3).abs() < 1e-6);
    let ColliderShape::Sphere { offset, radius } = hair.colliders[0].shape else { panic!("a sphere first") };
    assert!((offset - Vec3::new(0.0, 0.001, 0.0005)).length() < 1e-9 && (radius - 0.0008).abs() < 1e-9);
}
