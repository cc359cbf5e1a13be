//! Frame encodings: JSON text and protobuf `Frame` bytes (docs/api.md), written
//! straight from the core's pose buffers into one reusable buffer.
//!
//! A playback encodes each tick once for all its viewers. Two things differ
//! per viewer and are patched in only when they differ, which is rare: the
//! `dropped` count (a viewer whose buffer overflowed missed frames the
//! playback sent) and, for protobuf, the joint names a viewer must see in
//! its first frame. Protobuf makes the patch an append: a singular field
//! repeated later in a message overrides the earlier value, and a repeated
//! embedded message field merges, so `shared bytes + [dropped] + [pose with
//! joint names]` decodes as the patched frame in every conforming decoder.
//! JSON records where its `dropped` number sits and splices a new one in,
//! and so do compact frames (docs/compact-frames.md) their `dropped` varint.
//! A compact delta frame carries its key frame along, for a viewer that
//! missed it.

use std::io::Write;
use std::sync::Arc;

use bytes::{BufMut, Bytes, BytesMut};
use prost::encoding::{WireType, encode_key, encode_varint, encoded_len_varint, key_len};

use anim::character::FootReport;
use anim::ik::IkReport;
use anim::motion::{Planar, RootMotion};
use anim::{Event, Pose, Skeleton, Space};
use formats::wire::compact::{CompactEncoder, GraphFrame, Header, KEY_FRAME, RootMotionReport, Trailer};
use formats::wire::graph_inputs::write_report;
use formats::wire::json::{Extras, ParameterValues, PoseJson};
use formats::wire::proto::{ik_kind_to_pb, space_to_pb};
use formats::wire::proto_graph::report_to_proto;
use prost::Message;

use super::compact::CompactLayout;
use super::pinned::PinnedClip;
use anim::graph::GraphReport;

/// How frames travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Encoding {
    /// `{"seq","clip_time","sent_at_unix_nanos","dropped","events","pose"}`.
    #[default]
    Json,
    /// An encoded `inbetween.v1.Frame`.
    Protobuf,
    /// A compact frame (docs/compact-frames.md) of the stream's layout.
    Compact,
}

/// The names a stream's first protobuf frame carries (its joints', and its
/// parameters' with their widths), once per viewer.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Names {
    pub joints: Vec<String>,
    pub parameters: Vec<String>,
    pub widths: Vec<u32>,
}

/// Everything one frame says.
pub struct FrameData<'a> {
    pub seq: u64,
    pub dropped: u64,
    pub sent_at_unix_nanos: i64,
    pub clip_id: &'a str,
    /// The request time shown.
    pub time: f64,
    pub clip_time: f32,
    pub space: Space,
    pub skeleton: &'a Skeleton,
    pub pose: &'a Pose,
    /// The joints to send (skeleton order); `None`: all.
    pub joints: Option<&'a [usize]>,
    /// The parameters (docs/clip-format.md §3) to send, when the motion has any.
    pub parameters: Option<ParameterValues<'a>>,
    /// The frame's root motion, for motions that report it.
    pub root_motion: Option<RootMotion>,
    /// IK reports (docs/ik.md): the motion's clip constraints, then the stream's.
    pub ik: &'a [IkReport],
    /// Planted feet (docs/characters.md, “Planted feet”): JSON frames carry them.
    pub feet: &'a [FootReport],
    /// Events crossed (all of the clip's events, and indices into them).
    pub events: &'a [Event],
    pub crossed: &'a [u32],
    /// Protobuf only: put the joint names in this frame.
    pub with_names: bool,
    /// A graph stream's report of this tick, when it asked for reports
    /// (JSON: the frame's `graph` member; protobuf: `Pose.graph`).
    pub graph: Option<GraphReport<'a, Arc<dyn PinnedClip>>>,
}

