//! Compact frames (docs/compact-frames.md): a pose quantised to a stated
//! error, as key frames and delta frames, and the layout a stream's
//! `opened` message states once.
//!
//! The widths and the quantisation are the core's ([`anim::compact`]);
//! this module packs them into bits. A frame is a byte-aligned header (a
//! flags byte, LEB128 varints, the clip time as a little-endian f32) and a
//! body of bit fields packed least significant bit first. An encoder and a
//! decoder each keep their buffers across frames, so steady state allocates
//! nothing.

use anim::compact::{Axis, JointLayout, Layout, QuantisedJoint, Rotation, SmallestThree};
use anim::{Event, Pose};
use glam::Quat;
use serde::{Deserialize, Serialize};

/// The version of the layout this module writes (and the only one it reads).
pub const VERSION: u32 = 1;
/// Flags bit 0: a key frame (every joint's values), else a delta frame.
pub const KEY_FRAME: u8 = 1;
/// Flags bit 1: an events section follows the body.
pub const EVENTS: u8 = 2;
/// Flags bit 2: a root motion section follows the body (and the events).
pub const ROOT_MOTION: u8 = 4;
/// Flags bit 3: a graph report section follows (after the root motion).
pub const GRAPH: u8 = 8;
const KNOWN_FLAGS: u8 = KEY_FRAME | EVENTS | ROOT_MOTION | GRAPH;

/// The per-frame values outside the pose.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Header {
    pub seq: u64,
    pub dropped: u64,
    pub sent_at_unix_nanos: i64,
    pub clip_time: f32,
}

/// A frame's root motion report (docs/motion.md): its `delta` and `total`,
/// each `[x, y, z, yaw]` as f32s, in the order the frame sends them.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RootMotionReport {
    pub delta: [f32; 4],
    pub total: [f32; 4],
}

/// A graph stream's report of one tick (docs/graphs.md, “Reports”) by
/// index into the layout's `graph`: the current state, the transition in
/// progress as `(from, to, α)`, and each blend node evaluated with its
/// weights (as many as the node has points), as f32s.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GraphFrame {
    pub state: u32,
    pub transition: Option<(u32, u32, f32)>,
    pub weights: Vec<(u32, Vec<f32>)>,
}

impl GraphFrame {
    /// A tick's report as its section carries it (weights rounded to f32).
    pub fn of_report<C>(report: &anim::graph::GraphReport<'_, C>) -> GraphFrame {
        let (state, transition) = report.indices();
        let index = |i: usize| u32::try_from(i).expect("a graph has fewer than 2³² states and nodes");
        GraphFrame {
            state: index(state),
            transition: transition.map(|(from, to, alpha)| (index(from), index(to), alpha)),
            weights: report.indexed_weights().map(|(b, w)| (index(b), w.iter().map(|&w| w as f32).collect())).collect(),
        }
    }

    fn write(&self, out: &mut Vec<u8>) {
        put_varint(out, u64::from(self.state));
        match self.transition {
            None => put_varint(out, 0),
            Some((from, to, alpha)) => {
                put_varint(out, u64::from(from) + 1);
                put_varint(out, u64::from(to));
                out.extend_from_slice(&alpha.to_le_bytes());
            }
        }
        put_varint(out, self.weights.len() as u64);
        for (node, weights) in &self.weights {
            put_varint(out, u64::from(*node));
            weights.iter().for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
        }
    }

    /// The section at `at`, its indices checked against `graph`.
    fn read(bytes: &[u8], at: &mut usize, graph: &GraphDoc, out: &mut GraphFrame) -> Result<(), CompactError> {
        let states = graph.states.len();
        let state = |v: u64| graph_index(v, states, "state");
        out.state = state(take_varint(bytes, at, "graph report")?)?;
        out.transition = match take_varint(bytes, at, "graph report")? {
            0 => None,
            from => {
                let from = state(from - 1)?;
                let to = state(take_varint(bytes, at, "graph report")?)?;
                Some((from, to, take_f32(bytes, at, "graph report")?))
            }
        };
        let count = take_varint(bytes, at, "graph report")?;
        out.weights.clear();
        for _ in 0..count {
            let node = graph_index(take_varint(bytes, at, "graph report")?, graph.nodes.len(), "node")?;
            let points = graph.nodes[node as usize].points;
            let weights = (0..points).map(|_| take_f32(bytes, at, "graph report")).collect::<Result<_, _>>()?;
            out.weights.push((node, weights));
        }
        Ok(())
    }
}

