//! Composed motion (docs/motion.md): layers of clips, blended or added bottom to
//! top over the rest pose, with masks and sync groups.
//!
//! [`Motion::build`] checks a [`MotionSpec`] once: weights, speeds and
//! offsets; each mask resolved to one weight per joint of the output
//! skeleton (the first layer's clip's); each other layer's joints mapped
//! onto it by name; additive reference poses sampled; sync groups formed.
//! Sampling ([`Motion::sample`], [`Motion::sample_with`]) is then pure
//! arithmetic into a caller-owned [`MotionSampler`], with no allocation
//! once its buffers have their size. A motion of one full-weight layer
//! gives the clip's pose bit for bit.
//!
//! Module map: `spec` the authoring types; `error` why a motion is refused;
//! `mask` masks to per-joint weights; `sync` sync-group phases; `layering`
//! the per-joint blend and additive rules; `coverage` which joints each
//! layer must sample (its mask, and the layers above that hide it);
//! `sampler` the sampling loop;
//! `root` root motion; `player` a stream's live motions, weight ramps and
//! crossfades; `springs` the spring chains run on the composed pose.

mod coverage;
mod error;
mod joint_map;
mod layering;
mod mask;
mod player;
mod retarget;
pub mod root;
mod sampler;
mod spec;
mod springs;
mod sync;
mod warning;

use std::sync::Arc;

pub use error::{MotionError, MotionErrorKind};
pub(crate) use player::mix;
pub use player::{
    DeckState, FadeState, LayerPosition, MAX_FADES, Player, PlayerError, PlayerState, RampState,
    crossfade_drops_oldest, push_crossfade,
};
pub use root::Planar;
pub use sampler::{MotionOptions, MotionSampler, RootMotion};
pub use spec::{
    CharacterSpec, LayerMode, LayerSpec, MaskSpec, MotionSpec, RetargetSpec, RootMode, RootMotionSpec, SourcePose,
    UpAxis,
};
pub use springs::SpringRun;
pub use warning::MotionWarning;

use self::coverage::Reach;
use self::error::MotionErrorKind as K;
pub(crate) use self::joint_map::UNMAPPED;
use self::joint_map::joint_map;
use self::root::motion_transform;
use self::sync::SyncGroup;
use super::character::{FootPlanter, Retargeter};
use super::heap::vec_bytes;
use super::ik::{IkConstraint, IkLimits, build_constraints};
use super::spring::{Springs, SpringsSpec};
use super::{Clip, Cursor, Path, Playback, Pose, Skeleton};

/// Most layers in one motion.
pub const MAX_LAYERS: usize = 32;

/// Largest layer speed, as for streams.
pub const MAX_SPEED: f64 = 1000.0;

/// Anything that holds a built clip: a [`Clip`], or a cache entry.
pub trait ClipSource {
    fn clip(&self) -> &Clip;
}

impl ClipSource for Clip {
    fn clip(&self) -> &Clip {
        self
    }
}

impl<T: ClipSource + ?Sized> ClipSource for Arc<T> {
    fn clip(&self) -> &Clip {
        (**self).clip()
    }
}

impl<T: ClipSource + ?Sized> ClipSource for &T {
    fn clip(&self) -> &Clip {
        (**self).clip()
    }
}

/// A validated, immutable composition, ready to sample.
#[derive(Debug, Clone)]
pub struct Motion<C> {
    layers: Vec<Layer<C>>,
    groups: Vec<SyncGroup>,
    /// Each layer's clip duration, for the sync groups.
    durations: Vec<f64>,
    /// The layer weights the motion was built with.
    weights: Vec<f32>,
    root: Option<RootSetup>,
    /// Request-time IK (docs/ik.md), solved on the layered pose.
    ik: Vec<IkConstraint>,
    /// Layers whose clips have joints the output skeleton lacks.
    warnings: Vec<MotionWarning>,
    /// The output rig when the motion names a character.
    character: Option<Arc<spec::CharacterSpec>>,
    /// Spring chains on the output skeleton (docs/springs.md), if any.
    springs: Option<Springs>,
    /// The layer whose pose the caller hands in instead of a clip sample (a
    /// graph's, docs/graphs.md “What composes with a graph”), if any.
    external: Option<usize>,
}

