//! Compact frames (docs/compact-frames.md) on real clips: the Fox's walk, a
//! CMU take and the 20-joint benchmark clip. Every decoded frame is exactly
//! the encoder's quantised pose; every joint and virtual point is within
//! `max_error` of the f32 pose, measured by an f64 forward kinematics written
//! here; key frames and a 10 s stream against the protobuf frame of the same
//! poses. `cargo test -p inbetween-formats --test formats compact_sizes -- --nocapture`
//! prints the sizes BENCHMARKS.md records.

use anim::compact::{DEFAULT_MAX_ERROR, Layout, Ranges, default_distance};
use anim::{
    Channel, Clip, ClipSpec, Cursor, Ease, EventSpec, Interpolation, JointSpec, Keys, Playback, Pose, Skeleton,
    SkeletonSpec, TrackSpec, Transform,
};
use formats::import::ImportOptions;
use formats::wire::compact::{
    CompactDecoder, CompactEncoder, CompactError, GraphDoc, GraphFrame, GraphNodeDoc, Header, LayoutDoc,
    RootMotionReport, Trailer,
};
use formats::wire::proto::pb;
use glam::{DQuat, DVec3, Vec3, Vec4};
use prost::Message;

use crate::{build, import_file};

/// Model-space joint positions and the three points `distance` along each
/// joint's axes, `M_j · (distance · axis)`, in f64 (docs/clip-format.md,
/// “Skeleton and spaces”).
fn points(skeleton: &Skeleton, pose: &Pose, distance: f64) -> Vec<DVec3> {
    let n = pose.len();
    let (mut t, mut q, mut s) = (vec![DVec3::ZERO; n], vec![DQuat::IDENTITY; n], vec![DVec3::ONE; n]);
    let mut out = Vec::with_capacity(4 * n);
    for j in 0..n {
        let tl = Vec3::from(pose.translations[j]).as_dvec3();
        let (ql, sl) = (pose.rotations[j].as_dquat(), Vec3::from(pose.scales[j]).as_dvec3());
        (t[j], q[j], s[j]) = match skeleton.parent(j) {
            None => (tl, ql, sl),
            Some(p) => (t[p] + q[p] * (s[p] * tl), q[p] * ql, s[p] * sl),
        };
        out.push(t[j]);
        out.extend([DVec3::X, DVec3::Y, DVec3::Z].map(|axis| t[j] + q[j] * (s[j] * axis * distance)));
    }
    out
}

/// The 20-joint benchmark clip of `scripts/bench_rest.sh`: a chain of
/// 31-key Catmull-Rom rotations, the root also translated.
pub fn bench20() -> Clip {
    let joints = (0..20)
        .map(|i| JointSpec {
            name: format!("j{i}"),
            parent: (i > 0).then(|| format!("j{}", i - 1)),
            rest: Transform { translation: Vec3::new(0.0, 0.1, 0.0), ..Transform::IDENTITY },
            inverse_bind: None,
        })
        .collect();
    let times: Vec<f32> = (0..31).map(|k| k as f32 / 10.0).collect();
    let rot = |i: usize, k: usize| {
        let a = 0.3 * (k as f64 / 5.0 + i as f64).sin();
        Vec4::new(0.0, 0.0, (a / 2.0).sin() as f32, (a / 2.0).cos() as f32)
    };
    let mut tracks: Vec<TrackSpec> = (0..20)
        .map(|i| {
            let values = Keys::Vec4((0..31).map(|k| rot(i, k)).collect());
            TrackSpec::new(&format!("j{i}"), Channel::Rotation, Interpolation::CatmullRom, times.clone(), values)
        })
        .collect();
    let root = Keys::Vec3((0..31).map(|k| Vec3::new(k as f32 / 10.0, 0.0, 0.0)).collect());
    tracks.push(TrackSpec::new("j0", Channel::Translation, Interpolation::CatmullRom, times, root));
    build(&ClipSpec {
        name: "bench20".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks,
        playback: Playback::Loop,
        ..Default::default()
    })
}

