//! The JSON clip document and pose rendering (docs/clip-format.md §1 and docs/api.md).
//!
//! [`ClipDoc`] is the clip as it travels: parsed strictly (unknown fields are
//! refused, so a typo is an error rather than a silently ignored option),
//! converted to the core's [`ClipSpec`], and back again for imports and for
//! `GET /v1/clips/{id}`. Every error carries the JSON pointer of the field at
//! fault. Quaternions are `[x, y, z, w]` here and everywhere.

use bytes::BufMut;
use glam::{Mat4, Quat, Vec3, Vec4};
use serde::ser::{SerializeMap, SerializeSeq};
use serde::{Deserialize, Serialize, Serializer};

use super::doc::keys_doc;
pub use super::doc::{ChannelDoc, DocError, EaseDoc, EndsDoc, InterpolationDoc, PlaybackDoc, SpaceDoc, SpeedDoc};
pub use super::float::write_float;
use super::float::{common_text, finite_stand_in};
use super::ik::IkDoc;
use super::spring::{SpringDoc, springs_spec};
use anim::character::{FootReport, Side};
use anim::ik::IkReport;
use anim::motion::{Planar, RootMotion};
use anim::spring::SpringsSpec;
use anim::{
    Channel, ClipSpec, EventSpec, JointSpec, Keys, ParameterLayout, ParameterSpec, Pose, Skeleton, SkeletonSpec, Space,
    Transform,
};

/// A clip document: joints' keyframe tracks, an optional skeleton, events,
/// parameters and IK constraints, as `docs/clip-format.md` describes them
/// (with the evaluation math every pose follows).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ClipDoc {
    pub name: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skeleton: Option<SkeletonDoc>,
    pub tracks: Vec<TrackDoc>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub events: Vec<EventDoc>,
    #[serde(default)]
    pub playback: PlaybackDoc,
    /// IK constraints solved at every sample (`docs/ik.md`), targets and weights
    /// fixed or keyed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ik: Vec<IkDoc>,
    /// Named tracks that are not joints (docs/clip-format.md §3): morph weights, a
    /// camera's field of view. Poses carry their values under `parameters`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parameters: Vec<ParameterDoc>,
    /// Spring chains on the clip's skeleton (`docs/springs.md`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub springs: Vec<SpringDoc>,
    /// Labels to find the clip by (`GET /v1/clips?tag=`); never evaluated.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tags: Vec<String>,
    /// Free-form JSON object kept with the clip (source, author, licence…);
    /// never evaluated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Object>)]
    pub metadata: Option<serde_json::Map<String, serde_json::Value>>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SkeletonDoc {
    pub joints: Vec<JointDoc>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JointDoc {
    pub name: String,
    #[serde(default)]
    pub parent: Option<String>,
    #[serde(default, skip_serializing_if = "RestDoc::is_identity")]
    pub rest: RestDoc,
    /// Column-major 4×4, as glTF stores it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 16, max_items = 16)]
    pub inverse_bind: Option<[f32; 16]>,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RestDoc {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 3, max_items = 3)]
    pub translation: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 4, max_items = 4)]
    pub rotation: Option<[f32; 4]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(min_items = 3, max_items = 3)]
    pub scale: Option<[f32; 3]>,
}

impl RestDoc {
    fn is_identity(&self) -> bool {
        self.translation.is_none() && self.rotation.is_none() && self.scale.is_none()
    }
}

keys_doc!(TrackDoc { joint: String, channel: ChannelDoc });

/// A parameter track (docs/clip-format.md §3): every key a row of the same width
/// (1 to 256 numbers), each number interpolated as a translation component.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ParameterDoc {
    /// Unique among the clip's parameters; glTF morph weights take their node's name.
    pub name: String,
    /// `step`, `linear` (default), `catmull_rom`, `cubic_hermite` or `b_spline`.
    #[serde(default)]
    pub interpolation: InterpolationDoc,
    pub times: Vec<f32>,
    /// One row per time, all of one width.
    pub values: Vec<Vec<f32>>,
    /// `cubic_hermite` only: one row per key, units per second.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub in_tangents: Option<Vec<Vec<f32>>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub out_tangents: Option<Vec<Vec<f32>>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ends: Option<EndsDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tension: Option<f32>,
}

