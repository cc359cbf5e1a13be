//! The malformed-input corpus (`tests/corpus/`, README there: generate.py)
//! replayed against the real server on 127.0.0.1:0: every malformed file
//! gets a 4xx with a problem+json body (gRPC: a client-error code), the
//! store is unchanged after each, no panic is counted on `/metrics`, every
//! valid file is accepted, and the peak RSS grows by less than 256 MiB.
//!
//! `INBETWEEN_CORPUS_RECORD=1` rewrites `index.tsv` with the exact status
//! each malformed file got (for review in the diff); without it, a file with
//! a recorded status must get exactly that status again.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use axum::http::{Request, Uri};
use http_body_util::BodyExt;
use serde_json::Value;
use server::Config;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tower::{Service, ServiceExt};

use super::root;
use crate::common::TestApp;

/// Stands for a stored clip's id in http and grpc files (same length as an id).
const CLIP_ID_PLACEHOLDER: &str = "@@@@@@@@-@@@@-@@@@-@@@@-@@@@@@@@@@@@";

/// What the replay server allows (the corpus's over-limit files are just over these).
fn limits(config: &mut Config) {
    config.limits.max_body_bytes = 256 * 1024;
    config.limits.max_tracks = 64;
    config.limits.max_joints = 64;
    config.limits.max_keys_per_track = 1000;
    config.limits.max_import_resolved_bytes = 1024 * 1024;
    // Hundreds of writes in a few seconds over REST and gRPC (one budget):
    // the rate limit has its own test (tests/ops), it is not under test here.
    config.limits.write_rate = 1_000_000;
    config.limits.write_burst = 1_000_000;
}

/// gRPC codes a malformed request may get: the client's mistakes.
const CLIENT_CODES: &[tonic::Code] = &[
    tonic::Code::InvalidArgument,
    tonic::Code::ResourceExhausted,
    tonic::Code::NotFound,
    tonic::Code::FailedPrecondition,
    tonic::Code::OutOfRange,
];

/// The replay server and a gRPC channel for raw calls.
struct Server {
    app: TestApp,
    grpc: tonic::transport::Channel,
}

impl Server {
    async fn start() -> Server {
        let app = TestApp::builder().configure(limits).start().await;
        let grpc = app.channel().await;
        Server { app, grpc }
    }

    fn url(&self, path: &str) -> String {
        self.app.url(path)
    }

    async fn stop(self) {
        self.app.stop().await;
    }

    /// Every stored clip: id, version and document, to prove nothing changed.
    async fn snapshot(&self) -> Vec<(String, u64, String)> {
        let list: Value =
            self.app.http.get(self.url("/v1/clips?limit=1000")).send().await.unwrap().json().await.unwrap();
        let mut all = Vec::new();
        for clip in list["clips"].as_array().unwrap() {
            let id = clip["id"].as_str().unwrap().to_owned();
            let doc =
                self.app.http.get(self.url(&format!("/v1/clips/{id}"))).send().await.unwrap().text().await.unwrap();
            all.push((id, clip["version"].as_u64().unwrap(), doc));
        }
        all
    }

    /// One file as the area says (module docs of generate.py); the outcome
    /// as a status number or a gRPC code name, and whether an error came
    /// with a proper problem body.
    async fn send(&self, area: &str, name: &str, data: Vec<u8>, clip_id: &str) -> Outcome {
        match area {
            // Valid documents may share a name: each a new version of that clip.
            "json" => self.post("/v1/clips?replace=true", "application/json", data).await,
            "gltf" => self.post("/v1/clips/import?format=gltf&replace=true", "model/gltf+json", data).await,
            "glb" => self.post("/v1/clips/import?format=glb&replace=true", "model/gltf-binary", data).await,
            "bvh" => self.post("/v1/clips/import?format=bvh&replace=true", "application/octet-stream", data).await,
            "sniff" => self.post("/v1/clips/import?replace=true", "application/octet-stream", data).await,
            "http" => self.raw_http(&with_id(data, clip_id)).await,
            "grpc" => {
                let method = name.split_once('-').map_or(name, |(_, rest)| rest).split('.').next().unwrap();
                self.raw_grpc(method, with_id(data, clip_id)).await
            }
            other => panic!("unknown area {other}"),
        }
    }

