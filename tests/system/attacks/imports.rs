//! A 12 MiB multipart glTF whose buffers all name the same part once drove
//! the server to 9.5 GB (each buffer copied the part). Parts are now shared
//! and every buffer's `byteLength` counts against the import limit.
//!
//! Two connections trickling an import at 1 byte/s once held both of the
//! node's upload slots, and 119 of 119 other imports were shed for 30 s.
//! Slots are now per caller, and an upload slower than
//! `min_upload_bytes_per_sec` is cut off after `upload_rate_window_secs`.

use std::net::{IpAddr, SocketAddr};
use std::time::{Duration, Instant};

use reqwest::multipart::{Form, Part};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

use super::target;
use crate::common::{eventually, latency_checked, within};

/// A part just under 12 MiB.
const PART_BYTES: usize = 12 * 1024 * 1024 - 4096;

/// A `.gltf` of `nodes` animated nodes; node `i` reads its times from
/// buffer `2i` and its translations from buffer `2i + 1`, and every buffer
/// is `part.bin`, whole.
fn gltf(nodes: usize) -> Vec<u8> {
    let doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes).collect::<Vec<_>>()}],
        "nodes": (0..nodes).map(|i| json!({"name": format!("n{i}")})).collect::<Vec<_>>(),
        "buffers": (0..2 * nodes).map(|_| json!({"uri": "part.bin", "byteLength": PART_BYTES})).collect::<Vec<_>>(),
        "bufferViews": (0..nodes).flat_map(|i| [
            json!({"buffer": 2 * i, "byteOffset": 0, "byteLength": 8}),
            json!({"buffer": 2 * i + 1, "byteOffset": 8, "byteLength": 24}),
        ]).collect::<Vec<_>>(),
        "accessors": (0..nodes).flat_map(|i| [
            json!({"bufferView": 2 * i, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]}),
            json!({"bufferView": 2 * i + 1, "componentType": 5126, "count": 2, "type": "VEC3"}),
        ]).collect::<Vec<_>>(),
        "animations": [{
            "channels": (0..nodes).map(|i| json!({"sampler": i, "target": {"node": i, "path": "translation"}})).collect::<Vec<_>>(),
            "samplers": (0..nodes).map(|i| json!({"input": 2 * i, "output": 2 * i + 1})).collect::<Vec<_>>()
        }]
    });
    serde_json::to_vec(&doc).unwrap()
}

#[tokio::test(flavor = "multi_thread")]
async fn a_part_named_by_a_thousand_buffers_is_shared_and_refused() {
    let mut target = target(&[]).await;
    let http = crate::common::http_client();
    let mut part = vec![0u8; PART_BYTES];
    part[4..8].copy_from_slice(&1.0f32.to_le_bytes());
    let probes = target.probes().await;
    for _ in 0..4 {
        let form = Form::new()
            .part("file", Part::bytes(gltf(500)).file_name("shared.gltf"))
            .part("buffer", Part::bytes(part.clone()).file_name("part.bin"));
        let resp = http.post(target.server.url("/v1/clips/import")).multipart(form).send().await.unwrap();
        assert_eq!(resp.status(), 413);
        let problem: Value = resp.json().await.unwrap();
        assert_eq!(problem["code"], "resolved_bytes_too_large", "{problem}");
    }
    let report = probes.finish();
    let list: Value = http.get(target.server.url("/v1/clips")).send().await.unwrap().json().await.unwrap();
    assert_eq!(list["clips"].as_array().map(Vec::len), Some(0), "nothing stored: {list}");
    target.assert_survived("12 MiB part named by 1,000 glTF buffers", &report);
}

/// The default `upload_rate_window_secs` (docs/configuration.md): when a trickle is cut off.
const RATE_WINDOW: Duration = Duration::from_secs(3);

/// The default `body_read_timeout_secs`, which would cut a trickle off anyway, later.
const BODY_READ_TIMEOUT: Duration = Duration::from_secs(10);

/// A small BVH file (two joints, three frames).
fn small_bvh(seed: usize) -> Vec<u8> {
    let mut text = String::from(
        "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation \
         Yrotation\n  JOINT Chest\n  {\n    OFFSET 0 5 0\n    CHANNELS 3 Zrotation Xrotation Yrotation\n    End Site\n    \
         {\n      OFFSET 0 5 0\n    }\n  }\n}\nMOTION\nFrames: 3\nFrame Time: 0.033333\n",
    );
    for f in 0..3 {
        text.push_str(&format!("{f} {seed} 0 0 0 {f} 0 {f} 0\n"));
    }
    text.into_bytes()
}