impl ParameterDoc {
    fn to_spec(&self) -> ParameterSpec {
        ParameterSpec {
            name: self.name.clone(),
            interpolation: self.interpolation.into(),
            times: self.times.clone(),
            values: self.values.clone(),
            in_tangents: self.in_tangents.clone(),
            out_tangents: self.out_tangents.clone(),
            ends: self.ends.map(Into::into),
            tension: self.tension,
        }
    }

    fn from_spec(p: &ParameterSpec) -> ParameterDoc {
        ParameterDoc {
            name: p.name.clone(),
            interpolation: p.interpolation.into(),
            times: p.times.clone(),
            values: p.values.clone(),
            in_tangents: p.in_tangents.clone(),
            out_tangents: p.out_tangents.clone(),
            ends: p.ends.map(Into::into),
            tension: p.tension,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct EventDoc {
    pub time: f32,
    pub name: String,
}

/// Parses a clip document, reporting the JSON pointer of any type error.
pub fn parse_clip_doc(body: &[u8]) -> Result<ClipDoc, DocError> {
    parse_document(body)
}

/// Parses one JSON document of type `T` (clip, character), reporting the
/// JSON pointer of any type error; only whitespace may follow it.
pub(crate) fn parse_document<T: serde::de::DeserializeOwned>(body: &[u8]) -> Result<T, DocError> {
    let de = &mut serde_json::Deserializer::from_slice(body);
    let doc: T = serde_path_to_error::deserialize(&mut *de).map_err(|e| {
        let pointer = pointer_of(e.path());
        let inner = e.into_inner();
        let code = if inner.is_syntax() || inner.is_eof() { "malformed_json" } else { "invalid_field" };
        DocError { code, pointer, detail: inner.to_string() }
    })?;
    // Only whitespace may follow the document: `{...} x` is not a document.
    de.end().map_err(|e| DocError { code: "malformed_json", pointer: String::new(), detail: e.to_string() })?;
    Ok(doc)
}

fn pointer_of(path: &serde_path_to_error::Path) -> String {
    use serde_path_to_error::Segment;
    let mut s = String::new();
    for seg in path.iter() {
        match seg {
            Segment::Seq { index } => s.push_str(&format!("/{index}")),
            Segment::Map { key } => s.push_str(&format!("/{}", key.replace('~', "~0").replace('/', "~1"))),
            Segment::Enum { variant } => s.push_str(&format!("/{variant}")),
            Segment::Unknown => {}
        }
    }
    s
}

fn keys(rows: &[Vec<f32>], width: usize, pointer: &str, channel: Channel) -> Result<Keys, DocError> {
    if let Some((i, row)) = rows.iter().enumerate().find(|(_, r)| r.len() != width) {
        return Err(DocError {
            code: "wrong_width",
            pointer: format!("{pointer}/{i}"),
            detail: format!("a {} key has {width} numbers, got {}", channel.as_str(), row.len()),
        });
    }
    Ok(if width == 4 {
        Keys::Vec4(rows.iter().map(|r| Vec4::from_slice(r)).collect())
    } else {
        Keys::Vec3(rows.iter().map(|r| Vec3::from_slice(r)).collect())
    })
}

impl ClipDoc {
    /// The core's authoring form of this document.
    ///
    /// # Errors
    /// Key rows of the wrong width (the only rule the document's shape can
    /// break that the core cannot see); everything else is
    /// [`anim::Clip::build`]'s to judge.
    pub fn to_spec(&self) -> Result<ClipSpec, DocError> {
        let skeleton = self.skeleton.as_ref().map(|s| SkeletonSpec {
            joints: s
                .joints
                .iter()
                .map(|j| JointSpec {
                    name: j.name.clone(),
                    parent: j.parent.clone(),
                    rest: Transform {
                        translation: j.rest.translation.map_or(Vec3::ZERO, Vec3::from),
                        rotation: j.rest.rotation.map_or(Quat::IDENTITY, Quat::from_array),
                        scale: j.rest.scale.map_or(Vec3::ONE, Vec3::from),
                    },
                    inverse_bind: j.inverse_bind.map(|m| Mat4::from_cols_array(&m)),
                })
                .collect(),
        });
        let mut tracks = Vec::with_capacity(self.tracks.len());
        for (i, t) in self.tracks.iter().enumerate() {
            let channel = Channel::from(t.channel);
            let width = channel.width();
            let rows = |rows: &[Vec<f32>], field: &str| keys(rows, width, &format!("/tracks/{i}/{field}"), channel);
            tracks.push(t.keys_to_track((t.joint.clone(), channel), rows)?);
        }
        Ok(ClipSpec {
            name: self.name.clone(),
            skeleton,
            tracks,
            events: self.events.iter().map(|e| EventSpec { time: e.time, name: e.name.clone() }).collect(),
            playback: self.playback.into(),
            ik: (self.ik.iter().enumerate())
                .map(|(i, c)| c.to_keyed_spec(&format!("/ik/{i}")))
                .collect::<Result<_, _>>()?,
            parameters: self.parameters.iter().map(ParameterDoc::to_spec).collect(),
        })
    }

    /// The document for a spec (importers produce specs; clients get JSON).
    pub fn from_spec(spec: &ClipSpec) -> ClipDoc {
        let rows = |k: &Keys| -> Vec<Vec<f32>> {
            match k {
                Keys::Vec3(v) => v.iter().map(|x| x.to_array().to_vec()).collect(),
                Keys::Vec4(v) => v.iter().map(|x| x.to_array().to_vec()).collect(),
            }
        };
        let not = |v: bool| if v { None } else { Some(()) };
        ClipDoc {
            name: spec.name.clone(),
            skeleton: spec.skeleton.as_ref().map(|s| SkeletonDoc {
                joints: s
                    .joints
                    .iter()
                    .map(|j| JointDoc {
                        name: j.name.clone(),
                        parent: j.parent.clone(),
                        rest: RestDoc {
                            translation: not(j.rest.translation == Vec3::ZERO).map(|_| j.rest.translation.to_array()),
                            rotation: not(j.rest.rotation == Quat::IDENTITY).map(|_| j.rest.rotation.to_array()),
                            scale: not(j.rest.scale == Vec3::ONE).map(|_| j.rest.scale.to_array()),
                        },
                        inverse_bind: j.inverse_bind.map(|m| m.to_cols_array()),
                    })
                    .collect(),
            }),
            tracks: spec
                .tracks
                .iter()
                .map(|t| TrackDoc::keys_of_track(t, rows, t.joint.clone(), t.channel.into()))
                .collect(),
            events: spec.events.iter().map(|e| EventDoc { time: e.time, name: e.name.clone() }).collect(),
            playback: spec.playback.into(),
            ik: spec.ik.iter().map(IkDoc::from_keyed_spec).collect(),
            parameters: spec.parameters.iter().map(ParameterDoc::from_spec).collect(),
            springs: Vec::new(),
            tags: Vec::new(),
            metadata: None,
        }
    }
}

impl ClipDoc {
    /// The clip's spring chains in the core's form (substeps at the default
    /// rate), the rules that need no skeleton checked; compile them against
    /// the built clip's skeleton with [`super::spring::compile_springs`].
    ///
    /// # Errors
    /// A chain that breaks a rule of `docs/springs.md`, at its pointer.
    pub fn springs(&self) -> Result<SpringsSpec, DocError> {
        springs_spec(&self.springs, None, "")
    }
}

/// Parses and converts in one step: body bytes to the core's [`ClipSpec`].
pub fn parse_clip(body: &[u8]) -> Result<(ClipDoc, ClipSpec), DocError> {
    let doc = parse_clip_doc(body)?;
    let spec = doc.to_spec()?;
    Ok((doc, spec))
}

/// A pose in the docs/api.md shape, serialised straight from the core's buffers
/// (no intermediate per-joint allocation).
pub struct PoseJson<'a> {
    pub clip: &'a str,
    /// The request time.
    pub time: f64,
    /// The clip time it mapped to (after playback and ease).
    pub clip_time: f32,
    pub space: Space,
    pub skeleton: &'a Skeleton,
    pub pose: &'a Pose,
}

impl Serialize for PoseJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(5))?;
        m.serialize_entry("clip", self.clip)?;
        m.serialize_entry("time", &self.time)?;
        m.serialize_entry("clip_time", &self.clip_time)?;
        m.serialize_entry("space", self.space.as_str())?;
        m.serialize_entry("joints", &JointsJson { names: self.skeleton.names(), pose: self.pose })?;
        m.end()
    }
}

