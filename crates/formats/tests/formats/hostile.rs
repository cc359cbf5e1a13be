//! Bad and hostile files: each is refused with the expected code, without a
//! panic and without allocating from a lying header.

use base64::Engine as _;
use formats::import::{ErrorClass, Format, ImportLimits, ImportOptions, import};
use serde_json::{Value, json};

use super::reference::read;

fn b64(bytes: &[u8]) -> String {
    format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(bytes))
}

fn floats(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// A valid glTF: node 0 translated by a 2-key LINEAR animation. Buffer 0
/// holds the times (8 bytes) then the values (24 bytes).
fn mini() -> Value {
    let data = floats(&[0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0]);
    json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "box"}],
        "buffers": [{"byteLength": 32, "uri": b64(&data)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 8},
            {"buffer": 0, "byteOffset": 8, "byteLength": 24}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]},
            {"bufferView": 1, "componentType": 5126, "count": 2, "type": "VEC3"}
        ],
        "animations": [{
            "name": "move",
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
            "samplers": [{"input": 0, "output": 1, "interpolation": "LINEAR"}]
        }]
    })
}

pub fn gltf(edit: impl FnOnce(&mut Value)) -> Vec<u8> {
    let mut doc = mini();
    edit(&mut doc);
    serde_json::to_vec(&doc).unwrap()
}

