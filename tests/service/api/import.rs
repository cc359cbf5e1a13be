//! `POST /v1/clips/import` on the real third-party files: every clip the
//! library importer yields is stored whole, and posing it over HTTP equals
//! importing and evaluating the same bytes in-process.

use anim::{Clip, SampleOptions, Sampler, Space};
use formats::import::{ErrorClass, Format, ImportOptions, import};
use serde_json::{Value, json};

use super::TestApp;
use crate::common::testdata;

/// Files whose buffers travel inside them, with their format and the number
/// of clips (animations) they hold.
const FILES: &[(&str, Format, usize)] = &[
    ("gltf/AnimatedTriangle/AnimatedTriangle.gltf", Format::Gltf, 1),
    ("gltf/BoxAnimated/BoxAnimated.gltf", Format::Gltf, 1),
    ("gltf/CesiumMan/CesiumMan.gltf", Format::Gltf, 1),
    ("gltf/RiggedSimple/RiggedSimple.gltf", Format::Gltf, 1),
    ("gltf/Fox/Fox.glb", Format::Glb, 3),
    ("bvh/131_01.bvh", Format::Bvh, 1),
    ("bvh/05_20-daz.bvh", Format::Bvh, 1),
];

#[tokio::test]
async fn every_self_contained_testdata_file_imports_and_poses_like_the_library() {
    let app = TestApp::start().await;
    for &(file, format, clips) in FILES {
        let bytes = testdata(file);
        // No ?format: the server infers it from the bytes.
        // Unnamed animations of two files are both `animation0`: each file in a folder of its own.
        let url = app.url(&format!("/v1/clips/import?name_prefix={file}/"));
        let resp = app.http.post(url).body(bytes.clone()).send().await.unwrap();
        assert_eq!(resp.status(), 201, "{file}: {}", resp.text().await.unwrap());
        let body: Value = resp.json().await.unwrap();
        let stored = body["clips"].as_array().unwrap();
        assert_eq!(stored.len(), clips, "{file}: clip count");

        let expected = import(&bytes, format, &ImportOptions::default()).unwrap();
        for (summary, spec) in stored.iter().zip(&expected.clips) {
            let clip = Clip::build(spec).unwrap();
            assert_eq!(summary["name"], format!("{file}/{}", spec.name), "{file}");
            assert_eq!(summary["joints"], clip.joint_count(), "{file}");
            let id = summary["id"].as_str().unwrap();
            let mut sampler = Sampler::new();
            for k in 0..4 {
                let t = clip.start() as f64 + clip.duration() as f64 * (k as f64 + 0.37) / 4.0;
                let url = app.url(&format!("/v1/clips/{id}/pose?t={t}&space=model"));
                let pose: Value = app.http.get(url).send().await.unwrap().json().await.unwrap();
                let options = SampleOptions { space: Space::Model, ..Default::default() };
                clip.sample(t, &options, &mut sampler);
                let joints = pose["joints"].as_array().unwrap();
                assert_eq!(joints.len(), clip.joint_count());
                for (j, joint) in joints.iter().enumerate() {
                    let want = sampler.pose().translations[j];
                    for (axis, got) in joint["translation"].as_array().unwrap().iter().enumerate() {
                        // The same f32 evaluation, through its shortest JSON form.
                        let got = got.as_f64().unwrap() as f32;
                        assert_eq!(got, want[axis], "{file} joint {j} axis {axis} t={t}");
                    }
                }
            }
        }
    }
    let all = app.list_all(100, None).await;
    assert_eq!(all.len(), FILES.iter().map(|f| f.2).sum::<usize>());
    app.stop().await;
}

#[tokio::test]
async fn bvh_options_and_morph_free_results() {
    let app = TestApp::start().await;
    let url = app.url("/v1/clips/import?format=bvh&interpolation=catmull_rom&name=walk&scale=0.0564");
    let resp = app.http.post(url).body(testdata("bvh/131_03.bvh")).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let body: Value = resp.json().await.unwrap();
    assert_eq!(body["clips"][0]["name"], "walk");
    assert_eq!(body["warnings"], json!([]), "warnings are always listed, and a CMU take in metres has none");
    let id = body["clips"][0]["id"].as_str().unwrap();
    let doc: Value = app.get_json(&format!("/v1/clips/{id}")).await;
    assert!(doc["tracks"].as_array().unwrap().iter().all(|t| t["interpolation"] == "catmull_rom"));
    app.stop().await;
}