/// A layer whose pose is handed in at each sample instead of sampled from
/// its clip: at layer `layer`, poses of `skeleton` (mapped onto the output
/// by joint name, as a clip of that skeleton is, never retargeted), and the
/// reference pose an additive such layer is measured from.
pub(crate) struct External<'a> {
    pub layer: usize,
    pub skeleton: &'a Skeleton,
    pub reference: Pose,
}

/// One layer of a motion, read-only: what bounds its poses.
pub(crate) struct LayerView<'a> {
    pub clip: &'a Clip,
    pub mode: LayerMode,
    /// One weight per output joint.
    pub mask: &'a [f32],
    /// Per output joint, the layer clip's joint (or `UNMAPPED`).
    pub map: &'a [u32],
    /// Additive layers' reference pose, in the layer clip's joints (a
    /// retargeted layer's: the character's).
    pub reference: Option<&'a Pose>,
    /// Its pose is handed in (a graph's), not its clip's.
    pub external: bool,
    /// Onto the character, with the layer's foot planter.
    pub retarget: Option<(&'a Retargeter, Option<&'a FootPlanter>)>,
    /// Root motion `extract` on this (blend) layer: its root joint (in the
    /// layer's pose) put back at `M(start)`.
    pub extract: Option<LayerExtract>,
}

/// Where root motion `extract` keeps a blend layer's root (docs/motion.md,
/// “Root motion”): its joint in the layer's pose, its clip's `M(start)`,
/// and the up axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LayerExtract {
    pub joint: usize,
    pub start: Planar,
    pub up: UpAxis,
}

/// Root motion as built: the output skeleton's root-motion joint.
#[derive(Debug, Clone, Copy, PartialEq)]
struct RootSetup {
    joint: usize,
    mode: RootMode,
    up: UpAxis,
}

/// A layer's root-motion joint (in its clip) and its clip's cycle: `M(start)`,
/// the whole cycle and the root's yaw along it.
#[derive(Debug, Clone, PartialEq)]
struct LayerRoot {
    joint: usize,
    cycle: root::Cycle,
}

#[derive(Debug, Clone)]
struct Layer<C> {
    clip: C,
    mode: LayerMode,
    /// One weight per output joint.
    mask: Vec<f32>,
    /// Per output joint, the layer clip's joint index (or `UNMAPPED`).
    map: Vec<u32>,
    /// Whether every mask weight is 1 (a first layer at weight 1 is then
    /// the clip's own pose).
    unmasked: bool,
    /// The joints it reaches and hides (see `coverage`).
    reach: Reach,
    time: LayerTime,
    /// Additive layers: the reference pose, in the layer clip's joints.
    reference: Option<Pose>,
    /// With root motion, when the layer's clip has the root joint.
    root: Option<LayerRoot>,
    /// The output's parameters this layer's clip also has (docs/clip-format.md, “Parameters”).
    parameters: Vec<ParameterMap>,
    /// Onto the character, for a clip of another skeleton: its poses are
    /// then in the output's joints (each sampler works on its own copy).
    retarget: Option<Box<Retargeter>>,
    /// Keeps the retargeted feet planted (`retarget.feet`); each sampler
    /// works on its own copy, frame after frame.
    planter: Option<Box<FootPlanter>>,
}

