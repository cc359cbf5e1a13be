//! Sampling a [`Motion`]: each layer's clip time, its local pose, then the
//! layering of every output joint, bottom to top, over the rest pose; with
//! root motion, each layer's motion transform, the layered delta since the
//! previous sample and the running total. A layer samples and layers only
//! the joints it can still change (`coverage`): the pose is the same.

use super::coverage;
use super::joint_map::UNMAPPED;
use super::layering::{self, Joint};
use super::root::{Planar, RootAt, motion_transform};
use super::sync::position;
use super::{ClipSource, LayerMode, LayerTime, Motion, RootMode};
use crate::character::{FootPlanter, FootReport, Retargeter};
use crate::ik::{ChainStart, IkReport, IkSolver};
use crate::{Clip, Cursor, Ease, Playback, Pose, Skeleton, Space};

/// How a request samples a motion.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotionOptions {
    /// Applied to every layer's clip time after its playback.
    pub ease: Ease,
    pub space: Space,
}

/// Root motion of one sample: the layered delta since the previous sample
/// of this sampler (0 for the first) and the total since the first.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RootMotion {
    pub delta: Planar,
    pub total: Planar,
}

/// Reusable buffers: one per playback or per worker. It remembers each
/// layer's root position between samples, so consecutive samples report
/// the root's travel between them.
#[derive(Debug, Clone, Default)]
pub struct MotionSampler {
    cursors: Vec<Cursor>,
    layer: Pose,
    local: Pose,
    model: Pose,
    space: Space,
    phases: Vec<f64>,
    clip_times: Vec<f32>,
    /// Per layer, the output joints it must sample (see `coverage`), and
    /// scratch for working them out and for one layer's joints to sample
    /// in its clip's numbering.
    needs: Vec<u64>,
    hidden: Vec<u64>,
    kept: Vec<u64>,
    /// Per layer: where its root is, now and at the previous sample
    /// (`None`: no root in that layer, or no previous).
    roots: Vec<Option<RootAt>>,
    previous: Vec<Option<RootAt>>,
    root_motion: Option<RootMotion>,
    ik: IkSolver,
    /// The last sample's IK reports: each layer's clip constraints, then
    /// the motion's own (requests only).
    ik_reports: Vec<IkReport>,
    solved: Vec<IkReport>,
    /// Per layer, its own copy of the layer's retargeter (made at the
    /// first sample), and the source pose a retargeted layer samples into.
    retargeters: Vec<Option<Retargeter>>,
    /// Per layer, its own copy of the layer's foot planter and the clip
    /// time it last planted at (`None`: no frame since a start or a jump).
    planters: Vec<Option<(FootPlanter, Option<f32>)>>,
    source: Pose,
    /// A stateless request's spring simulation (motions with springs).
    springs: Option<Box<super::SpringRun>>,
}

impl MotionSampler {
    /// Empty buffers; they take their size at the first sample.
    pub fn new() -> Self {
        Self::default()
    }

    /// The pose of the last sample, in the space it asked for.
    pub fn pose(&self) -> &Pose {
        match self.space {
            Space::Local => &self.local,
            Space::Model => &self.model,
        }
    }

    /// The local pose of the last sample, whatever space was asked for.
    pub fn local(&self) -> &Pose {
        &self.local
    }

    /// Each layer's clip time in the last sample.
    pub fn clip_times(&self) -> &[f32] {
        &self.clip_times
    }

    /// The last sample's IK reports (docs/ik.md, “Reports”): each layer's clip
    /// constraints bottom to top, then, for [`Motion::sample`], the
    /// motion's own.
    pub fn ik_reports(&self) -> &[IkReport] {
        &self.ik_reports
    }

    /// The last sample's root motion, for motions that ask for it.
    pub fn root_motion(&self) -> Option<RootMotion> {
        self.root_motion
    }

