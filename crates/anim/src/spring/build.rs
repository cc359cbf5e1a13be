//! [`SpringsSpec`] → [`Springs`]: every rule of docs/springs.md checked once
//! against the skeleton, and the chains laid out for the substep loop.
//!
//! The loop visits only the joints it needs, in two runs of *slots*: the
//! `free` joints (ancestors of the chains and of the colliders' joints,
//! which the animation alone places), then the `driven` joints (the
//! turning joints and the joints between them), each after its parent.
//! So colliders are placed before any tail moves, and a joint's parent has
//! taken its own turn before the joint's tail moves (root to tip).

use std::collections::{HashMap, HashSet};

use glam::{Quat, Vec3A};

use super::error::{SpringError, SpringErrorKind as Kind};
use super::spec::{ChainSpec, ColliderShape, MAX_CHAINS, MAX_COLLIDERS, SUBSTEP_HZ_RANGE, SpringParams, SpringsSpec};
use crate::ik::model::{rotate, unit};
use crate::{Path, Pose, Skeleton};

/// No parent slot, or no bone.
pub(super) const NONE: u32 = u32::MAX;

/// A joint the substep loop places: where its parent's model transform is,
/// and the bone it turns, if any.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Link {
    pub joint: u32,
    pub parent_slot: u32,
    pub bone: u32,
    /// Whether another link is its child. A driven link without one (a
    /// chain's last turning joint) is not placed in model space: nothing
    /// reads it there, only its rotation counts.
    pub parent: bool,
}

/// One turning joint, with everything its substep needs precomputed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Bone {
    /// The unit direction to the tail in the joint's rest frame.
    pub axis: Vec3A,
    /// Joint to tail in the rest pose, in model space.
    pub length: f32,
    /// The joint's rest local rotation.
    pub rest: Quat,
    /// `1 − drag`.
    pub keep: f32,
    /// `stiffness·h`.
    pub pull: f32,
    /// `gravity·h²`.
    pub fall: Vec3A,
    pub radius: f32,
    /// The chain's colliders, `colliders[from..to]`.
    pub colliders: (u32, u32),
}

/// A collider, fixed to the joint in slot `slot`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Collider {
    pub slot: u32,
    pub a: Vec3A,
    /// The capsule's tail (`a` again for a sphere).
    pub b: Vec3A,
    pub radius: f32,
    pub capsule: bool,
}

/// Spring chains checked against one skeleton: what a
/// [`SpringSolver`](super::SpringSolver) runs. Immutable and shareable.
#[derive(Debug, Clone, PartialEq)]
pub struct Springs {
    pub(super) hz: f64,
    pub(super) joints: usize,
    /// Free slots first, then driven ones; each after its parent.
    pub(super) links: Vec<Link>,
    pub(super) free: usize,
    pub(super) bones: Vec<Bone>,
    /// Per bone, its joint (bones are in joint order).
    pub(super) bone_joints: Vec<u32>,
    pub(super) colliders: Vec<Collider>,
    /// The joints of `links`, as a bit set (joint `j` is bit `j % 64` of
    /// word `j / 64`): the only joints of a substep's pose it reads.
    reads: Vec<u64>,
    names: Vec<String>,
}

