//! Warnings (issue 18, docs/warnings.md): every code from a document or
//! file that triggers it, over the real server (REST uploads, the import
//! route, gRPC PutClip) and the CLI; the files users try produce none; and
//! `fix=hemisphere` turns a CUBICSPLINE rotation the short way, checked
//! against the pose worked out by hand.

use std::process::Command;

use base64::Engine as _;
use formats::wire::proto::pb;
use serde_json::{Value, json};

use super::{TestApp, WAVE, canonical};

// ---- Documents and files that trigger each code ----

/// `[x, y, z, w]` of a rotation by `deg` degrees about z.
fn about_z(deg: f64) -> [f64; 4] {
    let h = deg.to_radians() / 2.0;
    [0.0, 0.0, h.sin(), h.cos()]
}

/// A clip document with one joint `bone` and the given track.
fn doc_with(track: Value) -> String {
    json!({"name": "w", "skeleton": {"joints": [{"name": "bone"}]}, "tracks": [track]}).to_string()
}

/// Norms 2 and 1 (key 0 is off; key 1 is unit).
fn not_unit_doc() -> String {
    doc_with(json!({"joint": "bone", "channel": "rotation", "times": [0, 1], "values": [[0, 0, 0, 2], [0, 0, 0, 1]]}))
}

/// 10°, 20° and 30° about z, written `[w, x, y, z]`.
fn w_first_doc() -> String {
    let values: Vec<[f64; 4]> = [10.0, 20.0, 30.0].map(about_z).iter().map(|q| [q[3], q[0], q[1], q[2]]).collect();
    doc_with(json!({"joint": "bone", "channel": "rotation", "times": [0, 1, 2], "values": values}))
}

/// Twelve keys at 0, 1, …, 11.
fn frames_doc() -> String {
    let times: Vec<u32> = (0..12).collect();
    let values: Vec<[f32; 3]> = (0..12).map(|i| [i as f32, 0.0, 0.0]).collect();
    doc_with(json!({"joint": "bone", "channel": "translation", "times": times, "values": values}))
}

/// A quarter turn about z, its second key written as `-q`.
fn hemisphere_doc() -> String {
    let q = about_z(90.0).map(|c| -c);
    doc_with(json!({"joint": "bone", "channel": "rotation", "interpolation": "cubic_hermite", "times": [0, 1],
        "values": [[0, 0, 0, 1], q], "in_tangents": [[0, 0, 0, 0], [0, 0, 0, 0]],
        "out_tangents": [[0, 0, 0, 0], [0, 0, 0, 0]]}))
}

/// A glTF file assembled from float accessors in one embedded buffer.
#[derive(Default)]
struct Gltf {
    data: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Gltf {
    /// An accessor of `kind` (`SCALAR`, `VEC3`, `VEC4`, `MAT4`) over `floats`.
    fn accessor(&mut self, kind: &str, floats: &[f32]) -> usize {
        let width = match kind {
            "SCALAR" => 1,
            "VEC3" => 3,
            "VEC4" => 4,
            _ => 16,
        };
        let offset = self.data.len();
        self.data.extend(floats.iter().flat_map(|f| f.to_le_bytes()));
        let bytes = floats.len() * 4;
        self.views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes}));
        let mut accessor = json!({"bufferView": self.views.len() - 1, "componentType": 5126, "count": floats.len() / width, "type": kind});
        if kind == "SCALAR" {
            let max = floats.iter().copied().fold(f32::MIN, f32::max);
            let min = floats.iter().copied().fold(f32::MAX, f32::min);
            accessor["min"] = json!([min]);
            accessor["max"] = json!([max]);
        }
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    /// `doc` with the buffer, views and accessors filled in.
    fn finish(self, mut doc: Value) -> Vec<u8> {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&self.data)
        );
        doc["asset"] = json!({"version": "2.0"});
        doc["buffers"] = json!([{"byteLength": self.data.len(), "uri": uri}]);
        doc["bufferViews"] = Value::Array(self.views);
        doc["accessors"] = Value::Array(self.accessors);
        serde_json::to_vec(&doc).unwrap()
    }
}

