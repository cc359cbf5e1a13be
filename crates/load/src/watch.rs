//! `inbetween watch`: one WebSocket stream in the terminal, so the documents'
//! stream commands need nothing but the project (no websocat, no jq).
//!
//! `--motion FILE` opens `GET /v1/stream` with `{"op":"open","motion":…}`;
//! `--graph ID` opens it with a motion of that graph (docs/graphs.md), its
//! report asked for, and `--set [SEQ:]NAME=VALUE` sets its parameters as the
//! stream opens or when frame SEQ arrives; `--clip ID` streams `/v1/clips/{ID}/stream`; `--broadcast ID` watches
//! `/v1/broadcasts/{ID}/stream` (docs/broadcasts.md: its controls act on the
//! broadcast for every viewer when the token may write). Each frame is printed as one
//! compact line (or its JSON with `--raw`) on stdout; the `opened` message,
//! errors and the close code go to stderr. Controls come from stdin (one JSON
//! object a line) and from `--at SEQ=JSON`, sent when frame SEQ arrives, so a
//! crossfade can be scripted. A clip may be named `"name:Walk"` wherever a
//! document says `"clip"`: the name is looked up (`GET /v1/clips?name=Walk`,
//! exactly one match) before anything is sent, so example files need no ids.

use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;
use futures_util::{SinkExt, StreamExt};
use percent_encoding::{AsciiSet, NON_ALPHANUMERIC, utf8_percent_encode};
use serde_json::{Value, json};
use tokio::sync::mpsc;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::protocol::CloseFrame;
use tokio_tungstenite::tungstenite::{self, Message};

/// What a `"clip"` value starts with when it names a clip instead of its id.
const NAME_PREFIX: &str = "name:";

/// What is percent-encoded in a clip id or joint name: all but RFC 3986's unreserved characters.
const ENCODED: &AsciiSet = &NON_ALPHANUMERIC.remove(b'-').remove(b'_').remove(b'.').remove(b'~');

/// The close code of a stream that ended as asked (`max_frames`, `stop`).
const NORMAL_CLOSE: u16 = 1000;

#[derive(Debug, Args)]
pub struct WatchArgs {
    /// The server's base URL.
    #[arg(long, default_value = "http://127.0.0.1:8080")]
    server: String,
    /// A motion document (docs/motion.md) to stream over `GET /v1/stream`; a layer may name its clip
    /// `"clip": "name:NAME"`.
    #[arg(
        long,
        required_unless_present_any = ["clip", "broadcast", "graph"],
        conflicts_with_all = ["clip", "broadcast", "graph"]
    )]
    motion: Option<PathBuf>,
    /// Stream this stored graph (an id, or `name:NAME`) over `GET /v1/stream`, each frame with its report.
    #[arg(long, conflicts_with_all = ["clip", "broadcast"])]
    graph: Option<String>,
    /// Set a graph parameter: `NAME=VALUE` as the stream opens, `SEQ:NAME=VALUE` when frame SEQ arrives
    /// (repeatable; VALUE is a number, `true` or `false`).
    #[arg(long = "set", value_name = "[SEQ:]NAME=VALUE", value_parser = parse_set, requires = "graph")]
    set: Vec<Setting>,
    /// Stream this clip (an id, or `name:NAME`) over `/v1/clips/{ID}/stream`.
    #[arg(long, conflicts_with = "broadcast")]
    clip: Option<String>,
    /// Watch this broadcast over `/v1/broadcasts/{ID}/stream` (its own fps and joints; `--fps`, `--max-frames`,
    /// `--joints` and `--space` do not apply).
    #[arg(long)]
    broadcast: Option<String>,
    /// Frames per second.
    #[arg(long, default_value_t = 30)]
    fps: u32,
    /// End after this many frames (close 1000).
    #[arg(long)]
    max_frames: Option<u64>,
    /// Only these joints in each frame (comma-separated names).
    #[arg(long, value_delimiter = ',')]
    joints: Vec<String>,
    /// local or model space.
    #[arg(long, value_parser = ["local", "model"])]
    space: Option<String>,
    /// Send a control when frame SEQ arrives: `SEQ=JSON` or `SEQ=@FILE` (repeatable).
    #[arg(long = "at", value_name = "SEQ=JSON", value_parser = parse_at)]
    at: Vec<Timed>,
    /// Print each frame's JSON instead of a summary line.
    #[arg(long)]
    raw: bool,
    /// Bearer token for the server's read routes.
    #[arg(long, env = "INBETWEEN_TOKEN", hide_env_values = true)]
    token: Option<String>,
}

