//! Skinned glTF models: the skeleton matches the file's skin and node
//! hierarchy, and model-space and skinning matrices match a plain matrix
//! evaluation of the node hierarchy.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use anim::{Clip, Space};
use formats::import::ImportOptions;

use super::reference::{Mat, RawGltf, Sampler, trs};
use super::{build, import_file, opts};

/// The joints the importer documents: every skin joint, every animated
/// node, and all their ancestors, computed from the raw JSON.
fn expected_nodes(raw: &RawGltf, animation: usize) -> BTreeSet<usize> {
    let mut nodes: BTreeSet<usize> = BTreeSet::new();
    let animated: BTreeSet<usize> = raw.json["animations"][animation]["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["target"]["node"].as_u64().unwrap() as usize)
        .collect();
    nodes.extend(&animated);
    for skin in raw.json["skins"].as_array().unwrap() {
        let joints: Vec<usize> =
            skin["joints"].as_array().unwrap().iter().map(|j| j.as_u64().unwrap() as usize).collect();
        if joints.iter().any(|j| animated.contains(j)) {
            nodes.extend(joints);
        }
    }
    for n in nodes.clone() {
        let mut at = n;
        while let Some(p) = raw.parent_of(at) {
            nodes.insert(p);
            at = p;
        }
    }
    nodes
}

/// World matrices of `nodes` at time `t`: each node's local matrix (its
/// animated T, R, S from the spec formulas, else its static transform),
/// multiplied down from the root.
fn world(raw: &RawGltf, animation: usize, nodes: &BTreeSet<usize>, t: f64) -> HashMap<usize, Mat> {
    let channels = raw.json["animations"][animation]["channels"].as_array().unwrap();
    let local = |n: usize| -> Mat {
        let mine: Vec<_> = channels.iter().filter(|c| c["target"]["node"].as_u64() == Some(n as u64)).collect();
        if mine.is_empty() {
            return raw.static_local(n);
        }
        let node = raw.node(n);
        let get = |k: &str, d: &[f64]| -> Vec<f64> {
            node[k].as_array().map_or(d.to_vec(), |a| a.iter().map(|x| x.as_f64().unwrap()).collect())
        };
        let (mut tr, mut r, mut s) =
            (get("translation", &[0.0; 3]), get("rotation", &[0.0, 0.0, 0.0, 1.0]), get("scale", &[1.0; 3]));
        for c in mine {
            let sampler = Sampler::read(raw, animation, c["sampler"].as_u64().unwrap() as usize);
            match c["target"]["path"].as_str().unwrap() {
                "translation" => tr = sampler.eval(t, false),
                "rotation" => r = sampler.eval(t, true),
                "scale" => s = sampler.eval(t, false),
                _ => {}
            }
        }
        trs(&tr, &r, &s)
    };
    let mut out = HashMap::new();
    for &n in nodes {
        let mut m = local(n);
        let mut at = n;
        while let Some(p) = raw.parent_of(at) {
            m = local(p).mul(&m);
            at = p;
        }
        out.insert(n, m);
    }
    out
}

/// The skins' inverse bind matrices by joint node.
fn inverse_binds(raw: &RawGltf) -> HashMap<usize, Mat> {
    let mut out = HashMap::new();
    for skin in raw.json["skins"].as_array().unwrap() {
        let matrices = raw.accessor(skin["inverseBindMatrices"].as_u64().unwrap() as usize);
        for (j, m) in skin["joints"].as_array().unwrap().iter().zip(matrices) {
            out.entry(j.as_u64().unwrap() as usize).or_insert_with(|| Mat::from_cols(&m));
        }
    }
    out
}

fn check_model(rel: &str, expected_clips: &[(&str, usize)]) {
    let raw = RawGltf::load(rel);
    let imported = import_file(rel, &ImportOptions::default());
    assert_eq!(imported.clips.len(), expected_clips.len(), "{rel}");
    let binds = inverse_binds(&raw);
    for (a, (spec, &(name, keys))) in imported.clips.iter().zip(expected_clips).enumerate() {
        assert_eq!(spec.name, name);
        let clip: Clip = build(spec);
        let nodes = expected_nodes(&raw, a);

        // Joints: count, names and parents as in the file, parents first.
        let skeleton = clip.skeleton();
        assert_eq!(skeleton.len(), nodes.len(), "{rel} {name}: joint count");
        let expected: BTreeMap<String, Option<String>> =
            nodes.iter().map(|&n| (raw.node_name(n), raw.parent_of(n).map(|p| raw.node_name(p)))).collect();
        let got: BTreeMap<String, Option<String>> = (0..skeleton.len())
            .map(|j| (skeleton.names()[j].clone(), skeleton.parent(j).map(|p| skeleton.names()[p].clone())))
            .collect();
        assert_eq!(got, expected, "{rel} {name}: hierarchy");
        assert!((0..skeleton.len()).all(|j| skeleton.parent(j).is_none_or(|p| p < j)), "parents first");
        assert!(skeleton.has_inverse_binds(), "{rel}: the skin's inverse bind matrices are kept");
        let node_of: Vec<usize> =
            skeleton.names().iter().map(|n| *nodes.iter().find(|&&i| raw.node_name(i) == *n).unwrap()).collect();

        // Keys as the file has them.
        let sampler = Sampler::read(&raw, a, 0);
        assert_eq!(sampler.times.len(), keys, "{rel} {name}: key count");
        assert_eq!(clip.end() as f64, *sampler.times.last().unwrap());

        // Model-space and skinning matrices at keys, between keys, and outside.
        let (start, end) = (clip.start() as f64, clip.end() as f64);
        let times = [start - 0.1, start, start + 0.3 * (end - start), (start + end) / 2.0 + 0.013, end, end + 1.0];
        let mut sampler_buf = anim::Sampler::new();
        let (mut model, mut skinning) = (Vec::new(), Vec::new());
        for t in times {
            let expected = world(&raw, a, &nodes, t.clamp(start, end));
            clip.matrices(t, &opts(Space::Local), false, &mut sampler_buf, &mut model);
            assert!(clip.matrices(t, &opts(Space::Local), true, &mut sampler_buf, &mut skinning));
            for (j, &n) in node_of.iter().enumerate() {
                let m = expected[&n];
                let tol = 2e-5 * (1.0 + m.max_abs());
                let d = m.max_diff(&model[j].to_cols_array());
                assert!(d <= tol, "{rel} {name} t={t} joint {}: model matrix off by {d}", skeleton.names()[j]);
                let skin = binds.get(&n).map_or(m, |b| m.mul(b));
                let tol = 2e-5 * (1.0 + m.max_abs() * binds.get(&n).map_or(1.0, Mat::max_abs));
                let d = skin.max_diff(&skinning[j].to_cols_array());
                assert!(d <= tol, "{rel} {name} t={t} joint {}: skinning matrix off by {d}", skeleton.names()[j]);
            }
        }
    }
}

#[test]
fn rigged_simple_with_matrix_nodes() {
    check_model("gltf/RiggedSimple/RiggedSimple.gltf", &[("animation0", 50)]);
    // The first key is not at 0: the clip starts where its keys start.
    let spec = &import_file("gltf/RiggedSimple/RiggedSimple.gltf", &ImportOptions::default()).clips[0];
    assert!((build(spec).start() - 0.041_666).abs() < 1e-4);
}

#[test]
fn cesium_man_with_unnamed_nodes() {
    check_model("gltf/CesiumMan/CesiumMan.gltf", &[("animation0", 49)]);
}

#[test]
fn fox_with_three_animations() {
    check_model("gltf/Fox/Fox.glb", &[("Survey", 83), ("Walk", 18), ("Run", 25)]);
}
