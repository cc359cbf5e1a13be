//! The page keeps up: a 994-key CMU mocap take (131_01, 120 Hz) streamed at
//! 60 fps, its longest curve plotted, WebGL in software, and the lateness
//! the page itself shows (from the server sending a frame to the page
//! drawing it) stays under 100 ms. Before the render loop the page fell
//! seconds behind on such a take, and further behind every second.
//!
//! The default suite, often beside compilers on 2 cores, checks the median
//! and that the page is not behind at the end; the bound on nine readings
//! in ten is checked with `INBETWEEN_SLOW=1`, which `.ci/run` runs alone.

use serde_json::Value;

use super::{TOKEN, select_clip, set_value, start, text};
use crate::common::{latency_checked, within};

/// Lateness the page may show while it keeps up (ms): in nine readings of
/// ten on a quiet machine, in half of them on a loaded one.
const KEEPS_UP_MS: f64 = 100.0;
/// Lateness no reading may reach: a page that fell behind, as before the
/// render loop, shows seconds and grows. A single reading between the two is
/// a stall of the machine (2 cores shared with compilers in CI), not the page.
const NEVER_MS: f64 = 1000.0;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_long_mocap_curve_plays_without_falling_behind() {
    let app = start().await;
    let bvh = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/bvh/131_01.bvh")).unwrap();
    let imported = app
        .http
        .post(app.url("/v1/clips/import?format=bvh"))
        .bearer_auth(TOKEN)
        .header("content-type", "application/octet-stream")
        .body(bvh)
        .send()
        .await
        .unwrap();
    assert_eq!(imported.status(), 201);
    let imported: Value = imported.json().await.unwrap();
    let id = imported["clips"][0]["id"].as_str().unwrap().to_owned();
    let doc: Value = app.http.get(app.url(&format!("/v1/clips/{id}"))).send().await.unwrap().json().await.unwrap();
    let hips = doc["tracks"].as_array().unwrap().iter().find(|t| t["channel"] == "rotation").unwrap();
    let keys = hips["times"].as_array().unwrap().len();
    assert_eq!(keys, 994, "the take's frames, one key each");

    let Some(mut browser) = super::cdp::Browser::launch_alone().await else { return };
    let page = &mut browser.page;
    page.navigate(&app.url("/viewer")).await;
    select_clip(page, &id).await;
    // The rate first: a new rate reloads the curve, and the draws are counted from the last load on.
    set_value(page, "fps", "60").await;
    let joint = hips["joint"].as_str().unwrap();
    set_value(page, "curve-joint", joint).await;
    set_value(page, "curve-channel", "rotation").await;
    // The rotation curve, not the translation one (as many keys) still shown until it comes.
    let plotted = format!(
        "window.inbetweenViewer.curve?.channel === 'rotation' && window.inbetweenViewer.curve.keys.length === {keys}"
    );
    page.wait_for(&plotted, 10).await;
    page.eval("document.getElementById('play').click()").await;
    page.wait_for("window.inbetweenViewer.state.frames >= 30", 10).await;
    let layer_draws = page.eval("window.inbetweenViewer.state.curveLayerDraws").await;

    // Four seconds of playing, read every 100 ms as a person reads the readout.
    let mut shown = vec![];
    within(20 * super::cdp::PATIENCE, "four seconds of lateness readings", async {
        for _ in 0..40 {
            let late = text(page, "late").await;
            let ms: f64 =
                late.strip_suffix(" ms").and_then(|n| n.parse().ok()).unwrap_or_else(|| panic!("late: {late}"));
            shown.push(ms);
            tokio::time::sleep(std::time::Duration::from_millis(100)).await;
        }
    })
    .await;
    let mut sorted = shown.clone();
    sorted.sort_by(f64::total_cmp);
    let at = |share: f64| sorted[((sorted.len() as f64 * share) as usize).saturating_sub(1)];
    // The last second, whatever came before it: a page that fell behind stays behind.
    let mut last_second = shown[30..].to_vec();
    last_second.sort_by(f64::total_cmp);
    let (median, last) = (at(0.5), last_second[4]);
    assert!(median < KEEPS_UP_MS, "the page was {median} ms behind in half the readings: {shown:?}");
    assert!(last < NEVER_MS, "the page was {last} ms behind in half the last second: {shown:?}");
    let (p90, worst) = (at(0.9), at(1.0));
    if latency_checked() {
        // The bound of the quiet run (.ci/run runs it alone): nine readings in ten, and every one.
        assert!(p90 < KEEPS_UP_MS, "the page fell {p90} ms behind in a tenth of the readings: {shown:?}");
        assert!(worst < NEVER_MS, "the page fell {worst} ms behind: {shown:?}");
        let mean: f64 = shown[30..].iter().sum::<f64>() / 10.0;
        assert!(mean < KEEPS_UP_MS, "lateness over the last second averaged {mean} ms: {shown:?}");
    }
    let frames = page.eval("window.inbetweenViewer.state.frames").await.as_f64().unwrap();
    assert!(frames >= 150.0, "frames kept coming at 60 fps: {frames}");
    // The 994 keys were drawn once: playing moves only the playhead's layer.
    assert_eq!(page.eval("window.inbetweenViewer.state.curveLayerDraws").await, layer_draws);
    eprintln!(
        "lateness shown over 4 s at 60 fps: 90th percentile {p90} ms, worst {worst} ms, of {} readings",
        shown.len()
    );
}
