//! [`Clip`]: the validated, immutable runtime form of a [`ClipSpec`], and
//! the sampling kernel.
//!
//! `Clip::build` is the only constructor, so a `Clip` that exists is valid:
//! sampling cannot fail and does not allocate once the caller's buffers
//! ([`Cursor`], [`Pose`]) have their size. Tracks are stored by channel and
//! kind (`tracks`), so sampling is a handful of tight loops.

use std::collections::{HashMap, HashSet};
use std::sync::atomic::AtomicBool;

use glam::Mat4;

use super::arc::Meter;
use super::compile::{self, Compiled, finite3, unit_quat};
use super::error::{ClipError, ClipErrorKind as K};
use super::heap::vec_bytes;
use super::ik::{IkLimits, IkReport, KeyedIk, KeyedIkState};
use super::parameters::{ParameterLayout, Parameters};
use super::path::Path;
use super::skeleton::{NO_PARENT, Pose, Skeleton};
use super::spec::{Channel, ClipSpec, Ease, EventSpec, MAX_NAME_CHARS, Playback, SkeletonSpec, Space, TrackSpec};
use super::time::TimeRange;
use super::timeline::{Span, Timeline};
use super::tracks::{QuatTracks, Spans, Vec3Tracks};

/// The largest model-space scale or translation magnitude a joint below a
/// root may reach: 1/340 of `f32::MAX`, so matrix products (and a skinning
/// matrix's inverse bind) keep headroom.
pub const MAX_MODEL_MAGNITUDE: f64 = 1e36;

/// The build work [`Clip::build`] allows a clip: quadrature evaluations
/// plus arc-length pieces of its constant-speed tables, summed over the
/// whole clip. A unit is about 25 ns of one core (release build) and leaves
/// about half a byte of tables, so this is at most ~0.4 s and ~8 MB: room for
/// a constant-speed path of ~150 smooth segments (each ~100k units at the
/// 1e-6 tolerance). The server's `max_build_work` setting replaces it.
pub const DEFAULT_BUILD_WORK: u64 = 16_000_000;

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
    /// Joints with a translation track, in track order (root motion's default joint).
    translated: Vec<u32>,
    events: Vec<Event>,
    /// Constraints solved after the tracks at every sample (docs/ik.md).
    ik: Option<KeyedIk>,
    /// Named tracks that are not joints (docs/clip-format.md, “Parameters”).
    parameters: Parameters,
    /// What the build spent (see [`DEFAULT_BUILD_WORK`]).
    build_work: u64,
}

/// Per-caller search state: the last span of each timeline, which makes
/// forward playback O(1). Any cursor works with any clip (it re-fits itself),
/// but a cursor kept per playback is what makes it fast.
#[derive(Debug, Clone, Default)]
pub struct Cursor {
    hints: Vec<u32>,
    spans: Vec<Span>,
    /// Per timeline, the pass of [`Clip::sample_joints_into`] that located
    /// its span (that sampling locates only the timelines it reads).
    stamps: Vec<u32>,
    pass: u32,
    /// The clip's IK constraints as last filled, and their solver (boxed:
    /// most clips have none).
    ik: Option<Box<KeyedIkState>>,
}

impl Cursor {
    /// The IK reports of the last sample taken with this cursor, one per
    /// constraint of its clip (empty for a clip without IK).
    pub fn ik_reports(&self) -> &[IkReport] {
        self.ik.as_ref().map_or(&[], |state| state.reports())
    }

    #[inline]
    fn fit(&mut self, timelines: usize) {
        if self.hints.len() != timelines {
            self.hints.clear();
            self.hints.resize(timelines, 0);
            self.spans.clear();
            self.spans.resize(timelines, Span::default());
            self.stamps.clear();
            self.stamps.resize(timelines, 0);
        }
    }

    /// A new pass: every span is stale until located again.
    #[inline]
    fn next_pass(&mut self) {
        self.pass = self.pass.wrapping_add(1);
        if self.pass == 0 {
            self.stamps.fill(0);
            self.pass = 1;
        }
    }
}

/// The spans of one [`Clip::sample_joints_into`]: located on first use,
/// for the joints `keep` accepts.
struct LazySpans<'a, K> {
    timelines: &'a [Timeline],
    cursor: &'a mut Cursor,
    t: f32,
    keep: K,
}

impl<K: Fn(u32) -> bool> Spans for LazySpans<'_, K> {
    #[inline(always)]
    fn keeps(&self, joint: u32) -> bool {
        (self.keep)(joint)
    }

    #[inline(always)]
    fn span(&mut self, timeline: u32) -> Span {
        let (i, cursor) = (timeline as usize, &mut *self.cursor);
        if cursor.stamps[i] != cursor.pass {
            cursor.stamps[i] = cursor.pass;
            cursor.spans[i] = self.timelines[i].locate(self.t, &mut cursor.hints[i]);
        }
        cursor.spans[i]
    }
}

