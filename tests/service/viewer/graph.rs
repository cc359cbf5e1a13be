//! A graph played in the viewer (docs/graphs.md): the Fox's locomotion
//! graph picked in the graph panel, then, while it streams, the speed slider
//! dragged and the trigger pressed. The page sends `set` controls; the
//! frames' reports take the graph from `idle` through the fade to `move`,
//! with the weights the blend's definition gives for the speed set, and the
//! trigger to `look`; the panel shows each.

use serde_json::json;

use super::{click, set_value, text, viewer_on_clip};
use crate::api::graph_samples::fox_graph_as;

/// Waits until the panel's state line says `want`.
async fn state_shows(page: &mut super::cdp::Page, want: &str, seconds: u64) {
    page.wait_for(&format!("document.getElementById('graph-state').textContent === {}", json!(want)), seconds).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_speed_slider_takes_the_fox_from_idle_to_a_run_and_the_trigger_to_a_look() {
    let app = super::start().await;
    let (graph, _) = fox_graph_as(&app, Some(super::TOKEN)).await;
    let listed = app.get_json("/v1/graphs").await;
    let summary = listed["graphs"].as_array().unwrap().iter().find(|g| g["id"] == json!(graph)).unwrap();
    let survey = summary["clips"][0].as_str().unwrap().to_owned();
    let Some(mut browser) = viewer_on_clip(&app, &survey).await else { return };
    let page = &mut browser.page;

    let option = format!("[...document.getElementById('graph').options].some(o => o.value === {})", json!(graph));
    page.wait_for(&option, 10).await;
    set_value(page, "graph", &graph).await;
    page.wait_for("document.body.classList.contains('graphing') && document.getElementById('graph-speed')", 10).await;
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
