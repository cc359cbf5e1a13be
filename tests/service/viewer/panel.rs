//! The composition, IK and broadcast panel in the browser: a crossfade from
//! the page's button reaches the server (the frames change clip, and once
//! the fade is over they are the other clip's poses, as REST gives them), a
//! layer's weight slider moves the pose live, dragging an IK handle moves the
//! effector to the dragged target (read from the frames the page receives),
//! and a broadcast link opened in a second tab shows the same `seq` and pose
//! as the first, with the controls shown only where the write token is.

use std::time::Duration;

use serde_json::{Value, json};

use super::cdp::{Browser, Page};
use super::{TOKEN, click, floats, select_clip, set_value, start, text};
use crate::common::WAVE;

/// wave.json's skeleton with other tracks: its root held far away, so its
/// poses differ from the wave's everywhere.
const AWAY: &str = r#"{"name": "away", "skeleton": {"joints": [
    {"name": "root", "parent": null},
    {"name": "arm", "parent": "root", "rest": {"translation": [0, 1, 0]}}]},
  "tracks": [{"joint": "root", "channel": "translation", "interpolation": "linear",
              "times": [0, 2], "values": [[3, 0, 0], [3, 0.5, 0]]}],
  "playback": "loop"}"#;

/// A bent arm, upper and lower 0.5 long, swaying slowly at the shoulder.
const ARM: &str = r#"{"name": "arm3", "skeleton": {"joints": [
    {"name": "body", "parent": null},
    {"name": "shoulder", "parent": "body", "rest": {"translation": [0, 1, 0]}},
    {"name": "elbow", "parent": "shoulder", "rest": {"translation": [0.5, 0, 0]}},
    {"name": "hand", "parent": "elbow", "rest": {"translation": [0, 0.5, 0]}}]},
  "tracks": [{"joint": "shoulder", "channel": "rotation", "interpolation": "linear",
              "times": [0, 2, 4], "values": [[0, 0, 0, 1], [0, 0, 0.0998, 0.995], [0, 0, 0, 1]]}],
  "playback": "loop"}"#;

/// The last frame the page received, as JSON.
const LAST_FRAME: &str = "window.inbetweenViewer.panel.lastFrame";

