//! The cost model: the encoded size of an answer that produces poses, and
//! the work it takes in work units (`work::price`: evaluation, IK,
//! encoding), worked out from the clip and the request before anything is
//! evaluated, and checked against the limits.
//!
//! The sizes are upper bounds, not guesses: every number is counted at the
//! longest text it can print as (an `f32` at [`F32_TEXT`] bytes, an `f64`
//! at [`F64_TEXT`]), every joint name at its exact escaped length, every
//! protobuf length prefix at its widest varint. A unit test holds them
//! against the bytes really written. Typical poses come out at a half to a
//! third of the bound (short floats such as `0.0`).

use super::raw::{Field, Format, Locate, unprocessable};
use crate::config::Limits;
use crate::error::ApiError;
use crate::stream::{Encoding, MAX_EVENTS_PER_FRAME};
use crate::work::price;
use anim::Clip;
use prost::encoding::encoded_len_varint;

/// The longest JSON text of a finite `f32` (`-1.17549435e-38`, with room).
pub const F32_TEXT: u64 = 16;
/// The longest JSON text of a finite `f64` (`-2.2250738585072014e-308`).
pub const F64_TEXT: u64 = 24;
/// The widest varint length prefix this server writes (any `u32` length).
const VARINT: u64 = 5;

/// The largest unary answer (`SampleBatch`) sent; larger ones are
/// `SampleStream`'s. Clients' default receive limit is 4 MiB: this is what
/// a client that raised it may get in one message.
pub const MAX_UNARY_ANSWER_BYTES: u64 = 16 * 1024 * 1024;

/// How an answer travels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wire {
    /// REST's JSON documents, WebSocket JSON frames.
    Json,
    /// gRPC messages, WebSocket protobuf frames.
    Protobuf,
}

impl From<Encoding> for Wire {
    fn from(e: Encoding) -> Wire {
        match e {
            Encoding::Json => Wire::Json,
            // A compact frame's envelope on gRPC is a protobuf `Frame`.
            Encoding::Protobuf | Encoding::Compact => Wire::Protobuf,
        }
    }
}

/// An upper bound of one answer's encoded size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Estimate {
    /// Bytes written once (the envelope; protobuf's joint names).
    pub fixed: u64,
    /// Bytes per pose.
    pub per_pose: u64,
}

impl Estimate {
    /// The bound for `poses` poses.
    pub fn total(&self, poses: u64) -> u64 {
        self.fixed.saturating_add(self.per_pose.saturating_mul(poses))
    }

    /// A batch answer (`{"poses":[…]}` / `PoseBatch`) of `clip` (its id
    /// `clip_id`) rendered as `format`.
    pub fn batch(clip: &Clip, clip_id: &str, format: Format, wire: Wire) -> Estimate {
        match wire {
            Wire::Json => Estimate { fixed: 12, per_pose: json_pose(clip, clip_id, format) + 1 },
            // A pose is an embedded message: its tag and length, then the pose.
            Wire::Protobuf => Estimate { fixed: proto_names(clip), per_pose: 1 + VARINT + proto_pose(clip, format) },
        }
    }

    /// One pose answer (`GET …/pose`, `Sample`, whose names are in the pose).
    pub fn pose(clip: &Clip, clip_id: &str, format: Format, wire: Wire) -> Estimate {
        match wire {
            Wire::Json => Estimate { fixed: 0, per_pose: json_pose(clip, clip_id, format) },
            Wire::Protobuf => Estimate { fixed: proto_names(clip), per_pose: proto_pose(clip, format) },
        }
    }

    /// One stream frame (names included, as in a first frame; the most
    /// events a frame carries, each as long as the clip's longest: a fast
    /// loop crosses the same events again and again).
    pub fn frame(clip: &Clip, clip_id: &str, wire: Wire) -> u64 {
        let events = if clip.events().is_empty() { 0 } else { MAX_EVENTS_PER_FRAME as u64 };
        let longest = |size: &dyn Fn(&str) -> u64| clip.events().iter().map(|e| size(&e.name)).max().unwrap_or(0);
        match wire {
            // `{"seq":u64,"clip_time":f32,"sent_at_unix_nanos":i64,"dropped":u64,"events":[…],"pose":…}`
            Wire::Json => {
                let event = longest(&|name| 20 + F32_TEXT + json_str(name) + 1);
                80 + 3 * 20 + F32_TEXT + events * event + json_pose(clip, clip_id, Format::Trs)
            }
            Wire::Protobuf => {
                let event = longest(&|name| 1 + VARINT + 5 + 1 + VARINT + name.len() as u64);
                4 * 11 + events * event + 1 + VARINT + proto_names(clip) + proto_pose(clip, Format::Trs)
            }
        }
    }
}

