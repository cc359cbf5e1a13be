//! BVH files: counts as in the file, and model-space joint positions equal
//! to matrix forward kinematics computed here from the raw channel values.

use anim::{Channel, Interpolation, Keys, Space};
use formats::import::ImportOptions;

use super::reference::{Mat, read};
use super::{build, import_file, sample};

struct RawJoint {
    name: String,
    parent: Option<usize>,
    offset: [f64; 3],
    channels: Vec<String>,
}

/// A straightforward whitespace-token reading of a well-formed BVH.
struct RawBvh {
    joints: Vec<RawJoint>,
    end_sites: usize,
    frame_time: f64,
    frames: Vec<Vec<f64>>,
}

impl RawBvh {
    fn parse(rel: &str) -> RawBvh {
        let text = String::from_utf8(read(rel)).unwrap();
        let mut tokens = text.split_whitespace();
        let mut joints: Vec<RawJoint> = Vec::new();
        let mut stack: Vec<usize> = Vec::new();
        let mut end_sites = 0;
        let number = |t: Option<&str>| -> f64 { t.unwrap().parse().unwrap() };
        loop {
            match tokens.next().unwrap() {
                "HIERARCHY" | "{" => {}
                "ROOT" | "JOINT" => {
                    let name = tokens.next().unwrap().to_owned();
                    joints.push(RawJoint { name, parent: stack.last().copied(), offset: [0.0; 3], channels: vec![] });
                    stack.push(joints.len() - 1);
                }
                "End" => {
                    assert_eq!(tokens.next(), Some("Site"));
                    let parent = *stack.last().unwrap();
                    let name = format!("{}_end", joints[parent].name);
                    joints.push(RawJoint { name, parent: Some(parent), offset: [0.0; 3], channels: vec![] });
                    stack.push(joints.len() - 1);
                    end_sites += 1;
                }
                "}" => {
                    stack.pop();
                }
                "OFFSET" => {
                    let j = *stack.last().unwrap();
                    joints[j].offset = [number(tokens.next()), number(tokens.next()), number(tokens.next())];
                }
                "CHANNELS" => {
                    let j = *stack.last().unwrap();
                    let n: usize = tokens.next().unwrap().parse().unwrap();
                    joints[j].channels = (0..n).map(|_| tokens.next().unwrap().to_owned()).collect();
                }
                "MOTION" => break,
                other => panic!("unexpected {other}"),
            }
        }
        assert_eq!(tokens.next(), Some("Frames:"));
        let count: usize = tokens.next().unwrap().parse().unwrap();
        assert_eq!((tokens.next(), tokens.next()), (Some("Frame"), Some("Time:")));
        let frame_time = number(tokens.next());
        let width: usize = joints.iter().map(|j| j.channels.len()).sum();
        let values: Vec<f64> = tokens.map(|t| t.parse().unwrap()).collect();
        assert_eq!(values.len(), count * width, "{rel}: the data holds every frame");
        let frames = values.chunks(width).map(<[f64]>::to_vec).collect();
        RawBvh { joints, end_sites, frame_time, frames }
    }

    /// World matrices at frame `k`: `M = M_parent · T · R_1 · R_2 · R_3`
    /// with `T` the position channels (else OFFSET) and `R_i` the rotation
    /// channels in the order listed, each an axis rotation matrix.
    fn world(&self, k: usize) -> Vec<Mat> {
        let values = &self.frames[k];
        let mut at = 0;
        let mut out: Vec<Mat> = Vec::with_capacity(self.joints.len());
        for joint in &self.joints {
            let mut t = joint.offset;
            let mut r = Mat::IDENTITY;
            for c in &joint.channels {
                let v = values[at];
                at += 1;
                match c.as_str() {
                    "Xposition" => t[0] = v,
                    "Yposition" => t[1] = v,
                    "Zposition" => t[2] = v,
                    "Xrotation" => r = r.mul(&Mat::axis_rotation(0, v)),
                    "Yrotation" => r = r.mul(&Mat::axis_rotation(1, v)),
                    "Zrotation" => r = r.mul(&Mat::axis_rotation(2, v)),
                    other => panic!("{other}"),
                }
            }
            let local = Mat::translation(t).mul(&r);
            out.push(match joint.parent {
                Some(p) => out[p].mul(&local),
                None => local,
            });
        }
        out
    }
}

