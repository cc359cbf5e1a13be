//! The viewer's rough edges, in the browser: a `once` clip that ends and
//! starts over, a read-token server used from the token field (the stream
//! authenticated by its subprotocol), problem bodies shown with their detail
//! and code, the page on a 1366×768 screen, and the keyboard shortcuts.

use std::time::Duration;

use serde_json::json;
use server::config::Secret;

use super::cdp::Browser;
use super::{TOKEN, select_clip, set_value, start, text, text_number, viewer_on_clip};
use crate::common::{TestApp, WAVE};

/// The read token of [`reading_server`].
const READ: &str = "viewer read/token+1";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_once_clip_shows_its_end_and_play_starts_it_over() {
    let app = start().await;
    let id = app.create_id(WAVE, Some(TOKEN)).await;
    let Some(mut browser) = viewer_on_clip(&app, &id).await else { return };
    let page = &mut browser.page;

    // wave.json loops by default; `once` at 4× ends its 3 s in 0.75 s.
    set_value(page, "playback", "once").await;
    set_value(page, "speed", "4").await;
    set_value(page, "fps", "60").await;
    page.eval("document.getElementById('play').click()").await;
    page.wait_for("window.inbetweenViewer.state.ended === true", 10).await;
    assert_eq!(text(page, "play").await, "Play", "the button offers to play again");
    assert_eq!(text(page, "clip-time").await, "3.000 s");
    let status = text(page, "status").await;
    assert!(status.contains("ended at 3 s"), "status: {status}");
    assert_eq!(page.eval("window.inbetweenViewer.state.ws").await, json!(null), "the stream is closed");

    // Play starts over from the start: early clip times, then the end again.
    page.eval("document.getElementById('play').click()").await;
    assert_eq!(text(page, "play").await, "Pause");
    page.wait_for("(s => s.ws && s.frames >= 1)(window.inbetweenViewer.state)", 10).await;
    let first = page.eval("window.inbetweenViewer.state.firstClipTime").await.as_f64().unwrap();
    assert!(first < 0.2, "restarted from the start: first clip time {first}");
    assert_eq!(page.eval("window.inbetweenViewer.state.ended").await, false);
    // The status says what is true now: no end while it plays again, the header names the clip playing.
    let (status, header) = (text(page, "status").await, text(page, "now-playing").await);
    assert!(!status.contains("ended"), "status while playing again: {status}");
    assert_eq!(header, "playing: wave");
    page.wait_for("window.inbetweenViewer.state.ended === true", 10).await;
    assert_eq!(text(page, "play").await, "Play");
    assert_eq!(text(page, "now-playing").await, "ended: wave");
    // Looping from here: the end is no longer said.
    set_value(page, "playback", "loop").await;
    page.eval("document.getElementById('play').click()").await;
    page.wait_for("(s => s.ws && s.frames >= 3)(window.inbetweenViewer.state)", 10).await;
    // The clip's footstep at 1 s may already have been said on a starved page.
    let status = text(page, "status").await;
    assert!(
        ["wave: 2 joints, 0–3 s", "event: footstep"].contains(&status.as_str()),
        "the range rounded, no stale end: {status}"
    );
}

