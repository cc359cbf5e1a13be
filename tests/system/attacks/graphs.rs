//! Expensive graphs from small bodies: a 2D blend's triangulation tests
//! every triple of its points against every point, so its cost grows as the
//! fourth power of the points — a few kilobytes of blend points would be
//! hours of one core. A blend's points are bounded (`max_blend_points`,
//! checked before anything is built), a graph's nodes too, and what is left
//! is priced before it runs (docs/api.md, "Work and its price"): the node
//! refuses or runs it off the async workers, and keeps answering. A graph
//! playing live takes `set` controls: a socket flooding them meets the
//! bounds every control has (32 pending per stream; a broadcast's draw on
//! the write budget and its store queue), and the node keeps answering.

use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::{Target, target};

/// A clip on the `hips`–`spine` chain.
fn chain_clip(name: &str) -> String {
    json!({"name": name,
        "skeleton": {"joints": [{"name": "hips"}, {"name": "spine", "parent": "hips"}]},
        "tracks": [{"joint": "hips", "channel": "rotation", "interpolation": "linear",
                    "times": [0, 1], "values": [[0, 0, 0, 1], [0, 0.2, 0, 0.98]]}]})
    .to_string()
}

/// A graph of `nodes` 2D blends of `points` points each on a grid (every
/// cell cocircular: the hardest triangulation), over `clips` in turn.
fn grid_graph(name: &str, nodes: usize, points: usize, clips: &[String]) -> Value {
    let grid: Vec<Value> =
        (0..points).map(|i| json!({"clip": clips[i % clips.len()], "at": [(i % 8) as f64, (i / 8) as f64]})).collect();
    let blends: serde_json::Map<String, Value> = (0..nodes)
        .map(|n| (format!("b{n:03}"), json!({"blend2d": {"x": "x", "y": "y", "points": grid, "sync": false}})))
        .collect();
    json!({"name": name,
        "parameters": {"x": {"type": "float", "default": 0, "min": 0, "max": 8},
                       "y": {"type": "float", "default": 0, "min": 0, "max": 8}},
        "nodes": blends, "output": "b000"})
}

async fn post(http: &reqwest::Client, url: &str, body: &Value) -> (u16, Value) {
    let resp = http.post(url).json(body).send().await.unwrap();
    let status = resp.status().as_u16();
    (status, resp.json().await.unwrap_or(Value::Null))
}

#[tokio::test(flavor = "multi_thread")]
async fn blend_points_are_bounded_and_priced_and_the_node_keeps_answering() {
    let mut target = target(&["--node-work-per-sec", "1000000000000", "--request-timeout-secs", "300"]).await;
    let http = crate::common::http_client();
    let mut clips = Vec::new();
    for name in ["a", "b", "c"] {
        let resp = http
            .post(target.server.url("/v1/clips"))
            .header("content-type", "application/json")
            .body(chain_clip(name))
            .send()
            .await
            .unwrap();
        assert_eq!(resp.status(), 201);
        clips.push(resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned());
    }
    let url = target.server.url("/v1/graphs");

    // 2,000 points in one blend (~140 KB): 1.6·10¹³ tests if it were triangulated; refused unread.
    let probes = target.probes().await;
    let huge = grid_graph("huge", 1, 2000, &clips);
    let (status, problem) = post(&http, &url, &huge).await;
    let report = probes.finish();
    assert_eq!(
        (status, problem["code"].as_str(), problem["pointer"].as_str()),
        (422, Some("too_many_points"), Some("/nodes/b000/blend2d/points")),
        "{problem}"
    );
    target.assert_survived("a 2,000-point blend space", &report);

    // 128 blends of 32 points (each 32⁴ ≈ 10⁶ units): over max_request_work, refused by its price.
    let probes = target.probes().await;
    let (status, problem) = post(&http, &url, &grid_graph("wide", 128, 32, &clips)).await;
    let report = probes.finish();
    assert_eq!((status, problem["code"].as_str()), (422, Some("too_much_work")), "{problem}");
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.contains("building this graph") && detail.contains("max_request_work"), "{detail}");
    target.assert_survived("128 blends of 32 points", &report);

    // The most the price admits, eight at once: built on the work threads while the probes answer.
    let probes = target.probes().await;
    let uploads = (0..8).map(|i| {
        let (http, url, body) = (http.clone(), url.clone(), grid_graph(&format!("admitted-{i}"), 48, 32, &clips));
        async move { post(&http, &url, &body).await }
    });
    let answers = futures_util::future::join_all(uploads).await;
    let report = probes.finish();
    for (status, problem) in &answers {
        // Admitted, or refused by the caller's or the node's share of the work: never a 5xx but 503.
        assert!(
            *status == 201 || (*status == 429 && problem["code"] == "caller_work_limit") || *status == 503,
            "{status} {problem}"
        );
    }
    assert!(answers.iter().any(|(s, _)| *s == 201), "some graph was admitted: {answers:?}");
    target.assert_survived("eight admitted 48-blend graphs at once", &report);
}