    /// The next sample's delta is 0 (a jump: a seek), the total carries on;
    /// planted feet forget their anchors.
    pub fn rebase_root(&mut self) {
        self.previous.clear();
        self.forget_feet();
    }

    /// The first planting layer's feet at the last sample (docs/characters.md,
    /// “Planted feet”); `None` when no layer plants.
    pub fn feet(&self) -> Option<&[FootReport]> {
        self.planters.iter().flatten().next().map(|(planter, _)| planter.reports())
    }

    /// The next sample is a first frame for the foot planters: contact by
    /// height alone, new anchors.
    fn forget_feet(&mut self) {
        for (planter, last) in self.planters.iter_mut().flatten() {
            planter.reset();
            *last = None;
        }
    }

    /// What root motion carries to the next sample: each layer's root at
    /// the last sample (empty after a jump) and the last root motion.
    pub(crate) fn root_state(&self) -> (Vec<Option<RootAt>>, Option<RootMotion>) {
        (self.previous.clone(), self.root_motion)
    }

    /// Puts back what [`MotionSampler::root_state`] took.
    pub(crate) fn set_root_state(&mut self, previous: Vec<Option<RootAt>>, root_motion: Option<RootMotion>) {
        self.previous = previous;
        self.root_motion = root_motion;
    }

    /// The next sample starts the springs afresh from rest (its warmup).
    pub fn restart_springs(&mut self) {
        if let Some(run) = self.springs.as_mut() {
            run.restart();
        }
    }

    /// The next sample starts the root motion afresh: delta and total 0.
    pub fn restart_root(&mut self) {
        self.previous.clear();
        self.root_motion = None;
        self.forget_feet();
    }
}

impl MotionSampler {
    /// Puts the local pose into the space asked for.
    fn finish(&mut self, skeleton: &crate::Skeleton, space: Space) {
        if space == Space::Model {
            skeleton.to_model(&self.local, &mut self.model);
        }
        self.space = space;
    }
}

impl<C: ClipSource> Motion<C> {
    /// The pose at motion time `tau` with the motion's own weights (a
    /// request's answer). Returns the first layer's clip time.
    ///
    /// With spring chains, the sampler runs one simulation through the
    /// times it is given in order, from rest `warmup` before the first
    /// (docs/springs.md, “Time”); a time before the last starts it again.
    pub fn sample(&self, tau: f64, options: &MotionOptions, sampler: &mut MotionSampler) -> f32 {
        let clip_time = self.sample_local(tau, options.ease, None, sampler);
        if let Some(springs) = &self.springs {
            let MotionSampler { springs: run, local, .. } = sampler;
            let run = run.get_or_insert_with(|| Box::new(super::SpringRun::new(springs)));
            run.stateless_frame(self, springs, tau, options.ease, local);
        }
        sampler.finish(self.skeleton(), options.space);
        clip_time
    }

    /// The layered local pose at `tau` with the motion's own weights and
    /// its IK solved: what springs run on. With `only` (the joints a spring
    /// substep reads, [`crate::spring::Springs::reads`]) and no IK of the
    /// motion's own, right at those joints only, bit for bit as the whole
    /// pose has them ([`Motion::sample_joints_with`]); the motion's IK
    /// reads whole chains, so with it the whole pose is sampled.
    pub(super) fn sample_local(&self, tau: f64, ease: Ease, only: Option<&[u64]>, sampler: &mut MotionSampler) -> f32 {
        let mut phases = std::mem::take(&mut sampler.phases);
        self.phases_at(tau, &self.weights, &mut phases);
        let only = only.filter(|_| self.ik.is_empty());
        let clip_time = self.layer_into(tau, (&phases, &self.weights), (ease, only), sampler, None);
        sampler.phases = phases;
        if !self.ik.is_empty() {
            let MotionSampler { ik, local, ik_reports, solved, .. } = sampler;
            ik.solve(self.skeleton(), local, &self.ik, ChainStart::Cold, solved);
            ik_reports.extend_from_slice(solved);
        }
        clip_time
    }

