//! The floor's bare sender, run as its own process (`inbetween load-floor`):
//! the least work that can deliver the server's frames (see `floor`).
//!
//! The sender does only what every sender must. Connections are spread over
//! the server's phase grid (`stream::Grid::phases`), one task per phase on
//! one thread. Per tick a phase's task re-stamps the frame once (a
//! [`Template`]'s holes: `seq`, `sent_at_unix_nanos`, and `dropped` = 0),
//! frames it once — `ws-json`/`ws-protobuf`: an unmasked server WebSocket
//! frame, text or binary; `tcp`, the gRPC floor: the 5-byte gRPC message
//! prefix, without HTTP/2 — and writes it with one non-blocking write per
//! connection. A `tcp` connection carries as many streams as the gRPC run put
//! on each HTTP/2 connection (the client says how many when it connects), and
//! one `writev` carries a copy for each, as the server's lanes batch a
//! connection's streams. A socket that would block drops that tick and counts
//! it; a write cut short is finished before the connection's next frame.
//!
//! The process reads the frame from stdin (a `u32` big-endian length, then the
//! bytes), prints `{"port", "epoch_unix_ns"}` as its first line, sends until
//! stdin closes (so it cannot outlive the load generator) and prints its
//! [`Tally`] as its last line. Tick `n` of phase `p` is due at `epoch + p ms +
//! ⌊n·10⁹/fps⌋ ns` and its `seq` is `n`, so the load generator measures the
//! floor's lateness on the floor's grid exactly as it does the server's.

use std::io::{ErrorKind, IoSlice, Read};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, bail};
use bytes::{Buf, Bytes, BytesMut};
use prost::encoding::{WireType, decode_key, decode_varint, encode_varint};
use serde::{Deserialize, Serialize};
use tokio::io::AsyncReadExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};

use crate::clock::{ClockSync, unix_now_ns};
use crate::{Mode, Options};
use formats::wire::grid::{self, PHASE_HEADER};

/// How long a connection may take to say what it carries.
const HANDSHAKE: Duration = Duration::from_secs(10);
/// The most streams one `tcp` connection may carry.
pub const MAX_COPIES: usize = 4096;
/// Frames one `writev` takes at most.
const IOV: usize = 128;
/// The largest frame the floor accepts on stdin.
const MAX_FRAME: usize = 64 << 20;

/// What the floor sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// WebSocket text frames of JSON.
    WsJson,
    /// WebSocket binary frames of protobuf.
    WsProtobuf,
    /// gRPC messages (the 5-byte prefix and a protobuf `Frame`) on raw TCP.
    Tcp,
}

impl Kind {
    pub fn as_str(self) -> &'static str {
        match self {
            Kind::WsJson => "ws-json",
            Kind::WsProtobuf => "ws-protobuf",
            Kind::Tcp => "tcp",
        }
    }

    /// The floor of a run's mode and encoding.
    pub fn of(opts: &Options) -> Kind {
        match (opts.mode, opts.ws_protobuf) {
            (Mode::GrpcStream, _) => Kind::Tcp,
            (_, false) => Kind::WsJson,
            (_, true) => Kind::WsProtobuf,
        }
    }

    /// The frame of tick `seq`, framed for the wire.
    fn frame(self, template: &Template, seq: u64, sent_at: i64) -> Bytes {
        let mut payload = Vec::with_capacity(template.bytes.len() + 16);
        template.stamp(seq, sent_at, &mut payload);
        let mut out = Vec::with_capacity(payload.len() + 10);
        match self {
            Kind::WsJson => ws_header(payload.len(), false, &mut out),
            Kind::WsProtobuf => ws_header(payload.len(), true, &mut out),
            Kind::Tcp => grpc_prefix(payload.len(), &mut out),
        }
        out.extend_from_slice(&payload);
        Bytes::from(out)
    }
}

