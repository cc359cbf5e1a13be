//! The three.js client (examples/clients/three) in Chromium: its ten-line
//! example page, served as static files the way a user would serve them, plays
//! the Fox's walk from a compact stream at 20 fps on a three.js `SkinnedMesh`
//! rendered at the browser's rate.
//!
//! - Smooth: while it plays, no two rendered frames show the same pose, and
//!   several are rendered between two ticks (interpolated, not stepped).
//! - Right: the bones shown at a moment, composed to model space, are within the
//!   layout's error bound of the f64 interpolation of the server's own poses at the
//!   two ticks around the page's render time (docs/compact-frames.md, "The error
//!   bound": joint origins and the points at `distance` along each axis).
//!
//! Set `INBETWEEN_THREE_SCREENSHOT=path.png` to save a screenshot of the page.
//!
//! three.js comes from `examples/clients/three/node_modules` (pinned, `npm ci`,
//! which .ci/run does before `cargo test`); without it the test skips, or fails
//! when a browser is required.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{DMat4, DQuat, DVec3};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

use super::cdp::{Browser, REQUIRE_ENV};
use super::{floats, import_fox, start};

/// The stream's rate: the "20 fps network rate".
const FPS: u32 = 20;
/// Rendered frames recorded while playing (a second at 60 Hz).
const RENDERED: usize = 60;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_fox_walks_on_three_js_from_a_compact_stream_interpolated_between_ticks() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    if !three_installed(&root) {
        return;
    }
    let app = start().await;
    let imported = import_fox(&app).await;
    let walk = imported["clips"].as_array().unwrap().iter().find(|c| c["name"] == "Walk").unwrap();
    let walk = walk["id"].as_str().unwrap().to_owned();
    let files = StaticFiles::serve(root).await;
    // Alone: the smoothness measured is the page's, not other Chromiums' beside it on 2 cores.
    let Some(mut browser) = Browser::launch_alone().await else { return };
    let page = &mut browser.page;
    page.set_viewport(640, 400).await;
    let server = app.ws_url("");
    let url = format!("{}/examples/clients/three/index.html?server={server}&clip={walk}&fps={FPS}", files.origin());
    page.navigate(&url).await;
    page.wait_for("window.player?.frames >= 10 && window.player.shown?.mode === 'interpolate'", 30).await;
    assert_eq!(page.eval("player.decoder !== null && player.missing.length").await, json!(0), "every joint bound");
    if let Some(path) = std::env::var_os("INBETWEEN_THREE_SCREENSHOT") {
        std::fs::write(&path, page.screenshot(None).await).unwrap();
        eprintln!("screenshot written to {}", path.to_string_lossy());
    }

    let rendered = page.eval(&record(RENDERED)).await;
    let rendered = rendered.as_array().unwrap();
    let repeated = rendered.iter().filter(|r| r["same"] == true).count();
    let ticks: std::collections::BTreeSet<u64> = rendered.iter().map(|r| r["from"].as_u64().unwrap()).collect();
    let between = rendered.iter().filter(|r| (0.05..0.95).contains(&r["alpha"].as_f64().unwrap())).count();
    let modes: HashMap<String, usize> = rendered.iter().fold(HashMap::new(), |mut m, r| {
        *m.entry(r["mode"].as_str().unwrap().to_owned()).or_default() += 1;
        m
    });
    eprintln!("{RENDERED} rendered frames over {} ticks: {between} between ticks, modes {modes:?}", ticks.len());
    assert_eq!(repeated, 0, "a pose shown twice in a row while playing: {rendered:?}");
    assert!(ticks.len() >= 2, "the stream moved on: {ticks:?}");
    // At least two rendered frames a tick on average, and at least one strictly between every tick seen.
    assert!(rendered.len() >= 2 * ticks.len(), "{} frames over {} ticks", rendered.len(), ticks.len());
    assert!(between >= ticks.len(), "{between} frames strictly between ticks, over {} ticks", ticks.len());

    let shown = interpolated_moment(page).await;
    let clip_doc = app.get_json(&format!("/v1/clips/{walk}")).await;
    let parents = parents(&clip_doc);
    let names: Vec<String> = serde_json::from_value(shown["names"].clone()).unwrap();
    let at = |end: &str| shown[end]["clipTime"].as_f64().unwrap();
    let (pose_a, pose_b) = (
        app.get_json(&format!("/v1/clips/{walk}/pose?t={}&space=local", at("from"))).await,
        app.get_json(&format!("/v1/clips/{walk}/pose?t={}&space=local", at("to"))).await,
    );
    let alpha = shown["alpha"].as_f64().unwrap();
    let reference: Vec<Trs> =
        local(&pose_a, &names).iter().zip(local(&pose_b, &names)).map(|(a, b)| a.interpolate(&b, alpha)).collect();
    let page_pose: Vec<Trs> = shown["bones"].as_array().unwrap().iter().map(Trs::from_page).collect();
    let distance = shown["distance"].as_f64().unwrap();
    let bound = shown["bound"].as_f64().unwrap();
    let parent_index: Vec<Option<usize>> =
        names.iter().map(|n| parents[n].as_ref().map(|p| names.iter().position(|m| m == p).unwrap())).collect();
    let worst = worst_point(&model(&page_pose, &parent_index), &model(&reference, &parent_index), distance);
    eprintln!(
        "shown between seq {} and {} at alpha {alpha:.3}: worst point {worst:e} off, bound {bound:e} at distance {distance}",
        shown["from"]["seq"], shown["to"]["seq"]
    );
    // The page interpolates f32 values in f64; rounding of the Fox's size adds a few ULPs above the bound.
    assert!(worst <= bound * 1.05 + 1e-5, "worst point {worst} off the interpolated server pose (bound {bound})");
}