/// A control to send once frame `seq` (or a later one, if frames were
/// dropped) has arrived.
#[derive(Debug, Clone, PartialEq)]
pub struct Timed {
    seq: u64,
    control: Control,
}

/// A graph parameter set from the command line: at frame `seq`, or as the
/// stream opens (`None`).
#[derive(Debug, Clone, PartialEq)]
pub struct Setting {
    seq: Option<u64>,
    name: String,
    value: Value,
}

/// Parses `--set NAME=VALUE` or `--set SEQ:NAME=VALUE`.
fn parse_set(text: &str) -> Result<Setting, String> {
    let (name, value) = text.split_once('=').ok_or("expected NAME=VALUE or SEQ:NAME=VALUE")?;
    let (seq, name) = match name.split_once(':') {
        Some((seq, name)) => (Some(seq.trim().parse().map_err(|_| format!("{seq:?} is not a frame number"))?), name),
        None => (None, name),
    };
    let value = match serde_json::from_str(value.trim()) {
        Ok(value @ (Value::Number(_) | Value::Bool(_))) => value,
        _ => return Err(format!("{value:?} is not a number, true or false")),
    };
    Ok(Setting { seq, name: name.trim().to_owned(), value })
}

/// The `set` controls of `settings`: those for the stream's opening, then
/// one per frame number named, in order of frame.
fn set_controls(settings: &[Setting]) -> (Option<Value>, Vec<(u64, Value)>) {
    let mut at: BTreeMap<Option<u64>, serde_json::Map<String, Value>> = BTreeMap::new();
    for s in settings {
        at.entry(s.seq).or_default().insert(s.name.clone(), s.value.clone());
    }
    let control = |parameters| json!({"op": "set", "parameters": Value::Object(parameters)});
    let opening = at.remove(&None).map(control);
    (opening, at.into_iter().filter_map(|(seq, p)| Some((seq?, control(p)))).collect())
}

/// A control as given on the command line: inline JSON or a file of it.
#[derive(Debug, Clone, PartialEq)]
enum Control {
    Inline(Value),
    File(PathBuf),
}

/// Parses `--at SEQ=JSON` or `--at SEQ=@FILE`; inline JSON must be an object.
fn parse_at(text: &str) -> Result<Timed, String> {
    let (seq, control) = text.split_once('=').ok_or("expected SEQ=JSON or SEQ=@FILE")?;
    let seq = seq.trim().parse().map_err(|_| format!("{seq:?} is not a frame number"))?;
    let control = match control.strip_prefix('@') {
        Some(path) if !path.is_empty() => Control::File(PathBuf::from(path)),
        Some(_) => return Err("@ needs a file name".into()),
        None => Control::Inline(control_object(control)?),
    };
    Ok(Timed { seq, control })
}

/// A control line: a JSON object.
fn control_object(text: &str) -> Result<Value, String> {
    match serde_json::from_str(text) {
        Ok(value @ Value::Object(_)) => Ok(value),
        Ok(_) => Err("a control is a JSON object, e.g. {\"op\":\"pause\"}".into()),
        Err(e) => Err(format!("not JSON: {e}")),
    }
}

/// The clip names a document refers to (`"clip": "name:X"` at any depth).
fn clip_names(doc: &Value) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    visit_clips(doc, &mut |clip| {
        if let Some(name) = clip.strip_prefix(NAME_PREFIX) {
            names.insert(name.to_owned());
        }
    });
    names
}

fn visit_clips(doc: &Value, found: &mut impl FnMut(&str)) {
    match doc {
        Value::Object(map) => {
            for (key, value) in map {
                match value {
                    Value::String(clip) if key == "clip" => found(clip),
                    _ => visit_clips(value, found),
                }
            }
        }
        Value::Array(items) => items.iter().for_each(|v| visit_clips(v, found)),
        _ => {}
    }
}

/// Replaces each `"clip": "name:X"` by `"clip": ids[X]`; names not in `ids`
/// stay as they are (the server then refuses them as unknown clips).
fn substitute_names(doc: &mut Value, ids: &BTreeMap<String, String>) {
    match doc {
        Value::Object(map) => {
            for (key, value) in map.iter_mut() {
                let id = match value.as_str().and_then(|c| c.strip_prefix(NAME_PREFIX)) {
                    Some(name) if key == "clip" => ids.get(name).cloned(),
                    _ => None,
                };
                match id {
                    Some(id) => *value = Value::String(id),
                    None => substitute_names(value, ids),
                }
            }
        }
        Value::Array(items) => items.iter_mut().for_each(|v| substitute_names(v, ids)),
        _ => {}
    }
}

