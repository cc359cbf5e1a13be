//! `formats::fuzzing::import_gltf` (shared with the corpus replay in `cargo test`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| formats::fuzzing::import_gltf(data));
