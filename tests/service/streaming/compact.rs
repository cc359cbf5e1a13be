//! `encoding=compact` (docs/compact-frames.md) on a real server: WebSocket
//! streams, broadcast watches and gRPC `StreamFrames`, each decoded here by a
//! decoder written from the docs page alone (not the formats crate's) and
//! held, joint by joint and virtual point by virtual point in model space
//! (f64), to within `max_error` of the server's own uncompressed frames of
//! the same stream at the same ticks.

use std::collections::BTreeMap;

use formats::wire::proto::pb;
use futures_util::StreamExt;
use prost::Message as _;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::{TestApp, within};
use crate::common::app::Ws;

/// A six-joint arm: a translating, turning root, four turning joints (one
/// scaling), a constant tip, so chains, scales and constant channels all
/// show.
const PARENTS: [Option<usize>; 6] = [None, Some(0), Some(1), Some(2), Some(3), Some(4)];

fn arm_clip() -> String {
    let joint = |name: &str, parent: Option<&str>, y: f64| json!({"name": name, "parent": parent, "rest": {"translation": [0, y, 0]}});
    let rot = |joint: &str, qs: Value| json!({"joint": joint, "channel": "rotation", "interpolation": "linear", "times": [0, 0.5, 1, 1.5, 2], "values": qs});
    let s = std::f64::consts::FRAC_1_SQRT_2;
    json!({
        "name": "compact arm",
        "playback": "loop",
        "skeleton": {"joints": [
            joint("root", None, 0.0), joint("spine", Some("root"), 0.5), joint("neck", Some("spine"), 0.4),
            joint("upper", Some("neck"), 0.3), joint("lower", Some("upper"), 0.3), joint("tip", Some("lower"), 0.2)
        ]},
        "tracks": [
            {"joint": "root", "channel": "translation", "interpolation": "linear", "times": [0, 1, 2],
             "values": [[0, 0, 0], [0.4, 0.1, -0.2], [0, 0, 0]]},
            rot("root", json!([[0, 0, 0, 1], [0, 0.3826834, 0, 0.9238795], [0, s, 0, s], [0, 0.3826834, 0, 0.9238795], [0, 0, 0, 1]])),
            rot("spine", json!([[0, 0, 0, 1], [0.258819, 0, 0, 0.9659258], [0, 0, 0, 1], [-0.258819, 0, 0, 0.9659258], [0, 0, 0, 1]])),
            rot("neck", json!([[0, 0, 0.1305262, 0.9914449], [0, 0, -0.1305262, 0.9914449], [0, 0, 0.1305262, 0.9914449], [0, 0, -0.1305262, 0.9914449], [0, 0, 0.1305262, 0.9914449]])),
            rot("upper", json!([[0.5, 0.5, 0.5, 0.5], [s, 0, 0, s], [0, 0, 0, 1], [0, s, 0, s], [0.5, 0.5, 0.5, 0.5]])),
            rot("lower", json!([[0, 0, 0, 1], [0, 0, 0.8660254, 0.5], [0, 0, 1, 0], [0, 0, 0.8660254, -0.5], [0, 0, 0, 1]])),
            {"joint": "upper", "channel": "scale", "interpolation": "linear", "times": [0, 1, 2],
             "values": [[1, 1, 1], [1.2, 0.9, 1], [1, 1, 1]]}
        ]
    })
    .to_string()
}

// ------------------------------------------------------------- the decoder

/// A quantised channel: its width and range (docs: "The layout document").
#[derive(Debug, Clone, Copy)]
struct Field {
    bits: u32,
    min: f64,
    max: f64,
}

impl Field {
    /// `min + (u · (max − min)) / n`, `n = 2^bits − 1`; bits 0: `min`.
    fn value(&self, u: u64) -> f64 {
        if self.bits == 0 {
            self.min
        } else {
            self.min + (u as f64 * (self.max - self.min)) / ((1u64 << self.bits) - 1) as f64
        }
    }
}

enum Rotation {
    Constant([f64; 4]),
    SmallestThree { largest: Option<usize>, components: [Field; 4] },
}

struct Joint {
    rotation: Rotation,
    translation: [Field; 3],
    scale: [Field; 3],
}

impl Joint {
    fn animated(&self) -> bool {
        matches!(self.rotation, Rotation::SmallestThree { .. })
            || self.translation.iter().chain(&self.scale).any(|f| f.bits > 0)
    }
}

struct Layout {
    /// The error it states it keeps within (docs: "The error bound").
    bound: f64,
    distance: f64,
    key_interval: u64,
    joints: Vec<Joint>,
    /// Each blend node's number of points, when the layout has a `graph`.
    points: Vec<usize>,
}

fn fields<const N: usize>(v: &Value) -> [Field; N] {
    std::array::from_fn(|k| Field {
        bits: v["bits"][k].as_u64().unwrap() as u32,
        min: v["min"][k].as_f64().unwrap(),
        max: v["max"][k].as_f64().unwrap(),
    })
}

fn layout(doc: &Value) -> Layout {
    assert_eq!(doc["version"], 1);
    let joints = doc["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| Joint {
            rotation: match (&j["rotation"]["constant"], &j["rotation"]["smallest_three"]) {
                (Value::Array(q), _) => Rotation::Constant(std::array::from_fn(|k| q[k].as_f64().unwrap())),
                (_, r) => Rotation::SmallestThree {
                    largest: r["largest"].as_u64().map(|l| l as usize),
                    components: fields(r),
                },
            },
            translation: fields(&j["translation"]),
            scale: fields(&j["scale"]),
        })
        .collect();
    let nodes = doc["graph"]["nodes"].as_array().cloned().unwrap_or_default();
    let points = nodes.iter().map(|n| n["points"].as_u64().unwrap() as usize).collect();
    Layout {
        bound: doc["bound"].as_f64().unwrap(),
        distance: doc["distance"].as_f64().unwrap(),
        key_interval: doc["key_interval"].as_u64().unwrap(),
        joints,
        points,
    }
}

/// Bits least significant first, each byte from bit 0 (docs: "Bit order").
struct Bits<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Bits<'_> {
    fn read(&mut self, n: u32) -> u64 {
        let mut v = 0;
        for i in 0..n as usize {
            let bit = self.at + i;
            v |= u64::from((self.bytes[bit / 8] >> (bit % 8)) & 1) << i;
        }
        self.at += n as usize;
        v
    }
}

fn varint(bytes: &[u8], at: &mut usize) -> u64 {
    let mut v = 0;
    for shift in (0..64).step_by(7) {
        let b = bytes[*at];
        *at += 1;
        v |= u64::from(b & 0x7f) << shift;
        if b & 0x80 == 0 {
            return v;
        }
    }
    panic!("a varint over 64 bits")
}

/// A local pose: per joint its translation, rotation `[x, y, z, w]` and scale.
type Pose = ([f64; 3], [f64; 4], [f64; 3]);

/// One joint's raw fields: the largest index, three rotation values, translation, scale.
type Raw = [u64; 10];

/// A decoded frame: header, whether a key frame, the local pose (f32 values).
#[derive(Debug, Clone)]
struct Decoded {
    seq: u64,
    dropped: u64,
    key: bool,
    key_seq: u64,
    clip_time: f32,
    /// Its layout's `bound`.
    bound: f64,
    /// The first frame of a layout sent mid-stream.
    new_layout: bool,
    pose: Vec<Pose>,
    /// Indices into the layout's `events` (docs: flags bit 1).
    events: Vec<u64>,
    /// Root motion delta then total, each x, y, z, yaw (docs: flags bit 2).
    root_motion: Option<[f32; 8]>,
    /// The graph report (docs: flags bit 3).
    graph: Option<Report>,
}

/// A graph report by index: the state, the transition `(from, to, alpha)`,
/// each blend node's index and weights.
type Report = (u64, Option<(u64, u64, f32)>, Vec<(u64, Vec<f32>)>);

fn f32_at(bytes: &[u8], at: &mut usize) -> f32 {
    *at += 4;
    f32::from_le_bytes(bytes[*at - 4..*at].try_into().unwrap())
}

struct Decoder {
    layout: Layout,
    keys: Option<(u64, Vec<Raw>)>,
}

impl Decoder {
    fn joint(&self, j: &Joint, bits: &mut Bits<'_>) -> Raw {
        let mut raw = [0; 10];
        if let Rotation::SmallestThree { largest, components } = &j.rotation {
            raw[0] = largest.map_or_else(|| bits.read(2), |l| l as u64);
            let mut slot = 1;
            for (k, c) in components.iter().enumerate() {
                if k as u64 != raw[0] {
                    raw[slot] = bits.read(c.bits);
                    slot += 1;
                }
            }
        }
        for (a, f) in j.translation.iter().chain(&j.scale).enumerate() {
            raw[4 + a] = bits.read(f.bits);
        }
        raw
    }