/// A glTF whose node 1 (`bone`, child of `root`) has one animated channel:
/// `path` sampled by `interpolation` at `times`, output `output`. Channel 0
/// of animation 0 is a constant translation of `root`, so the interesting
/// channel is channel 1 and its sampler is sampler 1.
fn gltf_channel(path: &str, interpolation: &str, times: &[f32], output: &[f32]) -> Vec<u8> {
    let mut g = Gltf::default();
    let still_times = g.accessor("SCALAR", &[0.0, 1.0]);
    let still = g.accessor("VEC3", &[0.0; 6]);
    let input = g.accessor("SCALAR", times);
    let output = g.accessor(if path == "rotation" { "VEC4" } else { "VEC3" }, output);
    g.finish(json!({
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "root", "children": [1]}, {"name": "bone"}],
        "animations": [{"name": "lift",
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}},
                         {"sampler": 1, "target": {"node": 1, "path": path}}],
            "samplers": [{"input": still_times, "output": still},
                         {"input": input, "output": output, "interpolation": interpolation}]}]
    }))
}

fn flat(keys: &[[f64; 4]]) -> Vec<f32> {
    keys.iter().flatten().map(|&c| c as f32).collect()
}

fn not_unit_gltf() -> Vec<u8> {
    gltf_channel("rotation", "LINEAR", &[0.0, 1.0], &flat(&[[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.1]]))
}

fn w_first_gltf() -> Vec<u8> {
    let keys: Vec<[f64; 4]> = [10.0, 20.0, 30.0].map(about_z).iter().map(|q| [q[3], q[0], q[1], q[2]]).collect();
    gltf_channel("rotation", "LINEAR", &[0.0, 1.0, 2.0], &flat(&keys))
}

fn frames_gltf() -> Vec<u8> {
    let times: Vec<f32> = (0..12).map(|i| i as f32).collect();
    gltf_channel("translation", "LINEAR", &times, &[0.5; 36])
}

/// CUBICSPLINE, zero tangents: identity at t = 0, a quarter turn about z at
/// t = 1 written as `-q` (what Blender 3.x's exporter does).
fn hemisphere_gltf() -> Vec<u8> {
    let zero = [0.0; 4];
    let keys = [zero, [0.0, 0.0, 0.0, 1.0], zero, zero, about_z(90.0).map(|c| -c), zero];
    gltf_channel("rotation", "CUBICSPLINE", &[0.0, 1.0], &flat(&keys))
}

/// Two skins of the one joint `bone` with different inverse bind matrices:
/// the second skin's is not imported.
fn skin_conflict_gltf() -> Vec<u8> {
    let mut g = Gltf::default();
    let identity: Vec<f32> = (0..16).map(|i| if i % 5 == 0 { 1.0 } else { 0.0 }).collect();
    let mut moved = identity.clone();
    moved[12] = 1.0;
    let first = g.accessor("MAT4", &identity);
    let second = g.accessor("MAT4", &moved);
    let times = g.accessor("SCALAR", &[0.0, 1.0]);
    let values = g.accessor("VEC3", &[0.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    g.finish(json!({
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "root", "children": [1]}, {"name": "bone"}],
        "skins": [{"joints": [1], "inverseBindMatrices": first}, {"joints": [1], "inverseBindMatrices": second}],
        "animations": [{"channels": [{"sampler": 0, "target": {"node": 1, "path": "translation"}}],
            "samplers": [{"input": times, "output": values}]}]
    }))
}

/// A BVH whose `Frame Time` is 1: frames numbered, not timed.
fn frames_bvh() -> Vec<u8> {
    let mut bvh = String::from(
        "HIERARCHY\nROOT hip\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition Zposition\n  \
         End Site\n  {\n    OFFSET 0 1 0\n  }\n}\nMOTION\nFrames: 12\nFrame Time: 1\n",
    );
    for i in 0..12 {
        bvh.push_str(&format!("{i} 0 0\n"));
    }
    bvh.into_bytes()
}

/// `joints` joints, each with one rotation track whose first key has norm 2:
/// one `rotation_not_unit` per track, `joints` warnings before the cap.
fn many_not_unit_doc(joints: usize) -> String {
    let names: Vec<String> = (0..joints).map(|i| format!("j{i}")).collect();
    let skeleton: Vec<Value> = names.iter().map(|n| json!({"name": n})).collect();
    let tracks: Vec<Value> = (names.iter())
        .map(|n| json!({"joint": n, "channel": "rotation", "times": [0, 1], "values": [[0, 0, 0, 2], [0, 0, 0, 1]]}))
        .collect();
    json!({"name": "many", "skeleton": {"joints": skeleton}, "tracks": tracks}).to_string()
}

