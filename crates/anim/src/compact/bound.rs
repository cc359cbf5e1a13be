//! Ranges that bound every pose a composed motion or a graph can produce
//! (docs/compact-frames.md, “What a compact stream plays”), derived by
//! interval arithmetic from its clips' ranges instead of observed.
//!
//! Per joint, starting from the rest pose and layer by layer:
//! - a blend layer moves a translation or scale toward the layer's by a
//!   weight in [0, 1], so the result lies between the two: the union of the
//!   ranges holds it, whatever the weights, masks and sync;
//! - an additive layer adds `w·(t_l − t_r)` (`w` in [0, 1]) to a
//!   translation, and multiplies a scale by `1 + w·(s_l / s_r − 1)`: the
//!   range of the difference (or of the factor) hulled with 0 (or 1) is
//!   added (or multiplied, as intervals);
//! - a rotation stays constant only while every layer that reaches the joint
//!   holds the same one (an additive layer: its reference's); otherwise it is
//!   sent free (any three components), since a slerp leaves the components'
//!   ranges. IK and springs turn joints and never move or scale them.
//!
//! A graph's poses are its states' motions under weights its parameters
//! set, crossfaded (a lerp): the union of every state's bound holds them.
//! Clip layers around a graph layer its poses as a clip's: that union is
//! the graph layer's own ranges.

use glam::{Quat, Vec3A};

use super::{JointRange, ROUNDING_MARGIN, Ranges, Unbounded, canonical, moved};
use crate::graph::{Graph, GraphPost};
use crate::ik::IkConstraint;
use crate::motion::{ClipSource, LayerMode, LayerView, Motion, UNMAPPED};
use crate::spring::Springs;
use crate::{Clip, Pose, Skeleton};

/// The ranges of each distinct clip a bound reads, taken once.
struct ClipRanges<'a> {
    rate: f32,
    taken: Vec<(&'a Clip, Ranges)>,
}

impl<'a> ClipRanges<'a> {
    fn of(&mut self, clip: &'a Clip) -> &Ranges {
        let at = match self.taken.iter().position(|(c, _)| std::ptr::eq(*c, clip)) {
            Some(at) => at,
            None => {
                self.taken.push((clip, Ranges::of_clip(clip, self.rate)));
                self.taken.len() - 1
            }
        };
        &self.taken[at].1
    }
}

impl Ranges {
    /// The rest pose of `skeleton` alone.
    pub fn at_rest(skeleton: &Skeleton) -> Ranges {
        let mut ranges = Ranges::new(skeleton.len());
        ranges.observe(skeleton.rest());
        ranges
    }

    /// Widens each joint's ranges to hold `other`'s too (of as many joints).
    pub fn union(&mut self, other: &Ranges) {
        for (r, o) in self.joints.iter_mut().zip(&other.joints) {
            r.blend(o);
        }
    }

    /// Joint `j`'s rotation may be any rotation.
    pub fn free_rotation(&mut self, j: usize) {
        self.joints[j].free_rotation();
    }

    /// Frees the rotations `ik` and `springs` turn (they change rotations
    /// only: docs/ik.md, docs/springs.md).
    pub fn turned_by(&mut self, skeleton: &Skeleton, ik: &[IkConstraint], springs: Option<&Springs>) {
        turned_joints(skeleton, ik).into_iter().for_each(|j| self.free_rotation(j));
        springs.into_iter().flat_map(Springs::spring_joints).for_each(|j| self.free_rotation(j));
    }

    /// Ranges holding every pose `motion` produces at any layer weights
    /// (its own IK and springs included), its clips' own ranges taken at
    /// every key and `rate` times a second.
    ///
    /// # Errors
    /// As [`Ranges::boundable`].
    pub fn of_motion<C: ClipSource>(motion: &Motion<C>, rate: f32) -> Result<Ranges, Unbounded> {
        let mut clips = ClipRanges { rate, taken: Vec::new() };
        of_motion(motion, &mut clips)
    }

