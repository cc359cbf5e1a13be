//! glTF samplers: STEP, LINEAR and CUBICSPLINE against the spec's formulas.

use std::collections::BTreeSet;

use anim::{Channel, Clip, Interpolation, Space};
use formats::import::ImportOptions;

use super::reference::{RawGltf, Sampler, gltf_slerp, quat_diff, vec_diff};
use super::{build, import_file, sample};

/// The named tolerance of docs/clip-format.md §2.9.
const TOL: f64 = 1e-5;

/// The local value of `node`'s `path` in `clip` at time `t`.
fn local(clip: &Clip, joint: &str, path: &str, t: f64) -> Vec<f32> {
    let j = clip.skeleton().index_of(joint).unwrap_or_else(|| panic!("no joint {joint}"));
    let s = sample(clip, t, Space::Local);
    let pose = s.pose();
    match path {
        "translation" => pose.translations[j].to_array().to_vec(),
        "rotation" => pose.rotations[j].to_array().to_vec(),
        "scale" => pose.scales[j].to_array().to_vec(),
        other => panic!("{other}"),
    }
}

fn diff(expected: &[f64], got: &[f32], rotation: bool) -> f64 {
    if rotation { quat_diff(expected, [got[0], got[1], got[2], got[3]]) } else { vec_diff(expected, got) }
}

/// Checks one single-sampler channel: at every key the file's key value, at
/// quarter points of every interval the Appendix C formula, and clamping
/// outside the keys. Returns the sampler's interpolation.
fn check_channel(raw: &RawGltf, clip: &Clip, animation: usize, channel: usize) -> (String, String) {
    let ch = &raw.json["animations"][animation]["channels"][channel];
    let node = ch["target"]["node"].as_u64().unwrap() as usize;
    let path = ch["target"]["path"].as_str().unwrap().to_owned();
    let rotation = path == "rotation";
    let sampler = Sampler::read(raw, animation, ch["sampler"].as_u64().unwrap() as usize);
    let joint = raw.node_name(node);
    let what = |t: f64| format!("{} {joint} {path} ({}) at t={t}", clip.name(), sampler.interpolation);

    for (k, &t) in sampler.times.iter().enumerate() {
        let mut key = sampler.value(k).to_vec();
        if rotation {
            let n = key.iter().map(|x| x * x).sum::<f64>().sqrt();
            key.iter_mut().for_each(|x| *x /= n);
        }
        let got = local(clip, &joint, &path, t);
        assert!(diff(&key, &got, rotation) <= TOL, "{}: key {key:?}, got {got:?}", what(t));
    }
    for w in sampler.times.windows(2) {
        for f in [0.25, 0.5, 0.75] {
            let t = w[0] + f * (w[1] - w[0]);
            let expected = sampler.eval(t, rotation);
            let got = local(clip, &joint, &path, t);
            assert!(diff(&expected, &got, rotation) <= TOL, "{}: expected {expected:?}, got {got:?}", what(t));
        }
    }
    let (first, last) = (sampler.times[0], *sampler.times.last().unwrap());
    for t in [first - 0.5, last + 0.5] {
        let expected = sampler.eval(t, rotation);
        let got = local(clip, &joint, &path, t);
        assert!(diff(&expected, &got, rotation) <= TOL, "{}: clamped {expected:?}, got {got:?}", what(t));
    }
    (path, sampler.interpolation)
}

#[test]
fn interpolation_test_samplers_follow_the_gltf_formulas() {
    let rel = "gltf/InterpolationTest/InterpolationTest.gltf";
    let raw = RawGltf::load(rel);
    let imported = import_file(rel, &ImportOptions::default());
    let animations = raw.json["animations"].as_array().unwrap();
    assert_eq!(imported.clips.len(), animations.len());
    let mut covered = BTreeSet::new();
    for (a, animation) in animations.iter().enumerate() {
        let name = animation["name"].as_str().unwrap();
        let spec = imported.clips.iter().find(|c| c.name == name).unwrap_or_else(|| panic!("no clip {name}"));
        assert_eq!(spec.tracks.len(), 1, "{name}");
        let clip = build(spec);
        let (path, interpolation) = check_channel(&raw, &clip, a, 0);
        // Keyed on the sampler, not the name: "Linear Scale" is CUBICSPLINE here.
        let expected = match interpolation.as_str() {
            "STEP" => Interpolation::Step,
            "LINEAR" => Interpolation::Linear,
            _ => Interpolation::CubicHermite,
        };
        assert_eq!(spec.tracks[0].interpolation, expected, "{name}");
        covered.insert(format!("{path} {interpolation}"));
    }
    let expected: BTreeSet<String> = [
        "rotation CUBICSPLINE",
        "rotation LINEAR",
        "rotation STEP",
        "scale CUBICSPLINE",
        "scale STEP",
        "translation CUBICSPLINE",
        "translation LINEAR",
        "translation STEP",
    ]
    .into_iter()
    .map(String::from)
    .collect();
    assert_eq!(covered, expected);
}