/// The same in a glTF: `nodes` children of one root, each with a LINEAR
/// rotation channel whose first key has norm 2.
fn many_not_unit_gltf(nodes: usize) -> Vec<u8> {
    let mut g = Gltf::default();
    let times = g.accessor("SCALAR", &[0.0, 1.0]);
    let keys = g.accessor("VEC4", &flat(&[[0.0, 0.0, 0.0, 2.0], [0.0, 0.0, 0.0, 1.0]]));
    let mut all = vec![json!({"name": "root", "children": (1..=nodes).collect::<Vec<_>>()})];
    all.extend((0..nodes).map(|i| json!({"name": format!("j{i}")})));
    let channels: Vec<Value> =
        (0..nodes).map(|i| json!({"sampler": 0, "target": {"node": i + 1, "path": "rotation"}})).collect();
    g.finish(json!({
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": all,
        "animations": [{"name": "many", "channels": channels,
            "samplers": [{"input": times, "output": keys}]}]
    }))
}

// ---- Helpers ----

/// The `(code, pointer)` of each warning of an answer.
fn codes(body: &Value) -> Vec<(String, String)> {
    let warnings = body["warnings"].as_array().unwrap_or_else(|| panic!("no warnings list: {body}"));
    warnings
        .iter()
        .map(|w| {
            assert!(!w["detail"].as_str().unwrap().is_empty(), "{w}");
            (w["code"].as_str().unwrap().to_owned(), w["pointer"].as_str().unwrap().to_owned())
        })
        .collect()
}

fn pairs(list: &[(&str, &str)]) -> Vec<(String, String)> {
    list.iter().map(|(c, p)| ((*c).to_owned(), (*p).to_owned())).collect()
}

/// `POST /v1/clips/import{query}` with `bytes`; asserts 201.
async fn import(app: &TestApp, query: &str, bytes: Vec<u8>) -> Value {
    // The tests import one file several ways: each a new version of its clip.
    let query = if query.is_empty() { "?replace=true".to_owned() } else { format!("{query}&replace=true") };
    let resp = app.http.post(app.url(&format!("/v1/clips/import{query}"))).body(bytes).send().await.unwrap();
    let status = resp.status();
    let body: Value = resp.json().await.unwrap();
    assert_eq!(status, 201, "{body}");
    body
}

/// `doc` (a clip named `w`) named `name` instead: names identify clips.
fn renamed(doc: &str, name: &str) -> String {
    doc.replacen("\"name\":\"w\"", &format!("\"name\":\"{name}\""), 1)
}

/// The rotation of joint `joint` at `time` of clip `id`, local space.
async fn rotation_at(app: &TestApp, id: &str, joint: &str, time: f64) -> [f64; 4] {
    let pose = app.get_json(&format!("/v1/clips/{id}/pose?t={time}")).await;
    let joints = pose["joints"].as_array().unwrap();
    let j = joints.iter().find(|j| j["name"] == joint).unwrap_or_else(|| panic!("{pose}"));
    let r: Vec<f64> = j["rotation"].as_array().unwrap().iter().map(|c| c.as_f64().unwrap()).collect();
    [r[0], r[1], r[2], r[3]]
}

/// `a` and `b` are the same rotation (`q` or `-q`) within `tol`.
fn assert_same_rotation(a: [f64; 4], b: [f64; 4], tol: f64, what: &str) {
    let dot: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let sign = dot.signum();
    for (x, y) in a.iter().zip(b) {
        assert!((x - sign * y).abs() < tol, "{what}: {a:?} vs {b:?}");
    }
}

// ---- Tests ----