/// One parameter of a layer: its entries in the layer clip's pose and in the
/// output pose (the same count: widths must agree).
#[derive(Debug, Clone, Copy, PartialEq)]
struct ParameterMap {
    from: u32,
    to: u32,
    entries: u32,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum LayerTime {
    Free { offset: f64, speed: f64, playback: Playback },
    Synced { group: usize },
}

impl<C: ClipSource> Motion<C> {
    /// Checks `spec` and prepares it for sampling.
    ///
    /// # Errors
    /// The first rule of docs/motion.md it breaks, with the path of the field
    /// relative to the motion (`layers/2/mask/joints/spine`).
    pub fn build(spec: MotionSpec<C>) -> Result<Motion<C>, MotionError> {
        Motion::build_limited(spec, &IkLimits::default())
    }

    /// [`Motion::build`] with the service's ceilings on IK constraints,
    /// effectors and iterations.
    ///
    /// # Errors
    /// As [`Motion::build`]; `ik` constraints are checked against the
    /// output skeleton and `ik_limits` (paths `ik/0/joints/1`).
    pub fn build_limited(spec: MotionSpec<C>, ik_limits: &IkLimits) -> Result<Motion<C>, MotionError> {
        Motion::build_external(spec, ik_limits, None)
    }

    /// [`Motion::build_limited`] with one layer's pose handed in at each
    /// sample ([`External`]): that layer's clip only lends its parameters'
    /// layout and its place among the layers.
    pub(crate) fn build_external(
        spec: MotionSpec<C>,
        ik_limits: &IkLimits,
        mut external: Option<External<'_>>,
    ) -> Result<Motion<C>, MotionError> {
        let layers_path = Path::root().field("layers");
        if spec.layers.is_empty() {
            return Err(MotionError::new(layers_path, K::NoLayers));
        }
        if spec.layers.len() > MAX_LAYERS {
            let provided = spec.layers.len();
            return Err(MotionError::new(layers_path, K::TooManyLayers { max: MAX_LAYERS, provided }));
        }
        let mut groups: Vec<SyncGroup> = Vec::new();
        let (mut layers, mut durations, mut weights) = (Vec::new(), Vec::new(), Vec::new());
        let mut warnings = Vec::new();
        let character = spec.character;
        for (i, layer) in spec.layers.into_iter().enumerate() {
            let path = layers_path.clone().index(i);
            weights.push(mask::check_weight(layer.weight, &path.clone().field("weight"))?);
            check_layer_numbers(&layer, &path)?;
            let first_skeleton =
                layers.first().map_or(layer.clip.clip().skeleton(), |l: &Layer<C>| l.clip.clip().skeleton());
            let output = character.as_ref().map_or(first_skeleton, |c| &c.skeleton);
            let time = layer_time(&layer, i, &mut groups);
            durations.push(layer.clip.clip().range().duration());
            let mask = mask::resolve(layer.mask.as_ref(), output, &path.clone().field("mask"))?;
            let outside = external.as_ref().filter(|e| e.layer == i).map(|e| e.skeleton);
            let clip_path = path.clone().field(if outside.is_some() { "graph" } else { "clip" });
            let (retarget, planter) = match &character {
                Some(c) if outside.is_none() && !retarget::same_rig(c, layer.clip.clip()) => {
                    let (options, at) = match &layer.retarget {
                        Some(own) => (own, path.clone().field("retarget")),
                        None => (&spec.retarget, Path::root().field("retarget")),
                    };
                    let (retargeter, planter) = retarget::layer_retargeter(c, layer.clip.clip(), options, &path, &at)?;
                    (Some(Box::new(retargeter)), planter.map(Box::new))
                }
                _ => (None, None),
            };
            let (map, joint_count) = match &retarget {
                Some(_) => ((0..output.len() as u32).collect(), output.len()),
                None => {
                    let own = outside.unwrap_or(layer.clip.clip().skeleton());
                    let map = joint_map(output, own);
                    check_shared_joints(&map, output, own, &clip_path)?;
                    warnings.extend(MotionWarning::for_layer(clip_path, output, own));
                    (map, own.len())
                }
            };
            let first = layers.first().map_or(layer.clip.clip(), |l: &Layer<C>| l.clip.clip());
            let parameters = parameter_map(first.parameters(), layer.clip.clip().parameters(), &path)?;
            let handed = match outside {
                Some(_) => external.as_mut().map(|e| std::mem::take(&mut e.reference)),
                None => None,
            };
            let reference = (layer.mode == LayerMode::Additive).then(|| {
                handed.unwrap_or_else(|| {
                    reference_pose(layer.clip.clip(), layer.reference_time, retarget.as_deref().cloned())
                })
            });
            layers.push(Layer {
                parameters,
                reach: Reach::new(layer.mode, &map, &mask, joint_count),
                unmasked: mask.iter().all(|m| *m >= 1.0),
                mask,
                map,
                time,
                reference,
                mode: layer.mode,
                root: None,
                clip: layer.clip,
                retarget,
                planter,
            });
        }
        let root = match &character {
            Some(c) => character_root_setup(spec.root_motion.as_ref(), c)?,
            None => root_setup(spec.root_motion.as_ref(), layers[0].clip.clip())?,
        };
        let output = character.as_ref().map_or(layers[0].clip.clip().skeleton(), |c| &c.skeleton);
        let (ik, springs) = post_stages(&spec.ik, &spec.springs, output, ik_limits)?;
        if let Some(setup) = root {
            let name = output.names()[setup.joint].clone();
            for layer in &mut layers {
                layer.root = match layer.retarget.as_deref().cloned() {
                    Some(retargeter) => retargeted_root(layer.clip.clip(), retargeter, setup.joint, setup.up),
                    None => layer_root(layer.clip.clip(), &name, setup.up),
                };
            }
        }
        let external = external.map(|e| e.layer);
        Ok(Motion { layers, groups, durations, weights, root, ik, warnings, character, springs, external })
    }

