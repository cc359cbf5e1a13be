//! `inbetween sample` at the clip's seams (docs/clip-format.md §2.7): a time written as the
//! clip document writes its first or last key is that key in every
//! playback mode (`loop` maps the end to the start), though f32 holds
//! neither 0.1, 1/3 nor 1.3 exactly. Expected values are the documents'
//! own key values.

use serde_json::Value;

use super::cli::run;

/// A step track: x = `values[i]` from `times[i]` on.
fn step_clip(times: [&str; 3]) -> String {
    format!(
        r#"{{"name": "seam", "tracks": [{{"joint": "j", "channel": "translation", "interpolation": "step",
            "times": [{}], "values": [[1, 0, 0], [2, 0, 0], [3, 0, 0]]}}]}}"#,
        times.join(", ")
    )
}

/// (clip time, x) of each pose `inbetween sample` prints for `args`.
fn sample(doc: &str, args: &[&str]) -> Vec<(f32, f32)> {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("seam.json");
    std::fs::write(&file, doc).unwrap();
    let mut all = vec!["sample", file.to_str().unwrap()];
    all.extend_from_slice(args);
    let out = run(&all);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    let poses: Value = serde_json::from_slice(&out.stdout).expect("stdout is JSON");
    let number = |v: &Value| v.as_f64().unwrap_or_else(|| panic!("a number: {v}")) as f32;
    poses
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (number(&p["clip_time"]), number(&p["joints"][0]["translation"][0])))
        .collect()
}

#[test]
fn both_seams_in_every_mode() {
    let third = 1.0f32 / 3.0;
    // (key times as the document writes them, their f32 values, request
    // times that must count as the start).
    let cases = [
        (["0.1", "0.7", "1.3"], [0.1f32, 0.7, 1.3], vec!["0.1"]),
        (["0.33333334", "1.0", "2.3333333"], [third, 1.0, 2.0 + third], vec!["0.33333334", "0.3333333333333333"]),
    ];
    for (times, keys, starts) in cases {
        let doc = step_clip(times);
        for mode in ["once", "loop", "ping_pong"] {
            // The end: the last key, or in loop the first key at the start.
            let end = if mode == "loop" { (keys[0], 1.0) } else { (keys[2], 3.0) };
            for start in &starts {
                let got = sample(&doc, &["--t", start, "--t", times[1], "--t", times[2], "--playback", mode]);
                assert_eq!(got, [(keys[0], 1.0), (keys[1], 2.0), end], "{mode} {times:?} from {start}");
            }
        }
    }
}

#[test]
fn a_frame_range_ending_on_the_end_loops_to_the_start() {
    // 0.1 + k/5 for k = 0..=6: the last frame is 0.1 + 1.2 (= 1.3000000000000003).
    let doc = step_clip(["0.1", "0.7", "1.3"]);
    let range = ["--start", "0.1", "--end", "1.3", "--fps", "5"];
    let last = |mode: &str| *sample(&doc, &[&range[..], &["--playback", mode]].concat()).last().unwrap();
    assert_eq!(last("once"), (1.3, 3.0));
    assert_eq!(last("ping_pong"), (1.3, 3.0));
    assert_eq!(last("loop"), (0.1, 1.0));
    let all = sample(&doc, &[&range[..], &["--playback", "loop"]].concat());
    assert_eq!(all.len(), 7, "{all:?}");
    assert_eq!(all[0], (0.1, 1.0), "the first frame is the start");
}