impl Springs {
    /// Checks `spec` against `skeleton` (docs/springs.md, “Fields”).
    ///
    /// # Errors
    /// The first rule broken, with its path from the document
    /// (`springs/0/joints/2`, `spring_substep_hz`).
    pub fn build(spec: &SpringsSpec, skeleton: &Skeleton) -> Result<Springs, SpringError> {
        spec.check()?;
        // Names looked up once each: a chain down thousands of joints builds in linear time.
        let mut index: HashMap<&str, usize> = HashMap::with_capacity(skeleton.len());
        for (j, name) in skeleton.names().iter().enumerate() {
            index.entry(name.as_str()).or_insert(j);
        }
        let mut model = Pose::default();
        skeleton.to_model(skeleton.rest(), &mut model);
        let mut bone_of: Vec<u32> = vec![NONE; skeleton.len()];
        let mut bones: Vec<(u32, Bone)> = Vec::new();
        let mut colliders: Vec<(u32, ColliderSpecAt)> = Vec::new();
        for (c, chain) in spec.chains.iter().enumerate() {
            let at = Path::root().field("springs").index(c);
            let joints = resolve_chain(chain, skeleton, &index, &at)?;
            let first = colliders.len() as u32;
            for (k, collider) in chain.colliders.iter().enumerate() {
                let joint = index.get(collider.joint.as_str()).copied().ok_or_else(|| {
                    let path = at.clone().field("colliders").index(k).field("joint");
                    SpringError::new(path, Kind::UnknownJoint { joint: collider.joint.clone() })
                })?;
                colliders.push((
                    joint as u32,
                    ColliderSpecAt { shape: collider.shape, path: at.clone().field("colliders").index(k) },
                ));
            }
            let range = (first, colliders.len() as u32);
            for (i, pair) in joints.windows(2).enumerate() {
                let (joint, tail) = (pair[0], pair[1]);
                if bone_of[joint] != NONE {
                    let path = at.clone().field("joints").index(i);
                    return Err(SpringError::new(path, Kind::JointInTwoChains { joint: chain.joints[i].clone() }));
                }
                bone_of[joint] = bones.len() as u32;
                let params = params_of(chain, &chain.joints[i]);
                let bone = bone(skeleton, &model, (joint, tail), params, spec.substep_hz, range).ok_or_else(|| {
                    SpringError::new(
                        at.clone().field("joints").index(i),
                        Kind::ZeroLength { joint: chain.joints[i].clone() },
                    )
                })?;
                bones.push((joint as u32, bone));
            }
        }
        // Bones in joint order, so parents turn first whatever the chains' order.
        let mut order: Vec<usize> = (0..bones.len()).collect();
        order.sort_by_key(|&b| bones[b].0);
        let mut renumber = vec![0u32; bones.len()];
        for (new, &old) in order.iter().enumerate() {
            renumber[old] = new as u32;
        }
        for b in bone_of.iter_mut().filter(|b| **b != NONE) {
            *b = renumber[*b as usize];
        }
        let bone_joints: Vec<u32> = order.iter().map(|&b| bones[b].0).collect();
        let bones: Vec<Bone> = order.iter().map(|&b| bones[b].1).collect();
        let (links, free, slot_of) = lay_out(skeleton, &bone_of, &colliders)?;
        let colliders = colliders
            .iter()
            .map(|&(joint, ref c)| {
                let (a, b, radius, capsule) = match c.shape {
                    ColliderShape::Sphere { offset, radius } => (offset, offset, radius, false),
                    ColliderShape::Capsule { offset, tail, radius } => (offset, tail, radius, true),
                };
                Collider { slot: slot_of[joint as usize], a: a.into(), b: b.into(), radius, capsule }
            })
            .collect();
        let names = spec.chains.iter().map(|c| c.name.clone()).collect();
        let mut reads = vec![0u64; skeleton.len().div_ceil(64)];
        for link in &links {
            reads[link.joint as usize / 64] |= 1 << (link.joint % 64);
        }
        let joints = skeleton.len();
        Ok(Springs { hz: spec.substep_hz, joints, links, free, bones, bone_joints, colliders, reads, names })
    }

    /// Springs that move nothing (a document without chains).
    pub fn none(skeleton: &Skeleton) -> Springs {
        Springs::build(&SpringsSpec::default(), skeleton).expect("no chains break no rule")
    }

    /// Whether there is no chain.
    pub fn is_empty(&self) -> bool {
        self.bones.is_empty()
    }

    /// Substeps per second.
    pub fn substep_hz(&self) -> f64 {
        self.hz
    }

    /// The chains' names, in document order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The joints springs turn, in joint order (their rotation keys are
    /// ignored: the simulation sets them).
    pub fn spring_joints(&self) -> impl ExactSizeIterator<Item = usize> + '_ {
        self.bone_joints.iter().map(|&j| j as usize)
    }

    /// The joints whose local transforms a substep reads (the chains, the
    /// colliders' joints and their ancestors), as a bit set over the
    /// skeleton's joints, joint `j` bit `j % 64` of word `j / 64`: a pose
    /// given to the substeps need be right at these joints only.
    pub fn reads(&self) -> &[u64] {
        &self.reads
    }

    /// Bytes held on the heap (what a cache counts).
    pub fn heap_bytes(&self) -> usize {
        use crate::heap::vec_bytes;
        vec_bytes(&self.links)
            + vec_bytes(&self.bones)
            + vec_bytes(&self.bone_joints)
            + vec_bytes(&self.colliders)
            + vec_bytes(&self.reads)
            + vec_bytes(&self.names)
            + self.names.iter().map(String::capacity).sum::<usize>()
    }

    /// What one substep costs: joints moved, and collider tests (each joint
    /// against each collider of its chain).
    pub fn substep_work(&self) -> (usize, usize) {
        let tests = self.bones.iter().map(|b| (b.colliders.1 - b.colliders.0) as usize).sum();
        (self.bones.len(), tests)
    }
}