/// How a request maps to clip time and space (docs/clip-format.md, 2.6–2.8).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SampleOptions {
    /// `None`: the clip's own default.
    pub playback: Option<Playback>,
    pub ease: Ease,
    pub space: Space,
}

impl Clip {
    /// Validates `spec` and compiles it (docs/clip-format.md, “Data model” and
    /// “Evaluation math”) within [`DEFAULT_BUILD_WORK`].
    ///
    /// # Errors
    /// The first rule `spec` breaks, with the path of the offending field.
    pub fn build(spec: &ClipSpec) -> Result<Clip, ClipError> {
        Clip::build_within(spec, DEFAULT_BUILD_WORK)
    }

    /// [`Clip::build`] with a budget of `max_work` units of build work for
    /// the whole clip, however it is split into tracks; the build stops as
    /// soon as it is spent.
    ///
    /// # Errors
    /// As [`Clip::build`]; `build_budget_exceeded` (at the track that went
    /// over) past `max_work`.
    pub fn build_within(spec: &ClipSpec, max_work: u64) -> Result<Clip, ClipError> {
        Clip::build_cancellable(spec, max_work, &AtomicBool::new(false))
    }

    /// [`Clip::build_within`] that stops soon after `cancel` is raised (its
    /// caller gave up: a client gone, a timeout), instead of finishing work
    /// nobody will use.
    ///
    /// # Errors
    /// As [`Clip::build_within`]; `build_cancelled` once `cancel` is raised.
    pub fn build_cancellable(spec: &ClipSpec, max_work: u64, cancel: &AtomicBool) -> Result<Clip, ClipError> {
        Clip::build_limited(spec, max_work, &IkLimits::default(), cancel)
    }

    /// [`Clip::build_cancellable`] with the service's ceilings on IK
    /// constraints, effectors and iterations.
    ///
    /// # Errors
    /// As [`Clip::build_cancellable`]; an `ik` constraint over `ik_limits`.
    pub fn build_limited(
        spec: &ClipSpec,
        max_work: u64,
        ik_limits: &IkLimits,
        cancel: &AtomicBool,
    ) -> Result<Clip, ClipError> {
        Clip::build_kernel(spec, max_work, ik_limits, cancel, true)
    }

    /// [`Clip::build`] without the SIMD groups: every track on the scalar
    /// kernel, for tests that hold the two kernels to each other.
    ///
    /// # Errors
    /// As [`Clip::build`].
    #[doc(hidden)]
    pub fn build_scalar(spec: &ClipSpec) -> Result<Clip, ClipError> {
        Clip::build_kernel(spec, DEFAULT_BUILD_WORK, &IkLimits::default(), &AtomicBool::new(false), false)
    }

    /// Every build, phase by phase, each refusing what it checks in the
    /// order the tests pin: the name, the skeleton, the joint tracks, the
    /// parameters, the keyed IK, the events. Without `simd_groups` every
    /// track stays on the scalar kernel.
    fn build_kernel(
        spec: &ClipSpec,
        max_work: u64,
        ik_limits: &IkLimits,
        cancel: &AtomicBool,
        simd_groups: bool,
    ) -> Result<Clip, ClipError> {
        check_header(spec)?;
        let skeleton = build_skeleton(spec)?;
        let mut timelines = Timelines::default();
        let mut meter = Meter::new(max_work, cancel);
        let mut joints = JointTracks::build(&spec.tracks, &skeleton, &mut timelines, &mut meter)?;
        if simd_groups {
            joints.group();
        }
        let mut domain = joints.domain;
        let built = Parameters::build(&spec.parameters, &mut meter, |times| timelines.intern(times))?;
        joints.base.parameters = built.base;
        if let Some(range) = built.domain {
            domain.widen(range);
            domain.check(Path::root().field("parameters"))?;
        }
        let ik = build_keyed_ik(spec, &skeleton, ik_limits, &mut meter, &mut domain)?;
        let events = build_events(&spec.events)?;
        Ok(Clip {
            name: spec.name.clone(),
            playback: spec.playback,
            start: domain.start,
            end: domain.end,
            skeleton,
            timelines: timelines.list,
            base: joints.base,
            translations: joints.translations,
            rotations: joints.rotations,
            scales: joints.scales,
            track_count: spec.tracks.len(),
            translated: joints.translated,
            events,
            ik,
            parameters: built.parameters,
            build_work: meter.spent(),
        })
    }

    /// The build work this clip took (quadrature evaluations plus
    /// arc-length pieces): what [`Clip::build_within`] checks.
    pub fn build_work(&self) -> u64 {
        self.build_work
    }

