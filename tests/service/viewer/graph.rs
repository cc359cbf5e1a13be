//! A graph played in the viewer (docs/graphs.md): the Fox's locomotion
//! graph picked in the graph panel, then, while it streams, the speed slider
//! dragged and the trigger pressed. The page sends `set` controls; the
//! frames' reports take the graph from `idle` through the fade to `move`,
//! with the weights the blend's definition gives for the speed set, and the
//! trigger to `look`; the panel shows each. With a chain on the Fox's tail
//! from the springs panel, the graph's motion carries it: the pose the page
//! shows is the server's pose of the graph with those springs, its tail away
//! from the same graph's without them at the same tick, and the stream the
//! slider takes to a run opens with the chain.
//!
//! With root motion ("trail") and a two-bone handle on a foreleg picked
//! beside the graph, the stream opens with both, its frames are the
//! server's samples of that motion tick for tick (root motion and IK
//! reports included), the trail grows from them, and removing the handle
//! opens the graph's stream again without it (its IK is fixed when it opens).
//! A graph over the CMU take played on CesiumMan: the joint selects offer
//! CesiumMan's joints, root motion follows its hips, the stream opens with
//! the character and its frames, CesiumMan's, are the server's samples.
//!
//! `INBETWEEN_GRAPH_SCREENSHOT=docs/images/viewer-graph.png` saves the page
//! with the Fox running on the graph, its tail on springs (docs/viewer.md).

use serde_json::{Value, json};

use super::{TOKEN, click, floats, post_json, set_value, text, viewer_on_clip};
use crate::api::graph_samples::fox_graph_as;

/// Waits until the panel's state line says `want`.
async fn state_shows(page: &mut super::cdp::Page, want: &str, seconds: u64) {
    page.wait_for(&format!("document.getElementById('graph-state').textContent === {}", json!(want)), seconds).await;
}

/// The Fox's locomotion graph stored on `app`, its first clip, and a
/// browser on the viewer with that clip (`None` where no browser can run).
async fn fox_graph_viewer(app: &crate::common::TestApp) -> Option<(String, String, super::cdp::Browser)> {
    let (graph, _) = fox_graph_as(app, Some(super::TOKEN)).await;
    let listed = app.get_json("/v1/graphs").await;
    let summary = listed["graphs"].as_array().unwrap().iter().find(|g| g["id"] == json!(graph)).unwrap();
    let survey = summary["clips"][0].as_str().unwrap().to_owned();
    let browser = viewer_on_clip(app, &survey).await?;
    Some((graph, survey, browser))
}