    /// Whether its clips' ranges can bound `motion`'s poses: what
    /// [`Ranges::of_motion`] refuses, checked without sampling a clip.
    ///
    /// # Errors
    /// A layer retargeted onto a character whose hips are below a joint of
    /// another role (`Ranges::retargeted`).
    pub fn boundable<C: ClipSource>(motion: &Motion<C>) -> Result<(), Unbounded> {
        motion.layer_views().filter_map(|l| l.retarget).try_for_each(|(r, _)| moved::retarget_boundable(r))
    }

    /// Ranges holding every pose a motion over `graph` produces: the graph's
    /// own, or with clip layers beside it ([`GraphPost::mix`]) those layered
    /// as [`Ranges::of_motion`] does with the graph's ranges as its layer's;
    /// then the joints `post`'s IK and springs turn.
    ///
    /// # Errors
    /// As [`Ranges::of_motion`], for any state's motion and the clip layers.
    pub fn of_played<C: ClipSource>(graph: &Graph<C>, post: &GraphPost<C>, rate: f32) -> Result<Ranges, Unbounded> {
        let mut clips = ClipRanges { rate, taken: Vec::new() };
        let mut own = Ranges::at_rest(graph.skeleton());
        for motion in graph.state_motions() {
            own.union(&of_motion(motion, &mut clips)?);
        }
        let Some(mix) = post.mix() else {
            own.turned_by(graph.skeleton(), post.ik(), post.springs());
            return Ok(own);
        };
        Ranges::boundable(mix)?;
        let skeleton = mix.skeleton();
        let mut ranges = Ranges::at_rest(skeleton);
        for layer in mix.layer_views() {
            if layer.external {
                apply_layer(&mut ranges, &layer, &own);
            } else {
                let clip = clips.of(layer.clip);
                apply_layer(&mut ranges, &layer, moved(&layer, clip)?.as_ref().unwrap_or(clip));
            }
        }
        ranges.turned_by(skeleton, post.ik(), post.springs());
        for r in &mut ranges.joints {
            r.pad();
        }
        Ok(ranges)
    }

    /// Whether [`Ranges::of_played`] bounds a motion over `graph`.
    ///
    /// # Errors
    /// As [`Ranges::of_played`].
    pub fn played_boundable<C: ClipSource>(graph: &Graph<C>, post: &GraphPost<C>) -> Result<(), Unbounded> {
        graph.state_motions().try_for_each(|m| Ranges::boundable(m))?;
        post.mix().map_or(Ok(()), |m| Ranges::boundable(m))
    }

    /// As [`Ranges::graph_samples`], and each clip layer's beside the graph.
    pub fn played_samples<C: ClipSource>(graph: &Graph<C>, post: &GraphPost<C>, rate: f32) -> u64 {
        let layers = post.mix().into_iter().flat_map(|m| m.layer_views().filter(|l| !l.external).map(|l| l.clip));
        distinct_samples(graph.state_motions().flat_map(|m| m.layers().map(ClipSource::clip)).chain(layers), rate)
    }

    /// How many clip poses [`Ranges::of_motion`] samples: each distinct
    /// clip's [`Ranges::clip_samples`] and the rest pose.
    pub fn motion_samples<C: ClipSource>(motion: &Motion<C>, rate: f32) -> u64 {
        distinct_samples(motion.layers().map(ClipSource::clip), rate)
    }

    /// As [`Ranges::motion_samples`], for every state of `graph`.
    pub fn graph_samples<C: ClipSource>(graph: &Graph<C>, rate: f32) -> u64 {
        distinct_samples(graph.state_motions().flat_map(|m| m.layers().map(ClipSource::clip)), rate)
    }

    /// The first joint of `pose` outside the ranges and the channel that
    /// leaves them: a translation or scale beyond its range, a rotation
    /// other than a constant one (by more than 1e-6 rad, a slerp's rounding
    /// between equal rotations) or beyond its components' ranges.
    pub fn outside(&self, pose: &Pose) -> Option<(usize, &'static str)> {
        self.joints.iter().enumerate().find_map(|(j, r)| r.outside(pose, j).map(|channel| (j, channel)))
    }
}