/// The most a compact stream sends in one tick (docs/compact-frames.md):
/// a key frame a viewer missed and the delta frame after it, each a
/// header of varints at their widest and a clip time, per joint its
/// changed bit, a rotation's largest index and every channel at 24 bits,
/// then the most events a frame carries (as indices into the clip's
/// `events`) and a root motion report.
pub fn compact_frame(joints: usize, events: usize) -> u64 {
    let header = 1 + 4 * 10 + 4;
    let joint_bits = 1 + 2 + 9 * u64::from(anim::compact::MAX_BITS);
    let index = encoded_len_varint(events.saturating_sub(1) as u64) as u64;
    let events = if events == 0 { 0 } else { VARINT + MAX_EVENTS_PER_FRAME as u64 * index };
    2 * (header + (joints as u64 * joint_bits).div_ceil(8) + events + COMPACT_ROOT_MOTION)
}

/// A compact graph stream's frame's report section at most
/// (docs/compact-frames.md, “The graph report section”): the state, the
/// transition (`from + 1`, `to`, `alpha`) and the node count, then per blend
/// node its index and its weights as f32s; twice, as [`compact_frame`]
/// counts (a delta frame may carry its key frame along).
pub fn compact_graph_report<C>(graph: &anim::graph::Graph<C>) -> u64 {
    let nodes: u64 = graph.blend_nodes().map(|(_, points)| VARINT + 4 * points as u64).sum();
    2 * (4 * VARINT + 4 + nodes)
}

/// A compact frame's root motion section: delta and total, four f32s each.
const COMPACT_ROOT_MOTION: u64 = 32;

/// The JSON text of one pose, names included.
fn json_pose(clip: &Clip, clip_id: &str, format: Format) -> u64 {
    let names: u64 = clip.skeleton().names().iter().map(|n| json_str(n)).sum();
    let joints = clip.joint_count() as u64;
    // `{"clip":…,"time":…,"clip_time":…,"space":"local","joints":[…]}`, and
    // matrices' `,"format":"skinning"`.
    let head = 60 + json_str(clip_id) + F64_TEXT + F32_TEXT;
    let (head, per_joint) = match format {
        // `{"name":…,"translation":[3],"rotation":[4],"scale":[3]},`
        Format::Trs => (head, 52 + 7 + 10 * F32_TEXT),
        // `{"name":…,"matrix":[16]},`
        Format::Matrix | Format::Skinning => (head + 20, 22 + 15 + 16 * F32_TEXT),
    };
    head + names + joints * per_joint + ik_reports(clip.ik_count() as u64, Wire::Json) + json_parameters(clip)
}

/// `,"parameters":{"name":[v,…],…}` (docs/clip-format.md §3): every parameter, whatever
/// a request's subset (a bound), each value at its longest.
fn json_parameters(clip: &Clip) -> u64 {
    let layout = clip.parameters();
    if layout.is_empty() {
        return 0;
    }
    let names: u64 = layout.names().iter().map(|n| json_str(n) + 4).sum();
    16 + names + layout.total_width() as u64 * (F32_TEXT + 1)
}

/// Bytes of `n` IK reports (docs/ik.md) in a pose: JSON
/// `,"ik":[{"kind":"two_bone","residual":…,"iterations":…,"converged":false},…]`,
/// protobuf `IkReport` messages (kind, residual, iterations, converged).
pub fn ik_reports(n: u64, wire: Wire) -> u64 {
    match wire {
        // 73 bytes of the widest report around its residual, and a comma.
        Wire::Json if n > 0 => 8 + n * (74 + F32_TEXT),
        Wire::Json => 0,
        Wire::Protobuf => n * (2 + 2 + 5 + 6 + 2),
    }
}