    /// The pose at motion time `tau` with sync-group `phases` (from
    /// [`Motion::phases_at`] or kept by a stream) and live layer
    /// `weights`. Returns the first layer's clip time.
    ///
    /// # Panics
    /// If `phases` has fewer entries than the motion has sync groups, or
    /// `weights` fewer than it has layers.
    pub fn sample_with(
        &self,
        tau: f64,
        phases: &[f64],
        weights: &[f32],
        options: &MotionOptions,
        sampler: &mut MotionSampler,
    ) -> f32 {
        let clip_time = self.layer_into(tau, (phases, weights), (options.ease, None), sampler, None);
        sampler.finish(self.skeleton(), options.space);
        clip_time
    }

    /// [`Motion::sample_with`] in local space, right at the output joints
    /// in `only` (a bit set, joint `j` bit `j % 64` of word `j / 64`) and
    /// unspecified elsewhere: each layer samples and layers only those of
    /// its joints, so they are bit for bit what the whole pose has there.
    /// What a spring substep sees ([`crate::spring::Springs::reads`]).
    pub(crate) fn sample_joints_with(
        &self,
        tau: f64,
        (phases, weights): (&[f64], &[f32]),
        ease: Ease,
        only: &[u64],
        sampler: &mut MotionSampler,
    ) {
        self.layer_into(tau, (phases, weights), (ease, Some(only)), sampler, None);
        sampler.space = Space::Local;
    }

    /// [`Motion::sample_with`], in local space, for a motion built with a
    /// handed-in layer: `external` is that layer's pose (in the skeleton it
    /// was built with), layered where its clip's pose would be.
    pub(crate) fn sample_external(
        &self,
        tau: f64,
        (phases, weights): (&[f64], &[f32]),
        external: &Pose,
        sampler: &mut MotionSampler,
    ) {
        self.layer_into(tau, (phases, weights), (Ease::Linear, None), sampler, Some(external));
        sampler.finish(self.skeleton(), Space::Local);
    }

    /// Each layer's clip pose (its clip IK solved), layered into the
    /// sampler's local pose, with root motion; returns the first layer's
    /// clip time. With `only`, the output joints outside it are skipped
    /// (see [`Motion::sample_joints_with`]); a handed-in layer's pose is `external`.
    fn layer_into(
        &self,
        tau: f64,
        (phases, weights): (&[f64], &[f32]),
        (ease, only): (Ease, Option<&[u64]>),
        sampler: &mut MotionSampler,
        external: Option<&Pose>,
    ) -> f32 {
        let MotionSampler {
            cursors,
            layer: scratch,
            local,
            clip_times,
            roots,
            needs,
            hidden,
            kept,
            ik_reports,
            retargeters,
            planters,
            source,
            ..
        } = sampler;
        if retargeters.len() != self.layers.len() {
            *retargeters = self.layers.iter().map(|l| l.retarget.as_deref().cloned()).collect();
            *planters = self.layers.iter().map(|l| l.planter.as_deref().map(|p| (p.clone(), None))).collect();
        }
        let skeleton = self.skeleton();
        let words = coverage::words(self.skeleton().len());
        coverage::needs(self.layers.iter().map(|l| (l.mode, &l.reach)), weights, words, needs, hidden);
        if let Some(only) = only {
            coverage::restrict(needs, words, only);
        }
        cursors.resize_with(self.layers.len(), Cursor::default);
        roots.clear();
        clip_times.clear();
        ik_reports.clear();
        for (i, layer) in self.layers.iter().enumerate() {
            let (t, cycle) = self.layer_time(i, tau, phases, ease);
            let has_ik = layer.clip.clip().ik_count() > 0;
            clip_times.push(t);
            let need = &needs[i * words..(i + 1) * words];
            let direct = i == 0 && layer.mode == LayerMode::Blend && weights[0] >= 1.0 && layer.unmasked;
            if let Some(pose) = external.filter(|_| self.external == Some(i)) {
                handed_in(
                    layer,
                    (i, direct),
                    (pose, weights[i], need),
                    (self.skeleton(), self.parameters().entries()),
                    local,
                );
                roots.push(None);
                continue;
            }
            if direct {
                // The common case, and the bit-for-bit promise: the first
                // full-weight layer is the clip's own pose.
                let (retargeter, planter) = (retargeters[0].as_mut(), planters[0].as_mut());
                let sampling = Sampling { need, kept, source, retargeter, planter, skeleton };
                layer.sample_needed(t, sampling, &mut cursors[0], local);
                ik_reports.extend_from_slice(cursors[0].ik_reports());
                roots.push(self.take_root(layer, (cycle, t), local));
                continue;
            }
            if i == 0 {
                at_rest(self.skeleton(), self.parameters().entries(), local);
            }
            let parameters = !layer.parameters.is_empty() && weights[i] > 0.0;
            if layer.root.is_none() && !has_ik && !parameters && need.iter().all(|w| *w == 0) {
                // Weight 0, or hidden everywhere: nothing to sample. (A
                // clip with IK still solves, so its reports are there.)
                roots.push(None);
                continue;
            }
            let (retargeter, planter) = (retargeters[i].as_mut(), planters[i].as_mut());
            let sampling = Sampling { need, kept, source, retargeter, planter, skeleton };
            layer.sample_needed(t, sampling, &mut cursors[i], scratch);
            ik_reports.extend_from_slice(cursors[i].ik_reports());
            roots.push(self.take_root(layer, (cycle, t), scratch));
            layer.apply(scratch, weights[i], need, local);
        }
        if self.root.is_some() {
            self.layer_root_motion(weights, sampler);
        }
        sampler.clip_times[0]
    }

