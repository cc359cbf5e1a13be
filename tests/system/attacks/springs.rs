//! Spring chains as a lever (docs/springs.md, “Cost”): one chain down a
//! 4,096-joint body with 64 colliders at 1,000 substeps per second is
//! 4,094 × 64 collider tests per substep, 1,000 substeps of warmup per
//! pose. Its price counts substeps × joints × colliders, so the pose and
//! the broadcast are refused before anything is simulated, and the prober
//! stays within its budget while an attacker keeps asking.

use std::time::{Duration, Instant};

use futures_util::future::join_all;
use serde_json::{Value, json};

use super::target;
use crate::common::chain_clip;

/// The heaviest chains a document may carry on the 4,096-joint chain clip.
fn heavy_springs() -> Value {
    let joints: Vec<String> = (1..4096).map(|j| format!("j{j}")).collect();
    let sphere = json!({"joint": "j0", "sphere": {"offset": [0, 0, 0], "radius": 0.001}});
    json!([{"name": "whip", "joints": joints, "colliders": vec![sphere; 64]}])
}

#[tokio::test(flavor = "multi_thread")]
async fn heavy_spring_chains_are_refused_by_their_price() {
    let mut target = target(&[]).await;
    let http = crate::common::http_client();
    let id = target.server.create(&http, &chain_clip(4096, json!([]))).await;
    let motion = json!({"layers": [{"clip": id}], "springs": heavy_springs(), "spring_substep_hz": 1000});
    let body = json!({"motion": motion, "time": 0.5}).to_string();
    // A light version of the same chains is served: the price, not the shape, refuses.
    let light = json!({"layers": [{"clip": id}],
                       "springs": [{"name": "tip", "joints": ["j4094", "j4095"]}]});
    let resp = http.post(target.server.url("/v1/poses")).json(&json!({"motion": light, "time": 0.5})).send().await;
    assert_eq!(resp.unwrap().status(), 200, "a two-joint chain is affordable");
    // The first refusal builds the motion (a miss of the motion cache), the
    // chain compiled in linear time; the attackers' then hit the cache.
    let resp = http.post(target.server.url("/v1/poses")).header("content-type", "application/json");
    let first = resp.body(body.clone()).send().await.unwrap();
    assert_eq!(first.status(), 422);
    let probes = target.probes().await;
    let until = Instant::now() + Duration::from_secs(2);
    let attacker = |http: reqwest::Client, url: String, body: String| async move {
        let mut refusals = 0u32;
        while Instant::now() < until {
            let resp = http.post(&url).header("content-type", "application/json").body(body.clone()).send().await;
            let resp = resp.unwrap();
            assert_eq!(resp.status(), 422);
            let problem: Value = resp.json().await.unwrap();
            assert_eq!(problem["code"], "too_much_work", "{problem}");
            refusals += 1;
        }
        refusals
    };
    let url = target.server.url("/v1/poses");
    let refusals: u32 = join_all((0..4).map(|_| attacker(http.clone(), url.clone(), body.clone()))).await.iter().sum();
    // A broadcast of the same motion is refused at its creation, priced per second.
    let broadcast = json!({"motion": motion, "fps": 60});
    let resp = http.post(target.server.url("/v1/broadcasts")).json(&broadcast).send().await.unwrap();
    let status = resp.status().as_u16();
    let problem: Value = resp.json().await.unwrap();
    assert_eq!((status, problem["code"].as_str()), (422, Some("too_much_work")), "{problem}");
    let report = probes.finish();
    println!("FIGURE {refusals} refusals of a 4,095-joint, 64-collider spring chain at 1,000 Hz in 2 s");
    assert!(refusals >= 20, "only {refusals} refusals in 2 s: springs were simulated before refusing");
    target.assert_survived("heavy spring chains", &report);
}
