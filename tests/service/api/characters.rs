//! `/v1/characters` (docs/characters.md): characters stored and versioned
//! like clips, their role maps as the summaries report them, imports of a
//! glTF skin (CesiumMan) and a BVH hierarchy (CMU 131_03), the mesh, and the
//! refusals, against the real server over HTTP.

use glam::{DMat4, DQuat, DVec3};
use serde_json::{Value, json};

use super::TestApp;
use crate::common::testdata;

/// A Mixamo-named upper body: hips, spine, neck, head and both arms, no legs.
fn legless(name: &str) -> Value {
    let joint = |name: &str, parent: Option<&str>, y: f64| json!({"name": name, "parent": parent, "rest": {"translation": [0.0, y, 0.0]}});
    let arm = |name: &str, parent: &str, x: f64| json!({"name": name, "parent": parent, "rest": {"translation": [x, 0.0, 0.0]}});
    json!({
        "name": name,
        "skeleton": {"joints": [
            joint("mixamorig:Hips", None, 1.0),
            joint("mixamorig:Spine", Some("mixamorig:Hips"), 0.1),
            joint("mixamorig:Spine1", Some("mixamorig:Spine"), 0.1),
            joint("mixamorig:Neck", Some("mixamorig:Spine1"), 0.3),
            joint("mixamorig:Head", Some("mixamorig:Neck"), 0.1),
            arm("mixamorig:LeftArm", "mixamorig:Spine1", 0.2),
            arm("mixamorig:LeftForeArm", "mixamorig:LeftArm", 0.3),
            arm("mixamorig:RightArm", "mixamorig:Spine1", -0.2),
            arm("mixamorig:RightForeArm", "mixamorig:RightArm", -0.3),
        ]},
    })
}

async fn post(app: &TestApp, path: &str, body: &Value) -> reqwest::Response {
    app.http.post(app.url(path)).json(body).send().await.unwrap()
}

async fn problem(resp: reqwest::Response) -> (u16, Value) {
    (resp.status().as_u16(), resp.json().await.unwrap())
}

#[tokio::test]
async fn a_character_is_created_read_replaced_under_if_match_and_deleted() {
    let app = TestApp::start().await;
    let resp = post(&app, "/v1/characters", &legless("upper")).await;
    assert_eq!(resp.status(), 201);
    let location = resp.headers()["location"].to_str().unwrap().to_owned();
    assert_eq!(resp.headers()["etag"], "\"1\"");
    let created: Value = resp.json().await.unwrap();
    let id = created["id"].as_str().unwrap().to_owned();
    assert_eq!(location, format!("/v1/characters/{id}"));
    assert_eq!((created["version"].as_u64(), created["joints"].as_u64()), (Some(1), Some(9)));
    assert_eq!(created["mesh"], false);

    // The document as stored: the skeleton as sent.
    let doc = app.get_json(&location).await;
    assert_eq!(doc["name"], "upper");
    assert_eq!(doc["skeleton"]["joints"].as_array().unwrap().len(), 9);
    assert_eq!(doc["skeleton"]["joints"][1]["parent"], "mixamorig:Hips");

    // A replace at a stale version is refused and changes nothing; at the current one it bumps the version.
    let mut renamed = legless("upper-2");
    renamed["roles"] = json!({"chest": "mixamorig:Spine1"});
    let stale = app.http.put(app.url(&location)).header("if-match", "\"7\"").json(&renamed).send().await.unwrap();
    let (status, body) = problem(stale).await;
    assert_eq!((status, body["code"].as_str()), (412, Some("version_mismatch")));
    let ok = app.http.put(app.url(&location)).header("if-match", "\"1\"").json(&renamed).send().await.unwrap();
    assert_eq!(ok.status(), 200);
    assert_eq!(ok.headers()["etag"], "\"2\"");
    let replaced: Value = ok.json().await.unwrap();
    assert_eq!((replaced["id"].as_str(), replaced["name"].as_str()), (Some(id.as_str()), Some("upper-2")));
    assert_eq!(replaced["roles"]["chest"], json!({"joint": "mixamorig:Spine1", "by": "given"}));

    // Listed by its folder-like prefix, then deleted (a stale If-Match first refused).
    let listed = app.get_json("/v1/characters?name_prefix=upper-").await;
    let names: Vec<&str> =
        listed["characters"].as_array().unwrap().iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["upper-2"]);
    let stale = app.http.delete(app.url(&location)).header("if-match", "\"1\"").send().await.unwrap();
    assert_eq!(stale.status(), 412);
    let gone = app.http.delete(app.url(&location)).header("if-match", "\"2\"").send().await.unwrap();
    assert_eq!(gone.status(), 204);
    let (status, body) = problem(app.http.get(app.url(&location)).send().await.unwrap()).await;
    assert_eq!((status, body["code"].as_str()), (404, Some("character_not_found")));
}