/// Picks `graph` in the graph panel, once it is listed: its controls show.
async fn pick_graph(page: &mut super::cdp::Page, graph: &str) {
    let option = format!("[...document.getElementById('graph').options].some(o => o.value === {})", json!(graph));
    page.wait_for(&option, 10).await;
    set_value(page, "graph", graph).await;
    let picked = format!("window.inbetweenViewer.state.graph?.id === {}", json!(graph));
    page.wait_for(&format!("document.body.classList.contains('graphing') && {picked}"), 10).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_speed_slider_takes_the_fox_from_idle_to_a_run_and_the_trigger_to_a_look() {
    let app = super::start().await;
    let Some((graph, survey, mut browser)) = fox_graph_viewer(&app).await else { return };
    let page = &mut browser.page;

    pick_graph(page, &graph).await;
    state_shows(page, "idle", 10).await; // the paused pose's report
    assert!(page.eval("document.getElementById('layers').offsetParent === null").await.as_bool().unwrap());

    click(page, "play").await;
    page.wait_for("window.inbetweenViewer.state.frames > 0", 10).await;
    // Speed 2: halfway between Walk (at 1) and Run (at 3).
    set_value(page, "graph-speed", "2").await;
    state_shows(page, "move", 10).await;
    page.wait_for("document.getElementById('graph-weights').textContent.includes('move: Walk 0.50 · Run 0.50')", 10)
        .await;
    set_value(page, "graph-speed", "3").await;
    page.wait_for("document.getElementById('graph-weights').textContent === 'move: Run 1.00'", 10).await;

    click(page, "graph-survey").await;
    page.wait_for("document.getElementById('graph-state').textContent.startsWith('move → look')", 10).await;
    state_shows(page, "look", 10).await;

    // Back to the layers: the composition controls return, the motion is the clip again.
    set_value(page, "graph", "").await;
    page.wait_for("!document.body.classList.contains('graphing')", 10).await;
    let motion = page.eval("window.inbetweenViewer.panel.motion()").await;
    assert_eq!(motion["layers"][0]["clip"], json!(survey), "{motion}");
    assert_eq!(text(page, "graph-state").await, "");
}

/// With **frames: compact** a graph streams compact frames, and the page
/// shows the report of their graph report section (docs/compact-frames.md):
/// the state, the transition into a look, the blend weights.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_compact_graph_stream_shows_the_report_its_frames_carry() {
    let app = super::start().await;
    let Some((graph, _, mut browser)) = fox_graph_viewer(&app).await else { return };
    let page = &mut browser.page;
    pick_graph(page, &graph).await;
    set_value(page, "encoding", "compact").await;
    click(page, "play").await;
    page.wait_for("window.inbetweenViewer.state.frames > 0", 10).await;
    state_shows(page, "idle", 10).await;
    set_value(page, "graph-speed", "2").await;
    state_shows(page, "move", 10).await;
    page.wait_for("document.getElementById('graph-weights').textContent.includes('move: Walk 0.50 · Run 0.50')", 10)
        .await;
    click(page, "graph-survey").await;
    page.wait_for("document.getElementById('graph-state').textContent.startsWith('move → look')", 10).await;
    state_shows(page, "look", 10).await;
    // The frames were compact: binary messages, decoded in the page.
    let layout = page.eval("window.inbetweenViewer.state.compactLayout?.graph?.states ?? null").await;
    assert_eq!(layout, json!(["idle", "look", "move"]), "the compact layout names the graph's states");
}

const TAIL_TIP: &str = "b_Tail03_014";

/// The server's model-space position of `joint` in the graph `motion` at
/// `time`, with `speed` set at time 0 (the page's paused view: its settings
/// as inputs at 0, at its 30 fps).
async fn graph_pose(app: &crate::common::TestApp, motion: &Value, time: f64, speed: f64, joint: &str) -> Vec<f64> {
    let body = json!({"motion": motion, "time": time, "space": "model", "fps": 30,
                      "inputs": [{"time": 0, "set": {"speed": speed}}]});
    let pose = post_json(app, "/v1/poses", &body).await;
    let joint = pose["joints"].as_array().unwrap().iter().find(|j| j["name"] == joint).unwrap();
    floats(&joint["translation"])
}

