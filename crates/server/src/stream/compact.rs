//! Compact frames on a stream (docs/compact-frames.md): the layout a stream
//! states once, chosen from the poses its motion can produce.
//!
//! The layout's ranges are what makes its error bound hold: a pose outside
//! them is clamped. So a compact stream plays only what its ranges were
//! taken from — one clip at full weight, sampled at every key and on a
//! 240 Hz grid, with its rest pose — and refuses the controls that would
//! play something else (a crossfade, a layer ramp, an `ik` control).

use std::sync::Arc;

use anim::compact::{Layout, MIN_DISTANCE, MIN_MAX_ERROR, Ranges, default_distance};
use anim::{Clip, Skeleton};
use formats::wire::compact::LayoutDoc;

use super::pinned::StreamMotion;

/// Samples per second the ranges are taken at, besides every key.
pub const RANGE_RATE: f32 = 240.0;

/// A compact stream's layout: the widths and ranges of its channels, the
/// document its `opened` message carries, and how far apart key frames
/// may be.
#[derive(Debug)]
pub struct CompactLayout {
    pub layout: Layout,
    /// The layout document (docs/compact-frames.md, "The layout document").
    pub document: Arc<str>,
    pub key_interval: u64,
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

/// The clip a compact stream of `motion` plays: its one layer's, when that
/// layer is the whole pose (full weight, not retargeted, the same joints, no
/// motion-level IK or root motion).
///
/// # Errors
/// `compact_unsupported`, saying what the motion has that compact frames cannot bound.
pub fn plain_clip(motion: &StreamMotion) -> Result<&Clip, CompactRefusal> {
    let refuse = |what: &str| CompactRefusal {
        code: "compact_unsupported",
        field: "encoding",
        detail: format!(
            "compact frames need a motion of one clip played whole; this one has {what} (docs/compact-frames.md)"
        ),
    };
    if motion.layer_count() != 1 {
        return Err(refuse("several layers"));
    }
    if !motion.ik().is_empty() {
        return Err(refuse("IK constraints of its own"));
    }
    if motion.has_root_motion() || motion.is_retargeted(0) {
        return Err(refuse("root motion or retargeting"));
    }
    if motion.weights().first().is_some_and(|w| *w != 1.0) {
        return Err(refuse("a layer weight below 1"));
    }
    let clip = motion.first_clip().clip();
    if clip.joint_count() != motion.skeleton().len() {
        return Err(refuse("a mask or a skeleton other than its clip's"));
    }
    Ok(clip)
}

/// The poses choosing a layout for `clip` samples (its rest pose too).
pub fn layout_samples(clip: &Clip) -> u64 {
    Ranges::clip_samples(clip, RANGE_RATE) + 1
}

impl CompactLayout {
    /// The layout of `clip`'s poses (and its rest pose) at `max_error` and
    /// `distance` (`None`: 10 % of the rest height), with key frames at least
    /// once a second at `fps`.
    pub fn of_clip(clip: &Clip, max_error: f32, distance: Option<f32>, fps: u32) -> CompactLayout {
        let skeleton: &Skeleton = clip.skeleton();
        let mut ranges = Ranges::of_clip(clip, RANGE_RATE);
        ranges.observe(skeleton.rest());
        let distance = distance.unwrap_or_else(|| default_distance(skeleton));
        let layout = Layout::choose(skeleton, &ranges, max_error, distance);
        let key_interval = u64::from(fps.max(1));
        let doc = LayoutDoc::new(&layout, skeleton.names(), key_interval);
        let document = serde_json::to_string(&doc).expect("a layout document serialises").into();
        CompactLayout { layout, document, key_interval }
    }

    /// What tells two layouts apart for sharing a playback.
    pub fn key(&self) -> (u32, u32) {
        (self.layout.max_error.to_bits(), self.layout.distance.to_bits())
    }
}