    fn decode(&mut self, bytes: &[u8]) -> Decoded {
        let flags = bytes[0];
        assert_eq!(flags & !0b1111, 0, "unknown flags");
        let key = flags & 1 == 1;
        let mut at = 1;
        let seq = varint(bytes, &mut at);
        let dropped = varint(bytes, &mut at);
        let key_seq = seq - varint(bytes, &mut at);
        let _sent_at = varint(bytes, &mut at);
        let clip_time = f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
        at += 4;
        let mut bits = Bits { bytes: &bytes[at..], at: 0 };
        let raws: Vec<Raw> = if key {
            self.layout.joints.iter().map(|j| self.joint(j, &mut bits)).collect()
        } else {
            let (k, base) = self.keys.as_ref().expect("a delta frame after its key frame");
            assert_eq!(*k, key_seq, "seq {seq}: a delta frame of key frame {key_seq}, and the last seen is {k}");
            let mut raws = base.clone();
            for (j, raw) in self.layout.joints.iter().zip(&mut raws) {
                if j.animated() && bits.read(1) == 1 {
                    *raw = self.joint(j, &mut bits);
                }
            }
            raws
        };
        at += bits.at.div_ceil(8);
        let mut events = Vec::new();
        if flags & 2 != 0 {
            let count = varint(bytes, &mut at);
            events = (0..count).map(|_| varint(bytes, &mut at)).collect();
        }
        let root_motion = (flags & 4 != 0).then(|| {
            let values: [f32; 8] =
                std::array::from_fn(|k| f32::from_le_bytes(bytes[at + 4 * k..at + 4 * k + 4].try_into().unwrap()));
            at += 32;
            values
        });
        let graph = (flags & 8 != 0).then(|| {
            let state = varint(bytes, &mut at);
            let transition = match varint(bytes, &mut at) {
                0 => None,
                from => Some((from - 1, varint(bytes, &mut at), f32_at(bytes, &mut at))),
            };
            let nodes = (0..varint(bytes, &mut at)).map(|_| {
                let node = varint(bytes, &mut at);
                (node, (0..self.layout.points[node as usize]).map(|_| f32_at(bytes, &mut at)).collect())
            });
            (state, transition, nodes.collect())
        });
        assert_eq!(bytes.len(), at, "seq {seq}: no trailing bytes");
        if key {
            self.keys = Some((seq, raws.clone()));
        }
        let pose = self.layout.joints.iter().zip(&raws).map(|(j, raw)| pose_of(j, raw)).collect();
        let bound = self.layout.bound;
        Decoded { seq, dropped, key, key_seq, clip_time, bound, new_layout: false, pose, events, root_motion, graph }
    }

    /// A new layout mid-stream (docs: "A new layout"): its frames decode
    /// with it, from a key frame on.
    fn relayout(&mut self, doc: &Value) {
        self.layout = layout(doc);
        self.keys = None;
    }
}

/// docs: "Decoding values": f64 in the order written, rounded to f32 once.
fn pose_of(j: &Joint, raw: &Raw) -> Pose {
    let f32_of = |v: f64| f64::from(v as f32);
    let rotation = match &j.rotation {
        Rotation::Constant(q) => *q,
        Rotation::SmallestThree { components, .. } => {
            let largest = raw[0] as usize;
            let sent: Vec<usize> = (0..4).filter(|&k| k != largest).collect();
            let mut v: Vec<f64> = sent.iter().zip(&raw[1..4]).map(|(&k, &u)| components[k].value(u)).collect();
            let s = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            let big = if s < 1.0 {
                (1.0 - s).sqrt()
            } else {
                v.iter_mut().for_each(|c| *c /= s.sqrt());
                0.0
            };
            let mut q = [0.0; 4];
            q[largest] = big;
            for (&k, c) in sent.iter().zip(v) {
                q[k] = c;
            }
            q.map(f32_of)
        }
    };
    let axes = |fs: &[Field; 3], us: &[u64]| std::array::from_fn(|a| f32_of(fs[a].value(us[a])));
    (axes(&j.translation, &raw[4..7]), rotation, axes(&j.scale, &raw[7..10]))
}

// ------------------------------------------------------ the error, in model space

type Affine = ([[f64; 3]; 3], [f64; 3]);

