//! Durability: the real binary, `kill -9` in the middle of a stream of
//! uploads, a restart on the same data directory. Every clip that got a 201
//! is there byte for byte; anything else present is a whole upload that was
//! in flight; nothing is half-written.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use serde_json::Value;

use super::canonical;
use crate::common::ServerProcess;

const CLIENTS: usize = 4;
/// Kill once this many uploads have been acknowledged.
const KILL_AFTER: usize = 40;

async fn start(dir: &Path) -> ServerProcess {
    ServerProcess::serve().data_dir(dir).start().await
}

/// A clip of 12 joints × 3 channels × 30 keys, unique per (client, k).
fn doc(client: usize, k: usize) -> String {
    let times: Vec<f32> = (0..30).map(|i| i as f32 / 10.0).collect();
    let mut tracks = Vec::new();
    for j in 0..12 {
        let v = (client * 1000 + k) as f32 + j as f32 / 100.0;
        for channel in ["translation", "scale"] {
            tracks
                .push(serde_json::json!({"joint": format!("j{j}"), "channel": channel, "interpolation": "catmull_rom",
                "times": times, "values": (0..30).map(|i| [v, i as f32, 1.0]).collect::<Vec<_>>()}));
        }
        tracks.push(serde_json::json!({"joint": format!("j{j}"), "channel": "rotation", "interpolation": "linear",
            "times": times, "values": vec![[0.0, 0.0, 0.0, 1.0]; 30]}));
    }
    canonical(&serde_json::json!({"name": format!("c{client}-{k}"), "tracks": tracks}).to_string())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn acknowledged_uploads_survive_kill_9() {
    let dir = tempfile::tempdir().unwrap();
    let mut server = start(dir.path()).await;
    let acked = Arc::new(AtomicUsize::new(0));
    let reached = Arc::new(tokio::sync::Notify::new());
    let mut clients = Vec::new();
    for client in 0..CLIENTS {
        let (base, acked, reached) = (server.base(), acked.clone(), reached.clone());
        clients.push(tokio::spawn(async move {
            let http = crate::common::http_client();
            // name → (document, id if acknowledged)
            let mut sent: HashMap<String, (String, Option<String>)> = HashMap::new();
            for k in 0.. {
                let body = doc(client, k);
                let name = format!("c{client}-{k}");
                sent.insert(name.clone(), (body.clone(), None));
                let resp = http
                    .post(format!("{base}/v1/clips"))
                    .header("content-type", "application/json")
                    .body(body)
                    .send()
                    .await;
                let Ok(resp) = resp else { break };
                if resp.status() != 201 {
                    break;
                }
                let Ok(summary) = resp.json::<Value>().await else { break };
                sent.get_mut(&name).unwrap().1 = Some(summary["id"].as_str().unwrap().to_owned());
                if acked.fetch_add(1, Ordering::SeqCst) + 1 == KILL_AFTER {
                    reached.notify_one();
                }
            }
            sent
        }));
    }
    reached.notified().await;
    server.kill(); // SIGKILL while the clients are mid-upload
    let mut sent = HashMap::new();
    for c in clients {
        sent.extend(c.await.unwrap());
    }
    let acked_count = sent.values().filter(|(_, id)| id.is_some()).count();
    assert!(acked_count >= KILL_AFTER);

    let mut server = start(dir.path()).await;
    let http = crate::common::http_client();
    let mut listed = Vec::new();
    let mut cursor = String::new();
    loop {
        let page: Value = http
            .get(format!("{}/v1/clips?limit=1000{cursor}", server.base()))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        listed.extend(page["clips"].as_array().unwrap().iter().cloned());
        match page["next_cursor"].as_str() {
            Some(c) => cursor = format!("&cursor={c}"),
            None => break,
        }
    }
    let mut found = HashMap::new();
    for summary in &listed {
        let (name, id) = (summary["name"].as_str().unwrap(), summary["id"].as_str().unwrap());
        let (expected, acked_id) = sent.get(name).unwrap_or_else(|| panic!("unknown clip {name} after restart"));
        if let Some(acked_id) = acked_id {
            assert_eq!(acked_id, id, "{name} changed id");
        }
        let body = http.get(format!("{}/v1/clips/{id}", server.base())).send().await.unwrap().text().await.unwrap();
        assert_eq!(&body, expected, "{name} is not byte-for-byte what was uploaded");
        assert!(found.insert(name.to_owned(), id.to_owned()).is_none(), "{name} stored twice");
    }
    for (name, (_, id)) in &sent {
        if id.is_some() {
            assert!(found.contains_key(name), "{name} got a 201 but is gone after kill -9");
        }
    }
    server.kill();
}

#[tokio::test]
async fn sigterm_drains_and_exits_cleanly_keeping_the_data() {
    let dir = tempfile::tempdir().unwrap();
    let mut server = start(dir.path()).await;
    let http = crate::common::http_client();
    let body = doc(0, 0);
    let resp = http
        .post(format!("{}/v1/clips", server.base()))
        .header("content-type", "application/json")
        .body(body.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 201);
    let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    server.signal("TERM");
    let status = server.wait_exit(std::time::Duration::from_secs(15)).await.expect("exits after SIGTERM");
    assert!(status.success(), "exit status after SIGTERM: {status}");

    let mut server = start(dir.path()).await;
    let got = http.get(format!("{}/v1/clips/{id}", server.base())).send().await.unwrap().text().await.unwrap();
    assert_eq!(got, body);
    server.kill();
}
