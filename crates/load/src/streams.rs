//! Stream modes: `grpc-stream` (`StreamFrames`) and `ws-stream` (the
//! WebSocket route), N streams at F fps.
//!
//! Independent streams ask for different start times, so each is its own
//! playback on the server; `--shared` streams ask for the same one, so those
//! that join within the same tick share one evaluation per tick (the server
//! matches viewers by their first grid tick; the report shows how many
//! playbacks it started). Streams are opened at most [`OPENING`] at a time;
//! the measured window starts once every stream has delivered a frame (or
//! the opening deadline passed) plus a settling second, and lasts the
//! duration. Frames received outside the window are not recorded. A stream
//! that ends or fails inside the run is reopened (a `reconnect`).
//!
//! With a motion, gRPC streams send it in `StreamRequest.motion`; WebSocket
//! streams open `GET /v1/stream` and send it in the `open` message, and
//! read the grid phase from the server's `opened` answer (the upgrade's
//! headers are sent before the motion is known).
//!
//! `ws-broadcast` viewers open `GET /v1/broadcasts/{id}/stream` of the one
//! broadcast the run created (see `broadcast`) and are measured like any
//! WebSocket stream; the server counters are then the broadcast's
//! (broadcasts created, broadcast ticks evaluated), and the broadcast is
//! deleted when the run ends.
//!
//! With a floor (`floor`), the same streams are measured against the bare
//! sender instead: WebSocket streams open `ws://127.0.0.1:{port}/`, and the
//! gRPC floor's streams share raw TCP connections as they shared HTTP/2 ones,
//! each connection's reader handing every stream its frames (as tonic's
//! connection task does); the clock is the floor's grid, and there are no
//! server counters.
//!
//! Clients decode only the frame header (`seq`, `sent_at_unix_nanos`,
//! `dropped`): the gRPC side through a codec for a three-field message
//! (protobuf skips the pose), the WebSocket side by skipping the pose while
//! parsing JSON. On a 2-core machine the client's CPU is the server's too.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicI64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context;
use bytes::Bytes;
use futures_util::{SinkExt, StreamExt};
use serde::Deserialize;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{Semaphore, mpsc, watch};
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tonic::codegen::http::uri::PathAndQuery;
use tonic::transport::Channel;

use super::clock::{ClockSync, unix_now_ns};
use super::floor::sender::{MAX_COPIES, Target};
use super::histogram::Latency;
use super::lateness::StreamTracker;
use super::motion::{Playable, SetCycle};
use super::procstat::{self, ProcSample};
use super::report::{Report, ServerUsage, StreamStats};
use super::{Env, Mode, Options, broadcast, setup};
use formats::wire::frame::WireFrame;
use formats::wire::grid::PHASE_HEADER;
use formats::wire::proto::pb;

/// Streams being opened at once.
const OPENING: usize = 64;
/// gRPC streams per HTTP/2 connection when `--connections` is not given.
const STREAMS_PER_CONNECTION: usize = 100;
/// Time given to the server to settle after the last stream opened.
const SETTLE: Duration = Duration::from_secs(1);
/// How long opening one stream may take.
const OPEN_TIMEOUT: Duration = Duration::from_secs(10);
/// A WebSocket client's read buffer. tungstenite zero-fills the buffer's
/// free space before each read, one or two a frame: with its default
/// (128 KiB) that memset was 28 % of the generator's CPU in a broadcast run.
/// A frame bigger than this reserves its own length when its header arrives.
const READ_BUFFER_BYTES: usize = 8 * 1024;

/// The header of a `Frame` (docs/api.md): protobuf skips the other fields.
#[derive(Clone, PartialEq, prost::Message)]
pub struct FrameHead {
    #[prost(uint64, tag = "1")]
    pub seq: u64,
    #[prost(int64, tag = "3")]
    pub sent_at_unix_nanos: i64,
    #[prost(uint64, tag = "4")]
    pub dropped: u64,
}

/// The same header of a JSON frame; serde skips the pose and events.
#[derive(Deserialize)]
struct JsonHead {
    seq: u64,
    sent_at_unix_nanos: i64,
    dropped: u64,
}

/// A JSON frame's header. The server writes `seq`, `clip_time`,
/// `sent_at_unix_nanos` and `dropped` before the events and the pose, so
/// only that prefix is read: skipping a pose with serde cost the client
/// about what writing it cost the server, on the same two cores. A frame
/// written in another order is parsed whole.
fn json_head(text: &str) -> Option<JsonHead> {
    let head = text.find(",\"events\":").map(|end| &text[..end]);
    let number = |key: &str| {
        let head = head?;
        let at = head.find(key)? + key.len();
        let digits = head[at..].split(|c: char| !(c.is_ascii_digit() || c == '-')).next()?;
        digits.parse::<i64>().ok()
    };
    match (number("\"seq\":"), number("\"sent_at_unix_nanos\":"), number("\"dropped\":")) {
        (Some(seq), Some(sent_at_unix_nanos), Some(dropped)) if seq >= 0 && dropped >= 0 => {
            Some(JsonHead { seq: seq as u64, sent_at_unix_nanos, dropped: dropped as u64 })
        }
        _ => serde_json::from_str(text).ok(),
    }
}