#[tokio::test]
async fn names_identify_characters_and_replace_true_makes_a_new_version() {
    let app = TestApp::start().await;
    let first: Value = post(&app, "/v1/characters", &legless("rig")).await.json().await.unwrap();
    let (status, body) = problem(post(&app, "/v1/characters", &legless("rig")).await).await;
    assert_eq!((status, body["code"].as_str(), body["pointer"].as_str()), (409, Some("name_taken"), Some("/name")));
    assert!(body["detail"].as_str().unwrap().contains(first["id"].as_str().unwrap()), "{body}");

    let again = post(&app, "/v1/characters?replace=true", &legless("rig")).await;
    assert_eq!(again.status(), 200);
    let again: Value = again.json().await.unwrap();
    assert_eq!((again["id"].as_str(), again["version"].as_u64()), (first["id"].as_str(), Some(2)));
    let all = app.get_json("/v1/characters?name=rig").await;
    assert_eq!(all["characters"].as_array().unwrap().len(), 1);

    // A rename onto a taken name is refused too.
    let other: Value = post(&app, "/v1/characters", &legless("other")).await.json().await.unwrap();
    let url = format!("/v1/characters/{}", other["id"].as_str().unwrap());
    let (status, body) = problem(app.http.put(app.url(&url)).json(&legless("rig")).send().await.unwrap()).await;
    assert_eq!((status, body["code"].as_str()), (409, Some("name_taken")));
}

/// The legless rig: its named roles read by the Mixamo table, and a
/// `missing_role` warning for each leg role and nothing else essential.
#[tokio::test]
async fn roles_say_how_they_were_found_and_a_rig_without_legs_is_warned_about() {
    let app = TestApp::start().await;
    let mut doc = legless("upper");
    doc["roles"] = json!({"head": "mixamorig:Neck", "neck": null});
    let created: Value = post(&app, "/v1/characters", &doc).await.json().await.unwrap();
    assert_eq!(created["family"], "mixamo");
    assert_eq!(created["roles"]["hips"], json!({"joint": "mixamorig:Hips", "by": "name"}));
    // Mixamo: Spine → spine, Spine1 → chest.
    assert_eq!(created["roles"]["chest"], json!({"joint": "mixamorig:Spine1", "by": "name"}));
    assert_eq!(created["roles"]["leftUpperArm"], json!({"joint": "mixamorig:LeftArm", "by": "name"}));
    // Given roles win; a role given as null stays unmapped.
    assert_eq!(created["roles"]["head"], json!({"joint": "mixamorig:Neck", "by": "given"}));
    assert!(created["roles"].get("neck").is_none(), "{created}");
    let missing: Vec<&str> = (created["warnings"].as_array().unwrap().iter())
        .map(|w| {
            assert_eq!(w["code"], "missing_role");
            w["pointer"].as_str().unwrap()
        })
        .collect();
    assert_eq!(missing, ["/roles/leftUpperLeg", "/roles/leftLowerLeg", "/roles/rightUpperLeg", "/roles/rightLowerLeg"]);
}

