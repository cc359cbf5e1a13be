//! The kill -9 crash test. Eight uploaders send JSON clips, glTF, GLB and BVH
//! files (1 KiB to 4 MiB) to the real binary, which is killed with SIGKILL
//! at a random moment 50–2000 ms in, then restarted, `CRASH_CYCLES` times
//! (3 in `cargo test`; `CRASH_CYCLES=50` is the full run). After every kill:
//! `PRAGMA integrity_check` is `ok` on the database file; the server is
//! ready again in under 2 s; every acknowledged clip is there and equal
//! (by hash) to what a crash-free server stores for the same upload; and
//! every stored clip is the whole of some upload (nothing partial).

use std::collections::{HashMap, HashSet};
use std::hash::{Hash, Hasher};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use base64::Engine as _;
use sqlx::Connection;

use super::start;

/// One upload: where it goes and its bytes.
struct Upload {
    /// With `replace=true`: names identify clips, so sending an upload
    /// again makes a new version of its clip (the same document).
    path: String,
    content_type: &'static str,
    body: Vec<u8>,
}

/// Sizes of each kind of file, roughly (keys are scaled to reach them).
const SIZES: [usize; 4] = [1 << 10, 16 << 10, 256 << 10, 4 << 20];

fn hash(bytes: &[u8]) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    bytes.hash(&mut h);
    h.finish()
}

/// Key times and translations of a smooth path, `n` keys.
fn keys(n: usize, seed: usize) -> (Vec<f32>, Vec<[f32; 3]>) {
    let times = (0..n).map(|i| i as f32 / 30.0).collect();
    let s = seed as f32;
    let values = (0..n).map(|i| [(i as f32 * 0.1 + s).sin(), (i as f32 * 0.07).cos(), s * 0.01]).collect();
    (times, values)
}

fn json_clip(target: usize, seed: usize) -> Upload {
    let n = (target / 48).max(2);
    let (times, values) = keys(n, seed);
    let doc = serde_json::json!({
        "name": format!("crash-json-{seed}"),
        "skeleton": {"joints": [{"name": "root", "parent": null}]},
        "tracks": [{"joint": "root", "channel": "translation", "interpolation": "linear",
                     "times": times, "values": values}],
    });
    Upload {
        path: "/v1/clips?replace=true".into(),
        content_type: "application/json",
        body: serde_json::to_vec(&doc).unwrap(),
    }
}

/// A glTF document animating one node's translation; `buffer` is its bytes
/// (times then values), referenced by `uri` (or the GLB chunk when `None`).
fn gltf_doc(n: usize, times: &[f32], uri: Option<String>, name: &str) -> serde_json::Value {
    let t_end = times[n - 1];
    let mut buffer = serde_json::json!({"byteLength": n * 16});
    if let Some(uri) = uri {
        buffer["uri"] = uri.into();
    }
    serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "root"}],
        "buffers": [buffer],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": n * 4},
            {"buffer": 0, "byteOffset": n * 4, "byteLength": n * 12}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": n, "type": "SCALAR", "min": [0.0], "max": [t_end]},
            {"bufferView": 1, "componentType": 5126, "count": n, "type": "VEC3"}
        ],
        "animations": [{"name": name, "samplers": [{"input": 0, "output": 1, "interpolation": "LINEAR"}],
                         "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}]}]
    })
}

fn gltf_bytes(n: usize, seed: usize) -> (Vec<f32>, Vec<u8>) {
    let (times, values) = keys(n, seed);
    let mut bin = Vec::with_capacity(n * 16);
    times.iter().for_each(|t| bin.extend_from_slice(&t.to_le_bytes()));
    values.iter().flatten().for_each(|v| bin.extend_from_slice(&v.to_le_bytes()));
    (times, bin)
}

fn gltf_file(target: usize, seed: usize) -> Upload {
    let n = (target * 3 / 4 / 16).max(2);
    let (times, bin) = gltf_bytes(n, seed);
    let uri =
        format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&bin));
    let doc = gltf_doc(n, &times, Some(uri), &format!("crash-gltf-{seed}"));
    Upload {
        path: "/v1/clips/import?replace=true".into(),
        content_type: "model/gltf+json",
        body: serde_json::to_vec(&doc).unwrap(),
    }
}