/// The measured window on the local wall clock (ns; 0 = not set yet).
struct Window {
    start: AtomicI64,
    end: AtomicI64,
    opened: AtomicUsize,
}

#[derive(Default)]
struct StreamResult {
    frames: u64,
    dropped: u64,
    gaps: u64,
    reconnects: u64,
    opened: bool,
    errors: BTreeMap<String, u64>,
}

impl StreamResult {
    fn error(&mut self, kind: impl Into<String>) {
        *self.errors.entry(kind.into()).or_default() += 1;
    }

    fn merge(&mut self, o: &StreamResult) {
        self.frames += o.frames;
        self.dropped += o.dropped;
        self.gaps += o.gaps;
        self.reconnects += o.reconnects;
        for (k, v) in &o.errors {
            *self.errors.entry(k.clone()).or_default() += v;
        }
    }
}

/// The lateness histograms of a group of streams. An HDR histogram is a few
/// hundred KiB; one set per stream took 24 GiB for 20,000 streams, so
/// [`GROUP`] streams share one set (each frame takes its lock for a few
/// ns: 100 streams at 60 fps are 6,000 uncontended locks a second).
#[derive(Debug, Default)]
struct Hists {
    send: Latency,
    receive: Latency,
    jitter: Latency,
    first_tenth: Latency,
    last_tenth: Latency,
}

impl Hists {
    fn merge(&mut self, o: &Hists) {
        self.send.merge(&o.send);
        self.receive.merge(&o.receive);
        self.jitter.merge(&o.jitter);
        self.first_tenth.merge(&o.first_tenth);
        self.last_tenth.merge(&o.last_tenth);
    }
}

/// Streams per shared set of histograms.
const GROUP: usize = 100;

/// What one stream task needs.
#[derive(Clone)]
struct Spec {
    mode: Mode,
    ws_base: String,
    ws_protobuf: bool,
    clip_id: String,
    motion: Option<Arc<Playable>>,
    /// A graph stream's parameter set once a second.
    set_cycle: Option<Arc<SetCycle>>,
    /// When in its second this stream sends its sets: the streams' sets
    /// spread over the second, as players' inputs are, not all at once.
    set_phase: Duration,
    fps: u32,
    /// `ws-broadcast`: the broadcast the viewers watch.
    broadcast: Option<String>,
    /// The floor the streams connect to instead of the server.
    floor: Option<Target>,
    clock: ClockSync,
    window: Arc<Window>,
    opening: Arc<Semaphore>,
}

/// A frame header, or the end of the stream (with why, if it failed).
#[derive(Debug)]
enum Got {
    Frame(u64, i64, u64),
    End(Option<String>),
}

/// The server's first message on `GET /v1/stream`: its grid phase, or
/// why it refused the motion.
#[derive(Deserialize)]
struct OpenAnswer {
    opened: Option<Opened>,
    error: Option<OpenProblem>,
}

#[derive(Deserialize)]
struct Opened {
    grid_phase_ms: u32,
}

#[derive(Deserialize)]
struct OpenProblem {
    code: String,
}

type WebSocket = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// An open stream of either transport.
enum Open {
    Grpc(Box<tonic::Streaming<FrameHead>>),
    Ws(Box<WebSocket>, bool, Option<Setter>),
    /// A stream of a shared floor connection: what its reader hands it.
    Floor(mpsc::UnboundedReceiver<Got>),
}

/// What a stream connects through.
#[derive(Clone)]
enum Link {
    /// An HTTP/2 connection to the server's gRPC port.
    Grpc(Channel),
    /// Its own connection (a WebSocket).
    Own,
    /// Its place on a floor connection, taken when it opens.
    Floor(Arc<Mutex<Option<mpsc::UnboundedReceiver<Got>>>>),
}