impl PoseJson<'_> {
    /// Appends exactly the JSON that `serde_json` writes for this pose, but
    /// directly (the pose route and JSON stream frames spend most of their
    /// time here, and serde's per-field plumbing cost more than the floats),
    /// with a composed answer's joint subset and root motion.
    pub fn write_with(&self, out: &mut impl BufMut, extras: Extras<'_>) {
        write_head(out, self.clip, self.time, self.clip_time);
        out.put_slice(b",\"space\":\"");
        out.put_slice(self.space.as_str().as_bytes());
        out.put_slice(b"\",\"joints\":[");
        let (p, names) = (self.pose, self.skeleton.names());
        let mut joint = Scratch::new();
        for (k, j) in extras.indices(names.len()).enumerate() {
            if k > 0 {
                out.put_u8(b',');
            }
            out.put_slice(b"{\"name\":");
            write_json_str(out, &names[j]);
            joint.clear();
            joint.push(b",\"translation\":");
            joint.floats(&p.translations[j].to_array());
            joint.push(b",\"rotation\":");
            joint.floats(&p.rotations[j].to_array());
            joint.push(b",\"scale\":");
            joint.floats(&p.scales[j].to_array());
            joint.push(b"}");
            out.put_slice(joint.as_bytes());
        }
        out.put_u8(b']');
        extras.write_parameters(out);
        extras.write_root_motion(out);
        super::ik::write_reports(out, extras.ik);
        extras.write_feet(out);
        out.put_slice(extras.tail);
        out.put_u8(b'}');
    }
}

