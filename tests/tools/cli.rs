//! `inbetween sample`: the real binary on `examples/wave.json`, its output
//! shape (docs/api.md pose) and values checked against the library, and bad
//! input refused with the validation error on stderr.

use std::path::PathBuf;
use std::process::{Command, Output};

use anim::{Clip, Ease, SampleOptions, Sampler, Space};
use formats::wire::json::parse_clip;
use glam::Mat4;
use serde_json::Value;

fn wave_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples/wave.json")
}

fn wave() -> Clip {
    let (_, spec) = parse_clip(&std::fs::read(wave_path()).unwrap()).unwrap();
    Clip::build(&spec).unwrap()
}

pub fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_inbetween")).args(args).output().expect("the binary runs")
}

fn sample_ok(args: &[&str]) -> Vec<Value> {
    let wave = wave_path();
    let mut all = vec!["sample", wave.to_str().unwrap()];
    all.extend_from_slice(args);
    let out = run(&all);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    let v: Value = serde_json::from_slice(&out.stdout).expect("stdout is JSON");
    v.as_array().expect("a JSON array of poses").clone()
}

fn floats(v: &Value, len: usize) -> Vec<f32> {
    let a = v.as_array().unwrap_or_else(|| panic!("an array: {v}"));
    assert_eq!(a.len(), len, "{v}");
    a.iter().map(|x| x.as_f64().expect("a number") as f32).collect()
}

/// Every pose has the docs/api.md shape and the library's values, exactly.
fn check_poses(poses: &[Value], times: &[f64], space: Space) {
    let clip = wave();
    assert_eq!(poses.len(), times.len());
    let mut sampler = Sampler::new();
    for (pose, &t) in poses.iter().zip(times) {
        let keys: Vec<&str> = pose.as_object().unwrap().keys().map(String::as_str).collect();
        for k in ["clip", "time", "space", "joints"] {
            assert!(keys.contains(&k), "pose lacks {k}: {pose}");
        }
        assert_eq!(pose["clip"], "wave");
        assert_eq!(pose["time"].as_f64(), Some(t));
        assert_eq!(pose["space"], space.as_str());
        let options = SampleOptions { playback: None, ease: Ease::Linear, space };
        let ct = clip.sample(t, &options, &mut sampler);
        assert_eq!(pose["clip_time"].as_f64().map(|x| x as f32), Some(ct));
        let joints = pose["joints"].as_array().unwrap();
        assert_eq!(joints.len(), 2);
        let p = sampler.pose();
        for (j, (joint, name)) in joints.iter().zip(["root", "arm"]).enumerate() {
            assert_eq!(joint["name"], name);
            assert_eq!(floats(&joint["translation"], 3), p.translations[j].to_array());
            assert_eq!(floats(&joint["rotation"], 4), p.rotations[j].to_array(), "[x, y, z, w]");
            assert_eq!(floats(&joint["scale"], 3), p.scales[j].to_array());
        }
    }
}

#[test]
fn samples_given_times() {
    let poses = sample_ok(&["--t", "0.5", "--t", "1.25", "--t", "-0.5", "--t", "4"]);
    check_poses(&poses, &[0.5, 1.25, -0.5, 4.0], Space::Local);
    // wave.json loops (duration 3): t = 4 plays clip time 1.
    assert_eq!(poses[3]["clip_time"].as_f64(), Some(1.0));
}

#[test]
fn samples_a_frame_range() {
    let poses = sample_ok(&["--start", "0", "--end", "1", "--fps", "4"]);
    check_poses(&poses, &[0.0, 0.25, 0.5, 0.75, 1.0], Space::Local);
    let poses = sample_ok(&["--start", "0", "--end", "1", "--fps", "4", "--space", "model"]);
    check_poses(&poses, &[0.0, 0.25, 0.5, 0.75, 1.0], Space::Model);
}