    async fn post(&self, path: &str, content_type: &str, body: Vec<u8>) -> Outcome {
        let response =
            self.app.http.post(self.url(path)).header("content-type", content_type).body(body).send().await.unwrap();
        let status = response.status().as_u16();
        let content_type = response.headers().get("content-type").map(|v| v.to_str().unwrap().to_owned());
        let body = response.bytes().await.unwrap();
        Outcome::http(status, content_type.as_deref(), &body)
    }

    /// Sends a whole HTTP/1.1 request as it is and reads the response until
    /// the server closes (the requests say `Connection: close`).
    async fn raw_http(&self, request: &[u8]) -> Outcome {
        let mut stream = tokio::net::TcpStream::connect(self.app.addr).await.unwrap();
        // The server may answer (413) and close before reading it all.
        let _ = stream.write_all(request).await;
        let mut response = Vec::new();
        let read = tokio::time::timeout(Duration::from_secs(5), stream.read_to_end(&mut response)).await;
        if read.is_err() {
            return Outcome {
                result: "no response within 5 s".into(),
                problem: false,
                grpc: None,
                said: String::new(),
            };
        }
        let text = String::from_utf8_lossy(&response);
        let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
        let status = head.split(' ').nth(1).and_then(|s| s.parse().ok()).unwrap_or(0);
        let content_type = head
            .lines()
            .find_map(|l| l.split_once(':').filter(|(k, _)| k.eq_ignore_ascii_case("content-type")))
            .map(|(_, v)| v.trim().to_owned());
        Outcome::http(status, content_type.as_deref(), dechunk(head, body).as_bytes())
    }

    /// Sends `body` as the request body of `/inbetween.v1.Animation/<method>`
    /// over HTTP/2 (tonic's own channel), and reads the status from the
    /// headers (trailers-only) or the trailers.
    async fn raw_grpc(&self, method: &str, body: Vec<u8>) -> Outcome {
        let uri: Uri = format!("/inbetween.v1.Animation/{method}").parse().unwrap();
        let request = Request::post(uri)
            .header("content-type", "application/grpc")
            .header("te", "trailers")
            .body(tonic::body::Body::new(http_body_util::Full::new(bytes::Bytes::from(body))))
            .unwrap();
        let mut channel = self.grpc.clone();
        let response = channel.ready().await.unwrap().call(request).await.unwrap();
        let (parts, body) = response.into_parts();
        let collected = tokio::time::timeout(Duration::from_secs(10), body.collect()).await;
        let trailers = collected.ok().and_then(Result::ok).and_then(|c| c.trailers().cloned());
        let status = tonic::Status::from_header_map(&parts.headers)
            .or_else(|| trailers.as_ref().and_then(tonic::Status::from_header_map));
        match status {
            Some(status) => {
                let said = status.message().to_owned();
                Outcome { result: format!("{:?}", status.code()), problem: true, grpc: Some(status), said }
            }
            None => Outcome { result: "no-status".into(), problem: false, grpc: None, said: String::new() },
        }
    }
}

/// `data` with the placeholder replaced by `clip_id` (same length).
fn with_id(data: Vec<u8>, clip_id: &str) -> Vec<u8> {
    let placeholder = CLIP_ID_PLACEHOLDER.as_bytes();
    let mut out = data;
    let mut at = 0;
    while let Some(i) = out[at..].windows(placeholder.len()).position(|w| w == placeholder) {
        out[at + i..at + i + placeholder.len()].copy_from_slice(clip_id.as_bytes());
        at += i + placeholder.len();
    }
    out
}