    /// Layers whose clips have joints the output skeleton lacks, bottom to
    /// top (what an answer shows as warnings).
    pub fn warnings(&self) -> &[MotionWarning] {
        &self.warnings
    }

    /// The output skeleton: the character's, else the first layer's clip's.
    pub fn skeleton(&self) -> &Skeleton {
        self.character.as_ref().map_or(self.layers[0].clip.clip().skeleton(), |c| &c.skeleton)
    }

    /// How many feet the layers plant (`retarget.feet`): each a two-bone
    /// solve per pose.
    pub fn planted_feet(&self) -> usize {
        self.layers.iter().filter_map(|l| l.planter.as_deref()).map(FootPlanter::feet).sum()
    }

    /// Whether layer `i` is retargeted onto the character.
    pub fn is_retargeted(&self, i: usize) -> bool {
        self.layers[i].retarget.is_some()
    }

    /// The output's parameters (docs/clip-format.md, “Parameters”): the first layer's clip's.
    pub fn parameters(&self) -> &crate::ParameterLayout {
        self.layers[0].clip.clip().parameters()
    }

    /// The first layer's clip (whose id a pose names).
    pub fn first_clip(&self) -> &C {
        &self.layers[0].clip
    }

    /// Each layer's clip, bottom to top.
    pub fn layers(&self) -> impl Iterator<Item = &C> {
        self.layers.iter().map(|l| &l.clip)
    }

    /// Each layer as compact frames' bounds read it (docs/compact-frames.md), bottom to top.
    pub(crate) fn layer_views(&self) -> impl Iterator<Item = LayerView<'_>> {
        self.layers.iter().enumerate().map(|(i, l)| LayerView {
            external: self.external == Some(i),
            clip: l.clip.clip(),
            mode: l.mode,
            mask: &l.mask,
            map: &l.map,
            reference: l.reference.as_ref(),
            retarget: l.retarget.as_deref().map(|r| (r, l.planter.as_deref())),
            extract: self.layer_extract(l),
        })
    }

    /// Where `extract` keeps layer `l`'s root, if it does (a blend layer
    /// that has the root joint, under root motion `extract`).
    fn layer_extract(&self, l: &Layer<C>) -> Option<LayerExtract> {
        let setup = self.root.filter(|r| r.mode == RootMode::Extract && l.mode == LayerMode::Blend)?;
        let root = l.root.as_ref()?;
        Some(LayerExtract { joint: root.joint, start: root.cycle.start, up: setup.up })
    }