pub fn fox_walk() -> Clip {
    // The Fox is in centimetres; bounds are in metres.
    let fox = import_file("gltf/Fox/Fox.glb", &ImportOptions { scale: 0.01, ..ImportOptions::default() });
    build(fox.clips.iter().find(|c| c.name.ends_with("Walk")).expect("the Fox has a walk"))
}

pub fn cmu_take() -> Clip {
    // CMU lengths are in units of 0.45 inch (the ASF's `length 0.45`).
    let options = ImportOptions { scale: 0.0254 / 0.45, ..ImportOptions::default() };
    build(&import_file("bvh/131_01.bvh", &options).clips[0])
}

/// The protobuf frame a stream sends for `pose` (without joint names).
fn protobuf_frame(header: &Header, pose: &Pose) -> usize {
    let flat3 = |v: &[glam::Vec3A]| v.iter().flat_map(|t| t.to_array()).collect::<Vec<f32>>();
    pb::Frame {
        seq: header.seq,
        clip_time: header.clip_time,
        sent_at_unix_nanos: header.sent_at_unix_nanos,
        dropped: header.dropped,
        events: vec![],
        pose: Some(pb::Pose {
            translations: flat3(&pose.translations),
            rotations: pose.rotations.iter().flat_map(|q| q.to_array()).collect(),
            scales: flat3(&pose.scales),
            time: f64::from(header.clip_time),
            clip_time: header.clip_time,
            ..Default::default()
        }),
        ..Default::default()
    }
    .encoded_len()
}

/// What streaming `clip` looped for `seconds` at `fps` measured.
struct Run {
    joints: usize,
    layout: Layout,
    key_bytes: usize,
    protobuf_bytes: f64,
    mean_bytes: f64,
    worst_error: f64,
}

/// Streams `clip` as a looped stream would, decoding every frame.
fn stream(clip: &Clip, seconds: u32, fps: u32) -> Run {
    let skeleton = clip.skeleton();
    let layout = Layout::choose(skeleton, &Ranges::of_clip(clip, 240.0), DEFAULT_MAX_ERROR, default_distance(skeleton));
    let distance = f64::from(layout.distance);
    let mut encoder = CompactEncoder::new(layout.clone(), u64::from(fps));
    let mut decoder = CompactDecoder::new(layout.clone());
    let (mut cursor, mut pose, mut decoded, mut quantised) =
        (Cursor::default(), Pose::default(), Pose::default(), Pose::default());
    let (mut bytes, mut protobuf, mut key_bytes, mut worst) = (0usize, 0usize, 0usize, 0.0f64);
    let frames = seconds * fps;
    for seq in 0..frames {
        let t = f64::from(seq) / f64::from(fps);
        let clip_time = clip.clip_time(t, Playback::Loop, Ease::Linear);
        clip.sample_into(clip_time, &mut cursor, &mut pose);
        let header = Header {
            seq: u64::from(seq),
            dropped: 0,
            sent_at_unix_nanos: 1_764_680_000_000_000_000 + seq as i64 * 33_333_333,
            clip_time,
        };
        let frame = encoder.encode(&header, &pose, false).to_vec();
        let info = decoder.decode(&frame, &mut decoded).expect("the encoder's frames decode");
        assert_eq!(info.header, header);
        encoder.quantised_pose(&mut quantised);
        assert_eq!(decoded, quantised, "{}: frame {seq} decodes to the quantised pose exactly", clip.name());
        let (a, b) = (points(skeleton, &pose, distance), points(skeleton, &decoded, distance));
        worst = a.iter().zip(&b).map(|(x, y)| x.distance(*y)).fold(worst, f64::max);
        if info.key {
            key_bytes = key_bytes.max(frame.len());
        }
        bytes += frame.len();
        protobuf += protobuf_frame(&header, &pose);
    }
    Run {
        joints: skeleton.len(),
        layout,
        key_bytes,
        protobuf_bytes: protobuf as f64 / f64::from(frames),
        mean_bytes: bytes as f64 / f64::from(frames),
        worst_error: worst,
    }
}

