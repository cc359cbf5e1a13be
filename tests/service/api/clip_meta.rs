//! Names, tags, metadata, PATCH and the skeleton route (issue 18): imported
//! clips named after their files on every import path, tags and metadata
//! kept and checked, merge patches with and without `If-Match` (their
//! events reaching new streams), and the skeleton a few KB where the
//! document is megabytes.

use formats::wire::proto::pb;
use futures_util::StreamExt;
use reqwest::multipart::{Form, Part};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::{TestApp, WAVE, within};
use crate::common::{ServerProcess, testdata, testdata_path};

/// The names of the clips an import answered with.
async fn imported_names(resp: reqwest::Response) -> Vec<String> {
    let status = resp.status();
    let body: Value = resp.json().await.unwrap();
    assert_eq!(status, 201, "{body}");
    body["clips"].as_array().unwrap().iter().map(|c| c["name"].as_str().unwrap().to_owned()).collect()
}

async fn multipart(app: &TestApp, query: &str, file_name: &str, bytes: Vec<u8>) -> Vec<String> {
    let form = Form::new().part("file", Part::bytes(bytes).file_name(file_name.to_owned()));
    let url = app.url(&format!("/v1/clips/import{query}"));
    imported_names(app.http.post(url).multipart(form).send().await.unwrap()).await
}

#[tokio::test]
async fn imports_are_named_from_the_query_the_file_name_or_the_file() {
    let app = TestApp::start().await;
    let bvh = testdata("bvh/131_03.bvh");
    let raw = |query: &str| app.http.post(app.url(&format!("/v1/clips/import{query}"))).body(bvh.clone()).send();
    assert_eq!(imported_names(raw("?name=take-3").await.unwrap()).await, ["take-3"], "?name= wins");
    assert_eq!(imported_names(raw("").await.unwrap()).await, ["bvh"], "a raw body has no file name");
    // A browser's upload (the viewer's, curl -F): the part's file name.
    assert_eq!(multipart(&app, "", "131_03.bvh", bvh.clone()).await, ["131_03"]);
    assert_eq!(multipart(&app, "?name=walk", "131_03.bvh", bvh.clone()).await, ["walk"], "?name= beats the file");
    // A glTF animation without a name is named after the file; named ones keep their own.
    let cesium = testdata("gltf/CesiumMan/CesiumMan.gltf");
    assert_eq!(multipart(&app, "", "CesiumMan.gltf", cesium).await, ["CesiumMan"]);
    let fox = testdata("gltf/Fox/Fox.glb");
    assert_eq!(multipart(&app, "", "Fox.glb", fox).await, ["Survey", "Walk", "Run"]);
    app.stop().await;
}