/// `index` when it is below `count` (a state or blend node of the layout's `graph`).
fn graph_index(index: u64, count: usize, what: &'static str) -> Result<u32, CompactError> {
    match u32::try_from(index) {
        Ok(i) if (i as usize) < count => Ok(i),
        _ => Err(CompactError::UnknownGraphIndex { what, index, count }),
    }
}

/// A little-endian f32 at `at`.
fn take_f32(bytes: &[u8], at: &mut usize, what: &'static str) -> Result<f32, CompactError> {
    let four = bytes.get(*at..*at + 4).ok_or(CompactError::Truncated(what))?;
    *at += 4;
    Ok(f32::from_le_bytes(four.try_into().expect("four bytes")))
}

/// What a frame carries after its pose, each section only when present:
/// the events crossed, as indices into the layout's `events`, the root
/// motion report and a graph stream's report.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Trailer<'a> {
    pub events: &'a [u32],
    pub root_motion: Option<RootMotionReport>,
    pub graph: Option<&'a GraphFrame>,
}

impl Trailer<'_> {
    /// The flag bits of the sections present.
    fn flags(&self) -> u8 {
        let events = if self.events.is_empty() { 0 } else { EVENTS };
        let graph = if self.graph.is_some() { GRAPH } else { 0 };
        events | graph | if self.root_motion.is_some() { ROOT_MOTION } else { 0 }
    }

    fn write(&self, out: &mut Vec<u8>) {
        if !self.events.is_empty() {
            put_varint(out, self.events.len() as u64);
            self.events.iter().for_each(|&i| put_varint(out, u64::from(i)));
        }
        if let Some(r) = &self.root_motion {
            r.delta.iter().chain(&r.total).for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
        }
        if let Some(g) = self.graph {
            g.write(out);
        }
    }
}

/// What a decoded frame said besides its pose (its events: [`CompactDecoder::events`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decoded {
    pub header: Header,
    pub key: bool,
    /// The `seq` of the key frame this frame's values are relative to (its
    /// own for a key frame).
    pub key_seq: u64,
    /// Delta frames: how many joints it carried.
    pub joints_sent: usize,
    pub root_motion: Option<RootMotionReport>,
}

/// Why bytes are not a compact frame of this layout.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CompactError {
    #[error("the frame ends before its {0}")]
    Truncated(&'static str),
    #[error("flags {0:#04x} use bits other than the key-frame, events, root motion and graph bits")]
    UnknownFlags(u8),
    #[error("{0} bytes follow the frame's last field")]
    TrailingBytes(usize),
    #[error("a delta frame refers to key frame {wanted}, and the last key frame seen is {seen:?}")]
    MissingKeyFrame { wanted: u64, seen: Option<u64> },
    #[error("a varint is longer than 64 bits")]
    VarintOverflow,
    #[error("event {index} is not in the layout's {count} events")]
    UnknownEvent { index: u64, count: usize },
    #[error("graph {what} {index} is not in the layout's {count} (or the layout has no `graph`)")]
    UnknownGraphIndex { what: &'static str, index: u64, count: usize },
}

impl CompactError {
    /// A stable code for the error.
    pub fn code(&self) -> &'static str {
        match self {
            CompactError::Truncated(_) => "compact_truncated",
            CompactError::UnknownFlags(_) => "compact_unknown_flags",
            CompactError::TrailingBytes(_) => "compact_trailing_bytes",
            CompactError::MissingKeyFrame { .. } => "compact_missing_key_frame",
            CompactError::VarintOverflow => "compact_varint_overflow",
            CompactError::UnknownEvent { .. } => "compact_unknown_event",
            CompactError::UnknownGraphIndex { .. } => "compact_unknown_graph_index",
        }
    }
}

