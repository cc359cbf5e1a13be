//! `/v1/graphs` (docs/graphs.md): graphs stored and versioned as
//! characters are (ETag, If-Match, names), checked whole at upload — their
//! clips found, every rule of the graph core with the document's JSON
//! pointers, the limits and the price — and the gRPC twins answering with
//! the same codes, against the real server.

use serde_json::{Value, json};

use super::TestApp;
use formats::wire::proto::pb;

/// A clip on a `hips`–`spine`–`head` chain (or any joint names), one
/// second long, its root turning by `angle` radians about y.
fn clip(name: &str, joints: &[&str], angle: f32) -> String {
    let skeleton: Vec<Value> = (joints.iter().enumerate())
        .map(|(i, j)| json!({"name": j, "parent": if i == 0 { Value::Null } else { json!(joints[i - 1]) }}))
        .collect();
    let (s, c) = (angle / 2.0).sin_cos();
    json!({
        "name": name,
        "skeleton": {"joints": skeleton},
        "tracks": [{"joint": joints[0], "channel": "rotation", "interpolation": "linear",
                    "times": [0, 1], "values": [[0, 0, 0, 1], [0, s, 0, c]]}],
    })
    .to_string()
}

const BODY: &[&str] = &["hips", "spine", "head"];

/// Three clips on one skeleton, stored: idle, walk, run.
async fn three_clips(app: &TestApp, prefix: &str) -> [String; 3] {
    let mut ids = Vec::new();
    for (i, name) in ["idle", "walk", "run"].into_iter().enumerate() {
        ids.push(app.create_id(&clip(&format!("{prefix}{name}"), BODY, 0.3 * i as f32), None).await);
    }
    ids.try_into().unwrap()
}

/// A walk-run graph over `[idle, walk, run]`, with a jump state on idle.
fn locomotion(name: &str, clips: &[String; 3]) -> Value {
    json!({
        "name": name,
        "parameters": {"speed": {"type": "float", "default": 0, "min": 0, "max": 6},
                       "jump": {"type": "trigger"}},
        "nodes": {
            "walkrun": {"blend1d": {"parameter": "speed", "points": [
                {"clip": clips[0], "at": 0}, {"clip": clips[1], "at": 1.5}, {"clip": clips[2], "at": 5}]}},
            "jump": {"clip": clips[0], "playback": "once"}},
        "machine": {"initial": "move",
            "states": {"move": {"node": "walkrun"}, "jump": {"node": "jump"}},
            "transitions": [
                {"from": "move", "to": "jump", "when": {"trigger": "jump"}, "duration": 0.1},
                {"from": "jump", "to": "move", "when": {"exit_time": 0.9}, "duration": 0.2}]}
    })
}

async fn send(req: reqwest::RequestBuilder) -> (u16, Value) {
    let resp = req.send().await.unwrap();
    let status = resp.status().as_u16();
    let text = resp.text().await.unwrap();
    (status, serde_json::from_str(&text).unwrap_or(Value::Null))
}

async fn post_graph(app: &TestApp, doc: &Value) -> (u16, Value) {
    send(app.http.post(app.url("/v1/graphs")).json(doc)).await
}