#[tokio::test]
async fn clip_uploads_answer_each_code_at_its_pointer_and_store_the_document_unchanged() {
    let app = TestApp::start().await;
    let cases = [
        (not_unit_doc(), ("rotation_not_unit", "/tracks/0/values/0")),
        (w_first_doc(), ("rotation_looks_w_first", "/tracks/0/values")),
        (frames_doc(), ("times_look_like_frames", "/tracks/0/times")),
        (hemisphere_doc(), ("rotation_hemisphere_flips", "/tracks/0/values/1")),
    ];
    for (i, (doc, expected)) in cases.iter().enumerate() {
        let doc = &renamed(doc, &format!("w{i}"));
        let created = app.create(doc, None).await;
        assert_eq!(codes(&created), pairs(&[*expected]), "{doc}");
        let id = created["id"].as_str().unwrap();
        assert_eq!(created["version"], 1);
        // Warnings change nothing stored: the document is kept as given (canonical form).
        let stored = app.http.get(app.url(&format!("/v1/clips/{id}"))).send().await.unwrap().text().await.unwrap();
        assert_eq!(stored, canonical(doc));
        // A replace answers the same warnings.
        let put = app.http.put(app.url(&format!("/v1/clips/{id}"))).header("content-type", "application/json");
        let resp = put.body(doc.clone()).send().await.unwrap();
        assert_eq!(resp.status(), 200);
        let replaced: Value = resp.json().await.unwrap();
        assert_eq!((codes(&replaced), &replaced["version"]), (pairs(&[*expected]), &json!(2)));
    }
    // Keys off the unit sphere are normalised when sampled: key 0 (norm 2) is the identity.
    let id = app.create_id(&renamed(&not_unit_doc(), "normalised"), None).await;
    assert_same_rotation(rotation_at(&app, &id, "bone", 0.0).await, [0.0, 0.0, 0.0, 1.0], 1e-6, "normalised key");
    // The documented example and a list of clips have none.
    assert_eq!(codes(&app.create(WAVE, None).await), []);
    let list = app.get_json("/v1/clips").await;
    assert!(list["clips"][0].get("warnings").is_none(), "only writes answer warnings: {list}");
    app.stop().await;
}

#[tokio::test]
async fn imports_answer_each_code_with_a_pointer_into_the_file() {
    let app = TestApp::start().await;
    let cases = [
        ("?format=gltf", not_unit_gltf(), ("rotation_not_unit", "/animations/0/channels/1")),
        ("?format=gltf", w_first_gltf(), ("rotation_looks_w_first", "/animations/0/channels/1")),
        ("?format=gltf", frames_gltf(), ("times_look_like_frames", "/animations/0/samplers/1/input")),
        ("?format=gltf", hemisphere_gltf(), ("rotation_hemisphere_flips", "/animations/0/channels/1")),
        ("?format=gltf", skin_conflict_gltf(), ("not_imported", "/skins/1/inverseBindMatrices")),
        ("?format=bvh", frames_bvh(), ("times_look_like_frames", "/MOTION/Frame Time")),
    ];
    for (query, bytes, expected) in cases {
        let body = import(&app, query, bytes).await;
        assert_eq!(codes(&body), pairs(&[expected]), "{body}");
        assert_eq!(body["clips"].as_array().unwrap().len(), 1, "valid files are still imported: {body}");
    }
    let bad = app.http.post(app.url("/v1/clips/import?fix=everything")).body(hemisphere_gltf()).send().await.unwrap();
    assert_eq!(bad.status(), 400);
    assert_eq!(bad.json::<Value>().await.unwrap()["code"], "bad_fix");
    app.stop().await;
}