#[tokio::test]
async fn bad_characters_are_refused_with_a_pointer() {
    let app = TestApp::start().await;
    let mut unknown_joint = legless("bad");
    unknown_joint["roles"] = json!({"leftHand": "mixamorig:LeftHand"});
    let (status, body) = problem(post(&app, "/v1/characters", &unknown_joint).await).await;
    assert_eq!(
        (status, body["code"].as_str(), body["pointer"].as_str()),
        (422, Some("unknown_joint"), Some("/roles/leftHand"))
    );

    let mut unknown_role = legless("bad");
    unknown_role["roles"] = json!({"tail": "mixamorig:Hips"});
    let (status, body) = problem(post(&app, "/v1/characters", &unknown_role).await).await;
    assert_eq!(
        (status, body["code"].as_str(), body["pointer"].as_str()),
        (422, Some("unknown_role"), Some("/roles/tail"))
    );

    let mut orphan = legless("bad");
    orphan["skeleton"]["joints"][2]["parent"] = json!("nobody");
    let (status, body) = problem(post(&app, "/v1/characters", &orphan).await).await;
    assert_eq!(status, 422, "{body}");
    assert!(body["pointer"].as_str().unwrap().starts_with("/skeleton/joints/2"), "{body}");

    let empty = json!({"name": "bad", "skeleton": {"joints": []}});
    let (status, body) = problem(post(&app, "/v1/characters", &empty).await).await;
    assert_eq!(
        (status, body["code"].as_str(), body["pointer"].as_str()),
        (422, Some("empty_skeleton"), Some("/skeleton/joints"))
    );

    let (status, body) = problem(post(&app, "/v1/characters", &json!({"name": "bad"})).await).await;
    assert_eq!((status, body["code"].as_str()), (422, Some("invalid_field")), "{body}");
    assert!(app.get_json("/v1/characters").await["characters"].as_array().unwrap().is_empty());
}

/// The model transform of every joint of a character document (parents first), in f64.
fn model_transforms(joints: &[Value]) -> Vec<DMat4> {
    let v3 = |v: &Value, d: f64| {
        v.as_array().map_or(DVec3::splat(d), |a| {
            DVec3::new(a[0].as_f64().unwrap(), a[1].as_f64().unwrap(), a[2].as_f64().unwrap())
        })
    };
    let mut model: Vec<DMat4> = Vec::new();
    for joint in joints {
        let rest = &joint["rest"];
        let q = rest["rotation"].as_array().map_or(DQuat::IDENTITY, |a| {
            DQuat::from_xyzw(
                a[0].as_f64().unwrap(),
                a[1].as_f64().unwrap(),
                a[2].as_f64().unwrap(),
                a[3].as_f64().unwrap(),
            )
        });
        let local = DMat4::from_scale_rotation_translation(v3(&rest["scale"], 1.0), q, v3(&rest["translation"], 0.0));
        let parent = joint["parent"].as_str().map(|p| joints.iter().position(|j| j["name"] == p).unwrap());
        model.push(parent.map_or(DMat4::IDENTITY, |p| model[p]) * local);
    }
    model
}

/// CesiumMan: one skin of 19 unnamed joints. Imported as a character, its
/// rest is the bind pose in the skeleton's frame: every skin joint's model
/// transform times its inverse bind matrix is one and the same matrix (the
/// mesh's Z-up bind space turned into the skeleton's Y-up frame by the node
/// above the joints; composed here in f64 from the stored document), the
/// figure stands along +Y as its clip does, its left leg is `node7` (it faces
/// +X, so its left is -Z), and its skinned mesh is served as a clip's is.
#[tokio::test]
async fn cesium_man_imports_at_its_bind_pose_with_its_mesh() {
    let app = TestApp::start().await;
    let file = testdata("gltf/CesiumMan/CesiumMan.gltf");
    let gltf: Value = serde_json::from_slice(&file).unwrap();
    let skin_joints = gltf["skins"][0]["joints"].as_array().unwrap().len();
    let resp = app
        .http
        .post(app.url("/v1/characters/import?format=gltf&name=cesium"))
        .body(file.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 201);
    let body: Value = resp.json().await.unwrap();
    let characters = body["characters"].as_array().unwrap();
    assert_eq!(characters.len(), 1, "{body}");
    let summary = &characters[0];
    assert_eq!((summary["name"].as_str(), summary["mesh"].as_bool()), (Some("cesium"), Some(true)));
    assert!(summary["joints"].as_u64().unwrap() as usize >= skin_joints);
    assert!(summary["roles"].get("hips").is_some(), "a humanoid's hips are found: {summary}");

    let id = summary["id"].as_str().unwrap();
    let doc = app.get_json(&format!("/v1/characters/{id}")).await;
    let joints = doc["skeleton"]["joints"].as_array().unwrap();
    let model = model_transforms(joints);
    let mut frames = Vec::new();
    for (joint, m) in joints.iter().zip(&model) {
        let Some(ib) = joint["inverse_bind"].as_array() else { continue };
        let ib: Vec<f64> = ib.iter().map(|x| x.as_f64().unwrap()).collect();
        frames.push((joint["name"].clone(), *m * DMat4::from_cols_slice(&ib)));
    }
    assert_eq!(frames.len(), skin_joints);
    for (name, frame) in &frames {
        assert!(frame.abs_diff_eq(frames[0].1, 1e-4), "{name}: {frame} against {}", frames[0].1);
    }
    let heights: Vec<f64> = model.iter().map(|m| m.w_axis.y).collect();
    let (low, high) = heights.iter().fold((f64::MAX, f64::MIN), |(l, h), &y| (l.min(y), h.max(y)));
    assert!(high - low > 1.0, "standing along +Y: heights {low}..{high}");
    assert_eq!(summary["roles"]["leftUpperLeg"]["joint"], "node7", "{summary}");

    let mesh = app.http.get(app.url(&format!("/v1/characters/{id}/mesh"))).send().await.unwrap();
    assert_eq!(mesh.status(), 200);
    assert_eq!(mesh.headers()["content-type"], "application/vnd.inbetween.mesh");
    let etag = mesh.headers()["etag"].to_str().unwrap().to_owned();
    assert_eq!(&mesh.bytes().await.unwrap()[..4], b"INBM");
    let again = app.http.get(app.url(&format!("/v1/characters/{id}/mesh"))).header("if-none-match", &etag);
    assert_eq!(again.send().await.unwrap().status(), 304);

    // The same file imported as clips makes the same character (one skin), listed with the clips.
    let clips = app
        .http
        .post(app.url("/v1/clips/import?format=gltf&name=cesium&replace=true"))
        .body(file)
        .send()
        .await
        .unwrap();
    assert_eq!(clips.status(), 201);
    let clips: Value = clips.json().await.unwrap();
    assert_eq!(clips["clips"].as_array().unwrap().len(), 1);
    let made = clips["characters"].as_array().unwrap();
    assert_eq!(made.len(), 1, "{clips}");
    assert_eq!(made[0]["mesh"], true);
}