/// The header of an unmasked, final server WebSocket frame (RFC 6455 §5.2):
/// FIN and opcode 1 (text) or 2 (binary), then the payload length in 7 bits,
/// or 126 and 16 bits, or 127 and 64 bits, big-endian.
pub fn ws_header(len: usize, binary: bool, out: &mut Vec<u8>) {
    out.push(0x80 | if binary { 0x2 } else { 0x1 });
    if len < 126 {
        out.push(len as u8);
    } else if len < 1 << 16 {
        out.push(126);
        out.extend_from_slice(&(len as u16).to_be_bytes());
    } else {
        out.push(127);
        out.extend_from_slice(&(len as u64).to_be_bytes());
    }
}

/// The gRPC length prefix: not compressed, then the length as a big-endian `u32`.
fn grpc_prefix(len: usize, out: &mut Vec<u8>) {
    out.push(0);
    out.extend_from_slice(&(len as u32).to_be_bytes());
}

/// A frame's header numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Hole {
    Seq,
    SentAt,
    Dropped,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Piece {
    Bytes(usize, usize),
    Hole(Hole),
}

/// A frame with holes where its header's numbers go: everything else is
/// sent as it came from the server, byte for byte.
#[derive(Debug, Clone)]
pub struct Template {
    bytes: Bytes,
    pieces: Vec<Piece>,
    json: bool,
}

impl Template {
    /// A JSON frame as the server writes it: the numbers of `"seq"`,
    /// `"sent_at_unix_nanos"` and `"dropped"` before `"events"`.
    ///
    /// # Errors
    /// Not UTF-8, or one of the three is not before `"events"`.
    pub fn json(frame: &[u8]) -> anyhow::Result<Template> {
        let text = std::str::from_utf8(frame).context("a JSON frame is UTF-8")?;
        let head = &text[..text.find(",\"events\":").context("no \"events\" in the JSON frame")?];
        let mut holes = Vec::new();
        for (key, hole) in
            [("\"seq\":", Hole::Seq), ("\"sent_at_unix_nanos\":", Hole::SentAt), ("\"dropped\":", Hole::Dropped)]
        {
            let at = head.find(key).with_context(|| format!("no {key} before \"events\""))? + key.len();
            let len = head[at..].find(|c: char| !(c.is_ascii_digit() || c == '-')).unwrap_or(head.len() - at);
            holes.push((at, at + len, hole));
        }
        Ok(Template::with_holes(frame, holes, true))
    }

    /// A protobuf `Frame`: every top-level `seq` (1), `sent_at_unix_nanos`
    /// (3) and `dropped` (4), wherever they are.
    ///
    /// # Errors
    /// Not a protobuf message, or no `seq` or `sent_at_unix_nanos`.
    pub fn protobuf(frame: &[u8]) -> anyhow::Result<Template> {
        let mut buf = frame;
        let mut holes = Vec::new();
        while buf.has_remaining() {
            let (tag, wire_type) = decode_key(&mut buf)?;
            let at = frame.len() - buf.len();
            let skip = match wire_type {
                WireType::Varint => {
                    decode_varint(&mut buf)?;
                    0
                }
                WireType::SixtyFourBit => 8,
                WireType::ThirtyTwoBit => 4,
                WireType::LengthDelimited => usize::try_from(decode_varint(&mut buf)?)?,
                WireType::StartGroup | WireType::EndGroup => bail!("groups are not used in a Frame"),
            };
            if buf.len() < skip {
                bail!("a field runs past the frame's end");
            }
            buf.advance(skip);
            let end = frame.len() - buf.len();
            let hole = match (tag, wire_type) {
                (1, WireType::Varint) => Some(Hole::Seq),
                (3, WireType::Varint) => Some(Hole::SentAt),
                (4, WireType::Varint) => Some(Hole::Dropped),
                _ => None,
            };
            holes.extend(hole.map(|h| (at, end, h)));
        }
        for needed in [Hole::Seq, Hole::SentAt] {
            if !holes.iter().any(|&(_, _, h)| h == needed) {
                bail!("the frame has no {needed:?}");
            }
        }
        Ok(Template::with_holes(frame, holes, false))
    }