/// The one clip id in a `GET /v1/clips?name=…` answer.
fn single_match(name: &str, page: &Value) -> anyhow::Result<String> {
    let clips = page["clips"].as_array().context("the clip list has no \"clips\" array")?;
    let ids: Vec<&str> = clips.iter().filter_map(|c| c["id"].as_str()).collect();
    match ids.as_slice() {
        [id] => Ok((*id).to_owned()),
        [] => bail!("no clip is named {name:?} (import it first, e.g. `inbetween import FILE --server URL`)"),
        _ => bail!("several clips are named {name:?} ({}, …): use an id instead", ids.join(", ")),
    }
}

/// The WebSocket URL of `path` on an `http://` server.
fn ws_url(server: &str, path: &str) -> anyhow::Result<String> {
    let base = server.trim_end_matches('/');
    match base.split_once("://") {
        Some(("http", rest)) => Ok(format!("ws://{rest}{path}")),
        Some(("https", _)) => bail!("watch speaks plain ws:// only; reach a TLS server through a local proxy"),
        _ => bail!("--server must be an http:// URL, not {server:?}"),
    }
}

/// The query of a clip stream.
fn clip_query(args: &WatchArgs) -> String {
    let mut query = format!("fps={}", args.fps);
    if let Some(n) = args.max_frames {
        query.push_str(&format!("&max_frames={n}"));
    }
    if let Some(space) = &args.space {
        query.push_str(&format!("&space={space}"));
    }
    if !args.joints.is_empty() {
        let names: Vec<String> = args.joints.iter().map(|j| utf8_percent_encode(j, ENCODED).to_string()).collect();
        query.push_str(&format!("&joints={}", names.join(",")));
    }
    query
}

/// The first message of `GET /v1/stream`.
fn open_message(motion: Value, args: &WatchArgs) -> Value {
    let mut open = json!({"op": "open", "motion": motion, "fps": args.fps});
    if let Some(n) = args.max_frames {
        open["max_frames"] = json!(n);
    }
    if let Some(space) = &args.space {
        open["space"] = json!(space);
    }
    if !args.joints.is_empty() {
        open["joints"] = json!(args.joints);
    }
    open
}

/// One frame as a line: seq, motion time, clip time, dropped, events, the
/// root motion total (when the motion asks for it) and the first joint.
fn frame_line(frame: &Value) -> String {
    let pose = &frame["pose"];
    let events: Vec<&str> =
        frame["events"].as_array().into_iter().flatten().filter_map(|e| e["name"].as_str()).collect();
    let mut line = format!(
        "seq={} time={:.4} clip_time={:.4} dropped={} events=[{}]",
        frame["seq"],
        pose["time"].as_f64().unwrap_or(f64::NAN),
        frame["clip_time"].as_f64().unwrap_or(f64::NAN),
        frame["dropped"],
        events.join(",")
    );
    let total = &pose["root_motion"]["total"];
    if !total.is_null() {
        line.push_str(&format!(
            " root_total={} yaw={:.4}",
            vec3(&total["translation"]),
            total["yaw"].as_f64().unwrap_or(f64::NAN)
        ));
    }
    if let Some(joint) = pose["joints"].get(0) {
        line.push_str(&format!(" {}={}", joint["name"].as_str().unwrap_or("?"), vec3(&joint["translation"])));
    }
    if let Some(reports) = pose["ik"].as_array() {
        line.push_str(&format!(" ik=[{}]", reports.iter().map(ik_report).collect::<Vec<_>>().join(",")));
    }
    let graph = if frame["graph"].is_object() { &frame["graph"] } else { &pose["graph"] };
    if graph.is_object() {
        line.push_str(&graph_report(graph));
    }
    line
}

