//! The skinned Fox in the browser (issue 20): imported from the examples,
//! its mesh is skinned on the GPU (WebGL2) from the streamed pose.
//!
//! The reference is derived here, not by the page: the Fox's positions,
//! joint indices, weights and inverse binds read straight from the GLB
//! (`common::glb`, not the importer), its model-space pose at the page's
//! time from `POST /v1/poses`, skinned on the CPU (`v = Σ w·M·invBind·v̂`)
//! and its triangles rasterized (pixel centres) through the page's camera
//! (math.js `cameraBasis`: yaw, pitch, distance, target, 45° vertical
//! field of view) into a silhouette. The page's silhouette is the pixels
//! that change when the mesh is switched on (skeleton overlay off), so the
//! floor grid under it does not count. They must overlap with IoU ≥ 0.9.
//! Then, playing, the mesh's pixels change between two frames.
//!
//! `INBETWEEN_MESH_SCREENSHOT=docs/images/viewer-fox.png` saves the page
//! with the Fox walking (the README's picture).

use std::time::Duration;

use glam::{DMat4, DQuat, DVec3, DVec4};
use serde_json::{Value, json};

use super::cdp::Page;
use super::{TOKEN, differs, post_json, start, viewer_on_clip};
use crate::common::glb::{FOX, Glb};

/// The RGB pixels of the scene's content box (the canvas buffer's own
/// pixels at scale 1), with its width and height.
async fn scene_pixels(page: &mut Page) -> (usize, usize, Vec<[u8; 3]>) {
    let rect = page
        .eval(
            "(() => { const c = document.getElementById('scene'); const r = c.getBoundingClientRect(); \
             return [r.x + c.clientLeft, r.y + c.clientTop, c.width, c.height]; })()",
        )
        .await;
    let rect: [f64; 4] = serde_json::from_value(rect).unwrap();
    let png = page.screenshot(Some(rect)).await;
    let mut reader = png::Decoder::new(std::io::Cursor::new(png)).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let pixels = buf[..info.buffer_size()].chunks_exact(channels).map(|p| [p[0], p[1], p[2]]).collect();
    assert_eq!((info.width as f64, info.height as f64), (rect[2], rect[3]), "one screenshot pixel per canvas pixel");
    (info.width as usize, info.height as usize, pixels)
}

/// math.js's `cameraBasis`, from the page's camera state: world point →
/// canvas pixel coordinates, `None` behind the near plane.
struct Camera {
    eye: DVec3,
    r: DVec3,
    u: DVec3,
    f: DVec3,
    focal: f64,
    centre: (f64, f64),
}

impl Camera {
    fn of(state: &Value, width: usize, height: usize) -> Camera {
        let c = &state["camera"];
        let (yaw, pitch, dist) =
            (c["yaw"].as_f64().unwrap(), c["pitch"].as_f64().unwrap(), c["dist"].as_f64().unwrap());
        let target: [f64; 3] = serde_json::from_value(c["target"].clone()).unwrap();
        let target = DVec3::from(target);
        let eye = target + dist * DVec3::new(pitch.cos() * yaw.sin(), pitch.sin(), pitch.cos() * yaw.cos());
        let f = (target - eye).normalize();
        let r = f.cross(DVec3::Y).normalize();
        let u = r.cross(f);
        let focal = height as f64 / (2.0 * (45f64.to_radians() / 2.0).tan());
        Camera { eye, r, u, f, focal, centre: (width as f64 / 2.0, height as f64 / 2.0) }
    }

    fn project(&self, p: DVec3) -> Option<(f64, f64)> {
        let d = p - self.eye;
        let z = d.dot(self.f);
        (z > 1e-6)
            .then(|| (self.centre.0 + d.dot(self.r) / z * self.focal, self.centre.1 - d.dot(self.u) / z * self.focal))
    }
}

