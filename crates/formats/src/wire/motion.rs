//! The JSON motion (docs/motion.md): layers of clips by id, masks, sync groups and
//! root motion, parsed strictly (unknown fields refused) into the core's
//! [`MotionSpec`] with the clip ids still to be looked up.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::doc::{DocError, PlaybackDoc};
use super::ik::IkDoc;
use super::spring::{SpringDoc, springs_spec};
use anim::character::Translation;
use anim::motion::{
    LayerMode, LayerSpec, MaskSpec, MotionSpec, RetargetSpec, RootMode, RootMotionSpec, SourcePose, UpAxis,
};
use anim::spring::{DEFAULT_SUBSTEP_HZ, SpringsSpec};

/// A composed motion: layers of clips with weights, masks, sync groups,
/// root motion and IK, as `docs/motion.md` describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MotionDoc {
    /// Bottom to top; the first layer's clip gives the output skeleton.
    pub layers: Vec<LayerDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub root_motion: Option<RootMotionDoc>,
    /// IK constraints solved on the layered pose (`docs/ik.md`), targets in
    /// model space.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ik: Vec<IkDoc>,
    /// Spring chains simulated on the composed pose (`docs/springs.md`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub springs: Vec<SpringDoc>,
    /// Substeps per second of the springs' simulation (default 120).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spring_substep_hz: Option<f64>,
    /// The output rig (a character id or `name:…`): every layer of another
    /// skeleton is retargeted onto it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub character: Option<String>,
    /// How layers are retargeted onto the character.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub retarget: Option<RetargetDoc>,
}

/// How a layer's clip plays on the motion's character (docs/motion.md, “Characters”).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RetargetDoc {
    /// The clip's reference pose: its rest pose by default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source_pose: Option<SourcePoseDoc>,
    #[serde(default)]
    pub translation: TranslationDoc,
    /// The character's reference pose: its rest by default;
    /// `{"rotations": {joint: [x, y, z, w]}}` replaces joints' local rotations
    /// (a character has no clip time, so `{"time": t}` is refused).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_pose: Option<SourcePoseDoc>,
    /// `plant`: each foot stays where it landed while the source's foot is
    /// in contact (docs/characters.md, “Planted feet”).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub feet: Option<FeetDoc>,
    /// With `feet: "plant"`: a source foot within this height above its lowest
    /// (times the hips ratio) is in contact; default 0.02 (the character's units).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_height: Option<f32>,
    /// With `feet: "plant"`: …and slower than this per second; default 0.1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_speed: Option<f32>,
}

/// What happens to a retargeted foot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum FeetDoc {
    /// Planted while in contact.
    Plant,
}