#[tokio::test]
async fn a_graph_is_created_read_listed_replaced_under_if_match_and_deleted() {
    let app = TestApp::start().await;
    let clips = three_clips(&app, "crud/").await;
    let resp = app.http.post(app.url("/v1/graphs")).json(&locomotion("hero/locomotion", &clips)).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    assert_eq!(resp.headers()["etag"], "\"1\"");
    let location = resp.headers()["location"].to_str().unwrap().to_owned();
    let created: Value = resp.json().await.unwrap();
    let id = created["id"].as_str().unwrap().to_owned();
    assert_eq!(location, format!("/v1/graphs/{id}"));
    // The summary: two nodes, the parameters' types, the states, each clip once in document order.
    assert_eq!((created["version"].as_u64(), created["nodes"].as_u64()), (Some(1), Some(2)));
    assert_eq!(created["parameters"], json!({"jump": "trigger", "speed": "float"}));
    assert_eq!(created["states"], json!(["jump", "move"]));
    assert_eq!(created["clips"], json!([clips[0], clips[1], clips[2]]));

    // The document as stored, with its ETag; If-None-Match of that version is a 304.
    let got = app.http.get(app.url(&location)).send().await.unwrap();
    assert_eq!(got.headers()["etag"], "\"1\"");
    let doc: Value = got.json().await.unwrap();
    assert_eq!(doc["nodes"]["walkrun"]["blend1d"]["points"][2], json!({"clip": clips[2], "at": 5.0}));
    let unchanged = app.http.get(app.url(&location)).header("if-none-match", "\"1\"").send().await.unwrap();
    assert_eq!(unchanged.status(), 304);

    // Names identify graphs.
    let (status, taken) = post_graph(&app, &locomotion("hero/locomotion", &clips)).await;
    assert_eq!((status, taken["code"].as_str(), taken["pointer"].as_str()), (409, Some("name_taken"), Some("/name")));

    // A stale If-Match is refused and changes nothing; the current one makes version 2.
    let mut faster = locomotion("hero/locomotion", &clips);
    faster["nodes"]["walkrun"]["blend1d"]["points"][2]["at"] = json!(4);
    let (status, stale) = send(app.http.put(app.url(&location)).header("if-match", "\"7\"").json(&faster)).await;
    assert_eq!((status, stale["code"].as_str()), (412, Some("version_mismatch")));
    assert_eq!(app.get_json(&location).await["nodes"]["walkrun"]["blend1d"]["points"][2]["at"], 5.0);
    let ok = app.http.put(app.url(&location)).header("if-match", "\"1\"").json(&faster).send().await.unwrap();
    assert_eq!((ok.status().as_u16(), ok.headers()["etag"].to_str().unwrap()), (200, "\"2\""));
    assert_eq!(app.get_json(&location).await["nodes"]["walkrun"]["blend1d"]["points"][2]["at"], 4.0);

    // Listed by name and by folder; a page of one has a cursor to the next.
    let other = locomotion("villain/locomotion", &clips);
    assert_eq!(post_graph(&app, &other).await.0, 201);
    let listed = app.get_json("/v1/graphs?name=hero/locomotion").await;
    assert_eq!(listed["graphs"].as_array().unwrap().len(), 1);
    assert_eq!(
        (listed["graphs"][0]["id"].as_str(), listed["graphs"][0]["version"].as_u64()),
        (Some(id.as_str()), Some(2))
    );
    let page = app.get_json("/v1/graphs?limit=1").await;
    assert_eq!(page["graphs"][0]["name"], "hero/locomotion");
    let cursor = page["next_cursor"].as_str().unwrap();
    let next = app.get_json(&format!("/v1/graphs?limit=1&cursor={cursor}")).await;
    assert_eq!((next["graphs"][0]["name"].as_str(), &next["next_cursor"]), (Some("villain/locomotion"), &Value::Null));

    // Deleted under If-Match (a stale one refused first); then it is gone.
    let (status, _) = send(app.http.delete(app.url(&location)).header("if-match", "\"1\"")).await;
    assert_eq!(status, 412);
    let (status, _) = send(app.http.delete(app.url(&location)).header("if-match", "\"2\"")).await;
    assert_eq!(status, 204);
    let (status, gone) = send(app.http.get(app.url(&location))).await;
    assert_eq!((status, gone["code"].as_str()), (404, Some("graph_not_found")));
    let (status, gone) = send(app.http.put(app.url(&location)).json(&faster)).await;
    assert_eq!((status, gone["code"].as_str()), (404, Some("graph_not_found")));
}

#[tokio::test]
async fn a_clip_that_does_not_exist_is_404_at_the_field_naming_it() {
    let app = TestApp::start().await;
    let mut clips = three_clips(&app, "missing/").await;
    clips[1] = "0190a1b2-c3d4-7e5f-8a9b-0c1d2e3f4a5b".to_owned();
    let (status, problem) = post_graph(&app, &locomotion("missing", &clips)).await;
    assert_eq!(
        (status, problem["code"].as_str(), problem["pointer"].as_str()),
        (404, Some("clip_not_found"), Some("/nodes/walkrun/blend1d/points/1/clip"))
    );
    // Nothing was stored.
    assert_eq!(app.get_json("/v1/graphs").await["graphs"], json!([]));
}

/// The graph of `locomotion` changed by `edit`.
fn edited(clips: &[String; 3], edit: impl FnOnce(&mut Value)) -> Value {
    let mut doc = locomotion("edited", clips);
    edit(&mut doc);
    doc
}

