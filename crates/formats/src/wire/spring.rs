//! Spring chains on the wire (docs/springs.md): the `springs` list a motion
//! or a clip document carries, and the motion's `spring_substep_hz`,
//! converted to the core's [`SpringsSpec`] and compiled against a skeleton,
//! with every refusal at its JSON pointer.

use std::collections::BTreeMap;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use super::doc::DocError;
use anim::Skeleton;
use anim::spring::{
    ChainSpec, ColliderShape, ColliderSpec, DEFAULT_SUBSTEP_HZ, JointParams, SpringError, SpringParams, Springs,
    SpringsSpec,
};

/// One chain: `joints[i]` turns so that `joints[i + 1]`, its tail, swings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SpringDoc {
    pub name: String,
    /// First to last, each a descendant of the one before; the last only
    /// marks the tail of the one before.
    pub joints: Vec<String>,
    /// Pull back toward the rest direction, ≥ 0 (default 1).
    #[serde(default = "stiffness")]
    pub stiffness: f32,
    /// The share of the last substep's motion lost, in [0, 1] (default 0.4).
    #[serde(default = "drag")]
    pub drag: f32,
    /// m/s² in model space (default none).
    #[serde(default, skip_serializing_if = "is_zero")]
    #[schema(min_items = 3, max_items = 3)]
    pub gravity: [f32; 3],
    /// The tails' radius against colliders, metres (default 0.02).
    #[serde(default = "radius")]
    pub radius: f32,
    /// Per-joint overrides, by the name of a joint that turns.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub joint_params: BTreeMap<String, JointParamsDoc>,
    /// Tested in order by every joint of the chain.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub colliders: Vec<ColliderDoc>,
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JointParamsDoc {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stiffness: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drag: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gravity: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<f32>,
}

/// A sphere or a capsule fixed to a joint (exactly one of the two).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ColliderDoc {
    pub joint: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sphere: Option<SphereDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub capsule: Option<CapsuleDoc>,
}

/// `offset` in the joint's local frame; `radius` in metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SphereDoc {
    #[serde(default)]
    pub offset: [f32; 3],
    pub radius: f32,
}

/// The points within `radius` of the segment `offset`–`tail` (both in the
/// joint's local frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CapsuleDoc {
    #[serde(default)]
    pub offset: [f32; 3],
    pub tail: [f32; 3],
    pub radius: f32,
}

fn stiffness() -> f32 {
    SpringParams::default().stiffness
}

fn drag() -> f32 {
    SpringParams::default().drag
}

fn radius() -> f32 {
    SpringParams::default().radius
}

fn is_zero(v: &[f32; 3]) -> bool {
    *v == [0.0; 3]
}

/// The core's form of `springs` and `hz` (default 120), with the rules that
/// need no skeleton checked; `pointer` is the document's place in its
/// message (`""` for a clip, `/motion` for a stream's motion).
///
/// # Errors
/// A collider that is not exactly one shape, or a rule of
/// [`SpringsSpec::check`], at its pointer.
pub fn springs_spec(springs: &[SpringDoc], hz: Option<f64>, pointer: &str) -> Result<SpringsSpec, DocError> {
    let chains = (springs.iter().enumerate())
        .map(|(i, s)| s.to_spec(&format!("{pointer}/springs/{i}")))
        .collect::<Result<_, _>>()?;
    let spec = SpringsSpec { chains, substep_hz: hz.unwrap_or(DEFAULT_SUBSTEP_HZ) };
    spec.check().map_err(|e| spring_error(e, pointer))?;
    Ok(spec)
}

/// `spec` compiled against `skeleton` (the clip's, or a motion's output
/// skeleton: its first layer's clip).
///
/// # Errors
/// A joint the skeleton lacks, joints that are not a chain, a collider on a
/// swinging joint (docs/springs.md, “Fields”), at its pointer.
pub fn compile_springs(spec: &SpringsSpec, skeleton: &Skeleton, pointer: &str) -> Result<Springs, DocError> {
    Springs::build(spec, skeleton).map_err(|e| spring_error(e, pointer))
}

/// A core refusal at `pointer` + its path.
pub fn spring_error(e: SpringError, pointer: &str) -> DocError {
    DocError { code: e.kind.code(), pointer: format!("{pointer}{}", e.path.to_pointer()), detail: e.kind.to_string() }
}

impl SpringDoc {
    fn to_spec(&self, pointer: &str) -> Result<ChainSpec, DocError> {
        let colliders = (self.colliders.iter().enumerate())
            .map(|(k, c)| c.to_spec(&format!("{pointer}/colliders/{k}")))
            .collect::<Result<_, _>>()?;
        Ok(ChainSpec {
            name: self.name.clone(),
            joints: self.joints.clone(),
            params: SpringParams {
                stiffness: self.stiffness,
                drag: self.drag,
                gravity: Vec3::from(self.gravity),
                radius: self.radius,
            },
            joint_params: (self.joint_params.iter())
                .map(|(name, p)| {
                    let params = JointParams {
                        stiffness: p.stiffness,
                        drag: p.drag,
                        gravity: p.gravity.map(Vec3::from),
                        radius: p.radius,
                    };
                    (name.clone(), params)
                })
                .collect(),
            colliders,
        })
    }

    /// The document of a chain (an import's, say).
    pub fn from_spec(chain: &ChainSpec) -> SpringDoc {
        SpringDoc {
            name: chain.name.clone(),
            joints: chain.joints.clone(),
            stiffness: chain.params.stiffness,
            drag: chain.params.drag,
            gravity: chain.params.gravity.to_array(),
            radius: chain.params.radius,
            joint_params: (chain.joint_params.iter())
                .map(|(name, p)| {
                    let doc = JointParamsDoc {
                        stiffness: p.stiffness,
                        drag: p.drag,
                        gravity: p.gravity.map(|g| g.to_array()),
                        radius: p.radius,
                    };
                    (name.clone(), doc)
                })
                .collect(),
            colliders: chain.colliders.iter().map(ColliderDoc::from_spec).collect(),
        }
    }
}

impl ColliderDoc {
    fn to_spec(&self, pointer: &str) -> Result<ColliderSpec, DocError> {
        let shape = match (self.sphere, self.capsule) {
            (Some(s), None) => ColliderShape::Sphere { offset: Vec3::from(s.offset), radius: s.radius },
            (None, Some(c)) => {
                ColliderShape::Capsule { offset: Vec3::from(c.offset), tail: Vec3::from(c.tail), radius: c.radius }
            }
            _ => {
                return Err(DocError {
                    code: "invalid_collider",
                    pointer: pointer.to_owned(),
                    detail: "a collider is exactly one of `sphere` and `capsule`".into(),
                });
            }
        };
        Ok(ColliderSpec { joint: self.joint.clone(), shape })
    }

    fn from_spec(c: &ColliderSpec) -> ColliderDoc {
        let (sphere, capsule) = match c.shape {
            ColliderShape::Sphere { offset, radius } => (Some(SphereDoc { offset: offset.to_array(), radius }), None),
            ColliderShape::Capsule { offset, tail, radius } => {
                (None, Some(CapsuleDoc { offset: offset.to_array(), tail: tail.to_array(), radius }))
            }
        };
        ColliderDoc { joint: c.joint.clone(), sphere, capsule }
    }
}