    /// Layer `i`'s unwrapped position at `tau` and the playback that maps
    /// it to a clip time: `offset + speed·τ` unsynced, `start + φ·D` (looping)
    /// synced.
    ///
    /// # Panics
    /// If there is no layer `i`, or `phases` has fewer entries than the
    /// motion has sync groups.
    pub fn layer_position(&self, i: usize, tau: f64, phases: &[f64]) -> (f64, Playback) {
        let clip: &Clip = self.layers[i].clip.clip();
        match self.layers[i].time {
            LayerTime::Free { offset, speed, playback } => (offset + speed * tau, playback),
            LayerTime::Synced { group } => {
                (f64::from(clip.range().start()) + phases[group] * self.durations[i], Playback::Loop)
            }
        }
    }

    /// Layer `i`'s clip time at `tau` and its loop cycle (0 unless it loops).
    fn layer_time(&self, i: usize, tau: f64, phases: &[f64], ease: Ease) -> (f32, i64) {
        let clip: &Clip = self.layers[i].clip.clip();
        let range = clip.range();
        let looping = range.duration() > 0.0;
        match self.layers[i].time {
            LayerTime::Free { offset, speed, playback } => {
                let x = offset + speed * tau;
                let cycle = if playback == Playback::Loop && looping { range.cycle(range.offset(x)).0 } else { 0.0 };
                (clip.clip_time(x, playback, ease), cycle as i64)
            }
            LayerTime::Synced { group } => {
                let x = position(phases[group], self.durations[i]);
                let cycle = if looping { phases[group].floor() + range.cycle(x).0 } else { 0.0 };
                (range.clip_time(f64::from(range.start()) + x, Playback::Loop, ease), cycle as i64)
            }
        }
    }