/// CMU 131_03 (ASF-style names): one character of its hierarchy, roles read
/// by the CMU ASF table (`LeftShoulder` is the upper arm there), the hips
/// standing where the first frame has them.
#[tokio::test]
async fn a_cmu_hierarchy_imports_with_its_roles_by_name() {
    let app = TestApp::start().await;
    let bvh = testdata("bvh/131_03.bvh");
    let resp = app
        .http
        .post(app.url("/v1/characters/import?format=bvh&name=cmu&scale=0.05644444"))
        .body(bvh.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 201);
    let body: Value = resp.json().await.unwrap();
    let cmu = &body["characters"][0];
    assert_eq!(
        (cmu["name"].as_str(), cmu["family"].as_str(), cmu["mesh"].as_bool()),
        (Some("cmu"), Some("cmu_asf"), Some(false))
    );
    for (role, joint) in [
        ("hips", "Hips"),
        ("leftUpperArm", "LeftShoulder"),
        ("leftLowerArm", "LeftElbow"),
        ("leftLowerLeg", "LeftKnee"),
        ("rightFoot", "RightAnkle"),
    ] {
        assert_eq!(cmu["roles"][role], json!({"joint": joint, "by": "name"}), "{role}");
    }
    assert!(cmu["warnings"].as_array().unwrap().is_empty(), "{cmu}");

    // The root's rest is the first frame's position (the first three numbers after `Frame Time`), scaled.
    let text = String::from_utf8(bvh).unwrap();
    let first_frame = text.lines().skip_while(|l| !l.starts_with("Frame Time")).nth(1).unwrap();
    let first: Vec<f64> = first_frame.split_whitespace().take(3).map(|x| x.parse().unwrap()).collect();
    let doc = app.get_json(&format!("/v1/characters/{}", cmu["id"].as_str().unwrap())).await;
    let hips = &doc["skeleton"]["joints"][0];
    assert_eq!(hips["name"], "Hips");
    for (axis, at) in first.iter().enumerate() {
        let got = hips["rest"]["translation"][axis].as_f64().unwrap();
        assert!((got - at * 0.05644444).abs() < 1e-4, "axis {axis}: {got} vs {}", at * 0.05644444);
    }
    // A BVH has no skin to draw.
    let mesh =
        app.http.get(app.url(&format!("/v1/characters/{}/mesh", cmu["id"].as_str().unwrap()))).send().await.unwrap();
    let (status, body) = problem(mesh).await;
    assert_eq!((status, body["code"].as_str()), (404, Some("no_mesh")));
}

