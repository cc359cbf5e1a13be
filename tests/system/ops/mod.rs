//! Operations tests: the real `inbetween` binary (`CARGO_BIN_EXE_inbetween`)
//! spawned on `127.0.0.1:0`, driven over loopback by real clients (reqwest,
//! raw TCP, tokio-tungstenite, tonic). One module per concern; the long runs
//! (`soak`, the overload measurement) need `INBETWEEN_SLOW=1`, the full crash
//! test `CRASH_CYCLES=50`; each has a script in `scripts/` and a row in
//! RELIABILITY.md.

mod answers;
mod builds;
mod caller;
mod checkpoints;
mod connections;
mod crash;
mod overload;
mod shutdown;
mod soak;

use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

pub use crate::common::{ServerProcess, WAVE};

/// `inbetween serve` on `data_dir` with `extra` flags, ready; its log
/// beside the data directory (`data.log`).
pub async fn start(data_dir: &Path, extra: &[&str]) -> ServerProcess {
    ServerProcess::serve().data_dir(data_dir).args(extra).log_to(&data_dir.with_extension("log")).start().await
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