    /// Where the layer's root is in `pose` (its clip's joints) at its loop
    /// `cycle` and clip `time`; with `extract`, a blend layer's root is put
    /// back at its clip's start position and heading.
    fn take_root(&self, layer: &super::Layer<C>, (cycle, time): (i64, f32), pose: &mut Pose) -> Option<RootAt> {
        let (setup, root) = (self.root?, layer.root.as_ref()?);
        let (t, q) = (pose.translations[root.joint], pose.rotations[root.joint]);
        let m = motion_transform(setup.up, t, q);
        if setup.mode == RootMode::Extract && layer.mode == LayerMode::Blend {
            let in_place = root.cycle.start.then(m.inverse(setup.up), setup.up);
            (pose.translations[root.joint], pose.rotations[root.joint]) = in_place.apply(setup.up, t, q);
        }
        Some(RootAt { cycle, time, m })
    }

    /// The blend layers' deltas since the previous sample, layered like the
    /// pose (lerped by weight times the root's mask, from a zero delta), and
    /// the total.
    fn layer_root_motion(&self, weights: &[f32], sampler: &mut MotionSampler) {
        let Some(setup) = self.root else { return };
        let mut delta = Planar::IDENTITY;
        if sampler.previous.len() == self.layers.len() {
            for (i, layer) in self.layers.iter().enumerate() {
                let (Some(root), Some(from), Some(to)) = (&layer.root, sampler.previous[i], sampler.roots[i]) else {
                    continue;
                };
                if layer.mode == LayerMode::Blend {
                    let w = f64::from(weights[i] * layer.mask[setup.joint]);
                    delta = delta.lerp(root.cycle.delta(from, to, setup.up), w);
                }
            }
        }
        let total = sampler.root_motion.map_or(Planar::IDENTITY, |r| r.total).then(delta, setup.up);
        sampler.root_motion = Some(RootMotion { delta, total });
        sampler.previous.clone_from(&sampler.roots);
    }
}

/// The rest pose of `skeleton`, each of its `parameters` entries at its
/// rest value 0 (docs/clip-format.md, “Parameters”: no morph, no offset):
/// what the first layer is layered over.
fn at_rest(skeleton: &Skeleton, parameters: usize, local: &mut Pose) {
    local.copy_from(skeleton.rest());
    local.parameters.clear();
    local.parameters.resize(parameters, glam::Vec3A::ZERO);
}

/// Layers a handed-in `pose` as layer `i` (`direct`: the first, full and
/// unmasked, so it is the pose itself) at `weight` on the joints `need`s.
fn handed_in<C>(
    layer: &super::Layer<C>,
    (i, direct): (usize, bool),
    (pose, weight, need): (&Pose, f32, &[u64]),
    (skeleton, parameters): (&Skeleton, usize),
    local: &mut Pose,
) {
    if direct {
        local.copy_from(pose);
        return;
    }
    if i == 0 {
        at_rest(skeleton, parameters, local);
    }
    layer.apply(pose, weight, need, local);
}

/// What sampling one layer needs besides its clip: the output joints it
/// must give, scratch, and for a retargeted layer the sampler's copy of
/// its retargeter and the source pose it samples into.
struct Sampling<'a> {
    need: &'a [u64],
    kept: &'a mut Vec<u64>,
    source: &'a mut Pose,
    retargeter: Option<&'a mut Retargeter>,
    /// The layer's foot planter and the clip time it last planted at.
    planter: Option<&'a mut (FootPlanter, Option<f32>)>,
    /// The output skeleton (the character's), which the planter solves on.
    skeleton: &'a Skeleton,
}