    /// Bytes the clip holds on the heap (its tables, names and curves), from
    /// the capacities it allocated: what a cache of clips should count.
    pub fn heap_bytes(&self) -> usize {
        let events = self.events.iter().map(|e| e.name.capacity()).sum::<usize>();
        let timelines = self.timelines.iter().map(Timeline::heap_bytes).sum::<usize>();
        self.name.capacity()
            + self.skeleton.heap_bytes()
            + vec_bytes(&self.timelines)
            + timelines
            + self.base.heap_bytes()
            + self.translations.heap_bytes()
            + self.rotations.heap_bytes()
            + self.scales.heap_bytes()
            + vec_bytes(&self.events)
            + events
            + self.ik.as_ref().map_or(0, KeyedIk::heap_bytes)
            + self.parameters.heap_bytes()
    }

    /// The clip's parameters (docs/clip-format.md, “Parameters”): names, widths and where each sits
    /// in [`Pose::parameters`].
    pub fn parameters(&self) -> &ParameterLayout {
        &self.parameters.layout
    }

    /// How many IK constraints each sample solves (docs/ik.md, “Keyed targets in clips”).
    pub fn ik_count(&self) -> usize {
        self.ik.as_ref().map_or(0, KeyedIk::len)
    }

    /// The IK constraints each sample solves, in order (keyed targets not
    /// filled in): their joints, effectors and iteration budgets.
    pub fn ik_constraints(&self) -> &[super::ik::IkConstraint] {
        self.ik.as_ref().map_or(&[], KeyedIk::constraints)
    }

    /// The clip's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The default playback mode.
    pub fn playback(&self) -> Playback {
        self.playback
    }

    /// Smallest first key over all tracks (docs/clip-format.md, “Data model”).
    pub fn start(&self) -> f32 {
        self.start
    }

    /// Largest last key over all tracks.
    pub fn end(&self) -> f32 {
        self.end
    }

    /// `end - start`, in seconds.
    pub fn duration(&self) -> f32 {
        self.end - self.start
    }

    /// The skeleton its poses are for.
    pub fn skeleton(&self) -> &Skeleton {
        &self.skeleton
    }

    /// Joints in its skeleton (and in every pose it samples).
    pub fn joint_count(&self) -> usize {
        self.skeleton.len()
    }

    /// Whether joint `j` has a translation track (even a constant one).
    pub fn has_translation_track(&self, j: usize) -> bool {
        self.translated.contains(&(j as u32))
    }

    /// The key times of joint `j`'s rotation track (none when it is
    /// constant or absent), for root motion's unwrapped yaw.
    pub(crate) fn rotation_key_times(&self, j: usize) -> impl Iterator<Item = f32> + '_ {
        let timeline = self.rotations.timeline_of(j as u32).map(|t| &self.timelines[t as usize]);
        timeline.into_iter().flat_map(|t| (0..t.len()).map(|i| t.time(i)))
    }

    /// Every key time of every track (repeats included), for analyses
    /// that must see each key's pose.
    pub(crate) fn key_times(&self) -> impl Iterator<Item = f32> + '_ {
        self.timelines.iter().flat_map(|t| (0..t.len()).map(|i| t.time(i)))
    }

    /// Joint tracks, constant ones included.
    pub fn track_count(&self) -> usize {
        self.track_count
    }

    /// How many tracks the SIMD groups evaluate (tracks sharing key times,
    /// four at a time; the rest run on the scalar kernel).
    #[doc(hidden)]
    pub fn simd_lanes(&self) -> usize {
        self.translations.simd_lanes() + self.rotations.simd_lanes() + self.scales.simd_lanes()
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
    /// (the seam rule of docs/clip-format.md, “Playback modes and time”; see [`TimeRange`]).
    pub fn range(&self) -> TimeRange {
        TimeRange::new(self.start, self.end)
    }

    /// Maps a request time to clip time (docs/clip-format.md, 2.6–2.7): playback first
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
        let spans = &mut &cursor.spans[..];
        self.translations.apply(spans, &mut pose.translations);
        self.rotations.apply(spans, &mut pose.rotations);
        self.scales.apply(spans, &mut pose.scales);
        self.parameters.apply(spans, &mut pose.parameters);
        self.solve_ik(t, cursor, pose);
    }

    /// Solves the clip's constraints on `pose`; a cursor last used with a
    /// clip that had some forgets their reports.
    #[inline]
    fn solve_ik(&self, t: f32, cursor: &mut Cursor, pose: &mut Pose) {
        match (&self.ik, &mut cursor.ik) {
            (Some(ik), state) => ik.solve(t, &self.skeleton, state.get_or_insert_default(), pose),
            (None, Some(state)) => state.forget_reports(),
            (None, None) => {}
        }
    }

    /// [`Clip::sample_into`] for the joints `keep` accepts (by index in this
    /// clip's skeleton); every other joint holds the clip's base pose (its
    /// rest with constant tracks). The tracks of the joints left out are not
    /// evaluated and timelines only they read are not searched: how a motion
    /// layer skips the joints its mask leaves out or a layer above hides.
    /// A clip with IK samples every joint: its solve reads whole chains.
    #[inline]
    pub(crate) fn sample_joints_into(&self, t: f32, cursor: &mut Cursor, pose: &mut Pose, keep: impl Fn(u32) -> bool) {
        if self.ik.is_some() {
            return self.sample_into(t, cursor, pose);
        }
        cursor.fit(self.timelines.len());
        cursor.next_pass();
        pose.copy_from(&self.base);
        let spans = &mut LazySpans { timelines: &self.timelines, cursor, t, keep };
        self.translations.apply(spans, &mut pose.translations);
        self.rotations.apply(spans, &mut pose.rotations);
        self.scales.apply(spans, &mut pose.scales);
        // Parameters belong to no joint: a layer always has them.
        let spans = &mut LazySpans { timelines: &self.timelines, cursor: &mut *spans.cursor, t, keep: |_: u32| true };
        self.parameters.apply(spans, &mut pose.parameters);
        self.solve_ik(t, cursor, pose);
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
    /// Empty buffers; they take their size at the first sample.
    pub fn new() -> Self {
        Self::default()
    }

    /// The IK reports of the last [`Clip::sample`] call (one per
    /// constraint of the clip).
    pub fn ik_reports(&self) -> &[IkReport] {
        self.cursor.ik_reports()
    }

    /// The pose of the last [`Clip::sample`] call, in the space it asked for.
    pub fn pose(&self) -> &Pose {
        match self.space {
            Space::Local => &self.local,
            Space::Model => &self.model,
        }
    }
}