struct ColliderSpecAt {
    shape: ColliderShape,
    path: Path,
}

impl SpringsSpec {
    /// The rules that need no skeleton (ranges, counts, finiteness, names),
    /// so a document can be refused before its clips are looked up;
    /// [`Springs::build`] checks them again with the rest.
    ///
    /// # Errors
    /// The first rule broken, with its path.
    pub fn check(&self) -> Result<(), SpringError> {
        check_shape(self)
    }
}

fn check_shape(spec: &SpringsSpec) -> Result<(), SpringError> {
    let hz = spec.substep_hz;
    if !hz.is_finite() || !SUBSTEP_HZ_RANGE.contains(&hz) {
        return Err(SpringError::new(Path::root().field("spring_substep_hz"), Kind::SubstepHzOutOfRange { hz }));
    }
    if spec.chains.len() > MAX_CHAINS {
        let kind = Kind::TooManyChains { max: MAX_CHAINS, provided: spec.chains.len() };
        return Err(SpringError::new(Path::root().field("springs"), kind));
    }
    let mut names = HashSet::new();
    for (c, chain) in spec.chains.iter().enumerate() {
        let at = Path::root().field("springs").index(c);
        if !names.insert(chain.name.as_str()) {
            return Err(SpringError::new(at.field("name"), Kind::DuplicateName { name: chain.name.clone() }));
        }
        if chain.joints.len() < 2 {
            return Err(SpringError::new(at.field("joints"), Kind::TooShort { joints: chain.joints.len() }));
        }
        check_params(&chain.params, &at)?;
        for (name, params) in &chain.joint_params {
            let path = at.clone().field("joint_params").key(name);
            check_params(&params.over(chain.params), &path)?;
            let turning = &chain.joints[..chain.joints.len() - 1];
            if !turning.contains(name) {
                return Err(SpringError::new(path, Kind::NotASpringJoint { joint: name.clone() }));
            }
        }
        if chain.colliders.len() > MAX_COLLIDERS {
            let kind = Kind::TooManyColliders { max: MAX_COLLIDERS, provided: chain.colliders.len() };
            return Err(SpringError::new(at.field("colliders"), kind));
        }
        for (k, collider) in chain.colliders.iter().enumerate() {
            check_collider(collider.shape, at.clone().field("colliders").index(k))?;
        }
    }
    Ok(())
}

fn check_params(p: &SpringParams, at: &Path) -> Result<(), SpringError> {
    let field = |name| at.clone().field(name);
    if !p.stiffness.is_finite() || p.stiffness < 0.0 {
        return Err(SpringError::new(field("stiffness"), Kind::StiffnessOutOfRange { stiffness: p.stiffness }));
    }
    if !(0.0..=1.0).contains(&p.drag) {
        return Err(SpringError::new(field("drag"), Kind::DragOutOfRange { drag: p.drag }));
    }
    if !p.gravity.is_finite() {
        return Err(SpringError::new(field("gravity"), Kind::NonFinite));
    }
    if !p.radius.is_finite() || p.radius < 0.0 {
        return Err(SpringError::new(field("radius"), Kind::RadiusOutOfRange { radius: p.radius }));
    }
    Ok(())
}

fn check_collider(shape: ColliderShape, at: Path) -> Result<(), SpringError> {
    let (name, offset, tail, radius) = match shape {
        ColliderShape::Sphere { offset, radius } => ("sphere", offset, offset, radius),
        ColliderShape::Capsule { offset, tail, radius } => ("capsule", offset, tail, radius),
    };
    let at = at.field(name);
    if !offset.is_finite() {
        return Err(SpringError::new(at.field("offset"), Kind::NonFinite));
    }
    if !tail.is_finite() {
        return Err(SpringError::new(at.field("tail"), Kind::NonFinite));
    }
    if !radius.is_finite() || radius < 0.0 {
        return Err(SpringError::new(at.field("radius"), Kind::RadiusOutOfRange { radius }));
    }
    Ok(())
}