impl<C: ClipSource> super::Layer<C> {
    /// Samples the layer's clip at clip time `t` into `pose` (its clip's
    /// joints) for the output joints in `need` and its root-motion joint;
    /// the whole clip when that is every joint it has. A retargeted layer
    /// samples its whole clip and retargets it: `pose` is then in the
    /// character's joints, with the clip's parameters.
    fn sample_needed(&self, t: f32, sampling: Sampling<'_>, cursor: &mut Cursor, pose: &mut Pose) {
        let Sampling { need, kept, source, retargeter, planter, skeleton } = sampling;
        let clip = self.clip.clip();
        if let Some(retargeter) = retargeter {
            clip.sample_into(t, cursor, source);
            pose.parameters.clone_from(&source.parameters);
            retargeter.retarget(source, pose);
            if let Some((planter, last)) = planter {
                // Speed is the source's per second of its clip, whichever way it plays.
                let dt = last.map(|last| (t - last).abs());
                planter.plant(retargeter, dt, skeleton, pose);
                *last = Some(t);
            }
            return;
        }
        if self.reach.whole && *need == *self.reach.reaches {
            clip.sample_into(t, cursor, pose);
            return;
        }
        // The needed joints in the clip's own numbering, so each track's
        // test is one bit.
        kept.clear();
        kept.resize(coverage::words(clip.joint_count()), 0);
        coverage::for_each(need, |j| coverage::insert(kept, self.map[j] as usize));
        if let Some(root) = &self.root {
            coverage::insert(kept, root.joint);
        }
        clip.sample_joints_into(t, cursor, pose, |j| coverage::has(kept, j as usize));
    }
}

impl<C> super::Layer<C> {
    /// Layers this layer's `pose` (in its clip's joints) onto `out` (in the
    /// output skeleton's) at layer weight `weight`, for the output joints in
    /// `need` (all mapped, with a positive mask).
    fn apply(&self, pose: &Pose, weight: f32, need: &[u64], out: &mut Pose) {
        self.apply_parameters(pose, weight, out);
        let source = |j: usize| {
            debug_assert_ne!(self.map[j], UNMAPPED, "a needed joint is mapped");
            self.map[j] as usize
        };
        match &self.reference {
            None => coverage::for_each(need, |j| {
                let mut now = joint(out, j);
                layering::blend(&mut now, &joint(pose, source(j)), weight * self.mask[j]);
                set_joint(out, j, now);
            }),
            Some(reference) => coverage::for_each(need, |j| {
                let mut now = joint(out, j);
                let s = source(j);
                layering::add(&mut now, &joint(pose, s), &joint(reference, s), weight * self.mask[j]);
                set_joint(out, j, now);
            }),
        }
    }
}

impl<C> super::Layer<C> {
    /// Layers the parameters this layer's clip has like translations
    /// (docs/motion.md, “How a pose is computed”): a blend lerps toward the
    /// layer's values by the layer weight (masks are per joint and do not
    /// apply), an additive layer adds `weight · (value − reference)`.
    /// Parameters it lacks stay as they are.
    fn apply_parameters(&self, pose: &Pose, weight: f32, out: &mut Pose) {
        if weight <= 0.0 {
            return;
        }
        for m in &self.parameters {
            let (from, to, n) = (m.from as usize, m.to as usize, m.entries as usize);
            let (layer, out) = (&pose.parameters[from..from + n], &mut out.parameters[to..to + n]);
            match &self.reference {
                None => out.iter_mut().zip(layer).for_each(|(o, l)| *o = layering::lerp(*o, *l, weight)),
                Some(reference) => {
                    let reference = &reference.parameters[from..from + n];
                    for ((o, l), r) in out.iter_mut().zip(layer).zip(reference) {
                        *o = layering::offset(*o, *l - *r, weight);
                    }
                }
            }
        }
    }
}

fn joint(pose: &Pose, j: usize) -> Joint {
    Joint { t: pose.translations[j], q: pose.rotations[j], s: pose.scales[j] }
}

fn set_joint(pose: &mut Pose, j: usize, joint: Joint) {
    (pose.translations[j], pose.rotations[j], pose.scales[j]) = (joint.t, joint.q, joint.s);
}

#[cfg(test)]
mod tests {
    use glam::{Quat, Vec3, Vec4};

    use super::*;
    use crate::motion::{LayerSpec, MaskSpec, MotionSpec, RootMode, RootMotionSpec};
    use crate::{Channel, ClipSpec, Interpolation, JointSpec, Keys, SkeletonSpec, TrackSpec, Transform};