#[test]
fn animated_triangle_takes_the_short_way_across_a_negative_dot_product() {
    let rel = "gltf/AnimatedTriangle/AnimatedTriangle.gltf";
    let raw = RawGltf::load(rel);
    let imported = import_file(rel, &ImportOptions::default());
    assert_eq!(imported.clips.len(), 1);
    assert_eq!(imported.clips[0].name, "animation0", "an unnamed animation is named by its index");
    let clip = build(&imported.clips[0]);
    check_channel(&raw, &clip, 0, 0);

    // The file's keys 4 → 5 have a negative dot product …
    let sampler = Sampler::read(&raw, 0, 0);
    let (a, b) = (sampler.value(3), sampler.value(4));
    assert!(a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>() < 0.0);
    // … 270° → 360° about Z: halfway is 315° (the long way would pass 135°).
    let half = (315f64.to_radians() / 2.0).sin_cos();
    let expected = [0.0, 0.0, half.0, half.1];
    let got = local(&clip, "node0", "rotation", 0.875);
    assert!(quat_diff(&expected, [got[0], got[1], got[2], got[3]]) <= TOL, "got {got:?}");
}

#[test]
fn box_animated_clamps_each_channel_and_lasts_as_long_as_its_longest() {
    let rel = "gltf/BoxAnimated/BoxAnimated.gltf";
    let raw = RawGltf::load(rel);
    let imported = import_file(rel, &ImportOptions::default());
    let spec = &imported.clips[0];
    let clip = build(spec);
    // Two channels of different lengths: 1.25–2.5 s and 0–3.708 s.
    let translation = Sampler::read(&raw, 0, 1);
    let rotation = Sampler::read(&raw, 0, 0);
    assert_eq!((rotation.times.len(), translation.times.len()), (2, 4));
    assert_eq!(clip.start() as f64, translation.times[0]);
    assert_eq!(clip.end() as f64, *translation.times.last().unwrap());
    assert!(clip.end() as f64 > *rotation.times.last().unwrap() + 1.0);
    for channel in 0..2 {
        check_channel(&raw, &clip, 0, channel);
    }
    // Clamped before its first key and after its last (not looped early).
    let first = rotation.value(0);
    let last = rotation.value(1);
    for (t, expected) in [(0.0, first), (1.0, first), (2.6, last), (3.5, last)] {
        let got = local(&clip, "node2", "rotation", t);
        assert!(quat_diff(expected, [got[0], got[1], got[2], got[3]]) <= TOL, "t={t}: got {got:?}");
    }
    // The keys' dot product is -4.5e-11: its sign decides the way. The spec
    // (s = dot/|dot|) goes to -key2, so halfway is +90° about X.
    let mid = 1.875;
    let got = local(&clip, "node2", "rotation", mid);
    let h = std::f64::consts::FRAC_1_SQRT_2;
    assert!(quat_diff(&[h, 0.0, 0.0, h], [got[0], got[1], got[2], got[3]]) <= TOL, "got {got:?}");
    assert!(quat_diff(&gltf_slerp(first, last, 0.5), [got[0], got[1], got[2], got[3]]) <= TOL);
    // The track kinds came from the samplers.
    assert!(spec.tracks.iter().all(|t| t.interpolation == Interpolation::Linear));
    let channels: BTreeSet<_> = spec.tracks.iter().map(|t| t.channel.as_str()).collect();
    assert_eq!(channels, [Channel::Rotation.as_str(), Channel::Translation.as_str()].into_iter().collect());
}

/// InterpolationTest's tangents are symmetric, so a swap of in- and
/// out-tangents would go unseen there; this file's are not. Keys 0 → 1 over
/// h = 2 s with out-tangent b₀ = 3 and in-tangent a₁ = −1 (the other two are
/// decoys): at u = ½ the Hermite formula gives
/// ⅛·2·3 + ½·1 + (−⅛)·2·(−1) = 0.75 + 0.5 + 0.25 = 1.5.
#[test]
fn cubicspline_uses_the_out_tangent_of_the_left_key_and_the_in_tangent_of_the_right() {
    use base64::Engine as _;
    use formats::import::{Format, import};
    let floats: Vec<f32> = [
        vec![0.0, 2.0],
        // key 0: in-tangent (decoy), value, out-tangent
        vec![100.0, 0.0, 0.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0],
        // key 1: in-tangent, value, out-tangent (decoy)
        vec![-1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 100.0, 0.0, 0.0],
    ]
    .concat();
    let bytes: Vec<u8> = floats.iter().flat_map(|x| x.to_le_bytes()).collect();
    let uri =
        format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&bytes));
    let doc = serde_json::json!({
        "asset": {"version": "2.0"},
        "nodes": [{"name": "n"}],
        "buffers": [{"byteLength": bytes.len(), "uri": uri}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 8},
            {"buffer": 0, "byteOffset": 8, "byteLength": 72}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 2, "type": "SCALAR"},
            {"bufferView": 1, "componentType": 5126, "count": 6, "type": "VEC3"}
        ],
        "animations": [{
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
            "samplers": [{"input": 0, "output": 1, "interpolation": "CUBICSPLINE"}]
        }]
    });
    let imported = import(&serde_json::to_vec(&doc).unwrap(), Format::Gltf, &ImportOptions::default()).unwrap();
    let clip = build(&imported.clips[0]);
    for (t, x) in [(0.0, 0.0), (1.0, 1.5), (2.0, 1.0)] {
        let got = local(&clip, "n", "translation", t);
        assert!((got[0] as f64 - x).abs() <= TOL, "t={t}: {got:?}, expected x = {x}");
    }
}