/// A graph over two chain clips: `x` blends them, the trigger `hop` fades
/// to the third and back when it has nearly played.
fn hop_graph(clips: &[String]) -> Value {
    json!({"name": "hop",
        "parameters": {"x": {"type": "float", "default": 0, "min": 0, "max": 8}, "hop": {"type": "trigger"}},
        "nodes": {"walk": {"blend1d": {"parameter": "x", "points": [{"clip": clips[0], "at": 0}, {"clip": clips[1], "at": 8}]}},
                  "hop": {"clip": clips[2], "playback": "once"}},
        "machine": {"initial": "walk", "states": {"walk": {"node": "walk"}, "hop": {"node": "hop"}},
            "transitions": [{"from": "walk", "to": "hop", "when": {"trigger": "hop"}, "duration": 0.2},
                            {"from": "hop", "to": "walk", "when": {"exit_time": 0.9}, "duration": 0.2}]}})
}

/// What one socket's flood of `set` controls met: sent, refused, and the
/// frames that came while it was sent.
#[derive(Debug)]
struct SetFlood {
    sent: u64,
    refused: u64,
    frames: u64,
}

/// Sends `sent` `set` controls on `ws` as fast as it takes them, reading
/// its answers meanwhile (each refusal one of `allowed`), until frames come
/// after the flood; then one last `set` of `x` = 8, and waits for a frame
/// that shows it (the blend all on its second point).
async fn flood_sets(
    ws: tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>,
    sent: u64,
    allowed: &[&str],
) -> SetFlood {
    let (mut tx, mut rx) = ws.split();
    let sender = tokio::spawn(async move {
        for k in 0..sent {
            let set = json!({"op": "set", "parameters": {"x": (k % 80) as f64 / 10.0, "hop": k % 7 == 0}});
            tx.send(Message::Text(set.to_string().into())).await.unwrap();
        }
        tx
    });
    let mut flood = SetFlood { sent, refused: 0, frames: 0 };
    let mut after = 0;
    while after < 30 {
        let msg = tokio::time::timeout(Duration::from_secs(5), rx.next()).await;
        let Message::Text(text) = msg.expect("the socket keeps answering").expect("open").unwrap() else { continue };
        let v: Value = serde_json::from_str(&text).unwrap();
        match v.get("error") {
            Some(problem) => {
                let code = problem["code"].as_str().unwrap_or_default();
                assert!(allowed.contains(&code), "{problem}");
                flood.refused += 1;
            }
            None => {
                flood.frames += 1;
                after += u64::from(sender.is_finished());
            }
        }
    }
    let mut tx = sender.await.unwrap();
    let last = Message::Text(json!({"op": "set", "parameters": {"x": 8}}).to_string().into());
    let until = Instant::now() + Duration::from_secs(20);
    tx.send(last.clone()).await.unwrap();
    let mut frames_since = 0;
    loop {
        assert!(Instant::now() < until, "the last set never showed: {flood:?}");
        let msg = tokio::time::timeout(Duration::from_secs(5), rx.next()).await;
        let Message::Text(text) = msg.expect("answered").expect("open").unwrap() else { continue };
        let v: Value = serde_json::from_str(&text).unwrap();
        if let Some(problem) = v.get("error") {
            // The flood's refusals still on their way, or the last set's own (sent again below).
            assert!(allowed.contains(&problem["code"].as_str().unwrap_or_default()), "{problem}");
            flood.refused += 1;
            continue;
        }
        let weights: Vec<f64> = v["graph"]["weights"]["walk"]
            .as_array()
            .map_or(Vec::new(), |w| w.iter().map(|x| x.as_f64().unwrap()).collect());
        if weights == [0.0, 1.0] && v["graph"]["state"] == "walk" {
            return flood;
        }
        frames_since += 1;
        if frames_since % 30 == 0 {
            tx.send(last.clone()).await.unwrap();
        }
    }
}

