//! Graphs and characters across nodes: each node keeps them built, by id at
//! one version (the cache of built documents), and a change on another
//! node reaches it within a second, through the same change feed as clips.

use serde_json::{Value, json};

use super::{Node, eventually, node_metric, propagation, start_all, until_subscribed};
use crate::common::pg::Schema;

/// A clip on the `Hips`–`Spine` chain, its hips turning about y.
fn chain_clip(name: &str) -> Value {
    json!({"name": name,
        "skeleton": {"joints": [{"name": "Hips"}, {"name": "Spine", "parent": "Hips", "rest": {"translation": [0, 0.2, 0]}}]},
        "tracks": [{"joint": "Hips", "channel": "rotation", "interpolation": "linear",
                    "times": [0, 1], "values": [[0, 0, 0, 1], [0, 0.2, 0, 0.98]]}]})
}

async fn post(http: &reqwest::Client, node: &Node, path: &str, body: &Value) -> Value {
    let resp = http.post(node.url(path)).json(body).send().await.unwrap();
    assert!(resp.status().is_success(), "{}: POST {path} answered {}", node.name, resp.status());
    resp.json().await.unwrap()
}

/// A graph playing `clips` as a blend over `speed` (at 0, 1, 2, …).
fn blend(name: &str, clips: &[&str]) -> Value {
    let points: Vec<Value> = clips.iter().enumerate().map(|(i, c)| json!({"clip": c, "at": i})).collect();
    json!({"name": name, "parameters": {"speed": {"type": "float", "default": 0, "min": 0, "max": 4}},
           "nodes": {"move": {"blend1d": {"parameter": "speed", "points": points}}}, "output": "move"})
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_graph_replaced_on_one_node_leaves_the_others_built_graphs_within_a_second() {
    let Some(schema) = Schema::create("graphs").await else { return };
    let [a, b] = start_all(&schema, ["node-a", "node-b"]).await;
    let http = crate::common::http_client();
    for node in [&a, &b] {
        until_subscribed(&http, node).await;
    }
    let walk = post(&http, &a, "/v1/clips", &chain_clip("walk")).await["id"].as_str().unwrap().to_owned();
    let run = post(&http, &a, "/v1/clips", &chain_clip("run")).await["id"].as_str().unwrap().to_owned();
    // Created on A: built there once, as it was checked.
    let created = post(&http, &a, "/v1/graphs", &blend("locomotion", &[&walk, &run])).await;
    let id = created["id"].as_str().unwrap().to_owned();
    eventually(propagation(), "node-a holds the graph built", || async {
        node_metric(&http, &a, "inbetween_graph_cache_entries").await == 1.0
    })
    .await;

    // Replaced on B (a third point): A lets its built version go, and serves the new document.
    let resp = http
        .put(b.url(&format!("/v1/graphs/{id}")))
        .header("if-match", "\"1\"")
        .json(&blend("locomotion", &[&walk, &run, &walk]))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200);
    eventually(propagation(), "node-a drops the built graph of version 1", || async {
        node_metric(&http, &a, "inbetween_graph_cache_entries").await == 0.0
    })
    .await;
    eventually(propagation(), "node-a serves version 2", || async {
        let resp = http.get(a.url(&format!("/v1/graphs/{id}"))).send().await.unwrap();
        let etag = resp.headers()["etag"].to_str().unwrap().to_owned();
        let doc: Value = resp.json().await.unwrap();
        etag == "\"2\"" && doc["nodes"]["move"]["blend1d"]["points"].as_array().unwrap().len() == 3
    })
    .await;
    // Deleted on A: B answers 404.
    assert_eq!(http.delete(a.url(&format!("/v1/graphs/{id}"))).send().await.unwrap().status(), 204);
    let status = http.get(b.url(&format!("/v1/graphs/{id}"))).send().await.unwrap().status();
    assert_eq!(status, 404);
    drop((a, b));
    schema.drop_now().await;
}

/// The status of a pose of `clip` played on `character` at `node`.
async fn played_on(http: &reqwest::Client, node: &Node, clip: &str, character: &str) -> u16 {
    let body = json!({"motion": {"layers": [{"clip": clip}], "character": character}, "time": 0.5});
    http.post(node.url("/v1/poses")).json(&body).send().await.unwrap().status().as_u16()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_character_replaced_on_one_node_is_played_anew_on_the_others_within_a_second() {
    let Some(schema) = Schema::create("characters").await else { return };
    let [a, b] = start_all(&schema, ["node-a", "node-b"]).await;
    let http = crate::common::http_client();
    for node in [&a, &b] {
        until_subscribed(&http, node).await;
    }
    let clip = post(&http, &a, "/v1/clips", &chain_clip("take")).await["id"].as_str().unwrap().to_owned();
    let own = json!({"name": "rig", "skeleton": chain_clip("rig")["skeleton"]});
    let character = post(&http, &a, "/v1/characters", &own).await["id"].as_str().unwrap().to_owned();
    // B plays the take on the character (its own skeleton): checked once, then held.
    assert_eq!(played_on(&http, &b, &clip, &character).await, 200);
    assert_eq!(node_metric(&http, &b, "inbetween_character_cache_entries").await, 1.0);
    assert_eq!(played_on(&http, &b, &clip, &character).await, 200);

    // Replaced on A by a rig with no joint or role in common: B must stop playing the held version.
    let stranger = json!({"name": "rig", "skeleton": {"joints": [{"name": "a"}, {"name": "b", "parent": "a"}]}});
    let resp = http.put(a.url(&format!("/v1/characters/{character}"))).json(&stranger).send().await.unwrap();
    assert_eq!(resp.status(), 200);
    eventually(propagation(), "node-b plays on the character's new version", || async {
        played_on(&http, &b, &clip, &character).await == 422
    })
    .await;
    drop((a, b));
    schema.drop_now().await;
}