#[test]
fn compact_sizes_and_errors_on_real_clips() {
    println!(
        "| clip | joints | key bits | bound (m) | worst error (m) | protobuf B | key frame B | ratio | mean B/frame (10 s, 30 fps) | ratio |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (name, clip) in [("Fox walk", fox_walk()), ("CMU 131_01", cmu_take()), ("20-joint benchmark", bench20())] {
        let run = stream(&clip, 10, 30);
        println!(
            "| {name} | {} | {} | {:.2e} | {:.2e} | {:.0} | {} | 1/{:.1} | {:.1} | 1/{:.1} |",
            run.joints,
            run.layout.key_bits(),
            run.layout.bound,
            run.worst_error,
            run.protobuf_bytes,
            run.key_bytes,
            run.protobuf_bytes / run.key_bytes as f64,
            run.mean_bytes,
            run.protobuf_bytes / run.mean_bytes,
        );
        assert!(run.layout.bound <= DEFAULT_MAX_ERROR, "{name}: computed bound {}", run.layout.bound);
        assert!(run.worst_error <= f64::from(DEFAULT_MAX_ERROR), "{name}: measured {}", run.worst_error);
        assert!(run.key_bytes as f64 <= run.protobuf_bytes / 6.0, "{name}: key frame {} B", run.key_bytes);
    }
}
#[test]
fn a_viewer_that_missed_the_key_frame_is_refused_until_it_gets_it() {
    let clip = bench20();
    let skeleton = clip.skeleton();
    let layout =
        Layout::choose(skeleton, &Ranges::of_clip(&clip, 240.0), DEFAULT_MAX_ERROR, default_distance(skeleton));
    // The layout travels as JSON in `opened`: the decoder works from that.
    let doc: LayoutDoc =
        serde_json::from_str(&serde_json::to_string(&LayoutDoc::new(&layout, skeleton.names(), 30, &[])).unwrap())
            .unwrap();
    assert_eq!(doc.layout(), layout);
    let mut encoder = CompactEncoder::new(layout.clone(), 30);
    let (mut cursor, mut pose, mut decoded) = (Cursor::default(), Pose::default(), Pose::default());
    let mut frames = Vec::new();
    for seq in 0..35u64 {
        clip.sample_into(seq as f32 / 30.0, &mut cursor, &mut pose);
        let header = Header { seq, clip_time: seq as f32 / 30.0, ..Header::default() };
        frames.push((encoder.encode(&header, &pose, false).to_vec(), encoder.last_key_frame().to_vec()));
    }
    assert_eq!(frames[0].0[0] & 1, 1, "the first frame is a key frame");
    assert_eq!(frames[30].0[0] & 1, 1, "a key frame a second later");
    assert!(frames[1..30].iter().all(|(f, _)| f[0] & 1 == 0));
    let mut late = CompactDecoder::new(doc.layout());
    assert_eq!(late.decode(&frames[5].0, &mut decoded), Err(CompactError::MissingKeyFrame { wanted: 0, seen: None }));
    // Sent the stream's last key frame first, it decodes the delta.
    late.decode(&frames[5].1, &mut decoded).unwrap();
    let info = late.decode(&frames[5].0, &mut decoded).unwrap();
    assert_eq!((info.key, info.key_seq, info.header.seq), (false, 0, 5));
    assert_eq!(
        late.decode(&frames[31].0, &mut decoded),
        Err(CompactError::MissingKeyFrame { wanted: 30, seen: Some(0) })
    );
    let mut cut = frames[5].0.clone();
    cut.pop();
    assert!(matches!(late.decode(&cut, &mut decoded), Err(CompactError::Truncated(_))));
    let mut long = frames[5].0.clone();
    long.push(0);
    assert_eq!(late.decode(&long, &mut decoded), Err(CompactError::TrailingBytes(1)));
}