#[tokio::test]
async fn every_rule_of_the_graph_is_refused_with_a_pointer_into_the_document() {
    let app = TestApp::start().await;
    let clips = three_clips(&app, "rules/").await;
    let stranger = app.create_id(&clip("rules/stranger", &["root", "tail"], 0.1), None).await;
    let cases: Vec<(&str, Value, &str, &str)> = vec![
        (
            "three points on one line",
            edited(&clips, |d| {
                d["parameters"]["direction"] = json!({"type": "float", "default": 0, "min": -180, "max": 180});
                d["nodes"]["strafe"] = json!({"blend2d": {"x": "direction", "y": "speed", "points": [
                    {"clip": clips[0], "at": [0, 0]}, {"clip": clips[1], "at": [90, 1.5]},
                    {"clip": clips[2], "at": [180, 3]}]}});
            }),
            "degenerate_blend_space",
            "/nodes/strafe/blend2d/points",
        ),
        (
            "two layers nodes naming each other",
            edited(&clips, |d| {
                d["nodes"]["a"] = json!({"layers": [{"node": "b"}]});
                d["nodes"]["b"] = json!({"layers": [{"node": "a"}]});
            }),
            "node_cycle",
            "/nodes/a",
        ),
        (
            "a blend over a parameter the graph lacks",
            edited(&clips, |d| d["nodes"]["walkrun"]["blend1d"]["parameter"] = json!("sped")),
            "unknown_parameter",
            "/nodes/walkrun/blend1d/parameter",
        ),
        (
            "a state naming no node",
            edited(&clips, |d| d["machine"]["states"]["jump"]["node"] = json!("leap")),
            "unknown_node",
            "/machine/states/jump/node",
        ),
        (
            "a transition to no state",
            edited(&clips, |d| d["machine"]["transitions"][0]["to"] = json!("fly")),
            "unknown_state",
            "/machine/transitions/0/to",
        ),
        (
            "a default above the maximum",
            edited(&clips, |d| d["parameters"]["speed"]["default"] = json!(7)),
            "parameter_range",
            "/parameters/speed/default",
        ),
        (
            "a blend point on another rig",
            edited(&clips, |d| d["nodes"]["walkrun"]["blend1d"]["points"][1]["clip"] = json!(stranger)),
            "incompatible_skeleton",
            "/nodes/walkrun/blend1d/points/1/clip",
        ),
    ];
    for (what, doc, code, pointer) in cases {
        let (status, problem) = post_graph(&app, &doc).await;
        assert_eq!(
            (status, problem["code"].as_str(), problem["pointer"].as_str()),
            (422, Some(code), Some(pointer)),
            "{what}: {problem}"
        );
    }
    assert_eq!(app.get_json("/v1/graphs").await["graphs"], json!([]), "nothing refused was stored");
}

#[tokio::test]
async fn the_limits_refuse_a_graph_before_it_is_built() {
    let app = TestApp::builder()
        .configure(|c| {
            c.limits.max_graph_nodes = 3;
            c.limits.max_blend_points = 4;
            c.limits.max_graph_bytes = 4096;
        })
        .start()
        .await;
    let clips = three_clips(&app, "limits/").await;
    let points: Vec<Value> = (0..5).map(|i| json!({"clip": clips[i % 3], "at": i})).collect();
    let wide = edited(&clips, |d| d["nodes"]["walkrun"]["blend1d"]["points"] = json!(points));
    let (status, problem) = post_graph(&app, &wide).await;
    assert_eq!(
        (status, problem["code"].as_str(), problem["pointer"].as_str()),
        (422, Some("too_many_points"), Some("/nodes/walkrun/blend1d/points"))
    );
    let crowded = edited(&clips, |d| {
        for n in 0..2 {
            d["nodes"][format!("extra{n}")] = json!({"clip": clips[0]});
        }
    });
    let (status, problem) = post_graph(&app, &crowded).await;
    assert_eq!(
        (status, problem["code"].as_str(), problem["pointer"].as_str()),
        (422, Some("too_many_nodes"), Some("/nodes"))
    );
    let padded = edited(&clips, |d| d["name"] = json!("x".repeat(5000)));
    let (status, problem) = post_graph(&app, &padded).await;
    assert_eq!((status, problem["code"].as_str()), (413, Some("body_too_large")));
    assert!(problem["detail"].as_str().unwrap().contains("max_graph_bytes"), "{problem}");
}

