//! REST API tests: the real `Application` on 127.0.0.1:0 with its own SQLite
//! file, driven by a real HTTP client (reqwest). One module per concern.

mod b_spline;
mod bad_inputs;
mod budget;
mod cache;
pub(crate) mod character_routes;
mod characters;
mod cli;
mod clip_meta;
mod clip_query;
mod clips;
mod compression;
mod concurrency;
mod cost;
mod durability;
pub(crate) mod graph_characters;
pub(crate) mod graph_root_motion;
pub(crate) mod graph_samples;
mod graphs;
mod grpc_motions;
mod ik;
mod import;
mod import_big;
mod logs;
mod mesh;
mod motion_cache;
mod motions;
mod numbers;
mod operations;
mod parameters;
mod poses;
mod priced_builds;
mod retarget_options;
pub(crate) mod rigs;
mod security;
mod shared_parts;
mod strict;
mod vrm;
mod warnings;
mod work;

use serde_json::Value;

pub use crate::common::{TestApp, WAVE, assert_close, within};

/// The canonical form the server stores for a document: parsed, re-serialised.
pub fn canonical(doc: &str) -> String {
    let parsed = formats::wire::json::parse_clip_doc(doc.as_bytes()).unwrap();
    serde_json::to_string(&parsed).unwrap()
}

/// A clip with `joints` root joints, each with a linear translation track of
/// `keys` keys whose every value is `[k, k, k]`, named `name`.
pub fn uniform_clip(name: &str, joints: usize, keys: usize, k: f32) -> String {
    let times: Vec<f32> = (0..keys).map(|i| i as f32).collect();
    let tracks: Vec<Value> = (0..joints)
        .map(|j| {
            serde_json::json!({
                "joint": format!("j{j}"), "channel": "translation", "interpolation": "linear",
                "times": times, "values": vec![[k, k, k]; keys],
            })
        })
        .collect();
    serde_json::json!({"name": name, "tracks": tracks}).to_string()
}
