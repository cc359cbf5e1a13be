//! Broadcasts across nodes (docs/broadcasts.md "Many nodes"): real processes on one
//! PostgreSQL schema. A broadcast created on one node is watched on three;
//! controls (play, pause, seek, speed, layer, crossfade) are posted to
//! different nodes; for every `seq` the viewers received, the frames are
//! equal apart from `sent_at_unix_nanos` and `dropped`. A fourth node
//! started after the controls computes the same frames from the stored
//! ones; a DELETE on one node closes the viewers on the others with 1000.
//! A node started long after the controls steps on from the stored
//! checkpoint and sends the same frames.
//! A control stored for a tick already past makes every node rewind and
//! converge; the idle timeout counts the viewers of every node.
//!
//! The clips move one joint along x (and the second along y) at 1 unit/s,
//! so a frame's pose says which time and which blend it shows; the checks
//! of each control's effect at its stamp are made against that by hand.

use std::collections::BTreeMap;
use std::time::Duration;

use futures_util::StreamExt;
use serde_json::{Value, json};
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio_tungstenite::tungstenite::Message;

use super::Node;
use crate::common::eventually;
use crate::common::pg::Schema;

const FPS: u64 = 20;

/// Controls are stamped this far ahead, generous for a loaded 2-core machine:
/// a node that hears one late still converges, but the frames it already
/// sent would differ, which this test would report.
const LEAD_MS: &str = "250";

/// A clip moving `axis` of joint `j` from 0 to 10 over 10 s, looping.
fn line_doc(axis: usize) -> String {
    let end = |v: f64| {
        let mut p = [0.0; 3];
        p[axis] = v;
        p
    };
    json!({"name": format!("line{axis}"), "playback": "loop", "tracks": [{"joint": "j", "channel": "translation",
        "interpolation": "linear", "times": [0.0, 10.0], "values": [end(0.0), end(10.0)]}]})
    .to_string()
}

async fn upload(http: &reqwest::Client, node: &Node, doc: String) -> String {
    let resp =
        http.post(node.url("/v1/clips")).header("content-type", "application/json").body(doc).send().await.unwrap();
    assert_eq!(resp.status(), 201, "{}: upload", node.name);
    resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned()
}

async fn post_control(http: &reqwest::Client, node: &Node, id: &str, body: Value) -> u64 {
    let resp = http.post(node.url(&format!("/v1/broadcasts/{id}/controls"))).json(&body).send().await.unwrap();
    let status = resp.status().as_u16();
    let answer: Value = resp.json().await.unwrap();
    assert_eq!(status, 200, "{}: control {body}: {answer}", node.name);
    answer["seq"].as_u64().unwrap()
}

/// What one viewer received: each frame by `seq`, without the two fields
/// that are its own (`sent_at_unix_nanos`, `dropped`); and how it closed.
type Seen = (BTreeMap<u64, Value>, Option<u16>);

/// A viewer's task and how far it got: the first and the latest `seq` it
/// received (`None` before its first frame), so a test waits for frames
/// rather than for time.
struct Viewer {
    task: JoinHandle<Seen>,
    progress: watch::Receiver<Option<(u64, u64)>>,
}

impl Viewer {
    fn first(&self) -> Option<u64> {
        self.progress.borrow().map(|(first, _)| first)
    }

    fn latest(&self) -> Option<u64> {
        self.progress.borrow().map(|(_, latest)| latest)
    }
}

/// Waits until every viewer in `viewers` has received a frame at `seq` or later.
async fn until_seen(viewers: &[&Viewer], seq: u64, what: &str) {
    let what = format!("every viewer received seq {seq} ({what})");
    eventually(PROGRESS, &what, || async { viewers.iter().all(|v| v.latest().is_some_and(|l| l >= seq)) }).await;
}

/// Waits until every viewer in `viewers` has received its first frame.
async fn until_watching(viewers: &[&Viewer]) {
    eventually(PROGRESS, "every viewer received a frame", || async { viewers.iter().all(|v| v.first().is_some()) })
        .await;
}

/// Generous for a loaded 2-core machine: a node starting, a notification
/// crossing PostgreSQL, a few ticks streaming.
const PROGRESS: Duration = Duration::from_secs(20);

