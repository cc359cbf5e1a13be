//! The browser viewer (`/viewer`), tested in a real headless Chromium
//! against the real server on 127.0.0.1:0: the page lists and selects a
//! clip, plays its WebSocket stream (the displayed `seq` advances), draws a
//! skeleton (pixels of the canvas), plots the same curve values the REST
//! `sample` endpoint gives, and uploads a clip through the file input,
//! asking for the write token.
//!
//! Without Chromium the browser tests skip with a message, unless
//! `INBETWEEN_REQUIRE_BROWSER=1` (CI) makes them fail. Set
//! `INBETWEEN_VIEWER_SCREENSHOT=path.png` to save a screenshot from the
//! upload test, `INBETWEEN_VIEWER_PANEL_SCREENSHOT=path.png` one of the
//! composition panel with the Fox (docs/viewer.md's docs/viewer-panel.png).

mod cdp;
mod character;
mod compact;
mod curves;
mod flows;
mod graph;
mod lag;
mod library;
mod mesh;
mod panel;
mod springs;
mod three_client;
mod units;
mod view;

use std::path::Path;
use std::time::Duration;

use serde_json::{Value, json};

use crate::common::{TestApp, WAVE, within};
use cdp::{Browser, Page};
const TOKEN: &str = "viewer-test-write-token";
/// The canvases' background colour (#101216 in scene.js and curves.js).
const BACKGROUND: [u8; 3] = [0x10, 0x12, 0x16];

/// The page's other ES modules (`viewer.js` imports them, `index.html` preloads them).
const MODULES: [&str; 18] = [
    "/viewer/math.js",
    "/viewer/dom.js",
    "/viewer/events.js",
    "/viewer/status.js",
    "/viewer/state.js",
    "/viewer/render.js",
    "/viewer/api.js",
    "/viewer/settings.js",
    "/viewer/pose.js",
    "/viewer/scene.js",
    "/viewer/curves.js",
    "/viewer/player.js",
    "/viewer/controls.js",
    "/viewer/clips.js",
    "/viewer/thumbs.js",
    "/viewer/library.js",
    "/viewer/upload.js",
    "/viewer/composition.js",
];

/// A server whose writes need [`TOKEN`].
async fn start() -> TestApp {
    TestApp::builder()
        .write_token(TOKEN)
        .release_capacity()
        .configure(|c| c.drain_timeout = Duration::from_secs(2))
        .start()
        .await
}

/// `POST path` with a JSON body; panics unless 200. Returns the JSON answer.
async fn post_json(app: &TestApp, path: &str, body: &Value) -> Value {
    let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
    assert_eq!(resp.status(), 200, "{path}");
    resp.json().await.unwrap()
}