fn glb(json: &[u8], bin: Option<&[u8]>) -> Vec<u8> {
    let pad = |v: &mut Vec<u8>, with: u8| {
        while !v.len().is_multiple_of(4) {
            v.push(with)
        }
    };
    let mut j = json.to_vec();
    pad(&mut j, b' ');
    let mut out = b"glTF".to_vec();
    out.extend(2u32.to_le_bytes());
    out.extend(0u32.to_le_bytes());
    out.extend((j.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(&j);
    if let Some(bin) = bin {
        let mut b = bin.to_vec();
        pad(&mut b, 0);
        out.extend((b.len() as u32).to_le_bytes());
        out.extend(b"BIN\0");
        out.extend(&b);
    }
    let len = out.len() as u32;
    out[8..12].copy_from_slice(&len.to_le_bytes());
    out
}

/// A node chain `depth` long with the animation on its deepest node.
fn deep_gltf(depth: usize) -> Vec<u8> {
    gltf(|d| {
        let nodes: Vec<Value> =
            (0..depth).map(|i| if i + 1 < depth { json!({"children": [i + 1]}) } else { json!({}) }).collect();
        d["nodes"] = Value::Array(nodes);
        d["animations"][0]["channels"][0]["target"]["node"] = json!(depth - 1);
    })
}

const BVH: &str = "HIERARCHY\nROOT hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n  JOINT spine\n  {\n    OFFSET 0 1 0\n    CHANNELS 3 Zrotation Xrotation Yrotation\n    End Site\n    {\n      OFFSET 0 1 0\n    }\n  }\n}\nMOTION\nFrames: 2\nFrame Time: 0.5\n0 0 0 0 0 0 0 0 0\n1 2 3 10 20 30 40 50 60\n";

fn bvh(from: &str, to: &str) -> Vec<u8> {
    assert!(BVH.contains(from), "{from}");
    BVH.replacen(from, to, 1).into_bytes()
}

fn deep_bvh(depth: usize) -> Vec<u8> {
    let mut s = String::from("HIERARCHY\nROOT j0\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n");
    for i in 1..depth {
        s.push_str(&format!("JOINT j{i}\n{{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"));
    }
    s.push_str(&"}\n".repeat(depth));
    s.push_str("MOTION\nFrames: 1\nFrame Time: 0.1\n");
    s.push_str(&"0 0 0 ".repeat(depth));
    s.push('\n');
    s.into_bytes()
}

#[test]
fn the_valid_baselines_import() {
    let imported = import(&gltf(|_| {}), Format::Gltf, &ImportOptions::default()).unwrap();
    assert_eq!(imported.clips[0].name, "move");
    let glb_bytes = glb(&gltf(|_| {}), None);
    assert_eq!(import(&glb_bytes, Format::Glb, &ImportOptions::default()).unwrap().clips.len(), 1);
    let imported = import(BVH.as_bytes(), Format::Bvh, &ImportOptions::default()).unwrap();
    let names: Vec<_> = imported.clips[0].skeleton.as_ref().unwrap().joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["hips", "spine", "spine_end"]);
    assert!(import(&deep_gltf(200), Format::Gltf, &ImportOptions::default()).is_ok());
    assert!(import(&deep_bvh(200), Format::Bvh, &ImportOptions::default()).is_ok());
}

#[test]
fn hostile_inputs_are_refused_with_a_reason() {
    let fox = read("gltf/Fox/Fox.glb");
    let interpolation_test = read("gltf/InterpolationTest/InterpolationTest.gltf");
    let nan = floats(&[0.0, 1.0, 0.0, 0.0, 0.0, f32::NAN, 2.0, 3.0]);
    let cases: Vec<(&str, Vec<u8>, Format, &str)> = vec![
        // Containers.
        ("empty glb", vec![], Format::Glb, "bad_container"),
        ("short glb header", b"glTF\x02\0\0\0".to_vec(), Format::Glb, "bad_container"),
        ("glb length under 12", b"glTF\x02\0\0\0\x04\0\0\0\0\0\0\0".to_vec(), Format::Glb, "bad_container"),
        ("truncated glb", fox[..1000].to_vec(), Format::Glb, "bad_container"),
        (
            "glb version 1",
            {
                let mut f = fox.clone();
                f[4] = 1;
                f
            },
            Format::Glb,
            "bad_container",
        ),
        (
            "glb chunk past the end",
            {
                let mut f = fox.clone();
                f[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
                f
            },
            Format::Glb,
            "bad_container",
        ),
        ("glb with broken json", glb(b"{\"asset\":", None), Format::Glb, "bad_json"),
        (
            "glb buffer without BIN chunk",
            glb(
                &gltf(|d| {
                    d["buffers"][0].as_object_mut().unwrap().remove("uri");
                }),
                None,
            ),
            Format::Glb,
            "invalid_gltf",
        ),
        ("empty gltf", vec![], Format::Gltf, "bad_json"),
        ("not json", b"HIERARCHY".to_vec(), Format::Gltf, "bad_json"),
        // URIs: never fetched.
        ("%FF uri", gltf(|d| d["buffers"][0]["uri"] = json!("%FF")), Format::Gltf, "external_uri"),
        ("file: uri", gltf(|d| d["buffers"][0]["uri"] = json!("file:///etc/passwd")), Format::Gltf, "external_uri"),
        ("../ uri", gltf(|d| d["buffers"][0]["uri"] = json!("../../etc/passwd")), Format::Gltf, "external_uri"),
        (
            "http: uri",
            gltf(|d| d["buffers"][0]["uri"] = json!("http://127.0.0.1:9/x.bin")),
            Format::Gltf,
            "external_uri",
        ),
        ("sibling .bin without a resolver", interpolation_test, Format::Gltf, "external_uri"),
        (
            "bad base64",
            gltf(|d| d["buffers"][0]["uri"] = json!("data:application/octet-stream;base64,@@@@")),
            Format::Gltf,
            "bad_data_uri",
        ),
        (
            "data uri without comma",
            gltf(|d| d["buffers"][0]["uri"] = json!("data:application/octet-stream;base64")),
            Format::Gltf,
            "bad_data_uri",
        ),
        // Lengths and counts.
        ("byteLength 2^64-1", gltf(|d| d["buffers"][0]["byteLength"] = json!(u64::MAX)), Format::Gltf, "out_of_bounds"),
        (
            "byteLength over the data",
            gltf(|d| d["buffers"][0]["byteLength"] = json!(33)),
            Format::Gltf,
            "out_of_bounds",
        ),
        (
            "sparse accessors of 10^5 keys from a few bytes",
            gltf(|d| {
                for a in 0..2 {
                    d["accessors"][a].as_object_mut().unwrap().remove("bufferView");
                    d["accessors"][a]["count"] = json!(100_000);
                    d["accessors"][a]["sparse"] = json!({
                        "count": 1,
                        "indices": {"bufferView": 0, "componentType": 5125},
                        "values": {"bufferView": 1}
                    });
                }
            }),
            Format::Gltf,
            "too_large",
        ),
        (
            "huge accessor count",
            gltf(|d| d["accessors"][0]["count"] = json!(4_000_000_000u64)),
            Format::Gltf,
            "too_large",
        ),
        (
            "accessor count past its view",
            gltf(|d| {
                d["accessors"][0]["count"] = json!(1000);
                d["accessors"][1]["count"] = json!(1000);
            }),
            Format::Gltf,
            "out_of_bounds",
        ),
        (
            "accessor offset past its view",
            gltf(|d| d["accessors"][1]["byteOffset"] = json!(4)),
            Format::Gltf,
            "out_of_bounds",
        ),
        (
            "buffer view past its buffer",
            gltf(|d| d["bufferViews"][1]["byteOffset"] = json!(1u64 << 40)),
            Format::Gltf,
            "out_of_bounds",
        ),
        (
            "byteStride under the element size",
            gltf(|d| d["bufferViews"][1]["byteStride"] = json!(4)),
            Format::Gltf,
            "invalid_gltf",
        ),
        ("output count mismatch", gltf(|d| d["accessors"][1]["count"] = json!(1)), Format::Gltf, "invalid_gltf"),
        (
            "accessor index out of range",
            gltf(|d| d["animations"][0]["samplers"][0]["input"] = json!(99)),
            Format::Gltf,
            "invalid_gltf",
        ),
        (
            "node index out of range",
            gltf(|d| d["animations"][0]["channels"][0]["target"]["node"] = json!(7)),
            Format::Gltf,
            "invalid_gltf",
        ),
        (
            "unknown target path",
            gltf(|d| d["animations"][0]["channels"][0]["target"]["path"] = json!("colour")),
            Format::Gltf,
            "invalid_gltf",
        ),
        ("integer times", gltf(|d| d["accessors"][0]["componentType"] = json!(5125)), Format::Gltf, "unsupported"),
        ("vec4 translation", gltf(|d| d["accessors"][1]["type"] = json!("VEC4")), Format::Gltf, "invalid_gltf"),
        // Values.
        ("NaN in an accessor", gltf(|d| d["buffers"][0]["uri"] = json!(b64(&nan))), Format::Gltf, "non_finite"),
        (
            "times not increasing",
            gltf(|d| d["buffers"][0]["uri"] = json!(b64(&floats(&[1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0])))),
            Format::Gltf,
            "times_not_increasing",
        ),
        (
            "shear matrix",
            gltf(|d| {
                d["nodes"] =
                    json!([{"children": [1], "matrix": [1,0,0,0, 0.5,1,0,0, 0,0,1,0, 0,0,0,1]}, {"name": "box"}]);
                d["animations"][0]["channels"][0]["target"]["node"] = json!(1);
            }),
            Format::Gltf,
            "unsupported",
        ),
        (
            "singular matrix",
            gltf(|d| {
                d["nodes"] =
                    json!([{"children": [1], "matrix": [0,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}, {"name": "box"}]);
                d["animations"][0]["channels"][0]["target"]["node"] = json!(1);
            }),
            Format::Gltf,
            "unsupported",
        ),
        (
            "no animations",
            gltf(|d| {
                d.as_object_mut().unwrap().remove("animations");
            }),
            Format::Gltf,
            "no_animations",
        ),
        (
            "only weights",
            gltf(|d| d["animations"][0]["channels"][0]["target"]["path"] = json!("weights")),
            Format::Gltf,
            "no_animations",
        ),
        // Graphs.
        (
            "node cycle",
            gltf(|d| d["nodes"] = json!([{"children": [1]}, {"children": [0]}])),
            Format::Gltf,
            "not_a_tree",
        ),
        ("node its own child", gltf(|d| d["nodes"] = json!([{"children": [0]}])), Format::Gltf, "not_a_tree"),
        (
            "node with two parents",
            gltf(|d| d["nodes"] = json!([{"children": [2]}, {"children": [2]}, {}])),
            Format::Gltf,
            "not_a_tree",
        ),
        ("10 000-deep nodes", deep_gltf(10_000), Format::Gltf, "too_deep"),
        // BVH.
        ("empty bvh", vec![], Format::Bvh, "bvh_syntax"),
        ("no HIERARCHY", bvh("HIERARCHY", "HIERARCH"), Format::Bvh, "bvh_syntax"),
        ("no MOTION", bvh("MOTION", "MOTON"), Format::Bvh, "bvh_syntax"),
        ("unbalanced braces", bvh("    }\n  }\n}", "    }\n  }\n"), Format::Bvh, "bvh_syntax"),
        ("stray brace", bvh("MOTION", "}\nMOTION"), Format::Bvh, "bvh_syntax"),
        (
            "unknown channel",
            bvh("Zrotation Xrotation Yrotation\n    End", "Zrotation Xrotation Wrotation\n    End"),
            Format::Bvh,
            "count_mismatch",
        ),
        (
            "CHANNELS count over the names",
            bvh("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 4 Zrotation Xrotation Yrotation"),
            Format::Bvh,
            "count_mismatch",
        ),
        (
            "CHANNELS count under the names",
            bvh("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 2 Zrotation Xrotation Yrotation"),
            Format::Bvh,
            "count_mismatch",
        ),
        ("CHANNELS 7", bvh("CHANNELS 6", "CHANNELS 7"), Format::Bvh, "bvh_syntax"),
        (
            "duplicate channel",
            bvh("Zrotation Xrotation Yrotation\n    End", "Zrotation Zrotation Yrotation\n    End"),
            Format::Bvh,
            "bvh_syntax",
        ),
        ("NaN token", bvh("1 2 3 10", "1 NaN 3 10"), Format::Bvh, "non_finite"),
        ("inf token", bvh("1 2 3 10", "1 inf 3 10"), Format::Bvh, "non_finite"),
        ("1e400", bvh("1 2 3 10", "1 1e400 3 10"), Format::Bvh, "non_finite"),
        ("1e39 position", bvh("1 2 3 10", "1 1e39 3 10"), Format::Bvh, "non_finite"),
        ("NaN offset", bvh("OFFSET 0 1 0\n    CHANNELS", "OFFSET 0 nan 0\n    CHANNELS"), Format::Bvh, "non_finite"),
        ("not a number", bvh("1 2 3 10", "1 two 3 10"), Format::Bvh, "bvh_syntax"),
        ("Frame Time: 0", bvh("Frame Time: 0.5", "Frame Time: 0"), Format::Bvh, "bad_frame_time"),
        ("Frame Time: -1", bvh("Frame Time: 0.5", "Frame Time: -1"), Format::Bvh, "bad_frame_time"),
        ("Frame Time: 1e-50", bvh("Frame Time: 0.5", "Frame Time: 1e-50"), Format::Bvh, "bad_frame_time"),
        ("Frame Time: 1e39", bvh("Frame Time: 0.5", "Frame Time: 1e39"), Format::Bvh, "bad_frame_time"),
        ("Frame Time: nan", bvh("Frame Time: 0.5", "Frame Time: nan"), Format::Bvh, "bad_frame_time"),
        ("Frames: 4000000000 with a tiny body", bvh("Frames: 2", "Frames: 4000000000"), Format::Bvh, "too_large"),
        ("Frames: 999999 with a tiny body", bvh("Frames: 2", "Frames: 999999"), Format::Bvh, "count_mismatch"),
        ("Frames: -1", bvh("Frames: 2", "Frames: -1"), Format::Bvh, "bvh_syntax"),
        ("Frames: 0", bvh("Frames: 2", "Frames: 0"), Format::Bvh, "no_animations"),
        ("more frames than declared", bvh("Frames: 2", "Frames: 1"), Format::Bvh, "count_mismatch"),
        ("a frame short of values", bvh("40 50 60", "40 50"), Format::Bvh, "count_mismatch"),
        ("a frame with extra values", bvh("40 50 60", "40 50 60 70"), Format::Bvh, "count_mismatch"),
        ("missing Frame Time", bvh("Frame Time: 0.5\n", ""), Format::Bvh, "bvh_syntax"),
        ("10 000-deep hierarchy", deep_bvh(10_000), Format::Bvh, "too_deep"),
    ];
    for (name, bytes, format, code) in cases {
        match import(&bytes, format, &ImportOptions::default()) {
            Ok(imported) => panic!("{name}: imported {} clips", imported.clips.len()),
            Err(e) => {
                assert_eq!(e.code(), code, "{name}: {e}");
                assert!(!e.to_string().is_empty());
            }
        }
    }
}

#[test]
fn limits_are_enforced_and_classed_as_too_large() {
    let tight = |edit: fn(&mut ImportLimits)| {
        let mut options = ImportOptions::default();
        edit(&mut options.limits);
        options
    };
    let cases: Vec<(&str, Vec<u8>, Format, ImportOptions)> = vec![
        ("bytes", BVH.as_bytes().to_vec(), Format::Bvh, tight(|l| l.max_bytes = 10)),
        ("joints", BVH.as_bytes().to_vec(), Format::Bvh, tight(|l| l.max_joints = 2)),
        ("frames", BVH.as_bytes().to_vec(), Format::Bvh, tight(|l| l.max_frames = 1)),
        ("tracks", BVH.as_bytes().to_vec(), Format::Bvh, tight(|l| l.max_tracks = 2)),
        ("total keys", BVH.as_bytes().to_vec(), Format::Bvh, tight(|l| l.max_total_keys = 5)),
        ("keys per track", gltf(|_| {}), Format::Gltf, tight(|l| l.max_keys_per_track = 1)),
        ("clips", read("gltf/Fox/Fox.glb"), Format::Glb, tight(|l| l.max_clips = 2)),
        ("depth", deep_bvh(5), Format::Bvh, tight(|l| l.max_depth = 4)),
    ];
    for (name, bytes, format, options) in cases {
        let e = import(&bytes, format, &options).expect_err(name);
        assert_eq!(e.class(), ErrorClass::TooLarge, "{name}: {e}");
    }
}

#[test]
fn malformed_and_unprocessable_are_told_apart() {
    let e = import(b"glTF", Format::Glb, &ImportOptions::default()).unwrap_err();
    assert_eq!(e.class(), ErrorClass::Malformed);
    let e = import(&gltf(|d| d["buffers"][0]["uri"] = json!("x.bin")), Format::Gltf, &ImportOptions::default())
        .unwrap_err();
    assert_eq!(e.class(), ErrorClass::Unprocessable);
    assert!(e.to_string().contains("x.bin"), "{e}");
}

/// Weights of a node without a mesh of morph targets have nothing to weigh:
/// a `not_imported` warning with the reason (with targets they are a
/// parameter, docs/clip-format.md §3: `tests/service/api/parameters.rs`).
#[test]
fn morph_weights_of_a_node_without_targets_are_reported_as_not_imported() {
    let bytes = gltf(|d| {
        let weights = json!({"sampler": 0, "target": {"node": 0, "path": "weights"}});
        d["animations"][0]["channels"].as_array_mut().unwrap().push(weights);
    });
    let imported = import(&bytes, Format::Gltf, &ImportOptions::default()).unwrap();
    assert_eq!(imported.clips[0].tracks.len(), 1);
    assert_eq!(imported.warnings.len(), 1);
    assert_eq!(
        (imported.warnings[0].code.as_str(), imported.warnings[0].pointer.as_str()),
        ("not_imported", "/animations/0/channels/1")
    );
    assert!(imported.warnings[0].detail.contains("no mesh with morph targets"), "{:?}", imported.warnings);
}

#[test]
fn repeated_names_are_made_unique_with_the_node_index() {
    // Nodes 0 and 1 are both "bone"; 2 is literally "bone#1", so node 1
    // cannot take that and counts on from 2.
    let bytes = gltf(|d| {
        d["nodes"] = json!([{"name": "bone", "children": [1]}, {"name": "bone", "children": [2]}, {"name": "bone#1"}]);
        d["animations"][0]["channels"][0]["target"]["node"] = json!(2);
    });
    let imported = import(&bytes, Format::Gltf, &ImportOptions::default()).unwrap();
    let joints = &imported.clips[0].skeleton.as_ref().unwrap().joints;
    let names: Vec<(&str, Option<&str>)> = joints.iter().map(|j| (j.name.as_str(), j.parent.as_deref())).collect();
    assert_eq!(names, [("bone", None), ("bone#2", Some("bone")), ("bone#1", Some("bone#2"))]);
    assert_eq!(imported.clips[0].tracks[0].joint, "bone#1");

    let bvh_bytes = bvh("JOINT spine", "JOINT hips");
    let imported = import(&bvh_bytes, Format::Bvh, &ImportOptions::default()).unwrap();
    let names: Vec<_> = imported.clips[0].skeleton.as_ref().unwrap().joints.iter().map(|j| j.name.clone()).collect();
    assert_eq!(names, ["hips", "hips#1", "hips_end"]);
}

#[test]
fn sparse_accessors_are_zeros_with_the_stored_values_substituted() {
    // The output has no buffer view: zeros, with element 1 replaced by (1, 2, 3)
    // from a second buffer (index u32 1, then the three floats).
    let mut sparse_data = 1u32.to_le_bytes().to_vec();
    sparse_data.extend(floats(&[1.0, 2.0, 3.0]));
    let bytes = gltf(|d| {
        d["buffers"].as_array_mut().unwrap().push(json!({"byteLength": 16, "uri": b64(&sparse_data)}));
        d["bufferViews"].as_array_mut().unwrap().push(json!({"buffer": 1, "byteOffset": 0, "byteLength": 4}));
        d["bufferViews"].as_array_mut().unwrap().push(json!({"buffer": 1, "byteOffset": 4, "byteLength": 12}));
        d["accessors"][1].as_object_mut().unwrap().remove("bufferView");
        d["accessors"][1]["sparse"] = json!({
            "count": 1,
            "indices": {"bufferView": 2, "componentType": 5125},
            "values": {"bufferView": 3}
        });
    });
    let imported = import(&bytes, Format::Gltf, &ImportOptions::default()).unwrap();
    let expected = anim::Keys::Vec3(vec![glam::Vec3::ZERO, glam::Vec3::new(1.0, 2.0, 3.0)]);
    assert_eq!(imported.clips[0].tracks[0].values, expected);
}
