//! The motion cache, seen from outside: one process of the real binary (so
//! its `/metrics` counts only this test's requests), a composition asked
//! for again is found built, a replaced clip is built again at its new
//! version, the bound holds, a deleted clip is 404. And, in process, that a
//! cached motion never keeps alive a clip the clip cache let go.

use std::sync::Arc;

use serde_json::{Value, json};

use crate::common::{ServerProcess, TestApp, assert_close, metric};

/// `hips` moving along x from 0 to `to` over 1 s (looping), `arm` above it.
fn walk(name: &str, to: f32) -> String {
    crate::common::hips_mover(name, to, 1.0, "loop")
}

struct Server {
    process: ServerProcess,
    http: reqwest::Client,
}

impl Server {
    async fn write(&self, method: reqwest::Method, path: &str, doc: &str) -> Value {
        let resp = self
            .http
            .request(method, self.process.url(path))
            .header("content-type", "application/json")
            .body(doc.to_owned())
            .send()
            .await
            .unwrap();
        assert!(resp.status().is_success(), "{path}: {}", resp.status());
        resp.json().await.unwrap()
    }

    /// `POST /v1/poses` at t = 0.5 in model space: the status and the answer.
    async fn pose(&self, motion: &Value, extra: &Value) -> (u16, Value) {
        let mut body = json!({"motion": motion, "time": 0.5, "space": "model"});
        body.as_object_mut().unwrap().extend(extra.as_object().unwrap().clone());
        let resp = self.http.post(self.process.url("/v1/poses")).json(&body).send().await.unwrap();
        (resp.status().as_u16(), resp.json().await.unwrap())
    }

    /// The hips' x of a full pose of `motion`.
    async fn hips_x(&self, motion: &Value) -> f64 {
        let (status, pose) = self.pose(motion, &json!({})).await;
        assert_eq!(status, 200, "{pose}");
        pose["joints"][0]["translation"][0].as_f64().unwrap()
    }

    /// (hits, misses, entries) of the motion cache on `/metrics`.
    async fn counts(&self) -> (f64, f64, f64) {
        let text = self.http.get(self.process.url("/metrics")).send().await.unwrap().text().await.unwrap();
        let read = |name: &str| metric(&text, name).unwrap_or_else(|| panic!("{name} in\n{text}"));
        (
            read("inbetween_motion_cache_hits_total"),
            read("inbetween_motion_cache_misses_total"),
            read("inbetween_motion_cache_entries"),
        )
    }
}