/// Appends bit fields to a byte buffer, least significant bit first.
struct BitWriter<'a> {
    out: &'a mut Vec<u8>,
    acc: u64,
    filled: u32,
}

impl<'a> BitWriter<'a> {
    fn new(out: &'a mut Vec<u8>) -> Self {
        BitWriter { out, acc: 0, filled: 0 }
    }

    /// The low `bits` bits of `value` (`bits <= 32`).
    fn write(&mut self, value: u32, bits: u8) {
        debug_assert!(bits == 32 || value >> bits == 0);
        self.acc |= u64::from(value) << self.filled;
        self.filled += u32::from(bits);
        while self.filled >= 8 {
            self.out.push(self.acc as u8);
            self.acc >>= 8;
            self.filled -= 8;
        }
    }

    /// Pads the last byte with zeros.
    fn finish(self) {
        if self.filled > 0 {
            self.out.push(self.acc as u8);
        }
    }
}

/// Reads bit fields written by [`BitWriter`].
struct BitReader<'a> {
    bytes: &'a [u8],
    bit: usize,
}

impl BitReader<'_> {
    fn read(&mut self, bits: u8) -> Result<u32, CompactError> {
        let mut value = 0u64;
        for i in 0..usize::from(bits) {
            let at = self.bit + i;
            let byte = *self.bytes.get(at / 8).ok_or(CompactError::Truncated("joint values"))?;
            value |= u64::from((byte >> (at % 8)) & 1) << i;
        }
        self.bit += usize::from(bits);
        Ok(value as u32)
    }

    fn bytes_used(&self) -> usize {
        self.bit.div_ceil(8)
    }
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn take_varint(bytes: &[u8], at: &mut usize, what: &'static str) -> Result<u64, CompactError> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let byte = *bytes.get(*at).ok_or(CompactError::Truncated(what))?;
        *at += 1;
        v |= u64::from(byte & 0x7f) << shift;
        if byte & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(CompactError::VarintOverflow)
}

fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

fn unzigzag(v: u64) -> i64 {
    (v >> 1) as i64 ^ -((v & 1) as i64)
}

fn write_header(out: &mut Vec<u8>, h: &Header, flags: u8, key_seq: u64) {
    out.push(flags);
    put_varint(out, h.seq);
    put_varint(out, h.dropped);
    put_varint(out, h.seq - key_seq);
    put_varint(out, zigzag(h.sent_at_unix_nanos));
    out.extend_from_slice(&h.clip_time.to_le_bytes());
}

fn write_joint(bits: &mut BitWriter<'_>, layout: &JointLayout, v: &QuantisedJoint) {
    if let Rotation::Quantised(r) = &layout.rotation {
        if r.largest.is_none() {
            bits.write(u32::from(v.largest), 2);
        }
        for (&c, k) in v.rotation.iter().zip(sent_components(v.largest)) {
            bits.write(c, r.components[k].bits);
        }
    }
    for (axes, values) in [(&layout.translation, &v.translation), (&layout.scale, &v.scale)] {
        for (axis, &u) in axes.iter().zip(values) {
            bits.write(u, axis.bits);
        }
    }
}

/// The components a smallest-three value sends, in order.
fn sent_components(largest: u8) -> impl Iterator<Item = usize> {
    (0..4).filter(move |&k| k != usize::from(largest))
}

fn read_joint(bits: &mut BitReader<'_>, layout: &JointLayout) -> Result<QuantisedJoint, CompactError> {
    let mut v = QuantisedJoint::default();
    if let Rotation::Quantised(r) = &layout.rotation {
        v.largest = match r.largest {
            Some(l) => l,
            None => bits.read(2)? as u8,
        };
        for (c, k) in v.rotation.iter_mut().zip(sent_components(v.largest)) {
            *c = bits.read(r.components[k].bits)?;
        }
    }
    for (axes, values) in [(&layout.translation, &mut v.translation), (&layout.scale, &mut v.scale)] {
        for (axis, u) in axes.iter().zip(values.iter_mut()) {
            *u = bits.read(axis.bits)?;
        }
    }
    Ok(v)
}

