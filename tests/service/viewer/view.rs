//! The 3D view as a tool: a click on a joint selects it (the curve and the
//! IK joint follow, the view frames it, a cyan ring marks it), a BVH figure
//! is framed to fill most of the view's height, and a Z-up file's import
//! warning puts a hint over the view.

use std::path::Path;

use serde_json::{Value, json};

use super::cdp::Page;
use super::{TOKEN, canvas_pixels, differs, set_value, start, viewer_on_clip};
use crate::common::WAVE;

/// The selection ring's colour (scene.js SELECTED_COLOR).
const CYAN: [u8; 3] = [0x3e, 0xe0, 0xff];

/// Where joint `name` is on the page, in CSS pixels of the viewport, through the page's own camera.
async fn joint_on_page(page: &mut Page, name: &str) -> [f64; 2] {
    let at = page
        .eval(&format!(
            "(v => {{ const s = v.state, cam = v.sceneCamera(), p = s.positions[s.names.indexOf({})]; \
             const [x, y] = v.toScreen(cam, v.toCamera(cam, p)); const r = document.getElementById('scene').getBoundingClientRect(); \
             return [r.left + x / cam.dpr, r.top + y / cam.dpr]; }})(window.inbetweenViewer)",
            json!(name)
        ))
        .await;
    serde_json::from_value(at).unwrap()
}

/// A click (press and release without moving) at `at`.
async fn click_at(page: &mut Page, at: [f64; 2]) {
    page.drag(at, at, 0).await;
}

