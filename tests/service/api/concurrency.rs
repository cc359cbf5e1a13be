//! 50 concurrent writers and readers on overlapping clips: every read sees a
//! whole version, and versions (ETags) only go up.

use std::collections::HashMap;

use serde_json::Value;

use super::{TestApp, canonical, uniform_clip};

const CLIPS: usize = 3;
const WRITERS: usize = 20;
const READERS: usize = 30;
const WRITES_EACH: usize = 5;
const READS_EACH: usize = 12;

/// The `k` of a document made by `uniform_clip("v{k}", 2, 2, k)`, checking
/// that every value in it agrees (a torn write would mix two `k`s).
fn whole_version(doc: &Value) -> f64 {
    let name = doc["name"].as_str().unwrap();
    let k: f64 = name.trim_start_matches('v').parse().unwrap();
    for track in doc["tracks"].as_array().unwrap() {
        for v in track["values"].as_array().unwrap() {
            for x in v.as_array().unwrap() {
                assert_eq!(x.as_f64().unwrap(), k, "document {name} mixes versions");
            }
        }
    }
    k
}

fn version_of(resp: &reqwest::Response) -> u64 {
    resp.headers()["etag"].to_str().unwrap().trim_matches('"').parse().unwrap()
}

async fn writer(app: &TestApp, ids: &[String], w: usize) -> Vec<(usize, u64, String)> {
    let mut done = Vec::new();
    for i in 0..WRITES_EACH {
        let c = (w + i) % ids.len();
        let k = (w * 100 + i + 1) as f32;
        let body = uniform_clip(&format!("v{k}"), 2, 2, k);
        let resp = app
            .http
            .put(app.url(&format!("/v1/clips/{}", ids[c])))
            .header("content-type", "application/json")
            .body(body.clone())
            .send()
            .await
            .unwrap();
        assert_eq!(resp.status(), 200);
        let version = version_of(&resp);
        let summary: Value = resp.json().await.unwrap();
        assert_eq!(summary["version"].as_u64(), Some(version));
        done.push((c, version, body));
    }
    done
}

async fn reader(app: &TestApp, ids: &[String], r: usize) {
    let mut last_seen = vec![0u64; ids.len()];
    for i in 0..READS_EACH {
        let c = (r + i) % ids.len();
        if i % 2 == 0 {
            let resp = app.http.get(app.url(&format!("/v1/clips/{}", ids[c]))).send().await.unwrap();
            assert_eq!(resp.status(), 200);
            let version = version_of(&resp);
            assert!(version >= last_seen[c], "version went back from {} to {version}", last_seen[c]);
            last_seen[c] = version;
            whole_version(&resp.json().await.unwrap());
        } else {
            let url = app.url(&format!("/v1/clips/{}/pose?t=0.5", ids[c]));
            let pose: Value = app.http.get(url).send().await.unwrap().json().await.unwrap();
            let joints = pose["joints"].as_array().unwrap();
            assert_eq!(joints.len(), 2);
            // Both joints carry the same k in any one version.
            assert_eq!(joints[0]["translation"], joints[1]["translation"], "torn pose");
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_writers_and_readers_see_whole_monotonic_versions() {
    // 50 clients on one address: above the default per-caller in-flight cap (32), which is not what this tests.
    let app = TestApp::builder().configure(|c| c.limits.max_in_flight_per_client = 64).start().await;
    let mut ids = Vec::new();
    for c in 0..CLIPS {
        ids.push(app.create(&uniform_clip("v0", 2, 2, 0.0), None).await["id"].as_str().unwrap().to_owned());
        let _ = c;
    }
    let writers = (0..WRITERS).map(|w| writer(&app, &ids, w));
    let readers = (0..READERS).map(|r| reader(&app, &ids, r));
    let (written, _) = tokio::join!(futures_util::future::join_all(writers), futures_util::future::join_all(readers));

    // Per clip: every replace got its own version, 2..=1+n, and the final
    // document is the one written at the highest version.
    let mut per_clip: HashMap<usize, Vec<(u64, String)>> = HashMap::new();
    for (c, v, body) in written.into_iter().flatten() {
        per_clip.entry(c).or_default().push((v, body));
    }
    for (c, mut versions) in per_clip {
        versions.sort();
        let got: Vec<u64> = versions.iter().map(|(v, _)| *v).collect();
        let expected: Vec<u64> = (2..=versions.len() as u64 + 1).collect();
        assert_eq!(got, expected, "clip {c}: versions are not one per write");
        let resp = app.http.get(app.url(&format!("/v1/clips/{}", ids[c]))).send().await.unwrap();
        assert_eq!(version_of(&resp), *got.last().unwrap());
        assert_eq!(resp.text().await.unwrap(), canonical(&versions.last().unwrap().1));
    }
    app.stop().await;
}
