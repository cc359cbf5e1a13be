//! The JSON motion (docs/motion.md): layers of clips by id, masks, sync groups and
//! root motion, parsed strictly (unknown fields refused) into the core's
//! [`MotionSpec`] with the clip ids still to be looked up.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::doc::{DocError, PlaybackDoc};
use super::ik::IkDoc;
use anim::motion::{LayerMode, LayerSpec, MaskSpec, MotionSpec, RootMode, RootMotionSpec, UpAxis};

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
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LayerDoc {
    /// A clip id; the version is pinned when the request or stream starts.
    pub clip: String,
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
}

impl LayerDoc {
    /// A full-weight blend layer of `clip` with every default (what a
    /// document that names only `clip` parses to).
    pub fn new(clip: &str) -> Self {
        LayerDoc {
            clip: clip.to_owned(),
            weight: one(),
            mode: LayerModeDoc::Blend,
            mask: None,
            offset: 0.0,
            speed: one_f64(),
            playback: None,
            sync: None,
            reference_time: None,
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
    /// The core's authoring form, with clip ids in place of clips;
    /// `pointer` is the motion's place in its message (`/motion`).
    ///
    /// # Errors
    /// An `ik` constraint of the wrong shape (see [`IkDoc::to_spec`]).
    pub fn to_spec(&self, pointer: &str) -> Result<MotionSpec<String>, DocError> {
        let ik = (self.ik.iter().enumerate())
            .map(|(i, c)| c.to_spec(&format!("{pointer}/ik/{i}")))
            .collect::<Result<_, _>>()?;
        Ok(MotionSpec {
            layers: self.layers.iter().map(LayerDoc::to_spec).collect(),
            root_motion: self.root_motion.as_ref().map(|r| RootMotionSpec {
                joint: r.joint.clone(),
                mode: match r.mode {
                    RootModeDoc::Report => RootMode::Report,
                    RootModeDoc::Extract => RootMode::Extract,
                },
                up: match r.up {
                    UpAxisDoc::Y => UpAxis::Y,
                    UpAxisDoc::Z => UpAxis::Z,
                },
            }),
            ik,
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
        }
    }
}

impl LayerDoc {
    fn from_spec(layer: &LayerSpec<String>) -> LayerDoc {
        LayerDoc {
            clip: layer.clip.clone(),
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
        }
    }

    fn to_spec(&self) -> LayerSpec<String> {
        LayerSpec {
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
        }
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
