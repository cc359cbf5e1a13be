//! A 12 MiB multipart glTF whose buffers all name the same part once drove
//! the server to 9.5 GB (each buffer copied the part). Parts are now shared
//! and every buffer's `byteLength` counts against the import limit.

use reqwest::multipart::{Form, Part};
use serde_json::{Value, json};

use super::target;

/// A part just under 12 MiB.
const PART_BYTES: usize = 12 * 1024 * 1024 - 4096;

/// A `.gltf` of `nodes` animated nodes; node `i` reads its times from
/// buffer `2i` and its translations from buffer `2i + 1`, and every buffer
/// is `part.bin`, whole.
fn gltf(nodes: usize) -> Vec<u8> {
    let doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes).collect::<Vec<_>>()}],
        "nodes": (0..nodes).map(|i| json!({"name": format!("n{i}")})).collect::<Vec<_>>(),
        "buffers": (0..2 * nodes).map(|_| json!({"uri": "part.bin", "byteLength": PART_BYTES})).collect::<Vec<_>>(),
        "bufferViews": (0..nodes).flat_map(|i| [
            json!({"buffer": 2 * i, "byteOffset": 0, "byteLength": 8}),
            json!({"buffer": 2 * i + 1, "byteOffset": 8, "byteLength": 24}),
        ]).collect::<Vec<_>>(),
        "accessors": (0..nodes).flat_map(|i| [
            json!({"bufferView": 2 * i, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]}),
            json!({"bufferView": 2 * i + 1, "componentType": 5126, "count": 2, "type": "VEC3"}),
        ]).collect::<Vec<_>>(),
        "animations": [{
            "channels": (0..nodes).map(|i| json!({"sampler": i, "target": {"node": i, "path": "translation"}})).collect::<Vec<_>>(),
            "samplers": (0..nodes).map(|i| json!({"input": 2 * i, "output": 2 * i + 1})).collect::<Vec<_>>()
        }]
    });
    serde_json::to_vec(&doc).unwrap()
}

#[tokio::test(flavor = "multi_thread")]
async fn a_part_named_by_a_thousand_buffers_is_shared_and_refused() {
    let mut target = target(&[]).await;
    let http = crate::common::http_client();
    let mut part = vec![0u8; PART_BYTES];
    part[4..8].copy_from_slice(&1.0f32.to_le_bytes());
    let probes = target.probes().await;
    for _ in 0..4 {
        let form = Form::new()
            .part("file", Part::bytes(gltf(500)).file_name("shared.gltf"))
            .part("buffer", Part::bytes(part.clone()).file_name("part.bin"));
        let resp = http.post(target.server.url("/v1/clips/import")).multipart(form).send().await.unwrap();
        assert_eq!(resp.status(), 413);
        let problem: Value = resp.json().await.unwrap();
        assert_eq!(problem["code"], "resolved_bytes_too_large", "{problem}");
    }
    let report = probes.finish();
    let list: Value = http.get(target.server.url("/v1/clips")).send().await.unwrap().json().await.unwrap();
    assert_eq!(list["clips"].as_array().map(Vec::len), Some(0), "nothing stored: {list}");
    target.assert_survived("12 MiB part named by 1,000 glTF buffers", &report);
}