#[tokio::test]
async fn a_repeated_composition_is_built_once_and_a_replaced_clip_is_built_again() {
    let dir = tempfile::tempdir().unwrap();
    let process = ServerProcess::serve().data_dir(dir.path()).env("INBETWEEN_MOTION_CACHE_ENTRIES", "2").start().await;
    let server = Server { process, http: crate::common::http_client() };
    let walk_id = server.write(reqwest::Method::POST, "/v1/clips", &walk("walk", 2.0)).await["id"].clone();
    let run_id = server.write(reqwest::Method::POST, "/v1/clips", &walk("run", 6.0)).await["id"].clone();
    let blend = |run_weight: f32| json!({"layers": [{"clip": walk_id}, {"clip": run_id, "weight": run_weight}]});
    assert_eq!(server.counts().await, (0.0, 0.0, 0.0));

    // At t = 0.5 walk's hips are at x = 1, run's at 3: 0.75·1 + 0.25·3 = 1.5.
    assert_close(server.hips_x(&blend(0.25)).await, 1.5, 1e-6, "first ask");
    assert_eq!(server.counts().await, (0.0, 1.0, 1.0), "built once and kept");
    assert_close(server.hips_x(&blend(0.25)).await, 1.5, 1e-6, "asked again");
    assert_eq!(server.counts().await, (1.0, 1.0, 1.0), "found built");
    // Another subset, space and format is the same motion.
    let (status, arm) = server.pose(&blend(0.25), &json!({"joints": ["arm"], "format": "matrix"})).await;
    assert_eq!((status, arm["joints"].as_array().map(Vec::len)), (200, Some(1)), "{arm}");
    assert_eq!(server.counts().await, (2.0, 1.0, 1.0), "the subset is not part of the key");
    // Another weight is another motion: 0.5·1 + 0.5·3 = 2.
    assert_close(server.hips_x(&blend(0.5)).await, 2.0, 1e-6, "another weight");
    assert_eq!(server.counts().await, (2.0, 2.0, 2.0));

    // Run replaced (now 0 → 10: x = 5 at t = 0.5): both motions over it go,
    // and the next pose is built on the new version: 0.75·1 + 0.25·5 = 2.
    server.write(reqwest::Method::PUT, &format!("/v1/clips/{}", run_id.as_str().unwrap()), &walk("run", 10.0)).await;
    assert_eq!(server.counts().await, (2.0, 2.0, 0.0), "the replace dropped the motions over the old version");
    assert_close(server.hips_x(&blend(0.25)).await, 2.0, 1e-6, "after the replace");
    assert_eq!(server.counts().await, (2.0, 3.0, 1.0));
    assert_close(server.hips_x(&blend(0.25)).await, 2.0, 1e-6, "the new version, found built");
    assert_eq!(server.counts().await, (3.0, 3.0, 1.0));

    // The bound (2): a third motion evicts the least recently used.
    assert_close(server.hips_x(&blend(0.5)).await, 0.5 + 2.5, 1e-6, "0.5·1 + 0.5·5");
    assert_close(server.hips_x(&json!({"layers": [{"clip": walk_id}]})).await, 1.0, 1e-6, "walk alone");
    assert_eq!(server.counts().await, (3.0, 5.0, 2.0));
    assert_close(server.hips_x(&blend(0.25)).await, 2.0, 1e-6, "evicted, built again");
    assert_eq!(server.counts().await, (3.0, 6.0, 2.0));

    // Run deleted: 404, and only walk's own motion is left.
    let resp = server.http.delete(server.process.url(&format!("/v1/clips/{}", run_id.as_str().unwrap()))).send();
    assert_eq!(resp.await.unwrap().status(), 204);
    let (status, problem) = server.pose(&blend(0.25), &json!({})).await;
    assert_eq!((status, problem["code"].as_str()), (404, Some("clip_not_found")), "{problem}");
    assert_eq!(server.counts().await, (3.0, 6.0, 1.0));
}

/// `POST /v1/poses` of `motion` on an in-process app: the hips' x.
async fn hips_x(app: &TestApp, motion: &Value) -> f64 {
    let pose = app.post_json("/v1/poses", &json!({"motion": motion, "time": 0.5})).await;
    pose["joints"][0]["translation"][0].as_f64().unwrap_or_else(|| panic!("{pose}"))
}

#[tokio::test]
async fn an_evicted_clip_takes_its_motions_with_it_and_is_freed() {
    let app = TestApp::builder().configure(|c| c.limits.cache_entries = 2).start().await;
    let (walk_id, run_id) =
        (app.create_id(&walk("walk", 2.0), None).await, app.create_id(&walk("run", 6.0), None).await);
    let blend = json!({"layers": [{"clip": walk_id}, {"clip": run_id, "weight": 0.25}]});
    assert_close(hips_x(&app, &blend).await, 1.5, 1e-6, "0.75·1 + 0.25·3");
    assert_close(hips_x(&app, &json!({"layers": [{"clip": walk_id}]})).await, 1.0, 1e-6, "walk alone");
    assert_eq!(app.state.motions.len(), 2);
    let run = Arc::downgrade(&app.state.cache.get(&run_id).unwrap());
    app.state.cache.get(&walk_id); // run is now the least recently used clip

    // A third clip evicts run from the clip cache: the blend over it goes
    // too, so nothing holds run's compiled clip any more.
    app.create_id(&walk("other", 1.0), None).await;
    assert!(app.state.cache.get(&run_id).is_none(), "run was evicted");
    assert_eq!(app.state.motions.len(), 1, "only walk's own motion is left");
    assert!(run.upgrade().is_none(), "the evicted clip was freed, not kept alive by a cached motion");
    assert_close(hips_x(&app, &blend).await, 1.5, 1e-6, "the blend, built again");
    app.stop().await;
}

