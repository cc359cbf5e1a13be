//! `inbetween import` as a user runs it: the real binary, on the real files.

use std::process::{Command, Output};

use anim::Clip;
use formats::wire::json::parse_clip;
use serde_json::{Value, json};

use crate::common::testdata_path as testdata;

fn inbetween(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_inbetween")).args(args).output().expect("run inbetween")
}

/// Runs `inbetween import` and returns its parsed stdout.
fn import_ok(args: &[&str]) -> Value {
    let out = inbetween(&[&["import"], args].concat());
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("stdout is JSON")
}

#[test]
fn prints_clip_documents_that_parse_and_build() {
    // Fox and the DAZ take are in centimetres: said, and silenced by the scale the warning names.
    for (rel, clips, units) in [
        ("gltf/InterpolationTest/InterpolationTest.gltf", 9, None),
        ("gltf/Fox/Fox.glb", 3, Some("/nodes")),
        ("bvh/05_20-daz.bvh", 1, Some("/HIERARCHY")),
    ] {
        let path = testdata(rel);
        let out = import_ok(&[path.to_str().unwrap()]);
        let docs = out["clips"].as_array().unwrap();
        assert_eq!(docs.len(), clips, "{rel}");
        let expected = units.map_or(json!([]), |at| json!([["units_look_like_centimeters", at]]));
        let codes: Vec<Value> =
            (out["warnings"].as_array().unwrap().iter()).map(|w| json!([w["code"], w["pointer"]])).collect();
        assert_eq!(Value::from(codes), expected, "{rel}");
        let scaled = import_ok(&[path.to_str().unwrap(), "--scale", "0.01"]);
        assert_eq!(scaled["warnings"], json!([]), "{rel} with --scale 0.01");
        for doc in docs {
            assert_eq!(doc["playback"], "loop", "imports loop by default");
            let (_, spec) = parse_clip(&serde_json::to_vec(doc).unwrap()).unwrap();
            Clip::build(&spec).unwrap();
        }
    }
    let once =
        import_ok(&[testdata("gltf/Fox/Fox.glb").to_str().unwrap(), "--playback", "once", "--name-prefix", "fox/"]);
    assert_eq!(
        (once["clips"][1]["name"].as_str(), once["clips"][1]["playback"].as_str()),
        (Some("fox/Walk"), Some("once"))
    );
    let bvh = import_ok(&[testdata("bvh/131_01.bvh").to_str().unwrap(), "--interpolation", "catmull_rom"]);
    assert_eq!(bvh["clips"][0]["name"], "131_01", "BVH clips are named after the file");
    assert_eq!(bvh["clips"][0]["tracks"][0]["interpolation"], "catmull_rom");
    let smooth = import_ok(&[testdata("bvh/131_01.bvh").to_str().unwrap(), "--interpolation", "b_spline"]);
    let tracks = smooth["clips"][0]["tracks"].as_array().unwrap();
    assert!(tracks.iter().all(|t| t["interpolation"] == "b_spline"), "every BVH track smoothed");
    let (_, spec) = parse_clip(&serde_json::to_vec(&smooth["clips"][0]).unwrap()).unwrap();
    Clip::build(&spec).unwrap();
}

#[test]
fn reads_only_plain_sibling_buffers() {
    let dir = tempfile::tempdir().unwrap();
    let source = std::fs::read_to_string(testdata("gltf/InterpolationTest/InterpolationTest.gltf")).unwrap();
    std::fs::copy(testdata("gltf/InterpolationTest/interpolation.bin"), dir.path().join("interpolation.bin")).unwrap();
    let sub = dir.path().join("sub");
    std::fs::create_dir(&sub).unwrap();
    for (uri, ok) in [
        ("interpolation.bin", true),
        ("interpolation%2Ebin", true),
        ("../interpolation.bin", false),
        ("%2E%2E%2Finterpolation.bin", false),
        ("file:///etc/passwd", false),
        ("/etc/passwd", false),
        ("%FF", false),
    ] {
        let file = sub.join("model.gltf");
        if uri.contains("..") || uri.contains("%2E%2E") {
            // The .bin sits one level up: reachable only through `..`.
            std::fs::write(&file, source.replace("\"interpolation.bin\"", &format!("\"{uri}\""))).unwrap();
        } else {
            std::fs::copy(dir.path().join("interpolation.bin"), sub.join("interpolation.bin")).unwrap();
            std::fs::write(&file, source.replace("\"interpolation.bin\"", &format!("\"{uri}\""))).unwrap();
        }
        let out = inbetween(&["import", file.to_str().unwrap()]);
        assert_eq!(out.status.success(), ok, "{uri}: {}", String::from_utf8_lossy(&out.stderr));
        if !ok {
            assert!(String::from_utf8_lossy(&out.stderr).contains("external_uri"), "{uri}");
        }
    }
}

#[test]
fn reports_bad_files_on_stderr_with_the_code() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("broken.bvh");
    std::fs::write(
        &file,
        "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n}\nMOTION\nFrames: 1\nFrame Time: 0\n0\n",
    )
    .unwrap();
    let out = inbetween(&["import", file.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(out.stdout.is_empty());
    assert!(String::from_utf8_lossy(&out.stderr).contains("bad_frame_time"));
}

/// An FBX file is refused by name with the conversion, not with a hint to
/// pass `--format`, whatever its extension.
#[test]
fn an_fbx_file_is_refused_with_the_conversion() {
    let dir = tempfile::tempdir().unwrap();
    for (name, body) in [
        ("hero.fbx", &b"Kaydara FBX Binary  \x00\x1a\x00\xe8\x1c\x00\x00"[..]),
        ("hero.dat", &b"; FBX 7.4.0 project file\nFBXHeaderExtension:  {\n"[..]),
        ("ascii.fbx", &b"FBXHeaderExtension:  {\n"[..]),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, body).unwrap();
        let out = inbetween(&["import", path.to_str().unwrap()]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{name}");
        assert!(
            stderr.contains("fbx_not_supported") && stderr.contains("FBX2glTF") && stderr.contains("Blender"),
            "{stderr}"
        );
        assert!(!stderr.contains("--format"), "{name}: converting, not --format, is the fix: {stderr}");
    }
}