/// The body of a chunked response, joined (others as they are).
fn dechunk(head: &str, body: &str) -> String {
    if !head.to_ascii_lowercase().contains("transfer-encoding: chunked") {
        return body.to_owned();
    }
    let mut out = String::new();
    let mut rest = body;
    while let Some((size, after)) = rest.split_once("\r\n") {
        let Ok(n) = usize::from_str_radix(size.trim(), 16) else { break };
        if n == 0 || after.len() < n {
            break;
        }
        out.push_str(&after[..n]);
        rest = after[n..].trim_start_matches("\r\n");
    }
    out
}

struct Outcome {
    /// The HTTP status number, or the gRPC code's name.
    result: String,
    /// HTTP: a problem+json body with a `code`; gRPC: a status was sent.
    problem: bool,
    grpc: Option<tonic::Status>,
    /// The problem's `code` and `detail` (HTTP), for a failure's message.
    said: String,
}

impl Outcome {
    fn http(status: u16, content_type: Option<&str>, body: &[u8]) -> Outcome {
        let parsed = serde_json::from_slice::<Value>(body).ok();
        let problem = content_type == Some("application/problem+json")
            && parsed.as_ref().is_some_and(|v| v["code"].is_string() && v["status"] == status);
        let said = parsed.map_or_else(String::new, |v| format!("{} {}", v["code"], v["detail"]));
        Outcome { result: status.to_string(), problem, grpc: None, said }
    }

    /// A server error: a 5xx, or its gRPC equivalents.
    fn is_server_error(&self) -> bool {
        use tonic::Code::{DataLoss, Internal, Unavailable, Unknown};
        match &self.grpc {
            Some(status) => matches!(status.code(), Internal | Unknown | DataLoss | Unavailable),
            None => self.result.starts_with('5'),
        }
    }

    /// A client error: a 4xx, or a gRPC client-error code.
    fn is_client_error(&self) -> bool {
        match &self.grpc {
            Some(status) => CLIENT_CODES.contains(&status.code()),
            None => self.result.starts_with('4') && self.result.len() == 3,
        }
    }
}

struct Entry {
    file: String,
    expect: String,
    /// For `@shared/...` entries: the area to send it as.
    area: Option<String>,
}

fn index_path() -> PathBuf {
    root().join("tests/corpus/index.tsv")
}

fn read_index() -> (String, Vec<Entry>) {
    let text = std::fs::read_to_string(index_path()).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().to_owned();
    let entries = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let mut cols = l.split('\t');
            let file = cols.next().unwrap().to_owned();
            let expect = cols.next().expect("an expectation").to_owned();
            Entry { file, expect, area: cols.next().map(str::to_owned) }
        })
        .collect();
    (header, entries)
}

/// The path of an index entry: in tests/corpus, or a real file (`@shared/`:
/// `examples/` when the repository ships it, else ../shared/testdata).
fn resolve(file: &str) -> PathBuf {
    match file.strip_prefix("@shared/") {
        Some(rest) => crate::common::testdata_path(rest),
        None => root().join("tests/corpus").join(file),
    }
}

/// A line of this process's `/proc/self/status` (the server runs in it), in KiB.
fn status_kib(field: &str) -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with(field)).unwrap();
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}

/// Starts a new peak: the tests that ran before this one in the process
/// (a 200 MB import, compressed answers) set their own high-water marks,
/// which are not the corpus's (Linux: `clear_refs` 5 resets `VmHWM`).
/// Returns the resident set now, which the peak is measured from.
fn restart_peak_kib() -> u64 {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
    status_kib("VmRSS:")
}