/// One stream's encoder: quantises each pose, and writes a key frame when
/// asked, on the first frame, or `key_interval` frames after the last one;
/// otherwise a delta frame of the joints whose values differ from it.
#[derive(Debug)]
pub struct CompactEncoder {
    layout: Layout,
    key_interval: u64,
    key: Vec<QuantisedJoint>,
    key_seq: Option<u64>,
    key_frame: Vec<u8>,
    values: Vec<QuantisedJoint>,
    frame: Vec<u8>,
}

impl CompactEncoder {
    /// `key_interval`: frames between key frames at most (the stream's fps
    /// makes it at least one a second), at least 1.
    pub fn new(layout: Layout, key_interval: u64) -> Self {
        CompactEncoder {
            layout,
            key_interval: key_interval.max(1),
            key: Vec::new(),
            key_seq: None,
            key_frame: Vec::new(),
            values: Vec::new(),
            frame: Vec::new(),
        }
    }

    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// The frame for `pose` (a local pose of the layout's joints).
    pub fn encode(&mut self, header: &Header, pose: &Pose, force_key: bool) -> &[u8] {
        self.encode_with(header, pose, force_key, &Trailer::default())
    }

    /// The frame for `pose`, with `trailer`'s sections after the body.
    pub fn encode_with(&mut self, header: &Header, pose: &Pose, force_key: bool, trailer: &Trailer<'_>) -> &[u8] {
        self.layout.quantise(pose, &mut self.values);
        let due = self.key_seq.is_none_or(|k| header.seq < k || header.seq - k >= self.key_interval);
        self.frame.clear();
        if force_key || due {
            self.key.clone_from(&self.values);
            self.key_seq = Some(header.seq);
            write_header(&mut self.frame, header, KEY_FRAME | trailer.flags(), header.seq);
            let mut bits = BitWriter::new(&mut self.frame);
            for (layout, v) in self.layout.joints.iter().zip(&self.values) {
                write_joint(&mut bits, layout, v);
            }
            bits.finish();
            trailer.write(&mut self.frame);
            self.key_frame.clone_from(&self.frame);
        } else {
            let key_seq = self.key_seq.expect("a key frame was sent");
            write_header(&mut self.frame, header, trailer.flags(), key_seq);
            let mut bits = BitWriter::new(&mut self.frame);
            for ((layout, v), key) in self.layout.joints.iter().zip(&self.values).zip(&self.key) {
                if layout.is_animated() {
                    let changed = v != key;
                    bits.write(u32::from(changed), 1);
                    if changed {
                        write_joint(&mut bits, layout, v);
                    }
                }
            }
            bits.finish();
            trailer.write(&mut self.frame);
        }
        &self.frame
    }

    /// The last key frame's bytes: what a viewer that missed it is sent
    /// before the stream's next delta frame.
    pub fn last_key_frame(&self) -> &[u8] {
        &self.key_frame
    }

    /// The quantised pose of the last frame encoded, decoded: exactly what
    /// a decoder shows.
    pub fn quantised_pose(&self, out: &mut Pose) {
        self.layout.dequantise(&self.values, out);
    }
}

/// Decodes a stream's frames (the key frame's values kept for its deltas).
#[derive(Debug)]
pub struct CompactDecoder {
    layout: Layout,
    /// How many events the layout document lists: an index beyond is refused.
    event_count: usize,
    key: Vec<QuantisedJoint>,
    key_seq: Option<u64>,
    values: Vec<QuantisedJoint>,
    events: Vec<u32>,
    /// The layout's `graph` (empty without one: every index is refused).
    graph: GraphDoc,
    /// The last frame's graph report, when it had one.
    report: Option<GraphFrame>,
}

