//! [`Clip`]: the validated, immutable runtime form of a [`ClipSpec`], and
//! the sampling kernel.
//!
//! `Clip::build` is the only constructor, so a `Clip` that exists is valid:
//! sampling cannot fail and does not allocate once the caller's buffers
//! ([`Cursor`], [`Pose`]) have their size. Tracks are stored by channel and
//! kind (`tracks`), so sampling is a handful of tight loops.

use std::collections::HashMap;

use glam::Mat4;

use super::compile::{self, Compiled, finite3, unit_quat};
use super::error::{ClipError, ClipErrorKind as K, Path};
use super::skeleton::{NO_PARENT, Pose, Skeleton};
use super::spec::{Channel, ClipSpec, Ease, Playback, Space};
use super::time::TimeRange;
use super::timeline::{Span, Timeline};
use super::tracks::{QuatTracks, Vec3Tracks};

/// Longest accepted clip or event name, in characters.
pub const MAX_NAME_CHARS: usize = 256;

/// A named instant of the clip (a footstep, a sound cue).
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    pub time: f32,
    pub name: String,
}

/// A validated clip, ready to sample.
#[derive(Debug, Clone, PartialEq)]
pub struct Clip {
    name: String,
    playback: Playback,
    start: f32,
    end: f32,
    skeleton: Skeleton,
    timelines: Vec<Timeline>,
    /// The rest pose with constant (single-key) tracks applied: what each
    /// sample starts from.
    base: Pose,
    translations: Vec3Tracks,
    rotations: QuatTracks,
    scales: Vec3Tracks,
    track_count: usize,
    events: Vec<Event>,
}

/// Per-caller search state: the last span of each timeline, which makes
/// forward playback O(1). Any cursor works with any clip (it re-fits itself),
/// but a cursor kept per playback is what makes it fast.
#[derive(Debug, Clone, Default)]
pub struct Cursor {
    hints: Vec<u32>,
    spans: Vec<Span>,
}

impl Cursor {
    #[inline]
    fn fit(&mut self, timelines: usize) {
        if self.hints.len() != timelines {
            self.hints.clear();
            self.hints.resize(timelines, 0);
            self.spans.clear();
            self.spans.resize(timelines, Span::default());
        }
    }
}

/// How a request maps to clip time and space (SPEC §2.6–2.8).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SampleOptions {
    /// `None`: the clip's own default.
    pub playback: Option<Playback>,
    pub ease: Ease,
    pub space: Space,
}

