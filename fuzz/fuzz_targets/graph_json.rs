//! `formats::fuzzing::graph_json` (shared with the corpus replay in `cargo test`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| formats::fuzzing::graph_json(data));