impl CompactDecoder {
    /// A decoder of frames of `layout` that carry no events and no graph report.
    pub fn new(layout: Layout) -> Self {
        let (key, values, events) = (Vec::new(), Vec::new(), Vec::new());
        let graph = GraphDoc::default();
        CompactDecoder { layout, event_count: 0, key, key_seq: None, values, events, graph, report: None }
    }

    /// A decoder of the frames the layout document `doc` describes.
    pub fn of_document(doc: &LayoutDoc) -> Self {
        let graph = doc.graph.clone().unwrap_or_default();
        CompactDecoder { event_count: doc.events.len(), graph, ..CompactDecoder::new(doc.layout()) }
    }

    /// The graph report of the last frame decoded, when it carried one.
    pub fn graph_report(&self) -> Option<&GraphFrame> {
        self.report.as_ref()
    }

    /// Decodes frames of the layout document `doc` from now on: a new
    /// layout mid-stream (docs/compact-frames.md, "A new layout"). What
    /// the last key frame held is forgotten, so a delta frame before the
    /// new layout's first key frame is refused.
    pub fn relayout(&mut self, doc: &LayoutDoc) {
        *self = CompactDecoder::of_document(doc);
    }

    /// The events of the last frame decoded: indices into the layout
    /// document's `events`, in the order they were crossed.
    pub fn events(&self) -> &[u32] {
        &self.events
    }

    /// Decodes `bytes` into `pose`.
    ///
    /// # Errors
    /// The bytes are not a frame of this layout, or a delta frame's key
    /// frame was not seen.
    pub fn decode(&mut self, bytes: &[u8], pose: &mut Pose) -> Result<Decoded, CompactError> {
        let flags = *bytes.first().ok_or(CompactError::Truncated("flags"))?;
        if flags & !KNOWN_FLAGS != 0 {
            return Err(CompactError::UnknownFlags(flags));
        }
        let key = flags & KEY_FRAME != 0;
        let mut at = 1;
        let seq = take_varint(bytes, &mut at, "seq")?;
        let dropped = take_varint(bytes, &mut at, "dropped")?;
        let key_seq = seq.wrapping_sub(take_varint(bytes, &mut at, "key offset")?);
        let sent_at_unix_nanos = unzigzag(take_varint(bytes, &mut at, "sent_at")?);
        let clip_time = bytes.get(at..at + 4).ok_or(CompactError::Truncated("clip time"))?;
        let clip_time = f32::from_le_bytes(clip_time.try_into().expect("four bytes"));
        let mut bits = BitReader { bytes: &bytes[at + 4..], bit: 0 };
        let joints_sent = if key { self.read_key(&mut bits, seq)? } else { self.read_delta(&mut bits, key_seq)? };
        at += 4 + bits.bytes_used();
        self.read_events(bytes, &mut at, flags & EVENTS != 0)?;
        let root_motion = if flags & ROOT_MOTION != 0 { Some(read_root_motion(bytes, &mut at)?) } else { None };
        self.read_graph(bytes, &mut at, flags & GRAPH != 0)?;
        if at < bytes.len() {
            return Err(CompactError::TrailingBytes(bytes.len() - at));
        }
        self.layout.dequantise(&self.values, pose);
        let header = Header { seq, dropped, sent_at_unix_nanos, clip_time };
        Ok(Decoded { header, key, key_seq, joints_sent, root_motion })
    }

    /// The events section, when the flags announce it.
    fn read_events(&mut self, bytes: &[u8], at: &mut usize, present: bool) -> Result<(), CompactError> {
        self.events.clear();
        if !present {
            return Ok(());
        }
        let count = take_varint(bytes, at, "events")?;
        for _ in 0..count {
            let index = take_varint(bytes, at, "events")?;
            match u32::try_from(index) {
                Ok(i) if (i as usize) < self.event_count => self.events.push(i),
                _ => return Err(CompactError::UnknownEvent { index, count: self.event_count }),
            }
        }
        Ok(())
    }

