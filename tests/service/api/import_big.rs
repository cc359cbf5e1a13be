//! Big character files (issue 18): `POST /v1/clips/import` and `inbetween
//! import` take a file far over the JSON body limit, spooled or opened rather
//! than held, reading only its glTF JSON and animation data; the memory that
//! costs is measured on the real binary. Every 413 names its limit, its value
//! and how to raise it.

use std::io::Write;
use std::net::SocketAddr;
use std::path::Path;
use std::process::Stdio;
use std::time::Duration;

use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use super::TestApp;
use crate::common::{ServerProcess, testdata};

/// The padding "image" that no animation references: the file is 200 MB.
const PADDING_BYTES: usize = 200_000_000;

/// The peak RSS an import may add, server or CLI (issue 18).
const RSS_BOUND: u64 = 64 << 20;

/// How much more the 200 MB file may cost than the same file without its
/// image: imports of one file vary by up to ±10 MiB from run to run (the
/// allocator), while reading the image would cost 190 MiB.
const SLACK: u64 = 32 << 20;

fn u32_at(b: &[u8], at: usize) -> usize {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap()) as usize
}

/// Keys of the generated animation: with three rotation tracks on one time
/// accessor, 20 000 keys are 1.04 MB of animation data.
const LONG_KEYS: usize = 20_000;

/// Writes Fox.glb plus a generated animation `Long` (three of its joints
/// swinging for [`LONG_KEYS`] keys), so the file holds about 1.1 MB of
/// animation data, after `padding` bytes of a PNG image inserted at the
/// start of its BIN chunk (every other buffer view moved up past it): with
/// 200 MB of padding, the animations lie past 200 MB that only the image
/// references.
fn write_fox(path: &Path, padding: usize) {
    let fox = testdata("gltf/Fox/Fox.glb");
    let json_len = u32_at(&fox, 12);
    let mut doc: Value = serde_json::from_slice(&fox[20..20 + json_len]).unwrap();
    let bin_at = 20 + json_len;
    let mut bin = fox[bin_at + 8..bin_at + 8 + u32_at(&fox, bin_at)].to_vec();
    bin.resize(bin.len().next_multiple_of(4), 0);
    add_long_animation(&mut doc, &mut bin);
    for view in doc["bufferViews"].as_array_mut().unwrap() {
        let offset = view["byteOffset"].as_u64().unwrap_or(0);
        view["byteOffset"] = json!(offset + padding as u64);
    }
    if padding > 0 {
        let views = doc["bufferViews"].as_array_mut().unwrap();
        views.push(json!({"buffer": 0, "byteOffset": 0, "byteLength": padding}));
        let padding_view = views.len() - 1;
        doc["images"].as_array_mut().unwrap().push(json!({"bufferView": padding_view, "mimeType": "image/png"}));
    }
    doc["buffers"][0]["byteLength"] = json!(padding + bin.len());
    let mut json = serde_json::to_vec(&doc).unwrap();
    json.resize(json.len().next_multiple_of(4), b' ');
    let bin_len = padding + bin.len();
    let total = 12 + 8 + json.len() + 8 + bin_len;
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    for word in [u32::from_le_bytes(*b"glTF"), 2, total as u32, json.len() as u32] {
        out.write_all(&word.to_le_bytes()).unwrap();
    }
    out.write_all(b"JSON").unwrap();
    out.write_all(&json).unwrap();
    out.write_all(&(bin_len as u32).to_le_bytes()).unwrap();
    out.write_all(b"BIN\0").unwrap();
    // Not zeros: bytes a filesystem stores like any others.
    let block: Vec<u8> = (0..1 << 20).map(|i: u32| (i.wrapping_mul(2_654_435_761) >> 24) as u8).collect();
    let mut left = padding;
    while left > 0 {
        let n = left.min(block.len());
        out.write_all(&block[..n]).unwrap();
        left -= n;
    }
    out.write_all(&bin).unwrap();
    out.flush().unwrap();
    assert_eq!(std::fs::metadata(path).unwrap().len(), total as u64);
}