/// The Fox's vertices skinned on the CPU to the model-space `pose`.
fn skinned_fox(fox: &Glb, pose: &Value) -> Vec<DVec3> {
    let model: std::collections::HashMap<&str, DMat4> = (pose["joints"].as_array().unwrap().iter())
        .map(|j| {
            let v = |k: &str| -> Vec<f64> { serde_json::from_value(j[k].clone()).unwrap() };
            let (t, q, s) = (v("translation"), v("rotation"), v("scale"));
            let m = DMat4::from_scale_rotation_translation(
                DVec3::new(s[0], s[1], s[2]),
                DQuat::from_xyzw(q[0], q[1], q[2], q[3]),
                DVec3::new(t[0], t[1], t[2]),
            );
            (j["name"].as_str().unwrap(), m)
        })
        .collect();
    let skin = fox.json["skins"][0]["inverseBindMatrices"].as_u64().unwrap() as usize;
    let joints: Vec<DMat4> = (fox.skin_joint_names(0).iter().zip(fox.accessor(skin)))
        .map(|(name, bind)| model[name.as_str()] * DMat4::from_cols_slice(&bind))
        .collect();
    let (positions, indices, weights) =
        (fox.attribute("POSITION"), fox.attribute("JOINTS_0"), fox.attribute("WEIGHTS_0"));
    (0..positions.len())
        .map(|v| {
            let total: f64 = weights[v].iter().sum();
            let p = DVec4::new(positions[v][0], positions[v][1], positions[v][2], 1.0);
            (0..4).map(|k| weights[v][k] / total * (joints[indices[v][k] as usize] * p)).sum::<DVec4>().truncate()
        })
        .collect()
}

/// The pixels whose centres lie inside a triangle (non-indexed: every three
/// vertices), either winding.
fn rasterize(camera: &Camera, vertices: &[DVec3], width: usize, height: usize) -> Vec<bool> {
    let mut mask = vec![false; width * height];
    for tri in vertices.chunks_exact(3) {
        let Some(p) = tri.iter().map(|&v| camera.project(v)).collect::<Option<Vec<_>>>() else { continue };
        let edge = |a: (f64, f64), b: (f64, f64), x: f64, y: f64| (b.0 - a.0) * (y - a.1) - (b.1 - a.1) * (x - a.0);
        let area = edge(p[0], p[1], p[2].0, p[2].1);
        if area.abs() < 1e-12 {
            continue;
        }
        let (lo_x, hi_x) =
            (p.iter().map(|q| q.0).fold(f64::MAX, f64::min), p.iter().map(|q| q.0).fold(f64::MIN, f64::max));
        let (lo_y, hi_y) =
            (p.iter().map(|q| q.1).fold(f64::MAX, f64::min), p.iter().map(|q| q.1).fold(f64::MIN, f64::max));
        for y in (lo_y.floor().max(0.0) as usize)..(hi_y.ceil().min(height as f64) as usize) {
            for x in (lo_x.floor().max(0.0) as usize)..(hi_x.ceil().min(width as f64) as usize) {
                let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
                let w = [edge(p[1], p[2], cx, cy), edge(p[2], p[0], cx, cy), edge(p[0], p[1], cx, cy)];
                if w.iter().all(|&e| e * area >= 0.0) {
                    mask[y * width + x] = true;
                }
            }
        }
    }
    mask
}

async fn check(page: &mut Page, id: &str, on: bool) {
    page.eval(&format!(
        "(b => {{ b.checked = {on}; b.dispatchEvent(new Event('change')); }})(document.getElementById({}))",
        json!(id)
    ))
    .await;
}