/// One encoded frame, shared by every viewer of its playback.
#[derive(Debug, Clone, PartialEq)]
pub struct Encoded {
    pub seq: u64,
    pub dropped: u64,
    pub clip_time: f32,
    pub encoding: Encoding,
    pub bytes: Bytes,
    /// Whether the joint names are in it (protobuf).
    pub has_names: bool,
    /// JSON and compact: the byte range of the `dropped` number.
    dropped_at: (u32, u32),
    /// Compact: the `seq` of the key frame this frame is relative to (its
    /// own for a key frame).
    pub key_seq: Option<u64>,
    /// Compact delta frames: that key frame, for a viewer that missed it.
    pub key: Option<Arc<Encoded>>,
    /// Compact: the document of the layout it is encoded in, which a viewer
    /// that has not had it is sent first (docs/compact-frames.md).
    pub layout: Option<Arc<str>>,
}

/// A reusable encoder: the buffer's storage is recycled once viewers drop
/// their copies, so steady state allocates nothing beyond the bytes sent.
#[derive(Debug, Default)]
pub struct FrameEncoder {
    encoding: Encoding,
    buf: BytesMut,
    compact: Option<Compact>,
}

/// A compact stream's encoder, its layout's document and its last key frame.
#[derive(Debug)]
struct Compact {
    encoder: CompactEncoder,
    document: Arc<str>,
    key: Option<Arc<Encoded>>,
}

impl Compact {
    /// A new encoder of `layout`: its first frame is a key frame.
    fn of(layout: &CompactLayout) -> Compact {
        let encoder = CompactEncoder::new(layout.layout.clone(), layout.key_interval);
        Compact { encoder, document: Arc::clone(&layout.document), key: None }
    }
}

impl FrameEncoder {
    /// A JSON or protobuf encoder (compact frames need a layout: [`FrameEncoder::compact`]).
    pub fn new(encoding: Encoding) -> Self {
        FrameEncoder { encoding, buf: BytesMut::new(), compact: None }
    }

    /// A compact encoder of `layout`.
    pub fn compact(layout: &CompactLayout) -> Self {
        let compact = Compact::of(layout);
        FrameEncoder { encoding: Encoding::Compact, buf: BytesMut::new(), compact: Some(compact) }
    }

    /// Encodes in `layout` from the next frame on, a key frame
    /// (docs/compact-frames.md, "A new layout"); a no-op for JSON and protobuf.
    pub fn relayout(&mut self, layout: &CompactLayout) {
        if let Some(compact) = self.compact.as_mut() {
            *compact = Compact::of(layout);
        }
    }

    pub fn encode(&mut self, f: &FrameData<'_>) -> Encoded {
        let dropped_at = match self.encoding {
            Encoding::Json => write_json(&mut self.buf, f),
            Encoding::Protobuf => {
                write_protobuf(&mut self.buf, f);
                (0, 0)
            }
            Encoding::Compact => return self.encode_compact(f),
        };
        Encoded {
            seq: f.seq,
            dropped: f.dropped,
            clip_time: f.clip_time,
            encoding: self.encoding,
            bytes: self.buf.split().freeze(),
            has_names: f.with_names || self.encoding == Encoding::Json,
            dropped_at,
            key_seq: None,
            key: None,
            layout: None,
        }
    }