fn glb_file(target: usize, seed: usize) -> Upload {
    let n = (target / 16).max(2);
    let (times, mut bin) = gltf_bytes(n, seed);
    let mut json = serde_json::to_vec(&gltf_doc(n, &times, None, &format!("crash-glb-{seed}"))).unwrap();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut body = Vec::with_capacity(total);
    body.extend_from_slice(b"glTF");
    body.extend_from_slice(&2u32.to_le_bytes());
    body.extend_from_slice(&u32::try_from(total).unwrap().to_le_bytes());
    body.extend_from_slice(&u32::try_from(json.len()).unwrap().to_le_bytes());
    body.extend_from_slice(b"JSON");
    body.extend_from_slice(&json);
    body.extend_from_slice(&u32::try_from(bin.len()).unwrap().to_le_bytes());
    body.extend_from_slice(b"BIN\0");
    body.extend_from_slice(&bin);
    Upload { path: "/v1/clips/import?replace=true".into(), content_type: "model/gltf-binary", body }
}

fn bvh_file(target: usize, seed: usize) -> Upload {
    let mut text = String::from(
        "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n  JOINT Chest\n  {\n    OFFSET 0 5 0\n    CHANNELS 3 Zrotation Xrotation Yrotation\n    End Site\n    {\n      OFFSET 0 5 0\n    }\n  }\n}\nMOTION\n",
    );
    let frames = (target / 60).max(2);
    text.push_str(&format!("Frames: {frames}\nFrame Time: 0.033333\n"));
    for f in 0..frames {
        let a = (f + seed) as f32 * 0.01;
        text.push_str(&format!(
            "{:.4} {:.4} {:.4} {:.3} {:.3} {:.3} {:.3} {:.3} {:.3}\n",
            a.sin(),
            10.0 + a.cos(),
            seed as f32,
            a * 10.0 % 90.0,
            a * 5.0 % 45.0,
            a * 3.0 % 30.0,
            a * 7.0 % 60.0,
            a * 2.0 % 20.0,
            a % 10.0
        ));
    }
    Upload {
        path: format!("/v1/clips/import?replace=true&name=crash-bvh-{seed}"),
        content_type: "application/x-bvh",
        body: text.into_bytes(),
    }
}

fn uploads() -> Vec<Upload> {
    let mut all = Vec::new();
    for (i, size) in SIZES.iter().enumerate() {
        all.push(json_clip(*size, i));
        all.push(gltf_file(*size, i));
        all.push(glb_file(*size, i));
        all.push(bvh_file(*size, i));
    }
    all
}

/// Sends one upload; the ids of the clips it created when acknowledged.
async fn send(http: &reqwest::Client, base: &str, u: &Upload) -> Result<Vec<String>, String> {
    let r = http
        .post(format!("{base}{}", u.path))
        .header("content-type", u.content_type)
        .body(u.body.clone())
        .send()
        .await
        .map_err(|e| e.to_string())?;
    let status = r.status();
    let v: serde_json::Value = r.json().await.map_err(|e| e.to_string())?;
    if status != 201 && status != 200 {
        return Err(format!("{status}: {v}"));
    }
    Ok(match v["clips"].as_array() {
        Some(clips) => clips.iter().map(|c| c["id"].as_str().unwrap().to_owned()).collect(),
        None => vec![v["id"].as_str().unwrap().to_owned()],
    })
}

/// The stored document of a clip (what GET returns), hashed.
async fn stored_hash(http: &reqwest::Client, base: &str, id: &str) -> Option<u64> {
    let r = http.get(format!("{base}/v1/clips/{id}")).send().await.unwrap();
    (r.status() == 200).then_some(hash(&r.bytes().await.unwrap()))
}

/// Every clip id in the store, through the paginated list.
async fn all_ids(http: &reqwest::Client, base: &str) -> Vec<String> {
    let mut ids = Vec::new();
    let mut cursor: Option<String> = None;
    loop {
        let mut url = format!("{base}/v1/clips?limit=1000");
        if let Some(c) = &cursor {
            url.push_str(&format!("&cursor={c}"));
        }
        let v: serde_json::Value = http.get(url).send().await.unwrap().json().await.unwrap();
        ids.extend(v["clips"].as_array().unwrap().iter().map(|c| c["id"].as_str().unwrap().to_owned()));
        match v["next_cursor"].as_str() {
            Some(c) => cursor = Some(c.to_owned()),
            None => return ids,
        }
    }
}

async fn integrity_check(db: &std::path::Path) -> String {
    let url = format!("sqlite://{}", db.display());
    let mut conn = sqlx::SqliteConnection::connect(&url).await.expect("open the database file");
    let (result,): (String,) = sqlx::query_as("PRAGMA integrity_check").fetch_one(&mut conn).await.unwrap();
    conn.close().await.unwrap();
    result
}

/// A small xorshift generator (the seed is printed, so a run can be repeated).
struct Rng(u64);