    /// `holes` are (start, end, hole), not overlapping.
    fn with_holes(frame: &[u8], mut holes: Vec<(usize, usize, Hole)>, json: bool) -> Template {
        holes.sort_by_key(|h| h.0);
        let mut pieces = Vec::new();
        let mut at = 0;
        for (start, end, hole) in holes {
            pieces.push(Piece::Bytes(at, start));
            pieces.push(Piece::Hole(hole));
            at = end;
        }
        pieces.push(Piece::Bytes(at, frame.len()));
        pieces.retain(|p| !matches!(p, Piece::Bytes(a, b) if a == b));
        Template { bytes: Bytes::copy_from_slice(frame), pieces, json }
    }

    /// The frame with these numbers (and `dropped` 0), appended to `out`.
    pub fn stamp(&self, seq: u64, sent_at: i64, out: &mut Vec<u8>) {
        for piece in &self.pieces {
            match *piece {
                Piece::Bytes(a, b) => out.extend_from_slice(&self.bytes[a..b]),
                Piece::Hole(hole) => {
                    let (unsigned, signed) = match hole {
                        Hole::Seq => (seq, None),
                        Hole::SentAt => (sent_at as u64, Some(sent_at)),
                        Hole::Dropped => (0, None),
                    };
                    match (self.json, signed) {
                        (false, _) => encode_varint(unsigned, out),
                        (true, Some(v)) => out.extend_from_slice(v.to_string().as_bytes()),
                        (true, None) => out.extend_from_slice(unsigned.to_string().as_bytes()),
                    }
                }
            }
        }
    }

    /// The template's frame as it came.
    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }
}

/// What the sender did over its life, summed over its phases.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Tally {
    /// Connections accepted.
    pub connections: u64,
    /// Ticks with at least one connection (summed over phases).
    pub ticks: u64,
    /// Write system calls.
    pub writes: u64,
    /// Stream frames written (whole or begun), and dropped because a socket would block.
    pub frames: u64,
    pub dropped: u64,
    /// Writes cut short (finished before the connection's next frame).
    pub short_writes: u64,
}

impl Tally {
    fn add(&mut self, o: &Tally) {
        self.connections += o.connections;
        self.ticks += o.ticks;
        self.writes += o.writes;
        self.frames += o.frames;
        self.dropped += o.dropped;
        self.short_writes += o.short_writes;
    }
}

/// The floor's first line.
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct Hello {
    pub(super) port: u16,
    pub(super) epoch_unix_ns: i64,
}

/// The floor process (`inbetween load-floor`; module doc).
///
/// # Errors
/// No frame on stdin, a frame that is not of `kind`, an fps out of 1..=240,
/// or no loopback port to bind.
pub fn run_sender(kind: Kind, fps: u32) -> anyhow::Result<()> {
    if !(1..=240).contains(&fps) {
        bail!("--fps must be 1..=240");
    }
    let mut stdin = std::io::stdin();
    let mut len = [0u8; 4];
    stdin.read_exact(&mut len).context("reading the frame's length from stdin")?;
    let len = u32::from_be_bytes(len) as usize;
    if len > MAX_FRAME {
        bail!("a {len}-byte frame is more than the floor sends");
    }
    let mut frame = vec![0; len];
    stdin.read_exact(&mut frame).context("reading the frame from stdin")?;
    let template = match kind {
        Kind::WsJson => Template::json(&frame)?,
        Kind::WsProtobuf | Kind::Tcp => Template::protobuf(&frame)?,
    };
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    runtime.block_on(async move {
        let listener = TcpListener::bind("127.0.0.1:0").await?;
        let (base, epoch_unix_ns) = (Instant::now(), unix_now_ns());
        let hello = Hello { port: listener.local_addr()?.port(), epoch_unix_ns };
        println!("{}", serde_json::to_string(&hello)?);
        // Stdin's end is the signal to stop: the thread ends with it.
        let (stop_tx, stop_rx) = watch::channel(false);
        std::thread::spawn(move || {
            let _ = std::io::copy(&mut stdin, &mut std::io::sink());
            stop_tx.send_replace(true);
        });
        let tally = serve(listener, kind, fps, template, base, stop_rx).await;
        println!("{}", serde_json::to_string(&tally)?);
        Ok::<(), anyhow::Error>(())
    })
}