/// What a composed answer (docs/motion.md) adds to a pose document: only some
/// joints (in skeleton order), and the root motion.
#[derive(Debug, Clone, Copy, Default)]
pub struct Extras<'a> {
    pub joints: Option<&'a [usize]>,
    pub root_motion: Option<RootMotion>,
    /// IK reports (docs/ik.md), written when there are any.
    pub ik: &'a [IkReport],
    /// Parameter values (docs/clip-format.md §3), written when the clip has parameters.
    pub parameters: Option<ParameterValues<'a>>,
    /// JSON members written last, before the closing brace (a composed
    /// pose's `,"warnings":[…]`); empty for none.
    pub tail: &'a [u8],
    /// Planted feet (docs/characters.md, “Planted feet”), written when there are any.
    pub feet: &'a [FootReport],
}

/// Bytes one foot's report adds to a pose at most (`"right":{"planted":false,"slide":…}`,
/// the number as [`write_float`] writes an f32), and the member around them.
pub const FOOT_REPORT_BYTES: u64 = 64;
pub const FEET_MEMBER_BYTES: u64 = 12;

/// A pose's parameters as an answer shows them: `"parameters": {"name":
/// [values]}`, every parameter or a request's subset (indices in the
/// layout, in layout order).
#[derive(Debug, Clone, Copy)]
pub struct ParameterValues<'a> {
    pub layout: &'a ParameterLayout,
    pub values: &'a [glam::Vec3A],
    pub subset: Option<&'a [usize]>,
}