impl Open {
    async fn next(&mut self) -> Got {
        match self {
            Open::Grpc(s) => match s.message().await {
                Ok(Some(f)) => Got::Frame(f.seq, f.sent_at_unix_nanos, f.dropped),
                Ok(None) => Got::End(Some("ended".into())),
                Err(status) => Got::End(Some(format!("grpc:{:?}", status.code()))),
            },
            Open::Ws(ws, protobuf, setter) => loop {
                let due = setter.as_ref().map(|s| s.due);
                let message = tokio::select! {
                    m = ws.next() => m,
                    () = sleep_until_some(due) => {
                        let control = setter.as_mut().map(Setter::next).unwrap_or_default();
                        if ws.send(Message::Text(control.into())).await.is_err() {
                            return Got::End(Some("ws_error".into()));
                        }
                        continue;
                    }
                };
                match message {
                    Some(Ok(Message::Text(t))) if !*protobuf => match json_head(&t) {
                        Some(h) => return Got::Frame(h.seq, h.sent_at_unix_nanos, h.dropped),
                        None => return Got::End(Some("bad_frame".into())),
                    },
                    Some(Ok(Message::Binary(b))) if *protobuf => match <FrameHead as prost::Message>::decode(b) {
                        Ok(h) => return Got::Frame(h.seq, h.sent_at_unix_nanos, h.dropped),
                        Err(_) => return Got::End(Some("bad_frame".into())),
                    },
                    Some(Ok(Message::Ping(_) | Message::Pong(_))) => continue,
                    Some(Ok(Message::Close(c))) => {
                        return Got::End(Some(c.map_or("closed".into(), |c| format!("closed:{}", u16::from(c.code)))));
                    }
                    Some(Ok(_)) => return Got::End(Some("unexpected_message".into())),
                    Some(Err(_)) => return Got::End(Some("ws_error".into())),
                    None => return Got::End(Some("ended".into())),
                }
            },
            Open::Floor(frames) => frames.recv().await.unwrap_or(Got::End(Some("ended".into()))),
        }
    }

    async fn close(self) {
        if let Open::Ws(mut ws, _, _) = self {
            let _ = tokio::time::timeout(Duration::from_secs(1), ws.close()).await;
        }
    }
}

impl Spec {
    /// Opens a stream; with it, the grid phase the server announced.
    async fn open(&self, link: &Link, start_time: f64) -> Result<(Open, Option<u32>), String> {
        match (self.mode, link) {
            (_, Link::Floor(frames)) => {
                let frames = lock(frames).take().ok_or_else(|| "floor_connection_gone".to_string())?;
                Ok((Open::Floor(frames), None))
            }
            (Mode::GrpcStream, Link::Grpc(channel)) => self.open_grpc(channel, start_time).await,
            (Mode::GrpcStream, Link::Own) => Err("no_channel".into()),
            _ => {
                let encoding = if self.ws_protobuf { "protobuf" } else { "json" };
                let url = match (&self.broadcast, &self.motion) {
                    _ if self.floor.is_some() => format!("ws://127.0.0.1:{}/", self.floor.map_or(0, |f| f.port)),
                    (Some(id), _) => format!("{}v1/broadcasts/{id}/stream?encoding={encoding}", self.ws_base),
                    (None, None) => format!(
                        "{}v1/clips/{}/stream?fps={}&start={start_time}&encoding={encoding}",
                        self.ws_base, self.clip_id, self.fps
                    ),
                    (None, Some(_)) => format!("{}v1/stream", self.ws_base),
                };
                let config = WebSocketConfig::default().read_buffer_size(READ_BUFFER_BYTES);
                let connected = tokio_tungstenite::connect_async_with_config(url, Some(config), false).await;
                let (mut ws, resp) = connected.map_err(|e| match e {
                    tokio_tungstenite::tungstenite::Error::Http(r) => format!("http:{}", r.status().as_u16()),
                    _ => "connect".to_string(),
                })?;
                let phase = match self.motion.as_ref().filter(|_| self.broadcast.is_none() && self.floor.is_none()) {
                    None => resp.headers().get(PHASE_HEADER).and_then(|v| v.to_str().ok()?.parse().ok()),
                    Some(motion) => {
                        // A graph plays from its start: every stream at time 0.
                        let start = if motion.graph { 0.0 } else { start_time };
                        let open = serde_json::json!({"op": "open", "motion": motion.json, "fps": self.fps,
                                                      "start": start, "encoding": encoding});
                        Some(open_motion(&mut ws, open.to_string()).await?)
                    }
                };
                let setter = self.set_cycle.clone().map(|cycle| Setter::new(cycle, self.set_phase));
                Ok((Open::Ws(Box::new(ws), self.ws_protobuf, setter), phase))
            }
        }
    }

    async fn open_grpc(&self, channel: &Channel, start_time: f64) -> Result<(Open, Option<u32>), String> {
        let resp = self.grpc_stream::<FrameHead>(channel, start_time).await?;
        let phase = resp.metadata().get(PHASE_HEADER).and_then(|v| v.to_str().ok()?.parse().ok());
        Ok((Open::Grpc(Box::new(resp.into_inner())), phase))
    }