impl Rng {
    fn below(&mut self, n: u64) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0 % n
    }
}

#[tokio::test(flavor = "multi_thread")]
async fn kill_9_loses_no_acknowledged_clip_and_leaves_no_partial_one() {
    let cycles: usize = std::env::var("CRASH_CYCLES").ok().and_then(|s| s.parse().ok()).unwrap_or(3);
    let seed = std::env::var("CRASH_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or_else(|| {
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos() as u64 | 1
    });
    let mut rng = Rng(seed);
    let files = Arc::new(uploads());
    let http = crate::common::http_client();
    let no_rate_limit = ["--write-rate", "1000000", "--write-burst", "1000000"];

    // What a crash-free server stores for each upload.
    let reference_dir = tempfile::tempdir().unwrap();
    let reference = start(&reference_dir.path().join("data"), &no_rate_limit).await;
    let base = format!("http://{}", reference.http);
    let mut expected: HashMap<u64, usize> = HashMap::new();
    for (i, f) in files.iter().enumerate() {
        let ids = send(&http, &base, f).await.unwrap_or_else(|e| panic!("upload {i} ({}): {e}", f.content_type));
        assert_eq!(ids.len(), 1, "upload {i} makes one clip");
        expected.insert(stored_hash(&http, &base, &ids[0]).await.unwrap(), i);
    }
    drop(reference);
    let expected = Arc::new(expected);

    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    // Acknowledged: clip id -> the upload it came from.
    let acked: Arc<Mutex<HashMap<String, usize>>> = Arc::default();
    let (mut worst_ready, mut attempts) = (Duration::ZERO, 0usize);
    for cycle in 0..=cycles {
        if cycle > 0 {
            assert_eq!(integrity_check(&data.join("inbetween.db")).await, "ok", "cycle {cycle}");
        }
        let server = start(&data, &no_rate_limit).await;
        worst_ready = worst_ready.max(server.ready_after);
        if crate::common::latency_checked() {
            assert!(server.ready_after < Duration::from_secs(2), "ready after {:?}", server.ready_after);
        }
        let base = format!("http://{}", server.http);
        // Everything acknowledged so far is there, unaltered.
        let acked_now = acked.lock().unwrap().clone();
        for (id, file) in acked_now {
            let got = stored_hash(&http, &base, &id).await;
            assert!(got.is_some(), "cycle {cycle}: acknowledged clip {id} is lost");
            assert_eq!(expected.get(&got.unwrap()), Some(&file), "cycle {cycle}: clip {id} is altered");
        }
        // Everything stored is the whole of some upload.
        let mut seen = HashSet::new();
        for id in all_ids(&http, &base).await {
            let h = stored_hash(&http, &base, &id).await.unwrap();
            assert!(expected.contains_key(&h), "cycle {cycle}: clip {id} is not any upload (partial?)");
            seen.insert(id);
        }
        assert!(acked.lock().unwrap().keys().all(|id| seen.contains(id)), "cycle {cycle}: listing misses a clip");
        if cycle == cycles {
            break;
        }
        let sent = Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let uploaders: Vec<_> = (0..8)
            .map(|u| {
                let (http, base, files, acked, sent) =
                    (http.clone(), base.clone(), files.clone(), acked.clone(), sent.clone());
                let mut k = u * 3;
                tokio::spawn(async move {
                    loop {
                        let i = k % files.len();
                        k += 5;
                        sent.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        match send(&http, &base, &files[i]).await {
                            Ok(ids) => acked.lock().unwrap().extend(ids.into_iter().map(|id| (id, i))),
                            // Pacing the retry of a refused upload: not a wait on anything.
                            Err(_) => tokio::time::sleep(Duration::from_millis(5)).await,
                        }
                    }
                })
            })
            .collect();
        let kill_after = Duration::from_millis(50 + rng.below(1951));
        // The time is the behaviour here: a kill at a random moment of the uploads.
        tokio::time::sleep(kill_after).await;
        server.signal("KILL");
        let mut server = server;
        server.wait_exit(Duration::from_secs(5)).await.expect("killed");
        for u in &uploaders {
            u.abort();
        }
        attempts += sent.load(std::sync::atomic::Ordering::Relaxed);
    }
    let acked = acked.lock().unwrap().len();
    println!(
        "crash: seed {seed}, {cycles} kill -9 cycles, {attempts} uploads attempted, {acked} clips acknowledged, 0 lost, 0 altered, 0 partial, integrity ok, slowest restart to ready {worst_ready:?}"
    );
    assert!(cycles == 0 || acked > 0, "nothing was acknowledged: the test tested nothing");
}