    /// The graph report section, when the flags announce it.
    fn read_graph(&mut self, bytes: &[u8], at: &mut usize, present: bool) -> Result<(), CompactError> {
        if !present {
            self.report = None;
            return Ok(());
        }
        let mut report = self.report.take().unwrap_or_default();
        GraphFrame::read(bytes, at, &self.graph, &mut report)?;
        self.report = Some(report);
        Ok(())
    }

    fn read_key(&mut self, bits: &mut BitReader<'_>, seq: u64) -> Result<usize, CompactError> {
        self.values.clear();
        for layout in &self.layout.joints {
            self.values.push(read_joint(bits, layout)?);
        }
        self.key.clone_from(&self.values);
        self.key_seq = Some(seq);
        Ok(self.values.len())
    }

    fn read_delta(&mut self, bits: &mut BitReader<'_>, key_seq: u64) -> Result<usize, CompactError> {
        if self.key_seq != Some(key_seq) {
            return Err(CompactError::MissingKeyFrame { wanted: key_seq, seen: self.key_seq });
        }
        self.values.clone_from(&self.key);
        let mut sent = 0;
        for (layout, v) in self.layout.joints.iter().zip(&mut self.values) {
            if layout.is_animated() && bits.read(1)? == 1 {
                *v = read_joint(bits, layout)?;
                sent += 1;
            }
        }
        Ok(sent)
    }
}

/// The root motion section: eight little-endian f32s.
fn read_root_motion(bytes: &[u8], at: &mut usize) -> Result<RootMotionReport, CompactError> {
    let section = bytes.get(*at..*at + 32).ok_or(CompactError::Truncated("root motion"))?;
    *at += 32;
    let value = |k: usize| f32::from_le_bytes(section[4 * k..4 * k + 4].try_into().expect("four bytes"));
    Ok(RootMotionReport { delta: std::array::from_fn(value), total: std::array::from_fn(|k| value(k + 4)) })
}

/// The layout as the `opened` message states it (docs/compact-frames.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayoutDoc {
    pub version: u32,
    pub max_error: f32,
    pub distance: f32,
    /// The computed worst error of the widths, metres.
    pub bound: f32,
    /// Key frames come at least this many frames apart at most.
    pub key_interval: u64,
    pub joints: Vec<JointDoc>,
    /// The events a frame's events section indexes (the stream's clip's),
    /// sent once here; absent when there are none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub events: Vec<EventDoc>,
    /// A graph stream with `report`: the names its graph report section
    /// indexes, sent once here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub graph: Option<GraphDoc>,
}

/// The graph's states and blend nodes, in the graph's order: a frame's
/// graph report names them by index.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraphDoc {
    pub states: Vec<String>,
    pub nodes: Vec<GraphNodeDoc>,
}

/// A blend node: its name and how many points (weights) it has.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraphNodeDoc {
    pub name: String,
    pub points: usize,
}

/// An event of the layout's list: its clip time and name.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EventDoc {
    pub time: f32,
    pub name: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointDoc {
    pub name: String,
    pub rotation: RotationDoc,
    pub translation: AxesDoc,
    pub scale: AxesDoc,
}

/// `{"constant": [x, y, z, w]}` or `{"smallest_three": {...}}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum RotationDoc {
    Constant([f32; 4]),
    SmallestThree(SmallestThreeDoc),
}

/// The largest component's index when it is always the same (`null`: sent
/// per frame), and per component `[x, y, z, w]` its bits and range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SmallestThreeDoc {
    pub largest: Option<u8>,
    pub bits: [u8; 4],
    pub min: [f32; 4],
    pub max: [f32; 4],
}