/// A gRPC refusal's status code and its stable code.
fn refusal(status: &tonic::Status) -> (tonic::Code, &str) {
    (status.code(), status.metadata().get("x-error-code").unwrap().to_str().unwrap())
}

#[tokio::test]
async fn the_grpc_twins_store_the_same_graphs_and_refuse_with_the_same_codes() {
    let app = TestApp::start().await;
    let clips = three_clips(&app, "grpc/").await;
    let mut grpc = app.grpc().await;
    let document = locomotion("grpc/locomotion", &clips).to_string();
    let made = grpc
        .create_graph(pb::CreateGraphRequest { document: document.clone(), replace: false })
        .await
        .unwrap()
        .into_inner();
    assert_eq!((made.version, made.nodes, made.states.clone()), (1, 2, vec!["jump".to_owned(), "move".to_owned()]));
    assert_eq!(made.parameters["speed"], "float");
    assert_eq!(made.clips, clips.to_vec());
    // The same graph over REST.
    let rest = app.get_json(&format!("/v1/graphs/{}", made.id)).await;
    assert_eq!(rest["name"], "grpc/locomotion");

    let record =
        grpc.get_graph(pb::GetGraphRequest { graph_id: "name:grpc/locomotion".into() }).await.unwrap().into_inner();
    assert_eq!(record.summary.unwrap().id, made.id);
    let stored: Value = serde_json::from_str(&record.document).unwrap();
    assert_eq!(stored, rest);

    let taken =
        grpc.create_graph(pb::CreateGraphRequest { document: document.clone(), replace: false }).await.unwrap_err();
    assert_eq!(refusal(&taken), (tonic::Code::AlreadyExists, "name_taken"));
    let replaced = grpc
        .create_graph(pb::CreateGraphRequest { document: document.clone(), replace: true })
        .await
        .unwrap()
        .into_inner();
    assert_eq!((replaced.id.as_str(), replaced.version), (made.id.as_str(), 2));

    let unknown = edited(&clips, |d| d["nodes"]["walkrun"]["blend1d"]["parameter"] = json!("sped")).to_string();
    let bad = grpc.create_graph(pb::CreateGraphRequest { document: unknown, replace: false }).await.unwrap_err();
    assert_eq!(refusal(&bad), (tonic::Code::InvalidArgument, "unknown_parameter"));
    assert!(bad.message().ends_with("(at /nodes/walkrun/blend1d/parameter)"), "{}", bad.message());
    let mut missing = clips.clone();
    missing[2] = "0190a1b2-c3d4-7e5f-8a9b-0c1d2e3f4a5b".to_owned();
    let document_missing = locomotion("grpc/missing", &missing).to_string();
    let bad =
        grpc.create_graph(pb::CreateGraphRequest { document: document_missing, replace: false }).await.unwrap_err();
    assert_eq!(refusal(&bad), (tonic::Code::NotFound, "clip_not_found"));
    assert!(bad.message().ends_with("(at /nodes/walkrun/blend1d/points/2/clip)"), "{}", bad.message());

    let stale = pb::ReplaceGraphRequest { graph_id: made.id.clone(), document: document.clone(), if_version: Some(1) };
    assert_eq!(
        refusal(&grpc.replace_graph(stale).await.unwrap_err()),
        (tonic::Code::FailedPrecondition, "version_mismatch")
    );
    let current = pb::ReplaceGraphRequest { graph_id: made.id.clone(), document, if_version: Some(2) };
    assert_eq!(grpc.replace_graph(current).await.unwrap().into_inner().version, 3);

    let listed =
        grpc.list_graphs(pb::ListGraphsRequest { name_prefix: "grpc/".into(), ..Default::default() }).await.unwrap();
    assert_eq!(listed.into_inner().graphs.iter().map(|g| g.version).collect::<Vec<_>>(), [3]);
    grpc.delete_graph(pb::DeleteGraphRequest { graph_id: made.id.clone(), if_version: Some(3) }).await.unwrap();
    let gone = grpc.get_graph(pb::GetGraphRequest { graph_id: made.id }).await.unwrap_err();
    assert_eq!(refusal(&gone), (tonic::Code::NotFound, "graph_not_found"));
}