    /// Six joints (two branches), every one turning and moving; `k` makes
    /// the clips differ.
    fn clip(k: f32) -> Clip {
        let joint = |name: &str, parent: Option<&str>| JointSpec {
            name: name.into(),
            parent: parent.map(Into::into),
            rest: Transform { translation: Vec3::new(0.0, 0.1, 0.0), ..Transform::IDENTITY },
            inverse_bind: None,
        };
        let names = ["root", "a", "b", "c", "d", "e"];
        let parents = [None, Some("root"), Some("a"), Some("root"), Some("c"), Some("d")];
        let joints = names.iter().zip(parents).map(|(n, p)| joint(n, p)).collect();
        let times = vec![0.0, 0.4, 1.0];
        let mut tracks = Vec::new();
        for (i, name) in names.iter().enumerate() {
            let a = k + i as f32 * 0.1;
            let turn = |x: f32| Vec4::from(Quat::from_euler(glam::EulerRot::XYZ, x, 0.5 * x, -x));
            let turns = Keys::Vec4(vec![turn(0.0), turn(a), turn(-a)]);
            let moves = Keys::Vec3(vec![Vec3::ZERO, Vec3::splat(a), Vec3::new(a, 0.0, -a)]);
            tracks.push(TrackSpec::new(name, Channel::Rotation, Interpolation::Linear, times.clone(), turns));
            tracks.push(TrackSpec::new(name, Channel::Translation, Interpolation::CatmullRom, times.clone(), moves));
        }
        let skeleton = Some(SkeletonSpec { joints });
        Clip::build(&ClipSpec { name: format!("c{k}"), skeleton, tracks, ..Default::default() }).unwrap()
    }

    #[test]
    fn sampling_some_joints_gives_them_bit_for_bit_as_the_whole_pose_does() {
        let (walk, wave, lean) = (clip(0.3), clip(0.9), clip(-0.5));
        let mask = MaskSpec { joints: vec![("c".into(), 0.5), ("a".into(), 1.0)], descendants: true, default: None };
        let spec = MotionSpec {
            layers: vec![
                LayerSpec { speed: 1.3, ..LayerSpec::new(&walk) },
                LayerSpec { weight: 0.7, mask: Some(mask), offset: 0.2, ..LayerSpec::new(&wave) },
                LayerSpec { weight: 0.4, mode: LayerMode::Additive, ..LayerSpec::new(&lean) },
            ],
            root_motion: Some(RootMotionSpec { mode: RootMode::Extract, ..RootMotionSpec::default() }),
            ..MotionSpec::default()
        };
        let motion = Motion::build(spec).unwrap();
        let options = MotionOptions::default();
        // Joints 1 (a), 2 (b) and 4 (d): neither the root nor every joint.
        let only = [0b10110u64];
        let (mut whole, mut some) = (MotionSampler::new(), MotionSampler::new());
        let mut phases = Vec::new();
        for weights in [[1.0, 0.7, 0.4], [0.6, 1.0, 0.0], [1.0, 0.0, 1.0]] {
            for i in 0..40 {
                let tau = f64::from(i) * 0.07 - 0.5;
                motion.phases_at(tau, &weights, &mut phases);
                motion.sample_with(tau, &phases, &weights, &options, &mut whole);
                motion.sample_joints_with(tau, (&phases, &weights), options.ease, &only, &mut some);
                let (w, s) = (whole.local(), some.local());
                for j in [1, 2, 4] {
                    let bits = |p: &Pose| {
                        let (t, q, s) = (p.translations[j], p.rotations[j], p.scales[j]);
                        [t.to_array(), s.to_array()].concat().into_iter().chain(q.to_array()).map(f32::to_bits)
                    };
                    assert!(bits(w).eq(bits(s)), "joint {j} at {tau}: {:?} vs {:?}", w.rotations[j], s.rotations[j]);
                }
                assert_eq!(whole.root_motion(), some.root_motion(), "the root's travel at {tau}");
            }
        }
    }
}