#[test]
fn events_and_root_motion_follow_the_body_and_are_checked() {
    let clip = stepping_half_turn();
    let layout = Layout::choose(clip.skeleton(), &Ranges::of_clip(&clip, 240.0), DEFAULT_MAX_ERROR, 0.1);
    let doc = LayoutDoc::new(&layout, clip.skeleton().names(), 30, clip.events());
    let mut encoder = CompactEncoder::new(layout.clone(), 30);
    let (header, pose) = (Header { seq: 3, ..Header::default() }, clip.skeleton().rest().clone());
    let plain = encoder.encode(&header, &pose, true).to_vec();
    let trailer = Trailer { events: &[2, 0], root_motion: Some(STEPS[2]), graph: None };
    let full = encoder.encode_with(&header, &pose, true, &trailer).to_vec();
    // Flags gain bits 1 and 2; the body is the same; then count, indices, 8 f32s.
    assert_eq!(full[0], 0b111);
    assert_eq!(full[1..plain.len()], plain[1..]);
    let mut tail = vec![2, 2, 0];
    STEPS[2].delta.iter().chain(&STEPS[2].total).for_each(|v| tail.extend(v.to_le_bytes()));
    assert_eq!(full[plain.len()..], tail);
    let (mut decoder, mut out) = (CompactDecoder::of_document(&doc), Pose::default());
    assert_eq!(decoder.decode(&full, &mut out).unwrap().root_motion, Some(STEPS[2]));
    assert_eq!(decoder.events(), [2, 0]);
    assert_eq!(decoder.decode(&plain, &mut out).unwrap().root_motion, None);
    assert!(decoder.events().is_empty());
    // An index past the layout's three events, a section cut short, an unknown flag.
    let mut unknown = full.clone();
    unknown[plain.len() + 1] = 3;
    assert_eq!(decoder.decode(&unknown, &mut out), Err(CompactError::UnknownEvent { index: 3, count: 3 }));
    assert_eq!(decoder.decode(&full[..full.len() - 1], &mut out), Err(CompactError::Truncated("root motion")));
    let mut flagged = plain.clone();
    flagged[0] |= 16;
    assert_eq!(decoder.decode(&flagged, &mut out), Err(CompactError::UnknownFlags(17)));
    // A decoder without the document knows no events.
    assert!(matches!(CompactDecoder::new(layout).decode(&full, &mut out), Err(CompactError::UnknownEvent { .. })));
}

#[test]
fn the_graph_report_follows_the_root_motion_and_is_checked() {
    let clip = half_turn();
    let layout = Layout::choose(clip.skeleton(), &Ranges::of_clip(&clip, 240.0), DEFAULT_MAX_ERROR, 0.1);
    let mut doc = LayoutDoc::new(&layout, clip.skeleton().names(), 30, clip.events());
    doc.graph = Some(report_graph());
    let mut encoder = CompactEncoder::new(layout.clone(), 30);
    let (header, pose) = (Header { seq: 3, ..Header::default() }, clip.skeleton().rest().clone());
    let plain = encoder.encode(&header, &pose, true).to_vec();
    let report = &graph_reports()[1];
    let trailer = Trailer { root_motion: Some(STEPS[0]), graph: Some(report), ..Trailer::default() };
    let full = encoder.encode_with(&header, &pose, true, &trailer).to_vec();
    // Flags gain bits 2 and 3; after the root motion's 32 bytes: state 2, from + 1 = 2,
    // to 2, α, one node: index 0 and its two weights.
    assert_eq!(full[0], 0b1101);
    let section = &full[plain.len() + 32..];
    let mut expected = vec![2, 2, 2];
    expected.extend(0.25f32.to_le_bytes());
    expected.extend([1, 0]);
    [0.25f32, 0.75].iter().for_each(|w| expected.extend(w.to_le_bytes()));
    assert_eq!(section, expected);
    let (mut decoder, mut out) = (CompactDecoder::of_document(&doc), Pose::default());
    decoder.decode(&full, &mut out).unwrap();
    assert_eq!(decoder.graph_report(), Some(report));
    decoder.decode(&plain, &mut out).unwrap();
    assert_eq!(decoder.graph_report(), None);
    // A state, a transition's state or a node past the layout's; a section cut short.
    let at = plain.len() + 32;
    for (offset, what, index, count) in [(0, "state", 5, 3), (1, "state", 8, 3), (2, "state", 3, 3), (8, "node", 2, 2)]
    {
        let mut bad = full.clone();
        bad[at + offset] = u8::try_from(index + u64::from(offset == 1)).unwrap();
        assert_eq!(decoder.decode(&bad, &mut out), Err(CompactError::UnknownGraphIndex { what, index, count }));
    }
    assert_eq!(decoder.decode(&full[..full.len() - 1], &mut out), Err(CompactError::Truncated("graph report")));
    // A decoder without the layout's `graph` knows no states.
    let no_graph = CompactDecoder::new(layout).decode(&full, &mut out);
    assert!(matches!(no_graph, Err(CompactError::UnknownGraphIndex { what: "state", .. })));
}

