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
    for (rel, clips) in
        [("gltf/InterpolationTest/InterpolationTest.gltf", 9), ("gltf/Fox/Fox.glb", 3), ("bvh/05_20-daz.bvh", 1)]
    {
        let path = testdata(rel);
        let out = import_ok(&[path.to_str().unwrap()]);
        let docs = out["clips"].as_array().unwrap();
        assert_eq!(docs.len(), clips, "{rel}");
        assert_eq!(out["warnings"], json!([]));
        for doc in docs {
            let (_, spec) = parse_clip(&serde_json::to_vec(doc).unwrap()).unwrap();
            Clip::build(&spec).unwrap();
        }
    }
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