#[tokio::test]
async fn a_motion_over_a_clip_too_large_to_cache_is_not_cached_either() {
    let app = TestApp::builder().configure(|c| c.limits.cache_bytes = 1).start().await;
    let id = app.create_id(&walk("walk", 2.0), None).await;
    for _ in 0..2 {
        assert_close(hips_x(&app, &json!({"layers": [{"clip": id}]})).await, 1.0, 1e-6, "from the store each time");
    }
    assert!(app.state.cache.is_empty() && app.state.motions.is_empty());
    app.stop().await;
}

/// `inbetween_stream_playbacks_total` of `server`.
async fn playbacks(server: &Server) -> f64 {
    let text = server.http.get(server.process.url("/metrics")).send().await.unwrap().text().await.unwrap();
    metric(&text, "inbetween_stream_playbacks_total").unwrap_or(0.0)
}

/// Opens `GET /v1/stream` on `motion` at 1 fps and reads its first frame's seq.
async fn first_frame(server: &Server, motion: &Value) -> u64 {
    use futures_util::{SinkExt, StreamExt};
    use tokio_tungstenite::tungstenite::Message;
    let (mut ws, _) = tokio_tungstenite::connect_async(server.process.ws_url("/v1/stream")).await.unwrap();
    let open = json!({"op": "open", "motion": motion, "fps": 1, "max_frames": 1});
    ws.send(Message::Text(open.to_string().into())).await.unwrap();
    loop {
        let Some(Ok(Message::Text(text))) = crate::common::within(5, "a message", ws.next()).await else {
            panic!("the stream ended early")
        };
        let v: Value = serde_json::from_str(&text).unwrap();
        if let Some(seq) = v["seq"].as_u64() {
            return seq;
        }
        assert!(v.get("opened").is_some(), "{v}");
    }
}

#[tokio::test]
async fn viewers_of_one_composition_share_a_playback_and_another_composition_has_its_own() {
    let dir = tempfile::tempdir().unwrap();
    let process = ServerProcess::serve().data_dir(dir.path()).start().await;
    let server = Server { process, http: crate::common::http_client() };
    let walk_id = server.write(reqwest::Method::POST, "/v1/clips", &walk("walk", 2.0)).await["id"].clone();
    let run_id = server.write(reqwest::Method::POST, "/v1/clips", &walk("run", 6.0)).await["id"].clone();
    let blend = |run_weight: f32| json!({"layers": [{"clip": walk_id}, {"clip": run_id, "weight": run_weight}]});
    // Viewers opening within one 1 s tick of each other join the first one's
    // playback (the cached motion is one program); a tick falling between two
    // opens splits them, so a few tries are allowed.
    let mut shared = false;
    for _ in 0..3 {
        let before = playbacks(&server).await;
        let motion = blend(0.25);
        let seqs = futures_util::future::join_all((0..3).map(|_| first_frame(&server, &motion))).await;
        if playbacks(&server).await - before == 1.0 {
            assert_eq!(seqs, [0, 0, 0], "every viewer of a shared playback sees its frame 0");
            shared = true;
            break;
        }
    }
    assert!(shared, "three viewers of one composition never shared a playback");
    let before = playbacks(&server).await;
    let (a, b) = (blend(0.25), blend(0.5));
    futures_util::future::join(first_frame(&server, &a), first_frame(&server, &b)).await;
    assert_eq!(playbacks(&server).await - before, 2.0, "another weight is another playback");
}