    /// A `StreamFrames` call whose frames decode as `T`.
    async fn grpc_stream<T: prost::Message + Default + Send + 'static>(
        &self,
        channel: &Channel,
        start_time: f64,
    ) -> Result<tonic::Response<tonic::Streaming<T>>, String> {
        let mut grpc = tonic::client::Grpc::new(channel.clone());
        grpc.ready().await.map_err(|_| "connect".to_string())?;
        let req = pb::StreamRequest {
            clip_id: if self.motion.is_some() { String::new() } else { self.clip_id.clone() },
            motion: self.motion.as_ref().map(|m| m.pb.clone()),
            fps: self.fps,
            start_time: Some(start_time),
            ..Default::default()
        };
        let path = PathAndQuery::from_static("/inbetween.v1.Animation/StreamFrames");
        let codec = tonic_prost::ProstCodec::<pb::StreamRequest, T>::default();
        grpc.server_streaming(tonic::Request::new(req), path, codec).await.map_err(|s| format!("grpc:{:?}", s.code()))
    }

    /// One stream until `stop`: open, receive, reopen on failure.
    async fn run(
        self,
        link: Link,
        start_time: f64,
        hists: Arc<Mutex<Hists>>,
        mut stop: watch::Receiver<bool>,
    ) -> StreamResult {
        let mut out = StreamResult::default();
        loop {
            if *stop.borrow_and_update() {
                return out;
            }
            let permit = self.opening.acquire().await.expect("the semaphore is never closed");
            let opened = tokio::select! {
                r = tokio::time::timeout(OPEN_TIMEOUT, self.open(&link, start_time)) => r,
                _ = stopped(&mut stop) => return out,
            };
            drop(permit);
            let (mut stream, phase) = match opened {
                Ok(Ok(s)) => s,
                Ok(Err(kind)) => {
                    out.error(kind);
                    // Bounded retries: a refused stream waits before trying again.
                    tokio::select! {
                        _ = tokio::time::sleep(Duration::from_millis(250)) => continue,
                        _ = stopped(&mut stop) => return out,
                    }
                }
                Err(_) => {
                    out.error("timeout");
                    continue;
                }
            };
            let mut tracker = StreamTracker::new(self.clock, self.fps, phase);
            let mut first = true;
            loop {
                let got = tokio::select! {
                    got = stream.next() => got,
                    _ = stopped(&mut stop) => {
                        stream.close().await;
                        return out;
                    }
                };
                match got {
                    Got::Frame(seq, sent_at, dropped) => {
                        let received = unix_now_ns();
                        if first {
                            first = false;
                            if out.opened {
                                out.reconnects += 1;
                            } else {
                                out.opened = true;
                                self.window.opened.fetch_add(1, Ordering::Relaxed);
                            }
                        }
                        let o = tracker.observe(seq, sent_at, received);
                        let (start, end) =
                            (self.window.start.load(Ordering::Relaxed), self.window.end.load(Ordering::Relaxed));
                        if start == 0 || received < start || received >= end {
                            continue;
                        }
                        out.frames += 1;
                        out.dropped += dropped;
                        out.gaps += o.gap;
                        let tenth = (end - start) / 10;
                        let mut h = lock(&hists);
                        h.send.record_ns(o.send_late_ns);
                        h.receive.record_ns(o.receive_late_ns);
                        if let Some(j) = o.jitter_ns {
                            h.jitter.record_ns(j);
                        }
                        if received < start + tenth {
                            h.first_tenth.record_ns(o.receive_late_ns);
                        } else if received >= end - tenth {
                            h.last_tenth.record_ns(o.receive_late_ns);
                        }
                    }
                    Got::End(why) => {
                        if let Some(kind) = why {
                            out.error(kind);
                        }
                        break;
                    }
                }
            }
        }
    }
}

/// A stream's `set` controls, one a second from a second (and its phase)
/// after it opened.
struct Setter {
    cycle: Arc<SetCycle>,
    sent: usize,
    due: tokio::time::Instant,
}

impl Setter {
    fn new(cycle: Arc<SetCycle>, phase: Duration) -> Setter {
        Setter { cycle, sent: 0, due: tokio::time::Instant::now() + Duration::from_secs(1) + phase }
    }

    /// The control now due; the next is due a second later.
    fn next(&mut self) -> String {
        self.sent += 1;
        self.due += Duration::from_secs(1);
        self.cycle.control(self.sent)
    }
}

/// Waits until `due`, or forever without one.
async fn sleep_until_some(due: Option<tokio::time::Instant>) {
    match due {
        Some(due) => tokio::time::sleep_until(due).await,
        None => std::future::pending().await,
    }
}