#[tokio::test]
async fn serves_the_page_with_content_types_etags_and_a_strict_csp() {
    let app = start().await;
    let page = app.http.get(app.url("/viewer")).send().await.unwrap();
    assert_eq!(page.status(), 200);
    let header = |r: &reqwest::Response, name: &str| r.headers()[name].to_str().unwrap().to_owned();
    assert_eq!(header(&page, "content-type"), "text/html; charset=utf-8");
    let csp = header(&page, "content-security-policy");
    for directive in ["default-src 'none'", "script-src 'self'", "connect-src 'self'", "frame-ancestors 'none'"] {
        assert!(csp.contains(directive), "{directive} missing from {csp}");
    }
    assert!(!csp.contains("unsafe"), "{csp}");
    assert_eq!(header(&page, "cache-control"), "no-cache");
    let etag = header(&page, "etag");
    let html = page.text().await.unwrap();
    // One entry module; the modules it imports (mesh.js among them) preloaded.
    assert!(html.contains(r#"type="module" src="/viewer/viewer.js""#) && html.contains(r#"href="/viewer/viewer.css""#));
    assert!(html.contains(r#"rel="modulepreload" href="/viewer/mesh.js""#));
    assert!(!html.contains("<script>") && !html.contains("style="), "inline code would break the CSP");

    let again = app.http.get(app.url("/viewer")).header("if-none-match", &etag).send().await.unwrap();
    assert_eq!(again.status(), 304);
    assert!(again.bytes().await.unwrap().is_empty());

    for (path, content_type) in [
        ("/viewer/viewer.js", "text/javascript; charset=utf-8"),
        ("/viewer/viewer.css", "text/css; charset=utf-8"),
        ("/viewer/panel.js", "text/javascript; charset=utf-8"),
        ("/viewer/broadcast.js", "text/javascript; charset=utf-8"),
        ("/viewer/panel.css", "text/css; charset=utf-8"),
        ("/viewer/mesh.js", "text/javascript; charset=utf-8"),
    ]
    .into_iter()
    .chain(MODULES.iter().map(|m| (*m, "text/javascript; charset=utf-8")))
    {
        assert!(html.contains(&format!("=\"{path}\"")), "the page loads {path}");
        let resp = app.http.get(app.url(path)).send().await.unwrap();
        assert_eq!(resp.status(), 200, "{path}");
        assert_eq!(header(&resp, "content-type"), content_type);
        let tag = header(&resp, "etag");
        assert_ne!(tag, etag, "each file has its own tag");
        let again = app.http.get(app.url(path)).header("if-none-match", &tag).send().await.unwrap();
        assert_eq!(again.status(), 304, "{path}");
    }
    let openapi: Value = app.http.get(app.url("/openapi.json")).send().await.unwrap().json().await.unwrap();
    assert!(openapi["paths"]["/viewer"]["get"].is_object());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn plays_a_clip_and_plots_the_sampled_curves() {
    let app = start().await;
    let id = app.create_id(WAVE, Some(TOKEN)).await;
    let Some(mut browser) = Browser::launch().await else { return };
    let page = &mut browser.page;
    page.navigate(&app.url("/viewer")).await;

    // The list comes from the REST API; the filter hides what does not match.
    page.wait_for("document.querySelectorAll('#clips li').length === 1", 10).await;
    set_value(page, "filter", "nothing-matches").await;
    assert_eq!(page.eval("document.querySelectorAll('#clips li').length").await, 0);
    set_value(page, "filter", "WAV").await;
    page.eval(&format!("document.querySelector('#clips li[data-id={}]').click()", json!(id))).await;
    // The clip selected (its listeners have run), then its curve: a curve of `id` alone may be an earlier selection's.
    let selected = format!(
        "window.inbetweenViewer.state.clip?.id === {0} && window.inbetweenViewer.curve?.clip === {0}",
        json!(id)
    );
    page.wait_for(&selected, 10).await;

    set_value(page, "fps", "60").await;
    page.eval("document.getElementById('play').click()").await;
    page.wait_for("Number(document.getElementById('seq').textContent) >= 5", 10).await;
    let seq_before = text_number(page, "seq").await;
    let seq_after = next_frame(page, seq_before).await;
    assert!(seq_after > seq_before, "the displayed seq advances: {seq_before} then {seq_after}");
    assert!(text_number(page, "frames").await >= 5.0);
    let latency = page.eval("document.getElementById('latency').textContent").await;
    assert!(latency.as_str().unwrap().ends_with(" ms"), "latency readout: {latency}");
    // Every tick of this stream (seq 0, 1, …) is a frame received or one the
    // server counted dropped: frames + dropped = seq + 1, read at one instant.
    // On loopback at 60 fps drops are rare; a page starved on a busy 2-core
    // machine (the whole suite beside it) may miss more, never most.
    let counts = page
        .eval("(s => [s.seq, s.frames, s.dropped, Number(document.getElementById('dropped').textContent)])(window.inbetweenViewer.state)")
        .await;
    let [seq, frames, dropped, shown]: [u64; 4] = serde_json::from_value(counts).unwrap();
    assert_eq!(frames + dropped, seq + 1, "seq {seq}, {frames} frames, {dropped} dropped");
    assert!(dropped * 2 <= seq + 1, "{dropped} of {} ticks dropped", seq + 1);
    assert_eq!(shown, dropped, "the readout shows the count");

    // Pause holds the clip time while frames keep arriving.
    page.eval("document.getElementById('play').click()").await;
    until_held(page).await;
    let held = page.eval("document.getElementById('clip-time').textContent").await;
    let seq_paused = text_number(page, "seq").await;
    // Six more frames (100 ms at 60 fps) while paused.
    next_frame(page, seq_paused + 5.0).await;
    assert_eq!(page.eval("document.getElementById('clip-time').textContent").await, held);
    assert!(text_number(page, "seq").await > seq_paused);

    // The skeleton is on the canvas: background, grid and, in the joints'
    // orange, two joint dots.
    let pixels = canvas_pixels(page, "scene").await;
    let drawn = pixels.iter().filter(|p| differs(**p, BACKGROUND, 24)).count();
    let joints = pixels.iter().filter(|p| !differs(**p, [0xff, 0x8c, 0x1a], 40)).count();
    assert!(drawn * 100 > pixels.len(), "canvas nearly blank: {drawn} of {} pixels drawn", pixels.len());
    assert!(joints >= 40, "joint dots: {joints} orange pixels");

    // The curves panel plots exactly what the REST sample endpoint gives
    // (rotations as their quaternion components here; Euler angles in `curves.rs`).
    set_value(page, "curve-rotation", "quaternion").await;
    for (joint, channel, components) in [("root", "translation", 3), ("arm", "rotation", 4)] {
        set_value(page, "curve-joint", joint).await;
        set_value(page, "curve-channel", channel).await;
        let curve = page
            .wait_for(
                &format!(
                    "window.inbetweenViewer.curve?.joint === {} && window.inbetweenViewer.curve?.channel === {} \
                     && window.inbetweenViewer.curve",
                    json!(joint),
                    json!(channel)
                ),
                10,
            )
            .await;
        let times: Vec<f64> = serde_json::from_value(curve["times"].clone()).unwrap();
        assert!(times.len() > 100, "{} points", times.len());
        assert_eq!((times[0], *times.last().unwrap()), (0.0, 3.0), "the clip's whole range");
        let rest = post_json(
            &app,
            &format!("/v1/clips/{id}/sample"),
            &json!({"times": times, "space": "local", "playback": "once"}),
        )
        .await;
        let poses = rest["poses"].as_array().unwrap();
        assert_eq!(poses.len(), times.len());
        for (i, pose) in poses.iter().enumerate() {
            let expected =
                pose["joints"].as_array().unwrap().iter().find(|j| j["name"] == joint).unwrap()[channel].clone();
            assert_eq!(expected.as_array().unwrap().len(), components);
            assert_eq!(floats(&curve["values"][i]), floats(&expected), "{joint} {channel} at t = {}", times[i]);
        }
        // Keys are marked at the document's key times and values.
        let doc: Value = app.http.get(app.url(&format!("/v1/clips/{id}"))).send().await.unwrap().json().await.unwrap();
        let track = doc["tracks"].as_array().unwrap().iter().find(|t| t["joint"] == joint).unwrap();
        let keys = curve["keys"].as_array().unwrap();
        assert_eq!(keys.len(), track["times"].as_array().unwrap().len());
        for (k, key) in keys.iter().enumerate() {
            assert_eq!(key["time"].as_f64(), track["times"][k].as_f64());
            assert_eq!(floats(&key["value"]), floats(&track["values"][k]));
        }
    }
    assert_eq!(page.eval("window.inbetweenViewer.cspViolations").await, json!([]));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uploads_from_the_page_with_the_write_token_and_plays_in_local_space() {
    let app = start().await;
    let Some(mut browser) = Browser::launch().await else { return };
    let page = &mut browser.page;
    page.navigate(&app.url("/viewer")).await;
    page.wait_for("window.inbetweenViewer && document.getElementById('clips')", 10).await;

    // The first try has no token: the page asks for it, then retries.
    let wave = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/wave.json");
    page.set_files("#file", &[Path::new(wave)]).await;
    page.wait_for("document.getElementById('token-form').classList.contains('wanted')", 20).await;
    let status = page.eval("document.getElementById('status').textContent").await;
    assert!(status.as_str().unwrap().contains("write token"), "status: {status}");
    set_value(page, "token", TOKEN).await;
    page.eval("document.getElementById('token-form').requestSubmit()").await;
    page.wait_for("window.inbetweenViewer.state.clip?.name === 'wave'", 30).await;
    assert_eq!(page.eval("sessionStorage.getItem('inbetween.token')").await, TOKEN);
    assert_eq!(page.eval("document.getElementById('token-form').classList.contains('wanted')").await, false);

    let list: Value = app.http.get(app.url("/v1/clips")).send().await.unwrap().json().await.unwrap();
    assert_eq!(list["clips"].as_array().unwrap().len(), 1, "stored once: {list}");

    // Local space: the page composes the hierarchy itself.
    set_value(page, "space", "local").await;
    page.eval("document.getElementById('play').click()").await;
    page.wait_for("Number(document.getElementById('seq').textContent) >= 20", 15).await;
    let pixels = canvas_pixels(page, "scene").await;
    let joints = pixels.iter().filter(|p| !differs(**p, [0xff, 0x8c, 0x1a], 40)).count();
    assert!(joints >= 40, "joint dots: {joints} orange pixels");
    assert_eq!(page.eval("window.inbetweenViewer.cspViolations").await, json!([]));

    // A BVH from the page is named after its file, not "bvh" (the page sends it as multipart).
    let bvh = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/bvh/131_01.bvh");
    page.set_files("#file", &[Path::new(bvh)]).await;
    page.wait_for("window.inbetweenViewer.state.clip?.name === '131_01'", 30).await;

    if std::env::var_os("INBETWEEN_VIEWER_SCREENSHOT").is_some() {
        page.eval("document.getElementById('play').click()").await;
        page.picture("INBETWEEN_VIEWER_SCREENSHOT", Duration::from_millis(300), 1.0).await;
    }
}

/// A browser on the app's viewer page with clip `id` selected (`None`
/// where no browser can run, as [`Browser::launch`]).
async fn viewer_on_clip(app: &TestApp, id: &str) -> Option<Browser> {
    let mut browser = Browser::launch().await?;
    browser.page.navigate(&app.url("/viewer")).await;
    select_clip(&mut browser.page, id).await;
    Some(browser)
}

/// Selects the clip `id` in the list and waits until its curve is plotted.
async fn select_clip(page: &mut Page, id: &str) {
    page.wait_for(&format!("document.querySelector('#clips li[data-id={}]')", json!(id)), 10).await;
    page.eval(&format!("document.querySelector('#clips li[data-id={}]').click()", json!(id))).await;
    // The clip selected (its listeners have run), then its curve: a curve of `id` alone may be an earlier selection's.
    let selected = format!(
        "window.inbetweenViewer.state.clip?.id === {0} && window.inbetweenViewer.curve?.clip === {0}",
        json!(id)
    );
    page.wait_for(&selected, 10).await;
}

/// The text of the element `id`.
async fn text(page: &mut Page, id: &str) -> String {
    let value = page.eval(&format!("document.getElementById({}).textContent", json!(id))).await;
    value.as_str().unwrap_or_default().to_owned()
}

/// The Fox sample imported with the write token: the import's answer.
async fn import_fox(app: &TestApp) -> Value {
    let glb = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/gltf/Fox/Fox.glb")).unwrap();
    let imported = app
        .http
        .post(app.url("/v1/clips/import?format=glb"))
        .bearer_auth(TOKEN)
        .header("content-type", "application/octet-stream")
        .body(glb)
        .send()
        .await
        .unwrap();
    assert_eq!(imported.status(), 201);
    imported.json().await.unwrap()
}

/// Clicks the element `id`.
async fn click(page: &mut Page, id: &str) {
    page.eval(&format!("document.getElementById({}).click()", json!(id))).await;
}

/// Sets a form control's value and fires `input` and `change`, as typing would.
async fn set_value(page: &mut Page, id: &str, value: &str) {
    page.eval(&format!(
        "(() => {{ const e = document.getElementById({}); e.value = {}; \
         e.dispatchEvent(new Event('input')); e.dispatchEvent(new Event('change')); }})()",
        json!(id),
        json!(value)
    ))
    .await;
}

/// Waits until the page shows a frame past `seq`; returns the one it shows.
async fn next_frame(page: &mut Page, seq: f64) -> f64 {
    page.wait_for(&format!("Number(document.getElementById('seq').textContent) > {seq}"), 10).await;
    text_number(page, "seq").await
}

/// Waits until the shown clip time holds across a frame: a pause took effect.
async fn until_held(page: &mut Page) {
    let clip_time = "document.getElementById('clip-time').textContent";
    within(10 * cdp::PATIENCE, "the clip time held across a frame", async {
        loop {
            let (time, seq) = (page.eval(clip_time).await, text_number(page, "seq").await);
            next_frame(page, seq).await;
            if page.eval(clip_time).await == time {
                return;
            }
        }
    })
    .await;
}

async fn text_number(page: &mut Page, id: &str) -> f64 {
    let text = page.eval(&format!("document.getElementById({}).textContent", json!(id))).await;
    text.as_str().unwrap().parse().unwrap_or_else(|_| panic!("#{id} shows {text}, not a number"))
}

/// The RGB pixels of a canvas, from a real screenshot of its rectangle.
async fn canvas_pixels(page: &mut Page, id: &str) -> Vec<[u8; 3]> {
    let rect = page
        .eval(&format!(
            "(() => {{ const r = document.getElementById({}).getBoundingClientRect(); \
             return [r.x + 1, r.y + 1, r.width - 2, r.height - 2]; }})()",
            json!(id)
        ))
        .await;
    let rect: [f64; 4] = serde_json::from_value(rect).unwrap();
    let png = page.screenshot(Some(rect)).await;
    let decoder = png::Decoder::new(std::io::Cursor::new(png));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    assert!(channels >= 3 && info.bit_depth == png::BitDepth::Eight, "{:?}", info);
    let pixels: Vec<[u8; 3]> = buf[..info.buffer_size()].chunks_exact(channels).map(|p| [p[0], p[1], p[2]]).collect();
    assert!(pixels.len() > 100_000, "a canvas of {} pixels", pixels.len());
    pixels
}

/// A JSON array of numbers (`0` and `0.0` alike).
fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap_or_else(|| panic!("not an array: {v}")).iter().map(|x| x.as_f64().unwrap()).collect()
}

fn differs(a: [u8; 3], b: [u8; 3], tolerance: u8) -> bool {
    a.iter().zip(b).any(|(x, y)| x.abs_diff(y) > tolerance)
}
