//! VRM 1.0's `VRMC_springBone` extension → spring chains (docs/springs.md,
//! “Import”): one chain per `springs[k]`, its joints the nodes named, its
//! colliders those of its collider groups in order (each collider once).
//!
//! VRM keeps its parameters per joint; the chain takes its first joint's and
//! every other turning joint that differs gets `joint_params`. VRM's
//! `gravityPower·gravityDir` is a displacement rate applied once per update
//! (`Δ = gravityDir·gravityPower·Δt`), which the integration here writes as
//! an acceleration (`gravity·h²`): `gravity = gravityDir·gravityPower·60`
//! m/s² moves a tail as VRM does at 60 updates per second. `center` is not
//! supported (the chain runs in model space) and is said in a warning.

use serde::Deserialize;

use super::error::ImportError;
use super::names::unique_names;
use super::vrm_extension::{extensions, invalid};
use super::warning::{NOT_IMPORTED, Warning};
use anim::spring::{ChainSpec, ColliderShape, ColliderSpec, JointParams, SpringParams};
use glam::Vec3;

/// Where the extension sits in a glTF document (warnings point below it).
pub const POINTER: &str = "/extensions/VRMC_springBone";

/// VRM's per-joint defaults (the extension's JSON schema).
const HIT_RADIUS: f32 = 0.0;
const STIFFNESS: f32 = 1.0;
const GRAVITY_POWER: f32 = 0.0;
const GRAVITY_DIR: [f32; 3] = [0.0, -1.0, 0.0];
const DRAG_FORCE: f32 = 0.5;
/// VRM's updates per second that `gravityPower` is converted at.
const VRM_RATE: f32 = 60.0;

#[derive(Deserialize)]
struct Extensions {
    #[serde(rename = "VRMC_springBone")]
    spring_bone: Option<SpringBone>,
}

#[derive(Deserialize)]
struct SpringBone {
    #[serde(default)]
    colliders: Vec<Collider>,
    #[serde(default, rename = "colliderGroups")]
    collider_groups: Vec<ColliderGroup>,
    #[serde(default)]
    springs: Vec<Spring>,
}

#[derive(Deserialize)]
struct Collider {
    node: usize,
    shape: Shape,
}

#[derive(Deserialize)]
struct Shape {
    sphere: Option<Sphere>,
    capsule: Option<Capsule>,
}

#[derive(Deserialize)]
struct Sphere {
    #[serde(default)]
    offset: [f32; 3],
    #[serde(default)]
    radius: f32,
}

#[derive(Deserialize)]
struct Capsule {
    #[serde(default)]
    offset: [f32; 3],
    #[serde(default)]
    tail: [f32; 3],
    #[serde(default)]
    radius: f32,
}

#[derive(Deserialize)]
struct ColliderGroup {
    #[serde(default)]
    colliders: Vec<usize>,
}

#[derive(Deserialize)]
struct Spring {
    name: Option<String>,
    #[serde(default)]
    joints: Vec<Joint>,
    #[serde(default, rename = "colliderGroups")]
    collider_groups: Vec<usize>,
    center: Option<usize>,
}

#[derive(Deserialize)]
struct Joint {
    node: usize,
    #[serde(rename = "hitRadius")]
    hit_radius: Option<f32>,
    stiffness: Option<f32>,
    #[serde(rename = "gravityPower")]
    gravity_power: Option<f32>,
    #[serde(rename = "gravityDir")]
    gravity_dir: Option<[f32; 3]>,
    #[serde(rename = "dragForce")]
    drag_force: Option<f32>,
}

