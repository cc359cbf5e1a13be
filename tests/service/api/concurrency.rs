//! 50 concurrent writers and readers on overlapping clips: every read sees a
//! whole version, and versions (ETags) only go up. 320 concurrent PATCHes
//! without `If-Match` on one clip, through two servers on one store: none is
//! answered 412, and every one answered 200 is in the final version.

use std::collections::HashMap;

use serde_json::{Value, json};

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
    // `v{k}`, or `v{k}/{c}` for the c-th clip of the same start.
    let k: f64 = name.trim_start_matches('v').split('/').next().unwrap().parse().unwrap();
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
        ids.push(
            app.create(&uniform_clip(&format!("v0/{c}"), 2, 2, 0.0), None).await["id"].as_str().unwrap().to_owned(),
        );
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

/// PATCHes sent at once (half to each of the two servers).
const PATCHES: usize = 320;

/// A server on the store in `data`, with room for every patch at once from
/// one address. Commits skip the fsync: the race is under test, not the disk.
async fn node(data: &std::path::Path) -> TestApp {
    TestApp::builder()
        .data_dir(data)
        .configure(|c| {
            c.db.durability = server::store::Durability::UnsafeFast;
            c.limits.max_in_flight_per_client = 2 * PATCHES;
            c.limits.max_in_flight = 2 * PATCHES;
            c.limits.write_burst = 10 * PATCHES as u32;
        })
        .start()
        .await
}

/// Patch `i` adds the metadata key `w{i}`; returns its status, problem code and `Retry-After`.
async fn patch_one(app: &TestApp, id: &str, i: usize) -> (u16, Option<String>, bool) {
    let resp = app
        .http
        .patch(app.url(&format!("/v1/clips/{id}")))
        .header("content-type", "application/merge-patch+json")
        .body(json!({"metadata": {format!("w{i}"): i}}).to_string())
        .send()
        .await
        .unwrap();
    let (status, retry_after) = (resp.status().as_u16(), resp.headers().contains_key("retry-after"));
    let code =
        if status == 200 { None } else { resp.json::<Value>().await.unwrap()["code"].as_str().map(str::to_owned) };
    (status, code, retry_after)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn patches_without_if_match_are_never_412_and_none_is_lost() {
    // Two servers on one SQLite store: each lets its own patches of a clip
    // take turns, so the two race each other, as two nodes would.
    let data = tempfile::tempdir().unwrap();
    let (a, b) = (node(data.path()).await, node(data.path()).await);
    let id = a.create_id(&uniform_clip("v0", 2, 2, 0.0), None).await;
    let answers = futures_util::future::join_all((0..PATCHES).map(|i| {
        let app = if i % 2 == 0 { &a } else { &b };
        patch_one(app, &id, i)
    }))
    .await;

    let ok: Vec<usize> = (0..PATCHES).filter(|&i| answers[i].0 == 200).collect();
    let refused = answers.iter().filter(|r| r.0 == 412).count();
    let others: Vec<_> = answers.iter().filter(|r| r.0 != 200).collect();
    println!(
        "FIGURE {PATCHES} concurrent PATCHes without If-Match on two nodes: {} answered 200, {refused} 412, others {others:?}",
        ok.len()
    );
    assert_eq!(refused, 0, "a PATCH without If-Match was answered 412");
    for (status, code, retry_after) in &others {
        assert_eq!(
            (*status, code.as_deref(), *retry_after),
            (503, Some("unavailable"), true),
            "only a lost race may refuse"
        );
    }
    // The stored clip, read from the store (the caches of two servers without a change feed may lag).
    let stored = a.state.store.get(&id).await.unwrap().unwrap();
    assert_eq!(stored.meta.version, 1 + ok.len() as u64, "one version per patch answered 200");
    let doc: Value = serde_json::from_str(&stored.doc_json).unwrap();
    let keys: Vec<usize> = doc["metadata"].as_object().map_or(vec![], |m| {
        let mut keys: Vec<usize> = m.keys().map(|k| k[1..].parse().unwrap()).collect();
        keys.sort_unstable();
        keys
    });
    assert_eq!(keys, ok, "every patch answered 200, and only those, is in the final version");
    a.stop().await;
    b.stop().await;
}
