//! Broadcast checkpoints on one node with SQLite (docs/broadcasts.md
//! "Checkpoints"): a broadcast at 240 fps checkpointed every second runs
//! for several seconds with a seek and a speed change in its journal; the
//! server is stopped and started again on the same store; its first frame
//! after the restart comes after stepping at most one checkpoint interval,
//! a second and the time it was down, with another interval of slack
//! (`inbetween_broadcast_replayed_ticks_total`),
//! far fewer ticks than the broadcast's age, and shows the time the
//! controls say — which the restarted node read from the checkpoint, as
//! the journal no longer has them. A graph broadcast restarted the same way
//! shows what `POST /v1/samples` plays for its settings.

use std::time::{Duration, Instant};

use futures_util::StreamExt;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::{ServerProcess, start};
use crate::common::{eventually, latency_checked, metric};

const FPS: u64 = 240;
const CHECKPOINT_SECS: u64 = 1;

/// One joint moving along x at 1 unit/s over 100 s, looping.
const LINE: &str = r#"{"name": "line", "playback": "loop", "tracks": [{"joint": "j", "channel": "translation",
    "interpolation": "linear", "times": [0.0, 100.0], "values": [[0, 0, 0], [100, 0, 0]]}]}"#;

async fn post(http: &reqwest::Client, server: &ServerProcess, path: &str, body: Value) -> Value {
    let resp = http.post(server.url(path)).json(&body).send().await.unwrap();
    let status = resp.status().as_u16();
    let answer: Value = resp.json().await.unwrap();
    assert!(status == 200 || status == 201, "{path} {body}: {status} {answer}");
    answer
}

async fn seq_now(http: &reqwest::Client, server: &ServerProcess, id: &str) -> u64 {
    let summary: Value =
        http.get(server.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap().json().await.unwrap();
    summary["seq"].as_u64().unwrap_or(0)
}

async fn metric_of(http: &reqwest::Client, server: &ServerProcess, name: &str) -> f64 {
    let text = http.get(server.url("/metrics")).send().await.unwrap().text().await.unwrap();
    metric(&text, name).unwrap_or(0.0)
}

/// The server's CPU time so far (user + system), from `/proc/PID/stat`.
fn cpu(server: &ServerProcess) -> Duration {
    let stat = std::fs::read_to_string(format!("/proc/{}/stat", server.pid())).unwrap_or_default();
    let after = stat.rsplit_once(')').map_or("", |(_, rest)| rest);
    let fields: Vec<u64> = after.split_whitespace().map(|f| f.parse().unwrap_or(0)).collect();
    let ticks = fields.get(11).copied().unwrap_or(0) + fields.get(12).copied().unwrap_or(0);
    Duration::from_millis(ticks * 10)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restarted_node_replays_from_the_last_checkpoint_not_from_the_start() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let flags = ["--broadcast-checkpoint-secs", "1", "--broadcast-control-lead-ms", "0"];
    let http = reqwest::Client::new();
    let server = start(&data, &flags).await;
    let clip = server.create(&http, LINE).await;
    let created =
        post(&http, &server, "/v1/broadcasts", json!({"motion": {"layers": [{"clip": clip}]}, "fps": FPS})).await;
    let id = created["id"].as_str().unwrap().to_owned();
    let controls = format!("/v1/broadcasts/{id}/controls");
    let seek = post(&http, &server, &controls, json!({"op": "seek", "time": 2.0})).await["seq"].as_u64().unwrap();
    // The speed change a few ticks later, not at the seek's own tick (posted at once, both could take one tick).
    eventually(Duration::from_secs(10), "ticks after the seek", || async {
        seq_now(&http, &server, &id).await >= seek + 2
    })
    .await;
    let slow = post(&http, &server, &controls, json!({"op": "speed", "speed": 0.5})).await["seq"].as_u64().unwrap();
    // Six seconds of broadcast time: checkpoints every 240 ticks, the controls long behind the newest.
    let age = 6 * FPS;
    eventually(Duration::from_secs(20), "six seconds of broadcast", || async {
        seq_now(&http, &server, &id).await >= age
    })
    .await;
    server.until_metric(&http, "inbetween_broadcast_checkpoints_total", 4.0).await;
    server.signal("TERM");
    let mut server = server;
    assert!(server.wait_exit(Duration::from_secs(10)).await.is_some_and(|s| s.success()), "a clean stop");
    let stopped = Instant::now();

    let server = start(&data, &flags).await;
    let (mut ws, _) = tokio_tungstenite::connect_async(server.ws_url(&format!("/v1/broadcasts/{id}/stream")))
        .await
        .expect("the broadcast resumed");
    let first: Value = loop {
        match ws.next().await.expect("a frame").expect("a frame") {
            Message::Text(text) => break serde_json::from_str(&text).unwrap(),
            Message::Close(c) => panic!("closed: {c:?}"),
            _ => continue,
        }
    };
    let down = stopped.elapsed();
    // Everything the process did from its start: the catch-up runs as it starts.
    let cpu_used = cpu(&server);
    let k = first["seq"].as_u64().unwrap();
    // One interval and a second behind at most, the ticks it was down, and an interval of slack for the start.
    let bound = (2 * CHECKPOINT_SECS + 1) * FPS + (down.as_secs_f64() * FPS as f64) as u64;
    let replayed = metric_of(&http, &server, "inbetween_broadcast_replayed_ticks_total").await as u64;
    assert!(replayed <= bound, "replayed {replayed} ticks, at most {bound} (down {down:?}, the broadcast at tick {k})");
    assert!(replayed + 3 * FPS <= k, "replayed {replayed} ticks of a broadcast {k} ticks old: from a checkpoint");
    // The controls' effect, from the checkpoint: 2.0 at the seek, then half speed from tick `slow − 1`'s time on.
    let at_speed = 2.0 + (slow - 1 - seek) as f64 / FPS as f64;
    let want = at_speed + (k - (slow - 1)) as f64 * 0.5 / FPS as f64;
    let time = first["pose"]["time"].as_f64().unwrap();
    assert!((time - want).abs() < 1e-9, "tick {k}: time {time}, the controls say {want}");
    if latency_checked() {
        assert!(cpu_used < Duration::from_secs(1), "{cpu_used:?} of CPU from the start to the first frame");
    }
    eprintln!("restart: first frame at tick {k}, {replayed} ticks replayed, {cpu_used:?} CPU, down {down:?}");
}

/// One joint moving along y at 1 unit/s over 100 s, looping.
const RISE: &str = r#"{"name": "rise", "playback": "loop", "tracks": [{"joint": "j", "channel": "translation",
    "interpolation": "linear", "times": [0.0, 100.0], "values": [[0, 0, 0], [0, 100, 0]]}]}"#;