fn distinct_samples<'a>(clips: impl Iterator<Item = &'a Clip>, rate: f32) -> u64 {
    let mut seen: Vec<&Clip> = Vec::new();
    let mut samples = 1;
    for clip in clips {
        if !seen.iter().any(|c| std::ptr::eq(*c, clip)) {
            seen.push(clip);
            samples += Ranges::clip_samples(clip, rate);
        }
    }
    samples
}

fn of_motion<'a, C: ClipSource>(motion: &'a Motion<C>, clips: &mut ClipRanges<'a>) -> Result<Ranges, Unbounded> {
    Ranges::boundable(motion)?;
    let skeleton = motion.skeleton();
    let mut ranges = Ranges::at_rest(skeleton);
    for layer in motion.layer_views() {
        let own = clips.of(layer.clip);
        apply_layer(&mut ranges, &layer, moved(&layer, own)?.as_ref().unwrap_or(own));
    }
    ranges.turned_by(skeleton, motion.ik(), motion.springs());
    for r in &mut ranges.joints {
        r.pad();
    }
    Ok(ranges)
}

/// A layer's clip ranges `own` as the layer plays them, when it moves them:
/// retargeted onto its character, its root kept in place by `extract`.
fn moved(layer: &LayerView<'_>, own: &Ranges) -> Result<Option<Ranges>, Unbounded> {
    if layer.retarget.is_none() && layer.extract.is_none() {
        return Ok(None);
    }
    let mut own = match layer.retarget {
        Some((retargeter, planter)) => Ranges::retargeted(retargeter, planter, own)?,
        None => own.clone(),
    };
    layer.extract.iter().for_each(|e| own.extracted(e));
    Ok(Some(own))
}

/// Layers one motion layer's ranges (`own`, in its clip's joints) onto `ranges`.
fn apply_layer(ranges: &mut Ranges, layer: &LayerView<'_>, own: &Ranges) {
    for (j, r) in ranges.joints.iter_mut().enumerate() {
        let m = layer.map[j];
        if m == UNMAPPED || layer.mask[j] <= 0.0 {
            continue;
        }
        let from = &own.joints[m as usize];
        match (layer.mode, layer.reference) {
            (LayerMode::Additive, Some(reference)) => r.add(from, reference, m as usize),
            _ => r.blend(from),
        }
    }
}

impl JointRange {
    pub(super) fn free_rotation(&mut self) {
        self.first_rotation = Some(Quat::IDENTITY);
        self.rotation_varies = true;
        self.largest_seen = 0b1111;
    }

    fn is_constant_rotation(&self) -> bool {
        !self.rotation_varies
    }

    /// The one rotation of every pose (sign: largest positive), if it is one.
    pub(super) fn constant_rotation(&self) -> Option<Quat> {
        self.first_rotation.filter(|_| !self.rotation_varies)
    }

    /// Any lerp (slerp) of a pose within `self` toward one within `other`.
    fn blend(&mut self, other: &JointRange) {
        self.magnitude = self.magnitude.max(other.magnitude);
        self.t_min = self.t_min.min(other.t_min);
        self.t_max = self.t_max.max(other.t_max);
        self.s_min = self.s_min.min(other.s_min);
        self.s_max = self.s_max.max(other.s_max);
        let same = match (self.first_rotation, other.first_rotation) {
            (_, None) => true,
            (None, Some(_)) => {
                (self.first_rotation, self.rotation_varies) = (other.first_rotation, other.rotation_varies);
                self.largest_seen = other.largest_seen;
                self.q_min = other.q_min;
                self.q_max = other.q_max;
                return;
            }
            (Some(a), Some(b)) => self.is_constant_rotation() && other.is_constant_rotation() && a == b,
        };
        if !same {
            self.free_rotation();
        }
    }