impl Clip {
    /// Validates `spec` and compiles it (SPEC §1–2).
    ///
    /// # Errors
    /// The first rule `spec` breaks, with the path of the offending field.
    pub fn build(spec: &ClipSpec) -> Result<Clip, ClipError> {
        let chars = spec.name.chars().count();
        if chars == 0 || chars > MAX_NAME_CHARS {
            return Err(ClipError::new(Path::root().field("name"), K::BadName { max: MAX_NAME_CHARS }));
        }
        if spec.tracks.is_empty() {
            return Err(ClipError::new(Path::root().field("tracks"), K::NoTracks));
        }
        let skeleton = build_skeleton(spec)?;

        let mut timelines: Vec<Timeline> = Vec::new();
        let mut timeline_of: HashMap<Vec<u32>, u32> = HashMap::new();
        let mut intern = |times: Vec<f32>| -> u32 {
            let key: Vec<u32> = times.iter().map(|t| t.to_bits()).collect();
            *timeline_of.entry(key).or_insert_with(|| {
                timelines.push(Timeline::new(&times));
                (timelines.len() - 1) as u32
            })
        };
        let mut seen: HashMap<(usize, Channel), ()> = HashMap::new();
        let mut base = skeleton.rest().clone();
        let (mut translations, mut rotations, mut scales) =
            (Vec3Tracks::default(), QuatTracks::default(), Vec3Tracks::default());
        let (mut start, mut end) = (f32::INFINITY, f32::NEG_INFINITY);
        for (i, track) in spec.tracks.iter().enumerate() {
            let path = Path::root().field("tracks").index(i);
            let joint = skeleton.index_of(&track.joint).ok_or_else(|| {
                ClipError::new(path.clone().field("joint"), K::UnknownJoint { joint: track.joint.clone() })
            })?;
            if seen.insert((joint, track.channel), ()).is_some() {
                return Err(ClipError::new(
                    path.field("channel"),
                    K::DuplicateTrack { joint: track.joint.clone(), channel: track.channel.as_str() },
                ));
            }
            let j = joint;
            let joint = joint as u32;
            let domain = if track.channel == Channel::Rotation {
                let Compiled { times, curve, domain } = compile::quat_track(track, &path)?;
                rotations.push(joint, intern(times), curve, &mut base.rotations[j]);
                domain
            } else {
                let Compiled { times, curve, domain } = compile::vec3_track(track, &path)?;
                let (list, slot) = match track.channel {
                    Channel::Scale => (&mut scales, &mut base.scales[j]),
                    _ => (&mut translations, &mut base.translations[j]),
                };
                list.push(joint, intern(times), curve, slot);
                domain
            };
            start = start.min(domain.0);
            end = end.max(domain.1);
        }

        let mut events = Vec::with_capacity(spec.events.len());
        for (i, e) in spec.events.iter().enumerate() {
            let path = Path::root().field("events").index(i);
            if !e.time.is_finite() {
                return Err(ClipError::new(path.field("time"), K::NonFinite));
            }
            let chars = e.name.chars().count();
            if chars == 0 || chars > MAX_NAME_CHARS {
                return Err(ClipError::new(path.field("name"), K::BadName { max: MAX_NAME_CHARS }));
            }
            events.push(Event { time: e.time, name: e.name.clone() });
        }
        events.sort_by(|a, b| a.time.total_cmp(&b.time));

        Ok(Clip {
            name: spec.name.clone(),
            playback: spec.playback,
            start,
            end,
            skeleton,
            timelines,
            base,
            translations,
            rotations,
            scales,
            track_count: spec.tracks.len(),
            events,
        })
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// The default playback mode.
    pub fn playback(&self) -> Playback {
        self.playback
    }

    /// Smallest first key over all tracks (SPEC §1).
    pub fn start(&self) -> f32 {
        self.start
    }

    /// Largest last key over all tracks.
    pub fn end(&self) -> f32 {
        self.end
    }

    pub fn duration(&self) -> f32 {
        self.end - self.start
    }

    pub fn skeleton(&self) -> &Skeleton {
        &self.skeleton
    }

    pub fn joint_count(&self) -> usize {
        self.skeleton.len()
    }

    pub fn track_count(&self) -> usize {
        self.track_count
    }

    /// Distinct key-time arrays; tracks that share times share one search.
    pub fn timeline_count(&self) -> usize {
        self.timelines.len()
    }

    /// Events sorted by time.
    pub fn events(&self) -> &[Event] {
        &self.events
    }

    /// The clip's time range and the map from request times into it
    /// (SPEC §2.7's rule at the seams; see [`TimeRange`]).
    pub fn range(&self) -> TimeRange {
        TimeRange::new(self.start, self.end)
    }

    /// Maps a request time to clip time (SPEC §2.6–2.7): playback first
    /// (`once` clamps, `loop` wraps, `ping_pong` reflects), then the ease
    /// warp; a time that rounds to the start or end is exactly there.
    /// Non-finite `t` maps to the start. See [`TimeRange::clip_time`].
    pub fn clip_time(&self, t: f64, playback: Playback, ease: Ease) -> f32 {
        self.range().clip_time(t, playback, ease)
    }

    /// The local pose at clip time `t` (already mapped by
    /// [`Clip::clip_time`]; outside the range each track holds its ends).
    /// The hot path: no allocation once `cursor` and `pose` have been used
    /// with a clip of this size.
    #[inline]
    pub fn sample_into(&self, t: f32, cursor: &mut Cursor, pose: &mut Pose) {
        cursor.fit(self.timelines.len());
        for ((timeline, hint), span) in self.timelines.iter().zip(&mut cursor.hints).zip(&mut cursor.spans) {
            *span = timeline.locate(t, hint);
        }
        pose.copy_from(&self.base);
        let spans = &cursor.spans;
        self.translations.apply(spans, &mut pose.translations);
        self.rotations.apply(spans, &mut pose.rotations);
        self.scales.apply(spans, &mut pose.scales);
    }

    /// Like [`Clip::sample_into`] but takes a request time and options and
    /// returns the pose in the requested space. Returns the clip time used.
    pub fn sample(&self, t: f64, options: &SampleOptions, sampler: &mut Sampler) -> f32 {
        let clip_time = self.clip_time(t, options.playback.unwrap_or(self.playback), options.ease);
        self.sample_into(clip_time, &mut sampler.cursor, &mut sampler.local);
        if options.space == Space::Model {
            self.skeleton.to_model(&sampler.local, &mut sampler.model);
        }
        sampler.space = options.space;
        clip_time
    }

    /// Model matrices (or skinning matrices, `M_j · invBind_j`) at request
    /// time `t`, into `out`. Returns `false` if skinning was asked of a clip
    /// without inverse bind matrices.
    pub fn matrices(
        &self,
        t: f64,
        options: &SampleOptions,
        skinning: bool,
        sampler: &mut Sampler,
        out: &mut Vec<Mat4>,
    ) -> bool {
        let local = SampleOptions { space: Space::Local, ..*options };
        self.sample(t, &local, sampler);
        if skinning {
            self.skeleton.skinning_matrices(&sampler.local, out)
        } else {
            self.skeleton.model_matrices(&sampler.local, out);
            true
        }
    }
}

/// Reusable buffers for [`Clip::sample`]: one per playback or per worker.
#[derive(Debug, Clone, Default)]
pub struct Sampler {
    cursor: Cursor,
    local: Pose,
    model: Pose,
    space: Space,
}

impl Sampler {
    pub fn new() -> Self {
        Self::default()
    }