/// More warnings than the cap (100, docs/warnings.md): 150 tracks each off
/// the unit sphere answer the first 99 as they are, then one
/// `too_many_warnings` (empty pointer) saying the other 150 − 99 = 51 were
/// left out; the upload and the import still succeed.
#[tokio::test]
async fn more_warnings_than_the_cap_end_with_too_many_warnings() {
    let app = TestApp::start().await;
    let check = |body: &Value, pointer: &dyn Fn(usize) -> String| {
        let warnings = body["warnings"].as_array().unwrap();
        assert_eq!(warnings.len(), 100, "{body}");
        for (i, w) in warnings[..99].iter().enumerate() {
            assert_eq!(
                (w["code"].as_str().unwrap(), w["pointer"].as_str().unwrap()),
                ("rotation_not_unit", &*pointer(i))
            );
        }
        let last = &warnings[99];
        assert_eq!(last["code"], "too_many_warnings", "{last}");
        assert_eq!(last["pointer"], "", "{last}");
        assert_eq!(last["detail"], "51 more warnings were left out", "{last}");
    };
    let created = app.create(&many_not_unit_doc(150), None).await;
    check(&created, &|i| format!("/tracks/{i}/values/0"));
    let stored = app.get_json(&format!("/v1/clips/{}", created["id"].as_str().unwrap())).await;
    assert_eq!(stored["tracks"].as_array().unwrap().len(), 150, "every track kept");
    let imported = import(&app, "?format=gltf", many_not_unit_gltf(150)).await;
    check(&imported, &|i| format!("/animations/0/channels/{i}"));
    // At the cap exactly, nothing is cut: 100 warnings, the last a track's own.
    let at_cap = app.create(&many_not_unit_doc(100).replacen("\"many\"", "\"at cap\"", 1), None).await;
    assert_eq!(codes(&at_cap).last().unwrap(), &("rotation_not_unit".to_owned(), "/tracks/99/values/0".to_owned()));
    assert_eq!(codes(&at_cap).len(), 100);
    app.stop().await;
}

/// Hermite with zero tangents at `u = 1/2` weighs both keys by 1/2, so the
/// sample is the normalised mean of the keys as stored: with the second key
/// written as `-q` (a quarter turn about z), `([0,0,0,1] + [0,0,-s,-s])/2`
/// normalised (`s = √½`) is `[0, 0, -sin 67.5°, cos 67.5°]`: 135° the long
/// way, i.e. `-135°` about z. Flipped, the mean of `[0,0,0,1]` and
/// `[0,0,s,s]` is 45° about z, the short way.
#[tokio::test]
async fn fix_hemisphere_turns_the_short_way() {
    let app = TestApp::start().await;
    let s = 0.5f64.sqrt();
    let mean = |q: [f64; 4]| {
        let m = [0.5 * q[0], 0.5 * q[1], 0.5 * q[2], 0.5 * (1.0 + q[3])];
        let n = m.iter().map(|c| c * c).sum::<f64>().sqrt();
        m.map(|c| c / n)
    };
    let long_way = mean([0.0, 0.0, -s, -s]);
    let short_way = mean([0.0, 0.0, s, s]);
    assert_same_rotation(long_way, about_z(-135.0), 1e-12, "hand value, long way");
    assert_same_rotation(short_way, about_z(45.0), 1e-12, "hand value, short way");

    let as_given = import(&app, "?format=gltf", hemisphere_gltf()).await;
    let id = as_given["clips"][0]["id"].as_str().unwrap();
    assert_same_rotation(rotation_at(&app, id, "bone", 0.5).await, long_way, 1e-5, "keys as given");

    // Played once, so the clip's end is its last key (a loop would be back at the first).
    let fixed = import(&app, "?format=gltf&fix=hemisphere&playback=once", hemisphere_gltf()).await;
    assert_eq!(codes(&fixed), pairs(&[("rotation_hemisphere_flips", "/animations/0/channels/1")]));
    assert!(fixed["warnings"][0]["detail"].as_str().unwrap().contains("flipped"), "{fixed}");
    let id = fixed["clips"][0]["id"].as_str().unwrap();
    assert_same_rotation(rotation_at(&app, id, "bone", 0.5).await, short_way, 1e-5, "fix=hemisphere");
    // The ends are the keys either way.
    assert_same_rotation(rotation_at(&app, id, "bone", 1.0).await, about_z(90.0), 1e-6, "last key");
    app.stop().await;
}

#[tokio::test]
async fn grpc_put_clip_answers_the_warnings() {
    let app = TestApp::start().await;
    let mut grpc = app.grpc().await;
    let spec = |doc: &str| formats::wire::json::parse_clip(doc.as_bytes()).unwrap().1;
    let put = |doc: &str| pb::PutClipRequest {
        clip: Some(formats::wire::proto::clip_to_pb(&spec(doc))),
        ..Default::default()
    };
    let reply = grpc.put_clip(put(&w_first_doc())).await.unwrap().into_inner();
    let got: Vec<(&str, &str)> = reply.warnings.iter().map(|w| (w.code.as_str(), w.pointer.as_str())).collect();
    assert_eq!(got, [("rotation_looks_w_first", "/tracks/0/values")]);
    assert!(grpc.put_clip(put(WAVE)).await.unwrap().into_inner().warnings.is_empty());
    app.stop().await;
}