/// A clip of `joints` joints in a chain, each turning about all three axes
/// (the root also moving and, when `scaled`, scaling), as test vectors use.
fn turning_chain(name: &str, joints: usize, bone: f32, scaled: bool) -> Clip {
    let specs = (0..joints)
        .map(|i| JointSpec {
            name: format!("joint{i}"),
            parent: (i > 0).then(|| format!("joint{}", i - 1)),
            rest: Transform { translation: Vec3::new(0.0, bone, 0.01), ..Transform::IDENTITY },
            inverse_bind: None,
        })
        .collect();
    let times: Vec<f32> = (0..9).map(|k| k as f32 / 8.0).collect();
    let mut tracks: Vec<TrackSpec> = (0..joints)
        .map(|i| {
            let values = (0..9)
                .map(|k| {
                    let a = (k as f32 * 0.7 + i as f32).sin() * 0.6;
                    Vec4::from(glam::Quat::from_euler(glam::EulerRot::XYZ, a, 0.5 * a, -0.3 * a))
                })
                .collect();
            TrackSpec::new(
                &format!("joint{i}"),
                Channel::Rotation,
                Interpolation::Linear,
                times.clone(),
                Keys::Vec4(values),
            )
        })
        .collect();
    let root = Keys::Vec3((0..9).map(|k| Vec3::new(k as f32 * 0.1, 0.9 + 0.02 * (k as f32).sin(), 0.0)).collect());
    tracks.push(TrackSpec::new("joint0", Channel::Translation, Interpolation::Linear, times.clone(), root));
    if scaled {
        let s = Keys::Vec3((0..9).map(|k| Vec3::splat(1.0 + 0.05 * (k as f32).cos())).collect());
        tracks.push(TrackSpec::new("joint1", Channel::Scale, Interpolation::Linear, times, s));
    }
    build(&ClipSpec { name: name.into(), skeleton: Some(SkeletonSpec { joints: specs }), tracks, ..Default::default() })
}

/// A joint that turns half a revolution about x: the largest component
/// changes from w to x, so its index is sent in every frame.
fn half_turn() -> Clip {
    build(&half_turn_spec())
}

fn half_turn_spec() -> ClipSpec {
    let joints =
        vec![JointSpec { name: "spinner".into(), parent: None, rest: Transform::IDENTITY, inverse_bind: None }];
    let values = (0..5).map(|k| Vec4::from(glam::Quat::from_rotation_x(k as f32 * 0.75))).collect();
    let times = (0..5).map(|k| k as f32 * 0.25).collect();
    let track = TrackSpec::new("spinner", Channel::Rotation, Interpolation::Linear, times, Keys::Vec4(values));
    ClipSpec {
        name: "half-turn".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks: vec![track],
        ..Default::default()
    }
}

/// The half turn with three footsteps, for the vector whose frames carry
/// events and root motion.
fn stepping_half_turn() -> Clip {
    let mut spec = half_turn_spec();
    spec.name = "stepping".into();
    spec.events = [(0.0, "step_left"), (0.5, "step_right"), (0.875, "land")]
        .map(|(time, name)| EventSpec { time, name: name.into() })
        .to_vec();
    build(&spec)
}

/// Root motion reports of the stepping vector: a step forward turning a
/// little each frame, with a total in f32 that no short decimal states.
const STEPS: [RootMotionReport; 3] = [
    RootMotionReport { delta: [0.0, 0.0, 0.0, 0.0], total: [0.0, 0.0, 0.0, 0.0] },
    RootMotionReport { delta: [0.05, 0.0, -0.125, 0.1], total: [0.05, 0.0, -0.125, 0.1] },
    RootMotionReport { delta: [0.0625, -0.001, -0.1, 0.2], total: [0.1125, -0.001, -0.225, 0.3] },
];