fn local(t: [f64; 3], q: [f64; 4], s: [f64; 3]) -> Affine {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let [x, y, z, w] = q.map(|c| c / n);
    let r = [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
        [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
        [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
    ];
    (std::array::from_fn(|i| std::array::from_fn(|k| r[i][k] * s[k])), t)
}

fn then(parent: &Affine, child: &Affine) -> Affine {
    let (a, b) = parent;
    let m = std::array::from_fn(|i| std::array::from_fn(|k| (0..3).map(|l| a[i][l] * child.0[l][k]).sum()));
    let v = std::array::from_fn(|i| (0..3).map(|l| a[i][l] * child.1[l]).sum::<f64>() + b[i]);
    (m, v)
}

/// Each joint's model position and the three points `distance` along its axes.
fn points(parents: &[Option<usize>], pose: &[Pose], distance: f64) -> Vec<[f64; 3]> {
    let mut model: Vec<Affine> = Vec::new();
    let mut out = Vec::new();
    for (j, &(t, q, s)) in pose.iter().enumerate() {
        let l = local(t, q, s);
        let m = parents[j].map_or(l, |p| then(&model[p], &l));
        out.push(m.1);
        for axis in 0..3 {
            out.push(std::array::from_fn(|i| m.1[i] + distance * m.0[i][axis]));
        }
        model.push(m);
    }
    out
}

/// The largest distance between matching points of two poses.
fn worst(parents: &[Option<usize>], a: &[Pose], b: &[Pose], distance: f64) -> f64 {
    let (pa, pb) = (points(parents, a, distance), points(parents, b, distance));
    pa.iter().zip(&pb).map(|(x, y)| (0..3).map(|i| (x[i] - y[i]).powi(2)).sum::<f64>().sqrt()).fold(0.0, f64::max)
}

fn pose_of_pb(p: &pb::Pose) -> Vec<Pose> {
    let f = |v: &[f32], i: usize| f64::from(v[i]);
    (0..p.translations.len() / 3)
        .map(|j| {
            (
                std::array::from_fn(|k| f(&p.translations, 3 * j + k)),
                std::array::from_fn(|k| f(&p.rotations, 4 * j + k)),
                std::array::from_fn(|k| f(&p.scales, 3 * j + k)),
            )
        })
        .collect()
}

/// Holds each compact frame to the uncompressed frame of the same seq;
/// returns the seqs compared, key frames and deltas counted.
fn compare(
    compact: &[Decoded],
    plain: &BTreeMap<u64, Vec<Pose>>,
    max_error: f64,
    layout: &Layout,
) -> (usize, usize, usize) {
    compare_on(&PARENTS, compact, plain, max_error, layout)
}

fn compare_on(
    parents: &[Option<usize>],
    compact: &[Decoded],
    plain: &BTreeMap<u64, Vec<Pose>>,
    max_error: f64,
    layout: &Layout,
) -> (usize, usize, usize) {
    let (mut compared, mut keys, mut deltas) = (0, 0, 0);
    for d in compact {
        if d.key {
            keys += 1
        } else {
            deltas += 1
        }
        if let Some(p) = plain.get(&d.seq) {
            let e = worst(parents, &d.pose, p, layout.distance);
            assert!(e <= max_error, "seq {} (key {}): {e} m off, over {max_error}", d.seq, d.key);
            compared += 1;
        }
    }
    (compared, keys, deltas)
}

/// Key frames at least every `key_interval` ticks, each delta frame of the
/// last one, and every `seq` gap exactly the `dropped` of the frame after it.
fn check_keys(frames: &[Decoded], key_interval: u64) {
    let mut last_key = None;
    for (d, prev) in frames.iter().zip(std::iter::once(None).chain(frames.iter().map(Some))) {
        if let Some(prev) = prev {
            assert_eq!(d.dropped, d.seq - prev.seq - 1, "seq {} after {}", d.seq, prev.seq);
        }
        if d.key {
            assert_eq!(d.key_seq, d.seq);
            last_key = Some(d.seq);
        } else {
            assert_eq!(Some(d.key_seq), last_key, "seq {}: relative to the last key frame", d.seq);
            assert!(d.seq - d.key_seq < key_interval, "seq {}: key frame {} is too old", d.seq, d.key_seq);
        }
    }
}

// ------------------------------------------------------------- the sockets

async fn next_message(ws: &mut Ws) -> Message {
    loop {
        match within(5, "a message", ws.next()).await.expect("the socket closed").unwrap() {
            Message::Ping(_) | Message::Pong(_) => {}
            other => return other,
        }
    }
}

/// A compact WebSocket's `opened` layout and its next `n` frames, decoded.
async fn compact_frames(ws: &mut Ws, n: usize) -> (Value, Vec<Decoded>, Vec<usize>) {
    let doc = opened_layout(ws).await;
    let mut decoder = Decoder { layout: layout(&doc), keys: None };
    let (frames, sizes) = more_frames(ws, &mut decoder, n).await;
    (doc, frames, sizes)
}

/// The layout a compact socket's `opened` message states.
async fn opened_layout(ws: &mut Ws) -> Value {
    let Message::Text(opened) = next_message(ws).await else { panic!("the `opened` message first") };
    let opened: Value = serde_json::from_str(&opened).unwrap();
    let doc = opened["opened"]["compact"].clone();
    assert!(doc.is_object(), "a compact layout: {opened}");
    doc
}

/// The next `n` compact frames of `ws`, decoded by `decoder`, and their sizes.
async fn more_frames(ws: &mut Ws, decoder: &mut Decoder, n: usize) -> (Vec<Decoded>, Vec<usize>) {
    let (mut frames, mut sizes) = (Vec::new(), Vec::new());
    while frames.len() < n {
        match next_message(ws).await {
            Message::Binary(b) => {
                sizes.push(b.len());
                frames.push(decoder.decode(&b));
            }
            Message::Text(t) => {
                let v: Value = serde_json::from_str(&t).unwrap();
                assert!(v["layout"].is_object(), "expected a compact frame or a layout, got {v}");
                decoder.relayout(&v["layout"]);
                let Message::Binary(b) = next_message(ws).await else { panic!("a frame after the layout") };
                let d = Decoded { new_layout: true, ..decoder.decode(&b) };
                assert!(d.key && v["seq"] == d.seq, "the first frame in a new layout is a key frame of its seq: {v}");
                sizes.push(b.len());
                frames.push(d);
            }
            other => panic!("expected a compact frame, got {other:?}"),
        }
    }
    (frames, sizes)
}

async fn protobuf_frames(ws: &mut Ws, n: usize) -> BTreeMap<u64, Vec<Pose>> {
    let frames = whole_protobuf_frames(ws, n).await;
    frames.into_iter().map(|(seq, f)| (seq, pose_of_pb(f.pose.as_ref().unwrap()))).collect()
}

/// The next `n` protobuf frames of `ws` (fewer if it closes), by `seq`.
async fn whole_protobuf_frames(ws: &mut Ws, n: usize) -> BTreeMap<u64, pb::Frame> {
    let mut out = BTreeMap::new();
    while out.len() < n {
        match next_message(ws).await {
            Message::Binary(b) => {
                let f = pb::Frame::decode(b).unwrap();
                out.insert(f.seq, f);
            }
            Message::Close(_) => break,
            other => panic!("expected a protobuf frame, got {other:?}"),
        }
    }
    out
}

/// The arm clip with footsteps, two of them at its loop's ends.
fn stepping_arm_clip() -> String {
    let mut clip: Value = serde_json::from_str(&arm_clip()).unwrap();
    clip["name"] = json!("stepping arm");
    clip["events"] = json!([
        {"time": 0, "name": "start"}, {"time": 0.5, "name": "step_left"},
        {"time": 1.25, "name": "step_right"}, {"time": 2, "name": "end"}
    ]);
    clip.to_string()
}

/// The ticks both streams played after playing the one before: what
/// happened since the previous frame (events, a root delta) is the same
/// span of the clip in both. A loaded machine may make either skip ticks.
fn both_played<'a>(
    compact: &'a [Decoded],
    plain: &'a BTreeMap<u64, pb::Frame>,
) -> impl Iterator<Item = (&'a Decoded, &'a pb::Frame)> {
    compact.windows(2).filter(|w| w[1].seq == w[0].seq + 1).filter_map(|w| {
        let previous = plain.contains_key(&w[0].seq);
        plain.get(&w[1].seq).filter(|_| previous).map(|p| (&w[1], p))
    })
}

/// Per tick both played, the compact frame's events (named through the
/// layout's `events`) are the protobuf frame's; returns how many events
/// were compared.
fn same_events(doc: &Value, compact: &[Decoded], plain: &BTreeMap<u64, pb::Frame>) -> usize {
    let named = |i: &u64| {
        let e = &doc["events"][*i as usize];
        (e["time"].as_f64().unwrap() as f32, e["name"].as_str().unwrap().to_owned())
    };
    let mut seen = 0;
    for (d, p) in both_played(compact, plain) {
        let expected: Vec<(f32, String)> = p.events.iter().map(|e| (e.time, e.name.clone())).collect();
        assert_eq!(d.events.iter().map(named).collect::<Vec<_>>(), expected, "seq {}", d.seq);
        seen += expected.len();
    }
    seen
}

/// A compact clip stream of a clip with events carries, frame by frame,
/// the events its protobuf stream carries (through the loop's seam).
#[tokio::test]
async fn compact_frames_carry_the_protobuf_frames_events() {
    let app = TestApp::start().await;
    let id = app.create_id(&stepping_arm_clip(), None).await;
    let query = "fps=30&start=0&speed=1.3&max_frames=75";
    let mut compact = app.ws(&format!("/v1/clips/{id}/stream?{query}&encoding=compact")).await;
    let mut plain = app.ws(&format!("/v1/clips/{id}/stream?{query}&encoding=protobuf")).await;
    let (doc, frames, _) = compact_frames(&mut compact, 75).await;
    let plain = whole_protobuf_frames(&mut plain, 75).await;
    let names: Vec<&str> = doc["events"].as_array().unwrap().iter().map(|e| e["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["start", "step_left", "step_right", "end"]);
    // 75 frames at 1.3× cover 3.2 s of a 2 s loop: about seven events.
    assert!(same_events(&doc, &frames, &plain) >= 4);
    assert!(frames.iter().all(|d| d.root_motion.is_none()), "a clip stream reports no root motion");
}

/// A motion with root motion `report` streamed compact: every frame's root
/// delta and total are the protobuf frame's doubles rounded to f32, and
/// its events are the protobuf frame's.
#[tokio::test]
async fn compact_frames_carry_the_protobuf_frames_root_motion() {
    use futures_util::SinkExt;
    let app = TestApp::start().await;
    let id = app.create_id(&stepping_arm_clip(), None).await;
    let motion = json!({"layers": [{"clip": id}], "root_motion": {"joint": "root", "mode": "report"}});
    let open = |encoding: &str| {
        let msg =
            json!({"op": "open", "motion": motion, "fps": 30, "start": 0, "max_frames": 70, "encoding": encoding});
        Message::Text(msg.to_string().into())
    };
    let (mut compact, mut plain) = (app.ws("/v1/stream").await, app.ws("/v1/stream").await);
    compact.send(open("compact")).await.unwrap();
    plain.send(open("protobuf")).await.unwrap();
    let (doc, frames, _) = compact_frames(&mut compact, 70).await;
    let Message::Text(_) = next_message(&mut plain).await else { panic!("the protobuf stream's `opened` first") };
    let plain = whole_protobuf_frames(&mut plain, 70).await;
    let mut compared = 0;
    for (d, p) in both_played(&frames, &plain) {
        let r = p.pose.as_ref().unwrap().root_motion.expect("the protobuf frame reports root motion");
        let planar = |p: Option<pb::Planar>| {
            let p = p.unwrap_or_default();
            [p.x, p.y, p.z, p.yaw].map(|v| v as f32)
        };
        let (delta, total) = (planar(r.delta), planar(r.total));
        let got = d.root_motion.unwrap_or_else(|| panic!("seq {}: no root motion section", d.seq));
        assert_eq!((got[..4].to_vec(), got[4..].to_vec()), (delta.to_vec(), total.to_vec()), "seq {}", d.seq);
        compared += 1;
    }
    assert!(compared >= 40, "{compared} frames compared");
    let last = frames.last().unwrap().root_motion.unwrap();
    assert!(last[4] != 0.0 || last[6] != 0.0, "the root travels: {last:?}");
    assert!(same_events(&doc, &frames, &plain) >= 4);
}

#[tokio::test]
async fn websocket_compact_frames_decode_within_max_error_of_the_uncompressed_stream() {
    let app = TestApp::start().await;
    let id = app.create_id(&arm_clip(), None).await;
    for max_error in [1e-4, 1e-3, 1e-5] {
        let query = "fps=30&start=0&speed=1.3&max_frames=75";
        let mut compact =
            app.ws(&format!("/v1/clips/{id}/stream?{query}&encoding=compact&max_error={max_error}")).await;
        let mut plain = app.ws(&format!("/v1/clips/{id}/stream?{query}&encoding=protobuf")).await;
        let (doc, frames, sizes) = compact_frames(&mut compact, 75).await;
        let plain = protobuf_frames(&mut plain, 75).await;
        assert_eq!(doc["max_error"].as_f64().unwrap() as f32, max_error as f32);
        assert!(doc["bound"].as_f64().unwrap() <= max_error, "{doc}");
        assert_eq!(doc["joints"][5]["name"], "tip");
        assert!(doc["joints"][5]["rotation"]["constant"].is_array(), "the tip never turns: {}", doc["joints"][5]);
        let l = layout(&doc);
        assert_eq!(l.key_interval, 30, "a key frame at least once a second");
        check_keys(&frames, l.key_interval);
        let (compared, keys, deltas) = compare(&frames, &plain, max_error, &l);
        // A loaded machine skips ticks in either stream (each counts them in `dropped`); half of the 75 in
        // both is still every kind of frame compared many times over.
        assert!(compared >= 37, "{max_error}: only {compared} ticks in both streams");
        assert!(keys >= 2 && deltas >= 25, "{max_error}: {keys} key frames, {deltas} deltas");
        eprintln!("max_error {max_error}: key frame {} B, deltas {:?} B", sizes[0], &sizes[1..4]);
    }
}

#[tokio::test]
async fn grpc_compact_frames_decode_within_max_error_of_the_uncompressed_stream() {
    let app = TestApp::start().await;
    let id = app.create_id(&arm_clip(), None).await;
    let mut grpc = app.grpc().await;
    let request = |encoding: pb::FrameEncoding| pb::StreamRequest {
        clip_id: id.clone(),
        fps: 30,
        start_time: Some(0.25),
        max_frames: 70,
        encoding: encoding as i32,
        max_error: Some(5e-5),
        ..Default::default()
    };
    let mut compact = grpc.stream_frames(request(pb::FrameEncoding::Compact)).await.unwrap().into_inner();
    let plain_req = pb::StreamRequest { max_error: None, ..request(pb::FrameEncoding::Protobuf) };
    let mut plain = grpc.stream_frames(plain_req).await.unwrap().into_inner();
    let mut decoder = None;
    let mut frames = Vec::new();
    while let Some(f) = within(10, "a compact frame", compact.message()).await.unwrap() {
        assert!(f.pose.is_none() && f.seq == 0, "a compact Frame carries its bytes only");
        if decoder.is_none() {
            let doc: Value = serde_json::from_str(&f.compact_layout).expect("the layout on the first frame");
            decoder = Some((Decoder { layout: layout(&doc), keys: None }, layout(&doc)));
        } else {
            assert!(f.compact_layout.is_empty(), "the layout once");
        }
        frames.push(decoder.as_mut().unwrap().0.decode(&f.compact));
    }
    let mut uncompressed = BTreeMap::new();
    while let Some(f) = within(10, "a frame", plain.message()).await.unwrap() {
        uncompressed.insert(f.seq, pose_of_pb(f.pose.as_ref().unwrap()));
    }
    let (_, l) = decoder.unwrap();
    check_keys(&frames, l.key_interval);
    let (compared, keys, deltas) = compare(&frames, &uncompressed, 5e-5, &l);
    assert_eq!(frames.len(), 70);
    assert!(compared >= 55 && keys >= 2 && deltas >= 40, "{compared} compared, {keys} keys, {deltas} deltas");
}

#[tokio::test]
async fn broadcast_compact_viewers_decode_within_max_error_of_its_protobuf_viewers() {
    let app = TestApp::start().await;
    let id = app.create_id(&arm_clip(), None).await;
    let created = app.post_json("/v1/broadcasts", &json!({"motion": {"layers": [{"clip": id}]}, "fps": 20})).await;
    let b = created["id"].as_str().expect("a broadcast").to_owned();
    let mut compact = app.ws(&format!("/v1/broadcasts/{b}/stream?encoding=compact&max_error=0.0002")).await;
    let mut plain = app.ws(&format!("/v1/broadcasts/{b}/stream?encoding=protobuf")).await;
    let (doc, frames, _) = compact_frames(&mut compact, 45).await;
    let plain = protobuf_frames(&mut plain, 45).await;
    let l = layout(&doc);
    assert_eq!(l.key_interval, 20);
    // A viewer that joins between key frames gets the key frame first.
    assert!(frames[0].key, "a viewer's first frame is a key frame: {:?}", frames[0].seq);
    check_keys(&frames, l.key_interval);
    let (compared, keys, _) = compare(&frames, &plain, 2e-4, &l);
    assert!(compared >= 30 && keys >= 2, "{compared} compared, {keys} key frames");
    // While a compact viewer watches, a layer ramp (leaving the clip's own poses) brings it a new layout.
    let resp = app
        .http
        .post(app.url(&format!("/v1/broadcasts/{b}/controls")))
        .json(&json!({"op": "layer", "index": 0, "weight": 0.5, "duration": 0}))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status().as_u16(), 200);
    let relayout = loop {
        match next_message(&mut compact).await {
            Message::Binary(_) => {}
            Message::Text(t) => break serde_json::from_str::<Value>(&t).unwrap(),
            other => panic!("expected a compact frame or a layout, got {other:?}"),
        }
    };
    let mut decoder = Decoder { layout: layout(&relayout["layout"]), keys: None };
    let (after, _) = more_frames(&mut compact, &mut decoder, 10).await;
    assert!(after[0].key && relayout["seq"] == after[0].seq, "a key frame in it first: {relayout}");
    assert!(decoder.layout.bound <= 2e-4);
}

#[tokio::test]
async fn bad_compact_parameters_are_refused_with_stable_codes() {
    let app = TestApp::start().await;
    let id = app.create_id(&arm_clip(), None).await;
    let refused = |query: String| {
        let url = app.ws_url(&format!("/v1/clips/{id}/stream?{query}"));
        async move {
            use tokio_tungstenite::tungstenite::client::IntoClientRequest;
            let err = tokio_tungstenite::connect_async(url.into_client_request().unwrap()).await.unwrap_err();
            let tokio_tungstenite::tungstenite::Error::Http(resp) = err else { panic!("not refused: {err}") };
            let body: Value = serde_json::from_slice(resp.body().as_deref().unwrap_or_default()).unwrap();
            (resp.status().as_u16(), body["code"].as_str().unwrap().to_owned())
        }
    };
    let cases = [
        ("encoding=compact&max_error=0.0000009", 422, "max_error_out_of_range"),
        ("encoding=compact&max_error=-1", 422, "max_error_out_of_range"),
        ("encoding=compact&distance=0.001", 422, "distance_out_of_range"),
        ("encoding=compact&max_error=abc", 400, "bad_number"),
        ("encoding=compact&space=model", 422, "compact_unsupported"),
        ("encoding=compact&joints=root", 422, "compact_unsupported"),
        ("encoding=zip", 400, "bad_parameter"),
        ("encoding=json&max_error=0.001", 400, "unknown_parameter"),
    ];
    for (query, status, code) in cases {
        assert_eq!(refused(query.to_owned()).await, (status, code.to_owned()), "{query}");
    }
    // gRPC: the same codes under INVALID_ARGUMENT.
    let mut grpc = app.grpc().await;
    let cases = [
        (pb::StreamRequest { encoding: 2, max_error: Some(1e-7), ..Default::default() }, "max_error_out_of_range"),
        (pb::StreamRequest { encoding: 2, distance: Some(0.0), ..Default::default() }, "distance_out_of_range"),
        (pb::StreamRequest { encoding: 9, ..Default::default() }, "bad_parameter"),
    ];
    for (req, code) in cases {
        let req = pb::StreamRequest { clip_id: id.clone(), fps: 30, ..req };
        let status = grpc.stream_frames(req).await.unwrap_err();
        assert_eq!(status.code(), tonic::Code::InvalidArgument, "{code}: {status:?}");
        assert_eq!(status.metadata().get("x-error-code").unwrap().to_str().unwrap(), code);
    }
    // A layer ramp leaves one clip's observed ranges: the stream sends a new layout, then a key frame in it.
    let mut ws = app.ws(&format!("/v1/clips/{id}/stream?encoding=compact&fps=30")).await;
    let doc = opened_layout(&mut ws).await;
    let mut decoder = Decoder { layout: layout(&doc), keys: None };
    drop(more_frames(&mut ws, &mut decoder, 1).await);
    use futures_util::SinkExt;
    ws.send(Message::Text(r#"{"op":"layer","index":0,"weight":0.5,"duration":0}"#.into())).await.unwrap();
    let (frames, _) = more_frames(&mut ws, &mut decoder, 10).await;
    assert!(frames.iter().any(|d| d.new_layout), "a new layout within 10 frames");
}

/// The parents of a stored clip's joints, from its skeleton.
async fn parents(app: &TestApp, id: &str) -> Vec<Option<usize>> {
    let skeleton = app.get_json(&format!("/v1/clips/{id}/skeleton")).await;
    let joints = skeleton["joints"].as_array().unwrap();
    let index = |name: &str| joints.iter().position(|j| j["name"] == name).unwrap();
    joints.iter().map(|j| j["parent"].as_str().map(index)).collect()
}

async fn import(app: &TestApp, query: &str, file: &str, clip_suffix: &str) -> String {
    let url = app.url(&format!("/v1/clips/import?{query}"));
    let resp = app.http.post(url).body(crate::common::testdata(file)).send().await.unwrap();
    assert_eq!(resp.status(), 201, "{file}");
    let body: Value = resp.json().await.unwrap();
    let clips = body["clips"].as_array().unwrap();
    let clip = clips.iter().find(|c| c["name"].as_str().unwrap().ends_with(clip_suffix)).expect("the clip");
    clip["id"].as_str().unwrap().to_owned()
}

/// FIGURE lines for BENCHMARKS.md ("Compact frames"): key and delta frames
/// over the WebSocket for the Fox's walk and a CMU take, at the default
/// bound, against the protobuf frames of the same stream (without the joint
/// names of the first), every decoded frame held to the bound.
/// `cargo test --test service compact::figures -- --nocapture 2>&1 | grep FIGURE`
#[tokio::test]
async fn figures_key_and_delta_frames_on_the_wire() {
    let app = TestApp::start().await;
    let clips = [
        ("Fox walk", import(&app, "format=glb&name=fox&scale=0.01", "gltf/Fox/Fox.glb", "Walk").await),
        ("CMU 131_01", import(&app, "format=bvh&name=cmu&scale=0.05644444", "bvh/131_01.bvh", "cmu").await),
    ];
    for (name, id) in clips {
        let parents = parents(&app, &id).await;
        let query = "fps=30&start=0&playback=loop&max_frames=90";
        let mut compact = app.ws(&format!("/v1/clips/{id}/stream?{query}&encoding=compact")).await;
        let mut plain = app.ws(&format!("/v1/clips/{id}/stream?{query}&encoding=protobuf")).await;
        let (doc, frames, sizes) = compact_frames(&mut compact, 90).await;
        let mut pb_sizes = Vec::new();
        let mut uncompressed = BTreeMap::new();
        while uncompressed.len() < 90 {
            if let Message::Binary(b) = next_message(&mut plain).await {
                pb_sizes.push(b.len());
                let f = pb::Frame::decode(b).unwrap();
                uncompressed.insert(f.seq, pose_of_pb(f.pose.as_ref().unwrap()));
            }
        }
        let l = layout(&doc);
        check_keys(&frames, l.key_interval);
        let (compared, _, _) = compare_on(&parents, &frames, &uncompressed, 1e-4, &l);
        assert!(compared >= 60, "{name}: {compared} ticks compared");
        let keys: Vec<usize> = frames.iter().zip(&sizes).filter(|(d, _)| d.key).map(|(_, s)| *s).collect();
        let deltas: Vec<usize> = frames.iter().zip(&sizes).filter(|(d, _)| !d.key).map(|(_, s)| *s).collect();
        let protobuf = pb_sizes[1..].iter().sum::<usize>() as f64 / (pb_sizes.len() - 1) as f64;
        let key = keys.iter().sum::<usize>() as f64 / keys.len() as f64;
        let delta = deltas.iter().sum::<usize>() as f64 / deltas.len() as f64;
        println!(
            "FIGURE compact {name}: {} joints, protobuf {protobuf:.0} B, key {key:.0} B (1/{:.1}), delta {delta:.1} B \
             (1/{:.1}), {} key frames and {} deltas",
            parents.len(),
            protobuf / key,
            protobuf / delta,
            keys.len(),
            deltas.len()
        );
        assert!(key * 6.0 <= protobuf, "{name}: key frames at most 1/6 of the protobuf frame");
    }
}

// ------------------------------------------- composed motions and graphs

/// The arm clip with its root's path, the upper joint's scales and the
/// lower joint's turns changed: another clip of the same rig.
fn arm_variant(name: &str, path: Value, scales: Value, turn: f64) -> String {
    let mut clip: Value = serde_json::from_str(&arm_clip()).unwrap();
    clip["name"] = json!(name);
    clip["tracks"][0]["values"] = path;
    clip["tracks"][6]["values"] = scales;
    let (s, c) = (turn.sin(), turn.cos());
    clip["tracks"][5]["values"] = json!([[0, 0, 0, 1], [s, 0, 0, c], [0, 0, 0, 1], [-s, 0, 0, c], [0, 0, 0, 1]]);
    clip.to_string()
}

/// Two blend layers (one masked, weight 0.4), an additive layer whose
/// scales and turns differ from its reference, and a two-bone IK on the
/// result: streamed compact over `GET /v1/stream`, every decoded frame is
/// within `max_error` of the same motion's protobuf frames; a `layer` ramp
/// is taken in its layout (the derived ranges hold any weights), a
/// crossfade with a new one.
#[tokio::test]
async fn a_composed_motion_with_additive_layers_and_ik_decodes_within_max_error() {
    use futures_util::SinkExt;
    let app = TestApp::start().await;
    let base = app.create_id(&arm_clip(), None).await;
    let swing = arm_variant(
        "swing",
        json!([[0, 0, 0], [-0.3, 0.25, 0.1], [0, 0, 0]]),
        json!([[1, 1, 1], [0.8, 1.1, 1.3], [1, 1, 1]]),
        1.2,
    );
    let swing = app.create_id(&swing, None).await;
    let breathe = arm_variant(
        "breathe",
        json!([[0, 0, 0], [0.05, 0.02, 0], [0, 0, 0]]),
        json!([[1, 1, 1], [1.1, 1.1, 0.9], [1, 1, 1]]),
        0.4,
    );
    let breathe = app.create_id(&breathe, None).await;
    let motion = json!({
        "layers": [
            {"clip": base},
            {"clip": swing, "weight": 0.4, "offset": 0.3, "mask": {"joints": {"neck": 1}, "descendants": true}},
            {"clip": breathe, "mode": "additive", "weight": 0.6, "reference_time": 0.2}
        ],
        "ik": [{"kind": "two_bone", "joints": ["spine", "neck", "upper"], "target": [0.3, 0.8, 0.2]}]
    });
    let max_error = 1e-4;
    let open = |encoding: &str| {
        let mut msg =
            json!({"op": "open", "motion": motion, "fps": 30, "start": 0, "max_frames": 75, "encoding": encoding});
        if encoding == "compact" {
            msg["max_error"] = json!(max_error);
        }
        Message::Text(msg.to_string().into())
    };
    let (mut compact, mut plain) = (app.ws("/v1/stream").await, app.ws("/v1/stream").await);
    compact.send(open("compact")).await.unwrap();
    plain.send(open("protobuf")).await.unwrap();
    let (doc, frames, sizes) = compact_frames(&mut compact, 75).await;
    eprintln!("composed: key frame {} B, deltas {:?} B", sizes[0], &sizes[1..4]);
    let Message::Text(_) = next_message(&mut plain).await else { panic!("the protobuf stream's `opened` first") };
    let plain = protobuf_frames(&mut plain, 75).await;
    assert!(doc["bound"].as_f64().unwrap() <= max_error, "{doc}");
    // The IK's joints turn freely; the tip, which no layer or solver turns, stays constant.
    assert!(doc["joints"][1]["rotation"]["smallest_three"]["largest"].is_null(), "{}", doc["joints"][1]);
    assert!(doc["joints"][5]["rotation"]["constant"].is_array(), "{}", doc["joints"][5]);
    let l = layout(&doc);
    check_keys(&frames, l.key_interval);
    let (compared, keys, deltas) = compare(&frames, &plain, max_error, &l);
    assert!(compared >= 60 && keys >= 2 && deltas >= 40, "{compared} compared, {keys} keys, {deltas} deltas");

    // Controls: a crossfade brings a new layout, a layer ramp goes through.
    let mut ws = app.ws("/v1/stream").await;
    ws.send(Message::Text(
        json!({"op": "open", "motion": motion, "fps": 30, "encoding": "compact"}).to_string().into(),
    ))
    .await
    .unwrap();
    let doc = opened_layout(&mut ws).await;
    let mut decoder = Decoder { layout: layout(&doc), keys: None };
    let crossfade = json!({"op": "crossfade", "to": {"layers": [{"clip": swing}]}, "duration": 0.2});
    ws.send(Message::Text(crossfade.to_string().into())).await.unwrap();
    ws.send(Message::Text(r#"{"op":"layer","index":0,"weight":0.5,"duration":0.2}"#.into())).await.unwrap();
    // Both are taken (a refusal would be a text message among these
    // frames), and the frames go on decoding.
    let (more, _) = more_frames(&mut ws, &mut decoder, 35).await;
    assert_eq!(more.iter().filter(|d| d.new_layout).count(), 1, "one new layout, for the crossfade");
}

/// A graph broadcast (the Fox's locomotion) driven by `set` controls: a
/// compact viewer's frames decode within `max_error` of a protobuf viewer's
/// frames of the same ticks, through the transitions the sets fire.
#[tokio::test]
async fn a_graph_broadcast_with_set_controls_decodes_within_max_error() {
    let app = TestApp::start().await;
    let (graph, _) = crate::api::graph_samples::fox_graph(&app).await;
    let listed = app.get_json("/v1/graphs").await;
    let summary = listed["graphs"].as_array().unwrap().iter().find(|g| g["id"] == json!(graph)).unwrap();
    let parents = parents(&app, summary["clips"][0].as_str().unwrap()).await;
    let created = app.post_json("/v1/broadcasts", &json!({"motion": {"layers": [{"graph": graph}]}, "fps": 20})).await;
    let b = created["id"].as_str().unwrap_or_else(|| panic!("a broadcast: {created}")).to_owned();
    let max_error = 1e-3;
    let mut compact = app.ws(&format!("/v1/broadcasts/{b}/stream?encoding=compact&max_error={max_error}")).await;
    let mut plain = app.ws(&format!("/v1/broadcasts/{b}/stream?encoding=protobuf")).await;
    let plain = tokio::spawn(async move { protobuf_frames(&mut plain, 110).await });
    let doc = opened_layout(&mut compact).await;
    let l = layout(&doc);
    assert!(doc["bound"].as_f64().unwrap() <= max_error, "{doc}");
    let mut decoder = Decoder { layout: layout(&doc), keys: None };
    let app = &app;
    let set = |parameters: Value| {
        let url = app.url(&format!("/v1/broadcasts/{b}/controls"));
        let body = json!({"op": "set", "parameters": parameters});
        async move {
            let resp = app.http.post(url).json(&body).send().await.unwrap();
            assert!(resp.status().is_success(), "{}", resp.text().await.unwrap());
        }
    };
    let (mut frames, _) = more_frames(&mut compact, &mut decoder, 15).await;
    set(json!({"speed": 2.5})).await;
    frames.extend(more_frames(&mut compact, &mut decoder, 45).await.0);
    set(json!({"survey": true})).await;
    frames.extend(more_frames(&mut compact, &mut decoder, 40).await.0);
    check_keys(&frames, l.key_interval);
    let plain = plain.await.unwrap();
    let (compared, keys, _) = compare_on(&parents, &frames, &plain, max_error, &l);
    assert!(compared >= 80 && keys >= 4, "{compared} compared, {keys} key frames");
    // The sets moved the fox: the poses of the last ticks are not the idle's of the first.
    let (first, last) = (plain.values().next().unwrap(), plain.values().last().unwrap());
    assert!(worst(&parents, first, last, l.distance) > 0.01, "the graph left its idle");
}

// ------------------------------------------------- a new layout mid-stream

/// The walk (the arm clip) and a run of the same rig: a longer stride,
/// other scales, a wider turn of the lower joint.
async fn walk_and_run(app: &TestApp) -> (String, String) {
    let walk = app.create_id(&arm_clip(), None).await;
    let run = arm_variant(
        "run",
        json!([[0, 0, 0], [0.9, 0.3, -0.5], [0, 0, 0]]),
        json!([[1, 1, 1], [0.7, 1.2, 1.1], [1, 1, 1]]),
        1.4,
    );
    (walk, app.create_id(&run, None).await)
}

/// A two-bone IK on the arm's spine, neck and upper joints.
fn arm_ik() -> Value {
    json!([{"kind": "two_bone", "joints": ["spine", "neck", "upper"], "target": [0.3, 0.8, 0.2]}])
}

/// The seq of `plain` at the tick of `compact`'s `seq`: both streams
/// opened paused and took the same controls, then `play`, each at its own
/// tick; the first frame whose clip time went forward is the same tick
/// after play in both, matched by its clip time. (A crossfade taken while
/// paused moves the clip time back to its target's start, at whichever
/// of the frames read first it lands on.) Returns the shift from a
/// compact seq to a plain one, and the compact seq of that first frame.
fn aligned(compact: &[(u64, f32)], plain: &[(u64, f32)]) -> (i64, u64) {
    let moved = |frames: &[(u64, f32)]| {
        let at = frames.windows(2).position(|w| w[1].1 > w[0].1).expect("the clip time moves after play");
        frames[at + 1]
    };
    let (c, p) = (moved(compact), moved(plain));
    assert_eq!(c.1, p.1, "both streams' first frame after play shows the same clip time");
    (p.0 as i64 - c.0 as i64, c.0)
}

/// Holds every compact frame to the uncompressed frame of the same tick,
/// within its own layout's stated bound; returns how many were compared.
fn compare_shifted(
    compact: &[Decoded],
    plain: &BTreeMap<u64, Vec<Pose>>,
    (shift, from): (i64, u64),
    (max_error, distance): (f64, f64),
) -> usize {
    let mut compared = 0;
    for d in compact.iter().filter(|d| d.seq >= from) {
        assert!(d.bound <= max_error, "seq {}: a layout of bound {} over {max_error}", d.seq, d.bound);
        if let Some(p) = plain.get(&((d.seq as i64 + shift) as u64)) {
            let e = worst(&PARENTS, &d.pose, p, distance);
            assert!(e <= d.bound, "seq {} (key {}): {e} m off, over its layout's bound {}", d.seq, d.key, d.bound);
            compared += 1;
        }
    }
    compared
}

/// A compact stream of the walk crossfades to the run and takes an `ik`
/// control, each with a new layout sent before a key frame in it (docs:
/// "A new layout"); every frame decodes within its layout's bound of the
/// same stream's protobuf frames at the same tick.
#[tokio::test]
async fn a_websocket_compact_stream_crossfades_and_takes_ik_in_new_layouts() {
    use futures_util::SinkExt;
    let app = TestApp::start().await;
    let (walk, run) = walk_and_run(&app).await;
    let max_error = 1e-4;
    let open = |encoding: &str| {
        let motion = json!({"layers": [{"clip": walk}]});
        let mut msg =
            json!({"op": "open", "motion": motion, "fps": 30, "start": 0.3, "paused": true, "encoding": encoding});
        if encoding == "compact" {
            msg["max_error"] = json!(max_error);
        }
        Message::Text(msg.to_string().into())
    };
    let (mut compact, mut plain) = (app.ws("/v1/stream").await, app.ws("/v1/stream").await);
    compact.send(open("compact")).await.unwrap();
    plain.send(open("protobuf")).await.unwrap();
    let doc = opened_layout(&mut compact).await;
    let Message::Text(_) = next_message(&mut plain).await else { panic!("the protobuf stream's `opened` first") };
    assert!(doc["joints"][1]["rotation"]["smallest_three"]["largest"].is_u64(), "the walk's spine: {doc}");
    let crossfade = json!({"op": "crossfade", "to": {"layers": [{"clip": run}]}, "duration": 0.5});
    let ik = json!({"op": "ik", "constraints": arm_ik()});
    for ws in [&mut compact, &mut plain] {
        ws.send(Message::Text(crossfade.to_string().into())).await.unwrap();
        ws.send(Message::Text(ik.to_string().into())).await.unwrap();
    }
    let mut decoder = Decoder { layout: layout(&doc), keys: None };
    let (mut frames, _) = more_frames(&mut compact, &mut decoder, 6).await;
    let mut pb = whole_protobuf_frames(&mut plain, 6).await;
    for ws in [&mut compact, &mut plain] {
        ws.send(Message::Text(r#"{"op":"play"}"#.into())).await.unwrap();
    }
    frames.extend(more_frames(&mut compact, &mut decoder, 60).await.0);
    pb.extend(whole_protobuf_frames(&mut plain, 60).await);
    assert!(frames.iter().any(|d| d.new_layout), "a new layout");
    // The IK's joints turn freely in the layout the frames end in.
    assert!(
        decoder.layout.joints[1..4].iter().all(|j| matches!(j.rotation, Rotation::SmallestThree { largest: None, .. }))
    );
    let times: Vec<(u64, f32)> = frames.iter().map(|d| (d.seq, d.clip_time)).collect();
    let shift = aligned(&times, &pb.iter().map(|(s, f)| (*s, f.clip_time)).collect::<Vec<_>>());
    let plain: BTreeMap<u64, Vec<Pose>> = pb.iter().map(|(s, f)| (*s, pose_of_pb(f.pose.as_ref().unwrap()))).collect();
    let distance = doc["distance"].as_f64().unwrap();
    let compared = compare_shifted(&frames, &plain, shift, (max_error, distance));
    assert!(compared >= 40, "{compared} frames compared");
}

/// A `Play` call of `motion` opened paused at 0.3 s, and its frames.
async fn paused_play(
    app: &TestApp,
    motion: &pb::Motion,
    encoding: pb::FrameEncoding,
    max_error: Option<f64>,
) -> (tokio::sync::mpsc::Sender<pb::PlaybackControl>, tonic::Streaming<pb::Frame>) {
    use pb::playback_control::Op;
    let (tx, rx) = tokio::sync::mpsc::channel(8);
    let stream = pb::StreamRequest {
        fps: 30,
        start_time: Some(0.3),
        motion: Some(motion.clone()),
        encoding: encoding as i32,
        max_error,
        ..Default::default()
    };
    let open = Op::Open(pb::Open { stream: Some(stream), paused: true });
    tx.send(pb::PlaybackControl { op: Some(open) }).await.unwrap();
    let frames = app.grpc().await.play(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    (tx, frames)
}

/// The next `n` compact `Frame`s of a gRPC stream, decoded; a layout in
/// `compact_layout` after the first frame is a new one, its frame a key
/// frame in it.
async fn grpc_compact_frames(
    frames: &mut tonic::Streaming<pb::Frame>,
    decoder: &mut Option<Decoder>,
    n: usize,
) -> Vec<Decoded> {
    let mut out = Vec::new();
    while out.len() < n {
        let f = within(5, "a compact frame", frames.message()).await.unwrap().expect("a frame");
        let new_layout = !f.compact_layout.is_empty() && decoder.is_some();
        if !f.compact_layout.is_empty() {
            let doc: Value = serde_json::from_str(&f.compact_layout).unwrap();
            decoder.get_or_insert_with(|| Decoder { layout: layout(&doc), keys: None }).relayout(&doc);
        }
        let d = Decoded { new_layout, ..decoder.as_mut().expect("the layout on the first frame").decode(&f.compact) };
        assert!(!new_layout || d.key, "seq {}: the first frame in a new layout is a key frame", d.seq);
        out.push(d);
    }
    out
}

/// The gRPC `Play` twin of the WebSocket test above: a crossfade and an
/// `ik` control bring new layouts in `compact_layout`, and every frame
/// decodes within its layout's bound of a protobuf `Play` of the same.
#[tokio::test]
async fn a_grpc_compact_play_crossfades_and_takes_ik_in_new_layouts() {
    use pb::playback_control::Op;
    let app = TestApp::start().await;
    let (walk, run) = walk_and_run(&app).await;
    let motion = |clip: &str| pb::Motion {
        layers: vec![pb::Layer { clip_id: clip.to_owned(), ..Default::default() }],
        ..Default::default()
    };
    let max_error = 1e-4;
    let (ctx, mut compact) = paused_play(&app, &motion(&walk), pb::FrameEncoding::Compact, Some(max_error)).await;
    let (ptx, mut plain) = paused_play(&app, &motion(&walk), pb::FrameEncoding::Protobuf, None).await;
    let v3 = |[x, y, z]: [f32; 3]| pb::Vec3 { x, y, z };
    let ik = pb::IkConstraint {
        kind: Some(pb::ik_constraint::Kind::TwoBone(pb::IkTwoBone {
            joints: vec!["spine".into(), "neck".into(), "upper".into()],
            target: Some(pb::IkTarget { target: Some(pb::ik_target::Target::Point(v3([0.3, 0.8, 0.2]))) }),
            pole: None,
            weight: None,
        })),
    };
    // Frames of the walk first, so that the controls come mid-stream.
    let mut decoder = None;
    let mut frames = grpc_compact_frames(&mut compact, &mut decoder, 2).await;
    let mut pb = BTreeMap::new();
    while pb.len() < 2 {
        let f = within(5, "a frame", plain.message()).await.unwrap().expect("a frame");
        pb.insert(f.seq, f);
    }
    for tx in [&ctx, &ptx] {
        let fade = Op::Crossfade(pb::Crossfade { to: Some(motion(&run)), duration: 0.5, ease: 0 });
        tx.send(pb::PlaybackControl { op: Some(fade) }).await.unwrap();
        let ik = Op::Ik(pb::IkControl { constraints: vec![ik.clone()] });
        tx.send(pb::PlaybackControl { op: Some(ik) }).await.unwrap();
    }
    frames.extend(grpc_compact_frames(&mut compact, &mut decoder, 6).await);
    while pb.len() < 8 {
        let f = within(5, "a frame", plain.message()).await.unwrap().expect("a frame");
        pb.insert(f.seq, f);
    }
    for tx in [&ctx, &ptx] {
        tx.send(pb::PlaybackControl { op: Some(Op::Play(pb::Resume {})) }).await.unwrap();
    }
    frames.extend(grpc_compact_frames(&mut compact, &mut decoder, 60).await);
    while pb.len() < 68 {
        let f = within(5, "a frame", plain.message()).await.unwrap().expect("a frame");
        pb.insert(f.seq, f);
    }
    assert!(frames.iter().any(|d| d.new_layout), "a new layout");
    let l = &decoder.unwrap().layout;
    assert!(l.joints[1..4].iter().all(|j| matches!(j.rotation, Rotation::SmallestThree { largest: None, .. })));
    let times: Vec<(u64, f32)> = frames.iter().map(|d| (d.seq, d.clip_time)).collect();
    let shift = aligned(&times, &pb.iter().map(|(s, f)| (*s, f.clip_time)).collect::<Vec<_>>());
    let plain: BTreeMap<u64, Vec<Pose>> = pb.iter().map(|(s, f)| (*s, pose_of_pb(f.pose.as_ref().unwrap()))).collect();
    let compared = compare_shifted(&frames, &plain, shift, (max_error, l.distance));
    assert!(compared >= 40, "{compared} frames compared");
}

/// Choosing a new layout is priced as the open's layout is (docs:
/// "Price"): a crossfade to a clip so long that its range samples cost
/// more than `max_request_work` is refused `too_much_work` before any work,
/// and the stream goes on in its layout, holding what it held.
#[tokio::test]
async fn a_new_layout_over_the_request_limit_is_refused_and_the_stream_goes_on() {
    use futures_util::SinkExt;
    let app = TestApp::builder().configure(|c| c.limits.max_request_work = 100_000).start().await;
    let walk = app.create_id(&arm_clip(), None).await;
    // The arm slowed fifty times: 100 s, so 24,001 grid samples of a six-joint pose (7 units each) and more.
    let mut slow: Value = serde_json::from_str(&arm_clip()).unwrap();
    for track in slow["tracks"].as_array_mut().unwrap() {
        let times: Vec<f64> = track["times"].as_array().unwrap().iter().map(|t| t.as_f64().unwrap() * 50.0).collect();
        track["times"] = json!(times);
    }
    slow["name"] = json!("slow arm");
    let slow = app.create_id(&slow.to_string(), None).await;
    let mut ws = app.ws("/v1/stream").await;
    let open = json!({"op": "open", "motion": {"layers": [{"clip": walk}]}, "fps": 30, "encoding": "compact"});
    ws.send(Message::Text(open.to_string().into())).await.unwrap();
    let doc = opened_layout(&mut ws).await;
    let mut decoder = Decoder { layout: layout(&doc), keys: None };
    drop(more_frames(&mut ws, &mut decoder, 2).await);
    let held = app.state.work.meter().held();
    let fade = json!({"op": "crossfade", "to": {"layers": [{"clip": slow}]}, "duration": 0.2});
    ws.send(Message::Text(fade.to_string().into())).await.unwrap();
    let problem = loop {
        match next_message(&mut ws).await {
            Message::Binary(b) => drop(decoder.decode(&b)),
            Message::Text(t) => break serde_json::from_str::<Value>(&t).unwrap()["error"].clone(),
            other => panic!("{other:?}"),
        }
    };
    assert_eq!((problem["code"].as_str(), problem["status"].as_u64()), (Some("too_much_work"), Some(422)), "{problem}");
    let units: u64 = problem["detail"]
        .as_str()
        .unwrap()
        .split(" costs ")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(units >= 24_001 * 7, "{problem}");
    let (frames, _) = more_frames(&mut ws, &mut decoder, 5).await;
    assert!(frames.iter().all(|d| !d.new_layout), "the stream goes on in its layout");
    assert_eq!(app.state.work.meter().held(), held, "holding what it held");
}

// ------------------------------------------- derived ranges and graph reports

/// A stream opened on `GET /v1/stream` with `open` and `encoding`; its
/// `opened` message read.
async fn open_stream(app: &TestApp, open: &Value, encoding: &str) -> (Ws, Value) {
    use futures_util::SinkExt;
    let mut ws = app.ws("/v1/stream").await;
    let mut msg = open.clone();
    msg["encoding"] = json!(encoding);
    ws.send(Message::Text(msg.to_string().into())).await.unwrap();
    let Message::Text(opened) = next_message(&mut ws).await else { panic!("the `opened` message first") };
    let opened: Value = serde_json::from_str(&opened).unwrap();
    assert!(opened.get("opened").is_some(), "{msg}: {opened}");
    (ws, opened)
}

/// The stream `open` opened twice, in compact and in protobuf frames: both
/// sockets, the compact one's layout document and a decoder of it.
async fn compact_and_protobuf(app: &TestApp, open: &Value) -> (Ws, Ws, Value, Decoder) {
    let ((compact, opened), (plain, _)) =
        (open_stream(app, open, "compact").await, open_stream(app, open, "protobuf").await);
    let doc = opened["opened"]["compact"].clone();
    let decoder = Decoder { layout: layout(&doc), keys: None };
    (compact, plain, doc, decoder)
}

/// A character's parents by index, from its skeleton's joints.
async fn character_parents(app: &TestApp, character: &str) -> Vec<Option<usize>> {
    let joints = app.get_json(&format!("/v1/characters/{character}")).await["skeleton"]["joints"].clone();
    let joints = joints.as_array().unwrap();
    let names: Vec<&str> = joints.iter().map(|j| j["name"].as_str().unwrap()).collect();
    let index = |p: &str| names.iter().position(|n| *n == p).unwrap();
    joints.iter().map(|j| j["parent"].as_str().map(index)).collect()
}

/// A CMU take played on CesiumMan (retargeted, feet planted, with and without
/// root motion `extract`) streamed compact: each frame decodes within the
/// layout's `max_error` of the protobuf frame of the same tick (docs/
/// compact-frames.md, “What a compact stream plays”).
#[tokio::test]
async fn a_take_on_a_character_streams_compact_within_max_error_of_its_protobuf_frames() {
    let app = TestApp::start().await;
    let (take, cesium) = crate::api::character_routes::take_and_cesium(&app).await;
    let parents = character_parents(&app, &cesium).await;
    for root in [json!(null), json!({"mode": "extract"})] {
        let mut motion = json!({"layers": [{"clip": take}], "character": cesium, "retarget": {"feet": "plant"}});
        if !root.is_null() {
            motion["root_motion"] = root.clone();
        }
        let open = json!({"op": "open", "motion": motion, "fps": 30, "start": 0.5, "max_frames": 60});
        let (mut compact, mut plain, doc, mut decoder) = compact_and_protobuf(&app, &open).await;
        let max_error = doc["max_error"].as_f64().unwrap();
        assert!(doc["bound"].as_f64().unwrap() <= max_error, "{doc}");
        let l = layout(&doc);
        let (frames, sizes) = more_frames(&mut compact, &mut decoder, 60).await;
        let plain = protobuf_frames(&mut plain, 60).await;
        check_keys(&frames, l.key_interval);
        let (compared, keys, deltas) = compare_on(&parents, &frames, &plain, max_error, &l);
        assert!(
            compared >= 30 && keys >= 1 && deltas >= 20,
            "{root}: {compared} compared, {keys} keys, {deltas} deltas"
        );
        assert_eq!(frames.iter().all(|d| d.root_motion.is_some()), !root.is_null(), "{root}: the root motion section");
        eprintln!("131_01 on CesiumMan, root motion {root}: key frame {} B, deltas {:?} B", sizes[0], &sizes[1..4]);
    }
}

/// A motion with root motion `extract` streamed compact: the root kept in
/// place decodes within `max_error` of the protobuf frames, and the root
/// motion section is theirs.
#[tokio::test]
async fn an_extracted_root_streams_compact_within_max_error_of_its_protobuf_frames() {
    let app = TestApp::start().await;
    let id = app.create_id(&stepping_arm_clip(), None).await;
    let motion = json!({"layers": [{"clip": id}], "root_motion": {"joint": "root", "mode": "extract"}});
    let open = json!({"op": "open", "motion": motion, "fps": 30, "start": 0, "max_frames": 70});
    let (mut compact, mut plain, doc, mut decoder) = compact_and_protobuf(&app, &open).await;
    let l = layout(&doc);
    let (frames, _) = more_frames(&mut compact, &mut decoder, 70).await;
    let whole = whole_protobuf_frames(&mut plain, 70).await;
    let poses = whole.iter().map(|(seq, f)| (*seq, pose_of_pb(f.pose.as_ref().unwrap()))).collect();
    let (compared, _, _) = compare(&frames, &poses, doc["max_error"].as_f64().unwrap(), &l);
    assert!(compared >= 35, "{compared} frames compared");
    let mut reports = 0;
    for (d, p) in both_played(&frames, &whole) {
        let r = p.pose.as_ref().unwrap().root_motion.expect("the protobuf frame reports root motion");
        let total = r.total.unwrap_or_default();
        let got = d.root_motion.unwrap_or_else(|| panic!("seq {}: no root motion section", d.seq));
        assert_eq!(got[4..].to_vec(), [total.x, total.y, total.z, total.yaw].map(|v| v as f32).to_vec());
        reports += 1;
    }
    assert!(reports >= 30, "{reports} reports compared");
}

/// The JSON frames of `ws` until one of seq `until` or later: seq → frame.
async fn json_frames_until(ws: &mut Ws, until: u64) -> BTreeMap<u64, Value> {
    let mut out = BTreeMap::new();
    loop {
        let Message::Text(text) = next_message(ws).await else { panic!("a JSON frame") };
        let frame: Value = serde_json::from_str(&text).unwrap();
        let Some(seq) = frame["seq"].as_u64() else { continue };
        out.insert(seq, frame);
        if seq >= until {
            return out;
        }
    }
}

/// A compact frame's graph report, named through the layout's `graph`, as
/// a JSON frame's `graph` member states it (weights as f32s).
fn named_report(doc: &Value, (state, transition, weights): &Report) -> Value {
    let states = &doc["graph"]["states"];
    let mut report = json!({"state": states[*state as usize]});
    if let Some((from, to, alpha)) = transition {
        report["transition"] = json!({"from": states[*from as usize], "to": states[*to as usize], "alpha": alpha});
    }
    let nodes = &doc["graph"]["nodes"];
    let weights: serde_json::Map<String, Value> =
        weights.iter().map(|(n, w)| (nodes[*n as usize]["name"].as_str().unwrap().to_owned(), json!(w))).collect();
    report["weights"] = Value::Object(weights);
    report
}

/// A report with its numbers rounded to f32 (as a compact frame sends them)
/// and no null members.
fn report_as_f32(report: &Value) -> Value {
    match report {
        Value::Number(n) => json!(n.as_f64().unwrap() as f32),
        Value::Array(a) => Value::Array(a.iter().map(report_as_f32).collect()),
        Value::Object(o) => {
            Value::Object(o.iter().filter(|(_, v)| !v.is_null()).map(|(k, v)| (k.clone(), report_as_f32(v))).collect())
        }
        other => other.clone(),
    }
}

/// A graph broadcast with `report` watched in compact frames and in JSON:
/// every tick both show carries the same report (states, a transition, blend
/// weights as f32s) as the Fox goes from idle to a run and into a look.
#[tokio::test]
async fn a_compact_graph_watch_carries_the_json_frames_report() {
    let app = TestApp::start().await;
    let (graph, _) = crate::api::graph_samples::fox_graph(&app).await;
    let body = json!({"motion": {"layers": [{"graph": graph}]}, "fps": 30, "report": true});
    let resp = app.http.post(app.url("/v1/broadcasts")).json(&body).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    let mut compact = app.ws(&format!("/v1/broadcasts/{id}/stream?encoding=compact")).await;
    let mut plain = app.ws(&format!("/v1/broadcasts/{id}/stream")).await;
    let doc = opened_layout(&mut compact).await;
    assert_eq!(doc["graph"]["states"], json!(["idle", "look", "move"]), "the graph's states in its order");
    let mut decoder = Decoder { layout: layout(&doc), keys: None };
    let (mut frames, _) = more_frames(&mut compact, &mut decoder, 1).await;
    let controls = format!("/v1/broadcasts/{id}/controls");
    let set = |parameters: Value| json!({"op": "set", "parameters": parameters});
    let speed = app.post_json(&controls, &set(json!({"speed": 2.5}))).await["seq"].as_u64().unwrap();
    let mut plain_frames = json_frames_until(&mut plain, speed + 15).await;
    let survey = app.post_json(&controls, &set(json!({"survey": true}))).await["seq"].as_u64().unwrap();
    plain_frames.extend(json_frames_until(&mut plain, survey + 15).await);
    while frames.last().unwrap().seq < survey + 15 {
        frames.extend(more_frames(&mut compact, &mut decoder, 1).await.0);
    }
    let (mut compared, mut transitions, mut states) = (0, 0, std::collections::BTreeSet::new());
    for d in &frames {
        let Some(p) = plain_frames.get(&d.seq) else { continue };
        let report = d.graph.as_ref().unwrap_or_else(|| panic!("seq {}: no graph report section", d.seq));
        assert_eq!(report_as_f32(&named_report(&doc, report)), report_as_f32(&p["graph"]), "seq {}", d.seq);
        compared += 1;
        transitions += usize::from(report.1.is_some());
        states.insert(report.0);
    }
    assert!(
        compared >= 20 && transitions >= 3 && states.len() == 3,
        "{compared} compared, {transitions} in a transition, states {states:?}"
    );
}

// ------------------------------------------------ a broadcast's new layouts

/// The JSON frame's local pose (f32 values, as the server evaluated them).
fn pose_of_json(frame: &Value) -> Vec<Pose> {
    let v = |x: &Value| x.as_f64().unwrap();
    let joints = frame["pose"]["joints"].as_array().expect("a JSON frame's pose");
    let three = |x: &Value| std::array::from_fn(|k| v(&x[k]));
    joints
        .iter()
        .map(|j| (three(&j["translation"]), std::array::from_fn(|k| v(&j["rotation"][k])), three(&j["scale"])))
        .collect()
}

/// Holds each compact frame to the JSON frame of the same `seq` within its
/// layout's stated bound (itself within `max_error`); returns how many.
fn compare_json(compact: &[Decoded], json: &BTreeMap<u64, Value>, max_error: f64, distance: f64) -> usize {
    let mut compared = 0;
    for d in compact {
        assert!(d.bound <= max_error, "seq {}: a layout of bound {} over {max_error}", d.seq, d.bound);
        if let Some(frame) = json.get(&d.seq) {
            let e = worst(&PARENTS, &d.pose, &pose_of_json(frame), distance);
            assert!(e <= d.bound, "seq {} (key {}): {e} m off, over its layout's bound {}", d.seq, d.key, d.bound);
            compared += 1;
        }
    }
    compared
}

/// Whether the layout turns the arm's spine, neck and upper joints freely
/// (the two-bone IK's joints: `largest: null`).
fn ik_free(doc: &Value) -> bool {
    (1..4).all(|j| doc["joints"][j]["rotation"]["smallest_three"]["largest"].is_null())
}

/// Creates a broadcast of `clip` at 20 fps; returns its id.
async fn arm_broadcast(app: &TestApp, clip: &str) -> String {
    let created = app.post_json("/v1/broadcasts", &json!({"motion": {"layers": [{"clip": clip}]}, "fps": 20})).await;
    created["id"].as_str().unwrap_or_else(|| panic!("a broadcast: {created}")).to_owned()
}

/// Posts the crossfade to `run` and the arm's IK to broadcast `b`; returns the later stamp.
async fn fade_and_aim(app: &TestApp, b: &str, run: &str) -> u64 {
    let mut stamp = 0;
    let fade = json!({"op": "crossfade", "to": {"layers": [{"clip": run}]}, "duration": 0.5});
    for control in [fade, json!({"op": "ik", "constraints": arm_ik()})] {
        let resp = app.http.post(app.url(&format!("/v1/broadcasts/{b}/controls"))).json(&control).send().await.unwrap();
        let status = resp.status().as_u16();
        let answer: Value = resp.json().await.unwrap();
        assert_eq!(status, 200, "{answer}");
        stamp = answer["seq"].as_u64().unwrap();
    }
    stamp
}

/// docs/compact-frames.md "A broadcast's layouts": while a compact viewer
/// watches, a crossfade and an `ik` control make the broadcast send it a
/// new layout followed by a key frame in it; every frame decodes within its
/// layout's bound of a JSON viewer's frame of the same `seq`; and a compact
/// watch opened after the controls gets a layout that holds all of it.
#[tokio::test]
async fn a_broadcast_crossfades_and_takes_ik_in_new_compact_layouts() {
    let app = TestApp::start().await;
    let (walk, run) = walk_and_run(&app).await;
    let b = arm_broadcast(&app, &walk).await;
    let max_error = 1e-4;
    let mut compact = app.ws(&format!("/v1/broadcasts/{b}/stream?encoding=compact&max_error={max_error}")).await;
    let mut plain = app.ws(&format!("/v1/broadcasts/{b}/stream")).await;
    let doc = opened_layout(&mut compact).await;
    assert!(!ik_free(&doc), "the walk's own layout: {doc}");
    let mut decoder = Decoder { layout: layout(&doc), keys: None };
    let (mut frames, _) = more_frames(&mut compact, &mut decoder, 5).await;
    let stamp = fade_and_aim(&app, &b, &run).await;
    frames.extend(more_frames(&mut compact, &mut decoder, 50).await.0);
    let json = json_frames_until(&mut plain, frames.last().unwrap().seq).await;
    assert!(frames.iter().any(|d| d.new_layout), "a new layout");
    assert!(frames.iter().filter(|d| d.seq > stamp).count() >= 30, "frames after the controls");
    assert!(
        decoder.layout.joints[1..4].iter().all(|j| matches!(j.rotation, Rotation::SmallestThree { largest: None, .. })),
        "the IK's joints turn freely in the layout the frames end in"
    );
    let compared = compare_json(&frames, &json, max_error, doc["distance"].as_f64().unwrap());
    assert!(compared >= 40, "{compared} frames compared");
    // A watch opened afterwards: its layout holds what was played, and no new one follows.
    let mut late = app.ws(&format!("/v1/broadcasts/{b}/stream?encoding=compact&max_error={max_error}")).await;
    let late_doc = opened_layout(&mut late).await;
    assert!(ik_free(&late_doc), "the late watch's layout frees the IK's joints: {late_doc}");
    let mut late_decoder = Decoder { layout: layout(&late_doc), keys: None };
    let (late_frames, _) = more_frames(&mut late, &mut late_decoder, 20).await;
    assert!(late_frames.iter().all(|d| !d.new_layout), "its first layout holds the broadcast");
    let json = json_frames_until(&mut plain, late_frames.last().unwrap().seq).await;
    assert!(compare_json(&late_frames, &json, max_error, late_doc["distance"].as_f64().unwrap()) >= 15);
}

/// A broadcast that crossfaded and took `ik` under a compact viewer, resumed
/// after a restart from its stored checkpoint (which carries what it
/// played): a compact watch gets the very layout document it had before,
/// and its frames decode within the bound of the restarted node's JSON frames.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broadcast_restored_from_its_checkpoint_sends_the_same_compact_layout() {
    let data = tempfile::tempdir().unwrap();
    let every_second =
        |c: &mut server::config::Config| c.limits.broadcast_checkpoint = std::time::Duration::from_secs(1);
    let app = TestApp::builder().data_dir(data.path()).configure(every_second).start().await;
    let (walk, run) = walk_and_run(&app).await;
    let b = arm_broadcast(&app, &walk).await;
    let watch = format!("/v1/broadcasts/{b}/stream?encoding=compact");
    let mut compact = app.ws(&watch).await;
    let doc = opened_layout(&mut compact).await;
    let mut decoder = Decoder { layout: layout(&doc), keys: None };
    drop(more_frames(&mut compact, &mut decoder, 3).await);
    let stamp = fade_and_aim(&app, &b, &run).await;
    let (frames, _) = more_frames(&mut compact, &mut decoder, 10).await;
    assert!(frames.iter().any(|d| d.new_layout), "a new layout before the restart");
    let mut before = app.ws(&watch).await;
    let before = opened_layout(&mut before).await;
    assert!(ik_free(&before), "{before}");
    // A checkpoint of a tick after the controls is stored (the controls it names kept with it).
    let store = std::sync::Arc::clone(&app.state.store);
    crate::common::eventually(std::time::Duration::from_secs(10), "a checkpoint after the controls", || async {
        store.broadcast_checkpoint(&b).await.unwrap().is_some_and(|c| c.seq > stamp)
    })
    .await;
    drop(compact);
    app.stop().await;

    let app = TestApp::builder().data_dir(data.path()).configure(every_second).start().await;
    let summary = app.url(&format!("/v1/broadcasts/{b}"));
    crate::common::eventually(std::time::Duration::from_secs(5), "the resumed broadcast", || async {
        app.http.get(&summary).send().await.unwrap().status() == 200
    })
    .await;
    let mut compact = app.ws(&watch).await;
    let mut plain = app.ws(&format!("/v1/broadcasts/{b}/stream")).await;
    let after = opened_layout(&mut compact).await;
    assert_eq!(after, before, "the same layout document after the restart");
    let mut decoder = Decoder { layout: layout(&after), keys: None };
    let (frames, _) = more_frames(&mut compact, &mut decoder, 20).await;
    assert!(frames.iter().all(|d| !d.new_layout), "it holds the broadcast");
    let json = json_frames_until(&mut plain, frames.last().unwrap().seq).await;
    assert!(compare_json(&frames, &json, 1e-4, after["distance"].as_f64().unwrap()) >= 15);
    app.stop().await;
}