/// Whether three.js is installed for the page; panics when a browser is required and it is not.
fn three_installed(root: &Path) -> bool {
    let module = root.join("examples/clients/three/node_modules/three/build/three.module.js");
    if module.is_file() {
        return true;
    }
    let required = std::env::var(REQUIRE_ENV).is_ok_and(|v| v == "1");
    assert!(!required, "{REQUIRE_ENV}=1 but {} is missing: run `npm ci` in examples/clients/three", module.display());
    eprintln!("SKIPPED: three.js not installed (cd examples/clients/three && npm ci)");
    false
}

/// JavaScript recording `frames` rendered frames: the sample each showed and whether its pose repeated the previous one.
fn record(frames: usize) -> String {
    format!(
        "new Promise((resolve) => {{
           const rows = []; let last = null;
           const step = () => {{
             const pose = JSON.stringify(player.bound.map((b) => [b.position.toArray(), b.quaternion.toArray()]));
             const s = player.shown;
             rows.push({{ from: s.from.seq, to: s.to.seq, alpha: s.alpha, mode: s.mode, same: pose === last }});
             last = pose;
             if (rows.length < {frames}) requestAnimationFrame(step); else resolve(rows);
           }};
           requestAnimationFrame(step);
         }})"
    )
}

/// The bones the page shows and the sample they came from, read within one
/// rendered frame (after the player's update), at a moment between two ticks.
async fn interpolated_moment(page: &mut super::cdp::Page) -> Value {
    let read = "new Promise((resolve) => requestAnimationFrame(() => {
        const s = player.shown, end = (f) => ({ seq: f.seq, clipTime: f.clipTime });
        resolve({ mode: s.mode, alpha: s.alpha, from: end(s.from), to: end(s.to), names: player.names,
                  bound: player.decoder.layout.bound, distance: player.decoder.layout.distance,
                  bones: player.bound.map((b) => [b.position.toArray(), b.quaternion.toArray(), b.scale.toArray()]) });
      }))";
    for _ in 0..50 {
        let shown = page.eval(read).await;
        if shown["mode"] == "interpolate" && shown["alpha"].as_f64().is_some_and(|a| a > 0.0 && a < 1.0) {
            return shown;
        }
    }
    panic!("no rendered frame between two ticks in 50 tries");
}

/// Each joint's parent name, from the clip document's skeleton.
fn parents(clip: &Value) -> HashMap<String, Option<String>> {
    let joints = clip["skeleton"]["joints"].as_array().expect("the clip's skeleton");
    joints.iter().map(|j| (j["name"].as_str().unwrap().to_owned(), j["parent"].as_str().map(str::to_owned))).collect()
}

/// A local transform in f64.
struct Trs {
    translation: DVec3,
    rotation: DQuat,
    scale: DVec3,
}

impl Trs {
    /// `[translation, rotation, scale]` as the page read them from its bones.
    fn from_page(bone: &Value) -> Trs {
        let v = |k: usize| floats(&bone[k]);
        Trs {
            translation: DVec3::from_slice(&v(0)),
            rotation: DQuat::from_slice(&v(1)),
            scale: DVec3::from_slice(&v(2)),
        }
    }