/// Sends `template` at `fps` to every connection `listener` accepts until
/// `stop`, with tick `n` of phase `p` due at `base + p ms + n/fps`.
pub async fn serve(
    listener: TcpListener,
    kind: Kind,
    fps: u32,
    template: Template,
    base: Instant,
    mut stop: watch::Receiver<bool>,
) -> Tally {
    let phases = grid::phases(fps);
    let template = Arc::new(template);
    let mut joins = Vec::new();
    let mut groups = Vec::new();
    for phase in 0..phases {
        let (tx, rx) = mpsc::unbounded_channel();
        joins.push(tx);
        let grid = PhaseGrid { base, phase_ms: phase, fps };
        groups.push(tokio::spawn(send_phase(grid, kind, Arc::clone(&template), rx, stop.clone())));
    }
    let mut handshakes = tokio::task::JoinSet::new();
    let mut accepted = 0u64;
    loop {
        let stream = tokio::select! {
            r = listener.accept() => match r {
                Ok((s, _)) => s,
                // Out of descriptors: wait instead of spinning.
                Err(_) => {
                    tokio::time::sleep(Duration::from_millis(10)).await;
                    continue;
                }
            },
            _ = stopped(&mut stop) => break,
        };
        let phase = (accepted % u64::from(phases)) as u32;
        accepted += 1;
        let join = joins[phase as usize].clone();
        handshakes.spawn(async move {
            if let Ok(Ok(conn)) = tokio::time::timeout(HANDSHAKE, open(stream, kind, phase)).await {
                let _ = join.send(conn);
            }
        });
        while handshakes.try_join_next().is_some() {}
    }
    handshakes.abort_all();
    let mut tally = Tally { connections: accepted, ..Tally::default() };
    for group in groups {
        if let Ok(t) = group.await {
            tally.add(&t);
        }
    }
    tally
}

async fn stopped(stop: &mut watch::Receiver<bool>) {
    let _ = stop.wait_for(|s| *s).await;
}

/// A connection once it has said what it carries: `tcp` reads the number
/// of streams (`u32` big-endian); `ws` answers the WebSocket handshake with
/// the connection's phase in `stream::PHASE_HEADER`, then writes frames
/// straight to the socket.
async fn open(mut stream: TcpStream, kind: Kind, phase: u32) -> anyhow::Result<Conn> {
    stream.set_nodelay(true)?;
    let copies = match kind {
        Kind::Tcp => {
            let copies = stream.read_u32().await? as usize;
            if !(1..=MAX_COPIES).contains(&copies) {
                bail!("{copies} streams on one connection");
            }
            copies
        }
        Kind::WsJson | Kind::WsProtobuf => {
            #[allow(clippy::result_large_err)] // the signature tungstenite's `Callback` asks for
            let with_phase = move |_: &Request, mut response: Response| -> Result<Response, ErrorResponse> {
                response.headers_mut().insert(PHASE_HEADER, phase.into());
                Ok(response)
            };
            stream = tokio_tungstenite::accept_hdr_async(stream, with_phase).await?.into_inner();
            1
        }
    };
    Ok(Conn { stream, copies, pending: Bytes::new() })
}

/// When a phase's ticks are due.
#[derive(Debug, Clone, Copy)]
struct PhaseGrid {
    base: Instant,
    phase_ms: u32,
    fps: u32,
}

impl PhaseGrid {
    fn at(&self, n: u64) -> Instant {
        let ns = u128::from(n) * 1_000_000_000 / u128::from(self.fps);
        self.base + Duration::from_millis(self.phase_ms.into()) + Duration::from_nanos(ns as u64)
    }
}