/// `{"time": t}` (the clip at `t`) or `{"rotations": {joint: [x, y, z, w]}}`
/// (local rotations replacing the rest's).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum SourcePoseDoc {
    Time(f64),
    Rotations(BTreeMap<String, [f32; 4]>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum TranslationDoc {
    #[default]
    Hips,
    None,
    All,
}

impl RetargetDoc {
    /// The core's form; `pointer` is the document's (`/motion/retarget`).
    ///
    /// # Errors
    /// `zero_quaternion` for a rotation that cannot be normalised (as a
    /// clip's keys, docs/clip-format.md); `target_pose_needs_rotations` for
    /// a `target_pose` given as a time.
    pub fn to_spec(&self, pointer: &str) -> Result<RetargetSpec, DocError> {
        let source_pose = match &self.source_pose {
            None => SourcePose::Rest,
            Some(SourcePoseDoc::Time(t)) => SourcePose::Time(*t),
            Some(SourcePoseDoc::Rotations(r)) => {
                SourcePose::Rotations(rotations(r, &format!("{pointer}/source_pose/rotations"))?)
            }
        };
        let translation = match self.translation {
            TranslationDoc::Hips => Translation::Hips,
            TranslationDoc::None => Translation::None,
            TranslationDoc::All => Translation::All,
        };
        let target_pose = match &self.target_pose {
            None => Vec::new(),
            Some(SourcePoseDoc::Rotations(r)) => rotations(r, &format!("{pointer}/target_pose/rotations"))?,
            Some(SourcePoseDoc::Time(_)) => {
                let detail =
                    "a character has no clip time: give its reference pose as `{\"rotations\": {joint: [x, y, z, w]}}`";
                let pointer = format!("{pointer}/target_pose");
                return Err(DocError { code: "target_pose_needs_rotations", pointer, detail: detail.into() });
            }
        };
        let feet = self.feet(pointer)?;
        Ok(RetargetSpec { source_pose, translation, target_pose, feet })
    }

    /// The feet options: `None` unless `feet` is `plant`.
    ///
    /// # Errors
    /// `contact_out_of_range` for a threshold that is negative or not
    /// finite; `feet_not_planted` for a threshold without `feet: "plant"`.
    fn feet(&self, pointer: &str) -> Result<Option<anim::character::FeetOptions>, DocError> {
        let mut options = anim::character::FeetOptions::default();
        for (name, value, field) in [
            ("contact_height", self.contact_height, &mut options.contact_height),
            ("contact_speed", self.contact_speed, &mut options.contact_speed),
        ] {
            let Some(value) = value else { continue };
            let pointer = format!("{pointer}/{name}");
            if self.feet.is_none() {
                let detail = format!("`{name}` applies with `feet: \"plant\"`");
                return Err(DocError { code: "feet_not_planted", pointer, detail });
            }
            if !value.is_finite() || value < 0.0 {
                let detail = format!("`{name}` must be a finite number at least 0, got {value}");
                return Err(DocError { code: "contact_out_of_range", pointer, detail });
            }
            *field = value;
        }
        Ok(self.feet.map(|FeetDoc::Plant| options))
    }

    fn from_spec(spec: &RetargetSpec) -> RetargetDoc {
        let source_pose = match &spec.source_pose {
            SourcePose::Rest => None,
            SourcePose::Time(t) => Some(SourcePoseDoc::Time(*t)),
            SourcePose::Rotations(r) => {
                Some(SourcePoseDoc::Rotations(r.iter().map(|(n, q)| (n.clone(), q.to_array())).collect()))
            }
        };
        let translation = match spec.translation {
            Translation::Hips => TranslationDoc::Hips,
            Translation::None => TranslationDoc::None,
            Translation::All => TranslationDoc::All,
        };
        let target_pose = (!spec.target_pose.is_empty()).then(|| {
            SourcePoseDoc::Rotations(spec.target_pose.iter().map(|(n, q)| (n.clone(), q.to_array())).collect())
        });
        RetargetDoc {
            source_pose,
            translation,
            target_pose,
            feet: spec.feet.map(|_| FeetDoc::Plant),
            contact_height: spec.feet.map(|f| f.contact_height),
            contact_speed: spec.feet.map(|f| f.contact_speed),
        }
    }
}

/// A pose's named local rotations, each normalised in f64 as a skeleton's
/// rest rotations are (so a pose given as a rest's own rotations is that
/// rest exactly); one that cannot be (its norm below 1e-6, as a clip's key)
/// is `zero_quaternion` at `{pointer}/{joint}`.
fn rotations(named: &BTreeMap<String, [f32; 4]>, pointer: &str) -> Result<Vec<(String, glam::Quat)>, DocError> {
    named
        .iter()
        .map(|(name, q)| {
            let v = glam::DVec4::from_array(q.map(f64::from));
            let norm = v.length();
            if !norm.is_finite() || norm < 1e-6 {
                let detail = format!("quaternion has norm {norm:e}, below 1e-6");
                let pointer = format!("{pointer}/{}", name.replace('~', "~0").replace('/', "~1"));
                return Err(DocError { code: "zero_quaternion", pointer, detail });
            }
            Ok((name.clone(), glam::Quat::from_vec4((v / norm).as_vec4())))
        })
        .collect()
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LayerDoc {
    /// A clip id; the version is pinned when the request or stream starts.
    /// Required unless the layer names a `graph`.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub clip: String,
    /// A stored graph's id (or `name:<name>`) instead of a clip (docs/graphs.md, “What composes with a graph”):
    /// one layer of a motion, taking `weight`, `mask` and `mode` and no clip time fields.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub graph: Option<String>,
    /// In [0, 1].
    #[serde(default = "one")]
    pub weight: f32,
    #[serde(default)]
    pub mode: LayerModeDoc,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<MaskDoc>,
    /// Clip time at motion time 0.
    #[serde(default)]
    pub offset: f64,
    #[serde(default = "one_f64")]
    pub speed: f64,
    /// Default: the clip's own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub playback: Option<PlaybackDoc>,
    /// A sync group's name: its layers share one normalised phase.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sync: Option<String>,
    /// Additive layers: the clip time of the reference pose (default the clip's start).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_time: Option<f64>,
    /// This layer's retargeting onto the motion's character, instead of the motion's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub retarget: Option<RetargetDoc>,
}

impl LayerDoc {
    /// A full-weight blend layer of `clip` with every default (what a
    /// document that names only `clip` parses to).
    pub fn new(clip: &str) -> Self {
        LayerDoc {
            clip: clip.to_owned(),
            graph: None,
            weight: one(),
            mode: LayerModeDoc::Blend,
            mask: None,
            offset: 0.0,
            speed: one_f64(),
            playback: None,
            sync: None,
            reference_time: None,
            retarget: None,
        }
    }
}

fn one() -> f32 {
    1.0
}

fn one_f64() -> f64 {
    1.0
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum LayerModeDoc {
    #[default]
    Blend,
    Additive,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MaskDoc {
    /// Joint names and their weights in [0, 1].
    #[serde(default)]
    pub joints: BTreeMap<String, f32>,
    /// A named joint's weight extends to its descendants (the nearest named ancestor wins).
    #[serde(default)]
    pub descendants: bool,
    /// Joints not covered: default 0 when `joints` names any, else 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub default: Option<f32>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RootMotionDoc {
    /// Default: the first root joint with a translation track.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint: Option<String>,
    #[serde(default)]
    pub mode: RootModeDoc,
    #[serde(default)]
    pub up: UpAxisDoc,
}

impl RootMotionDoc {
    /// The core's form.
    pub fn to_spec(&self) -> RootMotionSpec {
        RootMotionSpec {
            joint: self.joint.clone(),
            mode: match self.mode {
                RootModeDoc::Report => RootMode::Report,
                RootModeDoc::Extract => RootMode::Extract,
            },
            up: match self.up {
                UpAxisDoc::Y => UpAxis::Y,
                UpAxisDoc::Z => UpAxis::Z,
            },
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum RootModeDoc {
    #[default]
    Report,
    Extract,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum UpAxisDoc {
    #[default]
    Y,
    Z,
}

impl MotionDoc {
    /// The core's authoring form, with clip ids in place of clips (and no
    /// character: the service looks `character` up and puts it in);
    /// `pointer` is the motion's place in its message (`/motion`).
    ///
    /// # Errors
    /// An `ik` constraint of the wrong shape (see [`IkDoc::to_spec`]); a
    /// spring chain breaking a rule that needs no skeleton.
    pub fn to_spec(&self, pointer: &str) -> Result<MotionSpec<String>, DocError> {
        let ik = (self.ik.iter().enumerate())
            .map(|(i, c)| c.to_spec(&format!("{pointer}/ik/{i}")))
            .collect::<Result<_, _>>()?;
        Ok(MotionSpec {
            layers: (self.layers.iter().enumerate())
                .map(|(i, layer)| layer.to_spec(&format!("{pointer}/layers/{i}")))
                .collect::<Result<_, _>>()?,
            root_motion: self.root_motion.as_ref().map(RootMotionDoc::to_spec),
            ik,
            character: None,
            retarget: match &self.retarget {
                Some(r) => r.to_spec(&format!("{pointer}/retarget"))?,
                None => RetargetSpec::default(),
            },
            springs: self.springs(pointer)?,
        })
    }
}

impl MotionDoc {
    /// The document that says `spec` again (`to_spec` of it gives `spec`
    /// back): how a motion that came another way (gRPC) is written down as
    /// JSON, e.g. a broadcast's crossfade kept in the store.
    pub fn from_spec(spec: &MotionSpec<String>) -> MotionDoc {
        MotionDoc {
            layers: spec.layers.iter().map(LayerDoc::from_spec).collect(),
            root_motion: spec.root_motion.as_ref().map(|r| RootMotionDoc {
                joint: r.joint.clone(),
                mode: match r.mode {
                    RootMode::Report => RootModeDoc::Report,
                    RootMode::Extract => RootModeDoc::Extract,
                },
                up: match r.up {
                    UpAxis::Y => UpAxisDoc::Y,
                    UpAxis::Z => UpAxisDoc::Z,
                },
            }),
            ik: spec.ik.iter().map(IkDoc::from_spec).collect(),
            springs: spec.springs.chains.iter().map(SpringDoc::from_spec).collect(),
            spring_substep_hz: (spec.springs.substep_hz != DEFAULT_SUBSTEP_HZ).then_some(spec.springs.substep_hz),
            character: None,
            retarget: (spec.retarget != RetargetSpec::default()).then(|| RetargetDoc::from_spec(&spec.retarget)),
        }
    }

    /// The motion's spring chains and substep rate in the core's form, the
    /// rules that need no skeleton checked (`pointer` as for
    /// [`MotionDoc::to_spec`]); compile them against the output skeleton
    /// with [`super::spring::compile_springs`].
    ///
    /// # Errors
    /// A chain or rate that breaks a rule of `docs/springs.md`, at its pointer.
    pub fn springs(&self, pointer: &str) -> Result<SpringsSpec, DocError> {
        springs_spec(&self.springs, self.spring_substep_hz, pointer)
    }
}

impl LayerDoc {
    fn from_spec(layer: &LayerSpec<String>) -> LayerDoc {
        LayerDoc {
            clip: layer.clip.clone(),
            graph: None,
            weight: layer.weight,
            mode: match layer.mode {
                LayerMode::Blend => LayerModeDoc::Blend,
                LayerMode::Additive => LayerModeDoc::Additive,
            },
            mask: layer.mask.as_ref().map(|m| MaskDoc {
                joints: m.joints.iter().cloned().collect(),
                descendants: m.descendants,
                default: m.default,
            }),
            offset: layer.offset,
            speed: layer.speed,
            playback: layer.playback.map(Into::into),
            sync: layer.sync.clone(),
            reference_time: layer.reference_time,
            retarget: layer.retarget.as_ref().map(RetargetDoc::from_spec),
        }
    }

    /// # Errors
    /// `graph_unsupported` for a layer naming a graph (what plays graphs
    /// takes them before this), `missing_field` for one naming nothing.
    fn to_spec(&self, pointer: &str) -> Result<LayerSpec<String>, DocError> {
        if self.graph.is_some() {
            let detail = "a graph layer plays where a motion is played as a whole (poses, samples, streams, \
                          broadcasts), not here (docs/graphs.md)";
            return Err(DocError {
                code: "graph_unsupported",
                pointer: format!("{pointer}/graph"),
                detail: detail.into(),
            });
        }
        if self.clip.is_empty() {
            let detail = "a layer names a `clip` (or a `graph`)".to_owned();
            return Err(DocError { code: "missing_field", pointer: format!("{pointer}/clip"), detail });
        }
        Ok(LayerSpec {
            clip: self.clip.clone(),
            weight: self.weight,
            mode: match self.mode {
                LayerModeDoc::Blend => LayerMode::Blend,
                LayerModeDoc::Additive => LayerMode::Additive,
            },
            mask: self.mask.as_ref().map(|m| MaskSpec {
                joints: m.joints.iter().map(|(name, w)| (name.clone(), *w)).collect(),
                descendants: m.descendants,
                default: m.default,
            }),
            offset: self.offset,
            speed: self.speed,
            playback: self.playback.map(Into::into),
            sync: self.sync.clone(),
            reference_time: self.reference_time,
            retarget: self.retarget.as_ref().map(|r| r.to_spec(&format!("{pointer}/retarget"))).transpose()?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_spec_written_back_as_a_document_parses_to_the_same_spec() {
        let doc: MotionDoc = serde_json::from_str(
            r#"{"layers": [
                {"clip": "walk", "weight": 0.75, "speed": -1.5, "offset": 0.25, "playback": "ping_pong", "sync": "loco"},
                {"clip": "wave", "mask": {"joints": {"spine": 0.5, "arm_l": 1}, "descendants": true, "default": 0.1}},
                {"clip": "breathe", "mode": "additive", "weight": 0.5, "reference_time": 0.4}
            ], "root_motion": {"joint": "hips", "mode": "extract", "up": "z"},
            "ik": [{"kind": "aim", "joint": "head", "target": [1, 2, 3], "forward": [0, 0, 1]}]}"#,
        )
        .unwrap();
        let spec = doc.to_spec("/motion").unwrap();
        let again = MotionDoc::from_spec(&spec);
        let json = serde_json::to_value(&again).unwrap();
        let reparsed: MotionDoc = serde_json::from_value(json).unwrap();
        assert_eq!(format!("{:?}", reparsed.to_spec("/motion").unwrap()), format!("{spec:?}"));
        assert_eq!(again.layers, doc.layers);
        assert_eq!(again.root_motion, doc.root_motion);
    }

    #[test]
    fn the_spec_example_parses_with_its_defaults() {
        let doc: MotionDoc = serde_json::from_str(
            r#"{"layers": [
                {"clip": "walk", "weight": 1.0, "sync": "locomotion"},
                {"clip": "run", "weight": 0.3, "sync": "locomotion"},
                {"clip": "wave", "mask": {"joints": {"spine": 1, "arm_l": 1}, "descendants": true}},
                {"clip": "breathe", "mode": "additive", "weight": 0.5, "reference_time": 0}
            ], "root_motion": {"joint": "hips", "mode": "extract"}}"#,
        )
        .unwrap();
        let spec = doc.to_spec("/motion").unwrap();
        assert_eq!(spec.layers.len(), 4);
        assert_eq!((spec.layers[2].weight, spec.layers[2].speed, spec.layers[2].offset), (1.0, 1.0, 0.0));
        assert_eq!(spec.layers[2].mask.as_ref().unwrap().joints, vec![("arm_l".into(), 1.0), ("spine".into(), 1.0)]);
        assert_eq!(spec.layers[3].mode, LayerMode::Additive);
        let root = spec.root_motion.unwrap();
        assert_eq!((root.joint.as_deref(), root.mode, root.up), (Some("hips"), RootMode::Extract, UpAxis::Y));
    }

    #[test]
    fn unknown_fields_are_refused() {
        assert!(serde_json::from_str::<MotionDoc>(r#"{"layers": [{"clip": "a", "wieght": 1}]}"#).is_err());
        assert!(serde_json::from_str::<MotionDoc>(r#"{"layers": [], "ik2": []}"#).is_err());
    }
}
