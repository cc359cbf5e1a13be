//! The viewer's JavaScript unit tests (`crates/server/src/rest/viewer/tests/`:
//! its maths, `math.js`), run by `node --test`. Without Node they skip with
//! a message, unless `INBETWEEN_REQUIRE_BROWSER=1` (CI) makes them fail, as
//! the browser tests do.

use std::path::Path;
use std::process::Command;

use super::cdp::REQUIRE_ENV;

/// The folder of the viewer's unit tests.
const TESTS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/crates/server/src/rest/viewer/tests");

#[test]
fn the_viewer_maths_passes_its_node_tests() {
    let files: Vec<_> = std::fs::read_dir(TESTS)
        .unwrap_or_else(|e| panic!("{TESTS}: {e}"))
        .map(|entry| entry.unwrap().path())
        .filter(|p| p.to_str().is_some_and(|p| p.ends_with(".test.js")))
        .collect();
    assert!(!files.is_empty(), "no *.test.js in {TESTS}");
    let node = match Command::new("node").arg("--version").output() {
        Ok(out) if out.status.success() => String::from_utf8_lossy(&out.stdout).trim().to_owned(),
        _ => {
            let required = std::env::var(REQUIRE_ENV).is_ok_and(|v| v == "1");
            assert!(!required, "{REQUIRE_ENV}=1 but no `node` on PATH (install Debian `nodejs`)");
            eprintln!("SKIPPED: no `node` on PATH for the viewer's unit tests (apt-get install nodejs)");
            return;
        }
    };
    let out = Command::new("node")
        .args(["--test", "--test-reporter=tap"])
        .args(&files)
        .current_dir(Path::new(TESTS))
        .output()
        .expect("running node --test");
    let report = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "node {node} --test failed:\n{report}");
    let passed = report.lines().find_map(|l| l.strip_prefix("# pass ")).and_then(|n| n.trim().parse::<u32>().ok());
    assert!(passed.is_some_and(|n| n > 0), "no test passed:\n{report}");
}