/// Sends the `open` message of a motion stream and returns the grid phase
/// of the server's `opened` answer; a refusal is an error kind
/// (`open:clip_not_found`, `closed:1013`).
async fn open_motion(ws: &mut WebSocket, open: String) -> Result<u32, String> {
    ws.send(Message::Text(open.into())).await.map_err(|_| "ws_error".to_string())?;
    loop {
        match ws.next().await {
            Some(Ok(Message::Text(t))) => {
                return match serde_json::from_str::<OpenAnswer>(&t) {
                    Ok(OpenAnswer { opened: Some(o), .. }) => Ok(o.grid_phase_ms),
                    Ok(OpenAnswer { error: Some(e), .. }) => Err(format!("open:{}", e.code)),
                    _ => Err("bad_opened".into()),
                };
            }
            Some(Ok(Message::Ping(_) | Message::Pong(_))) => continue,
            Some(Ok(Message::Close(c))) => {
                return Err(c.map_or("closed".into(), |c| format!("closed:{}", u16::from(c.code))));
            }
            Some(Ok(_)) => return Err("unexpected_message".into()),
            Some(Err(_)) => return Err("ws_error".into()),
            None => return Err("ended".into()),
        }
    }
}

/// Resolves once the run is over (the guard `wait_for` returns is not `Send`).
async fn stopped(stop: &mut watch::Receiver<bool>) {
    let _ = stop.wait_for(|s| *s).await;
}

/// Runs `n` streams against the server, or against the floor `floor`.
pub async fn run(opts: &Options, env: &Env, n: usize, floor: Option<&Target>) -> anyhow::Result<Report> {
    let links = Links::connect(opts, env, n, floor).await?;
    let server_pid = floor.map_or(env.server_pid, |f| Some(f.pid));
    let http = floor.is_none().then_some(&env.http);
    let broadcasting = opts.mode == Mode::WsBroadcast;
    let counters_before_open = counters(broadcasting, http).await;
    let broadcast = create_broadcast(opts, env, broadcasting && floor.is_none()).await?;
    let spec = Spec::new(opts, env, links.clock, broadcast.clone(), floor.copied())?;
    let window = Arc::clone(&spec.window);

    // After the broadcast exists: the RSS per viewer is the viewers' alone.
    let server_before = server_pid.and_then(procstat::sample);
    let (stop_tx, stop_rx) = watch::channel(false);
    let groups: Vec<Arc<Mutex<Hists>>> = (0..n.div_ceil(GROUP)).map(|_| Arc::default()).collect();
    let tasks = spawn_streams(opts, &spec, &links.links, &groups, n, stop_rx);
    wait_until_open(&window, n).await;
    let measured = Measured::window(opts, &window, server_pid, broadcasting, http).await;
    stop_tx.send_replace(true);

    let done = Collected::gather(tasks, &groups).await;
    for reader in links.readers {
        reader.abort();
    }
    if let Some(id) = &broadcast {
        broadcast::delete(&env.http, id).await;
    }
    let done = done?;
    let counters = [counters_before_open, measured.counters_before, measured.counters_after];
    let mut stats = done.stats(opts, n, measured.elapsed, links.clock, counters);
    stats.broadcast_id = broadcast;
    let server = measured.server_usage(server_pid, server_before, stats.opened, done.total.frames);
    Ok(Report {
        mode: opts.mode.as_str(),
        started_unix: measured.start as f64 / 1e9,
        http: env.http.to_string(),
        grpc: env.grpc.to_string(),
        clip_id: env.clip_id.clone(),
        motion: None,
        joints: None,
        concurrency: n,
        connections: links.connections,
        rate: None,
        elapsed_secs: measured.elapsed,
        ok: done.total.frames,
        throughput: done.total.frames as f64 / measured.elapsed,
        latency: None,
        streams: Some(stats),
        errors: done.total.errors,
        server,
        client_cpu_cores: measured.client_cpu_cores(),
        loadavg: None,
        ramp: None,
        floor: None,
    })
}

/// How a run's streams reach the server (or the floor), and its clock.
struct Links {
    /// Connections the streams share (a WebSocket is its own).
    connections: usize,
    /// Stream `i` rides `links[i % links.len()]`.
    links: Vec<Link>,
    clock: ClockSync,
    /// The gRPC floor's connection readers, aborted when the run ends.
    readers: Vec<tokio::task::JoinHandle<()>>,
}

impl Links {
    async fn connect(opts: &Options, env: &Env, n: usize, floor: Option<&Target>) -> anyhow::Result<Links> {
        let connections = match opts.mode {
            Mode::GrpcStream if opts.connections == 0 => n.div_ceil(STREAMS_PER_CONNECTION),
            Mode::GrpcStream => opts.connections.min(n),
            _ => n, // a WebSocket is its own connection
        };
        let grpc = opts.mode == Mode::GrpcStream;
        let (links, clock, readers) = match floor {
            Some(f) if grpc => {
                let (links, readers) = floor_links(f.port, n, connections).await?;
                (links, f.clock, readers)
            }
            Some(f) => (vec![Link::Own], f.clock, Vec::new()),
            None => {
                // The clock sync always goes over gRPC (the `Ping` RPC); WebSocket
                // streams use one extra channel for it.
                let channels = setup::channels(&env.grpc, if grpc { connections } else { 1 }).await?;
                let clock = setup::clock_sync(channels[0].clone()).await?;
                let links = if grpc { channels.into_iter().map(Link::Grpc).collect() } else { vec![Link::Own] };
                (links, clock, Vec::new())
            }
        };
        Ok(Links { connections, links, clock, readers })
    }
}