    /// The pose of the last [`Clip::sample`] call, in the space it asked for.
    pub fn pose(&self) -> &Pose {
        match self.space {
            Space::Local => &self.local,
            Space::Model => &self.model,
        }
    }
}

/// The skeleton of `spec`, or one root joint per animated joint in order of
/// first appearance when it has none (SPEC §1).
fn build_skeleton(spec: &ClipSpec) -> Result<Skeleton, ClipError> {
    let Some(skel) = &spec.skeleton else {
        let mut names: Vec<String> = Vec::new();
        for (i, t) in spec.tracks.iter().enumerate() {
            if t.joint.is_empty() {
                return Err(ClipError::new(Path::root().field("tracks").index(i).field("joint"), K::EmptyJointName));
            }
            if !names.contains(&t.joint) {
                names.push(t.joint.clone());
            }
        }
        let n = names.len();
        return Ok(Skeleton::new(names, vec![NO_PARENT; n], Pose::identity(n), None));
    };
    let joints = &skel.joints;
    let mut index: HashMap<&str, usize> = HashMap::with_capacity(joints.len());
    for (j, joint) in joints.iter().enumerate() {
        let path = Path::root().field("skeleton").field("joints").index(j);
        if joint.name.is_empty() {
            return Err(ClipError::new(path.field("name"), K::EmptyJointName));
        }
        if index.insert(joint.name.as_str(), j).is_some() {
            return Err(ClipError::new(path.field("name"), K::DuplicateJoint { name: joint.name.clone() }));
        }
    }
    let mut parents = Vec::with_capacity(joints.len());
    let mut rest = Pose::identity(0);
    let mut binds = Vec::with_capacity(joints.len());
    for (j, joint) in joints.iter().enumerate() {
        let path = Path::root().field("skeleton").field("joints").index(j);
        let parent = match &joint.parent {
            None => NO_PARENT,
            Some(p) => match index.get(p.as_str()) {
                None => return Err(ClipError::new(path.field("parent"), K::UnknownParent { parent: p.clone() })),
                Some(&pj) if pj < j => pj as u32,
                Some(_) if on_cycle(joints, &index, j) => {
                    return Err(ClipError::new(path.field("parent"), K::ParentCycle { joint: joint.name.clone() }));
                }
                Some(_) => return Err(ClipError::new(path.field("parent"), K::ParentAfterChild { parent: p.clone() })),
            },
        };
        parents.push(parent);
        let rp = path.clone().field("rest");
        rest.translations.push(finite3(joint.rest.translation, rp.clone().field("translation"))?);
        rest.scales.push(finite3(joint.rest.scale, rp.clone().field("scale"))?);
        let q = glam::Vec4::from(joint.rest.rotation);
        if !q.is_finite() {
            return Err(ClipError::new(rp.field("rotation"), K::NonFinite));
        }
        rest.rotations.push(unit_quat(q, &rp.field("rotation"))?.as_quat());
        if let Some(m) = joint.inverse_bind {
            if !m.is_finite() {
                return Err(ClipError::new(path.field("inverse_bind"), K::NonFinite));
            }
            binds.push(Some(m));
        } else {
            binds.push(None);
        }
    }
    let inverse_binds =
        binds.iter().any(Option::is_some).then(|| binds.iter().map(|b| b.unwrap_or(Mat4::IDENTITY)).collect());
    let names = joints.iter().map(|j| j.name.clone()).collect();
    Ok(Skeleton::new(names, parents, rest, inverse_binds))
}

/// Whether following parents from joint `j` comes back to `j`.
fn on_cycle(joints: &[super::spec::JointSpec], index: &HashMap<&str, usize>, j: usize) -> bool {
    let mut at = j;
    for _ in 0..joints.len() {
        match joints[at].parent.as_deref().and_then(|p| index.get(p)) {
            Some(&p) if p == j => return true,
            Some(&p) => at = p,
            None => return false,
        }
    }
    false
}

/// The times `start + k/fps` for `k = 0, 1, …` up to and including `end`
/// (a `start,end,fps` sample request, SPEC §3). The caller bounds the count
/// with [`frame_count`] before asking for them.
pub fn frame_times(start: f64, end: f64, fps: f64) -> impl Iterator<Item = f64> {
    (0..frame_count(start, end, fps)).map(move |k| start + k as f64 / fps)
}

/// How many frames [`frame_times`] yields (0 for an empty or invalid range).
pub fn frame_count(start: f64, end: f64, fps: f64) -> u64 {
    if !(start.is_finite() && end.is_finite() && fps.is_finite() && fps > 0.0 && end >= start) {
        return 0;
    }
    // A tolerance so that e.g. 0..1 at 30 fps includes t = 1.
    ((end - start) * fps + 1e-9).floor() as u64 + 1
}