/// Waits until the page has drawn a frame after this call.
async fn next_frame(page: &mut Page) {
    page.eval("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_fox_is_skinned_on_the_gpu_like_a_cpu_reference_and_walks() {
    let app = start().await;
    let glb = std::fs::read(FOX).unwrap();
    let imported =
        app.http.post(app.url("/v1/clips/import?format=glb")).bearer_auth(TOKEN).body(glb).send().await.unwrap();
    assert_eq!(imported.status(), 201);
    let imported: Value = imported.json().await.unwrap();
    let walk = imported["clips"].as_array().unwrap().iter().find(|c| c["name"] == "Walk").expect("the Fox walks");
    let id = walk["id"].as_str().unwrap().to_owned();
    let Some(mut browser) = viewer_on_clip(&app, &id).await else { return };
    let page = &mut browser.page;
    let info = page.wait_for("window.inbetweenViewer.mesh.draws > 0 && window.inbetweenViewer.mesh.info", 20).await;
    assert_eq!(info, json!({"vertices": 1728, "triangles": 576, "joints": 24, "textured": true, "normals": false}));

    // A pose held still: the seek bar at 0.4 s, no stream.
    let time = 0.4;
    super::set_value(page, "seek", &time.to_string()).await;
    page.wait_for(&format!("window.inbetweenViewer.state.requestTime === {time}"), 10).await;
    check(page, "show-skeleton", false).await;
    check(page, "show-mesh", false).await;
    next_frame(page).await;
    let (width, height, without) = scene_pixels(page).await;
    check(page, "show-mesh", true).await;
    next_frame(page).await;
    let (_, _, with) = scene_pixels(page).await;
    let shown: Vec<bool> = without.iter().zip(&with).map(|(a, b)| differs(*a, *b, 6)).collect();

    let state = page.eval("window.inbetweenViewer.state").await;
    assert_eq!(state["requestTime"], json!(time));
    let pose =
        post_json(&app, "/v1/poses", &json!({"motion": {"layers": [{"clip": id}]}, "time": time, "space": "model"}))
            .await;
    let fox = Glb::read(FOX);
    let reference = rasterize(&Camera::of(&state, width, height), &skinned_fox(&fox, &pose), width, height);
    let both = shown.iter().zip(&reference).filter(|(a, b)| **a && **b).count();
    let either = shown.iter().zip(&reference).filter(|(a, b)| **a || **b).count();
    let (page_px, reference_px) = (shown.iter().filter(|x| **x).count(), reference.iter().filter(|x| **x).count());
    assert!(reference_px > 5000, "the Fox fills the view: {reference_px} px");
    let iou = both as f64 / either as f64;
    eprintln!("silhouette: page {page_px} px, reference {reference_px} px, IoU {iou:.4}");
    assert!(iou >= 0.9, "IoU {iou:.4} (page {page_px} px, reference {reference_px} px, both {both})");

    // In local space the page composes the model matrices itself: the same picture.
    super::set_value(page, "space", "local").await;
    page.wait_for("window.inbetweenViewer.mesh.poseSpace === 'local'", 10).await;
    next_frame(page).await;
    let (_, _, local) = scene_pixels(page).await;
    let apart = with.iter().zip(&local).filter(|(a, b)| differs(**a, **b, 24)).count();
    assert!(apart * 50 <= page_px, "local space differs from model space in {apart} px of {page_px}");

    // Playing (looped: the imported Walk is `once`, 0.7 s): the mesh moves between frames.
    super::set_value(page, "playback", "loop").await;
    super::set_value(page, "fps", "30").await;
    page.eval("document.getElementById('play').click()").await;
    page.wait_for("Number(document.getElementById('seq').textContent) >= 5", 10).await;
    let (_, _, first) = scene_pixels(page).await;
    // Nine frames later (300 ms at 30 fps).
    let seq = super::text_number(page, "seq").await;
    super::next_frame(page, seq + 8.0).await;
    let (_, _, second) = scene_pixels(page).await;
    let moved = first.iter().zip(&second).filter(|(a, b)| differs(**a, **b, 24)).count();
    assert!(moved >= 300, "the walking Fox changes {moved} pixels in 300 ms");
    assert_eq!(page.eval("window.inbetweenViewer.cspViolations").await, json!([]));

    if std::env::var_os("INBETWEEN_MESH_SCREENSHOT").is_some() {
        check(page, "show-skeleton", true).await;
        // At 0.7 scale: the README's picture stays under 200 KB.
        page.picture("INBETWEEN_MESH_SCREENSHOT", Duration::from_millis(500), 0.7).await;
    }
}
