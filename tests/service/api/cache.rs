//! The compiled-clip cache: bounded, write-through, shared misses.

use std::sync::Arc;

use super::{TestApp, uniform_clip};

#[tokio::test]
async fn concurrent_misses_share_one_load_and_the_cache_stays_bounded() {
    let app = TestApp::builder().configure(|c| c.limits.cache_entries = 2).start().await;
    let mut ids = Vec::new();
    for k in 0..4 {
        ids.push(
            app.create(&uniform_clip(&format!("v{k}"), 3, 4, k as f32), None).await["id"].as_str().unwrap().to_owned(),
        );
    }
    // Write-through filled the cache with the last two; the first two were evicted.
    assert_eq!(app.state.cache.len(), 2);
    assert!(app.state.cache.get(&ids[0]).is_none());

    let loads = (0..16).map(|_| app.state.clip(&ids[0]));
    let clips = futures_util::future::join_all(loads).await;
    let first = clips[0].as_ref().unwrap();
    assert_eq!(first.meta.name, "v0");
    for c in &clips {
        assert!(Arc::ptr_eq(first, c.as_ref().unwrap()), "each miss compiled its own copy");
    }
    assert_eq!(app.state.cache.len(), 2);
    assert!(Arc::ptr_eq(first, &app.state.cache.get(&ids[0]).unwrap()), "the loaded clip was cached");

    // Every clip still answers poses, whatever was evicted.
    for (k, id) in ids.iter().enumerate() {
        let pose: serde_json::Value = app.get_json(&format!("/v1/clips/{id}/pose?t=1")).await;
        assert_eq!(pose["joints"][2]["translation"], serde_json::json!([k as f32, k as f32, k as f32]));
    }
    app.stop().await;
}

#[tokio::test]
async fn a_cached_pose_needs_no_store_round_trip() {
    let app = TestApp::start().await;
    let id = app.create(&uniform_clip("v7", 2, 2, 7.0), None).await["id"].as_str().unwrap().to_owned();
    app.state.store.close().await; // from here on, any store access fails with 503
    let pose = app.http.get(app.url(&format!("/v1/clips/{id}/pose?t=0.5"))).send().await.unwrap();
    assert_eq!(pose.status(), 200, "the pose came from the write-through cache");
    let sample = app
        .http
        .post(app.url(&format!("/v1/clips/{id}/sample")))
        .json(&serde_json::json!({"times": [0, 1]}))
        .send()
        .await
        .unwrap();
    assert_eq!(sample.status(), 200);
    let get = app.http.get(app.url(&format!("/v1/clips/{id}"))).send().await.unwrap();
    assert_eq!(get.status(), 503, "the document itself does come from the store");
    app.stop().await;
}
