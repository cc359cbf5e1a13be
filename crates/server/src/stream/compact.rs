//! Compact frames on a stream (docs/compact-frames.md): the layout a stream
//! states once, chosen from ranges that hold every pose its motion can
//! produce.
//!
//! The layout's ranges are what makes its error bound hold: a pose outside
//! them is clamped. A stream of one clip played whole takes them from the
//! clip's poses (sampled at every key and on a 240 Hz grid, with its rest
//! pose), and refuses the controls that would play something else (a
//! crossfade, a layer ramp, an `ik` control). A composed motion or a graph
//! takes ranges derived from its clips' (`anim::compact`), which hold its
//! poses under any layer weights and parameters.
//!
//! A control that would take a stream outside its layout (a crossfade, an
//! `ik` control, a layer ramp on one clip) gets a new one
//! ([`CompactLayout::after`]): the ranges widened to hold what the stream
//! plays from then on, sent before the next frame, a key frame.

use std::sync::Arc;

use anim::compact::{Layout, MIN_DISTANCE, MIN_MAX_ERROR, Ranges, Unbounded, default_distance};
use anim::{Clip, Event, Skeleton};
use formats::wire::compact::LayoutDoc;

use super::graph::GraphProgram;
use super::pinned::StreamMotion;

/// Samples per second the ranges are taken at, besides every key.
pub const RANGE_RATE: f32 = 240.0;

/// A compact stream's layout: the widths and ranges of its channels, the
/// document its `opened` message carries, and how far apart key frames
/// may be.
#[derive(Debug)]
pub struct CompactLayout {
    pub layout: Layout,
    /// The ranges it was chosen from, which a new layout widens.
    pub ranges: Ranges,
    /// The events its frames index (the stream's first clip's).
    pub events: Vec<Event>,
    /// The layout document (docs/compact-frames.md, "The layout document").
    pub document: Arc<str>,
    pub key_interval: u64,
    /// Whether the ranges hold the stream's poses at any layer weights
    /// (derived ones), so `layer` ramps keep within them.
    pub any_weights: bool,
}

/// What a client asked for: `max_error` and `distance` in metres (`None`:
/// the defaults).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CompactRequest {
    pub max_error: Option<f64>,
    pub distance: Option<f64>,
}

/// Why a stream cannot be sent compact, with its stable code.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{detail}")]
pub struct CompactRefusal {
    pub code: &'static str,
    /// The request field at fault.
    pub field: &'static str,
    pub detail: String,
}

impl CompactRequest {
    /// The checked bound and distance (`None`: the skeleton's default).
    ///
    /// # Errors
    /// `max_error_out_of_range`, `distance_out_of_range`.
    pub fn check(&self) -> Result<(f32, Option<f32>), CompactRefusal> {
        let max_error = self.max_error.unwrap_or(f64::from(anim::compact::DEFAULT_MAX_ERROR));
        if !max_error.is_finite() || max_error < f64::from(MIN_MAX_ERROR) || max_error > 1.0 {
            return Err(CompactRefusal {
                code: "max_error_out_of_range",
                field: "max_error",
                detail: format!("`max_error` must be within {MIN_MAX_ERROR}..=1 metres, got {max_error}"),
            });
        }
        let distance = match self.distance {
            Some(d) if !d.is_finite() || d < f64::from(MIN_DISTANCE) || d > 1e6 => {
                return Err(CompactRefusal {
                    code: "distance_out_of_range",
                    field: "distance",
                    detail: format!("`distance` must be within {MIN_DISTANCE}..=1e6 metres, got {d}"),
                });
            }
            d => d.map(|d| d as f32),
        };
        Ok((max_error as f32, distance))
    }
}

/// Where a compact stream's ranges come from.
#[derive(Debug, Clone, Copy)]
pub enum RangeSource<'a> {
    /// One clip played whole: its poses, observed.
    Clip(&'a Clip),
    /// A composed motion or a graph: derived from its clips' ranges.
    Derived,
}