/// docs/graphs.md "Streams and broadcasts": a graph broadcast whose `set`s
/// (a blend's parameter, then a trigger that fades to another state) are
/// long behind its newest checkpoint is stopped and started again on the
/// same store; its first frame after the restart, stepped from the
/// checkpoint (which holds the graph player's state), is the tick `POST
/// /v1/samples` plays for the same settings at the same ticks.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restarted_graph_broadcast_steps_on_from_its_checkpoint_as_samples_play_it() {
    const GRAPH_FPS: u64 = 30;
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let flags = ["--broadcast-checkpoint-secs", "1", "--broadcast-control-lead-ms", "0"];
    let http = reqwest::Client::new();
    let server = start(&data, &flags).await;
    let (x, y) = (server.create(&http, LINE).await, server.create(&http, RISE).await);
    let graph = json!({"name": "restart",
        "parameters": {"s": {"type": "float", "default": 0, "min": 0, "max": 1}, "go": {"type": "trigger"}},
        "nodes": {"mix": {"blend1d": {"parameter": "s", "points": [{"clip": x, "at": 0}, {"clip": y, "at": 1}]}},
                  "up": {"clip": y}},
        "machine": {"initial": "mix", "states": {"mix": {"node": "mix"}, "up": {"node": "up"}},
            "transitions": [{"from": "mix", "to": "up", "when": {"trigger": "go"}, "duration": 2.0}]}});
    let graph = post(&http, &server, "/v1/graphs", graph).await["id"].as_str().unwrap().to_owned();
    let motion = json!({"layers": [{"graph": graph}]});
    let created =
        post(&http, &server, "/v1/broadcasts", json!({"motion": motion, "fps": GRAPH_FPS, "report": true})).await;
    let id = created["id"].as_str().unwrap().to_owned();
    let controls = format!("/v1/broadcasts/{id}/controls");
    let set = |parameters: Value| json!({"op": "set", "parameters": parameters});
    let blend = post(&http, &server, &controls, set(json!({"s": 0.6}))).await["seq"].as_u64().unwrap();
    eventually(Duration::from_secs(10), "ticks after the set", || async {
        seq_now(&http, &server, &id).await >= blend + 2
    })
    .await;
    let went = post(&http, &server, &controls, set(json!({"go": true}))).await["seq"].as_u64().unwrap();
    eventually(Duration::from_secs(20), "six seconds of broadcast", || async {
        seq_now(&http, &server, &id).await >= went + 6 * GRAPH_FPS
    })
    .await;
    server.until_metric(&http, "inbetween_broadcast_checkpoints_total", 4.0).await;
    server.signal("TERM");
    let mut server = server;
    assert!(server.wait_exit(Duration::from_secs(10)).await.is_some_and(|s| s.success()), "a clean stop");

    let server = start(&data, &flags).await;
    let (mut ws, _) = tokio_tungstenite::connect_async(server.ws_url(&format!("/v1/broadcasts/{id}/stream")))
        .await
        .expect("the broadcast resumed");
    let first: Value = loop {
        match ws.next().await.expect("a frame").expect("a frame") {
            Message::Text(text) => break serde_json::from_str(&text).unwrap(),
            Message::Close(c) => panic!("closed: {c:?}"),
            _ => continue,
        }
    };
    let k = first["seq"].as_u64().unwrap();
    let replayed = metric_of(&http, &server, "inbetween_broadcast_replayed_ticks_total").await as u64;
    assert!(replayed + 3 * GRAPH_FPS <= k, "replayed {replayed} ticks of a broadcast {k} ticks old");
    let at = |seq: u64| seq as f64 / GRAPH_FPS as f64;
    let inputs = json!([{"time": at(blend), "set": {"s": 0.6}}, {"time": at(went), "set": {"go": true}}]);
    let body =
        json!({"motion": motion, "start": at(k), "end": at(k), "fps": GRAPH_FPS, "report": true, "inputs": inputs});
    let sampled = post(&http, &server, "/v1/samples", body).await;
    let pose = &sampled["poses"][0];
    assert_eq!(first["graph"], pose["graph"], "tick {k}'s report");
    assert_eq!(first["graph"]["state"], "up", "{first}");
    let xyz = |v: &Value| -> Vec<f64> {
        v["joints"][0]["translation"].as_array().unwrap().iter().map(|c| c.as_f64().unwrap()).collect()
    };
    let (shown, want) = (xyz(&first["pose"]), xyz(pose));
    assert!(shown.iter().zip(&want).all(|(a, b)| (a - b).abs() <= 1e-5 * b.abs().max(1.0)), "{shown:?} vs {want:?}");
}