/// One test vector of docs/compact-frames/: the layout, then frames in
/// order (one decoder for all of them) with the pose each decodes to, and
/// the events and root motion of frames that carry them (`trailers`, per
/// frame; empty: none).
fn vector(
    (name, description): (&str, &str),
    clip: &Clip,
    times: &[f32],
    key_interval: u64,
    trailers: &[Trailer<'_>],
) -> serde_json::Value {
    let (mut encoder, doc) = encoder_of(clip, &Ranges::of_clip(clip, 240.0), key_interval);
    let frames = frames_of(&mut encoder, clip, times.iter().copied().enumerate(), trailers);
    serde_json::json!({ "name": name, "description": description, "layout": doc, "frames": frames })
}

/// An encoder of the layout `ranges` choose on `clip`'s skeleton (with its
/// events), and the layout's document.
fn encoder_of(clip: &Clip, ranges: &Ranges, key_interval: u64) -> (CompactEncoder, LayoutDoc) {
    let skeleton = clip.skeleton();
    let layout = Layout::choose(skeleton, ranges, DEFAULT_MAX_ERROR, default_distance(skeleton));
    assert!(layout.bound <= DEFAULT_MAX_ERROR, "{}: bound {}", clip.name(), layout.bound);
    let doc = LayoutDoc::new(&layout, skeleton.names(), key_interval, clip.events());
    (CompactEncoder::new(layout, key_interval), doc)
}

/// The frames of `clip` at `(index, time)`s in `encoder`'s layout: frame
/// `index` is `seq` 7 + index, and index 2 says it dropped one.
fn frames_of(
    encoder: &mut CompactEncoder,
    clip: &Clip,
    times: impl Iterator<Item = (usize, f32)>,
    trailers: &[Trailer<'_>],
) -> Vec<serde_json::Value> {
    let (mut cursor, mut pose, mut quantised) = (Cursor::default(), Pose::default(), Pose::default());
    times
        .map(|(seq, t)| {
            clip.sample_into(t, &mut cursor, &mut pose);
            let header = Header {
                seq: seq as u64 + 7,
                dropped: u64::from(seq == 2),
                sent_at_unix_nanos: 1_764_680_000_000_000_000 + seq as i64 * 50_000_000,
                clip_time: t,
            };
            let trailer = trailers.get(seq).copied().unwrap_or_default();
            let bytes = encoder.encode_with(&header, &pose, false, &trailer).to_vec();
            encoder.quantised_pose(&mut quantised);
            let v3 = |v: &[glam::Vec3A]| v.iter().map(|t| t.to_array()).collect::<Vec<_>>();
            let mut frame = serde_json::json!({
                "hex": hex::encode(&bytes),
                "key": bytes[0] & 1 == 1,
                "seq": header.seq,
                "dropped": header.dropped,
                // A string: JSON numbers beyond 2^53 lose digits in JavaScript.
                "sent_at_unix_nanos": header.sent_at_unix_nanos.to_string(),
                "clip_time": header.clip_time,
                "pose": {
                    "translations": v3(&quantised.translations),
                    "rotations": quantised.rotations.iter().map(|q| q.to_array()).collect::<Vec<_>>(),
                    "scales": v3(&quantised.scales),
                },
            });
            if !trailer.events.is_empty() {
                frame["events"] = serde_json::json!(trailer.events);
            }
            if let Some(r) = trailer.root_motion {
                frame["root_motion"] = serde_json::json!({"delta": r.delta, "total": r.total});
            }
            if let Some(g) = trailer.graph {
                frame["graph"] = graph_json(g);
            }
            frame
        })
        .collect()
}

/// The half turn, then a new layout mid-stream (docs/compact-frames.md, "A
/// new layout") that also holds the spinner rising as it turns: two
/// frames in the first layout, then the new layout with a key frame and a
/// delta frame in it. The frame that comes first in a layout carries it as
/// `layout`.
fn relayout_vector() -> serde_json::Value {
    let turn = half_turn();
    let mut spec = half_turn_spec();
    spec.name = "rising".into();
    let rise = Keys::Vec3((0..3).map(|k| Vec3::new(0.0, 0.25 * k as f32, 0.1 * k as f32)).collect());
    spec.tracks.push(TrackSpec::new("spinner", Channel::Translation, Interpolation::Linear, vec![0.0, 0.5, 1.0], rise));
    let rising = build(&spec);
    let (mut encoder, first) = encoder_of(&turn, &Ranges::of_clip(&turn, 240.0), 30);
    let mut frames = frames_of(&mut encoder, &turn, [(0, 0.0), (1, 0.4)].into_iter(), &[]);
    let mut ranges = Ranges::of_clip(&turn, 240.0);
    ranges.union(&Ranges::of_clip(&rising, 240.0));
    let (mut encoder, second) = encoder_of(&rising, &ranges, 30);
    let mut after = frames_of(&mut encoder, &rising, [(2, 0.6), (3, 0.9)].into_iter(), &[]);
    after[0]["layout"] = serde_json::to_value(&second).unwrap();
    frames.extend(after);
    serde_json::json!({
        "name": "relayout",
        "description": "The half turn, then a new layout mid-stream that also holds the joint rising: a key frame and a delta frame in the first layout, then a frame carrying the new layout (`layout`: adopt it before decoding the frame, as a stream's layout message says), a key frame, and a delta frame in it.",
        "layout": first,
        "frames": frames,
    })
}

/// A frame's graph report as a test vector states it: indices into the
/// layout's `graph`, the weights as f32s.
fn graph_json(g: &GraphFrame) -> serde_json::Value {
    let transition = g.transition.map(|(from, to, alpha)| serde_json::json!({"from": from, "to": to, "alpha": alpha}));
    let weights: Vec<_> = g.weights.iter().map(|(node, w)| serde_json::json!({"node": node, "weights": w})).collect();
    serde_json::json!({"state": g.state, "transition": transition, "weights": weights})
}

/// The graph of the `graph-report` vector: three states, two blend nodes.
fn report_graph() -> GraphDoc {
    let node = |name: &str, points| GraphNodeDoc { name: name.to_owned(), points };
    GraphDoc {
        states: ["idle", "move", "jump"].map(str::to_owned).to_vec(),
        nodes: vec![node("walkrun", 2), node("aim", 3)],
    }
}

/// The `graph-report` vector's reports: a state alone, a transition with
/// one node's weights, both nodes' weights.
fn graph_reports() -> [GraphFrame; 3] {
    [
        GraphFrame { state: 0, transition: None, weights: vec![] },
        GraphFrame { state: 2, transition: Some((1, 2, 0.25)), weights: vec![(0, vec![0.25, 0.75])] },
        GraphFrame { state: 1, transition: None, weights: vec![(0, vec![0.5, 0.5]), (1, vec![0.125, 0.375, 0.5])] },
    ]
}

#[test]
fn the_documented_test_vectors_are_what_the_encoder_writes() {
    let reports = graph_reports();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/compact-frames");
    let vectors = [
        vector(
            (
                "chain",
                "Four joints turning about three axes, the root moving and the second joint scaling: a key frame, deltas, a key frame (key_interval 3).",
            ),
            &turning_chain("chain", 4, 0.08, true),
            &[0.0, 0.125, 0.25, 0.3, 0.5],
            3,
            &[],
        ),
        vector(
            ("half-turn", "One joint whose largest component changes from w to x: its index is sent in every frame."),
            &half_turn(),
            &[0.0, 0.4, 0.9],
            30,
            &[],
        ),
        vector(
            (
                "stepping",
                "The half turn with three events and root motion: a key frame with an event and root motion, a delta frame with root motion only, one with two events and root motion, and one with neither.",
            ),
            &stepping_half_turn(),
            &[0.0, 0.4, 0.9, 0.95],
            30,
            &[
                Trailer { events: &[0], root_motion: Some(STEPS[0]), graph: None },
                Trailer { events: &[], root_motion: Some(STEPS[1]), graph: None },
                Trailer { events: &[1, 2], root_motion: Some(STEPS[2]), graph: None },
            ],
        ),
        {
            let mut v = vector(
                (
                    "graph-report",
                    "The half turn on a graph stream with report: a key frame with a state alone, a delta frame with a transition and one blend node's weights, and one with root motion and both nodes' weights.",
                ),
                &half_turn(),
                &[0.0, 0.4, 0.9],
                30,
                &[
                    Trailer { graph: Some(&reports[0]), ..Trailer::default() },
                    Trailer { graph: Some(&reports[1]), ..Trailer::default() },
                    Trailer { root_motion: Some(STEPS[2]), graph: Some(&reports[2]), ..Trailer::default() },
                ],
            );
            v["layout"]["graph"] = serde_json::to_value(report_graph()).unwrap();
            v
        },
        vector(
            (
                "bench20",
                "The 20-joint benchmark clip (scripts/bench_rest.sh): rotations about z only, the root moving along x.",
            ),
            &bench20(),
            &[0.0, 1.0 / 30.0, 2.0 / 30.0],
            30,
            &[],
        ),
        vector(
            ("chain71", "71 joints turning about three axes, for timing decoders: a key frame and a delta frame."),
            &turning_chain("chain71", 71, 0.02, false),
            &[0.2, 0.25],
            30,
            &[],
        ),
        relayout_vector(),
    ];
    // The page's worked examples are these frames.
    let page = std::fs::read_to_string(dir.join("../compact-frames.md")).unwrap();
    for (vector, frame) in [(1, 1), (2, 2), (3, 1)] {
        let hex = vectors[vector]["frames"][frame]["hex"].as_str().unwrap();
        assert!(page.contains(hex), "docs/compact-frames.md shows {hex}");
    }
    let bless = std::env::var_os("INBETWEEN_BLESS").is_some();
    for v in vectors {
        let path = dir.join(format!("{}.json", v["name"].as_str().unwrap()));
        let text = serde_json::to_string_pretty(&v).unwrap() + "\n";
        if bless {
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(&path, &text).unwrap();
        }
        let stored = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(stored == text, "{} drifted from the encoder; regenerate with INBETWEEN_BLESS=1", path.display());
        // And the Rust decoder reads the stored vector back exactly.
        let doc: LayoutDoc = serde_json::from_value(v["layout"].clone()).unwrap();
        let mut decoder = CompactDecoder::of_document(&doc);
        let mut pose = Pose::default();
        for frame in v["frames"].as_array().unwrap() {
            if let Some(layout) = frame.get("layout") {
                decoder.relayout(&serde_json::from_value(layout.clone()).unwrap());
            }
            let info = decoder.decode(&hex::decode(frame["hex"].as_str().unwrap()).unwrap(), &mut pose).unwrap();
            assert_eq!(info.key, frame["key"].as_bool().unwrap());
            let events: Vec<u32> =
                serde_json::from_value(frame.get("events").cloned().unwrap_or_default()).unwrap_or_default();
            assert_eq!(decoder.events(), events);
            let root = frame.get("root_motion").map(|r| RootMotionReport {
                delta: serde_json::from_value(r["delta"].clone()).unwrap(),
                total: serde_json::from_value(r["total"].clone()).unwrap(),
            });
            assert_eq!(info.root_motion, root);
            assert_eq!(decoder.graph_report().map(graph_json), frame.get("graph").cloned());
            let rotations: Vec<[f32; 4]> = serde_json::from_value(frame["pose"]["rotations"].clone()).unwrap();
            assert_eq!(pose.rotations.iter().map(|q| q.to_array()).collect::<Vec<_>>(), rotations);
        }
    }
}

/// A new layout forgets the old key frame: the new layout's delta frame
/// before its key frame is refused, as any delta frame without its key.
#[test]
fn a_new_layout_resets_the_key_frame() {
    let v = relayout_vector();
    let frames = v["frames"].as_array().unwrap();
    let bytes = |i: usize| hex::decode(frames[i]["hex"].as_str().unwrap()).unwrap();
    let mut decoder = CompactDecoder::of_document(&serde_json::from_value(v["layout"].clone()).unwrap());
    let mut pose = Pose::default();
    decoder.decode(&bytes(0), &mut pose).unwrap();
    decoder.decode(&bytes(1), &mut pose).unwrap();
    decoder.relayout(&serde_json::from_value(frames[2]["layout"].clone()).unwrap());
    assert_eq!(decoder.decode(&bytes(3), &mut pose).unwrap_err().code(), "compact_missing_key_frame");
    assert!(decoder.decode(&bytes(2), &mut pose).unwrap().key);
    decoder.decode(&bytes(3), &mut pose).unwrap();
}