    /// A key or delta frame of the whole local pose; a key frame is kept
    /// for the delta frames after it.
    fn encode_compact(&mut self, f: &FrameData<'_>) -> Encoded {
        let compact = self.compact.as_mut().expect("a compact encoder has its layout");
        let header =
            Header { seq: f.seq, dropped: f.dropped, sent_at_unix_nanos: f.sent_at_unix_nanos, clip_time: f.clip_time };
        let graph = f.graph.as_ref().map(GraphFrame::of_report);
        let root_motion = f.root_motion.as_ref().map(compact_root_motion);
        let trailer = Trailer { events: f.crossed, root_motion, graph: graph.as_ref() };
        let frame = compact.encoder.encode_with(&header, f.pose, false, &trailer);
        let is_key = frame[0] & KEY_FRAME != 0;
        self.buf.extend_from_slice(frame);
        let key_seq = if is_key { f.seq } else { compact.key.as_ref().map_or(f.seq, |k| k.seq) };
        let encoded = Encoded {
            seq: f.seq,
            dropped: f.dropped,
            clip_time: f.clip_time,
            encoding: Encoding::Compact,
            bytes: self.buf.split().freeze(),
            has_names: true,
            dropped_at: compact_dropped_at(f.seq, f.dropped),
            key_seq: Some(key_seq),
            key: if is_key { None } else { compact.key.clone() },
            layout: Some(Arc::clone(&compact.document)),
        };
        if is_key {
            compact.key = Some(Arc::new(encoded.clone()));
        }
        encoded
    }
}

/// A root motion report as a compact frame carries it: the f64s of the
/// JSON and protobuf frames, rounded to f32.
fn compact_root_motion(r: &RootMotion) -> RootMotionReport {
    let planar = |p: &Planar| {
        let [x, y, z] = p.translation.to_array();
        [x, y, z, p.yaw].map(|v| v as f32)
    };
    RootMotionReport { delta: planar(&r.delta), total: planar(&r.total) }
}

/// Where a compact frame's `dropped` varint sits: after the flags byte and
/// the `seq` varint.
fn compact_dropped_at(seq: u64, dropped: u64) -> (u32, u32) {
    let a = 1 + encoded_len_varint(seq) as u32;
    (a, a + encoded_len_varint(dropped) as u32)
}

impl Encoded {
    /// These bytes as one viewer must see them: with its own `dropped`
    /// count, and (protobuf) with `names` added if it has not had them yet.
    /// Copies only when something differs.
    pub fn for_viewer(&self, dropped: u64, names: Option<&Names>) -> Bytes {
        let names = names.filter(|_| !self.has_names && self.encoding == Encoding::Protobuf);
        if dropped == self.dropped && names.is_none() {
            return self.bytes.clone();
        }
        let mut out = BytesMut::with_capacity(self.bytes.len() + 32);
        match self.encoding {
            Encoding::Json => {
                let (a, b) = (self.dropped_at.0 as usize, self.dropped_at.1 as usize);
                out.put_slice(&self.bytes[..a]);
                write!((&mut out).writer(), "{dropped}").expect("writing to memory");
                out.put_slice(&self.bytes[b..]);
            }
            Encoding::Compact => {
                let (a, b) = (self.dropped_at.0 as usize, self.dropped_at.1 as usize);
                out.put_slice(&self.bytes[..a]);
                encode_varint(dropped, &mut out);
                out.put_slice(&self.bytes[b..]);
            }
            Encoding::Protobuf => {
                out.put_slice(&self.bytes);
                if dropped != self.dropped {
                    encode_key(4, WireType::Varint, &mut out);
                    encode_varint(dropped, &mut out);
                }
                if let Some(names) = names {
                    let widths = widths_len(names.widths.iter().copied());
                    let len = names_len(1, names.joints.iter()) + names_len(11, names.parameters.iter()) + widths;
                    encode_key(6, WireType::LengthDelimited, &mut out);
                    encode_varint(len as u64, &mut out);
                    put_names(1, names.joints.iter(), &mut out);
                    put_names(11, names.parameters.iter(), &mut out);
                    put_widths(names.widths.iter().copied(), &mut out);
                }
            }
        }
        out.freeze()
    }
}