    /// The request-time IK constraints, solved after layering.
    pub fn ik(&self) -> &[IkConstraint] {
        &self.ik
    }

    /// The spring chains simulated on the composed pose, if any.
    pub fn springs(&self) -> Option<&Springs> {
        self.springs.as_ref()
    }

    /// Bytes this motion holds on the heap beyond its layers' clips (which
    /// it shares): per layer the mask, joint map, coverage bits and an
    /// additive layer's reference pose; the sync groups and IK constraints.
    pub fn heap_bytes(&self) -> usize {
        let layer = |l: &Layer<C>| {
            vec_bytes(&l.mask)
                + vec_bytes(&l.map)
                + std::mem::size_of_val(&*l.reach.reaches)
                + std::mem::size_of_val(&*l.reach.hides)
                + l.reference.as_ref().map_or(0, Pose::heap_bytes)
                + vec_bytes(&l.parameters)
                + l.retarget.as_deref().map_or(0, retargeter_bytes)
                + l.planter.as_deref().map_or(0, FootPlanter::heap_bytes)
        };
        let group = |g: &SyncGroup| g.name.capacity() + vec_bytes(&g.members);
        vec_bytes(&self.layers)
            + self.layers.iter().map(layer).sum::<usize>()
            + vec_bytes(&self.groups)
            + self.groups.iter().map(group).sum::<usize>()
            + vec_bytes(&self.durations)
            + vec_bytes(&self.weights)
            + vec_bytes(&self.ik)
            + self.ik.iter().map(IkConstraint::heap_bytes).sum::<usize>()
            + vec_bytes(&self.warnings)
            + self.warnings.iter().map(MotionWarning::heap_bytes).sum::<usize>()
            + self.springs.as_ref().map_or(0, Springs::heap_bytes)
    }

    /// IK reports each sample gives: every layer's clip constraints, bottom
    /// to top (a handed-in layer has none), then the motion's own.
    pub fn ik_report_count(&self) -> usize {
        let keyed = |(i, l): (usize, &Layer<C>)| if self.external == Some(i) { 0 } else { l.clip.clip().ik_count() };
        self.layers.iter().enumerate().map(keyed).sum::<usize>() + self.ik.len()
    }

    /// The up axis of the motion's root motion, if it has one.
    pub fn root_up(&self) -> Option<UpAxis> {
        self.root.map(|r| r.up)
    }

    /// Whether samples report root motion.
    pub fn has_root_motion(&self) -> bool {
        self.root.is_some()
    }

    /// Layers, bottom to top.
    pub fn layer_count(&self) -> usize {
        self.layers.len()
    }

    /// The layer weights the motion was built with.
    pub fn weights(&self) -> &[f32] {
        &self.weights
    }

    /// Distinct sync groups among the layers.
    pub fn sync_group_count(&self) -> usize {
        self.groups.len()
    }

    /// Each sync group's phase at motion time `tau` under constant
    /// `weights` (a stateless request), into `phases`.
    ///
    /// # Panics
    /// If `weights` has fewer entries than the motion has layers.
    pub fn phases_at(&self, tau: f64, weights: &[f32], phases: &mut Vec<f64>) {
        phases.clear();
        phases.extend(self.groups.iter().map(|g| g.phase_at(tau, &self.durations, weights)));
    }

    /// Advances each sync group's phase by `dtau` of motion time at the
    /// rate the current `weights` give: when weights change mid-stream the
    /// phase carries on from where it is.
    ///
    /// # Panics
    /// If `weights` has fewer entries than the motion has layers.
    pub fn advance_phases(&self, phases: &mut [f64], dtau: f64, weights: &[f32]) {
        for (phase, group) in phases.iter_mut().zip(&self.groups) {
            *phase += group.rate(&self.durations, weights) * dtau;
        }
    }
}