/// The broadcast a `ws-broadcast` run's viewers watch, created for the run:
/// its motion, or the clip alone.
async fn create_broadcast(opts: &Options, env: &Env, wanted: bool) -> anyhow::Result<Option<String>> {
    Ok(match (wanted, &env.motion) {
        (false, _) => None,
        (true, Some(m)) => Some(broadcast::create(&env.http, &m.json, opts.fps).await?),
        (true, None) => Some(broadcast::create(&env.http, &broadcast::clip_motion(&env.clip_id), opts.fps).await?),
    })
}

/// Starts the `n` streams, each on its link and counting into its group's
/// histograms, until `stop`.
fn spawn_streams(
    opts: &Options,
    spec: &Spec,
    links: &[Link],
    groups: &[Arc<Mutex<Hists>>],
    n: usize,
    stop: watch::Receiver<bool>,
) -> Vec<tokio::task::JoinHandle<StreamResult>> {
    (0..n)
        .map(|i| {
            // Independent streams differ in start time (1 ms apart), so the
            // server cannot merge them; shared ones all start at 0.
            let start_time = if opts.shared { 0.0 } else { i as f64 * 0.001 };
            let link = links[i % links.len()].clone();
            let hists = Arc::clone(&groups[i / GROUP]);
            let set_phase = Duration::from_secs_f64(i as f64 / n as f64);
            tokio::spawn(Spec { set_phase, ..spec.clone() }.run(link, start_time, hists, stop.clone()))
        })
        .collect()
}

/// The readings at the edges of the measured window.
struct Measured {
    /// The window's start, Unix ns.
    start: i64,
    elapsed: f64,
    counters_before: Option<(u64, u64)>,
    counters_after: Option<(u64, u64)>,
    server_start: Option<ProcSample>,
    server_end: Option<ProcSample>,
    client_start: Option<ProcSample>,
    client_end: Option<ProcSample>,
}

impl Measured {
    /// Opens the window for the streams' samples, waits the run's duration
    /// and reads the server's counters and both processes' usage either side.
    async fn window(
        opts: &Options,
        window: &Window,
        server_pid: Option<u32>,
        broadcasting: bool,
        http: Option<&reqwest::Url>,
    ) -> Measured {
        let counters_before = counters(broadcasting, http).await;
        let server_start = server_pid.and_then(procstat::sample);
        let client_start = procstat::sample_self();
        let start = unix_now_ns();
        window.end.store(start + opts.duration.as_nanos() as i64, Ordering::Relaxed);
        window.start.store(start, Ordering::Relaxed);
        tokio::time::sleep(opts.duration).await;
        let elapsed = (unix_now_ns() - start) as f64 / 1e9;
        let server_end = server_pid.and_then(procstat::sample);
        let client_end = procstat::sample_self();
        let counters_after = counters(broadcasting, http).await;
        Measured { start, elapsed, counters_before, counters_after, server_start, server_end, client_start, client_end }
    }

    /// The server's memory and CPU over the window, when all were read.
    fn server_usage(
        &self,
        server_pid: Option<u32>,
        before: Option<ProcSample>,
        opened: usize,
        frames: u64,
    ) -> Option<ServerUsage> {
        let (pid, b, s, e) = (server_pid?, before?, self.server_start?, self.server_end?);
        Some(ServerUsage {
            pid,
            rss_before_bytes: b.rss_bytes,
            rss_end_bytes: e.rss_bytes,
            // Per stream that opened: when some never do, dividing by the
            // streams asked for would understate each one's cost.
            rss_per_stream_bytes: Some((e.rss_bytes as f64 - b.rss_bytes as f64) / opened.max(1) as f64),
            cpu_cores: (e.cpu_secs - s.cpu_secs) / self.elapsed,
            cpu_us_per_op: (e.cpu_secs - s.cpu_secs) * 1e6 / frames.max(1) as f64,
        })
    }

    /// The load generator's own CPU over the window.
    fn client_cpu_cores(&self) -> Option<f64> {
        self.client_start.zip(self.client_end).map(|(b, a)| (a.cpu_secs - b.cpu_secs) / self.elapsed)
    }
}