/// A server whose reads need [`READ`] (and writes [`TOKEN`]).
async fn reading_server() -> TestApp {
    TestApp::builder()
        .configure(|c| {
            c.write_token = Some(Secret::new(TOKEN));
            c.read_token = Some(Secret::new(READ));
            c.drain_timeout = Duration::from_secs(2);
        })
        .start()
        .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_read_token_server_works_from_the_token_field() {
    let app = reading_server().await;
    let id = app.create_id(WAVE, Some(TOKEN)).await;
    let Some(mut browser) = Browser::launch().await else { return };
    let page = &mut browser.page;
    page.navigate(&app.url("/viewer")).await;

    // Without a token the list is refused, and the page says what to do.
    page.wait_for("document.getElementById('token-form').classList.contains('wanted')", 10).await;
    let status = page.wait_for("document.getElementById('status').textContent", 10).await;
    let status = status.as_str().unwrap();
    assert!(status.contains("needs a read token") && status.contains("unauthorized"), "status: {status}");

    // A wrong token is refused as such.
    set_value(page, "token", "not-it").await;
    page.eval("document.getElementById('token-form').requestSubmit()").await;
    page.wait_for("document.getElementById('status').textContent.includes('token was refused')", 10).await;

    // The right one (with characters a subprotocol cannot carry raw) lists,
    // selects and streams: the WebSocket carries it as a subprotocol.
    set_value(page, "token", READ).await;
    page.eval("document.getElementById('token-form').requestSubmit()").await;
    select_clip(page, &id).await;
    assert_eq!(page.eval("sessionStorage.getItem('inbetween.token')").await, READ);
    page.eval("document.getElementById('play').click()").await;
    page.wait_for("Number(document.getElementById('seq').textContent) >= 5", 10).await;
    assert_eq!(page.eval("window.inbetweenViewer.cspViolations").await, json!([]));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn problem_bodies_show_their_detail_and_code() {
    let app = start().await;
    let id = app.create_id(WAVE, Some(TOKEN)).await;
    let Some(mut browser) = viewer_on_clip(&app, &id).await else { return };
    let page = &mut browser.page;

    // A control the stream refuses: `{"error": {code, detail}}` on the socket.
    page.eval("document.getElementById('play').click()").await;
    page.wait_for("Number(document.getElementById('seq').textContent) >= 2", 10).await;
    set_value(page, "speed", "5000").await;
    page.wait_for("document.getElementById('status').textContent.includes('control refused')", 10).await;
    let status = text(page, "status").await;
    assert!(status.contains("bad_control") && status.contains("speed"), "status: {status}");
    assert!(!status.contains("[object"), "status: {status}");
    assert_eq!(page.eval("document.getElementById('speed').value").await, "1", "back to the speed in force");

    // A REST problem with a pointer: a clip document the server refuses.
    let bad = tempfile::Builder::new().suffix(".json").tempfile().unwrap();
    std::fs::write(bad.path(), r#"{"name": "bad", "tracks": [{"joint": "a", "channel": "rotation", "times": [1, 0], "values": [[0,0,0,1],[0,0,0,1]]}]}"#).unwrap();
    set_value(page, "token", TOKEN).await;
    page.eval("document.getElementById('token-form').requestSubmit()").await;
    page.set_files("#file", &[bad.path()]).await;
    // The status as it says so: the stream's events replace it soon after.
    let refused = "(s => s.includes('upload refused') && s)(document.getElementById('status').textContent)";
    let status = page.wait_for(refused, 20).await.as_str().unwrap().to_owned();
    assert!(status.contains("422") && status.contains("/tracks/0/times"), "detail, code, status and pointer: {status}");
    assert!(!status.contains("[object"), "status: {status}");

    // A stream setting the page can check itself, before any handshake.
    page.eval("document.getElementById('play').click()").await;
    set_value(page, "fps", "500").await;
    page.eval("document.getElementById('play').click()").await;
    let status = text(page, "status").await;
    assert!(status.contains("fps must be a whole number from 1 to 240"), "status: {status}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_fits_1366_by_768_and_answers_its_keys() {
    let app = start().await;
    let id = app.create_id(WAVE, Some(TOKEN)).await;
    let Some(mut browser) = Browser::launch().await else { return };
    let page = &mut browser.page;
    page.set_viewport(1366, 768).await;
    page.navigate(&app.url("/viewer")).await;
    select_clip(page, &id).await;

    let sizes = page
        .eval(
            "(e => [e.scrollWidth, e.scrollHeight, e.clientWidth, e.clientHeight, \
             document.getElementById('scene').clientHeight, document.getElementById('curves').clientHeight])\
             (document.scrollingElement)",
        )
        .await;
    let [scroll_w, scroll_h, client_w, client_h, scene_h, curves_h]: [u32; 6] = serde_json::from_value(sizes).unwrap();
    assert_eq!((client_w, client_h), (1366, 768));
    assert!(scroll_w <= client_w && scroll_h <= client_h, "scrolls: {scroll_w}×{scroll_h} in {client_w}×{client_h}");
    assert!(scene_h >= 300 && curves_h >= 100, "the canvases get the room: scene {scene_h} px, curves {curves_h} px");

    // Keys: End, Home, a frame step at 30 fps, a second with Shift, Space
    // (`once`, so that the end is shown as the end rather than the loop's start).
    set_value(page, "playback", "once").await;
    for (k, shift, shown) in [
        ("End", false, "3.000 s"),
        ("Home", false, "0.000 s"),
        ("ArrowRight", false, "0.033 s"),
        ("ArrowRight", true, "1.033 s"),
        ("ArrowLeft", false, "1.000 s"),
    ] {
        page.eval(&key(k, shift)).await;
        page.wait_for(&format!("document.getElementById('clip-time').textContent === {}", json!(shown)), 10).await;
    }
    page.eval(&key(" ", false)).await;
    page.wait_for("Number(document.getElementById('seq').textContent) >= 3", 10).await;
    assert_eq!(text(page, "play").await, "Pause");
    let before = text_number(page, "seq").await;
    page.eval(&key(" ", false)).await;
    assert_eq!(text(page, "play").await, "Play", "space pauses");
    assert!(before >= 3.0);
}

/// Paused poses asked in a row can be answered out of order (the browser
/// spreads them over connections; a loaded server finishes them in any
/// order): the page shows the pose last asked for, not the last to arrive.
/// Here the answer for t = 0 is held back until after the one for the end.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_late_answer_for_an_earlier_seek_does_not_replace_the_pose_shown() {
    let app = start().await;
    let id = app.create_id(WAVE, Some(TOKEN)).await;
    let Some(mut browser) = viewer_on_clip(&app, &id).await else { return };
    let page = &mut browser.page;
    set_value(page, "playback", "once").await;
    page.wait_for("document.getElementById('clip-time').textContent === '0.000 s'", 10).await;
    page.eval(
        "(() => { const plain = window.fetch; window.poseAnswers = 0; \
         window.fetch = async (path, options) => { \
           const response = await plain(path, options); \
           if (String(path).includes('/pose?') && String(path).includes('t=0&')) \
             await new Promise((done) => setTimeout(done, 600)); \
           window.poseAnswers += String(path).includes('/pose?'); \
           return response; }; })()",
    )
    .await;
    for k in ["End", "Home", "End"] {
        page.eval(&key(k, false)).await;
    }
    page.wait_for("window.poseAnswers === 3", 10).await;
    assert_eq!(text(page, "clip-time").await, "3.000 s", "the last seek wins");
    assert_eq!(page.eval("document.getElementById('seek').value").await, json!("3"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_fox_is_drawn_with_solid_bones_and_no_stray_one() {
    let app = start().await;
    let imported = super::import_fox(&app).await;
    let id = imported["clips"][0]["id"].as_str().unwrap().to_owned();
    let Some(mut browser) = viewer_on_clip(&app, &id).await else { return };
    let page = &mut browser.page;
    let drawn = page.wait_for("window.inbetweenViewer.drawn?.bones.length && window.inbetweenViewer.drawn", 10).await;

    // The Fox's 25 nodes: the scene root `root` (no skin joint), and its skin's
    // 24 joints, of which `_rootJoint` and `b_Root_00` weight no vertex (read
    // from the GLB's JOINTS_0/WEIGHTS_0): they only place the rig at the floor
    // origin. The 22 joints left, one of them (b_Hip_01) the root: 21 bones,
    // none from the floor to the hip.
    let bones: Vec<(String, String)> = serde_json::from_value(drawn["bones"].clone()).unwrap();
    assert_eq!(bones.len(), 21, "{bones:?}");
    assert_eq!(drawn["joints"], 22);
    for placement in ["root", "_rootJoint", "b_Root_00"] {
        assert!(bones.iter().all(|(p, c)| p != placement && c != placement), "{placement} drawn as a bone");
    }
    assert!(bones.contains(&("b_Hip_01".into(), "b_Spine01_02".into())));
    assert!(bones.contains(&("b_LeftFoot01_017".into(), "b_LeftFoot02_018".into())), "an unanimated tip is a joint");

    // Solids, not lines: lit bone faces in several shades of the bone grey and
    // spheres in the joints' orange.
    let pixels = super::canvas_pixels(page, "scene").await;
    let orange = pixels.iter().filter(|p| !super::differs(**p, [0xff, 0x8c, 0x1a], 40)).count();
    let greys: std::collections::BTreeSet<u8> = pixels
        .iter()
        .filter(|p| p[0] > 90 && p[0].abs_diff(p[2]) < 30 && p[1].abs_diff(p[2]) < 16 && p[2] >= p[0])
        .map(|p| p[2] / 16)
        .collect();
    let grey_pixels = pixels.iter().filter(|p| p[0] > 90 && p[2] >= p[0] && p[0].abs_diff(p[2]) < 30).count();
    assert!(orange >= 200, "joint spheres: {orange} orange pixels");
    assert!(grey_pixels >= 1000 && greys.len() >= 3, "bone solids: {grey_pixels} px in {} shades", greys.len());
}

/// A script pressing `k` (with Shift if `shift`) on the page, as the keyboard would.
fn key(k: &str, shift: bool) -> String {
    format!(
        "document.body.dispatchEvent(new KeyboardEvent('keydown', {{key: {}, shiftKey: {shift}, bubbles: true}}))",
        json!(k)
    )
}