fn write_json(buf: &mut BytesMut, f: &FrameData<'_>) -> (u32, u32) {
    #[derive(serde::Serialize)]
    struct EventJson<'a> {
        time: f32,
        name: &'a str,
    }
    buf.reserve(256 + f.pose.len() * 160);
    let mut w = buf.writer();
    let io = "writing to memory";
    write!(w, "{{\"seq\":{},\"clip_time\":", f.seq).expect(io);
    serde_json::to_writer(&mut w, &f.clip_time).expect(io);
    write!(w, ",\"sent_at_unix_nanos\":{},\"dropped\":", f.sent_at_unix_nanos).expect(io);
    let a = w.get_ref().len() as u32;
    write!(w, "{}", f.dropped).expect(io);
    let b = w.get_ref().len() as u32;
    w.write_all(b",\"events\":[").expect(io);
    for (i, &e) in f.crossed.iter().enumerate() {
        if i > 0 {
            w.write_all(b",").expect(io);
        }
        let e = &f.events[e as usize];
        serde_json::to_writer(&mut w, &EventJson { time: e.time, name: &e.name }).expect(io);
    }
    w.write_all(b"],\"pose\":").expect(io);
    let pose = PoseJson {
        clip: f.clip_id,
        time: f.time,
        clip_time: f.clip_time,
        space: f.space,
        skeleton: f.skeleton,
        pose: f.pose,
    };
    let (joints, root_motion, ik, parameters) = (f.joints, f.root_motion, f.ik, f.parameters);
    let extras = Extras { joints, root_motion, ik, parameters, tail: &[], feet: f.feet };
    pose.write_with(*w.get_mut(), extras);
    if let Some(report) = &f.graph {
        write_report(*w.get_mut(), report);
    }
    w.write_all(b"}").expect(io);
    (a, b)
}

fn len_field(tag: u32, len: usize) -> usize {
    key_len(tag) + encoded_len_varint(len as u64) + len
}

fn names_len<'a>(tag: u32, names: impl Iterator<Item = &'a String>) -> usize {
    names.map(|n| len_field(tag, n.len())).sum()
}

fn put_names<'a>(tag: u32, names: impl Iterator<Item = &'a String>, buf: &mut BytesMut) {
    for n in names {
        encode_key(tag, WireType::LengthDelimited, buf);
        encode_varint(n.len() as u64, buf);
        buf.put_slice(n.as_bytes());
    }
}

/// The bytes of `Pose.parameter_widths` (field 12, packed varints); none
/// when there are no widths.
fn widths_len(widths: impl Iterator<Item = u32>) -> usize {
    let body: usize = widths.map(|w| encoded_len_varint(u64::from(w))).sum();
    if body == 0 { 0 } else { len_field(12, body) }
}

fn put_widths(widths: impl Iterator<Item = u32> + Clone, buf: &mut BytesMut) {
    let body: usize = widths.clone().map(|w| encoded_len_varint(u64::from(w))).sum();
    if body == 0 {
        return;
    }
    encode_key(12, WireType::LengthDelimited, buf);
    encode_varint(body as u64, buf);
    for w in widths {
        encode_varint(u64::from(w), buf);
    }
}

/// The values of a frame's parameters, packed (field 13), and their count.
fn parameter_floats(p: &ParameterValues<'_>) -> usize {
    p.indices().map(|k| p.layout.widths()[k] as usize).sum()
}

/// A packed `repeated float` of `n` joints × `width` components.
fn put_packed(tag: u32, n: usize, width: usize, values: impl Iterator<Item = f32>, buf: &mut BytesMut) {
    if n == 0 {
        return;
    }
    encode_key(tag, WireType::LengthDelimited, buf);
    encode_varint((n * width * 4) as u64, buf);
    buf.reserve(n * width * 4);
    // Gathered on the stack and appended a chunk at a time: `put_f32_le`
    // per value is a `memcpy` call of 4 bytes (`put_slice` is not inlined).
    let mut chunk = [0u8; 256];
    let mut len = 0;
    for v in values {
        chunk[len..len + 4].copy_from_slice(&v.to_le_bytes());
        len += 4;
        if len == chunk.len() {
            buf.put_slice(&chunk);
            len = 0;
        }
    }
    buf.put_slice(&chunk[..len]);
}