impl Spec {
    /// What every stream of this run shares; the window is not open yet.
    fn new(
        opts: &Options,
        env: &Env,
        clock: ClockSync,
        broadcast: Option<String>,
        floor: Option<Target>,
    ) -> anyhow::Result<Spec> {
        let mut ws_base = env.http.clone();
        ws_base.set_scheme("ws").map_err(|()| anyhow::anyhow!("cannot make a ws:// URL of {}", env.http))?;
        let window =
            Arc::new(Window { start: AtomicI64::new(0), end: AtomicI64::new(i64::MAX), opened: AtomicUsize::new(0) });
        Ok(Spec {
            mode: opts.mode,
            ws_base: ws_base.to_string(),
            ws_protobuf: opts.ws_protobuf,
            clip_id: env.clip_id.clone(),
            motion: env.motion.clone().map(Arc::new),
            set_cycle: opts.set_cycle.clone().map(Arc::new),
            set_phase: Duration::ZERO,
            fps: opts.fps,
            broadcast,
            floor,
            clock,
            window,
            opening: Arc::new(Semaphore::new(OPENING)),
        })
    }
}

/// The server's (playbacks started, ticks evaluated) counters, or for
/// broadcast viewers (broadcasts created, broadcast ticks evaluated).
async fn counters(broadcasting: bool, http: Option<&reqwest::Url>) -> Option<(u64, u64)> {
    let http = http?;
    if broadcasting { broadcast::counters(http).await } else { setup::stream_counters(http).await }
}

/// The gRPC floor's connections (`floor`): stream `i` rides connection
/// `i % connections`, as on the server's channels, and is the `i /
/// connections`-th of its frames in every batch. Each connection says how
/// many streams it carries, then a reader hands the frames round.
async fn floor_links(
    port: u16,
    n: usize,
    connections: usize,
) -> anyhow::Result<(Vec<Link>, Vec<tokio::task::JoinHandle<()>>)> {
    let mut slots: Vec<Option<Link>> = vec![None; n];
    let mut readers = Vec::with_capacity(connections);
    for c in 0..connections {
        let members: Vec<usize> = (c..n).step_by(connections).collect();
        if members.len() > MAX_COPIES {
            anyhow::bail!("{} streams on one connection; the floor takes {}", members.len(), MAX_COPIES);
        }
        let mut stream =
            tokio::net::TcpStream::connect(("127.0.0.1", port)).await.context("connecting to the floor")?;
        stream.set_nodelay(true)?;
        stream.write_u32(members.len() as u32).await?;
        let mut senders = Vec::with_capacity(members.len());
        for i in members {
            let (tx, rx) = mpsc::unbounded_channel();
            senders.push(tx);
            slots[i] = Some(Link::Floor(Arc::new(Mutex::new(Some(rx)))));
        }
        readers.push(tokio::spawn(read_floor(stream, senders)));
    }
    Ok((slots.into_iter().map(|l| l.expect("every stream has a connection")).collect(), readers))
}

/// Reads gRPC messages (5-byte prefix, `Frame`) and hands them round its
/// streams, until the floor closes or every stream has gone.
async fn read_floor(stream: tokio::net::TcpStream, streams: Vec<mpsc::UnboundedSender<Got>>) {
    let mut reader = tokio::io::BufReader::with_capacity(64 * 1024, stream);
    let mut prefix = [0u8; 5];
    let mut message = Vec::new();
    let why = 'read: loop {
        for tx in &streams {
            if reader.read_exact(&mut prefix).await.is_err() {
                break 'read "ended";
            }
            let len = u32::from_be_bytes([prefix[1], prefix[2], prefix[3], prefix[4]]) as usize;
            message.resize(len, 0);
            if reader.read_exact(&mut message).await.is_err() {
                break 'read "ended";
            }
            let got = match <FrameHead as prost::Message>::decode(&message[..]) {
                Ok(h) => Got::Frame(h.seq, h.sent_at_unix_nanos, h.dropped),
                Err(_) => Got::End(Some("bad_frame".into())),
            };
            let _ = tx.send(got);
        }
        if streams.iter().all(mpsc::UnboundedSender::is_closed) {
            return;
        }
    };
    for tx in &streams {
        let _ = tx.send(Got::End(Some(why.into())));
    }
}

/// One frame as the server sent it, for the floor: the second of a fresh
/// stream of the run's clip or motion (a protobuf stream's first frame
/// carries the joint names, which no later frame does).
pub async fn sample_frame(opts: &Options, env: &Env) -> anyhow::Result<Bytes> {
    let clock = ClockSync { offset_ns: 0, rtt_ns: 0, grid_epoch_unix_ns: 0 };
    let spec = Spec::new(opts, env, clock, None, None)?;
    tokio::time::timeout(OPEN_TIMEOUT, take_frame(&spec, env)).await.context("no frame within the open timeout")?
}