/// The length of `s` as a JSON string, quotes and escapes included (as
/// `serde_json` escapes: `"`, `\` and control characters).
pub fn json_str(s: &str) -> u64 {
    let escaped: u64 = s
        .bytes()
        .map(|b| match b {
            b'"' | b'\\' | b'\n' | b'\t' | b'\r' | 0x08 | 0x0c => 2,
            0..0x20 => 6,
            _ => 1,
        })
        .sum();
    escaped + 2
}

/// Protobuf `joint_names`: a tag, a length and the bytes of each.
fn proto_names(clip: &Clip) -> u64 {
    let names = |names: &[String]| names.iter().map(|n| 1 + VARINT + n.len() as u64).sum::<u64>();
    let layout = clip.parameters();
    // `parameter_names`, and `parameter_widths` packed (a varint each).
    let parameters =
        if layout.is_empty() { 0 } else { names(layout.names()) + 1 + VARINT + VARINT * layout.len() as u64 };
    names(clip.skeleton().names()) + parameters
}

/// A protobuf `Pose` without its names.
fn proto_pose(clip: &Clip, format: Format) -> u64 {
    let joints = clip.joint_count() as u64;
    // time (9), clip_time (5), space (2).
    let scalars = 9 + 5 + 2 + ik_reports(clip.ik_count() as u64, Wire::Protobuf);
    // The packed `parameters` (docs/clip-format.md §3).
    let width = clip.parameters().total_width() as u64;
    let scalars = scalars + if width == 0 { 0 } else { 1 + VARINT + 4 * width };
    match format {
        Format::Trs => 3 * (1 + VARINT) + 40 * joints + scalars,
        Format::Matrix | Format::Skinning => (1 + VARINT) + 64 * joints + scalars,
    }
}

/// What one pose request costs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cost {
    pub poses: u64,
    pub joints: u64,
    /// Work units of one pose's evaluation (`work::price`).
    pub per_pose: u64,
    /// The encoded answer's upper bound.
    pub bytes: u64,
    /// How the answer will be compressed (`None`: as it is).
    pub compression: Option<price::Compression>,
}

impl Cost {
    /// What `poses` poses of `per_pose` units over `joints` joints cost,
    /// answered in at most `bytes` bytes sent as they are.
    pub fn new(poses: u64, joints: u64, per_pose: u64, bytes: u64) -> Cost {
        Cost { poses, joints, per_pose, bytes, compression: None }
    }

    /// The same answer compressed as `compression` says.
    pub fn compressed(self, compression: Option<price::Compression>) -> Cost {
        Cost { compression, ..self }
    }

    /// The request's whole price in work units: its poses, then the
    /// encoding of its answer and its compression.
    pub fn work(&self) -> u64 {
        let answer = price::encoding(self.bytes).saturating_add(price::compression(self.compression, self.bytes));
        self.poses.saturating_mul(self.per_pose).saturating_add(answer)
    }

    /// # Errors
    /// `too_many_poses` over `max_joint_poses` (poses × joints), then
    /// `too_much_work` over `max_request_work` (the price), then
    /// `answer_too_large` over `max_answer_bytes`; all at `field`, the
    /// request's times or range.
    pub fn check(&self, limits: &Limits, field: Field, at: Locate) -> Result<(), ApiError> {
        let joint_poses = self.poses.saturating_mul(self.joints);
        if joint_poses > limits.max_joint_poses as u64 {
            let detail = format!(
                "{} poses × {} joints = {joint_poses} joint poses; the limit (max_joint_poses, --max-joint-poses) is {}",
                self.poses, self.joints, limits.max_joint_poses
            );
            return Err(unprocessable("too_many_poses", field, at, detail));
        }
        let work = self.work();
        if work > limits.max_request_work {
            let detail = format!(
                "this request costs {work} work units ({} poses × {} units, {} to encode the answer and {} to compress \
                 it); the limit (max_request_work, --max-request-work) is {}",
                self.poses,
                self.per_pose,
                price::encoding(self.bytes),
                price::compression(self.compression, self.bytes),
                limits.max_request_work
            );
            return Err(unprocessable("too_much_work", field, at, detail));
        }
        if self.bytes > limits.max_answer_bytes as u64 {
            let detail = format!(
                "the answer would take up to {} bytes; the limit (max_answer_bytes, --max-answer-bytes) is {}",
                self.bytes, limits.max_answer_bytes
            );
            return Err(unprocessable("answer_too_large", field, at, detail));
        }
        Ok(())
    }
}