/// What choosing the layout of a stream of `motion` (or `graph`) reads,
/// and what it costs in poses: its one clip's, or every distinct clip of
/// its motion (a graph: of its states' motions), with the rest pose.
///
/// # Errors
/// `compact_unsupported`, saying what the stream has that no range can bound.
pub fn range_source<'a>(
    motion: &'a StreamMotion,
    graph: Option<&GraphProgram>,
) -> Result<(RangeSource<'a>, u64), CompactRefusal> {
    let refuse = |u: Unbounded| refusal(u.0);
    if let Some(graph) = graph {
        Ranges::played_boundable(&graph.graph, &graph.post).map_err(refuse)?;
        return Ok((RangeSource::Derived, Ranges::played_samples(&graph.graph, &graph.post, RANGE_RATE)));
    }
    if let Some(clip) = plain_clip(motion) {
        return Ok((RangeSource::Clip(clip), Ranges::clip_samples(clip, RANGE_RATE) + 1));
    }
    Ranges::boundable(motion).map_err(refuse)?;
    Ok((RangeSource::Derived, Ranges::motion_samples(motion, RANGE_RATE)))
}

pub(super) fn refusal(what: &str) -> CompactRefusal {
    CompactRefusal {
        code: "compact_unsupported",
        field: "encoding",
        detail: format!("compact frames cannot bound this stream's poses: it has {what} (docs/compact-frames.md)"),
    }
}

/// The clip of a motion that is one clip played whole (one full-weight
/// layer, not retargeted, the same joints, no motion-level IK, springs or
/// root motion), whose own poses bound it.
pub(super) fn plain_clip(motion: &StreamMotion) -> Option<&Clip> {
    let clip = motion.first_clip().clip();
    let whole = motion.layer_count() == 1
        && motion.ik().is_empty()
        && motion.springs().is_none()
        && !motion.has_root_motion()
        && !motion.is_retargeted(0)
        && motion.weights().first().is_some_and(|w| *w == 1.0)
        && clip.joint_count() == motion.skeleton().len();
    whole.then_some(clip)
}

/// The ranges of `clip`'s poses and its rest pose: what a stream of it
/// played whole takes its layout from.
pub(super) fn clip_ranges(clip: &Clip) -> Ranges {
    let mut ranges = Ranges::of_clip(clip, RANGE_RATE);
    ranges.observe(clip.skeleton().rest());
    ranges
}

/// What makes a compact stream choose a new layout (docs/compact-frames.md).
#[derive(Debug, Clone)]
pub enum Relayout {
    /// It plays this motion from now on, at any layer weights: a
    /// crossfade's target (the fade itself between it and what played), or
    /// a clip stream's motion once a layer ramp weighs it.
    Plays(Arc<StreamMotion>),
    /// An `ik` control's constraints turn these joints.
    Ik(Vec<anim::ik::IkConstraint>),
}

impl Relayout {
    /// The range samples it takes: each distinct clip of the motion it
    /// plays and the rest pose, or (IK) one pass over the ranges.
    pub fn samples(&self) -> u64 {
        match self {
            Relayout::Plays(motion) => Ranges::motion_samples(motion, RANGE_RATE),
            Relayout::Ik(_) => 1,
        }
    }
}

/// The largest price of one pose of any clip a stream of `motion` (or
/// `graph`) plays: what each of its range samples costs.
pub fn range_sample_price(
    motion: &StreamMotion,
    graph: Option<&GraphProgram>,
    clip_pose: impl Fn(&Clip) -> u64,
) -> u64 {
    let largest = |m: &StreamMotion| m.layers().map(|c| clip_pose(c.clip())).max().unwrap_or(0);
    match graph {
        Some(g) => g.graph.state_motions().chain(g.post.mix()).map(|m| largest(m)).max().unwrap_or(0),
        None => largest(motion),
    }
}