impl<'a> ParameterValues<'a> {
    /// `None` for a clip without parameters, so no `parameters` key is written.
    pub fn of(layout: &'a ParameterLayout, pose: &'a Pose, subset: Option<&'a [usize]>) -> Option<Self> {
        (!layout.is_empty()).then_some(ParameterValues { layout, values: &pose.parameters, subset })
    }

    /// The parameters shown, by index in the layout.
    pub fn indices(&self) -> impl Iterator<Item = usize> + Clone + '_ {
        let (every, some) = match self.subset {
            Some(subset) => (0..0, subset.iter()),
            None => (0..self.layout.len(), [].iter()),
        };
        every.chain(some.copied())
    }

    /// Component `c` of parameter `p`.
    pub fn value(&self, p: usize, c: usize) -> f32 {
        self.values[self.layout.range(p).start + c / 3][c % 3]
    }

    /// `,"parameters":{"name":[…],…}`.
    fn write(&self, out: &mut impl BufMut) {
        out.put_slice(b",\"parameters\":{");
        for (k, p) in self.indices().enumerate() {
            if k > 0 {
                out.put_u8(b',');
            }
            write_json_str(out, &self.layout.names()[p]);
            out.put_slice(b":[");
            for c in 0..self.layout.widths()[p] as usize {
                if c > 0 {
                    out.put_u8(b',');
                }
                write_float(out, self.value(p, c));
            }
            out.put_u8(b']');
        }
        out.put_u8(b'}');
    }
}

impl Extras<'_> {
    fn indices(&self, all: usize) -> impl Iterator<Item = usize> + '_ {
        let (every, some) = match self.joints {
            Some(joints) => (0..0, joints.iter()),
            None => (0..all, [].iter()),
        };
        every.chain(some.copied())
    }

    /// `,"parameters":{…}` when the clip has parameters.
    fn write_parameters(&self, out: &mut impl BufMut) {
        if let Some(parameters) = &self.parameters {
            parameters.write(out);
        }
    }

    /// `,"root_motion":{"delta":{…},"total":{…}}` when there is one.
    /// `,"feet":{"left":{"planted":true,"slide":s},…}`, when a layer plants feet.
    fn write_feet(&self, out: &mut impl BufMut) {
        if self.feet.is_empty() {
            return;
        }
        out.put_slice(b",\"feet\":{");
        for (i, foot) in self.feet.iter().enumerate() {
            if i > 0 {
                out.put_u8(b',');
            }
            out.put_slice(if foot.side == Side::Left { b"\"left\":{\"planted\":" } else { b"\"right\":{\"planted\":" });
            out.put_slice(if foot.planted { b"true" } else { b"false" });
            out.put_slice(b",\"slide\":");
            write_float(out, foot.slide);
            out.put_u8(b'}');
        }
        out.put_u8(b'}');
    }

    fn write_root_motion(&self, out: &mut impl BufMut) {
        let Some(root) = self.root_motion else { return };
        out.put_slice(b",\"root_motion\":{\"delta\":");
        write_planar(out, root.delta);
        out.put_slice(b",\"total\":");
        write_planar(out, root.total);
        out.put_u8(b'}');
    }
}

/// `{"translation":[x,y,z],"yaw":r}`.
fn write_planar(out: &mut impl BufMut, p: Planar) {
    out.put_slice(b"{\"translation\":[");
    for (i, x) in p.translation.to_array().into_iter().enumerate() {
        if i > 0 {
            out.put_u8(b',');
        }
        write_float(out, x);
    }
    out.put_slice(b"],\"yaw\":");
    write_float(out, p.yaw);
    out.put_u8(b'}');
}