/// The stages that run on a layered pose (docs/motion.md): the IK
/// constraints and the spring chains, checked against the output skeleton
/// (paths `ik/0/joints/1`, `springs/0/joints/2`). A motion's and a graph's
/// alike (docs/graphs.md, “What composes with a graph”).
///
/// # Errors
/// The first rule of docs/ik.md or docs/springs.md broken.
pub(crate) fn post_stages(
    ik: &[crate::ik::IkSpec],
    springs: &SpringsSpec,
    output: &Skeleton,
    ik_limits: &IkLimits,
) -> Result<(Vec<IkConstraint>, Option<Springs>), MotionError> {
    let ik = build_constraints(ik, output, ik_limits).map_err(|e| {
        let e = e.under(Path::root().field("ik"));
        MotionError::new(e.path, K::Ik(e.kind))
    })?;
    Ok((ik, build_springs(springs, output)?))
}

/// The chains of `spec` on the output skeleton; `None` without chains.
fn build_springs(spec: &SpringsSpec, output: &Skeleton) -> Result<Option<Springs>, MotionError> {
    if spec.chains.is_empty() {
        spec.check().map_err(|e| MotionError::new(e.path, K::Spring(e.kind)))?;
        return Ok(None);
    }
    Springs::build(spec, output).map(Some).map_err(|e| MotionError::new(e.path, K::Spring(e.kind)))
}

fn check_layer_numbers<C>(layer: &LayerSpec<C>, path: &Path) -> Result<(), MotionError> {
    for (value, field) in
        [(layer.offset, "offset"), (layer.speed, "speed"), (layer.reference_time.unwrap_or(0.0), "reference_time")]
    {
        if !value.is_finite() {
            return Err(MotionError::new(path.clone().field(field), K::NonFinite));
        }
    }
    if layer.speed.abs() > MAX_SPEED {
        let kind = K::SpeedOutOfRange { speed: layer.speed, max: MAX_SPEED };
        return Err(MotionError::new(path.clone().field("speed"), kind));
    }
    Ok(())
}

/// Bytes a retargeter holds: per target joint its source, offset,
/// reference transform, source translation and model transform; per source
/// joint its parent and model transform.
fn retargeter_bytes(r: &Retargeter) -> usize {
    let record = size_of::<Retargeter>();
    let transform = 3 * size_of::<glam::Vec3A>();
    let target = r.target_len() * (2 * size_of::<u32>() + size_of::<glam::Quat>() + 3 * transform);
    record + target + r.source_model().translations.len() * (size_of::<u32>() + transform)
}

/// Refuses a layer that maps no joint of the output skeleton although its
/// clip has joints: another rig, of which nothing would play.
fn check_shared_joints(map: &[u32], output: &Skeleton, layer: &Skeleton, path: &Path) -> Result<(), MotionError> {
    if layer.is_empty() || map.iter().any(|&j| j != UNMAPPED) {
        return Ok(());
    }
    let first = |s: &Skeleton| s.names().iter().take(error::NAMES_SHOWN + 1).cloned().collect();
    let kind = K::IncompatibleSkeleton { layer: first(layer), output: first(output) };
    Err(MotionError::new(path.clone(), kind))
}

/// How layer `index` finds its clip time; a synced layer joins (or
/// founds) its group, whose first layer sets the phase and its rate.
fn layer_time<C: ClipSource>(layer: &LayerSpec<C>, index: usize, groups: &mut Vec<SyncGroup>) -> LayerTime {
    let Some(name) = &layer.sync else {
        let playback = layer.playback.unwrap_or_else(|| layer.clip.clip().playback());
        return LayerTime::Free { offset: layer.offset, speed: layer.speed, playback };
    };
    if let Some(group) = groups.iter().position(|g| &g.name == name) {
        groups[group].members.push(index);
        return LayerTime::Synced { group };
    }
    let range = layer.clip.clip().range();
    let duration = range.duration();
    let phase0 = if duration > 0.0 { (layer.offset - f64::from(range.start())) / duration } else { 0.0 };
    groups.push(SyncGroup { name: name.clone(), members: vec![index], phase0, speed: layer.speed });
    LayerTime::Synced { group: groups.len() - 1 }
}

