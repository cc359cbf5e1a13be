//! `formats::fuzzing::import_evaluate`: sniff → import or parse → build →
//! sample at input-chosen times (shared with the corpus replay in `cargo test`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| formats::fuzzing::import_evaluate(data));