#[tokio::test]
async fn a_file_without_a_skin_makes_no_character() {
    let app = TestApp::start().await;
    let triangle = testdata("gltf/AnimatedTriangle/AnimatedTriangle.gltf");
    let (status, body) =
        problem(app.http.post(app.url("/v1/characters/import?format=gltf")).body(triangle).send().await.unwrap()).await;
    assert_eq!((status, body["code"].as_str()), (422, Some("no_skins")), "{body}");
}

/// The gRPC twins: the same store, summaries and codes as REST.
#[tokio::test]
async fn the_grpc_twins_write_read_and_refuse_as_rest_does() {
    use formats::wire::proto::pb;
    let app = TestApp::start().await;
    let mut grpc = app.grpc().await;
    let joint = |name: &str, parent: Option<&str>, y: f32| pb::Joint {
        name: name.into(),
        parent: parent.map(str::to_owned),
        rest: Some(pb::Transform { translation: vec![0.0, y, 0.0], ..Default::default() }),
        inverse_bind: vec![],
    };
    let character = |name: &str, given: &[(&str, &str)]| pb::Character {
        name: name.into(),
        skeleton: Some(pb::Skeleton {
            joints: vec![
                joint("Hips", None, 1.0),
                joint("Spine", Some("Hips"), 0.1),
                joint("Chest", Some("Spine"), 0.2),
            ],
        }),
        roles: given.iter().map(|(r, j)| (r.to_string(), j.to_string())).collect(),
        unmapped_roles: vec!["chest".into()],
    };
    let made = grpc
        .create_character(pb::CreateCharacterRequest {
            character: Some(character("g", &[("spine", "Spine")])),
            replace: false,
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!((made.version, made.joints), (1, 3));
    assert_eq!(made.roles["spine"], pb::RoleJoint { joint: "Spine".into(), by: "given".into() });
    assert!(!made.roles.contains_key("chest"), "unmapped as given");
    assert!(made.warnings.iter().any(|w| w.code == "missing_role" && w.pointer == "/roles/leftUpperLeg"));

    // Read back by name, as over REST by id.
    let record =
        grpc.get_character(pb::GetCharacterRequest { character_id: "name:g".into() }).await.unwrap().into_inner();
    let doc = record.character.unwrap();
    assert_eq!((doc.skeleton.unwrap().joints.len(), doc.unmapped_roles), (3, vec!["chest".to_owned()]));
    let rest = app.get_json(&format!("/v1/characters/{}", made.id)).await;
    assert_eq!(rest["roles"], json!({"spine": "Spine", "chest": null}));

    let taken = grpc
        .create_character(pb::CreateCharacterRequest { character: Some(character("g", &[])), replace: false })
        .await
        .unwrap_err();
    assert_eq!(
        (taken.code(), taken.metadata().get("x-error-code").unwrap().to_str().unwrap()),
        (tonic::Code::AlreadyExists, "name_taken")
    );
    let stale = pb::ReplaceCharacterRequest {
        character_id: made.id.clone(),
        character: Some(character("g", &[])),
        if_version: Some(9),
    };
    assert_eq!(grpc.replace_character(stale).await.unwrap_err().code(), tonic::Code::FailedPrecondition);
    let bad = pb::CreateCharacterRequest { character: Some(character("h", &[("leftHand", "Hand")])), replace: false };
    let bad = grpc.create_character(bad).await.unwrap_err();
    assert_eq!(
        (bad.code(), bad.metadata().get("x-error-code").unwrap().to_str().unwrap()),
        (tonic::Code::InvalidArgument, "unknown_joint")
    );

    let listed = grpc.list_characters(pb::ListCharactersRequest::default()).await.unwrap().into_inner();
    assert_eq!(listed.characters.len(), 1);
    let bvh = testdata("bvh/131_03.bvh");
    let imported = grpc
        .import_character(pb::ImportCharacterRequest {
            data: bvh,
            format: "bvh".into(),
            name: "cmu".into(),
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(imported.characters[0].family, "cmu_asf");
    grpc.delete_character(pb::DeleteCharacterRequest { character_id: made.id.clone(), if_version: Some(1) })
        .await
        .unwrap();
    let gone = grpc.get_character(pb::GetCharacterRequest { character_id: made.id }).await.unwrap_err();
    assert_eq!(
        (gone.code(), gone.metadata().get("x-error-code").unwrap().to_str().unwrap()),
        (tonic::Code::NotFound, "character_not_found")
    );
}