/// A clip's name, and that it animates something.
fn check_header(spec: &ClipSpec) -> Result<(), ClipError> {
    let chars = spec.name.chars().count();
    if chars == 0 || chars > MAX_NAME_CHARS {
        return Err(ClipError::new(Path::root().field("name"), K::BadName { max: MAX_NAME_CHARS }));
    }
    if spec.tracks.is_empty() && spec.parameters.is_empty() {
        return Err(ClipError::new(Path::root().field("tracks"), K::NoTracks));
    }
    Ok(())
}

/// A clip's timelines, one per distinct list of key times: tracks keyed at
/// the same times share one search.
#[derive(Default)]
struct Timelines {
    list: Vec<Timeline>,
    index: HashMap<Vec<u32>, u32>,
}

impl Timelines {
    /// The index of the timeline of `times`, added if it is new.
    fn intern(&mut self, times: Vec<f32>) -> u32 {
        let key: Vec<u32> = times.iter().map(|t| t.to_bits()).collect();
        *self.index.entry(key).or_insert_with(|| {
            self.list.push(Timeline::new(&times));
            (self.list.len() - 1) as u32
        })
    }
}

/// The time range a clip's keys cover so far.
#[derive(Debug, Clone, Copy)]
struct Domain {
    start: f32,
    end: f32,
}

impl Domain {
    /// No keys yet: any key widens it.
    const EMPTY: Domain = Domain { start: f32::INFINITY, end: f32::NEG_INFINITY };

    fn widen(&mut self, (first, last): (f32, f32)) {
        self.start = self.start.min(first);
        self.end = self.end.max(last);
    }

    /// Durations and clip-time arithmetic are f32 (the summary's
    /// `duration`), so the range must be too; `path` names the field that
    /// widened it past.
    fn check(self, path: Path) -> Result<(), ClipError> {
        if (self.end - self.start).is_finite() {
            return Ok(());
        }
        Err(ClipError::new(path, K::TimeRangeTooLarge { start: self.start, end: self.end }))
    }
}

/// A clip's joint tracks by channel and kind, and what they make of it: the
/// base pose (rest pose with constant tracks applied), the translated
/// joints, the time range.
struct JointTracks {
    base: Pose,
    translations: Vec3Tracks,
    rotations: QuatTracks,
    scales: Vec3Tracks,
    translated: Vec<u32>,
    domain: Domain,
}

impl JointTracks {
    /// Checks and compiles `tracks` (paths `/tracks/i/...`) in order, then
    /// refuses model-space transforms that could overflow.
    fn build(
        tracks: &[TrackSpec],
        skeleton: &Skeleton,
        timelines: &mut Timelines,
        meter: &mut Meter<'_>,
    ) -> Result<JointTracks, ClipError> {
        let mut out = JointTracks {
            base: skeleton.rest().clone(),
            translations: Vec3Tracks::default(),
            rotations: QuatTracks::default(),
            scales: Vec3Tracks::default(),
            translated: Vec::new(),
            domain: Domain::EMPTY,
        };
        let mut bounds = JointBounds::of_rest(skeleton.rest());
        let mut seen = HashSet::new();
        for (i, track) in tracks.iter().enumerate() {
            let path = Path::root().field("tracks").index(i);
            let joint = track_joint(track, skeleton, &path, &mut seen)?;
            let domain = out.add(track, joint, &path, timelines, meter, &mut bounds)?;
            out.domain.widen(domain);
            out.domain.check(path.field("times"))?;
        }
        bounds.check(skeleton)?;
        Ok(out)
    }