impl CompactLayout {
    /// The layout of a stream of `motion` (or `graph`) at `max_error` and
    /// `distance` (`None`: 10 % of the rest height), with key frames at
    /// least once a second at `fps`.
    ///
    /// # Errors
    /// As [`range_source`].
    pub fn of_stream(
        (motion, graph): (&StreamMotion, Option<&GraphProgram>),
        max_error: f32,
        distance: Option<f32>,
        fps: u32,
    ) -> Result<Self, CompactRefusal> {
        let skeleton = motion.skeleton();
        let ranges = match (graph, range_source(motion, graph)?.0) {
            (_, RangeSource::Clip(clip)) => return Ok(CompactLayout::of_clip(clip, max_error, distance, fps)),
            (Some(g), RangeSource::Derived) => {
                let ranges = Ranges::of_played(&g.graph, &g.post, RANGE_RATE).map_err(|u| refusal(u.0))?;
                // A graph stream with `report` names its states and blend nodes in the document,
                // which its frames' graph report section indexes.
                let named = |doc: LayoutDoc| if g.report { doc.with_graph(&g.graph) } else { doc };
                return Ok(CompactLayout::of_ranges(skeleton, &ranges, (max_error, distance), fps, (&[], named)));
            }
            (None, RangeSource::Derived) => Ranges::of_motion(motion, RANGE_RATE).map_err(|u| refusal(u.0))?,
        };
        let events = motion.first_clip().clip().events();
        Ok(CompactLayout::of_ranges(skeleton, &ranges, (max_error, distance), fps, (events, |doc| doc)))
    }

    /// The layout of `clip`'s poses (and its rest pose) at `max_error` and
    /// `distance` (`None`: 10 % of the rest height), with key frames at least
    /// once a second at `fps`.
    pub fn of_clip(clip: &Clip, max_error: f32, distance: Option<f32>, fps: u32) -> CompactLayout {
        let (skeleton, ranges) = (clip.skeleton(), clip_ranges(clip));
        CompactLayout {
            any_weights: false,
            ..CompactLayout::of_ranges(skeleton, &ranges, (max_error, distance), fps, (clip.events(), |doc| doc))
        }
    }

    /// A layout of derived `ranges` (they hold any layer weights), whose
    /// frames' events index `events` (the stream's clip's: what its
    /// frames cross, docs/compact-frames.md), its document as `named`
    /// completes it.
    pub(super) fn of_ranges(
        skeleton: &Skeleton,
        ranges: &Ranges,
        (max_error, distance): (f32, Option<f32>),
        fps: u32,
        (events, named): (&[Event], impl FnOnce(LayoutDoc) -> LayoutDoc),
    ) -> CompactLayout {
        let distance = distance.unwrap_or_else(|| default_distance(skeleton));
        let layout = Layout::choose(skeleton, ranges, max_error, distance);
        let key_interval = u64::from(fps.max(1));
        let doc = named(LayoutDoc::new(&layout, skeleton.names(), key_interval, events));
        let document = serde_json::to_string(&doc).expect("a layout document serialises").into();
        let (ranges, events) = (ranges.clone(), events.to_vec());
        CompactLayout { layout, ranges, events, document, key_interval, any_weights: true }
    }

    /// The layout a stream of this one needs once `change` applies, or
    /// `None` when this one still holds every pose it can play and its
    /// frames' events are the same. The ranges only widen, so they hold
    /// both sides of a crossfade (docs/compact-frames.md, "A new layout").
    ///
    /// # Errors
    /// As [`range_source`]: a crossfade to a motion no range bounds.
    pub fn after(&self, change: &Relayout, skeleton: &Skeleton) -> Result<Option<CompactLayout>, CompactRefusal> {
        let mut ranges = self.ranges.clone();
        let (events, any_weights) = match change {
            Relayout::Plays(motion) => {
                // A lerp between values within either range stays within
                // their union (derived ranges carry their rounding margin).
                ranges.union(&Ranges::of_motion(motion, RANGE_RATE).map_err(|u| refusal(u.0))?);
                (motion.first_clip().clip().events(), true)
            }
            Relayout::Ik(constraints) => {
                ranges.turned_by(skeleton, constraints, None);
                (self.events.as_slice(), self.any_weights)
            }
        };
        if ranges == self.ranges && events == self.events.as_slice() {
            return Ok(None);
        }
        let (max_error, distance) = (self.layout.max_error, Some(self.layout.distance));
        let fps = u32::try_from(self.key_interval).unwrap_or(u32::MAX);
        let layout = CompactLayout::of_ranges(skeleton, &ranges, (max_error, distance), fps, (events, |doc| doc));
        Ok(Some(CompactLayout { any_weights, ..layout }))
    }

    /// What tells two layouts apart for sharing a playback.
    pub fn key(&self) -> (u32, u32) {
        (self.layout.max_error.to_bits(), self.layout.distance.to_bits())
    }
}
