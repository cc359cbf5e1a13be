//! `GET /v1/clips/{id}/mesh` (issue 20): the Fox imported from the examples
//! keeps its skinned mesh, served in docs/mesh-format.md's binary form and
//! read back here against the GLB itself (its JSON and BIN chunk, not the
//! importer): vertex and joint counts, positions, joint indices, weights,
//! inverse binds and the texture's bytes. Revalidation answers 304; clips
//! without a mesh answer 404 `no_mesh`; a PATCH keeps the mesh, a PUT drops
//! it, a DELETE takes it along.

use serde_json::{Value, json};

use super::{TestApp, WAVE};
use crate::common::glb::{FOX, Glb};

/// The binary form's JSON header and body.
fn split(bytes: &[u8]) -> (Value, &[u8]) {
    assert_eq!(&bytes[..4], b"INBM");
    assert_eq!(u32::from_le_bytes(bytes[4..8].try_into().unwrap()), 1, "version");
    let len = u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize;
    assert_eq!(len % 4, 0);
    (serde_json::from_slice(&bytes[12..12 + len]).unwrap(), &bytes[12 + len..])
}

/// An array of the body as `f64`s, by the header's description of it.
fn array(header: &Value, body: &[u8], name: &str) -> Vec<f64> {
    let a = &header["arrays"][name];
    let (offset, length) = (a["offset"].as_u64().unwrap() as usize, a["length"].as_u64().unwrap() as usize);
    assert_eq!(offset % 4, 0, "{name} is aligned");
    let data = &body[offset..offset + length];
    match a["type"].as_str().unwrap() {
        "f32" => data.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap()) as f64).collect(),
        "u16" => data.chunks_exact(2).map(|b| u16::from_le_bytes(b.try_into().unwrap()) as f64).collect(),
        "u8" => data.iter().map(|&b| b as f64).collect(),
        "u32" => data.chunks_exact(4).map(|b| u32::from_le_bytes(b.try_into().unwrap()) as f64).collect(),
        other => panic!("array type {other}"),
    }
}

async fn import_fox(app: &TestApp) -> Vec<String> {
    let glb = std::fs::read(FOX).unwrap();
    let resp = app.http.post(app.url("/v1/clips/import?format=glb")).body(glb).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let body: Value = resp.json().await.unwrap();
    body["clips"].as_array().unwrap().iter().map(|c| c["id"].as_str().unwrap().to_owned()).collect()
}

async fn problem_code(resp: reqwest::Response) -> (u16, String) {
    let status = resp.status().as_u16();
    let body: Value = resp.json().await.unwrap();
    (status, body["code"].as_str().unwrap_or_default().to_owned())
}

#[tokio::test]
async fn the_fox_keeps_its_skinned_mesh_as_the_file_has_it() {
    let app = TestApp::start().await;
    let ids = import_fox(&app).await;
    let fox = Glb::read(FOX);
    let positions = fox.attribute("POSITION");
    let joints = fox.skin_joint_names(0);
    assert_eq!((positions.len(), joints.len()), (1728, 24), "the Fox, read from its own JSON");

    let resp = app.http.get(app.url(&format!("/v1/clips/{}/mesh", ids[0]))).send().await.unwrap();
    assert_eq!(resp.status(), 200);
    let header = |name: &str| resp.headers()[name].to_str().unwrap().to_owned();
    assert_eq!(header("content-type"), "application/vnd.inbetween.mesh");
    assert_eq!(header("cache-control"), "private, no-cache");
    let etag = header("etag");
    assert!(etag.starts_with("\"m-") && etag.len() == 36, "{etag}");
    let bytes = resp.bytes().await.unwrap();
    let (head, body) = split(&bytes);
    assert_eq!(head["vertices"], 1728);
    assert_eq!(head["joints"], json!(joints), "the skin's joints, in its order, by clip joint name");
    let flat = |rows: Vec<Vec<f64>>| rows.into_iter().flatten().collect::<Vec<f64>>();
    assert_eq!(array(&head, body, "position"), flat(positions));
    assert_eq!(array(&head, body, "joints"), flat(fox.attribute("JOINTS_0")));
    assert_eq!(array(&head, body, "weights"), flat(fox.attribute("WEIGHTS_0")));
    assert_eq!(array(&head, body, "uv"), flat(fox.attribute("TEXCOORD_0")));
    assert_eq!(array(&head, body, "indices"), (0..1728).map(f64::from).collect::<Vec<_>>(), "no indices: in order");
    assert!(head["arrays"].get("normal").is_none(), "the Fox has no normals: the page shades flat");
    let skin = fox.json["skins"][0]["inverseBindMatrices"].as_u64().unwrap() as usize;
    assert_eq!(array(&head, body, "inverse_binds"), flat(fox.accessor(skin)));
    // The base colour texture (26 KB, under the 1 MiB limit) as the file holds it.
    let image = fox.json["images"][0]["bufferView"].as_u64().unwrap() as usize;
    let texture = &head["textures"][0];
    assert_eq!(texture["mime_type"], "image/png");
    let at = texture["offset"].as_u64().unwrap() as usize;
    assert_eq!(&body[at..at + texture["length"].as_u64().unwrap() as usize], fox.view(image));
    assert_eq!(head["materials"][0]["texture"], 0);
    assert_eq!(head["primitives"], json!([{"first": 0, "count": 1728, "material": 0}]));

    // Every clip of the skin has it; revalidation is a 304 without a body.
    for id in &ids[1..] {
        let other = app.http.get(app.url(&format!("/v1/clips/{id}/mesh"))).send().await.unwrap();
        assert_eq!(other.headers()["etag"].to_str().unwrap(), etag, "same mesh, same tag");
    }
    let again = app
        .http
        .get(app.url(&format!("/v1/clips/{}/mesh", ids[0])))
        .header("if-none-match", &etag)
        .send()
        .await
        .unwrap();
    assert_eq!(again.status(), 304);
    assert_eq!(again.headers()["etag"].to_str().unwrap(), etag);
    assert!(again.bytes().await.unwrap().is_empty());
    let stale = app.http.get(app.url(&format!("/v1/clips/{}/mesh", ids[0]))).header("if-none-match", "\"m-0\"");
    assert_eq!(stale.send().await.unwrap().status(), 200);
    app.stop().await;
}