/// A JSON string, escaped as serde_json escapes it.
pub(crate) fn write_json_str(out: &mut impl BufMut, s: &str) {
    if s.bytes().all(|b| b >= 0x20 && b != b'"' && b != b'\\') {
        out.put_u8(b'"');
        out.put_slice(s.as_bytes());
        out.put_u8(b'"');
    } else {
        // Writing to memory cannot fail.
        let _ = serde_json::to_writer(out.writer(), s);
    }
}

/// A joint's numbers, assembled on the stack and appended with one copy.
///
/// `BufMut::put_slice` is not inlined, so appending each number, comma and
/// key on its own costs a call to `memcpy` for a handful of bytes: a
/// quarter of a 64-joint JSON frame's time went there. Here every copy has
/// a size the compiler sees (a literal key, or a number copied as at most
/// three overlapping 8-byte words), so it compiles to a few moves.
struct Scratch {
    bytes: [u8; Scratch::CAPACITY],
    len: usize,
}

impl Scratch {
    /// A 4×4 matrix: 16 numbers of at most 24 bytes, their commas and a key.
    const CAPACITY: usize = 512;

    fn new() -> Self {
        Scratch { bytes: [0; Self::CAPACITY], len: 0 }
    }

    fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.len]
    }

    fn clear(&mut self) {
        self.len = 0;
    }

    /// Appends a literal (its length is known where this is inlined).
    #[inline(always)]
    fn push(&mut self, s: &[u8]) {
        self.bytes[self.len..self.len + s.len()].copy_from_slice(s);
        self.len += s.len();
    }

    /// Appends a formatted number (at most 24 bytes) by fixed-size copies.
    #[inline(always)]
    fn push_number(&mut self, s: &[u8]) {
        let n = s.len();
        let to = &mut self.bytes[self.len..self.len + 24];
        if n >= 8 {
            to[..8].copy_from_slice(&s[..8]);
            if n > 16 {
                to[8..16].copy_from_slice(&s[8..16]);
            }
            to[n - 8..n].copy_from_slice(&s[n - 8..]);
        } else if n >= 4 {
            to[..4].copy_from_slice(&s[..4]);
            to[n - 4..n].copy_from_slice(&s[n - 4..]);
        } else if n >= 2 {
            // (Not a loop: the compiler would turn it back into `memcpy`.)
            to[..2].copy_from_slice(&s[..2]);
            to[n - 2..n].copy_from_slice(&s[n - 2..]);
        } else if n == 1 {
            to[0] = s[0];
        }
        self.len += n;
    }

    /// `[x,y,…]`, each number as [`write_float`] writes it.
    fn floats<const N: usize>(&mut self, xs: &[f32; N]) {
        self.push(b"[");
        for (i, &x) in xs.iter().enumerate() {
            if i > 0 {
                self.push(b",");
            }
            match common_text(x) {
                Some(text) => self.push(text),
                None => {
                    let x = if x.is_finite() { x } else { finite_stand_in(f64::from(x)) };
                    self.push_number(zmij::Buffer::new().format_finite(x).as_bytes());
                }
            }
        }
        self.push(b"]");
    }
}

struct JointsJson<'a> {
    names: &'a [String],
    pose: &'a Pose,
}

impl Serialize for JointsJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(self.names.len()))?;
        for (j, name) in self.names.iter().enumerate() {
            seq.serialize_element(&JointJson {
                name,
                translation: self.pose.translations[j].to_array(),
                rotation: self.pose.rotations[j].to_array(),
                scale: self.pose.scales[j].to_array(),
            })?;
        }
        seq.end()
    }
}

#[derive(Serialize)]
struct JointJson<'a> {
    name: &'a str,
    translation: [f32; 3],
    rotation: [f32; 4],
    scale: [f32; 3],
}

/// `{"clip":…,"time":…,"clip_time":…`: how every pose document starts.
fn write_head(out: &mut impl BufMut, clip: &str, time: f64, clip_time: f32) {
    out.put_slice(b"{\"clip\":");
    write_json_str(out, clip);
    out.put_slice(b",\"time\":");
    write_float(out, time);
    out.put_slice(b",\"clip_time\":");
    write_float(out, clip_time);
}