/// Watches broadcast `id` on `node` until it closes (or `limit`).
fn viewer(node: &Node, id: &str, limit: Duration) -> Viewer {
    let url = node.ws_url(&format!("/v1/broadcasts/{id}/stream"));
    let (report, progress) = watch::channel(None);
    let task = tokio::spawn(async move {
        let (mut ws, _) = tokio_tungstenite::connect_async(url).await.unwrap();
        let mut frames = BTreeMap::new();
        let deadline = tokio::time::Instant::now() + limit;
        loop {
            let next = tokio::time::timeout_at(deadline, ws.next()).await;
            match next {
                Ok(Some(Ok(Message::Text(text)))) => {
                    let mut frame: Value = serde_json::from_str(&text).unwrap();
                    let seq = frame["seq"].as_u64().unwrap();
                    let fields = frame.as_object_mut().unwrap();
                    fields.remove("sent_at_unix_nanos");
                    fields.remove("dropped");
                    frames.insert(seq, frame);
                    report.send_modify(|p| *p = Some((p.map_or(seq, |(first, _)| first), seq)));
                }
                Ok(Some(Ok(Message::Close(close)))) => return (frames, close.map(|c| u16::from(c.code))),
                Ok(Some(Ok(_))) => {}
                Ok(Some(Err(_)) | None) | Err(_) => return (frames, None),
            }
        }
    });
    Viewer { task, progress }
}

/// A frame's x and y of joint `j` and its motion time.
fn xy(frame: &Value) -> (f64, f64, f64) {
    let t = &frame["pose"]["joints"][0]["translation"];
    (t[0].as_f64().unwrap(), t[1].as_f64().unwrap(), frame["pose"]["time"].as_f64().unwrap())
}

/// One viewer's frames, named after its node, and whether that node rewound
/// (its `inbetween_broadcast_replays_total` moved: it heard a control after
/// the control's stamp).
struct Watched<'a> {
    name: &'a str,
    frames: &'a BTreeMap<u64, Value>,
    rewound: bool,
}

/// Compares the frames two viewers both received, seq by seq; returns how
/// many they share. They are equal, except where a node heard a control
/// late: the frames it sent from the stamp until it heard it do not show
/// the control, and the later ones are the other nodes' again
/// (docs/broadcasts.md "Many nodes"). So a difference is allowed only on a
/// node that rewound, only from `first_stamp` on, and the last ten shared
/// frames must agree (it converged).
fn agree(a: &Watched, b: &Watched, first_stamp: u64) -> usize {
    let shared: Vec<u64> = a.frames.keys().filter(|k| b.frames.contains_key(k)).copied().collect();
    let differ: Vec<u64> = shared.iter().copied().filter(|k| a.frames[k] != b.frames[k]).collect();
    if let Some(&k) = differ.first() {
        let why = format!("seq {k}: {} and {} differ ({} frames differ)", a.name, b.name, differ.len());
        assert!(a.rewound || b.rewound, "{why}, and neither node rewound");
        assert!(k >= first_stamp, "{why}, before any control");
        let tail = &shared[shared.len().saturating_sub(10)..];
        assert!(tail.iter().all(|k| !differ.contains(k)), "{why}, and they never converged: {differ:?}");
        eprintln!("{why}: the rewound node's frames before it heard a control");
    }
    shared.len()
}

async fn metric(http: &reqwest::Client, node: &Node, name: &str) -> f64 {
    let text = http.get(node.url("/metrics")).send().await.unwrap().text().await.unwrap();
    text.lines().find_map(|l| l.strip_prefix(name)?.trim().parse().ok()).unwrap_or(0.0)
}