#[tokio::test]
async fn clips_without_a_mesh_say_so_and_writes_keep_or_drop_it() {
    let app = TestApp::start().await;
    let mesh = |id: &str| app.http.get(app.url(&format!("/v1/clips/{id}/mesh"))).send();

    let wave = app.create_id(WAVE, None).await;
    assert_eq!(problem_code(mesh(&wave).await.unwrap()).await, (404, "no_mesh".into()), "a JSON clip");
    let bvh = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/bvh/131_01.bvh")).unwrap();
    let imported = app.http.post(app.url("/v1/clips/import?format=bvh")).body(bvh).send().await.unwrap();
    let imported: Value = imported.json().await.unwrap();
    let bvh_id = imported["clips"][0]["id"].as_str().unwrap();
    assert_eq!(problem_code(mesh(bvh_id).await.unwrap()).await, (404, "no_mesh".into()), "a BVH clip");
    let unknown = "0190f5d3-0000-7000-8000-000000000000";
    assert_eq!(problem_code(mesh(unknown).await.unwrap()).await, (404, "clip_not_found".into()));

    let ids = import_fox(&app).await;
    let (patched, replaced, deleted) = (&ids[0], &ids[1], &ids[2]);
    let etag = mesh(patched).await.unwrap().headers()["etag"].to_str().unwrap().to_owned();
    // A PATCH cannot touch the skeleton: the mesh stays, with its tag.
    let resp = app
        .http
        .patch(app.url(&format!("/v1/clips/{patched}")))
        .header("content-type", "application/merge-patch+json")
        .body(r#"{"name": "renamed fox"}"#)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200);
    let after = mesh(patched).await.unwrap();
    assert_eq!((after.status().as_u16(), after.headers()["etag"].to_str().unwrap()), (200, etag.as_str()));
    // A PUT of a JSON document keeps no mesh (it may rename or move the joints).
    let doc: Value = app.get_json(&format!("/v1/clips/{replaced}")).await;
    let resp = app.http.put(app.url(&format!("/v1/clips/{replaced}"))).json(&doc).send().await.unwrap();
    assert_eq!(resp.status(), 200);
    assert_eq!(problem_code(mesh(replaced).await.unwrap()).await, (404, "no_mesh".into()));
    let resp = app.http.delete(app.url(&format!("/v1/clips/{deleted}"))).send().await.unwrap();
    assert_eq!(resp.status(), 204);
    assert_eq!(problem_code(mesh(deleted).await.unwrap()).await, (404, "clip_not_found".into()));
    app.stop().await;
}

/// gRPC `GetMesh` serves the same bytes and entity tag as REST, and the same
/// refusals: NOT_FOUND `no_mesh` for a clip without one, `clip_not_found`.
#[tokio::test]
async fn grpc_get_mesh_serves_the_same_bytes_and_refusals() {
    use formats::wire::proto::pb;
    let app = TestApp::start().await;
    let fox = import_fox(&app).await;
    let wave = app.create_id(WAVE, None).await;
    let mut grpc = app.grpc().await;
    let get = |id: &str| pb::GetClipRequest { clip_id: id.to_owned() };

    let rest = app.http.get(app.url(&format!("/v1/clips/{}/mesh", fox[1]))).send().await.unwrap();
    let etag = rest.headers()["etag"].to_str().unwrap().to_owned();
    let bytes = rest.bytes().await.unwrap();
    let mesh = grpc.get_mesh(get(&fox[1])).await.unwrap().into_inner();
    assert!(mesh.data == bytes, "the same {} bytes as REST", bytes.len());
    assert_eq!(mesh.etag, etag);

    for (id, code) in [(wave.as_str(), "no_mesh"), ("0190f5d3-0000-7000-8000-000000000000", "clip_not_found")] {
        let status = grpc.get_mesh(get(id)).await.unwrap_err();
        assert_eq!(status.code(), tonic::Code::NotFound, "{id}");
        assert_eq!(status.metadata().get("x-error-code").unwrap(), code, "{id}");
    }
    app.stop().await;
}
