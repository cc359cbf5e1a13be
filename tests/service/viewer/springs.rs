//! Springs in the viewer (docs/springs.md): a chain added on the Fox's tail
//! from the springs panel goes into the page's motion, and the paused pose
//! the page shows is the server's pose of that motion (its tail swung by the
//! simulation, away from where the keyed walk puts it); **on** unticked takes
//! the chain out and the keyed tail comes back.

use serde_json::{Value, json};

use super::{click, floats, post_json, set_value, start, viewer_on_clip};

const TAIL_ROOT: &str = "b_Tail01_012";

/// The page's model-space position of `joint`.
async fn shown(page: &mut super::cdp::Page, joint: &str) -> Vec<f64> {
    let state = page.eval("window.inbetweenViewer.state").await;
    let k = state["names"].as_array().unwrap().iter().position(|n| n == joint).unwrap();
    floats(&state["positions"][k])
}

/// The server's model-space position of `joint` in `motion` at `time`.
async fn served(app: &crate::common::TestApp, motion: &Value, time: f64, joint: &str) -> Vec<f64> {
    let pose = post_json(app, "/v1/poses", &json!({"motion": motion, "time": time, "space": "model"})).await;
    let joint = pose["joints"].as_array().unwrap().iter().find(|j| j["name"] == joint).unwrap();
    floats(&joint["translation"])
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_chain_on_the_fox_s_tail_swings_it_as_the_server_simulates_and_off_brings_the_keyed_tail_back() {
    let app = start().await;
    let imported = super::import_fox(&app).await;
    let walk = imported["clips"].as_array().unwrap().iter().find(|c| c["name"] == "Walk").unwrap();
    let walk = walk["id"].as_str().unwrap().to_owned();
    let Some(mut browser) = viewer_on_clip(&app, &walk).await else { return };
    let page = &mut browser.page;

    // The picker offers the tail first (a swingy name); the chain runs down its first children.
    let first = page.wait_for("document.getElementById('spring-root').value", 10).await;
    assert_eq!(first, json!(TAIL_ROOT));
    click(page, "spring-add").await;
    let motion = page
        .wait_for("window.inbetweenViewer.panel.motion().springs && window.inbetweenViewer.panel.motion()", 10)
        .await;
    let chain: Vec<&str> =
        motion["springs"][0]["joints"].as_array().unwrap().iter().map(|j| j.as_str().unwrap()).collect();
    let doc = app.get_json(&format!("/v1/clips/{walk}")).await;
    let parent = |name: &str| {
        doc["skeleton"]["joints"].as_array().unwrap().iter().find(|j| j["name"] == name).unwrap()["parent"].clone()
    };
    assert_eq!(chain[0], TAIL_ROOT);
    assert!(chain.len() >= 3, "{chain:?}");
    for pair in chain.windows(2) {
        assert_eq!(parent(pair[1]), json!(pair[0]), "{chain:?} is a parent-child chain");
    }

    // Paused at 0.5 s: the page shows the server's pose of its motion, the tail tip swung off the keyed one.
    let (time, tip) = (0.5, *chain.last().unwrap());
    set_value(page, "seek", &time.to_string()).await;
    page.wait_for(&format!("window.inbetweenViewer.state.requestTime === {time}"), 10).await;
    let want = served(&app, &motion, time, tip).await;
    page.wait_for(
        &format!(
            "(() => {{ const s = window.inbetweenViewer.state; const p = s.positions[s.names.indexOf({})]; \
             return p && Math.hypot(p[0] - {}, p[1] - {}, p[2] - {}) < 1e-6; }})()",
            json!(tip),
            want[0],
            want[1],
            want[2]
        ),
        10,
    )
    .await;
    let keyed = served(&app, &json!({"layers": [{"clip": walk}]}), time, tip).await;
    let swing = distance(&want, &keyed);
    assert!(swing > 1e-3, "the simulated tail tip is {swing} m from the keyed one");

    // Off: the motion carries no springs and the keyed tail is shown again.
    click(page, "springs-on").await;
    page.wait_for("!window.inbetweenViewer.panel.motion().springs", 10).await;
    page.wait_for(
        &format!(
            "(() => {{ const s = window.inbetweenViewer.state; const p = s.positions[s.names.indexOf({})]; \
             return Math.hypot(p[0] - {}, p[1] - {}, p[2] - {}) < 1e-6; }})()",
            json!(tip),
            keyed[0],
            keyed[1],
            keyed[2]
        ),
        10,
    )
    .await;
    assert!(distance(&shown(page, tip).await, &keyed) < 1e-6);
}