/// One phase's connections: per tick, one stamp and one write each. A late
/// wake-up skips to the latest due tick, as the server does.
async fn send_phase(
    grid: PhaseGrid,
    kind: Kind,
    template: Arc<Template>,
    mut joins: mpsc::UnboundedReceiver<Conn>,
    mut stop: watch::Receiver<bool>,
) -> Tally {
    let mut tally = Tally::default();
    let mut conns: Vec<Conn> = Vec::new();
    let mut n = 0u64;
    loop {
        tokio::select! {
            _ = tokio::time::sleep_until(grid.at(n)) => {}
            _ = stopped(&mut stop) => return tally,
        }
        let now = Instant::now();
        while grid.at(n + 1) <= now {
            n += 1;
        }
        while let Ok(conn) = joins.try_recv() {
            conns.push(conn);
        }
        if !conns.is_empty() {
            tally.ticks += 1;
            let frame = kind.frame(&template, n, unix_now_ns());
            conns.retain_mut(|c| c.send(&frame, &mut tally));
        }
        n += 1;
    }
}

/// An accepted connection carrying `copies` streams.
struct Conn {
    stream: TcpStream,
    copies: usize,
    /// The rest of a write cut short.
    pending: Bytes,
}

impl Conn {
    /// Writes `frame` once per stream; `false` when the peer has gone.
    fn send(&mut self, frame: &Bytes, tally: &mut Tally) -> bool {
        let copies = self.copies as u64;
        if !self.pending.is_empty() {
            match self.stream.try_write(&self.pending) {
                Ok(0) => return false,
                Ok(k) => {
                    tally.writes += 1;
                    self.pending.advance(k);
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => {}
                Err(_) => return false,
            }
            if !self.pending.is_empty() {
                tally.dropped += copies;
                return true;
            }
        }
        let (len, total) = (frame.len(), frame.len() * self.copies);
        let mut sent = 0;
        while sent < total {
            let skip = sent % len;
            let whole = ((total - sent - (len - skip)) / len).min(IOV - 1);
            let mut iov = [IoSlice::new(&[]); IOV];
            iov[0] = IoSlice::new(&frame[skip..]);
            for slot in &mut iov[1..=whole] {
                *slot = IoSlice::new(frame);
            }
            match self.stream.try_write_vectored(&iov[..=whole]) {
                Ok(0) => return false,
                Ok(k) => {
                    tally.writes += 1;
                    sent += k;
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(_) => return false,
            }
        }
        if sent == 0 {
            tally.dropped += copies;
            return true;
        }
        tally.frames += copies;
        if sent < total {
            tally.short_writes += 1;
            let mut rest = BytesMut::with_capacity(total - sent);
            rest.extend_from_slice(&frame[sent % len..]);
            for _ in 0..(total - sent - (len - sent % len)) / len {
                rest.extend_from_slice(frame);
            }
            self.pending = rest.freeze();
        }
        true
    }
}

/// Where the floor's streams connect, and its grid's clock.
#[derive(Debug, Clone, Copy)]
pub struct Target {
    pub port: u16,
    pub pid: u32,
    pub clock: ClockSync,
}

#[cfg(test)]
mod tests {
    use prost::Message;
    use prost::encoding::encode_key;

    use super::*;
    use formats::wire::proto::pb;

    fn header(len: usize, binary: bool) -> Vec<u8> {
        let mut out = Vec::new();
        ws_header(len, binary, &mut out);
        out
    }

    /// RFC 6455 §5.2, bytes worked out by hand: 0x81 is FIN + text, 0x82
    /// FIN + binary; the length in 7 bits up to 125, 126 + 16 bits up to
    /// 65,535, 127 + 64 bits beyond; no mask bit (a server's frames).
    #[test]
    fn websocket_headers_follow_rfc_6455() {
        assert_eq!(header(0, false), [0x81, 0x00]);
        assert_eq!(header(125, true), [0x82, 0x7d]);
        assert_eq!(header(126, false), [0x81, 0x7e, 0x00, 0x7e]);
        assert_eq!(header(1000, true), [0x82, 0x7e, 0x03, 0xe8]);
        assert_eq!(header(65_535, true), [0x82, 0x7e, 0xff, 0xff]);
        assert_eq!(header(65_536, false), [0x81, 0x7f, 0, 0, 0, 0, 0, 0x01, 0x00, 0x00]);
        assert_eq!(header(0x0001_0203_0405, true), [0x82, 0x7f, 0, 0, 0, 0x01, 0x02, 0x03, 0x04, 0x05]);
    }

    /// A protobuf frame's header written as the server writes it: `seq`,
    /// `clip_time`, `sent_at_unix_nanos`, `dropped` (always present).
    fn pb_head(seq: u64, sent_at: i64, dropped: u64) -> Vec<u8> {
        let mut out = Vec::new();
        encode_key(1, WireType::Varint, &mut out);
        encode_varint(seq, &mut out);
        encode_key(2, WireType::ThirtyTwoBit, &mut out);
        out.extend_from_slice(&0.25f32.to_le_bytes());
        encode_key(3, WireType::Varint, &mut out);
        encode_varint(sent_at as u64, &mut out);
        encode_key(4, WireType::Varint, &mut out);
        encode_varint(dropped, &mut out);
        out
    }

    /// Re-stamping changes the header's numbers (even their length) and
    /// nothing else: the events and the pose are the same bytes.
    #[test]
    fn a_protobuf_frame_is_restamped_and_the_rest_kept() {
        let body = pb::Frame {
            events: vec![pb::Event { time: 0.25, name: "step".into() }],
            pose: Some(pb::Pose {
                translations: vec![1.0, 2.0, 3.0],
                rotations: vec![0.0, 0.0, 0.0, 1.0],
                ..Default::default()
            }),
            ..Default::default()
        }
        .encode_to_vec();
        let frame = [pb_head(3, 1_764_000_000_000_000_000, 2), body.clone()].concat();
        let template = Template::protobuf(&frame).unwrap();
        assert_eq!(template.len(), frame.len());
        for (seq, sent_at) in [(3, 1_764_000_000_000_000_000), (300, 1_800_000_000_123_456_789), (0, 1)] {
            let mut out = Vec::new();
            template.stamp(seq, sent_at, &mut out);
            assert_eq!(out, [pb_head(seq, sent_at, 0), body.clone()].concat(), "seq {seq}");
            let decoded = pb::Frame::decode(&out[..]).unwrap();
            assert_eq!((decoded.seq, decoded.sent_at_unix_nanos, decoded.dropped), (seq, sent_at, 0));
        }
        // A `dropped` the server appended for one viewer is zeroed too.
        let mut patched = frame.clone();
        encode_key(4, WireType::Varint, &mut patched);
        encode_varint(9, &mut patched);
        let mut out = Vec::new();
        Template::protobuf(&patched).unwrap().stamp(4, 5, &mut out);
        assert_eq!(pb::Frame::decode(&out[..]).unwrap().dropped, 0);
        assert!(Template::protobuf(&body).is_err(), "no seq");
        assert!(Template::protobuf(&frame[..frame.len() - 1]).is_err(), "cut short");
    }

    #[test]
    fn a_json_frame_is_restamped_and_the_rest_kept() {
        let frame = |seq: &str, sent_at: &str, dropped: &str| {
            format!(
                r#"{{"seq":{seq},"clip_time":0.25,"sent_at_unix_nanos":{sent_at},"dropped":{dropped},"events":[{{"time":0.25,"name":"seq"}}],"pose":{{"joints":[{{"name":"dropped","translation":[0,1,2]}}]}}}}"#
            )
        };
        let template = Template::json(frame("3", "1764000000000000000", "2").as_bytes()).unwrap();
        for (seq, sent_at) in [(3u64, 1_764_000_000_000_000_000i64), (123_456, 1_800_000_000_123_456_789), (0, -5)] {
            let mut out = Vec::new();
            template.stamp(seq, sent_at, &mut out);
            assert_eq!(String::from_utf8(out).unwrap(), frame(&seq.to_string(), &sent_at.to_string(), "0"));
        }
        assert!(Template::json(br#"{"seq":1,"dropped":0,"events":[]}"#).is_err(), "no sent_at");
        assert!(Template::json(br#"{"seq":1}"#).is_err(), "no events");
    }
}