    /// Compiles `track` of joint `j` into its list and records its bound;
    /// returns the time range its keys cover.
    fn add(
        &mut self,
        track: &TrackSpec,
        j: usize,
        path: &Path,
        timelines: &mut Timelines,
        meter: &mut Meter<'_>,
        bounds: &mut JointBounds,
    ) -> Result<(f32, f32), ClipError> {
        let joint = j as u32;
        if track.channel == Channel::Translation {
            self.translated.push(joint);
        }
        if track.channel == Channel::Rotation {
            let Compiled { times, curve, domain } = compile::quat_track(track, path)?;
            self.rotations.push(joint, timelines.intern(times), curve, &mut self.base.rotations[j]);
            return Ok(domain);
        }
        let Compiled { times, curve, domain } = compile::vec3_track(track, path, meter)?;
        let (list, slot, bound) = match track.channel {
            Channel::Scale => (&mut self.scales, &mut self.base.scales[j], &mut bounds.scales[j]),
            _ => (&mut self.translations, &mut self.base.translations[j], &mut bounds.translations[j]),
        };
        *bound = curve.max_abs() as f64;
        list.push(joint, timelines.intern(times), curve, slot);
        Ok(domain)
    }

    /// Moves tracks that share key times into SIMD groups.
    fn group(&mut self) {
        self.translations.group();
        self.rotations.group();
        self.scales.group();
    }
}

/// The joint `track` animates, refusing an unknown joint and a second
/// track of the same joint and channel.
fn track_joint(
    track: &TrackSpec,
    skeleton: &Skeleton,
    path: &Path,
    seen: &mut HashSet<(usize, Channel)>,
) -> Result<usize, ClipError> {
    let joint = skeleton
        .index_of(&track.joint)
        .ok_or_else(|| ClipError::new(path.clone().field("joint"), K::UnknownJoint { joint: track.joint.clone() }))?;
    if !seen.insert((joint, track.channel)) {
        let kind = K::DuplicateTrack { joint: track.joint.clone(), channel: track.channel.as_str() };
        return Err(ClipError::new(path.clone().field("channel"), kind));
    }
    Ok(joint)
}

/// The clip's keyed IK, widening `domain` by the times of its tracks.
fn build_keyed_ik(
    spec: &ClipSpec,
    skeleton: &Skeleton,
    limits: &IkLimits,
    meter: &mut Meter<'_>,
    domain: &mut Domain,
) -> Result<Option<KeyedIk>, ClipError> {
    let ik = match KeyedIk::build(&spec.ik, skeleton, limits, meter)? {
        None => None,
        Some((ik, range)) => {
            if let Some(range) = range {
                domain.widen(range);
            }
            Some(ik)
        }
    };
    domain.check(Path::root().field("ik"))?;
    Ok(ik)
}