/// Refusals carry the importer's code and the status of its class, and
/// store nothing.
#[tokio::test]
async fn bad_files_are_refused_whole_and_store_nothing() {
    let app = TestApp::builder().write_token("w").start().await;
    let interpolation_test = testdata("gltf/InterpolationTest/InterpolationTest.gltf");
    let external = import(&interpolation_test, Format::Gltf, &ImportOptions::default()).unwrap_err();
    let truncated = testdata("bvh/131_01.bvh")[..5000].to_vec();
    let cut = import(&truncated, Format::Bvh, &ImportOptions::default()).unwrap_err();
    let status_of = |class: ErrorClass| match class {
        ErrorClass::Malformed => 400,
        ErrorClass::TooLarge => 413,
        ErrorClass::Unprocessable => 422,
        ErrorClass::UnsupportedFormat => 415,
    };
    let cases: Vec<(&str, Vec<u8>, u16, &str)> = vec![
        ("short GLB header", b"glTF\x02\0\0\0".to_vec(), 400, ""),
        ("not a known format", b"hello, world".to_vec(), 400, "unknown_format"),
        ("a binary FBX", b"Kaydara FBX Binary  \x00\x1a\x00\xe8\x1c\x00\x00".to_vec(), 415, "fbx_not_supported"),
        ("an ASCII FBX", b"; FBX 7.4.0 project file\nFBXHeaderExtension:  {\n".to_vec(), 415, "fbx_not_supported"),
        ("external .bin buffer", interpolation_test, status_of(external.class()), external.code()),
        ("truncated BVH", truncated, status_of(cut.class()), cut.code()),
    ];
    for (what, body, status, code) in cases {
        let resp = app.http.post(app.url("/v1/clips/import")).bearer_auth("w").body(body).send().await.unwrap();
        assert_eq!(resp.status(), status, "{what}");
        assert_eq!(resp.headers()["content-type"], "application/problem+json", "{what}");
        let problem: Value = resp.json().await.unwrap();
        if !code.is_empty() {
            assert_eq!(problem["code"], code, "{what}: {problem}");
        }
        assert!(problem["detail"].as_str().is_some_and(|d| !d.is_empty()), "{what}");
    }
    let fox = testdata("gltf/Fox/Fox.glb");
    let no_token = app.http.post(app.url("/v1/clips/import")).body(fox.clone()).send().await.unwrap();
    assert_eq!(no_token.status(), 401);
    for (query, parameter) in [("format=obj", "format"), ("interpolation=cubic_hermite", "interpolation")] {
        let url = app.url(&format!("/v1/clips/import?{query}"));
        let resp = app.http.post(url).bearer_auth("w").body(fox.clone()).send().await.unwrap();
        assert_eq!(resp.status(), 400, "{query}");
        let problem: Value = resp.json().await.unwrap();
        assert_eq!(problem["parameter"], parameter);
    }
    assert!(app.list_all(100, Some("w")).await.is_empty(), "nothing stored");
    app.stop().await;
}

/// A `.gltf` whose buffer is a separate file imports when both travel in one
/// multipart upload (as a browser sends them); without the buffer it is refused.
#[tokio::test]
async fn multipart_uploads_carry_external_gltf_buffers() {
    use reqwest::multipart::{Form, Part};
    let app = TestApp::start().await;
    let gltf = testdata("gltf/InterpolationTest/InterpolationTest.gltf");
    let bin = testdata("gltf/InterpolationTest/interpolation.bin");
    let document = || Part::bytes(gltf.clone()).file_name("InterpolationTest.gltf");
    let form = Form::new().part("file", document()).part("buffer", Part::bytes(bin).file_name("interpolation.bin"));
    let resp = app.http.post(app.url("/v1/clips/import")).multipart(form).send().await.unwrap();
    assert_eq!(resp.status(), 201, "{}", resp.text().await.unwrap());
    let body: Value = resp.json().await.unwrap();
    assert_eq!(body["clips"].as_array().unwrap().len(), 9, "InterpolationTest has 9 animations");

    let alone = Form::new().part("file", document());
    let resp = app.http.post(app.url("/v1/clips/import")).multipart(alone).send().await.unwrap();
    assert_eq!(resp.status(), 422, "the document names a buffer the upload lacks");
    assert_eq!(resp.json::<Value>().await.unwrap()["code"], "external_uri");
    let no_document = Form::new().part("other", Part::bytes(b"x".to_vec()).file_name("notes.txt"));
    let resp = app.http.post(app.url("/v1/clips/import")).multipart(no_document).send().await.unwrap();
    assert_eq!(resp.status(), 400);
    assert_eq!(resp.json::<Value>().await.unwrap()["code"], "bad_upload");
    assert_eq!(app.list_all(100, None).await.len(), 9, "only the complete upload stored clips");
    app.stop().await;
}