/// The chain's joint indices, each below the one before.
fn resolve_chain(
    chain: &ChainSpec,
    skeleton: &Skeleton,
    index: &HashMap<&str, usize>,
    at: &Path,
) -> Result<Vec<usize>, SpringError> {
    let mut joints = Vec::with_capacity(chain.joints.len());
    for (i, name) in chain.joints.iter().enumerate() {
        let path = || at.clone().field("joints").index(i);
        let j = (index.get(name.as_str()).copied())
            .ok_or_else(|| SpringError::new(path(), Kind::UnknownJoint { joint: name.clone() }))?;
        if let Some(&before) = joints.last()
            && !is_below(skeleton, j, before)
        {
            let kind = Kind::NotAChain { joint: name.clone(), after: chain.joints[i - 1].clone() };
            return Err(SpringError::new(path(), kind));
        }
        joints.push(j);
    }
    Ok(joints)
}

/// Whether `joint` is a strict descendant of `ancestor`.
fn is_below(skeleton: &Skeleton, joint: usize, ancestor: usize) -> bool {
    let mut j = joint;
    while let Some(p) = skeleton.parent(j) {
        if p == ancestor {
            return true;
        }
        j = p;
    }
    false
}

fn params_of(chain: &ChainSpec, joint: &str) -> SpringParams {
    chain.joint_params.iter().find(|(name, _)| name == joint).map_or(chain.params, |(_, p)| p.over(chain.params))
}

/// The bone from `joint` to `tail`, or `None` when they coincide at rest.
fn bone(
    skeleton: &Skeleton,
    model: &Pose,
    (joint, tail): (usize, usize),
    p: SpringParams,
    hz: f64,
    colliders: (u32, u32),
) -> Option<Bone> {
    let offset = model.translations[tail] - model.translations[joint];
    let length = offset.length();
    let axis = unit(rotate(model.rotations[joint].conjugate(), offset))?;
    if length <= 1e-6 * (1.0 + model.translations[joint].length()) {
        return None;
    }
    let h = 1.0 / hz;
    Some(Bone {
        axis,
        length,
        rest: skeleton.rest().rotations[joint],
        keep: 1.0 - p.drag,
        pull: (f64::from(p.stiffness) * h) as f32,
        fall: (p.gravity.as_dvec3() * (h * h)).as_vec3().into(),
        radius: p.radius,
        colliders,
    })
}

/// The slots: free joints then driven ones, each in joint order, and each
/// joint's slot. A collider on a driven joint is refused.
fn lay_out(
    skeleton: &Skeleton,
    bone_of: &[u32],
    colliders: &[(u32, ColliderSpecAt)],
) -> Result<(Vec<Link>, usize, Vec<u32>), SpringError> {
    let n = skeleton.len();
    let mut driven = vec![false; n];
    for j in 0..n {
        driven[j] = bone_of[j] != NONE || skeleton.parent(j).is_some_and(|p| driven[p]);
    }
    for (joint, c) in colliders {
        if driven[*joint as usize] {
            let name = skeleton.names()[*joint as usize].clone();
            return Err(SpringError::new(c.path.clone().field("joint"), Kind::ColliderOnSpring { joint: name }));
        }
    }
    let mut needed = vec![false; n];
    let seeds = (0..n).filter(|&j| bone_of[j] != NONE).chain(colliders.iter().map(|(j, _)| *j as usize));
    for seed in seeds.collect::<Vec<_>>() {
        let mut j = Some(seed);
        while let Some(k) = j.filter(|&k| !needed[k]) {
            needed[k] = true;
            j = skeleton.parent(k);
        }
    }
    let mut slot_of = vec![NONE; n];
    let mut links = Vec::new();
    for pass_driven in [false, true] {
        for j in (0..n).filter(|&j| needed[j] && driven[j] == pass_driven) {
            slot_of[j] = links.len() as u32;
            let parent_slot = skeleton.parent(j).map_or(NONE, |p| slot_of[p]);
            links.push(Link { joint: j as u32, parent_slot, bone: bone_of[j], parent: false });
        }
    }
    for slot in links.iter().map(|l| l.parent_slot).filter(|&p| p != NONE).collect::<Vec<_>>() {
        links[slot as usize].parent = true;
    }
    let free = links.iter().filter(|l| !driven[l.joint as usize]).count();
    Ok((links, free, slot_of))
}
