//! The authoring form of a motion (docs/motion.md): what a request or a stream
//! control says, unchecked. [`Motion::build`](super::Motion::build) checks it.

use std::sync::Arc;

use glam::Quat;

use crate::character::{FeetOptions, RoleMap, Translation};
use crate::ik::IkSpec;
use crate::spring::SpringsSpec;
use crate::{Playback, Pose, Skeleton};

/// Layers bottom to top, what to do with the root's motion, and the IK
/// constraints solved on the layered pose.
#[derive(Debug, Clone)]
pub struct MotionSpec<C> {
    pub layers: Vec<LayerSpec<C>>,
    pub root_motion: Option<RootMotionSpec>,
    /// Request-time constraints (docs/ik.md), after layering and root motion.
    pub ik: Vec<IkSpec>,
    /// The output rig, instead of the first layer's clip's: every layer of
    /// another skeleton is retargeted onto it.
    pub character: Option<Arc<CharacterSpec>>,
    /// How layers are retargeted onto the character, unless a layer says.
    pub retarget: RetargetSpec,
    /// Spring chains (docs/springs.md) on the output skeleton, simulated
    /// on the composed pose; none by default.
    pub springs: SpringsSpec,
}

impl<C> Default for MotionSpec<C> {
    fn default() -> Self {
        MotionSpec {
            layers: Vec::new(),
            root_motion: None,
            ik: Vec::new(),
            character: None,
            retarget: RetargetSpec::default(),
            springs: SpringsSpec::default(),
        }
    }
}

/// A motion's output rig: a skeleton with its roles and reference pose,
/// resolved by the caller (a stored character).
#[derive(Debug, Clone, PartialEq)]
pub struct CharacterSpec {
    pub skeleton: Skeleton,
    pub roles: RoleMap,
    /// Its reference pose for retargeting (local); `None`: its rest pose.
    pub reference: Option<Pose>,
}

/// How a layer's clip is retargeted onto the character.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RetargetSpec {
    pub source_pose: SourcePose,
    pub translation: Translation,
    /// The character's reference pose: its reference (the rest) with these
    /// joints' local rotations replaced; empty: as it is.
    pub target_pose: Vec<(String, Quat)>,
    /// Plant the feet while the source's are in contact (`None`: don't).
    pub feet: Option<FeetOptions>,
}

/// The source side's reference pose.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum SourcePose {
    /// The clip's rest pose; a root at the origin with a translation track
    /// (a BVH's) at its first frame's position.
    #[default]
    Rest,
    /// The clip's pose at this clip time (clamped to its range).
    Time(f64),
    /// The rest pose with these joints' local rotations replaced.
    Rotations(Vec<(String, Quat)>),
}

impl<C> MotionSpec<C> {
    /// The same motion with each layer's clip replaced by `f(layer index,
    /// clip)`: how the edge swaps clip ids for the clips it looked up.
    ///
    /// # Errors
    /// The first error `f` returns.
    pub fn try_map<D, E>(self, mut f: impl FnMut(usize, C) -> Result<D, E>) -> Result<MotionSpec<D>, E> {
        let layers = self
            .layers
            .into_iter()
            .enumerate()
            .map(|(i, l)| {
                Ok(LayerSpec {
                    clip: f(i, l.clip)?,
                    weight: l.weight,
                    mode: l.mode,
                    mask: l.mask,
                    offset: l.offset,
                    speed: l.speed,
                    playback: l.playback,
                    sync: l.sync,
                    reference_time: l.reference_time,
                    retarget: l.retarget,
                })
            })
            .collect::<Result<_, E>>()?;
        let (root_motion, ik, character, retarget) = (self.root_motion, self.ik, self.character, self.retarget);
        Ok(MotionSpec { layers, root_motion, ik, character, retarget, springs: self.springs })
    }
}

/// One layer: a clip (already looked up, at the version it is pinned to)
/// and how it contributes.
#[derive(Debug, Clone)]
pub struct LayerSpec<C> {
    pub clip: C,
    /// In `[0, 1]`.
    pub weight: f32,
    pub mode: LayerMode,
    pub mask: Option<MaskSpec>,
    /// Clip time at motion time 0.
    pub offset: f64,
    pub speed: f64,
    /// `None`: the clip's own.
    pub playback: Option<Playback>,
    /// The sync group's name.
    pub sync: Option<String>,
    /// Additive layers: the clip time of the reference pose (`None`: the
    /// clip's start).
    pub reference_time: Option<f64>,
    /// This layer's retargeting, instead of the motion's.
    pub retarget: Option<RetargetSpec>,
}

impl<C> LayerSpec<C> {
    /// A full-weight blend layer of `clip` with every default.
    pub fn new(clip: C) -> Self {
        LayerSpec {
            clip,
            weight: 1.0,
            mode: LayerMode::Blend,
            mask: None,
            offset: 0.0,
            speed: 1.0,
            playback: None,
            sync: None,
            reference_time: None,
            retarget: None,
        }
    }
}

/// How a layer moves the pose beneath it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LayerMode {
    /// Toward the layer's pose by its weight.
    #[default]
    Blend,
    /// By the layer's difference from its reference pose, times its weight.
    Additive,
}

impl LayerMode {
    /// The mode's name in requests (`blend`, `additive`).
    pub fn as_str(self) -> &'static str {
        match self {
            LayerMode::Blend => "blend",
            LayerMode::Additive => "additive",
        }
    }
}

/// Per-joint weights by name, resolved on the output skeleton.
#[derive(Debug, Clone, Default)]
pub struct MaskSpec {
    /// Named joints and their weights, in `[0, 1]`.
    pub joints: Vec<(String, f32)>,
    /// Whether a named joint's weight extends to its descendants (the
    /// nearest named ancestor wins).
    pub descendants: bool,
    /// The weight of joints not covered: `None` is 0 when `joints` names
    /// any, else 1.
    pub default: Option<f32>,
}

/// `root_motion`: which joint carries the character's motion and whether
/// to take it out of the pose.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct RootMotionSpec {
    /// `None`: the first root joint with a translation track.
    pub joint: Option<String>,
    pub mode: RootMode,
    pub up: UpAxis,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RootMode {
    /// Report the deltas and totals only.
    #[default]
    Report,
    /// Report them and keep the character in place.
    Extract,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UpAxis {
    #[default]
    Y,
    Z,
}
