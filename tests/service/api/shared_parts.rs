//! A multipart glTF whose buffers all name one part: the part is shared, not
//! copied per buffer, and every buffer's `byteLength` counts against
//! `max_import_resolved_bytes` (413 `resolved_bytes_too_large` past it).

use reqwest::multipart::{Form, Part};
use serde_json::{Value, json};

use super::TestApp;

/// Bytes of the shared part: just over 1 MiB, so 64 buffers naming it
/// (64 MiB + 256 KiB) exceed the default 64 MiB and 16 fit.
const PART_BYTES: usize = (1 << 20) + 4096;

/// The part: key times `[0, 1]` then translations `[0,0,0]`, `[1,2,3]`,
/// then zeros.
fn part() -> Vec<u8> {
    let mut bytes: Vec<u8> = [0.0f32, 1.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0].iter().flat_map(|x| x.to_le_bytes()).collect();
    bytes.resize(PART_BYTES, 0);
    bytes
}

/// A `.gltf` with `nodes` animated nodes; node `i`'s times are read from
/// buffer `2i` and its translations from buffer `2i + 1`, and every buffer
/// is `part.bin`, whole.
fn gltf(nodes: usize) -> Vec<u8> {
    let buffers: Vec<Value> = (0..2 * nodes).map(|_| json!({"uri": "part.bin", "byteLength": PART_BYTES})).collect();
    let views: Vec<Value> = (0..nodes)
        .flat_map(|i| {
            [
                json!({"buffer": 2 * i, "byteOffset": 0, "byteLength": 8}),
                json!({"buffer": 2 * i + 1, "byteOffset": 8, "byteLength": 24}),
            ]
        })
        .collect();
    let accessors: Vec<Value> = (0..nodes)
        .flat_map(|i| {
            [
                json!({"bufferView": 2 * i, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]}),
                json!({"bufferView": 2 * i + 1, "componentType": 5126, "count": 2, "type": "VEC3"}),
            ]
        })
        .collect();
    let doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes).collect::<Vec<_>>()}],
        "nodes": (0..nodes).map(|i| json!({"name": format!("n{i}")})).collect::<Vec<_>>(),
        "buffers": buffers,
        "bufferViews": views,
        "accessors": accessors,
        "animations": [{
            "name": "shared",
            "channels": (0..nodes).map(|i| json!({"sampler": i, "target": {"node": i, "path": "translation"}})).collect::<Vec<_>>(),
            "samplers": (0..nodes).map(|i| json!({"input": 2 * i, "output": 2 * i + 1, "interpolation": "LINEAR"})).collect::<Vec<_>>()
        }]
    });
    serde_json::to_vec(&doc).unwrap()
}

async fn upload(app: &TestApp, nodes: usize) -> reqwest::Response {
    let form = Form::new()
        .part("file", Part::bytes(gltf(nodes)).file_name("shared.gltf"))
        .part("buffer", Part::bytes(part()).file_name("part.bin"));
    app.http.post(app.url("/v1/clips/import")).multipart(form).send().await.unwrap()
}

#[tokio::test]
async fn buffers_sharing_one_part_count_each_byte_length_against_the_limit() {
    let app = TestApp::start().await;

    // 32 nodes, 64 buffers of PART_BYTES each: 64 MiB + 256 KiB read.
    let resp = upload(&app, 32).await;
    assert_eq!(resp.status(), 413);
    let problem: Value = resp.json().await.unwrap();
    assert_eq!(problem["code"], "resolved_bytes_too_large", "{problem}");
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.contains(&(64u64 << 20).to_string()), "names the 64 MiB limit: {detail}");
    assert!(app.list_all(100, None).await.is_empty(), "nothing stored");

    // 8 nodes, 16 buffers: 16 MiB + 64 KiB, well within the limit.
    let resp = upload(&app, 8).await;
    assert_eq!(resp.status(), 201, "{}", resp.text().await.unwrap());
    let body: Value = resp.json().await.unwrap();
    let clips = body["clips"].as_array().unwrap();
    assert_eq!(clips.len(), 1);
    let id = clips[0]["id"].as_str().unwrap();
    let clip: Value = app.http.get(app.url(&format!("/v1/clips/{id}"))).send().await.unwrap().json().await.unwrap();
    let tracks = clip["tracks"].as_array().unwrap();
    assert_eq!(tracks.len(), 8, "one translation track per node");
    assert_eq!(tracks[7]["values"], json!([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]]), "read from the shared part");
    app.stop().await;
}
