//! The curves panel in the browser: rotations as Euler angles in each order
//! (checked by composing the shown angles back into the rotation, in f64),
//! parameters plotted from the same samples as REST, and cubic Hermite
//! tangents drawn as the handles docs/clip-format.md §2.5's segment implies.

use serde_json::{Value, json};

use super::cdp::Page;
use super::{TOKEN, floats, post_json, set_value, start, viewer_on_clip};

/// Selects a curve and waits until the panel shows it (`euler`: an order, or "quaternion").
async fn show_curve(page: &mut Page, joint: &str, channel: &str, euler: &str) -> Value {
    set_value(page, "curve-joint", joint).await;
    set_value(page, "curve-channel", channel).await;
    set_value(page, "curve-rotation", euler).await;
    let wanted = if channel == "rotation" && euler != "quaternion" { json!(euler) } else { json!(null) };
    page.wait_for(
        &format!(
            "(c => c && c.joint === {} && c.channel === {} && c.euler === {} && c)(window.inbetweenViewer.curve)",
            json!(joint),
            json!(channel),
            wanted
        ),
        10,
    )
    .await
}

type M3 = [[f64; 3]; 3];

fn mul(a: &M3, b: &M3) -> M3 {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

/// The rotation by `deg` degrees about axis 0 (x), 1 (y) or 2 (z).
fn axis(i: usize, deg: f64) -> M3 {
    let (s, c) = deg.to_radians().sin_cos();
    let (j, k) = ((i + 1) % 3, (i + 2) % 3);
    let mut m = [[0.0; 3]; 3];
    m[i][i] = 1.0;
    (m[j][j], m[j][k], m[k][j], m[k][k]) = (c, -s, s, c);
    m
}

fn from_quat([x, y, z, w]: [f64; 4]) -> M3 {
    [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
        [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
        [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
    ]
}

/// The quaternion of a rotation matrix with a positive trace.
fn to_quat(m: &M3) -> [f64; 4] {
    let w = (1.0 + m[0][0] + m[1][1] + m[2][2]).sqrt() / 2.0;
    [(m[2][1] - m[1][2]) / (4.0 * w), (m[0][2] - m[2][0]) / (4.0 * w), (m[1][0] - m[0][1]) / (4.0 * w), w]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rotations_show_as_euler_angles_in_the_chosen_order() {
    let app = start().await;
    // Key 1 is Rz(30°)·Ry(20°)·Rx(10°): X applied first, so "XYZ" shows (10, 20, 30).
    let q = to_quat(&mul(&axis(2, 30.0), &mul(&axis(1, 20.0), &axis(0, 10.0))));
    let clip = json!({"name": "turn", "tracks": [{"joint": "j", "channel": "rotation", "interpolation": "linear",
        "times": [0, 1], "values": [[0, 0, 0, 1], q]}]});
    let id = app.create_id(&clip.to_string(), Some(TOKEN)).await;
    let Some(mut browser) = viewer_on_clip(&app, &id).await else { return };
    let page = &mut browser.page;

    let curve = show_curve(page, "j", "rotation", "XYZ").await;
    let key = floats(&curve["keys"][1]["value"]);
    for (shown, want) in key.iter().zip([10.0, 20.0, 30.0]) {
        assert!((shown - want).abs() < 1e-4, "XYZ angles {key:?}");
    }
    // Every order's angles, composed back in that order, are the key's rotation.
    let want = from_quat(q);
    for order in ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"] {
        let curve = show_curve(page, "j", "rotation", order).await;
        let angles = floats(&curve["keys"][1]["value"]);
        let mut m = axis(0, 0.0);
        for c in order.chars() {
            let i = "XYZ".find(c).unwrap();
            m = mul(&axis(i, angles[i]), &m); // each later axis applied on the left
        }
        for (r, w) in m.iter().flatten().zip(want.iter().flatten()) {
            assert!((r - w).abs() < 1e-5, "{order}: {angles:?} composes to {m:?}, not {want:?}");
        }
        assert_eq!(floats(&curve["values"][0]), [0.0, 0.0, 0.0], "{order}: identity at the start");
        assert_eq!(curve["values"].as_array().unwrap()[0].as_array().unwrap().len(), 3);
    }
    let curve = show_curve(page, "j", "rotation", "quaternion").await;
    assert_eq!(curve["values"][0].as_array().unwrap().len(), 4);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn parameters_are_plotted_for_the_face_example() {
    let app = start().await;
    let id = app.create_id(include_str!("../../../examples/face.json"), Some(TOKEN)).await;
    let Some(mut browser) = viewer_on_clip(&app, &id).await else { return };
    let page = &mut browser.page;
    let options = page.eval("[...document.getElementById('curve-joint').options].map(o => o.value)").await;
    assert_eq!(options, json!(["head", "param:face_mesh", "param:camera_fov"]));

    for (name, width, keys) in [("face_mesh", 2, 5), ("camera_fov", 1, 3)] {
        let curve = show_curve(page, &format!("param:{name}"), "value", "XYZ").await;
        let times: Vec<f64> = serde_json::from_value(curve["times"].clone()).unwrap();
        assert!(times.len() > 100, "{} points", times.len());
        let rest =
            post_json(&app, &format!("/v1/clips/{id}/sample"), &json!({"times": times, "playback": "once"})).await;
        for (i, pose) in rest["poses"].as_array().unwrap().iter().enumerate() {
            assert_eq!(floats(&curve["values"][i]), floats(&pose["parameters"][name]), "{name} at {}", times[i]);
            assert_eq!(curve["values"][i].as_array().unwrap().len(), width);
        }
        assert_eq!(curve["keys"].as_array().unwrap().len(), keys, "{name}");
    }
    let curve = show_curve(page, "param:face_mesh", "value", "XYZ").await;
    assert_eq!(floats(&curve["keys"][3]["value"]), [0.0, 1.0], "the key at t = 1");
    assert_eq!(page.eval("document.getElementById('rotation-as').hidden").await, true);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cubic_hermite_tangents_are_drawn_as_handles() {
    let app = start().await;
    let clip = json!({"name": "hermite", "tracks": [{"joint": "j", "channel": "translation",
        "interpolation": "cubic_hermite", "times": [0, 2], "values": [[0, 0, 0], [1, 2, 3]],
        "in_tangents": [[0, 0, 0], [1, 1, 1]], "out_tangents": [[3, 0, 0], [0, 0, 0]]}]});
    let id = app.create_id(&clip.to_string(), Some(TOKEN)).await;
    let Some(mut browser) = viewer_on_clip(&app, &id).await else { return };
    let page = &mut browser.page;
    let curve = show_curve(page, "j", "translation", "XYZ").await;
    // Segment of h = 2 s: out of key 0 at (2/3, v0 + b0·2/3), into key 1 at (2 - 2/3, v1 - a1·2/3).
    let handles = &curve["tangents"];
    assert_eq!(handles[0]["in"], Value::Null);
    assert_eq!(handles[1]["out"], Value::Null);
    let close = |got: &Value, want: &[f64]| {
        let got = floats(got);
        got.len() == want.len() && got.iter().zip(want).all(|(g, w)| (g - w).abs() < 1e-9)
    };
    assert!(close(&json!([handles[0]["out"]["time"]]), &[2.0 / 3.0]), "{handles}");
    assert!(close(&handles[0]["out"]["value"], &[2.0, 0.0, 0.0]), "{handles}");
    assert!(close(&json!([handles[1]["in"]["time"]]), &[4.0 / 3.0]), "{handles}");
    assert!(close(&handles[1]["in"]["value"], &[1.0 / 3.0, 4.0 / 3.0, 7.0 / 3.0]), "{handles}");
}
