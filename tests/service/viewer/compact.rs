//! Compact frames in the viewer (docs/compact-frames.md): the Fox's walk
//! streamed with **frames: compact** is decoded in the page by the
//! JavaScript client's decoder. The pose it shows, paused, is the clip's
//! pose at the shown clip time within the stated bound, and the **rate**
//! readout shows the stream costing several times fewer bytes than the same
//! stream in JSON.

use serde_json::json;

use super::{click, floats, next_frame, set_value, start, text, until_held, viewer_on_clip};

/// The default `max_error`, metres at the default `distance` (docs/compact-frames.md).
const MAX_ERROR: f64 = 1e-4;

/// The bytes per second the page measured, once a second of frames has come.
async fn rate(page: &mut super::cdp::Page) -> f64 {
    page.wait_for("window.inbetweenViewer.state.ws && window.inbetweenViewer.state.seq !== null", 10).await;
    let seq = super::text_number(page, "seq").await;
    next_frame(page, seq + 35.0).await;
    page.eval("window.inbetweenViewer.state.bytesPerSecond").await.as_f64().unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_fox_walks_in_compact_frames_within_the_bound_at_a_fraction_of_the_bytes() {
    let app = start().await;
    let imported = super::import_fox(&app).await;
    let walk = imported["clips"].as_array().unwrap().iter().find(|c| c["name"] == "Walk").unwrap();
    let walk = walk["id"].as_str().unwrap().to_owned();
    let Some(mut browser) = viewer_on_clip(&app, &walk).await else { return };
    let page = &mut browser.page;
    set_value(page, "fps", "30").await;
    set_value(page, "playback", "loop").await;

    click(page, "play").await;
    let json_rate = rate(page).await;
    assert!(text(page, "rate").await.ends_with("B/s"), "{}", text(page, "rate").await);
    set_value(page, "encoding", "compact").await; // the stream opens again, compact
    let compact_rate = rate(page).await;
    eprintln!("the Fox's walk at 30 fps: JSON {json_rate} B/s, compact {compact_rate} B/s");
    assert!(compact_rate * 4.0 < json_rate, "compact {compact_rate} B/s against JSON {json_rate} B/s");

    click(page, "play").await; // pause: the page holds a decoded pose
    until_held(page).await;
    let shown = page.eval("window.inbetweenViewer.state").await;
    let time = shown["clipTime"].as_f64().unwrap();
    let pose = app.get_json(&format!("/v1/clips/{walk}/pose?t={time}&space=model")).await;
    let names: Vec<&str> = shown["names"].as_array().unwrap().iter().map(|n| n.as_str().unwrap()).collect();
    let mut worst: f64 = 0.0;
    for joint in pose["joints"].as_array().unwrap() {
        let k = names.iter().position(|n| *n == joint["name"]).unwrap();
        let (got, want) = (floats(&shown["positions"][k]), floats(&joint["translation"]));
        worst = worst.max(got.iter().zip(&want).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt());
    }
    // The page composes the local pose in f64 from f32 values: a few ULPs of the Fox's size above the bound.
    assert!(worst <= MAX_ERROR * 1.05 + 1e-5, "worst joint {worst} m off the clip's pose at {time}");
    assert_eq!(json!(names.len()), json!(pose["joints"].as_array().unwrap().len()));
}