/// Per-joint 4×4 matrices (`format=matrix` or `skinning`), column-major.
pub struct MatricesJson<'a> {
    pub clip: &'a str,
    pub time: f64,
    pub clip_time: f32,
    pub format: &'static str,
    pub skeleton: &'a Skeleton,
    pub matrices: &'a [Mat4],
}

impl MatricesJson<'_> {
    /// Appends exactly the JSON `serde_json` writes for these matrices
    /// (finite floats), directly, and never a `null` (see `write_float`).
    /// Every joint, or `extras`' subset, and its root motion.
    pub fn write_with(&self, out: &mut impl BufMut, extras: Extras<'_>) {
        write_head(out, self.clip, self.time, self.clip_time);
        out.put_slice(b",\"space\":\"model\",\"format\":");
        write_json_str(out, self.format);
        out.put_slice(b",\"joints\":[");
        let names = self.skeleton.names();
        let mut joint = Scratch::new();
        for (k, j) in extras.indices(names.len().min(self.matrices.len())).enumerate() {
            if k > 0 {
                out.put_u8(b',');
            }
            out.put_slice(b"{\"name\":");
            write_json_str(out, &names[j]);
            joint.clear();
            joint.push(b",\"matrix\":");
            joint.floats(&self.matrices[j].to_cols_array());
            joint.push(b"}");
            out.put_slice(joint.as_bytes());
        }
        out.put_u8(b']');
        extras.write_parameters(out);
        extras.write_root_motion(out);
        extras.write_feet(out);
        out.put_slice(extras.tail);
        out.put_u8(b'}');
    }
}