/// An import upload from `from` that declares 100 kB and sends one byte a
/// second; returns the answer's status, its problem code, and when it came.
async fn trickle(server: SocketAddr, from: IpAddr) -> (u16, String, Duration) {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.bind(SocketAddr::new(from, 0)).unwrap();
    let (mut read, mut write) = socket.connect(server).await.unwrap().into_split();
    let head = format!(
        "POST /v1/clips/import HTTP/1.1\r\nhost: {server}\r\ncontent-type: application/x-bvh\r\n\
         content-length: 100000\r\n\r\n"
    );
    write.write_all(head.as_bytes()).await.unwrap();
    let started = Instant::now();
    let writer = tokio::spawn(async move {
        let mut every = tokio::time::interval(Duration::from_secs(1));
        loop {
            every.tick().await;
            if write.write_all(b"H").await.is_err() {
                break;
            }
        }
    });
    let (mut answer, mut chunk, mut came) = (Vec::new(), [0u8; 4096], None);
    while !whole_answer(&answer) {
        let n = read.read(&mut chunk).await.unwrap_or(0);
        if n == 0 {
            break;
        }
        came.get_or_insert_with(|| started.elapsed());
        answer.extend_from_slice(&chunk[..n]);
    }
    writer.abort();
    let text = String::from_utf8_lossy(&answer);
    let status = text.split(' ').nth(1).and_then(|s| s.parse().ok()).unwrap_or(0);
    let body: Value = text.split_once("\r\n\r\n").and_then(|(_, b)| serde_json::from_str(b).ok()).unwrap_or_default();
    (status, body["code"].as_str().unwrap_or_default().to_owned(), came.unwrap_or_else(|| started.elapsed()))
}

/// Whether `answer` holds a whole HTTP/1.1 response with a `content-length`.
fn whole_answer(answer: &[u8]) -> bool {
    let text = String::from_utf8_lossy(answer);
    let Some((head, body)) = text.split_once("\r\n\r\n") else { return false };
    let length = head.lines().find_map(|l| {
        let (name, value) = l.split_once(':')?;
        name.eq_ignore_ascii_case("content-length").then(|| value.trim().parse::<usize>().ok())?
    });
    length.is_some_and(|n| body.len() >= n)
}

/// Six small imports one after the other from `from`; their statuses.
async fn imports_from(url: String, from: IpAddr) -> Vec<u16> {
    let http = crate::common::http_builder().local_address(from).build().unwrap();
    let mut statuses = Vec::new();
    for seed in 0..6 {
        // Each its own clip: names identify clips.
        let url = format!("{url}?name=from-{from}-{seed}");
        let resp = http.post(&url).header("content-type", "application/x-bvh").body(small_bvh(seed)).send().await;
        statuses.push(resp.unwrap().status().as_u16());
    }
    statuses
}

#[tokio::test(flavor = "multi_thread")]
async fn two_trickling_uploads_of_one_caller_block_no_other_caller_and_are_cut_off() {
    let mut target = target(&[]).await;
    let server = target.server.http;
    let probes = target.probes().await;
    let trickler = IpAddr::from([127, 0, 0, 2]);
    let tricklers = [tokio::spawn(trickle(server, trickler)), tokio::spawn(trickle(server, trickler))];
    eventually(Duration::from_secs(10), "both trickles hold an upload slot", || async {
        target.metric("inbetween_import_uploads").await == Some(2.0)
    })
    .await;
    // Four other callers (addresses), six imports each, while the trickles hold their slots.
    let url = target.server.url("/v1/clips/import");
    let others = (3..7).map(|last| imports_from(url.clone(), IpAddr::from([127, 0, 0, last])));
    let statuses: Vec<u16> = futures_util::future::join_all(others).await.into_iter().flatten().collect();
    let stored = statuses.iter().filter(|s| **s == 201).count();
    assert_eq!(stored, statuses.len(), "other callers' imports refused: {statuses:?}");
    assert!(tricklers.iter().all(|t| !t.is_finished()), "the imports ran while the trickles held their slots");
    let mut cut = Vec::new();
    for t in tricklers {
        let (status, code, after) = within(30, "a trickle's answer", t).await.unwrap();
        assert_eq!((status, code.as_str()), (408, "body_timeout"), "a trickle is cut off");
        assert!(after >= RATE_WINDOW, "cut off after {after:?}, within its grace");
        assert!(after < BODY_READ_TIMEOUT, "cut off by the arrival rate, not the body timeout: {after:?}");
        if latency_checked() {
            assert!(after <= RATE_WINDOW + Duration::from_millis(1500), "cut off late: {after:?}");
        }
        cut.push(after.as_secs_f64());
    }
    // Their slots are free again: the trickling caller imports too.
    let again = imports_from(url.clone(), trickler).await;
    assert!(again.iter().all(|s| *s == 201), "the trickler's own imports after the cut: {again:?}");
    let report = probes.finish();
    println!(
        "FIGURE two 1 B/s import uploads of one caller: {stored} of {} other callers' imports stored, trickles cut off \
         at {:.1} s and {:.1} s (408 body_timeout)",
        statuses.len(),
        cut[0],
        cut[1]
    );
    target.assert_survived("two 1 B/s import uploads of one caller", &report);
}