    /// Translation and scale lerped, rotation slerped along the shorter arc, written out here in f64.
    fn interpolate(&self, other: &Trs, t: f64) -> Trs {
        let (a, mut b) = (self.rotation, other.rotation);
        if a.dot(b) < 0.0 {
            b = -b;
        }
        let theta = a.dot(b).clamp(-1.0, 1.0).acos();
        let rotation = if theta < 1e-9 {
            (a * (1.0 - t) + b * t).normalize()
        } else {
            a * (((1.0 - t) * theta).sin() / theta.sin()) + b * ((t * theta).sin() / theta.sin())
        };
        Trs {
            translation: self.translation.lerp(other.translation, t),
            rotation,
            scale: self.scale.lerp(other.scale, t),
        }
    }

    fn matrix(&self) -> DMat4 {
        DMat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

/// A REST pose's joints, in the order of `names`.
fn local(pose: &Value, names: &[String]) -> Vec<Trs> {
    let joints: HashMap<&str, &Value> =
        pose["joints"].as_array().unwrap().iter().map(|j| (j["name"].as_str().unwrap(), j)).collect();
    names
        .iter()
        .map(|name| {
            let j = joints[name.as_str()];
            Trs {
                translation: DVec3::from_slice(&floats(&j["translation"])),
                rotation: DQuat::from_slice(&floats(&j["rotation"])),
                scale: DVec3::from_slice(&floats(&j["scale"])),
            }
        })
        .collect()
}

/// Model matrices `M_j = M_parent · T·R·S`, parents first.
fn model(pose: &[Trs], parents: &[Option<usize>]) -> Vec<DMat4> {
    let mut out: Vec<DMat4> = Vec::with_capacity(pose.len());
    for (j, trs) in pose.iter().enumerate() {
        let parent = parents[j].map_or(DMat4::IDENTITY, |p| out[p]);
        out.push(parent * trs.matrix());
    }
    out
}

/// The largest distance between the two poses' joint origins and points at `distance` along each joint's axes.
fn worst_point(a: &[DMat4], b: &[DMat4], distance: f64) -> f64 {
    let points = [DVec3::ZERO, DVec3::X * distance, DVec3::Y * distance, DVec3::Z * distance];
    a.iter()
        .zip(b)
        .flat_map(|(ma, mb)| points.map(|p| ma.transform_point3(p).distance(mb.transform_point3(p))))
        .fold(0.0, f64::max)
}

/// The repository's `examples/` over HTTP on 127.0.0.1, as `python3 -m http.server` would serve it to a user.
struct StaticFiles {
    port: u16,
    task: tokio::task::JoinHandle<()>,
}

impl StaticFiles {
    async fn serve(root: PathBuf) -> StaticFiles {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let port = listener.local_addr().unwrap().port();
        let task = tokio::spawn(async move {
            while let Ok((stream, _)) = listener.accept().await {
                tokio::spawn(answer(stream, root.clone()));
            }
        });
        StaticFiles { port, task }
    }

    fn origin(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }
}

impl Drop for StaticFiles {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Answers one GET (the connection then closes): a file under `examples/`, else 404.
async fn answer(mut stream: TcpStream, root: PathBuf) {
    let mut head = Vec::new();
    let mut buf = [0u8; 2048];
    while !head.windows(4).any(|w| w == b"\r\n\r\n") && head.len() < 16 * 1024 {
        match stream.read(&mut buf).await {
            Ok(0) | Err(_) => return,
            Ok(n) => head.extend_from_slice(&buf[..n]),
        }
    }
    let head = String::from_utf8_lossy(&head);
    let path = head.split(' ').nth(1).unwrap_or("/").split('?').next().unwrap_or("/");
    let file = path
        .strip_prefix("/examples/")
        .filter(|rest| !rest.split('/').any(|part| part == ".." || part.is_empty()))
        .and_then(|rest| std::fs::read(root.join("examples").join(rest)).ok());
    let response = match file {
        Some(body) => {
            let head = format!(
                "HTTP/1.1 200 OK\r\ncontent-type: {}\r\ncontent-length: {}\r\nconnection: close\r\n\r\n",
                content_type(path),
                body.len()
            );
            [head.into_bytes(), body].concat()
        }
        None => b"HTTP/1.1 404 Not Found\r\ncontent-length: 0\r\nconnection: close\r\n\r\n".to_vec(),
    };
    let _ = stream.write_all(&response).await;
    let _ = stream.shutdown().await;
}

fn content_type(path: &str) -> &'static str {
    match path.rsplit('.').next() {
        Some("html") => "text/html; charset=utf-8",
        Some("js" | "mjs") => "text/javascript; charset=utf-8",
        Some("json") => "application/json",
        Some("glb") => "model/gltf-binary",
        _ => "application/octet-stream",
    }
}