/// The frame's joints: the subset, or all of them.
fn joints<'a>(f: &'a FrameData<'_>) -> impl Iterator<Item = usize> + Clone + 'a {
    let (all, some) = match f.joints {
        Some(joints) => (0..0, joints.iter()),
        None => (0..f.pose.len(), [].iter()),
    };
    all.chain(some.copied())
}

/// `inbetween.v1.Planar` (x, y, z, yaw as doubles; zeros omitted as proto3 does).
fn planar_len(p: &Planar) -> usize {
    let [x, y, z] = p.translation.to_array();
    [x, y, z, p.yaw].iter().filter(|v| **v != 0.0).count() * 9
}

fn put_planar(tag: u32, p: &Planar, buf: &mut BytesMut) {
    encode_key(tag, WireType::LengthDelimited, buf);
    encode_varint(planar_len(p) as u64, buf);
    let [x, y, z] = p.translation.to_array();
    for (field, v) in [(1, x), (2, y), (3, z), (4, p.yaw)] {
        if v != 0.0 {
            encode_key(field, WireType::SixtyFourBit, buf);
            buf.put_f64_le(v);
        }
    }
}

fn root_motion_len(r: &RootMotion) -> usize {
    len_field(1, planar_len(&r.delta)) + len_field(2, planar_len(&r.total))
}

/// `inbetween.v1.IkReport` (kind, residual, iterations, converged; zeros
/// omitted as proto3 does, so the length is prost's to the byte).
fn report_len(r: &IkReport) -> usize {
    let kind = key_len(1) + encoded_len_varint(ik_kind_to_pb(r.kind) as u64);
    let residual = if r.residual == 0.0 { 0 } else { key_len(2) + 4 };
    let iterations = if r.iterations == 0 { 0 } else { key_len(3) + encoded_len_varint(u64::from(r.iterations)) };
    kind + residual + iterations + if r.converged { key_len(4) + 1 } else { 0 }
}

fn put_report(tag: u32, r: &IkReport, buf: &mut BytesMut) {
    encode_key(tag, WireType::LengthDelimited, buf);
    encode_varint(report_len(r) as u64, buf);
    encode_key(1, WireType::Varint, buf);
    encode_varint(ik_kind_to_pb(r.kind) as u64, buf);
    if r.residual != 0.0 {
        encode_key(2, WireType::ThirtyTwoBit, buf);
        buf.put_f32_le(r.residual);
    }
    if r.iterations != 0 {
        encode_key(3, WireType::Varint, buf);
        encode_varint(u64::from(r.iterations), buf);
    }
    if r.converged {
        encode_key(4, WireType::Varint, buf);
        buf.put_u8(1);
    }
}