/// The root-motion joint of the output skeleton: the named one, or the
/// first root joint with a translation track.
fn root_setup(spec: Option<&RootMotionSpec>, first: &Clip) -> Result<Option<RootSetup>, MotionError> {
    let Some(spec) = spec else { return Ok(None) };
    let skeleton = first.skeleton();
    let joint = match &spec.joint {
        Some(name) => skeleton.index_of(name).ok_or_else(|| {
            MotionError::new(Path::root().field("root_motion").field("joint"), K::UnknownJoint { joint: name.clone() })
        })?,
        None => (0..skeleton.len())
            .find(|&j| skeleton.parent(j).is_none() && first.has_translation_track(j))
            .ok_or_else(|| MotionError::new(Path::root().field("root_motion"), no_root_joint(first)))?,
    };
    Ok(Some(RootSetup { joint, mode: spec.mode, up: spec.up }))
}

/// Why no root-motion joint was found, with the candidates: the root
/// joints (which lack translation tracks) and the joints that have one.
fn no_root_joint(clip: &Clip) -> K {
    let skeleton = clip.skeleton();
    let names = |keep: &dyn Fn(usize) -> bool| -> Vec<String> {
        let joints = (0..skeleton.len()).filter(|&j| keep(j)).take(error::NAMES_SHOWN + 1);
        joints.map(|j| skeleton.names()[j].clone()).collect()
    };
    let roots = names(&|j| skeleton.parent(j).is_none());
    let translated = names(&|j| clip.has_translation_track(j));
    K::NoRootJoint { roots, translated }
}

/// The most samples of a root's yaw along its clip: a root rotation with more
/// keys is sampled at this many evenly spaced times instead, which bounds
/// what a motion build costs.
const MAX_YAW_SAMPLES: usize = 4096;

/// `clip`'s joint `name` with its cycle, if it has one.
fn layer_root(clip: &Clip, name: &str, up: UpAxis) -> Option<LayerRoot> {
    let joint = clip.skeleton().index_of(name)?;
    let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
    let at = |t: f32| {
        clip.sample_joints_into(t, &mut cursor, &mut pose, |j| j as usize == joint);
        motion_transform(up, pose.translations[joint], pose.rotations[joint])
    };
    Some(LayerRoot { joint, cycle: cycle_of(clip, &yaw_times(clip, joint), at, up) })
}

/// A retargeted layer's root: the character's joint `joint` in the poses
/// the retarget makes, its yaw summed at the times of the source's root.
fn retargeted_root(clip: &Clip, mut retargeter: Retargeter, joint: usize, up: UpAxis) -> Option<LayerRoot> {
    let source_root = (0..clip.joint_count()).find(|&j| clip.skeleton().parent(j).is_none()).unwrap_or(0);
    let (mut cursor, mut source, mut target) = (Cursor::default(), Pose::default(), Pose::default());
    let at = |t: f32| {
        clip.sample_into(t, &mut cursor, &mut source);
        retargeter.retarget(&source, &mut target);
        motion_transform(up, target.translations[joint], target.rotations[joint])
    };
    Some(LayerRoot { joint, cycle: cycle_of(clip, &yaw_times(clip, source_root), at, up) })
}

/// The cycle of a root whose motion transform at clip time `t` is `at(t)`,
/// its yaw summed at `times`.
fn cycle_of(clip: &Clip, times: &[f32], mut at: impl FnMut(f32) -> root::Planar, up: UpAxis) -> root::Cycle {
    let (start, end) = (at(clip.start()), at(clip.end()));
    let along: Vec<(f32, f64)> = times.iter().map(|&t| (t, at(t).yaw)).collect();
    let yaw = root::Unwrapped::new((clip.start(), start.yaw), along);
    root::Cycle::new(start, end, yaw, up)
}