/// Appends animation `Long` to the document and its data to `bin`: one
/// time accessor (60 keys a second) and a rotation swing about y for each
/// of the first three joints of Fox's skin.
fn add_long_animation(doc: &mut Value, bin: &mut Vec<u8>) {
    let mut view = |doc: &mut Value, bytes: Vec<u8>| -> usize {
        let views = doc["bufferViews"].as_array_mut().unwrap();
        views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len()}));
        bin.extend_from_slice(&bytes);
        views.len() - 1
    };
    let times: Vec<f32> = (0..LONG_KEYS).map(|i| i as f32 / 60.0).collect();
    let times_view = view(doc, times.iter().flat_map(|t| t.to_le_bytes()).collect());
    let accessors = doc["accessors"].as_array_mut().unwrap();
    accessors.push(json!({"bufferView": times_view, "componentType": 5126, "count": LONG_KEYS, "type": "SCALAR",
        "min": [0.0], "max": [times[LONG_KEYS - 1]]}));
    let input = accessors.len() - 1;
    let joints: Vec<u64> =
        doc["skins"][0]["joints"].as_array().unwrap()[..3].iter().map(|j| j.as_u64().unwrap()).collect();
    let (mut channels, mut samplers) = (Vec::new(), Vec::new());
    for (k, node) in joints.into_iter().enumerate() {
        let rotations: Vec<u8> = times
            .iter()
            .flat_map(|t| {
                let half = 0.5 * (t * (1.0 + k as f32)).sin();
                [0.0, half.sin(), 0.0, half.cos()]
            })
            .flat_map(f32::to_le_bytes)
            .collect();
        let output_view = view(doc, rotations);
        let accessors = doc["accessors"].as_array_mut().unwrap();
        accessors.push(json!({"bufferView": output_view, "componentType": 5126, "count": LONG_KEYS, "type": "VEC4"}));
        samplers.push(json!({"input": input, "output": accessors.len() - 1, "interpolation": "LINEAR"}));
        channels.push(json!({"sampler": k, "target": {"node": node, "path": "rotation"}}));
    }
    doc["animations"].as_array_mut().unwrap().push(json!({"name": "Long", "channels": channels, "samplers": samplers}));
}

/// A `/proc/PID/status` figure in bytes (`VmRSS`, `VmHWM`).
fn proc_status(pid: i32, field: &str) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let kb = status.lines().find_map(|l| l.strip_prefix(field)).unwrap().trim().trim_end_matches("kB").trim();
    kb.parse::<u64>().unwrap() * 1024
}

/// POSTs the file at `path` over a raw HTTP/1.1 connection, streamed from
/// disk (the test process never holds it), and returns the status and body.
async fn post_file(addr: SocketAddr, path: &Path) -> (u16, Value) {
    let len = std::fs::metadata(path).unwrap().len();
    let mut s = TcpStream::connect(addr).await.unwrap();
    let head = format!(
        "POST /v1/clips/import?replace=true HTTP/1.1\r\nHost: x\r\nContent-Type: model/gltf-binary\r\n\
         Content-Length: {len}\r\nConnection: close\r\n\r\n"
    );
    s.write_all(head.as_bytes()).await.unwrap();
    let mut file = tokio::io::BufReader::with_capacity(1 << 20, tokio::fs::File::open(path).await.unwrap());
    tokio::io::copy_buf(&mut file, &mut s).await.unwrap();
    let mut answer = Vec::new();
    s.read_to_end(&mut answer).await.unwrap();
    let text = String::from_utf8(answer).unwrap();
    let status = text[9..12].parse().unwrap();
    let body = text.split_once("\r\n\r\n").map_or("", |(_, b)| b);
    (status, serde_json::from_str(body).unwrap_or_else(|e| panic!("{e}: {text}")))
}

/// What one import did to a fresh server: its answer, the stored
/// documents, and how far its peak RSS rose over its RSS before.
struct Measured {
    answer: Value,
    docs: Vec<Value>,
    grown: u64,
    /// From the first byte sent to the answer.
    took: Duration,
}

