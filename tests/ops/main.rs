//! Operations tests: the real `inbetween` binary (`CARGO_BIN_EXE_inbetween`)
//! spawned on `127.0.0.1:0`, driven over loopback by real clients (reqwest,
//! raw TCP, tokio-tungstenite, tonic). One module per concern; the long runs
//! (`soak`, the full crash test, the overload measurement) are `#[ignore]`d
//! and have one command each in RELIABILITY.md.

mod caller;
mod connections;
mod crash;
mod overload;
mod shutdown;
mod soak;

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The SPEC §1 example: 2 joints, clip time [0, 3].
pub const WAVE: &str = include_str!("../../examples/wave.json");

/// A running `inbetween serve` process.
pub struct Server {
    pub child: Child,
    pub http: SocketAddr,
    pub grpc: SocketAddr,
    pub data_dir: PathBuf,
    /// How long from spawn until `/readyz` answered 200.
    pub ready_after: Duration,
}

impl Server {
    /// Spawns the binary on free ports with `data_dir` and `extra` flags and
    /// waits (at most 10 s) until `/readyz` answers 200.
    pub async fn start(data_dir: &Path, extra: &[&str]) -> Server {
        let started = Instant::now();
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(data_dir.with_extension("log"))
            .expect("open the server log");
        let mut child = Command::new(env!("CARGO_BIN_EXE_inbetween"))
            .args(["serve", "--listen", "127.0.0.1:0", "--grpc-listen", "127.0.0.1:0", "--data-dir"])
            .arg(data_dir)
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .expect("spawn inbetween");
        let stdout = child.stdout.take().expect("piped stdout");
        let (http, grpc) = tokio::task::spawn_blocking(move || {
            let mut lines = BufReader::new(stdout).lines();
            let mut addr = |prefix: &str| -> SocketAddr {
                let line = lines.next().expect("a listening line").expect("readable stdout");
                line.strip_prefix(prefix).unwrap_or_else(|| panic!("unexpected line `{line}`")).parse().unwrap()
            };
            (addr("inbetween listening on http://"), addr("inbetween gRPC listening on http://"))
        })
        .await
        .unwrap();
        let client = reqwest::Client::new();
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            let ok = client.get(format!("http://{http}/readyz")).send().await.is_ok_and(|r| r.status() == 200);
            if ok {
                break;
            }
            assert!(Instant::now() < deadline, "the server did not become ready within 10 s");
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        Server { child, http, grpc, data_dir: data_dir.to_owned(), ready_after: started.elapsed() }
    }

    pub fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.http)
    }

    pub fn pid(&self) -> i32 {
        i32::try_from(self.child.id()).unwrap()
    }

    /// Resident set size of the server process, from /proc.
    pub fn rss_bytes(&self) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.pid())).unwrap_or_default();
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
            .map_or(0, |kb| kb * 1024)
    }

    /// Sends `signal` (`"TERM"`, `"KILL"`) with kill(1).
    pub fn signal(&self, signal: &str) {
        let ok = Command::new("kill").arg(format!("-{signal}")).arg(self.pid().to_string()).status().unwrap();
        assert!(ok.success(), "kill -{signal} failed");
    }

    /// Waits up to `limit` for the process to exit; `None` if it did not.
    pub async fn wait_exit(&mut self, limit: Duration) -> Option<std::process::ExitStatus> {
        let deadline = Instant::now() + limit;
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return Some(status);
            }
            if Instant::now() >= deadline {
                return None;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// Uploads a JSON clip; returns its id.
    pub async fn create(&self, http: &reqwest::Client, body: &str) -> String {
        let resp = http
            .post(self.url("/v1/clips"))
            .header("content-type", "application/json")
            .body(body.to_owned())
            .send()
            .await
            .unwrap();
        assert_eq!(resp.status(), 201);
        let v: serde_json::Value = resp.json().await.unwrap();
        v["id"].as_str().unwrap().to_owned()
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Opens an HTTP/2 connection to the gRPC port by hand and starts a call of
/// `path` whose request message never comes: a call that stays in flight,
/// from a client that reads nothing (so it also ignores GOAWAY).
pub async fn raw_grpc_call(addr: SocketAddr, path: &str) -> tokio::net::TcpStream {
    use tokio::io::AsyncWriteExt;
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let mut out = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n".to_vec();
    out.extend_from_slice(&[0, 0, 0, 0x4, 0, 0, 0, 0, 0]); // empty SETTINGS
    let mut block = Vec::new();
    for (name, value) in [
        (":method", "POST"),
        (":scheme", "http"),
        (":path", path),
        (":authority", "localhost"),
        ("content-type", "application/grpc"),
        ("te", "trailers"),
    ] {
        // HPACK literal header field without indexing, new name, no Huffman.
        block.push(0);
        block.push(u8::try_from(name.len()).unwrap());
        block.extend_from_slice(name.as_bytes());
        block.push(u8::try_from(value.len()).unwrap());
        block.extend_from_slice(value.as_bytes());
    }
    let len = u32::try_from(block.len()).unwrap().to_be_bytes();
    out.extend_from_slice(&[len[1], len[2], len[3], 0x1, 0x4, 0, 0, 0, 1]); // HEADERS, END_HEADERS, stream 1
    out.extend_from_slice(&block);
    s.write_all(&out).await.unwrap();
    s
}

/// Sends `head` (a request head, possibly incomplete) on a new connection.
pub async fn raw_http(addr: SocketAddr, head: &str) -> tokio::net::TcpStream {
    use tokio::io::AsyncWriteExt;
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    s.write_all(head.as_bytes()).await.unwrap();
    s
}

/// Reads until the peer closes (or `limit` passes); returns what was read
/// and whether the peer closed.
pub async fn read_to_close(s: &mut tokio::net::TcpStream, limit: Duration) -> (Vec<u8>, bool) {
    use tokio::io::AsyncReadExt;
    let mut got = Vec::new();
    let deadline = tokio::time::Instant::now() + limit;
    let mut buf = [0u8; 4096];
    loop {
        match tokio::time::timeout_at(deadline, s.read(&mut buf)).await {
            Ok(Ok(0)) | Ok(Err(_)) => return (got, true),
            Ok(Ok(n)) => got.extend_from_slice(&buf[..n]),
            Err(_) => return (got, false),
        }
    }
}