#[test]
fn samples_model_matrices() {
    let poses = sample_ok(&["--t", "0.8", "--format", "matrix"]);
    assert_eq!(poses.len(), 1);
    assert_eq!(poses[0]["format"], "matrix");
    let clip = wave();
    let (mut sampler, mut expected) = (Sampler::new(), Vec::<Mat4>::new());
    assert!(clip.matrices(0.8, &SampleOptions::default(), false, &mut sampler, &mut expected));
    let joints = poses[0]["joints"].as_array().unwrap();
    for (joint, m) in joints.iter().zip(&expected) {
        assert_eq!(floats(&joint["matrix"], 16), m.to_cols_array(), "column-major");
    }
    // The arm's origin in model space: the root's translation plus (0, 1, 0).
    let root = floats(&joints[0]["matrix"], 16);
    let arm = floats(&joints[1]["matrix"], 16);
    assert!((arm[13] - root[13] - 1.0).abs() < 1e-6 && (arm[12] - root[12]).abs() < 1e-6);
}

#[test]
fn a_bad_clip_exits_non_zero_with_the_validation_error() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.json");
    std::fs::write(
        &bad,
        r#"{"name": "bad", "tracks": [{"joint": "a", "channel": "translation", "times": [0, 0], "values": [[0,0,0],[1,0,0]]}]}"#,
    )
    .unwrap();
    let out = run(&["sample", bad.to_str().unwrap(), "--t", "0"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("times_not_increasing") && stderr.contains("/tracks/0/times/1"), "stderr: {stderr}");
    assert!(out.stdout.is_empty(), "no half output");

    std::fs::write(&bad, "{not json").unwrap();
    let out = run(&["sample", bad.to_str().unwrap(), "--t", "0"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("malformed_json"));

    let wave = wave_path();
    for args in [vec!["--start", "1", "--end", "0", "--fps", "30"], vec![], vec!["--t", "0", "--format", "skinning"]] {
        let mut all = vec!["sample", wave.to_str().unwrap()];
        all.extend(args.iter());
        let out = run(&all);
        assert!(!out.status.success(), "{args:?} must be refused");
        assert!(!out.stderr.is_empty());
    }
    // 1e20 frames are counted without wrapping: too many, not none.
    let out = run(&["sample", wave.to_str().unwrap(), "--start", "0", "--end", "1e20", "--fps", "1"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && stderr.contains("frames requested; the limit is"), "stderr: {stderr}");
}

/// Runs the binary with `args`, reads `keep` bytes of its stdout and closes
/// the pipe, as `inbetween … | head -c KEEP` does; returns the bytes read,
/// the exit status and stderr.
fn closed_early(args: &[&str], keep: usize) -> (Vec<u8>, std::process::ExitStatus, String) {
    use std::io::Read;
    use std::process::Stdio;
    let mut child = Command::new(env!("CARGO_BIN_EXE_inbetween"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary runs");
    let mut head = vec![0; keep];
    child.stdout.take().unwrap().read_exact(&mut head).unwrap();
    // The stdout handle is dropped here: the reader has gone.
    let out = child.wait_with_output().unwrap();
    (head, out.status, String::from_utf8_lossy(&out.stderr).into_owned())
}

/// `inbetween import 131_01.bvh | head -c 10` and `inbetween sample … | head -c 10`:
/// the first bytes, then a quiet, successful exit (no "Broken pipe", no panic).
#[test]
fn a_reader_that_leaves_early_ends_the_output_quietly() {
    let bvh = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples/bvh/131_01.bvh");
    let wave = wave_path();
    // Both answers are megabytes: far more than a pipe holds, so the writer meets the closed end.
    let sample = vec!["sample", wave.to_str().unwrap(), "--start", "0", "--end", "100", "--fps", "100"];
    // In metres (the CMU unit): no warning on stderr either.
    for args in [vec!["import", bvh.to_str().unwrap(), "--scale", "0.0564"], sample] {
        let (head, status, stderr) = closed_early(&args, 10);
        assert!(
            head.starts_with(b"{\"clips\":[") || head.starts_with(b"[{\"clip\""),
            "{:?}",
            String::from_utf8_lossy(&head)
        );
        assert!(stderr.is_empty(), "{}: stderr {stderr:?}", args[0]);
        assert!(status.success(), "{}: {status}", args[0]);
    }
}