/// `inbetween_panics_total` summed over its sources (`None` if absent).
async fn panics(server: &Server) -> Option<u64> {
    let text = server.app.http.get(server.url("/metrics")).send().await.unwrap().text().await.unwrap();
    let values: Vec<u64> = text
        .lines()
        .filter(|l| l.starts_with("inbetween_panics_total{"))
        .map(|l| l.rsplit(' ').next().unwrap().parse::<f64>().unwrap() as u64)
        .collect();
    (!values.is_empty()).then(|| values.iter().sum())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_malformed_input_is_refused_and_every_valid_one_accepted() {
    let record = std::env::var_os("INBETWEEN_CORPUS_RECORD").is_some();
    let baseline_kib = restart_peak_kib();
    let server = Server::start().await;
    let wave = std::fs::read(root().join("examples/wave.json")).unwrap();
    let created = server.app.create(std::str::from_utf8(&wave).unwrap(), None).await;
    let clip_id = created["id"].as_str().unwrap().to_owned();
    assert_eq!(clip_id.len(), CLIP_ID_PLACEHOLDER.len());
    assert_eq!(panics(&server).await, Some(0), "inbetween_panics_total is on /metrics at 0");
    let mut before = server.snapshot().await;

    let (header, entries) = read_index();
    let mut failures = Vec::new();
    let mut observed: BTreeMap<String, String> = BTreeMap::new();
    let (mut malformed, mut server_errors, mut by_result) = (0, 0, BTreeMap::<String, usize>::new());
    for entry in entries.iter().filter(|e| e.file.starts_with("malformed/")) {
        let mut parts = entry.file.split('/');
        let (area, name) = (parts.nth(1).unwrap(), parts.next().unwrap());
        let data = std::fs::read(resolve(&entry.file)).unwrap();
        let outcome = server.send(area, name, data, &clip_id).await;
        malformed += 1;
        *by_result.entry(format!("{area} {}", outcome.result)).or_default() += 1;
        if outcome.is_server_error() {
            server_errors += 1;
        }
        if !outcome.is_client_error() || !outcome.problem {
            failures.push(format!("{}: got {} (problem body: {})", entry.file, outcome.result, outcome.problem));
        } else if !record && entry.expect != "4xx" && entry.expect != outcome.result {
            failures
                .push(format!("{}: expected {}, got {} ({})", entry.file, entry.expect, outcome.result, outcome.said));
        }
        observed.insert(entry.file.clone(), outcome.result);
        let now = server.snapshot().await;
        if now != before {
            failures.push(format!("{} changed the store", entry.file));
            before = now;
        }
    }
    assert_eq!(panics(&server).await, Some(0), "no panic while replaying the malformed corpus");

    let mut valid = 0;
    for entry in entries.iter().filter(|e| e.expect == "2xx") {
        let path = resolve(&entry.file);
        let Ok(data) = std::fs::read(&path) else {
            // ../shared/testdata is beside the repository in CI and here; say so if not.
            failures.push(format!("{} is missing", path.display()));
            continue;
        };
        let area = entry.area.clone().unwrap_or_else(|| entry.file.split('/').nth(1).unwrap().to_owned());
        let name = Path::new(&entry.file).file_name().unwrap().to_str().unwrap().to_owned();
        let outcome = server.send(&area, &name, data, &clip_id).await;
        if outcome.result.starts_with('2') {
            valid += 1;
        } else {
            failures.push(format!("valid {}: got {}", entry.file, outcome.result));
        }
    }
    assert_eq!(panics(&server).await, Some(0));
    let peak_mib = status_kib("VmHWM:").saturating_sub(baseline_kib) / 1024;
    server.stop().await;

    if record {
        let mut text = format!("{header}\n");
        for entry in &entries {
            let expect = observed.get(&entry.file).unwrap_or(&entry.expect);
            let area = entry.area.as_deref().map(|a| format!("\t{a}")).unwrap_or_default();
            writeln!(text, "{}\t{expect}{area}", entry.file).unwrap();
        }
        std::fs::write(index_path(), text).unwrap();
    }
    eprintln!(
        "hardening corpus: {malformed} malformed (5xx/INTERNAL: {server_errors}), {valid} valid accepted, \
         peak RSS growth {peak_mib} MiB; outcomes: {by_result:?}"
    );
    assert!(failures.is_empty(), "{} of the corpus failed:\n{}", failures.len(), failures.join("\n"));
    assert!(malformed >= 300 && valid >= 50, "{malformed} malformed, {valid} valid");
    assert_eq!(server_errors, 0);
    assert!(peak_mib < 256, "peak RSS grew by {peak_mib} MiB");
}