fn write_protobuf(buf: &mut BytesMut, f: &FrameData<'_>) {
    let n = f.joints.map_or(f.pose.len(), <[usize]>::len);
    let packed = |width: usize| if n == 0 { 0 } else { len_field(2, n * width * 4) };
    let all_names = f.skeleton.names();
    let names = if f.with_names { names_len(1, joints(f).map(|j| &all_names[j])) } else { 0 };
    let parameters = f.parameters.as_ref();
    let floats = parameters.map_or(0, parameter_floats);
    let parameter_names = match parameters.filter(|_| f.with_names) {
        Some(p) => {
            let widths = widths_len(p.indices().map(|k| p.layout.widths()[k]));
            names_len(11, p.indices().map(|k| &p.layout.names()[k])) + widths
        }
        None => 0,
    };
    let names = names + parameter_names + if floats == 0 { 0 } else { len_field(13, 4 * floats) };
    let space = space_to_pb(f.space) as u64;
    let root = f.root_motion.as_ref().map_or(0, |r| len_field(9, root_motion_len(r)));
    let ik: usize = f.ik.iter().map(|r| len_field(10, report_len(r))).sum();
    let graph = f.graph.as_ref().map(report_to_proto);
    let graph_len = graph.as_ref().map_or(0, |g| len_field(14, g.encoded_len()));
    let pose_len = names
        + 2 * packed(3)
        + packed(4)
        + (key_len(5) + 8)
        + (key_len(6) + 4)
        + key_len(8)
        + 1
        + root
        + ik
        + graph_len;
    let event_len = |e: &Event| (key_len(1) + 4) + len_field(2, e.name.len());
    let events: usize = f.crossed.iter().map(|&i| len_field(5, event_len(&f.events[i as usize]))).sum();
    buf.reserve(40 + events + len_field(6, pose_len));

    encode_key(1, WireType::Varint, buf);
    encode_varint(f.seq, buf);
    encode_key(2, WireType::ThirtyTwoBit, buf);
    buf.put_f32_le(f.clip_time);
    encode_key(3, WireType::Varint, buf);
    encode_varint(f.sent_at_unix_nanos as u64, buf);
    encode_key(4, WireType::Varint, buf);
    encode_varint(f.dropped, buf);
    for &i in f.crossed {
        let e = &f.events[i as usize];
        encode_key(5, WireType::LengthDelimited, buf);
        encode_varint(event_len(e) as u64, buf);
        encode_key(1, WireType::ThirtyTwoBit, buf);
        buf.put_f32_le(e.time);
        encode_key(2, WireType::LengthDelimited, buf);
        encode_varint(e.name.len() as u64, buf);
        buf.put_slice(e.name.as_bytes());
    }
    encode_key(6, WireType::LengthDelimited, buf);
    encode_varint(pose_len as u64, buf);
    if f.with_names {
        put_names(1, joints(f).map(|j| &all_names[j]), buf);
    }
    let p = f.pose;
    put_packed(2, n, 3, joints(f).flat_map(|j| p.translations[j].to_array()), buf);
    put_packed(3, n, 4, joints(f).flat_map(|j| p.rotations[j].to_array()), buf);
    put_packed(4, n, 3, joints(f).flat_map(|j| p.scales[j].to_array()), buf);
    encode_key(5, WireType::SixtyFourBit, buf);
    buf.put_f64_le(f.time);
    encode_key(6, WireType::ThirtyTwoBit, buf);
    buf.put_f32_le(f.clip_time);
    encode_key(8, WireType::Varint, buf);
    encode_varint(space, buf);
    if let Some(r) = &f.root_motion {
        encode_key(9, WireType::LengthDelimited, buf);
        encode_varint(root_motion_len(r) as u64, buf);
        put_planar(1, &r.delta, buf);
        put_planar(2, &r.total, buf);
    }
    for r in f.ik {
        put_report(10, r, buf);
    }
    if let Some(p) = parameters {
        if f.with_names {
            put_names(11, p.indices().map(|k| &p.layout.names()[k]), buf);
            put_widths(p.indices().map(|k| p.layout.widths()[k]), buf);
        }
        if floats > 0 {
            encode_key(13, WireType::LengthDelimited, buf);
            encode_varint((4 * floats) as u64, buf);
            for k in p.indices() {
                for c in 0..p.layout.widths()[k] as usize {
                    buf.put_f32_le(p.value(k, c));
                }
            }
        }
    }
    if let Some(g) = graph {
        encode_key(14, WireType::LengthDelimited, buf);
        encode_varint(g.encoded_len() as u64, buf);
        g.encode_raw(buf);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anim::ik::IkKind;
    use anim::{Clip, Interpolation, ParameterSpec, SampleOptions, Sampler};
    use formats::wire::json::parse_clip;
    use formats::wire::proto::{add_parameters, pb, pose_to_pb};
    use prost::Message;

    /// The example wave with two parameters (docs/clip-format.md §3): widths 4 (two
    /// entries, one padded) and 1, so frames carry names, widths and values.
    fn wave() -> Clip {
        let body = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/wave.json")).unwrap();
        let mut spec = parse_clip(&body).unwrap().1;
        let rows = |rows: &[&[f32]]| rows.iter().map(|r| r.to_vec()).collect::<Vec<_>>();
        let (times, curve) = (vec![0.0, 1.5, 3.0], Interpolation::CatmullRom);
        let mouth = rows(&[&[0.0, 1.0, -2.0, 0.5], &[1.0, 0.25, 3.0, 1e-7], &[0.0, 1.0, -2.0, 0.5]]);
        spec.parameters.push(ParameterSpec::new("mouth", curve, times.clone(), mouth));
        spec.parameters.push(ParameterSpec::new(
            "fov",
            Interpolation::Linear,
            times,
            rows(&[&[40.0], &[60.0], &[45.0]]),
        ));
        Clip::build(&spec).unwrap()
    }

    /// IK reports of every kind, with the zeros proto3 leaves out and the
    /// widest varint.
    const REPORTS: [IkReport; 4] = [
        IkReport { kind: IkKind::TwoBone, residual: 1.5e-6, iterations: 0, converged: true },
        IkReport { kind: IkKind::Aim, residual: 0.0, iterations: 0, converged: false },
        IkReport { kind: IkKind::Chain, residual: 3.25, iterations: u32::MAX, converged: false },
        IkReport { kind: IkKind::Chain, residual: -0.0, iterations: 100, converged: true },
    ];

    /// Encodes a frame of `clip` at request time `t` with every event
    /// crossed and `ik` reports, and returns the encoded frame and the
    /// expected proto frame built independently through the generated types.
    fn check(
        encoding: Encoding,
        (t, space): (f64, Space),
        with_names: bool,
        dropped: u64,
        ik: &[IkReport],
    ) -> (Encoded, pb::Frame) {
        let clip = wave();
        let mut sampler = Sampler::new();
        let clip_time = clip.sample(t, &SampleOptions { space, ..Default::default() }, &mut sampler);
        let crossed = [0u32];
        let data = FrameData {
            seq: 7,
            dropped,
            sent_at_unix_nanos: 1_700_000_000_123_456_789,
            clip_id: "c1",
            time: t,
            clip_time,
            space,
            skeleton: clip.skeleton(),
            pose: sampler.pose(),
            joints: None,
            parameters: ParameterValues::of(clip.parameters(), sampler.pose(), None),
            root_motion: None,
            ik,
            feet: &[],
            events: clip.events(),
            crossed: &crossed,
            with_names,
            graph: None,
        };
        let encoded = FrameEncoder::new(encoding).encode(&data);
        let names = with_names.then(|| clip.skeleton().names());
        let mut pose = pose_to_pb(names, sampler.pose(), t, clip_time, space);
        pose.ik = ik
            .iter()
            .map(|r| pb::IkReport {
                kind: match r.kind {
                    IkKind::TwoBone => pb::IkKind::TwoBone,
                    IkKind::Aim => pb::IkKind::Aim,
                    IkKind::Chain => pb::IkKind::Chain,
                } as i32,
                residual: r.residual,
                iterations: r.iterations,
                converged: r.converged,
            })
            .collect();
        add_parameters(&mut pose, ParameterValues::of(clip.parameters(), sampler.pose(), None), with_names);
        let expected = pb::Frame {
            seq: 7,
            clip_time,
            sent_at_unix_nanos: 1_700_000_000_123_456_789,
            dropped,
            events: vec![pb::Event { time: 1.0, name: "footstep".into() }],
            pose: Some(pose),
            ..Default::default()
        };
        (encoded, expected)
    }

    #[test]
    fn protobuf_frames_decode_to_the_generated_frame() {
        let cases = [
            (1.25, Space::Local, true, &[][..]),
            (0.4, Space::Model, false, &REPORTS[..1]),
            (2.5, Space::Model, true, &REPORTS[..]),
        ];
        for (t, space, names, ik) in cases {
            let (encoded, expected) = check(Encoding::Protobuf, (t, space), names, 3, ik);
            assert_eq!(pb::Frame::decode(encoded.bytes.clone()).unwrap(), expected);
            assert_eq!(encoded.bytes.len(), expected.encoded_len(), "{} reports", ik.len());
        }
    }

    #[test]
    fn packed_floats_are_the_values_in_order_across_chunks() {
        for n in [1, 63, 64, 65, 200] {
            let values: Vec<f32> = (0..n).map(|i| i as f32 * 0.37 - 5.0).collect();
            let mut buf = BytesMut::new();
            put_packed(2, n, 1, values.iter().copied(), &mut buf);
            let mut naive = BytesMut::new();
            encode_key(2, WireType::LengthDelimited, &mut naive);
            encode_varint((n * 4) as u64, &mut naive);
            values.iter().for_each(|v| naive.put_f32_le(*v));
            assert_eq!(buf, naive, "{n} values");
        }
    }

    #[test]
    fn a_viewer_patch_overrides_dropped_and_adds_the_names() {
        let (encoded, mut expected) = check(Encoding::Protobuf, (2.0, Space::Local), false, 0, &REPORTS);
        assert_eq!(encoded.for_viewer(0, None), encoded.bytes, "nothing to patch");
        let clip = wave();
        let names = Names {
            joints: clip.skeleton().names().to_vec(),
            parameters: clip.parameters().names().to_vec(),
            widths: clip.parameters().widths().to_vec(),
        };
        assert_eq!(names.widths, [4, 1]);
        let patched = pb::Frame::decode(encoded.for_viewer(5, Some(&names))).unwrap();
        expected.dropped = 5;
        let pose = expected.pose.as_mut().unwrap();
        pose.joint_names = names.joints;
        (pose.parameter_names, pose.parameter_widths) = (names.parameters, names.widths);
        assert_eq!(patched, expected);
    }

    #[test]
    fn json_frames_have_the_spec_shape_and_patch_dropped() {
        let (encoded, expected) = check(Encoding::Json, (1.25, Space::Local), false, 2, &REPORTS[..1]);
        let v: serde_json::Value = serde_json::from_slice(&encoded.bytes).unwrap();
        assert_eq!(v["seq"], 7);
        assert_eq!(v["dropped"], 2);
        assert_eq!(v["sent_at_unix_nanos"], 1_700_000_000_123_456_789i64);
        assert_eq!(v["clip_time"].as_f64().unwrap() as f32, expected.clip_time);
        assert_eq!(v["events"], serde_json::json!([{"time": 1.0, "name": "footstep"}]));
        assert_eq!(v["pose"]["clip"], "c1");
        assert_eq!(v["pose"]["joints"][1]["name"], "arm");
        let rot: Vec<f32> = serde_json::from_value(v["pose"]["joints"][1]["rotation"].clone()).unwrap();
        assert_eq!(rot, expected.pose.as_ref().unwrap().rotations[4..8]);
        let ik = serde_json::json!([{"kind": "two_bone", "residual": 1.5e-6, "iterations": 0, "converged": true}]);
        assert_eq!(v["pose"]["ik"], ik);
        let mouth: Vec<f32> = serde_json::from_value(v["pose"]["parameters"]["mouth"].clone()).unwrap();
        assert_eq!(mouth, expected.pose.as_ref().unwrap().parameters[..4]);
        assert_eq!(v["pose"]["parameters"]["fov"].as_array().unwrap().len(), 1);

        let v: serde_json::Value = serde_json::from_slice(&encoded.for_viewer(12345, None)).unwrap();
        assert_eq!(v["dropped"], 12345);
        assert_eq!(v["seq"], 7);
    }
}
