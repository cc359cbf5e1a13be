//! Every file of the committed fuzz corpus (`fuzz/corpus-min/<target>/`,
//! inputs the fuzzer found, plus the hardening corpus's files of the
//! target's formats, `tests/corpus/*/<area>/`) and every past crash
//! (`fuzz/regressions/<target>/`) through
//! `formats::fuzzing::<target>`, the function the libFuzzer target calls:
//! none may panic. No libFuzzer needed, so plain `cargo test` runs it.

use std::path::Path;

use formats::fuzzing::TARGETS;

use super::root;

/// The files of `dir` (none if it does not exist), sorted.
fn files(dir: &Path) -> Vec<std::path::PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut files: Vec<_> = entries.map(|e| e.unwrap().path()).filter(|p| p.is_file()).collect();
    files.sort();
    files
}

/// The hardening corpus's areas (tests/corpus) each target reads.
fn areas(target: &str) -> &'static [&'static str] {
    match target {
        "import_gltf" => &["gltf", "glb"],
        "import_bvh" => &["bvh"],
        "clip_json" => &["json"],
        "motion_json" | "graph_json" => &[],
        _ => &["gltf", "glb", "bvh", "json", "sniff"],
    }
}

/// The seed files of `target` in `dir` (`corpus-min` or `regressions`).
fn inputs(kind: &str, target: &str) -> Vec<std::path::PathBuf> {
    let mut all = files(&root().join("fuzz").join(kind).join(target));
    if kind == "corpus-min" {
        for area in areas(target) {
            for set in ["valid", "malformed"] {
                all.extend(files(&root().join("tests/corpus").join(set).join(area)));
            }
        }
    }
    all
}

fn replay(kind: &str) -> usize {
    let mut total = 0;
    for (name, target) in TARGETS {
        for file in inputs(kind, name) {
            let data = std::fs::read(&file).unwrap();
            let outcome = std::panic::catch_unwind(|| target(&data));
            assert!(outcome.is_ok(), "{name} panics on {}", file.display());
            total += 1;
        }
    }
    total
}

#[test]
fn the_fuzz_corpus_replays_without_a_panic() {
    let n = replay("corpus-min");
    // Every target has a committed corpus; an empty one would make this test vacuous.
    for (name, _) in TARGETS {
        assert!(inputs("corpus-min", name).len() >= 20, "no corpus for {name}");
    }
    assert!(n >= 400, "only {n} corpus files");
}

#[test]
fn every_past_crash_replays_without_a_panic() {
    let n = replay("regressions");
    assert!(n >= 3, "only {n} regression files");
}