/// A graph's report (docs/graphs.md) as ` state=S` or ` state=FROM>TO@α`,
/// then each blend's weights, ` NODE=[w,…]`.
fn graph_report(r: &Value) -> String {
    let t = &r["transition"];
    let mut text = match (t["from"].as_str(), t["to"].as_str()) {
        (Some(from), Some(to)) => format!(" state={from}>{to}@{:.2}", t["alpha"].as_f64().unwrap_or(f64::NAN)),
        _ => format!(" state={}", r["state"].as_str().unwrap_or("?")),
    };
    for (node, weights) in r["weights"].as_object().into_iter().flatten() {
        let ws: Vec<String> = weights
            .as_array()
            .into_iter()
            .flatten()
            .map(|w| format!("{:.2}", w.as_f64().unwrap_or(f64::NAN)))
            .collect();
        text.push_str(&format!(" {node}=[{}]", ws.join(",")));
    }
    text
}

/// One IK report (docs/ik.md) as `kind:residual:iterations` with `!` when it
/// did not converge.
fn ik_report(r: &Value) -> String {
    let converged = if r["converged"] == true { "" } else { "!" };
    let residual = r["residual"].as_f64().unwrap_or(f64::NAN);
    format!("{}:{residual:.1e}:{}{converged}", r["kind"].as_str().unwrap_or("?"), r["iterations"])
}

/// A server's problem as one line: `error CODE: DETAIL (at POINTER)`.
fn error_line(problem: &Value) -> String {
    let text = |key: &str| problem[key].as_str().unwrap_or("?").to_owned();
    let mut line = format!("error {}: {}", text("code"), text("detail"));
    if let Some(pointer) = problem["pointer"].as_str() {
        line.push_str(&format!(" (at {pointer})"));
    }
    line
}

fn vec3(v: &Value) -> String {
    let xs: Vec<String> = (0..3).map(|i| format!("{:.4}", v[i].as_f64().unwrap_or(f64::NAN))).collect();
    format!("[{}]", xs.join(","))
}

/// Watches until the stream closes, writing a line per frame to `out`.
///
/// # Errors
/// The server cannot be reached or refuses the stream, a name matches no
/// clip, or `out` fails (its reader left: the caller may end quietly).
pub fn run(args: WatchArgs, out: impl Write + Send) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    runtime.block_on(watch(args, out))
}

async fn watch<W: Write + Send>(args: WatchArgs, out: W) -> anyhow::Result<()> {
    let names = Names::new(&args.server, args.token.clone());
    let (opening_set, mut timed) = set_controls(&args.set);
    for t in &args.at {
        timed.push((t.seq, names.resolve(load_control(&t.control)?).await?));
    }
    timed.sort_by_key(|&(seq, _)| seq);
    let (path, open) = target(&args, &names).await?;
    let mut socket = connect(&ws_url(&args.server, &path)?, args.token.as_deref()).await?;
    for message in open.into_iter().chain(opening_set) {
        socket.send(Message::text(message.to_string())).await.context("sending the open message")?;
    }
    let session = Session { out, raw: args.raw, timed, next_timed: 0, frames: 0 };
    session.run(socket, stdin_lines(), &names).await
}

/// The stream's path and, for a motion, its open message (names resolved).
async fn target(args: &WatchArgs, names: &Names) -> anyhow::Result<(String, Option<Value>)> {
    if let Some(id) = &args.broadcast {
        return Ok((format!("/v1/broadcasts/{}/stream", utf8_percent_encode(id, ENCODED)), None));
    }
    if let Some(clip) = &args.clip {
        let id = match clip.strip_prefix(NAME_PREFIX) {
            Some(name) => names.lookup(name).await?,
            None => clip.clone(),
        };
        let id = utf8_percent_encode(&id, ENCODED);
        return Ok((format!("/v1/clips/{id}/stream?{}", clip_query(args)), None));
    }
    if let Some(graph) = &args.graph {
        let mut open = open_message(json!({"layers": [{"graph": graph}]}), args);
        open["report"] = json!(true);
        return Ok(("/v1/stream".to_owned(), Some(open)));
    }
    let path = args.motion.as_deref().context("--motion FILE, --graph ID or --clip ID")?;
    let motion = names.resolve(read_json(path)?).await?;
    Ok(("/v1/stream".to_owned(), Some(open_message(motion, args))))
}

fn load_control(control: &Control) -> anyhow::Result<Value> {
    match control {
        Control::Inline(value) => Ok(value.clone()),
        Control::File(path) => read_json(path),
    }
}

pub(crate) fn read_json(path: &Path) -> anyhow::Result<Value> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{} is not JSON", path.display()))
}

