//! Pose evaluation over HTTP agrees with the core and with hand-computed values.

use anim::{Clip, Ease, Playback, SampleOptions, Sampler, Space};
use glam::{Mat4, Quat, Vec3};
use serde_json::Value;

use super::{TestApp, WAVE, assert_close};

fn vec(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn wave_clip() -> Clip {
    let (_, spec) = formats::wire::json::parse_clip(WAVE.as_bytes()).unwrap();
    Clip::build(&spec).unwrap()
}

#[tokio::test]
async fn poses_equal_the_core_evaluation_at_many_times() {
    let app = TestApp::start().await;
    let id = app.create(WAVE, None).await["id"].as_str().unwrap().to_owned();
    let clip = wave_clip();
    let mut sampler = Sampler::new();
    for &t in &[0.0, 0.25, 1.0, 1.5, 2.2, 3.0, 4.75, -1.0] {
        for (space, space_name) in [(Space::Local, "local"), (Space::Model, "model")] {
            let url = app.url(&format!("/v1/clips/{id}/pose?t={t}&space={space_name}"));
            let pose: Value = app.http.get(url).send().await.unwrap().json().await.unwrap();
            let options = SampleOptions { playback: None, ease: Ease::Linear, space };
            let clip_time = clip.sample(t, &options, &mut sampler);
            assert_eq!(pose["clip"], id.as_str());
            assert_eq!(pose["space"], space_name);
            assert_eq!(pose["clip_time"].as_f64().unwrap() as f32, clip_time, "clip_time");
            let expected = sampler.pose();
            for (j, joint) in pose["joints"].as_array().unwrap().iter().enumerate() {
                let what = format!("t={t} {space_name} joint {j}");
                let tr = vec(&joint["translation"]);
                let rot = vec(&joint["rotation"]);
                let want_t: Vec<f32> = expected.translations[j].to_array().to_vec();
                let want_r: Vec<f32> = expected.rotations[j].to_array().to_vec();
                assert_eq!(tr.iter().map(|&x| x as f32).collect::<Vec<_>>(), want_t, "{what}");
                assert_eq!(rot.iter().map(|&x| x as f32).collect::<Vec<_>>(), want_r, "{what}");
            }
        }
    }
    app.stop().await;
}

#[tokio::test]
async fn poses_match_hand_computed_keys_and_the_hierarchy() {
    let app = TestApp::start().await;
    let id = app.create(WAVE, None).await["id"].as_str().unwrap().to_owned();
    let get = |q: String| {
        let url = app.url(&format!("/v1/clips/{id}/pose?{q}"));
        let client = app.http.clone();
        async move { client.get(url).send().await.unwrap().json::<Value>().await.unwrap() }
    };
    // Catmull-Rom passes through its keys: root at t=1 is key 1, [1,0,0];
    // the arm at t=1.5 is its middle key (rotation about z by 45°).
    let p = get("t=1".into()).await;
    assert_eq!(vec(&p["joints"][0]["translation"]), [1.0, 0.0, 0.0]);
    let p = get("t=1.5".into()).await;
    let r = vec(&p["joints"][1]["rotation"]);
    for (a, b) in r.iter().zip([0.0, 0.0, 0.382_683_4, 0.923_879_5]) {
        assert_close(*a, b, 1e-6, "arm rotation at 1.5");
    }
    // Model space: arm = root translation + rest offset [0,1,0] (root does not rotate).
    let p = get("t=1&space=model".into()).await;
    let arm = vec(&p["joints"][1]["translation"]);
    for (a, b) in arm.iter().zip([1.0, 1.0, 0.0]) {
        assert_close(*a, b, 1e-6, "arm model translation at 1");
    }
    // Loop playback (the clip's default) wraps: t = 4 is t = 1; `once` clamps to the end.
    assert_eq!(vec(&get("t=4".into()).await["joints"][0]["translation"]), [1.0, 0.0, 0.0]);
    assert_eq!(vec(&get("t=4&playback=once".into()).await["joints"][0]["translation"]), [0.0, 1.0, 0.0]);
    app.stop().await;
}

#[tokio::test]
async fn matrices_agree_with_model_space_trs() {
    let app = TestApp::start().await;
    let id = app.create(WAVE, None).await["id"].as_str().unwrap().to_owned();
    for t in [0.3, 1.1, 2.9] {
        let trs: Value = app.get_json(&format!("/v1/clips/{id}/pose?t={t}&space=model")).await;
        let mats: Value = app.get_json(&format!("/v1/clips/{id}/pose?t={t}&format=matrix")).await;
        assert_eq!(mats["format"], "matrix");
        for (a, b) in trs["joints"].as_array().unwrap().iter().zip(mats["joints"].as_array().unwrap()) {
            let tr = vec(&a["translation"]);
            let r = vec(&a["rotation"]);
            let s = vec(&a["scale"]);
            let expected = Mat4::from_scale_rotation_translation(
                Vec3::new(s[0] as f32, s[1] as f32, s[2] as f32),
                Quat::from_xyzw(r[0] as f32, r[1] as f32, r[2] as f32, r[3] as f32),
                Vec3::new(tr[0] as f32, tr[1] as f32, tr[2] as f32),
            );
            let m = vec(&b["matrix"]);
            for (got, want) in m.iter().zip(expected.to_cols_array()) {
                assert_close(*got, want as f64, 1e-5, &format!("matrix of {} at {t}", a["name"]));
            }
        }
    }
    app.stop().await;
}

#[tokio::test]
async fn sample_returns_one_pose_per_time_or_frame() {
    let app = TestApp::start().await;
    let id = app.create(WAVE, None).await["id"].as_str().unwrap().to_owned();
    let path = format!("/v1/clips/{id}/sample");
    let body: Value = app.post_json(&path, &serde_json::json!({"times": [0, 1, 2], "playback": "once"})).await;
    let poses = body["poses"].as_array().unwrap();
    let root: Vec<Vec<f64>> = poses.iter().map(|p| vec(&p["joints"][0]["translation"])).collect();
    assert_eq!(root, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]]);
    // 0..=1 s at 4 fps: frames at 0, 0.25, 0.5, 0.75, 1.
    let body: Value = app
        .post_json(&path, &serde_json::json!({"start": 0, "end": 1, "fps": 4, "space": "model", "ease": "ease_in_out"}))
        .await;
    let times: Vec<f64> = body["poses"].as_array().unwrap().iter().map(|p| p["time"].as_f64().unwrap()).collect();
    assert_eq!(times, [0.0, 0.25, 0.5, 0.75, 1.0]);
    let clip = wave_clip();
    let expected = clip.clip_time(0.25, Playback::Loop, Ease::EaseInOut);
    assert_eq!(body["poses"][1]["clip_time"].as_f64().unwrap() as f32, expected, "eased clip time");
    assert_eq!(body["poses"][0]["space"], "model");
    app.stop().await;
}

#[tokio::test]
async fn skinning_uses_the_inverse_binds() {
    let app = TestApp::start().await;
    // One joint at rest [0,2,0] with inverse bind = translate(0,-2,0): the
    // skinning matrix at rest is the identity.
    let doc = serde_json::json!({
        "name": "skin",
        "skeleton": {"joints": [{"name": "a", "parent": null, "rest": {"translation": [0, 2, 0]},
            "inverse_bind": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,-2,0,1]}]},
        "tracks": [{"joint": "a", "channel": "scale", "times": [0], "values": [[1, 1, 1]]}]
    });
    let id = app.create(&doc.to_string(), None).await["id"].as_str().unwrap().to_owned();
    let body: Value = app.get_json(&format!("/v1/clips/{id}/pose?t=0&format=skinning")).await;
    assert_eq!(body["format"], "skinning");
    assert_eq!(vec(&body["joints"][0]["matrix"]), Mat4::IDENTITY.to_cols_array().map(f64::from));
    app.stop().await;
}