/// `inbetween import ARGS…`, run without blocking the test's runtime (the
/// in-process server shares it): its standard output as JSON.
async fn cli_import(args: &[&std::ffi::OsStr]) -> Value {
    let mut command = tokio::process::Command::from(ServerProcess::command());
    command.arg("import").args(args).stdin(std::process::Stdio::null());
    let out = within(60, "inbetween import", command.output()).await.unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[tokio::test]
async fn the_cli_names_clips_after_the_file_too() {
    let app = TestApp::start().await;
    let base = app.url("");
    for (file, name) in [("bvh/131_03.bvh", "131_03"), ("gltf/CesiumMan/CesiumMan.gltf", "CesiumMan")] {
        let path = testdata_path(file);
        // To JSON, no server.
        let printed = cli_import(&[path.as_os_str()]).await;
        assert_eq!(printed["clips"][0]["name"], name, "{file}");
        // Uploaded.
        let created = cli_import(&[path.as_os_str(), "--server".as_ref(), base.as_ref()]).await;
        let id = created["clips"][0]["id"].as_str().unwrap();
        assert_eq!(app.get_json(&format!("/v1/clips/{id}")).await["name"], name, "{file}");
    }
    let path = testdata_path("bvh/131_03.bvh");
    let printed = cli_import(&[path.as_os_str(), "--name".as_ref(), "x".as_ref()]).await;
    assert_eq!(printed["clips"][0]["name"], "x", "--name wins");
    app.stop().await;
}

/// WAVE with `extra` fields merged in at the top level.
fn wave_with(extra: Value) -> String {
    let mut doc: Value = serde_json::from_str(WAVE).unwrap();
    for (k, v) in extra.as_object().unwrap() {
        doc[k] = v.clone();
    }
    doc.to_string()
}

async fn problem(resp: reqwest::Response) -> (u16, Value) {
    let status = resp.status().as_u16();
    (status, resp.json().await.unwrap())
}

#[tokio::test]
async fn tags_and_metadata_round_trip_and_are_checked() {
    let app = TestApp::start().await;
    let metadata = json!({"source": "mocap", "take": 3, "nested": {"fps": 120, "actors": ["a", "b"]}});
    let summary = app.create(&wave_with(json!({"tags": ["greeting", "upper body"], "metadata": metadata})), None).await;
    assert_eq!(summary["tags"], json!(["greeting", "upper body"]));
    let id = summary["id"].as_str().unwrap();
    let doc = app.get_json(&format!("/v1/clips/{id}")).await;
    assert_eq!((&doc["tags"], &doc["metadata"]), (&json!(["greeting", "upper body"]), &metadata));
    let listed = app.get_json("/v1/clips?tag=greeting").await;
    assert_eq!(listed["clips"][0]["tags"], json!(["greeting", "upper body"]));
    // Without either, the document has neither and the summary an empty list.
    let plain = app.create(&WAVE.replacen("\"wave\"", "\"plain\"", 1), None).await;
    assert_eq!(plain["tags"], json!([]));
    let plain_doc = app.get_json(&format!("/v1/clips/{}", plain["id"].as_str().unwrap())).await;
    assert!(plain_doc.get("tags").is_none() && plain_doc.get("metadata").is_none(), "{plain_doc}");

    let big = "x".repeat(16 * 1024);
    let cases = [
        (json!({"tags": ["a", "a"]}), "duplicate_tag", "/tags/1"),
        (json!({"tags": [""]}), "bad_tag", "/tags/0"),
        (json!({"tags": [" padded"]}), "bad_tag", "/tags/0"),
        (json!({"tags": ["tab\there"]}), "bad_tag", "/tags/0"),
        (json!({"tags": ["x".repeat(65)]}), "bad_tag", "/tags/0"),
        (json!({"tags": (0..33).map(|i| format!("t{i}")).collect::<Vec<_>>()}), "too_many_tags", "/tags"),
        (json!({"metadata": {"blob": big}}), "metadata_too_large", "/metadata"),
    ];
    for (extra, code, pointer) in cases {
        let resp = app.http.post(app.url("/v1/clips")).header("content-type", "application/json");
        let (status, body) = problem(resp.body(wave_with(extra.clone())).send().await.unwrap()).await;
        assert_eq!(
            (status, body["code"].as_str(), body["pointer"].as_str()),
            (422, Some(code), Some(pointer)),
            "{extra}: {body}"
        );
    }
    // Metadata is an object, tags strings: type errors at their pointers.
    for (extra, pointer) in [(json!({"metadata": [1]}), "/metadata"), (json!({"tags": [1]}), "/tags/0")] {
        let resp = app.http.post(app.url("/v1/clips")).header("content-type", "application/json");
        let (status, body) = problem(resp.body(wave_with(extra.clone())).send().await.unwrap()).await;
        assert_eq!(status, 422, "{extra}: {body}");
        assert!(body["pointer"].as_str().unwrap().starts_with(pointer), "{extra}: {body}");
    }
    assert_eq!(app.list_all(100, None).await.len(), 2, "nothing refused was stored");
    app.stop().await;
}

async fn patch(app: &TestApp, id: &str, if_match: Option<&str>, body: Value) -> reqwest::Response {
    let mut req =
        app.http.patch(app.url(&format!("/v1/clips/{id}"))).header("content-type", "application/merge-patch+json");
    if let Some(tag) = if_match {
        req = req.header("if-match", tag);
    }
    req.body(body.to_string()).send().await.unwrap()
}

#[tokio::test]
async fn patch_merges_beside_the_motion_and_honours_if_match() {
    let app = TestApp::start().await;
    let created = app.create(&wave_with(json!({"tags": ["a"], "metadata": {"keep": 1, "drop": 2}})), None).await;
    let id = created["id"].as_str().unwrap().to_owned();
    let before = app.get_json(&format!("/v1/clips/{id}")).await;

    let changes = json!({"name": "wave-2", "tags": ["b", "c"], "metadata": {"drop": null, "add": {"x": 1}}, "playback": "ping_pong"});
    let resp = patch(&app, &id, Some("\"1\""), changes).await;
    assert_eq!(resp.status(), 200);
    assert_eq!(resp.headers()["etag"], "\"2\"");
    let summary: Value = resp.json().await.unwrap();
    assert_eq!(
        (summary["version"].as_u64(), &summary["name"], &summary["playback"]),
        (Some(2), &json!("wave-2"), &json!("ping_pong"))
    );
    let after = app.get_json(&format!("/v1/clips/{id}")).await;
    assert_eq!(after["metadata"], json!({"keep": 1, "add": {"x": 1}}), "merged key by key, null removed");
    assert_eq!(after["tags"], json!(["b", "c"]));
    assert_eq!(
        (&after["tracks"], &after["skeleton"], &after["events"]),
        (&before["tracks"], &before["skeleton"], &before["events"])
    );
    // The index follows: the old tag finds nothing, the new ones the clip.
    assert_eq!(app.get_json("/v1/clips?tag=a").await["clips"], json!([]));
    assert_eq!(app.get_json("/v1/clips?tag=c").await["clips"][0]["id"], id.as_str());
    // The compiled clip follows too: ping-pong is the default playback of a pose.
    let pose = app.get_json(&format!("/v1/clips/{id}/pose?t=4")).await;
    let at_2 = app.get_json(&format!("/v1/clips/{id}/pose?t=2&playback=once")).await;
    assert_eq!(pose["joints"], at_2["joints"], "t=4 ping-pongs back to 2 on a 3 s clip");

    // A stale tag: 412 and nothing changes.
    let (status, body) = problem(patch(&app, &id, Some("\"1\""), json!({"name": "stale"})).await).await;
    assert_eq!((status, body["code"].as_str()), (412, Some("version_mismatch")), "{body}");
    assert_eq!(app.get_json(&format!("/v1/clips/{id}")).await["name"], "wave-2");
    // Without If-Match (as PUT): applied to the current version.
    let resp = patch(&app, &id, None, json!({"tags": null, "metadata": null})).await;
    assert_eq!((resp.status().as_u16(), resp.headers()["etag"].to_str().unwrap()), (200, "\"3\""));
    let after = app.get_json(&format!("/v1/clips/{id}")).await;
    assert!(after.get("tags").is_none() && after.get("metadata").is_none(), "null removes: {after}");
    let resp = patch(&app, &id, Some("*"), json!({"name": "any"})).await;
    assert_eq!(resp.status(), 200, "If-Match: * patches whatever version is there");
    // A patch that changes nothing writes nothing: same version, same ETag.
    for unchanged in [json!({}), json!({"name": "any"}), json!({"tags": []}), json!({"metadata": null})] {
        let resp = patch(&app, &id, None, unchanged.clone()).await;
        assert_eq!((resp.status().as_u16(), resp.headers()["etag"].to_str().unwrap()), (200, "\"4\""), "{unchanged}");
    }

    let refusals = [
        (json!({"tracks": []}), 422, "unpatchable_field", Some("/tracks")),
        (json!({"ik": []}), 422, "unpatchable_field", Some("/ik")),
        (json!({"name": null}), 422, "bad_patch", Some("/name")),
        (json!([1, 2]), 422, "bad_patch", Some("")),
        (json!({"events": [{"time": "soon", "name": "x"}]}), 422, "invalid_field", Some("/events/0/time")),
        (json!({"tags": ["dup", "dup"]}), 422, "duplicate_tag", Some("/tags/1")),
        (json!({"playback": "sideways"}), 422, "invalid_field", Some("/playback")),
    ];
    for (body, status, code, pointer) in refusals {
        let (got, problem) = problem(patch(&app, &id, None, body.clone()).await).await;
        assert_eq!(
            (got, problem["code"].as_str(), problem["pointer"].as_str()),
            (status, Some(code), pointer),
            "{body}: {problem}"
        );
    }
    let not_json =
        app.http.patch(app.url(&format!("/v1/clips/{id}"))).header("content-type", "application/json").body("{").send();
    assert_eq!(not_json.await.unwrap().status(), 400);
    let text =
        app.http.patch(app.url(&format!("/v1/clips/{id}"))).header("content-type", "text/plain").body("{}").send();
    assert_eq!(text.await.unwrap().status(), 415);
    let missing = server::store::new_clip_id();
    assert_eq!(patch(&app, &missing, None, json!({"name": "x"})).await.status(), 404);
    assert_eq!(app.get_json(&format!("/v1/clips/{id}")).await["name"], "any", "refusals changed nothing");
    app.stop().await;
}

#[tokio::test]
async fn patch_needs_the_write_scope() {
    let app = TestApp::builder().write_token("w").start().await;
    let id = app.create_id(WAVE, Some("w")).await;
    let url = app.url(&format!("/v1/clips/{id}"));
    let body = json!({"name": "x"}).to_string();
    let anonymous = app.http.patch(&url).header("content-type", "application/json").body(body.clone()).send();
    assert_eq!(anonymous.await.unwrap().status(), 401);
    let authed = app.http.patch(&url).bearer_auth("w").header("content-type", "application/json").body(body).send();
    assert_eq!(authed.await.unwrap().status(), 200);
    app.stop().await;
}

/// The event names of the JSON frames of a stream that plays `id` once from 0.
async fn streamed_events(app: &TestApp, id: &str) -> Vec<String> {
    let mut ws = app.ws(&format!("/v1/clips/{id}/stream?fps=30&speed=4&start=0&playback=once")).await;
    let mut names = Vec::new();
    loop {
        let msg = within(5, "a frame", ws.next()).await.expect("the socket closed").unwrap();
        let Message::Text(text) = msg else { continue };
        let frame: Value = serde_json::from_str(&text).unwrap();
        for e in frame["events"].as_array().unwrap() {
            names.push(e["name"].as_str().unwrap().to_owned());
        }
        if frame["clip_time"].as_f64().unwrap() >= 3.0 {
            return names;
        }
    }
}

#[tokio::test]
async fn patched_events_reach_the_streams_opened_after_the_patch() {
    let app = TestApp::start().await;
    let id = app.create_id(WAVE, None).await;
    assert_eq!(streamed_events(&app, &id).await, ["footstep"]);
    let events = json!({"events": [{"time": 0.5, "name": "lift"}, {"time": 2.5, "name": "land"}]});
    assert_eq!(patch(&app, &id, Some("\"1\""), events).await.status(), 200);
    assert_eq!(streamed_events(&app, &id).await, ["lift", "land"]);
    app.stop().await;
}

#[tokio::test]
async fn the_skeleton_is_a_few_kilobytes_where_the_document_is_megabytes() {
    let app = TestApp::start().await;
    let url = app.url("/v1/clips/import?name=131_03");
    let created: Value =
        app.http.post(url).body(testdata("bvh/131_03.bvh")).send().await.unwrap().json().await.unwrap();
    let summary = &created["clips"][0];
    let id = summary["id"].as_str().unwrap();
    let doc_text = app.http.get(app.url(&format!("/v1/clips/{id}"))).send().await.unwrap().text().await.unwrap();
    let resp = app.http.get(app.url(&format!("/v1/clips/{id}/skeleton"))).send().await.unwrap();
    assert_eq!(resp.headers()["etag"], "\"1\"");
    let skeleton_text = resp.text().await.unwrap();
    eprintln!("131_03: document {} bytes, skeleton {} bytes", doc_text.len(), skeleton_text.len());
    assert!(doc_text.len() > 1_000_000, "the document is megabytes: {}", doc_text.len());
    assert!(skeleton_text.len() < 8 * 1024, "the skeleton is a few KB: {}", skeleton_text.len());

    // Every joint, parent and rest transform as the document has them.
    let doc: Value = serde_json::from_str(&doc_text).unwrap();
    let skeleton: Value = serde_json::from_str(&skeleton_text).unwrap();
    let joints = skeleton["joints"].as_array().unwrap();
    let doc_joints = doc["skeleton"]["joints"].as_array().unwrap();
    assert_eq!(joints.len(), doc_joints.len());
    assert_eq!(joints.len() as u64, summary["joints"].as_u64().unwrap());
    for (got, want) in joints.iter().zip(doc_joints) {
        assert_eq!(got["name"], want["name"]);
        assert_eq!(got["parent"], want["parent"]);
        assert_eq!(got["rest"], want.get("rest").cloned().unwrap_or(json!({})), "{}", want["name"]);
    }
    assert_eq!((&skeleton["id"], &skeleton["name"], &skeleton["version"]), (&json!(id), &json!("131_03"), &json!(1)));
    assert_eq!((&skeleton["start"], &skeleton["end"]), (&summary["start"], &summary["end"]));
    assert_eq!(skeleton["parameters"], json!([]), "no clip carries parameters yet");
    assert_eq!(skeleton["inverse_binds"], false);
    let cached = app.http.get(app.url(&format!("/v1/clips/{id}/skeleton"))).header("if-none-match", "\"1\"").send();
    assert_eq!(cached.await.unwrap().status(), 304);
    let missing = app.http.get(app.url(&format!("/v1/clips/{}/skeleton", server::store::new_clip_id()))).send();
    assert_eq!(missing.await.unwrap().status(), 404);

    // gRPC GetSkeleton: the same joints.
    let mut grpc = app.grpc().await;
    let reply = grpc.get_skeleton(pb::GetClipRequest { clip_id: id.to_owned() }).await.unwrap().into_inner();
    let pb_joints = reply.skeleton.unwrap().joints;
    assert_eq!(pb_joints.len(), joints.len());
    for (got, want) in pb_joints.iter().zip(joints) {
        assert_eq!(got.name, want["name"].as_str().unwrap());
        assert_eq!(got.parent.as_deref(), want["parent"].as_str());
        let t: Vec<f64> = got.rest.as_ref().unwrap().translation.iter().map(|&v| f64::from(v)).collect();
        let want_t: Vec<f64> =
            want["rest"]["translation"].as_array().map_or(vec![], |a| a.iter().map(|v| v.as_f64().unwrap()).collect());
        assert_eq!(t.len(), want_t.len());
        for (a, b) in t.iter().zip(&want_t) {
            assert_eq!(*a as f32, *b as f32);
        }
        assert!(got.inverse_bind.is_empty());
    }
    assert_eq!(reply.summary.unwrap().id, id);
    assert!(reply.parameters.is_empty());
    app.stop().await;
}
