//! What a broadcast has played since its tick 0, as far as its compact
//! frames care (docs/compact-frames.md, "A broadcast's layouts"): the
//! distinct motions its crossfades faded to, the joints its `ik` controls
//! turned, and whether a layer ramp weighed its one clip.
//!
//! A compact layout's ranges must hold every pose the broadcast may play,
//! and they only widen; so the layout of one `max_error` and `distance`
//! is a pure function of the definition and this [`Reach`]: the
//! definition's ranges, united with each played motion's derived ranges,
//! the turned joints' rotations sent free, and the events of the motion
//! playing. Every node steps the same controls in the same order, so each
//! holds the same reach at each tick, and a checkpoint carries it (the
//! motions named by their controls, which the store keeps while it names
//! them): a late node, a restarted one and a compact watch opened after
//! the controls all choose the very layouts of the node that played them.
//!
//! Bounded: at most [`MAX_PLAYED`] distinct motions (a crossfade to the
//! same motion again, its clips at the same versions, counts once); a
//! crossfade to one more is refused `broadcast_motions_full`, and the
//! joints turned are at most the skeleton's.

use std::sync::Arc;

use anim::compact::{Ranges, turned_joints};
use anim::ik::IkConstraint;

use super::compact::{CompactLayout, CompactRefusal, RANGE_RATE, RangeSource, range_sample_price, range_source};
use super::control::{Control, Crossfade};
use super::params::StreamParams;
use super::pinned::StreamMotion;

/// Distinct motions a broadcast may crossfade to over its life.
pub const MAX_PLAYED: usize = 32;

/// A motion a crossfade played, the control that named it, and what tells
/// it from another (its message and its clips' versions).
#[derive(Debug, Clone)]
struct PlayedMotion {
    motion: Arc<StreamMotion>,
    control: Arc<str>,
    identity: Option<String>,
}

/// See the module docs.
#[derive(Debug, Clone)]
pub struct Reach {
    /// The definition is one clip played whole (its layout holds its own
    /// poses only, not other layer weights).
    plain: bool,
    motions: Vec<PlayedMotion>,
    /// Ascending, each once.
    turned: Vec<usize>,
    /// A layer ramp weighed the plain clip before any crossfade.
    reweighted: bool,
    /// The played motion playing now (`None`: the definition's).
    playing: Option<usize>,
    /// A crossfade heard from another node found [`MAX_PLAYED`] motions
    /// already played: no layout holds it any more.
    overflowed: bool,
}

/// What tells two reaches apart: equal ones choose equal layouts.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ReachSig {
    motions: Vec<Arc<str>>,
    turned: Vec<usize>,
    reweighted: bool,
    playing: Option<usize>,
    overflowed: bool,
}

/// A reach as a checkpoint writes it: the played motions by control id.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReachBits {
    pub motions: Vec<String>,
    pub turned: Vec<usize>,
    pub reweighted: bool,
    pub playing: Option<usize>,
    pub overflowed: bool,
}

impl Reach {
    /// A broadcast of `params` before its tick 0: nothing played.
    pub fn new(params: &StreamParams) -> Self {
        let plain = params.graph.is_none() && super::compact::plain_clip(&params.motion).is_some();
        Reach { plain, motions: Vec::new(), turned: Vec::new(), reweighted: false, playing: None, overflowed: false }
    }

    pub fn sig(&self) -> ReachSig {
        ReachSig {
            motions: self.motions.iter().map(|m| Arc::clone(&m.control)).collect(),
            turned: self.turned.clone(),
            reweighted: self.reweighted,
            playing: self.playing,
            overflowed: self.overflowed,
        }
    }

    /// Nothing played that the definition's own layout does not hold.
    fn is_start(&self) -> bool {
        self.motions.is_empty() && self.turned.is_empty() && !self.reweighted && !self.overflowed
    }

    /// Whether `control` would crossfade to a motion beyond [`MAX_PLAYED`].
    pub fn full_for(&self, control: &Control) -> bool {
        match control {
            Control::Crossfade(fade) => self.motions.len() >= MAX_PLAYED && self.find(fade).is_none(),
            _ => false,
        }
    }

    /// Takes in `control` (checked), applied as control `id`.
    pub fn apply(&mut self, control: &Control, id: &Arc<str>, skeleton: &anim::Skeleton) {
        match control {
            Control::Crossfade(fade) => self.crossfaded(fade, id),
            Control::SetIk(constraints) => self.turn(skeleton, constraints),
            Control::Layer { .. } if self.plain && self.motions.is_empty() => self.reweighted = true,
            _ => {}
        }
    }

    fn find(&self, fade: &Crossfade) -> Option<usize> {
        let identity = identity(fade);
        self.motions
            .iter()
            .position(|m| Arc::ptr_eq(&m.motion, &fade.to) || (identity.is_some() && m.identity == identity))
    }