fn check(rel: &str, joints: usize, end_sites: usize, frames: usize, interpolation: Interpolation) {
    let raw = RawBvh::parse(rel);
    assert_eq!((raw.joints.len() - raw.end_sites, raw.end_sites, raw.frames.len()), (joints, end_sites, frames));
    let options = ImportOptions { bvh_interpolation: interpolation, ..ImportOptions::default() };
    let imported = import_file(rel, &options);
    assert_eq!(imported.clips.len(), 1);
    let spec = &imported.clips[0];
    let clip = build(spec);

    // Joints (End Sites as `<parent>_end` leaves), frames and frame time.
    let skeleton = clip.skeleton();
    assert_eq!(skeleton.len(), joints + end_sites);
    for (j, joint) in raw.joints.iter().enumerate() {
        assert_eq!(skeleton.names()[j], joint.name);
        assert_eq!(skeleton.parent(j), joint.parent);
    }
    let root_rotation = spec
        .tracks
        .iter()
        .find(|t| t.joint == raw.joints[0].name && t.channel == Channel::Rotation)
        .expect("the root rotates");
    assert_eq!(root_rotation.times.len(), frames);
    assert!(matches!(&root_rotation.values, Keys::Vec4(v) if v.len() == frames));
    assert!(spec.tracks.iter().all(|t| t.interpolation == interpolation));
    let ft = root_rotation.times[1] as f64 - root_rotation.times[0] as f64;
    assert!((ft - raw.frame_time).abs() < 1e-6, "frame time {ft} vs {}", raw.frame_time);
    let last = (frames - 1) as f64 * raw.frame_time;
    assert!((clip.end() as f64 - last).abs() < 1e-5, "end {} vs {last}", clip.end());

    // Model-space positions of every joint at several frames.
    for k in [0, 1, 2, frames / 3, frames / 2, frames - 2, frames - 1] {
        let expected = raw.world(k);
        let s = sample(&clip, k as f64 * raw.frame_time, Space::Model);
        let pose = s.pose();
        for (j, m) in expected.iter().enumerate() {
            let p = m.position();
            let got = pose.translations[j].to_array();
            let d = (0..3).map(|i| (p[i] - got[i] as f64).abs()).fold(0.0, f64::max);
            let scale = p.iter().fold(1.0f64, |a, x| a.max(x.abs()));
            assert!(d <= 1e-5 * scale * 10.0, "{rel} frame {k} joint {}: {p:?} vs {got:?}", raw.joints[j].name);
        }
    }
}

#[test]
fn cmu_131_01_with_mixed_line_endings_and_rotation_orders() {
    check("bvh/131_01.bvh", 31, 7, 994, Interpolation::Linear);
}

#[test]
fn cmu_131_03() {
    check("bvh/131_03.bvh", 31, 7, 1102, Interpolation::Linear);
}

#[test]
fn cmu_05_20_motionbuilder_skeleton() {
    check("bvh/05_20-mb.bvh", 31, 7, 1096, Interpolation::Linear);
}

#[test]
fn cmu_05_20_daz_skeleton_with_tabs_and_43_joints() {
    check("bvh/05_20-daz.bvh", 43, 14, 1096, Interpolation::Linear);
}

#[test]
fn catmull_rom_on_request_still_passes_through_every_frame() {
    check("bvh/131_01.bvh", 31, 7, 994, Interpolation::CatmullRom);
}

/// Sums `|p(t+δ) − 2p(t) + p(t−δ)|²` over every joint's model-space
/// position at four samples per frame, and returns it with the positions
/// at the frame times.
fn second_difference_energy(clip: &anim::Clip, frame_time: f64, frames: usize) -> (f64, Vec<Vec<[f64; 3]>>) {
    let steps = 4 * (frames - 1);
    let positions: Vec<Vec<[f64; 3]>> = (0..=steps)
        .map(|k| {
            let s = sample(clip, k as f64 * frame_time / 4.0, Space::Model);
            s.pose().translations.iter().map(|p| p.as_dvec3().to_array()).collect()
        })
        .collect();
    let mut energy = 0.0;
    for w in positions.windows(3) {
        for ((before, now), after) in w[0].iter().zip(&w[1]).zip(&w[2]) {
            energy += (0..3).map(|i| (after[i] - 2.0 * now[i] + before[i]).powi(2)).sum::<f64>();
        }
    }
    let at_frames = positions.into_iter().step_by(4).collect();
    (energy, at_frames)
}

/// `interpolation=b_spline` smooths a capture: over CMU 131_03 the joints'
/// second-difference energy (sampled between frames too, where linear keys
/// have their kinks) is far below linear's, and below Catmull-Rom's, while
/// every joint stays close to its captured position at every frame.
#[test]
fn b_spline_smooths_a_capture_and_stays_close_to_it() {
    let rel = "bvh/131_03.bvh";
    let raw = RawBvh::parse(rel);
    let frames = raw.frames.len();
    let imported = |interpolation| {
        let spec = import_file(rel, &ImportOptions { bvh_interpolation: interpolation, ..ImportOptions::default() })
            .clips
            .remove(0);
        assert!(spec.tracks.iter().all(|t| t.interpolation == interpolation));
        build(&spec)
    };
    let (linear, captured) = second_difference_energy(&imported(Interpolation::Linear), raw.frame_time, frames);
    let (catmull, _) = second_difference_energy(&imported(Interpolation::CatmullRom), raw.frame_time, frames);
    let (smooth, at_frames) = second_difference_energy(&imported(Interpolation::BSpline), raw.frame_time, frames);
    let mut worst = 0.0f64;
    let mut extent = 0.0f64;
    for (got, want) in at_frames.iter().zip(&captured) {
        for (g, w) in got.iter().zip(want) {
            let d = (0..3).map(|i| (g[i] - w[i]).powi(2)).sum::<f64>().sqrt();
            worst = worst.max(d);
            extent = extent.max(w.iter().fold(0.0f64, |a, x| a.max(x.abs())));
        }
    }
    println!(
        "131_03 second-difference energy: linear {linear:.4e}, catmull_rom {catmull:.4e}, b_spline {smooth:.4e} \
         ({:.1}% of linear); worst b_spline distance from a captured joint position {worst:.4} (scene extent {extent:.1})",
        100.0 * smooth / linear
    );
    assert!(smooth < 0.5 * linear, "b_spline {smooth:e} vs linear {linear:e}");
    assert!(smooth < catmull, "b_spline {smooth:e} vs catmull_rom {catmull:e}");
    assert!(worst < 0.02 * extent, "b_spline strays {worst} from the capture");
}