fn joint<'a>(pose: &'a Value, name: &str) -> &'a Value {
    pose["joints"].as_array().unwrap().iter().find(|j| j["name"] == name).unwrap_or_else(|| panic!("{name} in {pose}"))
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_crossfade_from_the_button_reaches_the_server() {
    let app = start().await;
    let wave = app.create_id(WAVE, Some(TOKEN)).await;
    let away = app.create_id(AWAY, Some(TOKEN)).await;
    let other = app.create_id(ARM, Some(TOKEN)).await;
    let Some(mut browser) = Browser::launch().await else { return };
    let page = &mut browser.page;
    page.navigate(&app.url("/viewer")).await;
    select_clip(page, &wave).await;
    click(page, "play").await;
    page.wait_for(&format!("{LAST_FRAME}?.pose.clip === {}", json!(wave)), 10).await;

    // A clip of another skeleton is refused: the status says why, the layers stay.
    set_value(page, "fade-clip", &other).await;
    click(page, "fade").await;
    page.wait_for("document.getElementById('status').textContent.includes('control refused')", 10).await;
    let status = text(page, "status").await;
    assert!(status.contains("bad_control") && status.contains("skeleton"), "status: {status}");
    page.wait_for(&format!("window.inbetweenViewer.panel.layers[0].clip === {}", json!(wave)), 5).await;

    set_value(page, "fade-clip", &away).await;
    set_value(page, "fade-duration", "0.3").await;
    click(page, "fade").await;
    page.wait_for(&format!("{LAST_FRAME}.pose.clip === {}", json!(away)), 10).await;
    assert!(text(page, "playing").await.contains("away"), "the panel names the clip playing");
    page.wait_for(&format!("window.inbetweenViewer.state.clip.id === {}", json!(away)), 5).await;
    assert_eq!(page.eval("document.getElementById('seek').max").await, "2", "the seek bar spans the new clip");

    // After the fade only `away` remains: each frame is its pose at the
    // frame's clip time, as the REST pose route computes it.
    // (The frame's `time` is the motion time, 0 when the fade started.)
    let frame = page.wait_for(&format!("{LAST_FRAME}.pose.time > 0.4 && {LAST_FRAME}"), 10).await;
    let t = frame["pose"]["clip_time"].as_f64().unwrap();
    let rest: Value = app
        .http
        .get(app.url(&format!("/v1/clips/{away}/pose?t={t}&space=model")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    for name in ["root", "arm"] {
        let (got, want) =
            (floats(&joint(&frame["pose"], name)["translation"]), floats(&joint(&rest, name)["translation"]));
        assert!(distance(&got, &want) < 1e-4, "{name} at {t}: frame {got:?}, REST {want:?}");
    }
    assert!(floats(&joint(&frame["pose"], "root")["translation"])[0] > 2.9, "the far-away root: {frame}");
    assert_eq!(page.eval("window.inbetweenViewer.panel.layers.map(l => l.clip)").await, json!([away]));
    assert_eq!(page.eval("window.inbetweenViewer.cspViolations").await, json!([]));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_layers_weight_slider_blends_live() {
    let app = start().await;
    let wave = app.create_id(WAVE, Some(TOKEN)).await;
    let away = app.create_id(AWAY, Some(TOKEN)).await;
    let Some(mut browser) = Browser::launch().await else { return };
    let page = &mut browser.page;
    page.navigate(&app.url("/viewer")).await;
    select_clip(page, &wave).await;
    click(page, "play").await;
    page.wait_for("window.inbetweenViewer.state.frames >= 2", 10).await;

    // `away` as a second layer at full weight: the root is away's (x = 3).
    set_value(page, "layer-clip", &away).await;
    click(page, "layer-add").await;
    page.wait_for("document.querySelectorAll('#layers li').length === 2", 5).await;
    let root_x = format!("{LAST_FRAME}?.pose.joints.find(j => j.name === 'root').translation[0]");
    page.wait_for(&format!("{root_x} > 2.99"), 10).await;

    // Its slider at 0.5 is a live `layer` control: half way between the two.
    page.eval(
        "(e => { e.value = '0.5'; e.dispatchEvent(new Event('input')); })\
         (document.querySelector('#layers li[data-index=\"1\"] input[type=range]'))",
    )
    .await;
    let frame = page.wait_for(&format!("{root_x} < 2.9 && {LAST_FRAME}"), 10).await;
    let seq = frame["seq"].as_u64().unwrap();
    page.wait_for(&format!("{LAST_FRAME}.seq > {}", seq + 2), 10).await;
    let frame = page.eval(LAST_FRAME).await;
    let t = frame["pose"]["clip_time"].as_f64().unwrap();
    let wave_pose: Value =
        app.http.get(app.url(&format!("/v1/clips/{wave}/pose?t={t}"))).send().await.unwrap().json().await.unwrap();
    let wave_x = floats(&joint(&wave_pose, "root")["translation"])[0];
    let x = floats(&joint(&frame["pose"], "root")["translation"])[0];
    assert!((x - (0.5 * wave_x + 0.5 * 3.0)).abs() < 1e-3, "root x {x}: half of wave's {wave_x} and away's 3");
}

/// The handle's centre in the viewport's CSS pixels, and the camera's yaw.
async fn handle_on_screen(page: &mut Page) -> ([f64; 2], f64) {
    let at = page
        .eval(
            "(v => { const cam = v.sceneCamera(); const s = v.toScreen(cam, v.toCamera(cam, v.panel.ik.target)); \
             const r = document.getElementById('scene').getBoundingClientRect(); \
             return [r.left + s[0] / cam.dpr, r.top + s[1] / cam.dpr, v.state.camera.yaw]; })(window.inbetweenViewer)",
        )
        .await;
    let [x, y, yaw]: [f64; 3] = serde_json::from_value(at).unwrap();
    ([x, y], yaw)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dragging_an_ik_handle_moves_the_effector() {
    let app = start().await;
    let arm = app.create_id(ARM, Some(TOKEN)).await;
    let Some(mut browser) = Browser::launch().await else { return };
    let page = &mut browser.page;
    page.navigate(&app.url("/viewer")).await;
    select_clip(page, &arm).await;
    set_value(page, "ik-joint", "hand").await;
    set_value(page, "ik-kind", "two_bone").await;
    click(page, "ik-add").await;
    let ik = page.eval("window.inbetweenViewer.panel.ik").await;
    assert_eq!(ik["joints"], json!(["shoulder", "elbow", "hand"]), "two-bone: the joint, its parent and grandparent");
    let start_target = floats(&ik["target"]);

    // Paused, a drag fetches the solved pose (`POST /v1/poses` with the constraint).
    let (from, _) = handle_on_screen(page).await;
    page.drag(from, [from[0] + 15.0, from[1] + 15.0], 4).await;
    let paused_target = page.eval("window.inbetweenViewer.panel.ik.target").await;
    let hand_at = "(v => v.state.positions[v.state.names.indexOf('hand')])(window.inbetweenViewer)";
    page.wait_for(&format!("Math.hypot(...{hand_at}.map((x, k) => x - {paused_target}[k])) < 1e-3"), 10).await;
    click(page, "play").await;
    page.wait_for(&format!("{LAST_FRAME}?.pose.ik?.length === 1"), 10).await;

    // The handle is drawn over the scene: its cyan under the cursor.
    let (from, yaw) = handle_on_screen(page).await;
    let shot = page.screenshot(Some([from[0] - 12.0, from[1] - 12.0, 24.0, 24.0])).await;
    assert!(cyan_pixels(&shot) >= 20, "the handle is drawn where it is grabbed");

    let to = [from[0] - 40.0, from[1] + 35.0];
    page.drag(from, to, 10).await;
    let (_, yaw_after) = handle_on_screen(page).await;
    assert_eq!(yaw, yaw_after, "dragging the handle does not orbit the camera");
    let target = floats(&page.eval("window.inbetweenViewer.panel.ik.target").await);
    assert!(distance(&target, &start_target) > 0.05, "the target moved: {start_target:?} → {target:?}");

    // The frames the page receives put the hand on the dragged target (the
    // last one sent), reachable here: |l1 − l2| ≤ |target − shoulder| ≤ l1 + l2.
    let sent = format!(
        "(s => s && s.every((x, k) => Math.abs(x - {t}[k]) < 1e-12))(window.inbetweenViewer.panel.sentIk)",
        t = json!(target)
    );
    page.wait_for(&sent, 5).await;
    let check = format!(
        "(f => f && f.pose.ik[0].residual < 1e-4 && \
           Math.hypot(...f.pose.joints.find(j => j.name === 'hand').translation.map((x, k) => x - {t}[k])) < 1e-3 && f)({LAST_FRAME})",
        t = json!(target)
    );
    let frame = page.wait_for(&check, 10).await;
    let pose = &frame["pose"];
    let [shoulder, elbow, hand] = ["shoulder", "elbow", "hand"].map(|n| floats(&joint(pose, n)["translation"]));
    let (l1, l2, d) = (distance(&shoulder, &elbow), distance(&elbow, &hand), distance(&shoulder, &target));
    assert!((l1 - l2).abs() <= d && d <= l1 + l2, "reachable: l1 {l1}, l2 {l2}, distance {d}");
    assert!(distance(&hand, &target) < 1e-3 * (l1 + l2), "hand {hand:?} on target {target:?}");

    // The aim preset on the elbow: one `aim` constraint, solved (residual: the angle).
    click(page, "ik-remove").await;
    page.wait_for(&format!("{LAST_FRAME}.pose.ik === undefined"), 10).await;
    set_value(page, "ik-joint", "elbow").await;
    set_value(page, "ik-kind", "aim").await;
    click(page, "ik-add").await;
    let aim = page.eval("window.inbetweenViewer.panel.motion().ik").await;
    assert_eq!((&aim[0]["kind"], &aim[0]["joint"]), (&json!("aim"), &json!("elbow")));
    page.wait_for(&format!("(r => r && r.kind === 'aim' && r.residual < 1e-4)({LAST_FRAME}.pose.ik?.[0])"), 10).await;
    assert_eq!(page.eval("window.inbetweenViewer.cspViolations").await, json!([]));
}

/// Pixels of the handle's cyan (#3ad1e6) in a PNG.
fn cyan_pixels(png: &[u8]) -> usize {
    let decoder = png::Decoder::new(std::io::Cursor::new(png));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    buf[..info.buffer_size()]
        .chunks_exact(channels)
        .filter(|p| !super::differs([p[0], p[1], p[2]], [0x3a, 0xd1, 0xe6], 40))
        .count()
}

/// `{seq: pose}` of the broadcast frames a page received.
async fn broadcast_frames(page: &mut Page) -> serde_json::Map<String, Value> {
    let frames = page.eval("Object.fromEntries(window.inbetweenViewer.broadcast.frames)").await;
    frames.as_object().cloned().unwrap_or_default()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broadcast_link_shows_the_same_seq_and_pose_in_a_second_page() {
    let app = start().await;
    let wave = app.create_id(WAVE, Some(TOKEN)).await;
    let away = app.create_id(AWAY, Some(TOKEN)).await;
    let Some(mut browser) = Browser::launch().await else { return };
    let second = browser.new_page().await;
    let page = &mut browser.page;
    page.navigate(&app.url("/viewer")).await;
    set_value(page, "token", TOKEN).await;
    page.eval("document.getElementById('token-form').requestSubmit()").await;
    select_clip(page, &wave).await;
    set_value(page, "fps", "20").await;
    click(page, "broadcast").await;
    let link = page
        .wait_for("window.inbetweenViewer.broadcast.id && document.getElementById('broadcast-link').value", 10)
        .await;
    let link = link.as_str().unwrap().to_owned();
    let id = page.eval("window.inbetweenViewer.broadcast.id").await.as_str().unwrap().to_owned();
    assert_eq!(link, app.url(&format!("/viewer?broadcast={id}")));
    let listed: Value =
        app.http.get(app.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap().json().await.unwrap();
    assert_eq!((listed["fps"].as_u64(), &listed["motion"]["layers"][0]["clip"]), (Some(20), &json!(wave)));
    page.wait_for("window.inbetweenViewer.broadcast.canControl === true", 10).await;
    assert_eq!(page.eval("document.getElementById('play').hidden").await, false, "the write token controls");

    // The second tab (no token: read only on this server) opens the link.
    let mut second = second;
    second.navigate(&link).await;
    second.wait_for("window.inbetweenViewer.broadcast.frames.size >= 8", 15).await;
    second.wait_for("window.inbetweenViewer.broadcast.canControl === false", 10).await;
    for id in ["play", "seek", "composition", "ik-panel"] {
        let hidden = second.eval(&format!("document.getElementById({}).hidden", json!(id))).await;
        assert_eq!(hidden, true, "#{id} is a control: hidden without the write scope");
    }

    // The same seq carries the same pose in both tabs.
    let (a, b) = (broadcast_frames(page).await, broadcast_frames(&mut second).await);
    let common: Vec<&String> = b.keys().filter(|seq| a.contains_key(*seq)).collect();
    assert!(common.len() >= 5, "frames in common: {} ({} and {})", common.len(), a.len(), b.len());
    for seq in common {
        assert_eq!(a[seq], b[seq], "seq {seq}");
    }
    // Each shows the seq of the last frame it received: the broadcast's tick
    // (the two read a moment apart, on a machine that may be busy).
    let shown =
        "(v => [Number(document.getElementById('seq').textContent), v.panel.lastFrame.seq])(window.inbetweenViewer)";
    // The frames shown come at the tabs' animation frames (or their fallback timer).
    page.wait_for("window.inbetweenViewer.panel.lastFrame", 10).await;
    second.wait_for("window.inbetweenViewer.panel.lastFrame", 10).await;
    let mut shown_seqs = vec![];
    for tab in [&mut *page, &mut second] {
        let [on_screen, last]: [u64; 2] = serde_json::from_value(tab.eval(shown).await).unwrap();
        assert_eq!(on_screen, last, "the readout shows the last frame's seq");
        shown_seqs.push(last);
    }
    assert!(shown_seqs[0].abs_diff(shown_seqs[1]) <= 10, "both show the broadcast's seq: {shown_seqs:?}");

    // Pause in the first tab holds the pose in the second from the control's seq.
    click(page, "play").await;
    let applied = page.wait_for("window.inbetweenViewer.broadcast.lastControl?.op === 'pause' && window.inbetweenViewer.broadcast.lastControl.seq", 10).await;
    let k = applied.as_u64().unwrap();
    // (A frame this tab's socket dropped is missing from its map: wait for a later one.)
    second.wait_for(&format!("Math.max(...window.inbetweenViewer.broadcast.frames.keys()) >= {}", k + 6), 10).await;
    let b = broadcast_frames(&mut second).await;
    let held: Vec<&Value> = (k..=k + 6).filter_map(|s| b.get(&s.to_string())).map(|p| &p["time"]).collect();
    assert!(held.len() >= 3 && held.windows(2).all(|w| w[0] == w[1]), "paused from seq {k}: times {held:?}");

    // A crossfade from the first tab's button reaches the second tab's frames.
    click(page, "play").await;
    set_value(page, "fade-clip", &away).await;
    set_value(page, "fade-duration", "0.2").await;
    click(page, "fade").await;
    let applied = page.wait_for("window.inbetweenViewer.broadcast.lastControl?.op === 'crossfade' && window.inbetweenViewer.broadcast.lastControl.seq", 10).await;
    let k = applied.as_u64().unwrap();
    // Each tab's frames by seq: the wave's before the control's seq, away's from it on.
    let clips = |from: u64| {
        format!(
            "[...window.inbetweenViewer.broadcast.frames].filter(([s]) => s >= {from} && s < {k} + 12).map(([s, p]) => [s, p.clip])"
        )
    };
    for tab in [&mut second, page] {
        tab.wait_for(&format!("{}.length >= 6", clips(k)), 10).await;
        let seen: Vec<(u64, String)> = serde_json::from_value(tab.eval(&clips(k.saturating_sub(6))).await).unwrap();
        assert!(seen.iter().all(|(s, clip)| clip == if *s < k { &wave } else { &away }), "control at {k}: {seen:?}");
    }
    assert_eq!(second.eval("window.inbetweenViewer.cspViolations").await, json!([]));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_fox_walks_a_root_motion_trail_with_a_layer_and_a_handle_on_a_1366_by_768_screen() {
    let app = start().await;
    let imported = super::import_fox(&app).await;
    let id_of = |name: &str| {
        let clips = imported["clips"].as_array().unwrap();
        clips.iter().find(|c| c["name"] == name).unwrap_or_else(|| panic!("{name} in {imported}"))["id"]
            .as_str()
            .unwrap()
            .to_owned()
    };
    let (walk, survey) = (id_of("Walk"), id_of("Survey"));
    let Some(mut browser) = Browser::launch().await else { return };
    let page = &mut browser.page;
    page.set_viewport(1366, 768).await;
    page.navigate(&app.url("/viewer")).await;
    select_clip(page, &walk).await;
    set_value(page, "playback", "loop").await;
    set_value(page, "root-mode", "extract").await;
    set_value(page, "layer-clip", &survey).await;
    click(page, "layer-add").await;
    page.eval(
        "(e => { e.value = 'b_Spine01_02'; e.dispatchEvent(new Event('change')); })\
         (document.querySelector('#layers li[data-index=\"1\"] select'))",
    )
    .await;
    set_value(page, "ik-joint", "b_LeftFoot01_017").await;
    click(page, "ik-add").await;
    click(page, "play").await;
    page.wait_for("window.inbetweenViewer.state.frames >= 3", 10).await;
    let (from, _) = handle_on_screen(page).await;
    page.drag(from, [from[0] + 30.0, from[1] - 25.0], 6).await;
    page.wait_for("window.inbetweenViewer.panel.trail.length >= 20", 10).await;
    let motion = page.eval("window.inbetweenViewer.panel.motion()").await;
    assert_eq!(motion["root_motion"], json!({"mode": "extract", "joint": "b_Hip_01"}));
    assert_eq!(motion["layers"][1]["mask"], json!({"joints": {"b_Spine01_02": 1}, "descendants": true}));
    assert_eq!(motion["ik"][0]["joints"], json!(["b_LeftLeg01_015", "b_LeftLeg02_016", "b_LeftFoot01_017"]));
    let sizes = page
        .eval("(e => [e.scrollWidth, e.scrollHeight, e.clientWidth, e.clientHeight])(document.scrollingElement)")
        .await;
    let [scroll_w, scroll_h, client_w, client_h]: [u32; 4] = serde_json::from_value(sizes).unwrap();
    assert!(scroll_w <= client_w && scroll_h <= client_h, "scrolls: {scroll_w}×{scroll_h} in {client_w}×{client_h}");

    page.picture("INBETWEEN_VIEWER_PANEL_SCREENSHOT", Duration::from_millis(1500), 1.0).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn root_motion_is_a_trail_the_skeleton_walks_along_with_extract_on_or_off() {
    let app = start().await;
    let wave = app.create_id(WAVE, Some(TOKEN)).await;
    let Some(mut browser) = Browser::launch().await else { return };
    let page = &mut browser.page;
    page.navigate(&app.url("/viewer")).await;
    select_clip(page, &wave).await;
    // wave.json's root goes along x (0 → 1) in its first second, then up.
    // Each mode's stream starts near the clip's start (a mode change restarts
    // it from the time shown: Home first).
    for (mode, pose_moves) in [("report", true), ("extract", false)] {
        if page.eval("window.inbetweenViewer.state.ws").await.is_null() {
            set_value(page, "root-mode", mode).await;
            click(page, "play").await;
        } else {
            page.eval("document.body.dispatchEvent(new KeyboardEvent('keydown', {key: 'Home', bubbles: true}))").await;
            page.wait_for(&format!("{LAST_FRAME}.pose.clip_time < 0.15"), 10).await;
            set_value(page, "root-mode", mode).await;
        }
        page.wait_for("window.inbetweenViewer.panel.trail.length >= 10", 10).await;
        page.wait_for(&format!("{LAST_FRAME}.pose.clip_time > 0.5 && {LAST_FRAME}.pose.clip_time < 0.95"), 10).await;
        let seen = page
            .eval(&format!(
                "(v => [v.panel.trail[0], v.panel.trail.at(-1), v.state.positions[v.state.names.indexOf('root')],                    {LAST_FRAME}.pose.joints.find(j => j.name === 'root').translation])(window.inbetweenViewer)"
            ))
            .await;
        let [first, trail, drawn, sent]: [[f64; 3]; 4] = serde_json::from_value(seen).unwrap();
        assert_eq!((first[1], trail[1]), (0.0, 0.0), "{mode}: the trail is on the ground");
        assert!(trail[0] - first[0] > 0.2, "{mode}: the trail follows the root along x: {first:?} → {trail:?}");
        let ground = [drawn[0], 0.0, drawn[2]];
        assert!(
            distance(&ground, &trail) < 1e-4,
            "{mode}: the root is drawn on the trail's end: {drawn:?} vs {trail:?}"
        );
        assert_eq!(sent[0] > 0.3, pose_moves, "{mode}: the frames' root at x = {}", sent[0]);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_gizmos_arrow_moves_the_target_along_its_axis_only() {
    let app = start().await;
    let arm = app.create_id(ARM, Some(TOKEN)).await;
    let Some(mut browser) = Browser::launch().await else { return };
    let page = &mut browser.page;
    page.navigate(&app.url("/viewer")).await;
    select_clip(page, &arm).await;
    set_value(page, "ik-joint", "hand").await;
    set_value(page, "ik-kind", "two_bone").await;
    click(page, "ik-add").await;
    let start_target = floats(&page.eval("window.inbetweenViewer.panel.ik.target").await);

    // The up (Y) arrow (60 px long at the handle's depth), base and tip, on the page: grab
    // it halfway and drag 30 px down the screen, and 12 px sideways.
    let arrow = page
        .eval(
            "(v => { const cam = v.sceneCamera(), t = v.panel.ik.target, L = 60 * cam.dpr * v.toCamera(cam, t)[2] / cam.focal; \
             const r = document.getElementById('scene').getBoundingClientRect(); \
             const s = p => { const [x, y] = v.toScreen(cam, v.toCamera(cam, p)); return [r.left + x / cam.dpr, r.top + y / cam.dpr]; }; \
             return [s(t), s([t[0], t[1] + L, t[2]])]; })(window.inbetweenViewer)",
        )
        .await;
    let [base, tip]: [[f64; 2]; 2] = serde_json::from_value(arrow).unwrap();
    assert!(tip[1] < base[1] - 20.0, "the Y arrow points up the screen: {base:?} → {tip:?}");
    let yaw = page.eval("window.inbetweenViewer.state.camera.yaw").await;
    let grab = [(base[0] + tip[0]) / 2.0, (base[1] + tip[1]) / 2.0];
    page.drag(grab, [grab[0] + 12.0, grab[1] + 30.0], 6).await;
    assert_eq!(page.eval("window.inbetweenViewer.state.camera.yaw").await, yaw, "no orbit");
    let target = floats(&page.eval("window.inbetweenViewer.panel.ik.target").await);
    // Along Y only: X and Z exactly as they were (the drag went sideways too).
    assert_eq!((target[0], target[2]), (start_target[0], start_target[2]));
    assert!(target[1] < start_target[1] - 0.05, "moved down: {start_target:?} → {target:?}");
    // The paused view's pose solves for it: the hand on the new target.
    let hand_at = "(v => v.state.positions[v.state.names.indexOf('hand')])(window.inbetweenViewer)";
    page.wait_for(&format!("Math.hypot(...{hand_at}.map((x, k) => x - {}[k])) < 1e-3", json!(target)), 10).await;
}