    fn crossfaded(&mut self, fade: &Crossfade, id: &Arc<str>) {
        if let Some(at) = self.find(fade) {
            self.playing = Some(at);
            return;
        }
        if self.motions.len() >= MAX_PLAYED {
            self.overflowed = true;
            return;
        }
        let played = PlayedMotion { motion: Arc::clone(&fade.to), control: Arc::clone(id), identity: identity(fade) };
        self.motions.push(played);
        self.playing = Some(self.motions.len() - 1);
    }

    fn turn(&mut self, skeleton: &anim::Skeleton, constraints: &[IkConstraint]) {
        self.turned.extend(turned_joints(skeleton, constraints));
        self.turned.sort_unstable();
        self.turned.dedup();
    }

    /// As a checkpoint writes it (`None`: nothing played).
    pub fn bits(&self) -> Option<ReachBits> {
        (!self.is_start()).then(|| ReachBits {
            motions: self.motions.iter().map(|m| m.control.to_string()).collect(),
            turned: self.turned.clone(),
            reweighted: self.reweighted,
            playing: self.playing,
            overflowed: self.overflowed,
        })
    }

    /// The reach `bits` describe, each motion the crossfade `find` gives
    /// for its control's id; `None` if one is missing.
    pub fn from_bits(
        params: &StreamParams,
        bits: Option<&ReachBits>,
        find: &dyn Fn(&str) -> Option<Crossfade>,
    ) -> Option<Reach> {
        let mut reach = Reach::new(params);
        let Some(bits) = bits else { return Some(reach) };
        for id in &bits.motions {
            let fade = find(id)?;
            let identity = identity(&fade);
            reach.motions.push(PlayedMotion { motion: fade.to, control: id.as_str().into(), identity });
        }
        reach.turned.clone_from(&bits.turned);
        (reach.reweighted, reach.playing, reach.overflowed) = (bits.reweighted, bits.playing, bits.overflowed);
        Some(reach)
    }

    /// The range samples choosing a layout of this reach takes: the
    /// definition's, each played motion's, and one pass for the rest.
    pub fn samples(&self, params: &StreamParams) -> u64 {
        let (motion, graph) = (&params.motion, params.graph.as_ref());
        let base = range_source(motion, graph).map_or(0, |(_, samples)| samples);
        let ramped = if self.reweighted { Ranges::motion_samples(motion, RANGE_RATE) } else { 0 };
        let played: u64 = self.motions.iter().map(|m| Ranges::motion_samples(&m.motion, RANGE_RATE)).sum();
        base.saturating_add(ramped).saturating_add(played).saturating_add(1)
    }

    /// The price of one range sample: a pose of the costliest clip of any
    /// motion it samples.
    pub fn sample_price(&self, params: &StreamParams, clip_pose: &dyn Fn(&anim::Clip) -> u64) -> u64 {
        let base = range_sample_price(&params.motion, params.graph.as_ref(), clip_pose);
        let played = self.motions.iter().map(|m| range_sample_price(&m.motion, None, clip_pose));
        played.fold(base, u64::max)
    }

    /// The layout at `max_error` and `distance` (`None`: the skeleton's
    /// default) holding everything this reach played; a frame's events
    /// index the playing motion's first clip's.
    ///
    /// # Errors
    /// `compact_unsupported`: a motion played that no range bounds, or
    /// more than [`MAX_PLAYED`].
    pub fn layout(
        &self,
        params: &StreamParams,
        max_error: f32,
        distance: Option<f32>,
    ) -> Result<CompactLayout, CompactRefusal> {
        let (motion, graph, fps) = (&params.motion, params.graph.as_ref(), params.fps);
        if self.is_start() {
            return CompactLayout::of_stream((motion, graph), max_error, distance, fps);
        }
        if self.overflowed {
            return Err(super::compact::refusal(&format!("crossfaded to more than {MAX_PLAYED} distinct motions")));
        }
        let derived = |m: &StreamMotion| Ranges::of_motion(m, RANGE_RATE).map_err(|u| super::compact::refusal(u.0));
        let mut ranges = match range_source(motion, graph)?.0 {
            RangeSource::Clip(clip) => super::compact::clip_ranges(clip),
            RangeSource::Derived => derived(motion)?,
        };
        if self.reweighted {
            ranges.union(&derived(motion)?);
        }
        for m in &self.motions {
            ranges.union(&derived(&m.motion)?);
        }
        self.turned.iter().for_each(|&j| ranges.free_rotation(j));
        let playing = self.playing.map_or(motion, |at| &self.motions[at].motion);
        let events = playing.first_clip().clip().events();
        let skeleton = motion.skeleton();
        let layout = CompactLayout::of_ranges(skeleton, &ranges, (max_error, distance), fps, (events, |doc| doc));
        let any_weights = !(self.plain && self.motions.is_empty() && !self.reweighted);
        Ok(CompactLayout { any_weights, ..layout })
    }
}

/// What tells a crossfade's motion from another: its message and the
/// versions of its clips (`None`: not written down; only the same motion
/// is the same then).
fn identity(fade: &Crossfade) -> Option<String> {
    let source = fade.source.as_ref()?;
    let versions: Vec<String> = fade.to.layers().map(|c| format!("{}@{}", c.id(), c.version())).collect();
    Some(format!("{source}|{}", versions.join(",")))
}