/// Clip names looked up on the server.
pub(crate) struct Names {
    http: reqwest::Client,
    url: String,
    token: Option<String>,
}

impl Names {
    pub(crate) fn new(server: &str, token: Option<String>) -> Names {
        Names { http: reqwest::Client::new(), url: format!("{}/v1/clips", server.trim_end_matches('/')), token }
    }

    /// `doc` with every `"clip": "name:X"` replaced by X's id.
    pub(crate) async fn resolve(&self, mut doc: Value) -> anyhow::Result<Value> {
        let mut ids = BTreeMap::new();
        for name in clip_names(&doc) {
            let id = self.lookup(&name).await?;
            ids.insert(name, id);
        }
        substitute_names(&mut doc, &ids);
        Ok(doc)
    }

    async fn lookup(&self, name: &str) -> anyhow::Result<String> {
        let mut request = self.http.get(&self.url).query(&[("name", name), ("limit", "2")]);
        if let Some(token) = &self.token {
            request = request.bearer_auth(token);
        }
        let response = request.send().await.with_context(|| format!("GET {}?name={name}", self.url))?;
        let status = response.status();
        let body = response.text().await.with_context(|| format!("GET {}: reading the answer", self.url))?;
        if !status.is_success() {
            bail!("GET {}?name={name}: {status}: {body}", self.url);
        }
        single_match(name, &serde_json::from_str(&body).context("the clip list is not JSON")?)
    }
}

type Socket = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// Opens the WebSocket; a refused handshake reports the server's status and problem.
async fn connect(url: &str, token: Option<&str>) -> anyhow::Result<Socket> {
    let mut request = url.into_client_request().with_context(|| format!("bad URL {url}"))?;
    if let Some(token) = token {
        let value = format!("Bearer {token}").parse().context("the token is not a valid header value")?;
        request.headers_mut().insert("authorization", value);
    }
    match tokio_tungstenite::connect_async(request).await {
        Ok((socket, _)) => Ok(socket),
        Err(tungstenite::Error::Http(response)) => {
            let body = response.body().as_deref().map(String::from_utf8_lossy).unwrap_or_default();
            bail!("{url}: refused with {}: {body}", response.status())
        }
        Err(e) => Err(e).with_context(|| format!("connecting to {url}")),
    }
}

/// Lines typed on stdin. A plain thread (not tokio's stdin) so a read still
/// blocked at exit does not hold the runtime open.
fn stdin_lines() -> mpsc::UnboundedReceiver<String> {
    let (tx, rx) = mpsc::unbounded_channel();
    std::thread::spawn(move || {
        for line in std::io::stdin().lines() {
            let Ok(line) = line else { return };
            if tx.send(line).is_err() {
                return;
            }
        }
    });
    rx
}

/// One connection's state: what to print and which timed controls remain.
struct Session<W> {
    /// Where the frame lines go.
    out: W,
    raw: bool,
    timed: Vec<(u64, Value)>,
    next_timed: usize,
    frames: u64,
}

impl<W: Write + Send> Session<W> {
    async fn run(
        mut self,
        socket: Socket,
        mut stdin: mpsc::UnboundedReceiver<String>,
        names: &Names,
    ) -> anyhow::Result<()> {
        let (mut sink, mut incoming) = socket.split();
        let mut stdin_open = true;
        loop {
            tokio::select! {
                message = incoming.next() => {
                    let message = match message {
                        Some(m) => m.context("reading the stream")?,
                        None => bail!("the server closed the connection without a close frame"),
                    };
                    if let Message::Close(frame) = message {
                        return self.closed(frame);
                    }
                    for control in self.received(message)? {
                        sink.send(Message::text(control.to_string())).await.context("sending a control")?;
                    }
                }
                line = stdin.recv(), if stdin_open => match line {
                    Some(line) => {
                        if let Some(control) = typed_control(&line, names).await {
                            sink.send(Message::text(control.to_string())).await.context("sending a control")?;
                        }
                    }
                    None => stdin_open = false,
                },
            }
        }
    }