/// How much of the view's height the drawn joints span, and whether all are inside the view.
const FIGURE: &str = "(v => { const s = v.state, cam = v.sceneCamera(); \
    const at = s.positions.filter((p, i) => p && s.drawnJoints[i]).map(p => v.toScreen(cam, v.toCamera(cam, p))); \
    const ys = at.map(p => p[1]), xs = at.map(p => p[0]); \
    return [(Math.max(...ys) - Math.min(...ys)) / (2 * cam.cy), at.every(([x, y]) => x >= 0 && y >= 0 && x <= 2 * cam.cx && y <= 2 * cam.cy)]; \
    })(window.inbetweenViewer)";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_click_on_a_joint_selects_and_frames_it() {
    let app = start().await;
    let id = app.create_id(WAVE, Some(TOKEN)).await;
    let Some(mut browser) = viewer_on_clip(&app, &id).await else { return };
    let page = &mut browser.page;
    page.wait_for("window.inbetweenViewer.drawn?.joints === 2", 10).await;
    set_value(page, "curve-joint", "root").await;
    page.wait_for("window.inbetweenViewer.curve?.joint === 'root'", 10).await;
    assert_eq!(canvas_pixels(page, "scene").await.iter().filter(|p| !differs(**p, CYAN, 30)).count(), 0);

    // A click 6 px beside the arm's joint picks it.
    let [x, y] = joint_on_page(page, "arm").await;
    click_at(page, [x + 6.0, y - 3.0]).await;
    page.wait_for("window.inbetweenViewer.state.selectedJoint === 'arm'", 10).await;
    // Its curve is plotted, it is the IK joint, and the view is centred on it.
    page.wait_for("window.inbetweenViewer.curve?.joint === 'arm'", 10).await;
    assert_eq!(page.eval("document.getElementById('ik-joint').value").await, "arm");
    let centred = page
        .eval("(v => { const s = v.state; return [s.camera.target, s.positions[s.names.indexOf('arm')]]; })(window.inbetweenViewer)")
        .await;
    let [target, arm]: [[f64; 3]; 2] = serde_json::from_value(centred).unwrap();
    assert_eq!(target, arm, "framed on the joint");
    let [cx, cy] = joint_on_page(page, "arm").await;
    let view: [f64; 4] = serde_json::from_value(
        page.eval(
            "(r => [r.left, r.top, r.width, r.height])(document.getElementById('scene').getBoundingClientRect())",
        )
        .await,
    )
    .unwrap();
    assert!(
        (cx - (view[0] + view[2] / 2.0)).abs() < 2.0 && (cy - (view[1] + view[3] / 2.0)).abs() < 2.0,
        "at the centre: {cx}, {cy} in {view:?}"
    );
    // A cyan ring marks it on screen.
    let ring = canvas_pixels(page, "scene").await.iter().filter(|p| !differs(**p, CYAN, 30)).count();
    assert!(ring >= 40, "selection ring: {ring} cyan pixels");

    // A click far from every joint selects none; a drag orbits and selects nothing.
    click_at(page, [view[0] + 8.0, view[1] + 8.0]).await;
    page.wait_for("window.inbetweenViewer.state.selectedJoint === null", 10).await;
    let [x, y] = joint_on_page(page, "root").await;
    page.drag([x, y], [x + 60.0, y], 4).await;
    assert_eq!(page.eval("window.inbetweenViewer.state.selectedJoint").await, Value::Null);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bvh_figure_fills_the_view_and_stays_in_it_while_it_walks() {
    let app = start().await;
    let bvh = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/bvh/131_01.bvh")).unwrap();
    let imported: Value = app
        .http
        .post(app.url("/v1/clips/import?format=bvh"))
        .bearer_auth(TOKEN)
        .header("content-type", "application/octet-stream")
        .body(bvh)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let id = imported["clips"][0]["id"].as_str().unwrap().to_owned();
    let Some(mut browser) = viewer_on_clip(&app, &id).await else { return };
    let page = &mut browser.page;
    page.wait_for("window.inbetweenViewer.drawn?.joints > 20", 10).await;
    let (height, inside): (f64, bool) = serde_json::from_value(page.eval(FIGURE).await).unwrap();
    assert!(
        (0.5..1.0).contains(&height) && inside,
        "the figure spans {height} of the view's height (inside: {inside})"
    );
    eprintln!("the BVH figure spans {height:.3} of the view's height at its start");

    // The take walks metres away; the camera follows, the figure stays framed.
    set_value(page, "fps", "30").await;
    page.eval("document.getElementById('play').click()").await;
    page.wait_for("window.inbetweenViewer.state.clipTime > 5", 20).await;
    let (height, inside): (f64, bool) = serde_json::from_value(page.eval(FIGURE).await).unwrap();
    assert!(height > 0.4 && inside, "while walking the figure spans {height} of the view's height (inside: {inside})");
    eprintln!("the BVH figure spans {height:.3} of the view's height after 5 s of walking");
}

/// A Z-up BVH: the spine and legs along Z, 0.9 long; 0.1 across X; flat in Y.
const Z_UP_BVH: &str = "HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 0 0.3
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Head
    {
      OFFSET 0 0 0.3
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 0 0.1
      }
    }
  }
  JOINT LeftLeg
  {
    OFFSET 0.1 0 -0.05
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 0 -0.4
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
0 0 0.9 0 0 0 0 0 0 0 0 0 0 0 0
0 0 0.9 0 0 0 0 0 0 0 0 0 0 0 0
";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_z_up_import_shows_the_up_axis_hint() {
    let app = start().await;
    let id = app.create_id(WAVE, Some(TOKEN)).await;
    let Some(mut browser) = viewer_on_clip(&app, &id).await else { return };
    let page = &mut browser.page;
    assert_eq!(page.eval("document.getElementById('up-hint').hidden").await, true, "wave is Y-up");
    set_value(page, "token", TOKEN).await;
    page.eval("document.getElementById('token-form').requestSubmit()").await;
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("lying.bvh");
    std::fs::write(&file, Z_UP_BVH).unwrap();
    page.set_files("#file", &[Path::new(&file)]).await;
    page.wait_for("window.inbetweenViewer.state.clip?.name === 'lying'", 20).await;
    page.wait_for("!document.getElementById('up-hint').hidden", 10).await;
    let hint = page.eval("document.getElementById('up-hint').textContent").await;
    assert!(hint.as_str().unwrap().contains("up=z"), "{hint}");
    // Back on the Y-up clip, no hint.
    super::select_clip(page, &id).await;
    assert_eq!(page.eval("document.getElementById('up-hint').hidden").await, true);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bones_behind_the_mesh_are_dimmed() {
    let app = start().await;
    let imported = super::import_fox(&app).await;
    let walk = imported["clips"].as_array().unwrap().iter().find(|c| c["name"] == "Walk").unwrap();
    let id = walk["id"].as_str().unwrap().to_owned();
    let Some(mut browser) = viewer_on_clip(&app, &id).await else { return };
    let page = &mut browser.page;
    // Seen from the side, the far legs are behind the body: dimmed; the near ones, and the spine, not.
    page.eval("(c => { c.yaw = Math.PI / 2; c.pitch = 0.1; })(window.inbetweenViewer.state.camera)").await;
    page.eval("document.getElementById('show-mesh').dispatchEvent(new Event('change'))").await;
    let drawn = page.wait_for("window.inbetweenViewer.mesh.draws > 0 && window.inbetweenViewer.drawn?.dimmed > 0 && window.inbetweenViewer.drawn", 10).await;
    page.picture("INBETWEEN_VIEWER_DEPTH_SCREENSHOT", std::time::Duration::ZERO, 1.0).await;
    let (items, dimmed) = (drawn["items"].as_u64().unwrap(), drawn["dimmed"].as_u64().unwrap());
    assert!(items - dimmed >= 10, "{dimmed} of {items} parts dimmed: the near side stays bright");
    eprintln!("the Fox from the side: {dimmed} of {items} skeleton parts behind the mesh");
    // Without the mesh nothing hides them.
    page.eval(
        "(b => { b.checked = false; b.dispatchEvent(new Event('change')); })(document.getElementById('show-mesh'))",
    )
    .await;
    page.wait_for("window.inbetweenViewer.drawn?.dimmed === 0", 10).await;
}