/// The root-motion joint of a character: the named one, else its hips.
fn character_root_setup(
    spec: Option<&RootMotionSpec>,
    character: &spec::CharacterSpec,
) -> Result<Option<RootSetup>, MotionError> {
    let Some(spec) = spec else { return Ok(None) };
    let skeleton = &character.skeleton;
    let joint = match &spec.joint {
        Some(name) => skeleton.index_of(name).ok_or_else(|| {
            MotionError::new(Path::root().field("root_motion").field("joint"), K::UnknownJoint { joint: name.clone() })
        })?,
        None => character.roles.joint(crate::character::Role::Hips).ok_or_else(|| {
            let roots = (0..skeleton.len()).filter(|&j| skeleton.parent(j).is_none());
            let roots = roots.take(error::NAMES_SHOWN + 1).map(|j| skeleton.names()[j].clone()).collect();
            MotionError::new(Path::root().field("root_motion"), K::NoRootJoint { roots, translated: Vec::new() })
        })?,
    };
    Ok(Some(RootSetup { joint, mode: spec.mode, up: spec.up }))
}

/// The clip times after the start at which the root's yaw is summed
/// (docs/motion.md, “Root motion”): its rotation's keys inside the clip's
/// range and the midpoints between them, the last at the end; evenly spaced
/// past [`MAX_YAW_SAMPLES`].
fn yaw_times(clip: &Clip, joint: usize) -> Vec<f32> {
    let (start, end) = (clip.start(), clip.end());
    let inside = clip.rotation_key_times(joint).filter(|t| *t > start && *t < end);
    let keys: Vec<f32> = std::iter::once(start).chain(inside).chain(std::iter::once(end)).collect();
    if 2 * keys.len() > MAX_YAW_SAMPLES {
        let n = MAX_YAW_SAMPLES as f64;
        let at = |i: usize| (f64::from(start) + (f64::from(end) - f64::from(start)) * i as f64 / n) as f32;
        return (1..=MAX_YAW_SAMPLES).map(at).collect();
    }
    keys.windows(2).flat_map(|w| [w[0] + 0.5 * (w[1] - w[0]), w[1]]).collect()
}

/// Per output parameter the layer's clip also has (by name), where each
/// sits in either pose.
///
/// # Errors
/// `parameter_width_mismatch` when the layer's parameter of that name has
/// another width.
fn parameter_map(
    output: &crate::ParameterLayout,
    layer: &crate::ParameterLayout,
    path: &Path,
) -> Result<Vec<ParameterMap>, MotionError> {
    let mut maps = Vec::new();
    for (p, name) in output.names().iter().enumerate() {
        let Some(q) = layer.index_of(name) else { continue };
        let (expected, provided) = (output.widths()[p], layer.widths()[q]);
        if expected != provided {
            let kind = K::ParameterWidthMismatch { name: name.clone(), expected, provided };
            return Err(MotionError::new(path.clone().field("clip"), kind));
        }
        let (to, from) = (output.range(p), layer.range(q));
        maps.push(ParameterMap { from: from.start as u32, to: to.start as u32, entries: to.len() as u32 });
    }
    Ok(maps)
}

/// `clip`'s local pose at `time` (default its start), clamped to its range
/// with no playback mapping.
fn reference_pose(clip: &Clip, time: Option<f64>, retarget: Option<Retargeter>) -> Pose {
    let range = clip.range();
    let t = time.map_or(range.start(), |t| (t as f32).clamp(range.start(), range.end()));
    let mut pose = Pose::default();
    clip.sample_into(t, &mut Cursor::default(), &mut pose);
    match retarget {
        Some(mut retargeter) => {
            let mut target = pose.clone();
            retargeter.retarget(&pose, &mut target);
            target
        }
        None => pose,
    }
}