    /// Prints a message; returns the timed controls now due.
    ///
    /// # Errors
    /// Standard output is gone (its reader left: the watch ends quietly).
    fn received(&mut self, message: Message) -> std::io::Result<Vec<Value>> {
        let Message::Text(text) = message else { return Ok(Vec::new()) };
        let Ok(value) = serde_json::from_str::<Value>(&text) else {
            eprintln!("not JSON: {text}");
            return Ok(Vec::new());
        };
        if let Some(seq) = value["seq"].as_u64() {
            self.frames += 1;
            let line = if self.raw { text.to_string() } else { frame_line(&value) };
            writeln!(self.out, "{line}")?;
            return Ok(self.due(seq));
        }
        if let Some(opened) = value.get("opened") {
            eprintln!("opened {opened}");
        } else if let Some(error) = value.get("error") {
            eprintln!("{}", error_line(error));
        } else {
            eprintln!("{text}");
        }
        Ok(Vec::new())
    }

    fn due(&mut self, seq: u64) -> Vec<Value> {
        let start = self.next_timed;
        while self.timed.get(self.next_timed).is_some_and(|(at, _)| *at <= seq) {
            self.next_timed += 1;
        }
        self.timed[start..self.next_timed].iter().map(|(_, control)| control.clone()).collect()
    }

    /// Reports the close; anything but 1000 (a refused open, a stream cut
    /// off) is a failure.
    fn closed(&self, frame: Option<CloseFrame>) -> anyhow::Result<()> {
        let (code, reason) = frame.map_or((1005, String::new()), |f| (u16::from(f.code), f.reason.to_string()));
        eprintln!("closed {code} {reason} after {} frames", self.frames);
        if code != NORMAL_CLOSE {
            bail!("the stream closed with {code} {reason}");
        }
        Ok(())
    }
}