impl Serialize for MatricesJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        #[derive(Serialize)]
        struct Joint<'a> {
            name: &'a str,
            matrix: [f32; 16],
        }
        struct Joints<'a>(&'a [String], &'a [Mat4]);
        impl Serialize for Joints<'_> {
            fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                let mut seq = s.serialize_seq(Some(self.0.len()))?;
                for (name, m) in self.0.iter().zip(self.1) {
                    seq.serialize_element(&Joint { name, matrix: m.to_cols_array() })?;
                }
                seq.end()
            }
        }
        let mut m = s.serialize_map(Some(6))?;
        m.serialize_entry("clip", self.clip)?;
        m.serialize_entry("time", &self.time)?;
        m.serialize_entry("clip_time", &self.clip_time)?;
        m.serialize_entry("space", "model")?;
        m.serialize_entry("format", self.format)?;
        m.serialize_entry("joints", &Joints(self.skeleton.names(), self.matrices))?;
        m.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anim::{Clip, ClipSpec, Interpolation, Playback, SampleOptions, Sampler, TrackSpec};

    /// The shortcut for 0 and ±1 writes what the formatter would.
    #[test]
    fn the_common_values_are_written_as_the_formatter_writes_them() {
        for x in [0.0f32, -0.0, 1.0, -1.0] {
            let text = common_text(x).expect("a common value");
            assert_eq!(text, zmij::Buffer::new().format_finite(x).as_bytes(), "{x}");
        }
        for x in [f32::MIN_POSITIVE, -f32::MIN_POSITIVE, 1.0 + f32::EPSILON, 0.5, 2.0, f32::from_bits(1)] {
            assert_eq!(common_text(x), None, "{x}");
        }
    }

    /// The direct writer and serde agree byte for byte, names needing escapes included.
    #[test]
    fn direct_pose_writer_matches_serde() {
        let names = ["root", "arm \"left\"", "tab\there", "ünï", "back\\slash"];
        let tracks = names
            .iter()
            .enumerate()
            .map(|(j, n)| {
                let keys = vec![Vec3::new(j as f32, -0.1, 1e-7), Vec3::new(1.0 / 3.0, 2e20, -5.5)];
                TrackSpec::new(n, Channel::Translation, Interpolation::CatmullRom, vec![0.0, 1.0], Keys::Vec3(keys))
            })
            .collect();
        let spec = ClipSpec {
            name: "c".into(),
            skeleton: None,
            tracks,
            events: vec![],
            playback: Playback::Loop,
            ..Default::default()
        };
        let clip = Clip::build(&spec).unwrap();
        let mut sampler = Sampler::new();
        for t in [0.0, 0.123456789, 0.5, 7.25] {
            let clip_time = clip.sample(t, &SampleOptions::default(), &mut sampler);
            let pose = PoseJson {
                clip: "id \"x\"",
                time: t,
                clip_time,
                space: Space::Local,
                skeleton: clip.skeleton(),
                pose: sampler.pose(),
            };
            let mut direct = Vec::new();
            pose.write_with(&mut direct, Extras::default());
            assert_eq!(String::from_utf8(direct).unwrap(), serde_json::to_string(&pose).unwrap());
        }
    }

    /// Numbers of every length a float can format to are copied whole.
    #[test]
    fn scratch_copies_numbers_of_every_length() {
        let digits = b"123456789012345678901234";
        for n in 0..=24 {
            let mut scratch = Scratch::new();
            scratch.push(b"[");
            scratch.push_number(&digits[..n]);
            scratch.push_number(&digits[..n]);
            let mut expected = b"[".to_vec();
            expected.extend_from_slice(&digits[..n]);
            expected.extend_from_slice(&digits[..n]);
            assert_eq!(scratch.as_bytes(), expected, "{n} digits");
        }
        let mut scratch = Scratch::new();
        scratch.floats(&[f32::NAN, f32::INFINITY, -f32::INFINITY, -1.2345678e-38]);
        assert_eq!(scratch.as_bytes(), b"[0.0,3.4028235e+38,-3.4028235e+38,-1.2345678e-38]");
    }

    /// The matrix writer and serde agree byte for byte.
    #[test]
    fn direct_matrix_writer_matches_serde() {
        let keys = vec![Vec3::new(0.1, -2e-30, 3e30), Vec3::new(1.0 / 3.0, 2e20, -5.5)];
        let tracks = ["a", "b \"q\""]
            .iter()
            .map(|n| {
                TrackSpec::new(n, Channel::Translation, Interpolation::Linear, vec![0.0, 1.0], Keys::Vec3(keys.clone()))
            })
            .collect();
        let spec = ClipSpec {
            name: "c".into(),
            skeleton: None,
            tracks,
            events: vec![],
            playback: Playback::Once,
            ..Default::default()
        };
        let clip = Clip::build(&spec).unwrap();
        let (mut sampler, mut matrices) = (Sampler::new(), Vec::new());
        for (t, format) in [(0.25, "matrix"), (0.75, "skinning")] {
            clip.matrices(t, &SampleOptions::default(), false, &mut sampler, &mut matrices);
            let doc = MatricesJson {
                clip: "id",
                time: t,
                clip_time: t as f32,
                format,
                skeleton: clip.skeleton(),
                matrices: &matrices,
            };
            let mut direct = Vec::new();
            doc.write_with(&mut direct, Extras::default());
            assert_eq!(String::from_utf8(direct).unwrap(), serde_json::to_string(&doc).unwrap());
        }
    }

    /// A number is always written as a number, even one that should never
    /// reach the writer.
    #[test]
    fn non_finite_numbers_are_never_null() {
        for (x, expected) in [(f64::NAN, 0.0), (f64::INFINITY, f32::MAX), (f64::NEG_INFINITY, -f32::MAX)] {
            let mut out = Vec::new();
            write_float(&mut out, x);
            let text = String::from_utf8(out).unwrap();
            let value: serde_json::Value = serde_json::from_str(&text).unwrap();
            assert_eq!(value.as_f64().map(|v| v as f32), Some(expected), "{x} was written as {text}");
        }
    }
}