async fn store_hop_graph(target: &Target, http: &reqwest::Client) -> String {
    let mut clips = Vec::new();
    for name in ["ha", "hb", "hc"] {
        clips.push(target.server.create(http, &chain_clip(name)).await);
    }
    let (status, graph) = post(http, &target.server.url("/v1/graphs"), &hop_graph(&clips)).await;
    assert_eq!(status, 201, "{graph}");
    graph["id"].as_str().unwrap().to_owned()
}

/// A socket flooding its graph stream and a graph broadcast with `set`
/// controls: each is checked and queued or refused (`rate_limited` past the
/// write budget, `bad_control` past the 32 pending; a broadcast's
/// `unavailable` past its store queue), the frames keep coming, the last
/// setting shows, and the probes answer throughout.
#[tokio::test(flavor = "multi_thread")]
async fn a_set_flood_on_a_graph_stream_and_broadcast_leaves_the_node_answering() {
    let mut target = target(&[]).await;
    let http = crate::common::http_client();
    let graph = store_hop_graph(&target, &http).await;
    let motion = json!({"layers": [{"graph": graph}]});

    let probes = target.probes().await;
    let (mut ws, _) = tokio_tungstenite::connect_async(target.server.ws_url("/v1/stream")).await.unwrap();
    let open = json!({"op": "open", "motion": motion, "fps": 60, "report": true});
    ws.send(Message::Text(open.to_string().into())).await.unwrap();
    let started = Instant::now();
    let flood = flood_sets(ws, 20_000, &["rate_limited", "bad_control"]).await;
    let report = probes.finish();
    println!(
        "FIGURE {} set controls on a graph stream in {:.1} s: {} refused, {} frames meanwhile",
        flood.sent,
        started.elapsed().as_secs_f64(),
        flood.refused,
        flood.frames
    );
    target.assert_survived("a set flood on a graph stream", &report);

    let (status, b) =
        post(&http, &target.server.url("/v1/broadcasts"), &json!({"motion": motion, "report": true})).await;
    assert_eq!(status, 201, "{b}");
    let url = target.server.ws_url(&format!("/v1/broadcasts/{}/stream", b["id"].as_str().unwrap()));
    let probes = target.probes().await;
    let (ws, _) = tokio_tungstenite::connect_async(url).await.unwrap();
    let started = Instant::now();
    let flood = flood_sets(ws, 20_000, &["rate_limited", "unavailable", "bad_control"]).await;
    let report = probes.finish();
    println!(
        "FIGURE {} set controls on a graph broadcast in {:.1} s: {} refused, {} frames meanwhile",
        flood.sent,
        started.elapsed().as_secs_f64(),
        flood.refused,
        flood.frames
    );
    assert!(flood.refused > 0, "the write budget refused some: {flood:?}");
    target.assert_survived("a set flood on a graph broadcast", &report);
}