/// Imports `path` over HTTP on a fresh `inbetween serve` (the real binary,
/// so the RSS is the server's alone), measuring its peak RSS growth. Fox.glb
/// is imported first, so what is measured excludes the costs of a server's
/// first import (threads, the store's first pages) that no file causes.
async fn import_on_a_fresh_server(path: &Path, warm_up: &Path) -> Measured {
    let data = tempfile::tempdir().unwrap();
    // Generous timeouts: on a loaded 2-core machine 200 MB may take longer than the default 10 s to arrive.
    let timeouts = ["--body-read-timeout-secs", "120", "--request-timeout-secs", "180"];
    let server = ServerProcess::serve().data_dir(data.path()).args(timeouts).start().await;
    assert_eq!(post_file(server.http, warm_up).await.0, 201);
    let before = proc_status(server.pid(), "VmRSS:");
    // Start the peak from here when the kernel allows it (else it counts the startup peak too: a stricter bound).
    let _ = std::fs::write(format!("/proc/{}/clear_refs", server.pid()), "5");
    let started = std::time::Instant::now();
    let (status, answer) = post_file(server.http, path).await;
    let took = started.elapsed();
    let peak = proc_status(server.pid(), "VmHWM:");
    assert_eq!(status, 201, "{answer}");
    let http = reqwest::Client::new();
    let mut docs = Vec::new();
    for clip in answer["clips"].as_array().unwrap() {
        let url = server.url(&format!("/v1/clips/{}", clip["id"].as_str().unwrap()));
        docs.push(http.get(url).send().await.unwrap().json().await.unwrap());
    }
    Measured { answer, docs, grown: peak.saturating_sub(before), took }
}

/// A figure in MiB, for the record.
fn mib(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / f64::from(1 << 20))
}

/// `inbetween import FILE`: its stdout and its peak RSS (`VmHWM`). The CLI
/// writes its documents last, streamed, into a pipe this test leaves unread
/// until the CLI has started writing and its peak has held still: by then
/// the import is done. (wait4's `ru_maxrss` would count this test process
/// too, which the child was forked from.)
fn cli_import(path: &Path) -> (String, u64) {
    let mut child = ServerProcess::command().arg("import").arg(path).stdout(Stdio::piped()).spawn().unwrap();
    let pid = i32::try_from(child.id()).unwrap();
    let read = |file: &str| std::fs::read_to_string(format!("/proc/{pid}/{file}")).ok();
    let (mut peak, mut still_since) = (0, std::time::Instant::now());
    loop {
        // Sampling the child's memory as it runs: a measurement interval.
        std::thread::sleep(Duration::from_millis(10));
        let (Some(status), Some(io)) = (read("status"), read("io")) else { break };
        let hwm = status.lines().find_map(|l| l.strip_prefix("VmHWM:")).map(|v| v.trim().trim_end_matches("kB").trim());
        let hwm = hwm.and_then(|v| v.parse::<u64>().ok()).unwrap_or(0) * 1024;
        let writing = io.lines().find_map(|l| l.strip_prefix("wchar:")).is_some_and(|v| v.trim() != "0");
        if hwm != peak {
            (peak, still_since) = (hwm, std::time::Instant::now());
        } else if writing && still_since.elapsed() > Duration::from_millis(300) {
            break;
        }
    }
    let mut out = String::new();
    std::io::Read::read_to_string(&mut child.stdout.take().unwrap(), &mut out).unwrap();
    assert!(child.wait().unwrap().success(), "inbetween import {}", path.display());
    (out, peak)
}

/// A 200 MB GLB (1.1 MB of animations after a 200 MB image) imports over
/// real HTTP into the same clips as the same file without the image, while
/// the server's peak RSS grows by less than 64 MiB, and by no more than the
/// small file's import takes; `inbetween import` on it prints the same
/// documents as on the small file, within the same bounds.
#[tokio::test(flavor = "multi_thread")]
async fn a_200_mb_glb_imports_reading_only_its_animations() {
    let files = tempfile::tempdir().unwrap();
    let big = files.path().join("big-fox.glb");
    write_fox(&big, PADDING_BYTES);
    let small = files.path().join("fox.glb");
    write_fox(&small, 0);
    let (big_len, small_len) = (std::fs::metadata(&big).unwrap().len(), std::fs::metadata(&small).unwrap().len());

    let fox = files.path().join("Fox.glb");
    std::fs::write(&fox, testdata("gltf/Fox/Fox.glb")).unwrap();
    let on_small = import_on_a_fresh_server(&small, &fox).await;
    let on_big = import_on_a_fresh_server(&big, &fox).await;
    eprintln!(
        "server: peak RSS grown by {} importing the {big_len}-byte GLB in {:?}, {} importing the same without the \
         image ({small_len} bytes) in {:?}",
        mib(on_big.grown),
        on_big.took,
        mib(on_small.grown),
        on_small.took
    );
    assert_eq!(on_big.answer["clips"].as_array().unwrap().len(), 4, "Survey, Walk, Run, Long: {}", on_big.answer);
    assert_eq!(on_big.docs, on_small.docs, "the same clips as the file without the image");
    let long = on_big.docs.iter().find(|d| d["name"] == "Long").unwrap();
    assert_eq!(long["tracks"][2]["times"].as_array().unwrap().len(), LONG_KEYS, "every key of the generated animation");
    assert!(on_big.grown < RSS_BOUND, "the server's peak RSS grew by {} importing a 200 MB GLB", mib(on_big.grown));
    assert!(on_big.grown < on_small.grown + SLACK, "the image cost the server memory");

    let (small_out, small_peak) = cli_import(&small);
    let (big_out, big_peak) = cli_import(&big);
    eprintln!(
        "cli: inbetween import peaked at {} on the 200 MB GLB, {} without the image",
        mib(big_peak),
        mib(small_peak)
    );
    assert_eq!(big_out, small_out, "the CLI prints the same documents");
    assert!(big_peak < RSS_BOUND, "inbetween import peaked at {} on a 200 MB GLB", mib(big_peak));
    assert!(big_peak < small_peak + SLACK, "the image cost the CLI memory");
}