/// The clip's events, checked and sorted by time (stably: simultaneous
/// events keep their order).
fn build_events(specs: &[EventSpec]) -> Result<Vec<Event>, ClipError> {
    let mut events = Vec::with_capacity(specs.len());
    for (i, e) in specs.iter().enumerate() {
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
    Ok(events)
}

/// Per joint, the largest coordinate magnitude of its local translation
/// and scale over the whole clip (rest value, or its track's curve).
struct JointBounds {
    translations: Vec<f64>,
    scales: Vec<f64>,
}

impl JointBounds {
    fn of_rest(rest: &Pose) -> Self {
        let max = |v: &Vec<glam::Vec3A>| v.iter().map(|x| x.abs().max_element() as f64).collect();
        JointBounds { translations: max(&rest.translations), scales: max(&rest.scales) }
    }

    /// Refuses a clip whose model-space transforms could overflow f32
    /// (a 1,200-deep chain of scale 1.1 reaches 1e49): down each chain, the
    /// scale bound multiplies and the translation bound grows by the
    /// parent's scale times the local offset's length (≤ √3 × its largest
    /// coordinate; rotations keep lengths). A root's model transform is its
    /// local one, already a finite f32, so roots are not limited. A
    /// skinning matrix `M_j · invBind_j` has entries at most 4 × the
    /// largest of each, which must stay under `f32::MAX`.
    fn check(&self, skeleton: &Skeleton) -> Result<(), ClipError> {
        let n = skeleton.len();
        let (mut scale, mut reach) = (vec![0.0f64; n], vec![0.0f64; n]);
        let overflow =
            |path: Path, bound: f64, limit: f64| Err(ClipError::new(path, K::ModelSpaceOverflow { bound, limit }));
        let joint = |j: usize| Path::root().field("skeleton").field("joints").index(j);
        for j in 0..n {
            let local = self.translations[j] * 3f64.sqrt();
            (scale[j], reach[j]) = match skeleton.parent(j) {
                None => (self.scales[j], local),
                Some(p) => (scale[p] * self.scales[j], reach[p] + scale[p] * local),
            };
            let bound = scale[j].max(reach[j]);
            if skeleton.parent(j).is_some() && (bound.is_nan() || bound > MAX_MODEL_MAGNITUDE) {
                return overflow(joint(j), bound, MAX_MODEL_MAGNITUDE);
            }
            if let Some(bind) = skeleton.inverse_bind(j) {
                let skin = 4.0 * bound.max(1.0) * bind.abs().to_cols_array().into_iter().fold(0.0f32, f32::max) as f64;
                if skin > f32::MAX as f64 {
                    return overflow(joint(j).field("inverse_bind"), skin, f32::MAX as f64);
                }
            }
        }
        Ok(())
    }
}

/// A joint name: 1 to [`MAX_NAME_CHARS`] characters, as clip names.
fn check_joint_name(name: &str, path: Path) -> Result<(), ClipError> {
    if name.is_empty() {
        return Err(ClipError::new(path, K::EmptyJointName));
    }
    let chars = name.chars().count();
    if chars > MAX_NAME_CHARS {
        return Err(ClipError::new(path, K::JointNameTooLong { max: MAX_NAME_CHARS, chars }));
    }
    Ok(())
}

/// The skeleton of `spec`, or one root joint per animated joint in order of
/// first appearance when it has none (docs/clip-format.md, “Data model”).
fn build_skeleton(spec: &ClipSpec) -> Result<Skeleton, ClipError> {
    let Some(skel) = &spec.skeleton else {
        let mut names: Vec<String> = Vec::new();
        for (i, t) in spec.tracks.iter().enumerate() {
            check_joint_name(&t.joint, Path::root().field("tracks").index(i).field("joint"))?;
            if !names.contains(&t.joint) {
                names.push(t.joint.clone());
            }
        }
        let n = names.len();
        return Ok(Skeleton::new(names, vec![NO_PARENT; n], Pose::identity(n), None));
    };
    skeleton_from_spec(skel)
}

impl Skeleton {
    /// A skeleton on its own, such as a character's, under the rules of a clip's
    /// skeleton; a refusal's path points into it as into a clip (`/skeleton/joints/3/parent`).
    ///
    /// # Errors
    /// The first rule of docs/clip-format.md, “Data model”, the joints break.
    pub fn build(spec: &SkeletonSpec) -> Result<Skeleton, ClipError> {
        skeleton_from_spec(spec)
    }
}

/// The joints of `skel`, checked: names, parents before children, finite rests.
fn skeleton_from_spec(skel: &SkeletonSpec) -> Result<Skeleton, ClipError> {
    let joints = &skel.joints;
    let mut index: HashMap<&str, usize> = HashMap::with_capacity(joints.len());
    for (j, joint) in joints.iter().enumerate() {
        let path = Path::root().field("skeleton").field("joints").index(j);
        check_joint_name(&joint.name, path.clone().field("name"))?;
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
/// (a `start,end,fps` sample request). The caller bounds the count
/// with [`frame_count`] before asking for them.
pub fn frame_times(start: f64, end: f64, fps: f64) -> impl Iterator<Item = f64> {
    (0..frame_count(start, end, fps)).map(move |k| start + k as f64 / fps)
}

/// How many frames [`frame_times`] yields (0 for an empty or invalid
/// range), saturating at `u64::MAX`: a range of 1e20 frames must count as
/// too many, not wrap to none.
pub fn frame_count(start: f64, end: f64, fps: f64) -> u64 {
    if !(start.is_finite() && end.is_finite() && fps.is_finite() && fps > 0.0 && end >= start) {
        return 0;
    }
    // A tolerance so that e.g. 0..1 at 30 fps includes t = 1. The float
    // cast saturates; the `+ 1` must too.
    (((end - start) * fps + 1e-9).floor() as u64).saturating_add(1)
}

/// The numeric edge cases of issue 15: each derived value either stays a
/// finite f32 or the clip is refused with a code naming the field.
#[cfg(test)]
mod numeric_edges {
    use glam::{Quat, Vec3};

    use super::*;
    use crate::spec::{Interpolation, JointSpec, Keys, SkeletonSpec, Speed, TrackSpec, Transform};

    fn clip(tracks: Vec<TrackSpec>, skeleton: Option<SkeletonSpec>) -> Result<Clip, ClipError> {
        Clip::build(&ClipSpec {
            name: "edge".into(),
            skeleton,
            tracks,
            events: vec![],
            playback: Playback::Once,
            ..Default::default()
        })
    }

    fn translation(times: Vec<f32>, values: Vec<Vec3>) -> TrackSpec {
        TrackSpec::new("a", Channel::Translation, Interpolation::Linear, times, Keys::Vec3(values))
    }

    fn refusal(result: Result<Clip, ClipError>) -> (&'static str, String) {
        let e = result.expect_err("the clip must be refused");
        (e.kind.code(), e.path.to_pointer())
    }

    fn all_finite(pose: &Pose) -> bool {
        pose.translations.iter().chain(&pose.scales).all(|v| v.is_finite())
            && pose.rotations.iter().all(|q| q.is_finite())
    }

    #[test]
    fn frame_counts_saturate_instead_of_wrapping() {
        // (1e20 − 0)·1 + 1 frames is past u64::MAX; it used to wrap to 0.
        assert_eq!(frame_count(0.0, 1e20, 1.0), u64::MAX);
        assert_eq!(frame_count(0.0, f64::MAX, 240.0), u64::MAX);
        // Exactly the default pose limit: 0, 1/30, …, 9999/30.
        assert_eq!(frame_count(0.0, 9999.0 / 30.0, 30.0), 10_000);
        assert_eq!(frame_times(0.0, 9999.0 / 30.0, 30.0).count(), 10_000);
        assert_eq!(frame_count(0.0, 10_000.0 / 30.0, 30.0), 10_001);
    }

    #[test]
    fn subnormal_key_gaps_sample_finite_poses() {
        // 1/1.4e-45 overflows f32: the span search computed (t − t_i)·∞,
        // NaN at t = t_i (a BVH `Frame Time: 1e-45` gives such keys).
        let times = vec![0.0, 1e-45, 3e-45, 1.0];
        let values = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        for speed in [Speed::Keyed, Speed::Constant] {
            let mut track = translation(times.clone(), values.clone());
            track.speed = speed;
            let clip = clip(vec![track], None).expect("tiny gaps build");
            let mut sampler = Sampler::new();
            for t in [3e-45, 1e-45, 0.0, 2e-45, 0.5, 1.0] {
                clip.sample(t, &SampleOptions::default(), &mut sampler);
                assert!(all_finite(sampler.pose()), "{speed:?} at t = {t:e}");
            }
        }
    }

    #[test]
    fn constant_speed_over_tiny_times_samples_finite_poses() {
        // Normal gaps (1/gap fits f32) whose arc-length pieces fall at
        // subnormal spacing: those pieces merge, and every pose is finite.
        let times = vec![0.0, 1e-37, 2e-37, 4e-37];
        let values = vec![Vec3::ZERO, Vec3::new(1000.0, 5.0, 0.0), Vec3::new(-900.0, 0.0, 2.0), Vec3::ZERO];
        for interpolation in [Interpolation::Linear, Interpolation::CatmullRom] {
            let mut track = translation(times.clone(), values.clone());
            (track.interpolation, track.speed) = (interpolation, Speed::Constant);
            let clip = clip(vec![track], None).expect("normal gaps build");
            let mut sampler = Sampler::new();
            // At every arc-length breakpoint (where `t − t_i` is 0 and a
            // gap's infinite reciprocal made 0·∞ = NaN) and between them.
            let timeline = &clip.timelines[0];
            let breaks = (0..timeline.len()).map(|i| timeline.time(i) as f64);
            let between = (0..=400).map(|k| 4e-37 * k as f64 / 400.0);
            for t in breaks.rev().chain(between) {
                clip.sample(t, &SampleOptions::default(), &mut sampler);
                assert!(all_finite(sampler.pose()), "{interpolation:?} at t = {t:e}");
            }
        }
    }

    #[test]
    fn a_duration_past_f32_is_refused() {
        let wide = translation(vec![-3.4e38, 3.4e38], vec![Vec3::ZERO, Vec3::X]);
        assert_eq!(refusal(clip(vec![wide], None)), ("time_range_too_large", "/tracks/0/times".into()));
        // Each track fits; together they do not: the second one is named.
        let early = translation(vec![-3.4e38, 0.0], vec![Vec3::ZERO, Vec3::X]);
        let mut late = translation(vec![0.0, 3.4e38], vec![Vec3::ZERO, Vec3::X]);
        late.joint = "b".into();
        assert_eq!(refusal(clip(vec![early, late], None)), ("time_range_too_large", "/tracks/1/times".into()));
        // Half the range still builds, with a finite duration.
        let half = translation(vec![-1.7e38, 1.7e38], vec![Vec3::ZERO, Vec3::X]);
        assert_eq!(clip(vec![half], None).unwrap().duration(), 3.4e38);
    }

    fn chain(depth: usize, scale: f32) -> SkeletonSpec {
        let rest = Transform { translation: Vec3::X, rotation: Quat::IDENTITY, scale: Vec3::splat(scale) };
        let joints = (0..depth)
            .map(|j| JointSpec {
                name: if j == 0 { "a".into() } else { format!("j{j}") },
                parent: (j > 0).then(|| if j == 1 { "a".into() } else { format!("j{}", j - 1) }),
                rest,
                inverse_bind: None,
            })
            .collect();
        SkeletonSpec { joints }
    }

    #[test]
    fn a_deep_scale_chain_past_f32_is_refused() {
        let track = translation(vec![0.0, 1.0], vec![Vec3::ZERO, Vec3::X]);
        // Joint j's model scale is 1.1^(j+1); its offset of length ≤ √3
        // per joint, scaled by the parents, reaches √3·(1.1^(j+1) − 1)/0.1.
        let reach = |j: i32| 3f64.sqrt() * (1.1f64.powi(j + 1) - 1.0) / 0.1;
        let first_over = (0..1200).find(|&j| reach(j) > MAX_MODEL_MAGNITUDE).unwrap() as usize;
        assert!((830..850).contains(&first_over), "√3·1.1^840/0.1 ≈ 1e36");
        let (code, pointer) = refusal(clip(vec![track.clone()], Some(chain(1200, 1.1))));
        assert_eq!(code, "model_space_overflow");
        assert!(pointer.starts_with("/skeleton/joints/"), "{pointer}");
        let at: usize = pointer.rsplit('/').next().unwrap().parse().unwrap();
        assert!(at.abs_diff(first_over) <= 2, "refused at joint {at}, expected about {first_over}");
        // A 300-deep chain (1.1^300 ≈ 2.6e12) builds and its model space is finite.
        let clip = clip(vec![track], Some(chain(300, 1.1))).expect("a bounded chain builds");
        let mut sampler = Sampler::new();
        let model = SampleOptions { space: Space::Model, ..SampleOptions::default() };
        clip.sample(0.5, &model, &mut sampler);
        assert!(all_finite(sampler.pose()));
        let mut matrices = Vec::new();
        clip.matrices(0.5, &model, false, &mut sampler, &mut matrices);
        assert!(matrices.iter().all(|m| m.is_finite()));
    }

    #[test]
    fn an_inverse_bind_that_overflows_skinning_is_refused() {
        let track = translation(vec![0.0, 1.0], vec![Vec3::ZERO, Vec3::X]);
        let mut skeleton = chain(2, 2.0);
        // Scale 4 × entries 1e38 (× up to 4 terms) is past f32::MAX; 1e36 is not.
        skeleton.joints[1].inverse_bind = Some(glam::Mat4::from_diagonal(glam::Vec4::splat(1e38)));
        let refused = refusal(clip(vec![track.clone()], Some(skeleton.clone())));
        assert_eq!(refused, ("model_space_overflow", "/skeleton/joints/1/inverse_bind".into()));
        skeleton.joints[1].inverse_bind = Some(glam::Mat4::from_diagonal(glam::Vec4::splat(1e36)));
        let clip = clip(vec![track], Some(skeleton)).expect("a bounded skin builds");
        let (mut sampler, mut matrices) = (Sampler::new(), Vec::new());
        assert!(clip.matrices(1.0, &SampleOptions::default(), true, &mut sampler, &mut matrices));
        assert!(matrices.iter().all(|m| m.is_finite()));
    }

    fn hermite_rotation(values: Vec<glam::Vec4>, out_tangent: glam::Vec4) -> TrackSpec {
        let mut track =
            TrackSpec::new("a", Channel::Rotation, Interpolation::CubicHermite, vec![0.0, 100.0], Keys::Vec4(values));
        track.in_tangents = Some(Keys::Vec4(vec![glam::Vec4::ZERO; 2]));
        track.out_tangents = Some(Keys::Vec4(vec![out_tangent, glam::Vec4::ZERO]));
        track
    }

    #[test]
    fn a_hermite_rotation_through_zero_holds_its_key() {
        // q and −q with zero tangents: the cubic is exactly zero at u = ½.
        let track = hermite_rotation(vec![glam::Vec4::W, -glam::Vec4::W], glam::Vec4::ZERO);
        let built = clip(vec![track], None).expect("valid keys");
        let mut sampler = Sampler::new();
        built.sample(50.0, &SampleOptions::default(), &mut sampler);
        assert_eq!(sampler.pose().rotations[0], Quat::IDENTITY);
        let tangent = hermite_rotation(vec![glam::Vec4::W; 2], glam::Vec4::splat(3e38));
        assert_eq!(refusal(clip(vec![tangent], None)), ("curve_overflow", "/tracks/0/values/0".into()));
    }

    #[test]
    fn a_curve_overshooting_f32_is_refused() {
        // Hermite control point `c + h·b/3` = 100·3e38/3 = 1e40 leaves f32.
        let mut track = translation(vec![0.0, 100.0], vec![Vec3::ZERO, Vec3::ZERO]);
        track.interpolation = Interpolation::CubicHermite;
        track.in_tangents = Some(Keys::Vec3(vec![Vec3::ZERO; 2]));
        track.out_tangents = Some(Keys::Vec3(vec![Vec3::splat(3e38), Vec3::ZERO]));
        assert_eq!(refusal(clip(vec![track], None)), ("curve_overflow", "/tracks/0/values/0".into()));
    }
}