/// `inbetween import` prints the warnings in its JSON (and on stderr),
/// locally and with `--server`, and `--fix hemisphere` flips.
#[tokio::test]
async fn the_cli_reports_warnings_and_fixes_hemispheres() {
    let app = TestApp::start().await;
    let dir = tempfile::tempdir().unwrap();
    let files = [
        ("not_unit.gltf", not_unit_gltf(), ("rotation_not_unit", "/animations/0/channels/1")),
        ("w_first.gltf", w_first_gltf(), ("rotation_looks_w_first", "/animations/0/channels/1")),
        ("frames.gltf", frames_gltf(), ("times_look_like_frames", "/animations/0/samplers/1/input")),
        ("hemisphere.gltf", hemisphere_gltf(), ("rotation_hemisphere_flips", "/animations/0/channels/1")),
        ("skins.gltf", skin_conflict_gltf(), ("not_imported", "/skins/1/inverseBindMatrices")),
        ("frames.bvh", frames_bvh(), ("times_look_like_frames", "/MOTION/Frame Time")),
    ];
    // Off the test's runtime thread: the server it uploads to runs on it.
    let cli = async |args: &[&str]| {
        let owned: Vec<String> = args.iter().map(|a| (*a).to_owned()).collect();
        let run = move || Command::new(env!("CARGO_BIN_EXE_inbetween")).arg("import").args(&owned).output().unwrap();
        let out = tokio::task::spawn_blocking(run).await.unwrap();
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        let stdout: Value = serde_json::from_slice(&out.stdout).unwrap();
        (stdout, String::from_utf8(out.stderr).unwrap())
    };
    for (name, bytes, expected) in &files {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let path = path.to_str().unwrap();
        let (out, stderr) = cli(&[path]).await;
        assert_eq!(codes(&out), pairs(&[*expected]), "{name}");
        assert!(stderr.contains(&format!("{} at {}", expected.0, expected.1)), "{name}: {stderr}");
        let (uploaded, _) = cli(&[path, "--server", &app.url(""), "--replace"]).await;
        assert_eq!(codes(&uploaded), pairs(&[*expected]), "{name} --server");
        assert!(uploaded["clips"][0]["id"].is_string(), "{uploaded}");
    }
    // --fix hemisphere: the second key and its tangents are flipped in the printed document.
    let path = dir.path().join("hemisphere.gltf");
    let (fixed, _) = cli(&[path.to_str().unwrap(), "--fix", "hemisphere"]).await;
    let track = &fixed["clips"][0]["tracks"][1];
    let z = track["values"][1][2].as_f64().unwrap();
    assert!((z - 0.5f64.sqrt()).abs() < 1e-6, "{track}");
    assert!(fixed["warnings"][0]["detail"].as_str().unwrap().contains("flipped"), "{fixed}");
    app.stop().await;
}

/// The OpenAPI document names the warning shape wherever an answer carries it.
#[tokio::test]
async fn the_openapi_document_describes_the_warnings() {
    let app = TestApp::start().await;
    let doc: Value = app.get_json("/openapi.json").await;
    let schemas = &doc["components"]["schemas"];
    let warning = &schemas["Warning"];
    for field in ["code", "pointer", "detail"] {
        assert_eq!(warning["properties"][field]["type"], "string", "{warning}");
    }
    let items = |schema: &Value| schema["properties"]["warnings"]["items"]["$ref"].clone();
    assert_eq!(items(&schemas["ImportResult"]), "#/components/schemas/Warning");
    let written = serde_json::to_string(&schemas["ClipWritten"]).unwrap();
    assert!(written.contains("#/components/schemas/ClipSummary"), "{written}");
    assert!(written.contains("#/components/schemas/Warning"), "{written}");
    let created = &doc["paths"]["/v1/clips"]["post"]["responses"]["201"]["content"]["application/json"]["schema"];
    assert_eq!(created["$ref"], "#/components/schemas/ClipWritten");
    let fix =
        (doc["paths"]["/v1/clips/import"]["post"]["parameters"].as_array().unwrap().iter()).any(|p| p["name"] == "fix");
    assert!(fix, "the import route documents ?fix");
    app.stop().await;
}