async fn take_frame(spec: &Spec, env: &Env) -> anyhow::Result<Bytes> {
    if spec.mode == Mode::GrpcStream {
        let channel = setup::channels(&env.grpc, 1).await?.remove(0);
        let mut frames = spec.grpc_stream::<WireFrame>(&channel, 0.0).await.map_err(anyhow::Error::msg)?.into_inner();
        frames.message().await?;
        return Ok(frames.message().await?.context("the stream ended at its first frame")?.0);
    }
    let (open, _) = spec.open(&Link::Own, 0.0).await.map_err(anyhow::Error::msg)?;
    let Open::Ws(mut ws, _, _) = open else { anyhow::bail!("a WebSocket stream was expected") };
    let mut seen = 0;
    while let Some(message) = ws.next().await {
        let bytes = match message? {
            Message::Text(t) => Bytes::copy_from_slice(t.as_bytes()),
            Message::Binary(b) => b,
            Message::Close(c) => anyhow::bail!("the stream closed: {c:?}"),
            _ => continue,
        };
        seen += 1;
        if seen == 2 {
            let _ = tokio::time::timeout(Duration::from_secs(1), ws.close()).await;
            return Ok(bytes);
        }
    }
    anyhow::bail!("the stream ended before its second frame")
}

/// Waits until every stream has delivered a frame (or a deadline that grows
/// with their number), then lets the server settle, so the window measures
/// steady streaming and not the opening.
async fn wait_until_open(window: &Window, n: usize) {
    let open_deadline = Instant::now() + Duration::from_secs(10) + Duration::from_millis(n as u64 * 2);
    while window.opened.load(Ordering::Relaxed) < n && Instant::now() < open_deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    tokio::time::sleep(SETTLE).await;
}

/// Every stream's results, merged once the run has stopped them.
struct Collected {
    total: StreamResult,
    /// Streams that delivered at least one frame.
    opened: usize,
    hists: Hists,
}

impl Collected {
    async fn gather(
        tasks: Vec<tokio::task::JoinHandle<StreamResult>>,
        groups: &[Arc<Mutex<Hists>>],
    ) -> anyhow::Result<Collected> {
        let mut total = StreamResult::default();
        let mut opened = 0;
        for task in tasks {
            let r = task.await?;
            opened += usize::from(r.opened);
            total.merge(&r);
        }
        let mut hists = Hists::default();
        for group in groups {
            hists.merge(&lock(group));
        }
        Ok(Collected { total, opened, hists })
    }

    /// The report's stream figures; `counters` are the server's (playbacks,
    /// ticks) before the streams opened, at the window's start and at its end.
    fn stats(
        &self,
        opts: &Options,
        n: usize,
        elapsed: f64,
        clock: ClockSync,
        counters: [Option<(u64, u64)>; 3],
    ) -> StreamStats {
        let [before_open, before, after] = counters;
        let (total, hists) = (&self.total, &self.hists);
        StreamStats {
            streams: n,
            opened: self.opened,
            fps: opts.fps,
            shared: opts.shared || opts.mode == Mode::WsBroadcast,
            broadcast_id: None,
            encoding: match (opts.mode, opts.ws_protobuf) {
                (Mode::WsStream | Mode::WsBroadcast, false) => "json",
                _ => "protobuf",
            },
            frames_per_stream_per_sec: total.frames as f64 / n as f64 / elapsed,
            send_lateness: hists.send.summary(),
            receive_lateness: hists.receive.summary(),
            jitter: hists.jitter.summary(),
            drift_p50_us: (hists.last_tenth.quantile_ns(0.5) as f64 - hists.first_tenth.quantile_ns(0.5) as f64)
                / 1000.0,
            dropped: total.dropped,
            gaps: total.gaps,
            loss_ratio: if total.gaps == 0 { 0.0 } else { total.gaps as f64 / (total.frames + total.gaps) as f64 },
            reconnects: total.reconnects,
            clock,
            playbacks_started: before_open.zip(after).map(|(b, a)| a.0.saturating_sub(b.0)),
            ticks_evaluated: before.zip(after).map(|(b, a)| a.1.saturating_sub(b.1)),
        }
    }
}

/// Locks `mutex`, taking the guard even if a panicking holder poisoned it:
/// the histograms and frame lists it guards are whole between statements.
fn lock<T: ?Sized>(mutex: &std::sync::Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The prefix read agrees with a full parse, in the server's order and
    /// in any other.
    #[test]
    fn a_json_head_is_read_from_the_prefix_or_the_whole_frame() {
        let server = r#"{"seq":120,"clip_time":1.5e-3,"sent_at_unix_nanos":1764000000123456789,"dropped":3,"events":[],"pose":{"joints":[{"name":"seq","translation":[0,1,2]}]}}"#;
        let reordered = r#"{"dropped":3,"pose":{},"sent_at_unix_nanos":1764000000123456789,"seq":120,"events":[]}"#;
        for text in [server, reordered] {
            let h = json_head(text).expect(text);
            assert_eq!((h.seq, h.sent_at_unix_nanos, h.dropped), (120, 1_764_000_000_123_456_789, 3), "{text}");
        }
        assert!(json_head(r#"{"seq":-1,"clip_time":0,"sent_at_unix_nanos":1,"dropped":0,"events":[]}"#).is_none());
        assert!(json_head("not json").is_none());
    }
}