async fn node(schema: &Schema, name: &str) -> Node {
    Node::serve()
        .name(name)
        .args(["--db-max-connections", "4", "--broadcast-control-lead-ms", LEAD_MS, "--database-url"])
        .arg(schema.url(&format!("application_name={name}")))
        .start()
        .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_node_computes_the_same_frames_before_and_after_controls() {
    let Some(schema) = Schema::create("bcast").await else { return };
    let (a, b, c) = (node(&schema, "node-a").await, node(&schema, "node-b").await, node(&schema, "node-c").await);
    let http = crate::common::http_client();
    // A node is ready before it listens for announcements; one that missed a
    // control's would apply it only at its resync, late, and the frames it
    // sent meanwhile would differ (as they may: docs/broadcasts.md "Many nodes").
    for n in [&a, &b, &c] {
        super::until_subscribed(&http, n).await;
    }
    let x = upload(&http, &a, line_doc(0)).await;
    let y = upload(&http, &b, line_doc(1)).await;

    let body = json!({"motion": {"layers": [{"clip": x}, {"clip": y, "weight": 0.5}]}, "fps": FPS});
    let resp = http.post(a.url("/v1/broadcasts")).json(&body).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();

    // Watched on all three (B and C may not have heard of it yet: they read it from the store).
    let limit = Duration::from_secs(30);
    let viewers = [viewer(&a, &id, limit), viewer(&b, &id, limit), viewer(&c, &id, limit)];
    let all: Vec<&Viewer> = viewers.iter().collect();
    until_watching(&all).await;
    // Each control is shown for `held` ticks on every viewer before the next
    // is posted (the checks below look up to 5 ticks past a stamp).
    let held = 8;
    let mut stamps = BTreeMap::new();
    stamps.insert("pause", post_control(&http, &b, &id, json!({"op": "pause"})).await);
    until_seen(&all, stamps["pause"] + held, "pause").await;
    stamps.insert("play", post_control(&http, &c, &id, json!({"op": "play"})).await);
    until_seen(&all, stamps["play"] + held, "play").await;
    stamps.insert("seek", post_control(&http, &a, &id, json!({"op": "seek", "time": 9.0})).await);
    until_seen(&all, stamps["seek"] + held, "seek").await;
    stamps.insert("speed", post_control(&http, &b, &id, json!({"op": "speed", "speed": -2.0})).await);
    until_seen(&all, stamps["speed"] + held, "speed").await;
    let layer = json!({"op": "layer", "index": 1, "weight": 1.0, "duration": 0.5});
    stamps.insert("layer", post_control(&http, &a, &id, layer).await);
    until_seen(&all, stamps["layer"] + held, "layer").await;
    let fade = json!({"op": "crossfade", "to": {"layers": [{"clip": x}]}, "duration": 0.5});
    stamps.insert("crossfade", post_control(&http, &c, &id, fade).await);
    until_seen(&all, stamps["crossfade"] + FPS, "crossfade").await;

    // A node started after every control computes the same frames from the stored ones.
    let d = node(&schema, "node-d").await;
    let late = viewer(&d, &id, limit);
    until_watching(&[&late]).await;
    let shared_from = late.first().unwrap() + 12;
    until_seen(&[&viewers[0], &late], shared_from, "D and A share frames").await;

    // DELETE on B ends it for the viewers on A, C and D.
    let resp = http.delete(b.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap();
    assert_eq!(resp.status(), 204);
    let mut seen = Vec::new();
    for (name, v) in ["A", "B", "C", "D"].into_iter().zip(viewers.into_iter().chain([late])) {
        let (frames, close) =
            tokio::time::timeout(Duration::from_secs(5), v.task).await.expect("closed in time").unwrap();
        assert_eq!(close, Some(1000), "{name}'s viewer closed with 1000");
        seen.push((name, frames));
    }
    let mut replays = Vec::new();
    for n in [&a, &b, &c, &d] {
        replays.push(metric(&http, n, "inbetween_broadcast_replays_total").await);
    }
    eprintln!("broadcast replays: A {} B {} C {} D {}", replays[0], replays[1], replays[2], replays[3]);
    let seen: Vec<Watched> =
        seen.iter().zip(&replays).map(|((name, frames), &r)| Watched { name, frames, rewound: r > 0.0 }).collect();
    let (first_stamp, last_stamp) = (*stamps.values().min().unwrap(), *stamps.values().max().unwrap());
    for other in &seen[1..] {
        let shared = agree(&seen[0], other, first_stamp);
        eprintln!("A and {} share {shared} frames", other.name);
        if other.name == "D" {
            assert!(shared >= 10, "D shares {shared} frames with A");
            assert!(other.frames.keys().all(|&k| k > last_stamp), "D joined after the controls");
        } else {
            assert!(shared as u64 >= last_stamp, "{} shares only {shared} frames", other.name);
        }
    }
    // Each control shows at its stamp, on the frames of the nodes that never
    // rewound where they have them (those of one that did may predate a control).
    let mut f = BTreeMap::new();
    for w in seen.iter().filter(|w| w.rewound).chain(seen.iter().filter(|w| !w.rewound)) {
        f.extend(w.frames.iter().map(|(k, v)| (*k, v.clone())));
    }
    let at = |k: u64| xy(f.get(&k).unwrap_or_else(|| panic!("no viewer received seq {k}")));
    let (p, s) = (stamps["pause"], stamps["seek"]);
    assert_eq!(at(p).2, at(p - 1).2, "paused at its stamp");
    assert_eq!(at(p + 3).2, at(p - 1).2, "held while paused");
    assert!(at(stamps["play"]).2 > at(stamps["play"] - 1).2, "playing again");
    assert!((at(s).2 - 9.0).abs() < 1e-9, "the seek shows 9 s at its stamp: {:?}", at(s));
    let v = stamps["speed"];
    assert!((at(v).2 - (at(v - 1).2 - 2.0 / FPS as f64)).abs() < 1e-6, "speed -2 from its stamp");
    let l = stamps["layer"];
    // y is the layer's weight times the time (while the time is in (0, 10)).
    let weight = |k: u64| at(k).1 / at(k).2;
    assert!((weight(l - 1) - 0.5).abs() < 1e-3, "layer 1 at 0.5 before: {:?}", at(l - 1));
    assert!(stamps["crossfade"] > l + 5);
    assert!((weight(l + 5) - 1.0).abs() < 1e-3, "layer 1 ramped to 1 in 0.5 s at speed 2: {:?}", at(l + 5));
    let cf = stamps["crossfade"];
    assert!(at(cf + 12).1.abs() < 1e-6, "after the crossfade to x alone, y is 0: {:?}", at(cf + 12));
    // Gone everywhere.
    for n in [&a, &c, &d] {
        let resp = http.get(n.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap();
        assert_eq!(resp.status(), 404, "{}", n.name);
    }
    drop((a, b, c, d));
    schema.drop_now().await;
}

/// A control stored for a tick every node has already stepped (as a node
/// would see one it heard late): each node rewinds to a snapshot before its
/// stamp and steps again, and from then on they agree with each other and
/// with a node that started after it and computed everything from tick 0.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nodes_that_hear_a_control_for_a_past_tick_converge() {
    let Some(schema) = Schema::create("bpast").await else { return };
    let (a, b) = (node(&schema, "node-a").await, node(&schema, "node-b").await);
    let http = crate::common::http_client();
    // Both hear the insert below when it is made (not at a resync).
    for n in [&a, &b] {
        super::until_subscribed(&http, n).await;
    }
    let x = upload(&http, &a, line_doc(0)).await;
    let body = json!({"motion": {"layers": [{"clip": x}]}, "fps": FPS});
    let resp = http.post(a.url("/v1/broadcasts")).json(&body).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    let limit = Duration::from_secs(30);
    let viewers = [viewer(&a, &id, limit), viewer(&b, &id, limit)];
    // Both nodes have stepped (and streamed) well past the tick the control is stamped for.
    until_seen(&viewers.iter().collect::<Vec<_>>(), 30, "1.5 s of frames").await;

    // Stamped 20 ticks (1 s) ago, stored behind the nodes' backs: announced like any control.
    let summary: Value = http.get(a.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap().json().await.unwrap();
    let past = summary["seq"].as_u64().unwrap() - 20;
    let replays = "inbetween_broadcast_replays_total";
    let before = [metric(&http, &a, replays).await, metric(&http, &b, replays).await];
    let db = sqlx::PgPool::connect(&schema.url("")).await.unwrap();
    sqlx::query("INSERT INTO broadcast_controls (id, broadcast_id, seq, control) VALUES ($1, $2, $3, $4)")
        .bind(uuid::Uuid::now_v7().to_string())
        .bind(&id)
        .bind(past as i64)
        .bind(json!({"message": {"op": "seek", "time": 7.5}, "versions": {}}).to_string())
        .execute(&db)
        .await
        .unwrap();
    // Each node applies it when it hears of it, by rewinding: once both
    // have, every frame they send from their tick then on shows it.
    for (n, before) in [&a, &b].into_iter().zip(before) {
        let what = format!("{} rewound for the past control", n.name);
        eventually(Duration::from_secs(20), &what, || async { metric(&http, n, replays).await > before }).await;
    }
    let mut settled = 0;
    for n in [&a, &b] {
        let summary: Value =
            http.get(n.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap().json().await.unwrap();
        settled = settled.max(summary["seq"].as_u64().unwrap() + 1);
    }
    let c = node(&schema, "node-c").await;
    let late = viewer(&c, &id, limit);
    until_watching(&[&late]).await;
    let shared_from = late.first().unwrap().max(settled) + 12;
    until_seen(&[&viewers[0], &viewers[1], &late], shared_from.max(settled + 22), "A, B and C past the seek").await;
    let resp = http.delete(a.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap();
    assert_eq!(resp.status(), 204);
    let mut seen = Vec::new();
    for v in viewers.into_iter().chain([late]) {
        seen.push(tokio::time::timeout(Duration::from_secs(5), v.task).await.expect("closed in time").unwrap().0);
    }
    // From the tick both had rewound by, every node shows the seek as of its (past) stamp, alike.
    let after = |f: &BTreeMap<u64, Value>| f.range(settled..).map(|(k, v)| (*k, v.clone())).collect::<BTreeMap<_, _>>();
    let (fa, fb, fc) = (after(&seen[0]), after(&seen[1]), after(&seen[2]));
    let watched = |name, frames| Watched { name, frames, rewound: false };
    assert!(agree(&watched("A", &fa), &watched("B", &fb), past) >= 20);
    assert!(agree(&watched("A", &fa), &watched("C", &fc), past) >= 10, "C computed it from tick 0");
    for (k, frame) in &fa {
        let want = 7.5 + (k - past) as f64 / FPS as f64;
        assert!((xy(frame).2 - want).abs() < 1e-9, "seq {k}: {:?}, want time {want}", xy(frame));
    }
    db.close().await;
    drop((a, b, c));
    schema.drop_now().await;
}

/// The idle timeout counts viewers on every node: a broadcast created on A
/// and watched only on B lives on past its timeout; once nobody watches
/// anywhere, it ends on every node.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_idle_timeout_counts_viewers_on_every_node() {
    let Some(schema) = Schema::create("bidle").await else { return };
    let (a, b) = (node(&schema, "node-a").await, node(&schema, "node-b").await);
    let http = crate::common::http_client();
    let x = upload(&http, &a, line_doc(0)).await;
    let body = json!({"motion": {"layers": [{"clip": x}]}, "fps": FPS, "idle_timeout_secs": 2});
    let resp = http.post(a.url("/v1/broadcasts")).json(&body).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    let status = |n: &Node| {
        let (http, url) = (http.clone(), n.url(&format!("/v1/broadcasts/{id}")));
        async move { http.get(url).send().await.unwrap().status().as_u16() }
    };

    let watching = viewer(&b, &id, Duration::from_secs(4));
    // The time is the behaviour here: watched past its 2 s idle timeout.
    tokio::time::sleep(Duration::from_millis(3500)).await;
    assert_eq!(status(&a).await, 200, "watched on B: alive on A past its 2 s");
    let (frames, _) = watching.task.await.unwrap();
    assert!(frames.len() > 60, "B's viewer saw {} frames", frames.len());
    // Nobody watches now: within the timeout and a check or two, gone on both.
    let started = tokio::time::Instant::now();
    eventually(Duration::from_secs(6), "gone on A and B after the last viewer", || async {
        status(&a).await == 404 && status(&b).await == 404
    })
    .await;
    assert!(started.elapsed() > Duration::from_millis(1000), "not before its idle timeout");
    drop((a, b));
    schema.drop_now().await;
}

/// docs/broadcasts.md "Checkpoints", across nodes: A and B run a broadcast
/// checkpointed every second; its seek, speed and crossfade are long behind
/// the newest checkpoint (their rows let go) when a node D starts. D steps
/// on from the stored checkpoint — a few seconds of ticks, not the
/// broadcast's age — and its frames equal A's.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_late_node_steps_on_from_the_stored_checkpoint_and_sends_the_same_frames() {
    let Some(schema) = Schema::create("bckpt").await else { return };
    let start = |name: &'static str| {
        Node::serve()
            .name(name)
            .args(["--db-max-connections", "4", "--broadcast-control-lead-ms", LEAD_MS])
            .args(["--broadcast-checkpoint-secs", "1", "--database-url"])
            .arg(schema.url(&format!("application_name={name}")))
            .start()
    };
    let (a, b) = (start("node-a").await, start("node-b").await);
    let http = crate::common::http_client();
    for n in [&a, &b] {
        super::until_subscribed(&http, n).await;
    }
    let (x, y) = (upload(&http, &a, line_doc(0)).await, upload(&http, &a, line_doc(1)).await);
    let body = json!({"motion": {"layers": [{"clip": x}, {"clip": y, "weight": 0.5}]}, "fps": FPS});
    let resp = http.post(a.url("/v1/broadcasts")).json(&body).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    let limit = Duration::from_secs(60);
    let watched = viewer(&a, &id, limit);
    until_watching(&[&watched]).await;
    post_control(&http, &b, &id, json!({"op": "seek", "time": 3.0})).await;
    post_control(&http, &a, &id, json!({"op": "speed", "speed": 1.5})).await;
    let fade = json!({"op": "crossfade", "to": {"layers": [{"clip": y}]}, "duration": 2.0, "ease": "ease_in_out"});
    let faded = post_control(&http, &b, &id, fade).await;
    // Six checkpoints later every control is long behind the newest stored one.
    let age = faded + 6 * FPS;
    until_seen(&[&watched], age, "six checkpoint intervals past the controls").await;
    eventually(PROGRESS, "A stored checkpoints", || async {
        metric(&http, &a, "inbetween_broadcast_checkpoints_total").await >= 4.0
    })
    .await;

    let d = start("node-d").await;
    let late = viewer(&d, &id, limit);
    until_watching(&[&late]).await;
    let first = late.first().unwrap();
    until_seen(&[&watched, &late], first + 20, "D and A share frames").await;
    let replayed = metric(&http, &d, "inbetween_broadcast_replayed_ticks_total").await as u64;
    // The newest checkpoint is at most two intervals behind, plus D's start and a second of slack.
    assert!(replayed <= 5 * FPS, "D replayed {replayed} ticks of a broadcast {first} ticks old");
    assert!(replayed + 3 * FPS < first, "D replayed {replayed} of {first} ticks: from a checkpoint");

    let resp = http.delete(a.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap();
    assert_eq!(resp.status(), 204);
    let (mine, _) = tokio::time::timeout(Duration::from_secs(5), watched.task).await.unwrap().unwrap();
    let (theirs, _) = tokio::time::timeout(Duration::from_secs(5), late.task).await.unwrap().unwrap();
    let shared: Vec<u64> = theirs.keys().filter(|k| mine.contains_key(k)).copied().collect();
    assert!(shared.len() >= 20, "D shares {} frames with A", shared.len());
    for k in shared {
        assert_eq!(mine[&k], theirs[&k], "seq {k}: A and D");
    }
    drop((a, b, d));
    schema.drop_now().await;
}

/// A clip whose tail (three 0.1 m bones behind `hips`) hangs under gravity
/// while `hips` swings along x, with the tail as a spring chain
/// (docs/springs.md): every frame's tail depends on the whole simulation
/// before it.
fn tailed_doc() -> String {
    json!({
        "name": "tailed",
        "skeleton": {"joints": [
            {"name": "hips", "parent": null},
            {"name": "tail0", "parent": "hips", "rest": {"translation": [0, 0, -0.1]}},
            {"name": "tail1", "parent": "tail0", "rest": {"translation": [0, 0, -0.1]}},
            {"name": "tail_end", "parent": "tail1", "rest": {"translation": [0, 0, -0.1]}}
        ]},
        "tracks": [{"joint": "hips", "channel": "translation", "interpolation": "linear",
                    "times": [0, 0.5, 1], "values": [[0, 0, 0], [0.3, 0, 0], [0, 0, 0]]}],
        "playback": "loop",
        "springs": [{"name": "tail", "joints": ["tail0", "tail1", "tail_end"], "gravity": [0, -9.81, 0]}]
    })
    .to_string()
}

/// docs/springs.md "Time", across nodes: a broadcast of a clip with a spring
/// chain, watched on A and B, sends the same bytes for every frame both
/// received (after a pause and a seek, which restarts the chain); a node D
/// started after several checkpoints steps on from the stored one (which
/// carries the chain's state) and sends the same frames as A.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broadcast_with_springs_is_the_same_on_every_node_and_after_a_checkpoint() {
    let Some(schema) = Schema::create("bsprng").await else { return };
    let start = |name: &'static str| {
        Node::serve()
            .name(name)
            .args(["--db-max-connections", "4", "--broadcast-control-lead-ms", LEAD_MS])
            .args(["--broadcast-checkpoint-secs", "1", "--database-url"])
            .arg(schema.url(&format!("application_name={name}")))
            .start()
    };
    let (a, b) = (start("node-a").await, start("node-b").await);
    let http = crate::common::http_client();
    for n in [&a, &b] {
        super::until_subscribed(&http, n).await;
    }
    let clip = upload(&http, &a, tailed_doc()).await;
    let body = json!({"motion": {"layers": [{"clip": clip}]}, "fps": FPS, "space": "model"});
    let resp = http.post(a.url("/v1/broadcasts")).json(&body).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    let limit = Duration::from_secs(60);
    let (on_a, on_b) = (viewer(&a, &id, limit), viewer(&b, &id, limit));
    until_watching(&[&on_a, &on_b]).await;
    let paused = post_control(&http, &b, &id, json!({"op": "pause"})).await;
    until_seen(&[&on_a, &on_b], paused + FPS, "a second of settling while paused").await;
    post_control(&http, &a, &id, json!({"op": "play"})).await;
    let sought = post_control(&http, &b, &id, json!({"op": "seek", "time": 0.25})).await;
    until_seen(&[&on_a, &on_b], sought + 6 * FPS, "six checkpoint intervals past the controls").await;
    eventually(PROGRESS, "A stored checkpoints", || async {
        metric(&http, &a, "inbetween_broadcast_checkpoints_total").await >= 4.0
    })
    .await;
    let d = start("node-d").await;
    let late = viewer(&d, &id, limit);
    until_watching(&[&late]).await;
    let first = late.first().unwrap();
    until_seen(&[&on_a, &on_b, &late], first + 20, "D, A and B share frames").await;
    let replayed = metric(&http, &d, "inbetween_broadcast_replayed_ticks_total").await as u64;
    assert!(replayed + 3 * FPS < first, "D replayed {replayed} of {first} ticks: from a checkpoint");

    let resp = http.delete(a.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap();
    assert_eq!(resp.status(), 204);
    let take =
        |v: Viewer| async move { tokio::time::timeout(Duration::from_secs(5), v.task).await.unwrap().unwrap().0 };
    let (seen_a, seen_b, seen_d) = (take(on_a).await, take(on_b).await, take(late).await);
    // The tail really swings: a frame's tail is not where its rest pose puts it.
    let tail_end = |frame: &Value| frame["pose"]["joints"][3]["translation"].clone();
    let last = seen_a.values().last().unwrap();
    assert!(tail_end(last)[1].as_f64().unwrap() < -0.01, "the tail hangs under gravity: {last}");
    let sought_frame = &seen_a[&sought];
    let rest = [0.25 * 0.6, 0.0, -0.3];
    let at_seek: Vec<f64> = tail_end(sought_frame).as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!(
        at_seek.iter().zip(rest).all(|(x, r)| (x - r).abs() < 1e-6),
        "the seek's tick shows the rest pose: {at_seek:?}"
    );
    for (other, name) in [(&seen_b, "B"), (&seen_d, "D")] {
        let shared: Vec<u64> = other.keys().filter(|k| seen_a.contains_key(k)).copied().collect();
        assert!(shared.len() >= 20, "{name} shares {} frames with A", shared.len());
        for k in shared {
            assert_eq!(seen_a[&k], other[&k], "seq {k}: A and {name}");
        }
    }
    drop((a, b, d));
    schema.drop_now().await;
}

/// A graph over the two lines: `s` blends them, the trigger `go` fades to
/// the second alone, and `s` under 0.5 fades back (docs/graphs.md).
fn lines_graph(x: &str, y: &str) -> Value {
    json!({"name": "lines",
        "parameters": {"s": {"type": "float", "default": 0, "min": 0, "max": 1}, "go": {"type": "trigger"}},
        "nodes": {"mix": {"blend1d": {"parameter": "s", "points": [{"clip": x, "at": 0}, {"clip": y, "at": 1}]}},
                  "y": {"clip": y}},
        "machine": {"initial": "mix", "states": {"mix": {"node": "mix"}, "y": {"node": "y"}},
            "transitions": [{"from": "mix", "to": "y", "when": {"trigger": "go"}, "duration": 0.5},
                            {"from": "y", "to": "mix", "when": {"parameter": "s", "lt": 0.5}, "duration": 0.5}]}})
}

/// docs/graphs.md "Streams and broadcasts", across nodes: a graph broadcast
/// created on A, its `set`s posted to B and A, gives A and B the same
/// frames, each showing the setting from the seq it answered; a node D
/// started after several checkpoints steps on from the stored one (which
/// carries the graph player's state: values, states, node times, the fade)
/// and sends the same frames as A.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_graph_broadcast_set_on_one_node_gives_every_node_the_same_frames_and_checkpoints() {
    let Some(schema) = Schema::create("bgraph").await else { return };
    let start = |name: &'static str| {
        Node::serve()
            .name(name)
            .args(["--db-max-connections", "4", "--broadcast-control-lead-ms", LEAD_MS])
            .args(["--broadcast-checkpoint-secs", "1", "--database-url"])
            .arg(schema.url(&format!("application_name={name}")))
            .start()
    };
    let (a, b) = (start("node-a").await, start("node-b").await);
    let http = crate::common::http_client();
    for n in [&a, &b] {
        super::until_subscribed(&http, n).await;
    }
    let (x, y) = (upload(&http, &a, line_doc(0)).await, upload(&http, &a, line_doc(1)).await);
    let resp = http.post(a.url("/v1/graphs")).json(&lines_graph(&x, &y)).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let graph = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    let body = json!({"motion": {"layers": [{"graph": graph}]}, "fps": FPS, "report": true});
    let resp = http.post(a.url("/v1/broadcasts")).json(&body).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    let limit = Duration::from_secs(60);
    let (on_a, on_b) = (viewer(&a, &id, limit), viewer(&b, &id, limit));
    until_watching(&[&on_a, &on_b]).await;
    let set = post_control(&http, &b, &id, json!({"op": "set", "parameters": {"s": 0.25}})).await;
    until_seen(&[&on_a, &on_b], set + FPS, "a second of the blend").await;
    let went = post_control(&http, &a, &id, json!({"op": "set", "parameters": {"go": true, "s": 0.75}})).await;
    until_seen(&[&on_a, &on_b], went + 6 * FPS, "six checkpoint intervals past the sets").await;
    eventually(PROGRESS, "A stored checkpoints", || async {
        metric(&http, &a, "inbetween_broadcast_checkpoints_total").await >= 4.0
    })
    .await;
    let back = post_control(&http, &b, &id, json!({"op": "set", "parameters": {"s": 0.0}})).await;
    let d = start("node-d").await;
    let late = viewer(&d, &id, limit);
    until_watching(&[&late]).await;
    let first = late.first().unwrap();
    until_seen(&[&on_a, &on_b, &late], (first + 20).max(back + 2 * FPS), "D, A and B share frames").await;
    let replayed = metric(&http, &d, "inbetween_broadcast_replayed_ticks_total").await as u64;
    assert!(replayed + 3 * FPS < first, "D replayed {replayed} of {first} ticks: from a checkpoint");

    let resp = http.delete(a.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap();
    assert_eq!(resp.status(), 204);
    let take =
        |v: Viewer| async move { tokio::time::timeout(Duration::from_secs(5), v.task).await.unwrap().unwrap().0 };
    let (seen_a, seen_b, seen_d) = (take(on_a).await, take(on_b).await, take(late).await);
    let report = |k: u64| &seen_a[&k]["graph"];
    let weights = |k: u64| -> Vec<f64> {
        report(k)["weights"]["mix"].as_array().unwrap().iter().map(|w| w.as_f64().unwrap()).collect()
    };
    assert_eq!(weights(set - 1), [1.0, 0.0], "before the set: {}", report(set - 1));
    assert_eq!(weights(set), [0.75, 0.25], "from the set's seq: {}", report(set));
    assert_eq!(report(went)["state"], "y", "the trigger fires at its seq: {}", report(went));
    assert_eq!(report(back)["state"], "mix", "s under 0.5 fades back at its seq: {}", report(back));
    for (other, name) in [(&seen_b, "B"), (&seen_d, "D")] {
        let shared: Vec<u64> = other.keys().filter(|k| seen_a.contains_key(k)).copied().collect();
        assert!(shared.len() >= 20, "{name} shares {} frames with A", shared.len());
        for k in shared {
            assert_eq!(seen_a[&k], other[&k], "seq {k}: A and {name}");
        }
    }
    drop((a, b, d));
    schema.drop_now().await;
}