/// The detail of a 413 names the setting, its value, its flag and its
/// environment variable.
fn assert_names_limit(problem: &Value, setting: &str, value: u64) {
    let detail = problem["detail"].as_str().unwrap();
    let flag = format!("--{}", setting.replace('_', "-"));
    let env = format!("INBETWEEN_{}", setting.to_ascii_uppercase());
    for part in [setting, &value.to_string(), &flag, &env] {
        assert!(detail.contains(part), "{detail:?} lacks {part:?}");
    }
}

/// Over `max_import_bytes` an upload is refused with 413 naming it, whether
/// its length is declared (answered before the body is read) or it arrives
/// chunked (cut off once past the limit); under it, a file larger than
/// `max_body_bytes` imports, while a `.gltf` (held in memory whole) over
/// `max_body_bytes` is refused naming that limit, as is a JSON clip, and a
/// file whose content passes a clip limit names that one.
#[tokio::test(flavor = "multi_thread")]
async fn the_413s_name_the_limit_its_value_and_how_to_raise_it() {
    let app = TestApp::builder()
        .configure(|c| {
            c.limits.max_import_bytes = 150_000;
            c.limits.max_body_bytes = 100_000;
        })
        .start()
        .await;
    let fox = testdata("gltf/Fox/Fox.glb");
    assert!(fox.len() > 150_000);
    let resp = app.http.post(app.url("/v1/clips/import")).body(fox.clone()).send().await.unwrap();
    assert_eq!(resp.status(), 413);
    let problem: Value = resp.json().await.unwrap();
    assert_eq!(problem["code"], "body_too_large");
    assert_names_limit(&problem, "max_import_bytes", 150_000);

    // Chunked, so only counting the bytes as they arrive can stop it.
    let head = "POST /v1/clips/import HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n";
    let mut s = TcpStream::connect(app.addr).await.unwrap();
    s.write_all(head.as_bytes()).await.unwrap();
    let mut answer = Vec::new();
    for chunk in fox.chunks(8192) {
        let framed = [format!("{:x}\r\n", chunk.len()).as_bytes(), chunk, b"\r\n"].concat();
        if s.write_all(&framed).await.is_err() {
            break;
        }
        let mut buf = vec![0; 4096];
        if let Ok(Ok(n @ 1..)) = tokio::time::timeout(Duration::from_millis(20), s.read(&mut buf)).await {
            answer.extend_from_slice(&buf[..n]);
            break;
        }
    }
    let _ = tokio::time::timeout(Duration::from_secs(5), s.read_to_end(&mut answer)).await;
    let text = String::from_utf8_lossy(&answer);
    assert!(text.starts_with("HTTP/1.1 413"), "{text}");
    let problem: Value = serde_json::from_str(text.split_once("\r\n\r\n").unwrap().1).unwrap();
    assert_names_limit(&problem, "max_import_bytes", 150_000);
    app.stop().await;

    // Fox.glb (163 KB) under a max_import_bytes that fits it, over max_body_bytes: imported.
    let app = TestApp::builder().configure(|c| c.limits.max_body_bytes = 100_000).start().await;
    let resp = app.http.post(app.url("/v1/clips/import")).body(fox).send().await.unwrap();
    assert_eq!(resp.status(), 201, "{}", resp.text().await.unwrap());
    // CesiumMan.gltf (688 KB of JSON, read whole): over max_body_bytes.
    let gltf = testdata("gltf/CesiumMan/CesiumMan.gltf");
    let resp = app.http.post(app.url("/v1/clips/import")).body(gltf).send().await.unwrap();
    assert_eq!(resp.status(), 413);
    let problem: Value = resp.json().await.unwrap();
    assert_eq!(problem["code"], "document_too_large");
    assert_names_limit(&problem, "max_body_bytes", 100_000);
    // A JSON clip over max_body_bytes.
    let resp = app
        .http
        .post(app.url("/v1/clips"))
        .header("content-type", "application/json")
        .body(vec![b' '; 100_001])
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 413);
    assert_names_limit(&resp.json::<Value>().await.unwrap(), "max_body_bytes", 100_000);
    assert_eq!(app.list_all(100, None).await.len(), 3, "only Fox's three clips");
    app.stop().await;

    // A limit on what the import produces: a BVH of more frames than max_keys_per_track.
    let app = TestApp::builder().configure(|c| c.limits.max_keys_per_track = 100).start().await;
    let resp = app.http.post(app.url("/v1/clips/import")).body(testdata("bvh/131_01.bvh")).send().await.unwrap();
    assert_eq!(resp.status(), 413);
    let problem: Value = resp.json().await.unwrap();
    assert_eq!(problem["code"], "too_large");
    assert_names_limit(&problem, "max_keys_per_track", 100);
    app.stop().await;
}