/// The work of one second of a stream: `fps` frames of `per_frame` units
/// of evaluation, each encoded at most `frame_bytes` long.
pub fn stream_work(per_frame: u64, frame_bytes: u64, fps: u32) -> u64 {
    per_frame.saturating_add(price::encoding(frame_bytes)).saturating_mul(u64::from(fps))
}

/// Checks a stream's price per second of playback.
///
/// # Errors
/// `too_much_work` over `max_request_work`, at `fps`.
pub fn check_stream_work(per_sec: u64, limits: &Limits, at: Locate) -> Result<(), ApiError> {
    if per_sec > limits.max_request_work {
        let detail = format!(
            "this stream costs {per_sec} work units per second of playback; the limit (max_request_work, \
             --max-request-work) is {}",
            limits.max_request_work
        );
        return Err(unprocessable("too_much_work", Field::Fps, at, detail));
    }
    Ok(())
}

/// Checks a stream's frame estimate and its rate at `fps`.
///
/// # Errors
/// `frame_too_large` over `max_frame_bytes`, `stream_rate_too_high` over
/// `max_stream_bytes_per_sec`.
pub fn check_stream(frame_bytes: u64, fps: u32, limits: &Limits, at: Locate) -> Result<(), ApiError> {
    if frame_bytes > limits.max_frame_bytes as u64 {
        let detail = format!(
            "one frame would take up to {frame_bytes} bytes; the limit (max_frame_bytes, --max-frame-bytes) is {}",
            limits.max_frame_bytes
        );
        return Err(unprocessable("frame_too_large", Field::When, at, detail));
    }
    let rate = frame_bytes.saturating_mul(u64::from(fps));
    if rate > limits.max_stream_bytes_per_sec as u64 {
        let detail = format!(
            "{fps} frames/s of up to {frame_bytes} bytes is {rate} bytes/s; the limit (max_stream_bytes_per_sec, \
             --max-stream-bytes-per-sec) is {}",
            limits.max_stream_bytes_per_sec
        );
        return Err(unprocessable("stream_rate_too_high", Field::Fps, at, detail));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use glam::{Mat4, Vec3, Vec4};
    use prost::Message;

    use super::*;
    use anim::{
        Channel, ClipSpec, EventSpec, Interpolation, Keys, ParameterSpec, Playback, SampleOptions, Sampler, TrackSpec,
    };
    use formats::wire::json::{Extras, MatricesJson, ParameterValues, PoseJson};
    use formats::wire::proto::{add_parameters, matrices_to_pb, pb, pose_to_pb};

    const ID: &str = "0192f3a4-5b6c-7d8e-9f01-23456789abcd";

    /// A clip of `joints` joints named by `name`, whose values print as
    /// `digits`-long floats or as short ones.
    fn clip(joints: usize, name: impl Fn(usize) -> String, long_floats: bool) -> Clip {
        let (a, b) = if long_floats { (-1.234_567_9e-30, 9.876_543e21) } else { (0.0, 1.0) };
        let tracks = (0..joints)
            .flat_map(|j| {
                let n = name(j);
                let v3 = Keys::Vec3(vec![Vec3::splat(a), Vec3::new(b, a, b)]);
                let q = Keys::Vec4(vec![Vec4::new(0.0, 0.0, 0.0, 1.0), Vec4::new(0.123_456_79, 0.0, 0.0, 0.992_35)]);
                [
                    TrackSpec::new(&n, Channel::Translation, Interpolation::Linear, vec![0.0, 1.0], v3.clone()),
                    TrackSpec::new(&n, Channel::Rotation, Interpolation::Linear, vec![0.0, 1.0], q),
                    TrackSpec::new(&n, Channel::Scale, Interpolation::Linear, vec![0.0, 1.0], v3),
                ]
            })
            .collect();
        let events = vec![EventSpec { time: 0.5, name: "step \"left\"".into() }];
        // Parameters (docs/clip-format.md §3) of widths 1, 7 and 256, named like the joints.
        let parameters = [1, 7, 256]
            .iter()
            .enumerate()
            .map(|(k, &w)| {
                ParameterSpec::new(&name(k), Interpolation::Linear, vec![0.0, 1.0], vec![vec![a; w], vec![b; w]])
            })
            .collect();
        let spec = ClipSpec {
            name: "c".into(),
            skeleton: None,
            tracks,
            events,
            parameters,
            playback: Playback::Loop,
            ..Default::default()
        };
        Clip::build(&spec).unwrap()
    }

    /// The bytes really written for `times` as a REST batch and as a gRPC
    /// `PoseBatch`.
    fn written(clip: &Clip, format: Format, times: &[f64]) -> (u64, u64) {
        let (mut sampler, mut matrices) = (Sampler::new(), Vec::<Mat4>::new());
        let options = SampleOptions::default();
        let mut json = b"{\"poses\":[".to_vec();
        let mut batch = pb::PoseBatch {
            joint_names: clip.skeleton().names().to_vec(),
            parameter_names: clip.parameters().names().to_vec(),
            parameter_widths: clip.parameters().widths().to_vec(),
            poses: Vec::new(),
        };
        for (k, &t) in times.iter().enumerate() {
            if k > 0 {
                json.push(b',');
            }
            let clip_time = crate::request::evaluate(clip, t, &options, format, &mut sampler, &mut matrices);
            let parameters = ParameterValues::of(clip.parameters(), sampler.pose(), None);
            let extras = Extras { parameters, ..Extras::default() };
            if format == Format::Trs {
                let (skeleton, pose) = (clip.skeleton(), sampler.pose());
                PoseJson { clip: ID, time: t, clip_time, space: options.space, skeleton, pose }
                    .write_with(&mut json, extras);
                let mut pose = pose_to_pb(None, pose, t, clip_time, options.space);
                add_parameters(&mut pose, parameters, false);
                batch.poses.push(pose);
            } else {
                let doc = MatricesJson {
                    clip: ID,
                    time: t,
                    clip_time,
                    format: "skinning",
                    skeleton: clip.skeleton(),
                    matrices: &matrices,
                };
                doc.write_with(&mut json, extras);
                let mut pose = matrices_to_pb(None, &matrices, t, clip_time);
                add_parameters(&mut pose, parameters, false);
                batch.poses.push(pose);
            }
        }
        json.extend_from_slice(b"]}");
        (json.len() as u64, batch.encoded_len() as u64)
    }

    /// Every estimate bounds the real size, and within a small factor.
    #[test]
    fn the_estimate_bounds_the_written_answer_within_a_small_factor() {
        let times: Vec<f64> = (0..40).map(|k| -1e9 + f64::from(k) * 0.123_456_789_012_345).collect();
        let names: [(&str, &dyn Fn(usize) -> String); 3] = [
            ("short names", &|j| format!("j{j}")),
            ("names needing escapes", &|j| format!("\"\u{1}\\\t{j}")),
            ("256-character names", &|j| format!("{j:0>256}")),
        ];
        for (what, name) in names {
            for long_floats in [false, true] {
                let clip = clip(24, name, long_floats);
                for format in [Format::Trs, Format::Matrix] {
                    let (json, proto) = written(&clip, format, &times);
                    let n = times.len() as u64;
                    let json_bound = Estimate::batch(&clip, ID, format, Wire::Json).total(n);
                    let proto_bound = Estimate::batch(&clip, ID, format, Wire::Protobuf).total(n);
                    let case = format!("{what}, long floats {long_floats}, {format:?}");
                    assert!(json <= json_bound, "{case}: JSON {json} over its bound {json_bound}");
                    assert!(proto <= proto_bound, "{case}: protobuf {proto} over its bound {proto_bound}");
                    assert!(json_bound <= 4 * json, "{case}: JSON bound {json_bound} is over 4 × {json}");
                    assert!(proto_bound <= 2 * proto, "{case}: protobuf bound {proto_bound} is over 2 × {proto}");
                }
            }
        }
    }

    /// A frame's estimate bounds a real first frame (names, every event).
    #[test]
    fn the_frame_estimate_bounds_a_first_frame() {
        use crate::stream::{FrameData, FrameEncoder};
        let clip = clip(24, |j| format!("\"{j:0>200}"), true);
        let mut sampler = Sampler::new();
        let clip_time = clip.sample(0.75, &SampleOptions::default(), &mut sampler);
        for encoding in [Encoding::Json, Encoding::Protobuf] {
            let frame = FrameData {
                seq: u64::MAX,
                dropped: u64::MAX,
                sent_at_unix_nanos: i64::MIN,
                clip_id: ID,
                time: -1e300,
                clip_time,
                space: anim::Space::Local,
                skeleton: clip.skeleton(),
                pose: sampler.pose(),
                joints: None,
                parameters: formats::wire::json::ParameterValues::of(clip.parameters(), sampler.pose(), None),
                root_motion: None,
                ik: &[],
                feet: &[],
                events: clip.events(),
                crossed: &[0; MAX_EVENTS_PER_FRAME],
                with_names: true,
                graph: None,
            };
            let bytes = FrameEncoder::new(encoding).encode(&frame).bytes.len() as u64;
            let bound = Estimate::frame(&clip, ID, encoding.into());
            assert!(bytes <= bound && bound <= 4 * bytes, "{encoding:?}: {bytes} written, bound {bound}");
        }
    }

    /// The compact bound holds a key frame and a delta frame of a pose at the
    /// ends of its ranges' quantisation, each with the most events a frame
    /// carries and a root motion report.
    #[test]
    fn the_compact_bound_holds_a_key_and_a_delta_frame_with_both_sections() {
        use crate::stream::{CompactLayout, FrameData, FrameEncoder};
        use anim::motion::{Planar, RootMotion};
        let clip = clip(24, |j| format!("j{j}"), true);
        let layout = CompactLayout::of_clip(&clip, anim::compact::MIN_MAX_ERROR, None, 30);
        let mut encoder = FrameEncoder::compact(&layout);
        let mut sampler = Sampler::new();
        let last = (clip.events().len() - 1) as u32;
        let planar = Planar { translation: glam::DVec3::splat(1e30), yaw: -1e30 };
        let mut written = 0;
        for (seq, t) in [(u64::MAX - 1, 0.0), (u64::MAX, 0.75)] {
            let clip_time = clip.sample(t, &SampleOptions::default(), &mut sampler);
            let frame = FrameData {
                seq,
                dropped: u64::MAX,
                sent_at_unix_nanos: i64::MIN,
                clip_id: ID,
                time: t,
                clip_time,
                space: anim::Space::Local,
                skeleton: clip.skeleton(),
                pose: sampler.pose(),
                joints: None,
                parameters: None,
                root_motion: Some(RootMotion { delta: planar, total: planar }),
                ik: &[],
                feet: &[],
                events: clip.events(),
                crossed: &[last; MAX_EVENTS_PER_FRAME],
                with_names: true,
                graph: None,
            };
            written += encoder.encode(&frame).bytes.len() as u64;
        }
        let bound = compact_frame(clip.joint_count(), clip.events().len());
        assert!(written <= bound && bound <= 4 * written, "{written} written, bound {bound}");
    }

    /// The IK reports' bound holds the widest reports really written, on
    /// both wires, and is exact for protobuf's widest.
    #[test]
    fn ik_report_bounds_hold_the_widest_reports() {
        use anim::ik::{IkKind, IkReport};
        let report =
            |converged| IkReport { kind: IkKind::TwoBone, residual: -1.175_494_4e-38, iterations: u32::MAX, converged };
        for n in [1, 2, 32] {
            // JSON's widest says `false`, protobuf's `true` (proto3 omits false).
            let mut json = Vec::new();
            formats::wire::ik::write_reports(&mut json, &vec![report(false); n]);
            let bound = ik_reports(n as u64, Wire::Json);
            assert!(json.len() as u64 <= bound, "{n} JSON reports: {} bytes over {bound}", json.len());
            let pose = pose_to_pb(None, &anim::Pose::default(), 1.0, 1.0, anim::Space::Local);
            let with = pb::Pose { ik: formats::wire::proto::ik_reports_to_pb(&vec![report(true); n]), ..pose.clone() };
            let proto = (with.encoded_len() - pose.encoded_len()) as u64;
            assert_eq!(proto, ik_reports(n as u64, Wire::Protobuf), "{n} protobuf reports");
        }
        assert_eq!(ik_reports(0, Wire::Json), 0);
        assert_eq!(ik_reports(0, Wire::Protobuf), 0);
    }

    #[test]
    fn json_strings_are_measured_as_serde_escapes_them() {
        for s in ["", "plain", "q\"b\\", "\u{0}\u{1f}\n\t\r\u{8}\u{c}", "ünï ∑"] {
            assert_eq!(json_str(s), serde_json::to_string(s).unwrap().len() as u64, "{s:?}");
        }
    }
}