/// Per axis: bits (0: constant, `min == max`) and the range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxesDoc {
    pub bits: [u8; 3],
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl LayoutDoc {
    /// The document of `layout` for joints called `names`, whose frames'
    /// events index `events`.
    pub fn new(layout: &Layout, names: &[String], key_interval: u64, events: &[Event]) -> LayoutDoc {
        let axes = |a: &[Axis; 3]| AxesDoc { bits: a.map(|x| x.bits), min: a.map(|x| x.min), max: a.map(|x| x.max) };
        let joints = layout
            .joints
            .iter()
            .zip(names)
            .map(|(j, name)| JointDoc {
                name: name.clone(),
                rotation: match j.rotation {
                    Rotation::Constant(q) => RotationDoc::Constant(q.to_array()),
                    Rotation::Quantised(r) => RotationDoc::SmallestThree(SmallestThreeDoc {
                        largest: r.largest,
                        bits: r.components.map(|a| a.bits),
                        min: r.components.map(|a| a.min),
                        max: r.components.map(|a| a.max),
                    }),
                },
                translation: axes(&j.translation),
                scale: axes(&j.scale),
            })
            .collect();
        LayoutDoc {
            version: VERSION,
            max_error: layout.max_error,
            distance: layout.distance,
            bound: layout.bound,
            key_interval,
            joints,
            events: events.iter().map(|e| EventDoc { time: e.time, name: e.name.clone() }).collect(),
            graph: None,
        }
    }

    /// The same document naming `graph`'s states and blend nodes (a graph
    /// stream with `report`).
    pub fn with_graph<C>(self, graph: &anim::graph::Graph<C>) -> LayoutDoc {
        let states = graph.state_names().map(str::to_owned).collect();
        let nodes = graph.blend_nodes().map(|(name, points)| GraphNodeDoc { name: name.to_owned(), points }).collect();
        LayoutDoc { graph: Some(GraphDoc { states, nodes }), ..self }
    }

    /// The core's layout this document states.
    pub fn layout(&self) -> Layout {
        let axes = |a: &AxesDoc| std::array::from_fn(|k| Axis { min: a.min[k], max: a.max[k], bits: a.bits[k] });
        let joints = self
            .joints
            .iter()
            .map(|j| JointLayout {
                rotation: match &j.rotation {
                    RotationDoc::Constant(q) => Rotation::Constant(Quat::from_array(*q)),
                    RotationDoc::SmallestThree(r) => Rotation::Quantised(SmallestThree {
                        largest: r.largest,
                        components: std::array::from_fn(|k| Axis { min: r.min[k], max: r.max[k], bits: r.bits[k] }),
                    }),
                },
                translation: axes(&j.translation),
                scale: axes(&j.scale),
            })
            .collect();
        Layout { max_error: self.max_error, distance: self.distance, bound: self.bound, joints }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits_pack_least_significant_first() {
        let mut out = Vec::new();
        let mut bits = BitWriter::new(&mut out);
        bits.write(0b101, 3);
        bits.write(0b11, 2);
        bits.write(0x1ff, 9);
        bits.finish();
        // 101 | 11 << 3 | 1_1111_1111 << 5 = 0b11_1111_1111_1101 → 0xfd, 0x3f.
        assert_eq!(out, [0xfd, 0x3f]);
        let mut r = BitReader { bytes: &out, bit: 0 };
        assert_eq!((r.read(3), r.read(2), r.read(9)), (Ok(0b101), Ok(0b11), Ok(0x1ff)));
        assert_eq!(r.read(3), Err(CompactError::Truncated("joint values")));
    }

    #[test]
    fn varints_and_zigzag_round_trip() {
        for v in [0u64, 1, 127, 128, 300, u64::MAX] {
            let mut out = Vec::new();
            put_varint(&mut out, v);
            let mut at = 0;
            assert_eq!(take_varint(&out, &mut at, "x"), Ok(v));
            assert_eq!(at, out.len());
        }
        for v in [0i64, -1, 1, i64::MIN, i64::MAX, 1_700_000_000_000_000_000] {
            assert_eq!(unzigzag(zigzag(v)), v);
        }
        assert_eq!(zigzag(-1), 1);
        assert_eq!(zigzag(1), 2);
    }
}