/// A caller who may not write gets its 401 at once, its body unread: the
/// server spools nothing for it (the request declares 200 MB and sends none).
#[tokio::test]
async fn an_upload_from_a_caller_who_may_not_write_is_refused_before_it_is_read() {
    let app = TestApp::builder().write_token("w").start().await;
    let head = "POST /v1/clips/import HTTP/1.1\r\nHost: x\r\nContent-Type: model/gltf-binary\r\n\
                Content-Length: 200000000\r\n\r\n";
    let mut s = TcpStream::connect(app.addr).await.unwrap();
    s.write_all(head.as_bytes()).await.unwrap();
    let mut answer = Vec::new();
    tokio::time::timeout(Duration::from_secs(5), s.read_to_end(&mut answer)).await.expect("answered unread").unwrap();
    let text = String::from_utf8_lossy(&answer);
    assert!(text.starts_with("HTTP/1.1 401"), "{text}");
    assert!(text.to_ascii_lowercase().contains("www-authenticate: bearer"), "{text}");
    app.stop().await;
}

/// A small upload from a caller who may not write is read (and dropped)
/// before its 401: the client, still sending when the answer is ready, would
/// otherwise have its writes reset (a broken pipe, which is all hyper's
/// client, and so `inbetween import --server`, reported) instead of reading
/// the 401. The body follows the head a moment later, as a file does.
#[tokio::test]
async fn a_small_upload_refused_for_its_token_is_read_so_the_client_gets_the_401() {
    let app = TestApp::builder().write_token("w").start().await;
    let body = vec![0u8; 512 * 1024];
    let head = format!(
        "POST /v1/clips/import?replace=true HTTP/1.1\r\nHost: x\r\nContent-Type: model/gltf-binary\r\n\
         Authorization: Bearer wrong\r\nContent-Length: {}\r\n\r\n",
        body.len()
    );
    let mut s = TcpStream::connect(app.addr).await.unwrap();
    s.write_all(head.as_bytes()).await.unwrap();
    // The time is the behaviour here: the body follows the head a moment
    // later, and arrives paced, as a file does.
    tokio::time::sleep(Duration::from_millis(200)).await;
    for chunk in body.chunks(16 * 1024) {
        s.write_all(chunk).await.expect("the server reads the body it refuses");
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    let mut answer = Vec::new();
    tokio::time::timeout(Duration::from_secs(5), s.read_to_end(&mut answer)).await.expect("answered").unwrap();
    let text = String::from_utf8_lossy(&answer);
    assert!(text.starts_with("HTTP/1.1 401"), "{text}");
    assert!(text.to_ascii_lowercase().contains("connection: close"), "{text}");
    app.stop().await;
}