/// The file's spring chains (one per VRM spring, in order) and the nodes
/// they and their colliders use, or nothing when the file has no
/// `VRMC_springBone`. `names` are the nodes' joint names.
///
/// # Errors
/// The extension is malformed or names a node or collider that does not
/// exist.
pub fn chains(
    json: &[u8],
    names: &[String],
    warnings: &mut Vec<Warning>,
) -> Result<(Vec<ChainSpec>, Vec<usize>), ImportError> {
    let extensions = extensions::<Extensions>(json, "VRMC_springBone", POINTER)?;
    let Some(bone) = extensions.and_then(|e| e.spring_bone) else { return Ok((Vec::new(), Vec::new())) };
    let node =
        |n: usize, at: String| names.get(n).map(|_| n).ok_or_else(|| invalid(format!("{at}: node {n} does not exist")));
    let mut nodes = Vec::new();
    let mut colliders = Vec::with_capacity(bone.colliders.len());
    for (c, collider) in bone.colliders.iter().enumerate() {
        let at = format!("{POINTER}/colliders/{c}");
        nodes.push(node(collider.node, format!("{at}/node"))?);
        let shape = match (&collider.shape.sphere, &collider.shape.capsule) {
            (Some(s), None) => ColliderShape::Sphere { offset: Vec3::from(s.offset), radius: s.radius },
            (None, Some(c)) => {
                ColliderShape::Capsule { offset: c.offset.into(), tail: c.tail.into(), radius: c.radius }
            }
            _ => return Err(invalid(format!("{at}/shape: exactly one of sphere and capsule"))),
        };
        colliders.push(ColliderSpec { joint: names[collider.node].clone(), shape });
    }
    let spring_names = unique_names(
        (bone.springs.iter().enumerate())
            .map(|(k, s)| s.name.clone().filter(|n| !n.trim().is_empty()).unwrap_or_else(|| format!("spring{k}")))
            .collect(),
    );
    let mut chains = Vec::with_capacity(bone.springs.len());
    for ((k, spring), name) in bone.springs.iter().enumerate().zip(spring_names) {
        let at = format!("{POINTER}/springs/{k}");
        for (i, j) in spring.joints.iter().enumerate() {
            nodes.push(node(j.node, format!("{at}/joints/{i}/node"))?);
        }
        if spring.center.is_some() {
            warnings.push(Warning::new(
                NOT_IMPORTED,
                format!("{at}/center"),
                format!("spring '{name}': its center space is not supported; the chain swings in model space"),
            ));
        }
        let mut chain = ChainSpec::new(&name, &[]);
        chain.joints = spring.joints.iter().map(|j| names[j.node].clone()).collect();
        let params: Vec<SpringParams> = spring.joints.iter().map(params).collect();
        chain.params = params.first().copied().unwrap_or_default();
        let turning = spring.joints.len().saturating_sub(1);
        for (joint, p) in chain.joints.iter().zip(&params).take(turning).skip(1) {
            if *p != chain.params {
                chain.joint_params.push((joint.clone(), differences(*p, chain.params)));
            }
        }
        for (g, &group) in spring.collider_groups.iter().enumerate() {
            let members = bone
                .collider_groups
                .get(group)
                .ok_or_else(|| invalid(format!("{at}/colliderGroups/{g}: group {group} does not exist")))?;
            for &c in &members.colliders {
                let collider = colliders
                    .get(c)
                    .ok_or_else(|| invalid(format!("{POINTER}/colliderGroups/{group}: collider {c} does not exist")))?;
                if !chain.colliders.contains(collider) {
                    chain.colliders.push(collider.clone());
                }
            }
        }
        chains.push(chain);
    }
    nodes.sort_unstable();
    nodes.dedup();
    Ok((chains, nodes))
}

/// A VRM joint's settings, defaults filled, gravity as an acceleration.
fn params(j: &Joint) -> SpringParams {
    let dir = Vec3::from(j.gravity_dir.unwrap_or(GRAVITY_DIR));
    SpringParams {
        stiffness: j.stiffness.unwrap_or(STIFFNESS),
        drag: j.drag_force.unwrap_or(DRAG_FORCE),
        gravity: dir * j.gravity_power.unwrap_or(GRAVITY_POWER) * VRM_RATE,
        radius: j.hit_radius.unwrap_or(HIT_RADIUS),
    }
}

/// The overrides that make `base` into `p`.
fn differences(p: SpringParams, base: SpringParams) -> JointParams {
    JointParams {
        stiffness: (p.stiffness != base.stiffness).then_some(p.stiffness),
        drag: (p.drag != base.drag).then_some(p.drag),
        gravity: (p.gravity != base.gravity).then_some(p.gravity),
        radius: (p.radius != base.radius).then_some(p.radius),
    }
}
