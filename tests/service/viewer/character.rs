//! A take played on a character in the viewer: a CMU BVH take (131_01, its own rig,
//! no mesh) picked with CesiumMan (a glTF skin with other joint names). The
//! page then shows CesiumMan's joints, posed as the server retargets the
//! take (the same model-space positions `POST /v1/poses` answers), and its
//! skinned mesh moving; back on the take's own skeleton, neither remains.
//!
//! `INBETWEEN_CHARACTER_SCREENSHOT=docs/images/viewer-character.png` saves
//! the page with the take playing on CesiumMan (the README's picture).

use serde_json::{Value, json};

use super::{TOKEN, differs, floats, post_json, set_value, viewer_on_clip};
use crate::common::{TestApp, testdata};

/// `file` imported at `route` (a clip or character import) under `name`; the first summary.
pub(super) async fn import(app: &TestApp, route: &str, file: &str, name: &str) -> Value {
    let url = app.url(&format!("{route}?name={name}&replace=true"));
    let resp = app.http.post(url).bearer_auth(TOKEN).body(testdata(file)).send().await.unwrap();
    assert_eq!(resp.status(), 201, "{file}");
    let body: Value = resp.json().await.unwrap();
    let list = if route.contains("characters") { "characters" } else { "clips" };
    body[list][0].clone()
}

/// CesiumMan's vertex and skin joint counts, from the glTF file itself.
fn cesium_mesh() -> (u64, usize) {
    let gltf: Value = serde_json::from_slice(&testdata("gltf/CesiumMan/CesiumMan.gltf")).unwrap();
    let position = gltf["meshes"][0]["primitives"][0]["attributes"]["POSITION"].as_u64().unwrap();
    let vertices = gltf["accessors"][position as usize]["count"].as_u64().unwrap();
    (vertices, gltf["skins"][0]["joints"].as_array().unwrap().len())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cmu_take_plays_on_cesium_man_s_skinned_mesh() {
    let app = super::start().await;
    let cesium = import(&app, "/v1/characters/import", "gltf/CesiumMan/CesiumMan.gltf", "cesium").await;
    let character = cesium["id"].as_str().unwrap().to_owned();
    let take = import(&app, "/v1/clips/import", "bvh/131_01.bvh", "131_01").await;
    let take = take["id"].as_str().unwrap().to_owned();
    let Some(mut browser) = viewer_on_clip(&app, &take).await else { return };
    let page = &mut browser.page;
    assert_eq!(page.eval("window.inbetweenViewer.mesh.info").await, Value::Null, "a BVH take has no mesh");

    let option =
        format!("[...document.getElementById('character').options].some(o => o.value === {})", json!(character));
    page.wait_for(&option, 10).await;
    set_value(page, "character", &character).await;
    let info = page
        .wait_for(
            &format!(
                "window.inbetweenViewer.mesh.character === {} && window.inbetweenViewer.mesh.info",
                json!(character)
            ),
            20,
        )
        .await;
    let (vertices, skin_joints) = cesium_mesh();
    assert_eq!((&info["vertices"], &info["joints"]), (&json!(vertices), &json!(skin_joints)), "{info}");

    // A paused pose: CesiumMan's joints, where the server puts them.
    let time = 1.5;
    set_value(page, "seek", &time.to_string()).await;
    page.wait_for(
        &format!(
            "window.inbetweenViewer.state.requestTime === {time} && window.inbetweenViewer.state.names.length > 0"
        ),
        10,
    )
    .await;
    let shown = page.eval("window.inbetweenViewer.state").await;
    let doc = app.get_json(&format!("/v1/characters/{character}")).await;
    let joints: Vec<&str> =
        doc["skeleton"]["joints"].as_array().unwrap().iter().map(|j| j["name"].as_str().unwrap()).collect();
    let names: Vec<&str> = shown["names"].as_array().unwrap().iter().map(|n| n.as_str().unwrap()).collect();
    assert_eq!(names, joints, "the page shows CesiumMan's joints");
    let motion = json!({"layers": [{"clip": take}], "character": character});
    let pose = post_json(&app, "/v1/poses", &json!({"motion": motion, "time": time, "space": "model"})).await;
    for (k, joint) in pose["joints"].as_array().unwrap().iter().enumerate() {
        let (got, want) = (floats(&shown["positions"][k]), floats(&joint["translation"]));
        let off = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(off < 1e-6, "{}: page {got:?}, server {want:?}", joint["name"]);
    }

    // Playing, the skinned mesh moves.
    super::set_value(page, "fps", "30").await;
    page.eval("document.getElementById('play').click()").await;
    page.wait_for("Number(document.getElementById('seq').textContent) >= 5", 10).await;
    let first = super::canvas_pixels(page, "mesh-gl").await;
    let seq = super::text_number(page, "seq").await;
    super::next_frame(page, seq + 8.0).await;
    let second = super::canvas_pixels(page, "mesh-gl").await;
    let moved = first.iter().zip(&second).filter(|(a, b)| differs(**a, **b, 24)).count();
    assert!(moved >= 300, "CesiumMan changes {moved} pixels in 300 ms");
    let frame_joints = page.eval("window.inbetweenViewer.panel.lastFrame.pose.joints.length").await;
    assert_eq!(frame_joints, json!(joints.len()), "the stream's frames are CesiumMan's");
    // The README's picture of a take on a character.
    page.picture("INBETWEEN_CHARACTER_SCREENSHOT", std::time::Duration::from_millis(500), 0.7).await;

    // Back on the take's own skeleton: its joints, and no mesh.
    set_value(page, "character", "").await;
    page.wait_for("window.inbetweenViewer.mesh.info === null && window.inbetweenViewer.state.character === null", 10)
        .await;
    let take_doc = app.get_json(&format!("/v1/clips/{take}")).await;
    let take_joints = take_doc["skeleton"]["joints"].as_array().unwrap().len();
    page.wait_for(&format!("window.inbetweenViewer.panel.lastFrame.pose.joints.length === {take_joints}"), 10).await;
    assert_eq!(page.eval("window.inbetweenViewer.cspViolations").await, json!([]));
}