/// A line from stdin as a control to send; a bad line is reported and skipped.
async fn typed_control(line: &str, names: &Names) -> Option<Value> {
    let line = line.trim();
    if line.is_empty() {
        return None;
    }
    let resolved = match control_object(line) {
        Ok(control) => names.resolve(control).await.map_err(|e| format!("{e:#}")),
        Err(e) => Err(e),
    };
    resolved.map_err(|e| eprintln!("not sent: {e}")).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn at_takes_a_frame_number_and_inline_json_or_a_file() {
        let crossfade = r#"{"op":"crossfade","to":{"layers":[{"clip":"name:Run"}]},"duration":0.5}"#;
        let timed = parse_at(&format!("30={crossfade}")).unwrap();
        assert_eq!(timed.seq, 30);
        assert_eq!(timed.control, Control::Inline(serde_json::from_str(crossfade).unwrap()));
        // The first '=' separates: JSON may hold more.
        let timed = parse_at(r#"2={"op":"seek","time":1,"note":"a=b"}"#).unwrap();
        assert_eq!(timed.control, Control::Inline(json!({"op": "seek", "time": 1, "note": "a=b"})));
        assert_eq!(
            parse_at("7=@examples/motions/x.json").unwrap().control,
            Control::File("examples/motions/x.json".into())
        );
    }

    #[test]
    fn set_takes_a_parameter_now_or_at_a_frame_and_groups_them_into_set_controls() {
        let settings: Vec<Setting> = ["speed=2.5", "survey=true", "120:speed=4", "60:speed=1", "60:survey=true"]
            .into_iter()
            .map(|s| parse_set(s).unwrap())
            .collect();
        assert_eq!(settings[2], Setting { seq: Some(120), name: "speed".into(), value: json!(4) });
        let (opening, timed) = set_controls(&settings);
        assert_eq!(opening, Some(json!({"op": "set", "parameters": {"speed": 2.5, "survey": true}})));
        assert_eq!(
            timed,
            [
                (60, json!({"op": "set", "parameters": {"speed": 1, "survey": true}})),
                (120, json!({"op": "set", "parameters": {"speed": 4}}))
            ]
        );
        assert_eq!(set_controls(&settings[2..3]).0, None);
        for (text, why) in [("speed", "NAME=VALUE"), ("x:speed=1", "frame number"), ("speed=fast", "not a number")] {
            let error = parse_set(text).unwrap_err();
            assert!(error.contains(why), "{text}: {error}");
        }
    }

    #[test]
    fn a_frame_line_shows_the_graph_state_a_transition_and_the_weights() {
        let frame = json!({"seq": 9, "clip_time": 0.15, "dropped": 0, "events": [], "pose": {"time": 0.15, "joints": []},
            "graph": {"state": "move", "transition": {"from": "idle", "to": "move", "alpha": 0.25},
                      "weights": {"move": [0.75, 0.25]}}});
        assert_eq!(
            frame_line(&frame),
            "seq=9 time=0.1500 clip_time=0.1500 dropped=0 events=[] state=idle>move@0.25 move=[0.75,0.25]"
        );
        let settled = json!({"seq": 1, "pose": {"graph": {"state": "idle", "weights": {}}}});
        assert!(frame_line(&settled).ends_with(" state=idle"), "{}", frame_line(&settled));
    }

    #[test]
    fn at_refuses_what_is_not_a_frame_and_an_object() {
        for (text, why) in [
            ("{\"op\":\"pause\"}", "SEQ=JSON"),
            ("x={\"op\":\"pause\"}", "frame number"),
            ("-1={\"op\":\"pause\"}", "frame number"),
            ("3=pause", "not JSON"),
            ("3=[1,2]", "JSON object"),
            ("3=@", "file name"),
        ] {
            let error = parse_at(text).unwrap_err();
            assert!(error.contains(why), "{text}: {error}");
        }
    }

    #[test]
    fn names_are_found_and_replaced_at_any_depth_and_ids_left_alone() {
        let mut doc = json!({"op": "crossfade", "duration": 1, "to": {"layers": [
            {"clip": "name:Walk", "sync": "locomotion"},
            {"clip": "0193a5b2-0000-7000-8000-000000000000", "weight": 0.3},
            {"clip": "name:Run", "mask": {"joints": {"clip": 1}}},
            {"clip": "name:Walk"}
        ]}});
        let names: Vec<String> = clip_names(&doc).into_iter().collect();
        assert_eq!(names, ["Run", "Walk"]);
        let ids = BTreeMap::from([("Walk".to_owned(), "id-w".to_owned()), ("Run".to_owned(), "id-r".to_owned())]);
        substitute_names(&mut doc, &ids);
        let expected = json!({"op": "crossfade", "duration": 1, "to": {"layers": [
            {"clip": "id-w", "sync": "locomotion"},
            {"clip": "0193a5b2-0000-7000-8000-000000000000", "weight": 0.3},
            {"clip": "id-r", "mask": {"joints": {"clip": 1}}},
            {"clip": "id-w"}
        ]}});
        assert_eq!(doc, expected);
    }

    #[test]
    fn a_name_must_match_exactly_one_clip() {
        assert_eq!(single_match("Walk", &json!({"clips": [{"id": "a"}], "next_cursor": null})).unwrap(), "a");
        let none = single_match("Walk", &json!({"clips": []})).unwrap_err().to_string();
        assert!(none.contains("no clip is named \"Walk\""), "{none}");
        let two = single_match("Walk", &json!({"clips": [{"id": "a"}, {"id": "b"}]})).unwrap_err().to_string();
        assert!(two.contains("a, b"), "{two}");
    }

    #[test]
    fn an_error_line_names_the_code_the_detail_and_the_pointer() {
        let problem = json!({"code": "unknown_joint", "detail": "joint 'x' is not there", "pointer": "/to/layers/0"});
        assert_eq!(error_line(&problem), "error unknown_joint: joint 'x' is not there (at /to/layers/0)");
        assert_eq!(error_line(&json!({"code": "bad_control", "detail": "no"})), "error bad_control: no");
    }

    #[test]
    fn a_frame_line_shows_times_events_root_motion_and_the_first_joint() {
        let frame = json!({"seq": 4, "clip_time": 0.5, "dropped": 1, "events": [{"time": 0.5, "name": "step"}],
            "pose": {"time": 0.25, "joints": [{"name": "hips", "translation": [1, 2.5, -3]}],
                     "root_motion": {"delta": {}, "total": {"translation": [0.5, 0, 2], "yaw": 0.125}}}});
        assert_eq!(
            frame_line(&frame),
            "seq=4 time=0.2500 clip_time=0.5000 dropped=1 events=[step] root_total=[0.5000,0.0000,2.0000] \
             yaw=0.1250 hips=[1.0000,2.5000,-3.0000]"
        );
        let solved = json!({"seq": 0, "clip_time": 0, "dropped": 0, "events": [], "pose": {"time": 0, "joints": [],
            "ik": [{"kind": "two_bone", "residual": 1.5e-7, "iterations": 0, "converged": true},
                   {"kind": "chain", "residual": 0.25, "iterations": 100, "converged": false}]}});
        assert_eq!(
            frame_line(&solved),
            "seq=0 time=0.0000 clip_time=0.0000 dropped=0 events=[] ik=[two_bone:1.5e-7:0,chain:2.5e-1:100!]"
        );
    }
}