/// Waits until the page shows `joint` within 1e-6 of `want` (model space).
async fn shows_at(page: &mut super::cdp::Page, joint: &str, want: &[f64]) {
    page.wait_for(
        &format!(
            "(() => {{ const s = window.inbetweenViewer.state; const p = s.positions[s.names.indexOf({})]; \
             return p && Math.hypot(p[0] - {}, p[1] - {}, p[2] - {}) < 1e-6; }})()",
            json!(joint),
            want[0],
            want[1],
            want[2]
        ),
        10,
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_tail_chain_swings_the_fox_s_tail_on_the_graph_as_the_slider_takes_it_to_a_run() {
    let app = super::start().await;
    let Some((graph, _, mut browser)) = fox_graph_viewer(&app).await else { return };
    let page = &mut browser.page;
    assert_eq!(page.eval("document.getElementById('fps').value").await, json!("30"));

    pick_graph(page, &graph).await;
    state_shows(page, "idle", 10).await;

    // The springs panel stays beside the graph; its chain on the tail goes into the graph's motion.
    assert!(page.eval("document.getElementById('springs-panel').offsetParent !== null").await.as_bool().unwrap());
    page.wait_for("document.getElementById('spring-root').value === 'b_Tail01_012'", 10).await;
    click(page, "spring-add").await;
    let motion = page
        .wait_for("window.inbetweenViewer.panel.motion().springs && window.inbetweenViewer.panel.motion()", 10)
        .await;
    assert_eq!(motion["layers"], json!([{"graph": graph}]), "{motion}");
    assert_eq!(motion["springs"][0]["joints"], json!(["b_Tail01_012", "b_Tail02_013", TAIL_TIP]), "{motion}");

    // Paused at speed 3, 0.9 s in: the server's pose of the graph with the chain, the tail tip off the springless one's.
    let time = 0.9;
    set_value(page, "seek", &time.to_string()).await;
    page.wait_for(&format!("window.inbetweenViewer.state.requestTime === {time}"), 10).await;
    set_value(page, "graph-speed", "3").await; // a new paused pose at the time shown
    state_shows(page, "move", 10).await;
    let sprung = graph_pose(&app, &motion, time, 3.0, TAIL_TIP).await;
    shows_at(page, TAIL_TIP, &sprung).await;
    let keyed = graph_pose(&app, &json!({"layers": [{"graph": graph}]}), time, 3.0, TAIL_TIP).await;
    let swing = sprung.iter().zip(&keyed).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt();
    assert!(swing > 1e-3, "the sprung tail tip is {swing} units from the graph's own");

    // Back to idle, then played: the stream opens (from tick 0) with the chain, and the slider takes the Fox to a run.
    set_value(page, "graph-speed", "0").await;
    state_shows(page, "idle", 10).await;
    // The open messages the page sends, kept as sent.
    page.eval(
        "(() => { window.sentOpens = []; const send = WebSocket.prototype.send; \
         WebSocket.prototype.send = function (m) { \
           if (JSON.parse(m).op === 'open') window.sentOpens.push(JSON.parse(m)); return send.call(this, m); }; \
         return true; })()",
    )
    .await;
    click(page, "play").await;
    page.wait_for("window.inbetweenViewer.state.frames > 0", 10).await;
    let open = page.eval("window.sentOpens[0]").await;
    assert_eq!(open["motion"], motion, "{open}");
    assert_eq!(open["start"], json!(0), "{open}");
    set_value(page, "graph-speed", "2").await;
    state_shows(page, "move", 10).await;
    set_value(page, "graph-speed", "3").await;
    page.wait_for("document.getElementById('graph-weights').textContent === 'move: Run 1.00'", 10).await;
    assert!(
        page.eval("window.inbetweenViewer.state.ws !== null && window.inbetweenViewer.state.playing")
            .await
            .as_bool()
            .unwrap()
    );
    // The header and the composition column name the graph, not the clip whose skeleton it plays on.
    let graph_name = "document.getElementById('now-playing').textContent === 'playing: graph fox-locomotion'";
    page.wait_for(
        &format!("{graph_name} && document.getElementById('playing').textContent === 'playing: graph fox-locomotion'"),
        10,
    )
    .await;
    page.picture("INBETWEEN_GRAPH_SCREENSHOT", std::time::Duration::from_millis(700), 0.7).await;

    // Springs off: the graph plays on without the chain.
    click(page, "springs-on").await;
    page.wait_for("window.sentOpens.length === 2", 10).await;
    let open = page.eval("window.sentOpens[1]").await;
    assert!(open["motion"].get("springs").is_none(), "{open}");
    page.wait_for("window.inbetweenViewer.state.frames > 0 && window.inbetweenViewer.state.playing", 10).await;
}

/// Keeps, from now on, every `open` message the page sends (`window.sentOpens`)
/// and every frame its streams receive (`window.graphFrames`: seq, pose).
async fn record_streams(page: &mut super::cdp::Page) {
    page.eval(
        "(() => { window.sentOpens = []; window.graphFrames = []; const send = WebSocket.prototype.send; \
         WebSocket.prototype.send = function (m) { \
           if (JSON.parse(m).op === 'open') { window.sentOpens.push(JSON.parse(m)); \
             this.addEventListener('message', (e) => { const f = JSON.parse(e.data); \
               if (f.seq !== undefined) window.graphFrames.push({ seq: f.seq, pose: f.pose }); }); } \
           return send.call(this, m); }; return true; })()",
    )
    .await;
}

const FOOT: &str = "b_LeftFoot01_017";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_fox_graph_streams_with_a_root_motion_trail_and_a_foot_handle_picked_beside_it() {
    let app = super::start().await;
    let Some((graph, survey, mut browser)) = fox_graph_viewer(&app).await else { return };
    let page = &mut browser.page;
    pick_graph(page, &graph).await;
    state_shows(page, "idle", 10).await;

    // Only the layer controls step aside: the root row, the character picker and the IK panel stay.
    let shown = "(id => document.getElementById(id).offsetParent !== null)";
    let visible = page
        .eval(&format!(
            "['layers', 'layer-add', 'fade', 'root-mode', 'root-joint', 'character', 'ik-joint', 'ik-add'].map({shown})"
        ))
        .await;
    assert_eq!(visible, json!([false, false, false, true, true, true, true, true]), "{visible}");

    // The joint selects name the graph's output skeleton (its initial state's clip, Survey).
    let skeleton = app.get_json(&format!("/v1/clips/{survey}")).await;
    let joints: Vec<Value> =
        skeleton["skeleton"]["joints"].as_array().unwrap().iter().map(|j| j["name"].clone()).collect();
    let ik_options = page.eval("[...document.getElementById('ik-joint').options].map(o => o.value)").await;
    assert_eq!(ik_options, json!(joints));
    assert_eq!(page.eval("document.getElementById('root-joint').value").await, json!("b_Hip_01"));

    set_value(page, "root-mode", "report").await;
    set_value(page, "ik-joint", FOOT).await;
    page.wait_for("window.inbetweenViewer.state.positions.length > 0", 10).await;
    click(page, "ik-add").await;
    let motion = page.eval("window.inbetweenViewer.panel.motion()").await;
    assert_eq!(motion["layers"], json!([{"graph": graph}]), "{motion}");
    assert_eq!(motion["root_motion"], json!({"mode": "report", "joint": "b_Hip_01"}), "{motion}");
    assert_eq!(motion["ik"][0]["joints"], json!(["b_LeftLeg01_015", "b_LeftLeg02_016", FOOT]), "{motion}");

    record_streams(page).await;
    click(page, "play").await;
    page.wait_for("window.graphFrames.length >= 20 && window.inbetweenViewer.panel.trail.length >= 10", 10).await;
    let open = page.eval("window.sentOpens[0]").await;
    assert_eq!(open["motion"], motion, "the stream opens with the root motion and the handle: {open}");

    // Each frame is the server's sample of that motion at its tick: root motion, IK report and solved foot.
    let frames = page.eval("window.graphFrames.slice(0, 20)").await;
    let frames = frames.as_array().unwrap();
    assert!(
        frames.iter().all(|f| f["pose"]["ik"].as_array().map(Vec::len) == Some(1)),
        "every frame reports the handle"
    );
    frames_are_samples(&app, &open, frames, json!({"speed": 0}), FOOT).await;
    // The trail grows with the frames.
    let trail = page.eval("window.inbetweenViewer.panel.trail.length").await.as_u64().unwrap();
    page.wait_for(&format!("window.inbetweenViewer.panel.trail.length > {trail}"), 10).await;

    // A graph stream's IK is fixed when it opens: removing the handle opens it again without.
    click(page, "ik-remove").await;
    page.wait_for("window.sentOpens.length === 2", 10).await;
    let reopened = page.eval("window.sentOpens[1].motion").await;
    assert_eq!(reopened, json!({"layers": [{"graph": graph}], "root_motion": {"mode": "report", "joint": "b_Hip_01"}}));
    page.wait_for(
        "window.inbetweenViewer.state.playing && !window.inbetweenViewer.panel.lastFrame.pose.ik?.length",
        10,
    )
    .await;
}

/// `got` within 1e-9 of `want`, component by component.
fn assert_close(got: &[f64], want: &[f64], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: {got:?} vs {want:?}");
    assert!(got.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-9), "{what}: {got:?} vs {want:?}");
}

/// The frames' root motion totals and the named joint's translation, tick
/// for tick, against `POST /v1/samples` of the stream's `open` motion from
/// tick 0 with the page's held settings.
async fn frames_are_samples(app: &crate::common::TestApp, open: &Value, frames: &[Value], held: Value, joint: &str) {
    let last = frames.iter().map(|f| f["seq"].as_u64().unwrap()).max().unwrap();
    let body = json!({"motion": open["motion"], "start": 0, "end": last as f64 / 30.0, "fps": 30, "space": open["space"],
                      "inputs": [{"time": 0, "set": held}]});
    let samples = post_json(app, "/v1/samples", &body).await;
    let at = |p: &Value| {
        floats(&p["joints"].as_array().unwrap().iter().find(|j| j["name"] == joint).unwrap()["translation"])
    };
    let total = |p: &Value| floats(&p["root_motion"]["total"]["translation"]);
    for frame in frames {
        let (seq, pose) = (frame["seq"].as_u64().unwrap(), &frame["pose"]);
        let sample = &samples["poses"][seq as usize];
        assert_eq!(total(pose).len(), 3, "tick {seq} carries root motion: {pose}");
        assert_close(&total(pose), &total(sample), &format!("tick {seq}'s root motion"));
        assert_close(&at(pose), &at(sample), &format!("tick {seq}'s {joint}"));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_graph_over_the_cmu_take_walks_a_trail_on_cesium_man() {
    let app = super::start().await;
    let cesium =
        super::character::import(&app, "/v1/characters/import", "gltf/CesiumMan/CesiumMan.gltf", "cesium").await;
    let take = super::character::import(&app, "/v1/clips/import", "bvh/131_01.bvh", "131_01").await;
    let (character, take) = (cesium["id"].as_str().unwrap().to_owned(), take["id"].as_str().unwrap().to_owned());
    let hips = cesium["roles"]["hips"]["joint"].as_str().unwrap().to_owned();
    let doc = json!({"name": "take-walk", "parameters": {"pace": {"type": "float", "default": 0, "min": 0, "max": 1}},
                     "nodes": {"walk": {"clip": take}}, "output": "walk"});
    let resp = app.http.post(app.url("/v1/graphs")).bearer_auth(TOKEN).json(&doc).send().await.unwrap();
    let created: Value = resp.json().await.unwrap();
    let graph = created["id"].as_str().unwrap_or_else(|| panic!("{created}")).to_owned();
    let Some(mut browser) = viewer_on_clip(&app, &take).await else { return };
    let page = &mut browser.page;
    pick_graph(page, &graph).await;

    // On CesiumMan, the joint selects offer its joints, the root its hips.
    let option =
        format!("[...document.getElementById('character').options].some(o => o.value === {})", json!(character));
    page.wait_for(&option, 10).await;
    set_value(page, "character", &character).await;
    let joints = app.get_json(&format!("/v1/characters/{character}")).await["skeleton"]["joints"].clone();
    let names: Vec<Value> = joints.as_array().unwrap().iter().map(|j| j["name"].clone()).collect();
    let ik_joints = "JSON.stringify([...document.getElementById('ik-joint').options].map(o => o.value))";
    page.wait_for(&format!("{ik_joints} === {}", json!(json!(names).to_string())), 10).await;
    assert_eq!(page.eval("[...document.getElementById('root-joint').options].map(o => o.value)").await, json!([hips]));

    set_value(page, "root-mode", "report").await;
    record_streams(page).await;
    click(page, "play").await;
    page.wait_for("window.graphFrames.length >= 20 && window.inbetweenViewer.panel.trail.length >= 10", 10).await;
    let open = page.eval("window.sentOpens[0]").await;
    let want =
        json!({"layers": [{"graph": graph}], "root_motion": {"mode": "report", "joint": hips}, "character": character});
    assert_eq!(open["motion"], want, "{open}");
    let frames = page.eval("window.graphFrames.slice(0, 20)").await;
    frames_are_samples(&app, &open, frames.as_array().unwrap(), json!({"pace": 0}), &hips).await;
    // The take walks: the trail on the ground leaves where it started.
    let walked = "(t => t.length > 1 && Math.hypot(t.at(-1)[0] - t[0][0], t.at(-1)[2] - t[0][2]) > 0.05)";
    page.wait_for(&format!("{walked}(window.inbetweenViewer.panel.trail)"), 10).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_graph_broadcast_made_in_one_tab_is_adopted_by_its_link_in_another_and_driven_from_either() {
    let app = super::start().await;
    let Some((graph, _, mut browser)) = fox_graph_viewer(&app).await else { return };
    let mut second = browser.new_page().await;
    let page = &mut browser.page;
    set_value(page, "token", TOKEN).await; // the write scope, to make and drive a broadcast
    page.eval("document.getElementById('token-form').requestSubmit()").await;
    pick_graph(page, &graph).await;
    set_value(page, "graph-speed", "3").await; // held by the page, then sent to the broadcast it makes
    click(page, "broadcast").await;
    let id = page.wait_for("window.inbetweenViewer.broadcast.id", 10).await.as_str().unwrap().to_owned();
    let made = app.get_json(&format!("/v1/broadcasts/{id}")).await;
    assert_eq!(made["motion"]["layers"], json!([{"graph": graph}]), "{made}");
    // The page's speed reaches the broadcast: its frames report the run.
    page.wait_for("document.getElementById('graph-weights').textContent === 'move: Run 1.00'", 15).await;

    // The link, in a tab that has never picked the graph: it adopts the graph
    // and its controls, and shows the broadcast's reports.
    let link = page.eval("document.getElementById('broadcast-link').value").await.as_str().unwrap().to_owned();
    second.navigate(&link).await;
    let adopted = format!(
        "window.inbetweenViewer.state.graph?.id === {} && document.body.classList.contains('graphing') \
         && document.getElementById('graph').value === {0} && !!document.getElementById('graph-speed')",
        json!(graph)
    );
    second.wait_for(&adopted, 15).await;
    second.wait_for("document.getElementById('graph-weights').textContent === 'move: Run 1.00'", 15).await;
    assert_eq!(second.eval("window.inbetweenViewer.state.watching").await, json!(id));

    // A setting from the first tab changes what both show; the frames are the broadcast's, seq for seq.
    set_value(page, "graph-speed", "2").await;
    for tab in [&mut *page, &mut second] {
        tab.wait_for("document.getElementById('graph-weights').textContent.includes('move: Walk 0.50 · Run 0.50')", 15)
            .await;
    }
    let frames = "Object.fromEntries([...window.inbetweenViewer.broadcast.frames].slice(-30))";
    let (a, b) = (page.eval(frames).await, second.eval(frames).await);
    let (a, b) = (a.as_object().unwrap(), b.as_object().unwrap());
    let common: Vec<&String> = b.keys().filter(|seq| a.contains_key(*seq)).collect();
    assert!(common.len() >= 5, "frames in common: {}", common.len());
    assert!(common.iter().all(|seq| a[*seq] == b[*seq]), "the same seq, the same pose");
    assert!(common.iter().all(|seq| a[*seq]["clip"] == json!(graph)), "the frames are the graph's");
    assert_eq!(second.eval("window.inbetweenViewer.cspViolations").await, json!([]));
}