    /// Any additive step, weight in [0, 1], of a layer within `layer` whose
    /// reference is joint `m` of `reference`.
    fn add(&mut self, layer: &JointRange, reference: &Pose, m: usize) {
        let (tr, sr, qr) = (reference.translations[m], reference.scales[m], reference.rotations[m]);
        self.magnitude = self.magnitude.max(layer.magnitude).max(tr.abs().max_element()).max(sr.abs().max_element());
        self.t_min += (layer.t_min - tr).min(Vec3A::ZERO);
        self.t_max += (layer.t_max - tr).max(Vec3A::ZERO);
        for a in 0..3 {
            let (f_lo, f_hi) = factor(layer.s_min[a], layer.s_max[a], sr[a]);
            let corners = [self.s_min[a] * f_lo, self.s_min[a] * f_hi, self.s_max[a] * f_lo, self.s_max[a] * f_hi];
            self.s_min[a] = corners.into_iter().fold(f32::INFINITY, f32::min);
            self.s_max[a] = corners.into_iter().fold(f32::NEG_INFINITY, f32::max);
            self.magnitude = self.magnitude.max(self.s_min[a].abs()).max(self.s_max[a].abs());
        }
        let unchanged = layer.is_constant_rotation() && layer.first_rotation == Some(canonical(qr));
        if !unchanged {
            self.free_rotation();
        }
    }

    /// Widens every moving axis by the rounding margin.
    fn pad(&mut self) {
        let margin = Vec3A::splat(self.magnitude.max(self.t_min.abs().max(self.t_max.abs()).max_element()));
        let moving = self.t_min.cmplt(self.t_max);
        self.t_min = Vec3A::select(moving, self.t_min - margin * ROUNDING_MARGIN, self.t_min);
        self.t_max = Vec3A::select(moving, self.t_max + margin * ROUNDING_MARGIN, self.t_max);
        let margin = Vec3A::splat(self.magnitude.max(self.s_min.abs().max(self.s_max.abs()).max_element()));
        let moving = self.s_min.cmplt(self.s_max);
        self.s_min = Vec3A::select(moving, self.s_min - margin * ROUNDING_MARGIN, self.s_min);
        self.s_max = Vec3A::select(moving, self.s_max + margin * ROUNDING_MARGIN, self.s_max);
    }
}

impl JointRange {
    fn outside(&self, pose: &Pose, j: usize) -> Option<&'static str> {
        let within = |v: Vec3A, lo: Vec3A, hi: Vec3A| v.cmpge(lo).all() && v.cmple(hi).all();
        if !within(pose.translations[j], self.t_min, self.t_max) {
            return Some("translation");
        }
        if !within(pose.scales[j], self.s_min, self.s_max) {
            return Some("scale");
        }
        let q = canonical(pose.rotations[j]);
        let turned = match self.first_rotation {
            Some(first) if !self.rotation_varies => (first - q).length().min((first + q).length()) > 1e-6,
            _ if self.largest_seen.count_ones() == 1 => {
                let c = q.to_array();
                (0..4).any(|k| c[k] < self.q_min[k] || c[k] > self.q_max[k])
            }
            _ => false,
        };
        turned.then_some("rotation")
    }
}

/// The range of an additive scale factor `1 + w·(s / reference − 1)` for
/// `s` in `[lo, hi]` and `w` in [0, 1] (a zero reference counts as no change).
fn factor(lo: f32, hi: f32, reference: f32) -> (f32, f32) {
    if reference == 0.0 {
        return (1.0, 1.0);
    }
    let (a, b) = (lo / reference, hi / reference);
    (a.min(b).min(1.0), a.max(b).max(1.0))
}

/// The joints `ik` turns, ascending, each once: a two-bone chain's three,
/// an aim joint, a chain's joints and every ancestor of its effectors.
pub fn turned_joints(skeleton: &Skeleton, ik: &[IkConstraint]) -> Vec<usize> {
    let mut joints = Vec::new();
    for c in ik {
        match c {
            IkConstraint::TwoBone(t) => joints.extend(t.joints),
            IkConstraint::Aim(a) => joints.push(a.joint),
            IkConstraint::Chain(chain) => {
                joints.extend(chain.joints.iter().flatten());
                for e in &chain.effectors {
                    let mut at = Some(e.joint);
                    while let Some(j) = at {
                        joints.push(j);
                        at = skeleton.parent(j);
                    }
                }
            }
        }
    }
    joints.sort_unstable();
    joints.dedup();
    joints
}
