//! A take recorded on one skeleton, played on another.
//!
//! Per role both skeletons map, with `G` a joint's model-space rotation and
//! `G⁰` its rotation in its side's reference pose, the target joint's model
//! rotation is `G_d(t) = G_s(t)·(G⁰_s)⁻¹·G⁰_d`: the source's world-space
//! change from its reference, applied to the target's reference. Local
//! rotations follow top-down through the target's own hierarchy
//! (`q_l = G_parent⁻¹·G_d`). Unmapped target joints keep their reference
//! local rotation (a tail follows its parent); unmapped source joints are
//! ignored; every target joint keeps its reference scale and, but for the
//! hips, its reference local translation, so bone lengths are the target's.
//!
//! The hips' model position is `p⁰_d + k·(p_s(t) − p⁰_s)` with `k = h_d/h_s`,
//! `h` the height (`+Y`) of the hips above the lower foot in each reference
//! pose, or, when either side lacks feet, the length of the leg chain from
//! the hips down through the leg joints both sides map (the left leg, else
//! the right); `k = 1` when neither can be measured. [`Translation::All`]
//! also moves every other mapped joint's local translation by `k` times its
//! source's change; [`Translation::None`] keeps the hips at `p⁰_d`.
//!
//! [`Retargeter::new`] measures both references once; [`Retargeter::retarget`]
//! is then one model-space pass over the source and one over the target,
//! with no allocation once the output pose has its size.

use std::fmt;

use glam::{Quat, Vec3A};

use super::map::RoleMap;
use super::roles::{Role, Side};
use crate::{Pose, Skeleton};

/// A retarget needs the hips and at least this many roles in common.
pub const MIN_SHARED_ROLES: usize = 8;

/// No parent, or no source joint.
pub(crate) const NO_JOINT: u32 = u32::MAX;

/// What happens to translations (the hips' by default).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Translation {
    /// The hips follow the source's, scaled by `k`.
    #[default]
    Hips,
    /// The hips stay at their reference position.
    None,
    /// The hips as [`Translation::Hips`], and every mapped joint's local
    /// translation moves by `k` times its source's change.
    All,
}

impl Translation {
    /// The stable name (`hips`, `none`, `all`).
    pub fn as_str(self) -> &'static str {
        match self {
            Translation::Hips => "hips",
            Translation::None => "none",
            Translation::All => "all",
        }
    }
}

/// How to retarget.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RetargetOptions {
    pub translation: Translation,
}

/// One side of a retarget: a skeleton, its reference pose (local space,
/// one transform per joint) and its role map.
#[derive(Debug, Clone, Copy)]
pub struct Rig<'a> {
    pub skeleton: &'a Skeleton,
    pub reference: &'a Pose,
    pub roles: &'a RoleMap,
}

impl<'a> Rig<'a> {
    /// A rig whose reference is its skeleton's rest pose.
    pub fn at_rest(skeleton: &'a Skeleton, roles: &'a RoleMap) -> Rig<'a> {
        Rig { skeleton, reference: skeleton.rest(), roles }
    }
}

/// The rest pose of `skeleton` with some local rotations replaced: a
/// reference that turns an A-pose into a T-pose.
///
/// # Panics
/// If a joint index is not a joint of `skeleton`.
pub fn rest_with_rotations(skeleton: &Skeleton, rotations: &[(usize, Quat)]) -> Pose {
    let mut pose = skeleton.rest().clone();
    for &(joint, q) in rotations {
        pose.rotations[joint] = q.normalize();
    }
    pose
}

/// Why two rigs cannot be retargeted.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RetargetError {
    /// They share no hips, or fewer than [`MIN_SHARED_ROLES`] roles:
    /// `missing` are the target's roles the source lacks (and `hips` if
    /// either lacks it).
    UnmappableSkeleton { shared: usize, missing: Vec<Role> },
    /// A reference pose does not have one transform per joint.
    ReferenceSize { target: bool, expected: usize, provided: usize },
}

impl RetargetError {
    /// A stable machine-readable code.
    pub fn code(&self) -> &'static str {
        match self {
            RetargetError::UnmappableSkeleton { .. } => "unmappable_skeleton",
            RetargetError::ReferenceSize { .. } => "reference_pose_size",
        }
    }
}

impl fmt::Display for RetargetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RetargetError::UnmappableSkeleton { shared, missing } => {
                let names: Vec<&str> = missing.iter().map(|r| r.name()).collect();
                write!(f, "the skeletons share {shared} roles (the hips and {MIN_SHARED_ROLES} needed); ")?;
                write!(f, "the source lacks: {}", names.join(", "))
            }
            RetargetError::ReferenceSize { target, expected, provided } => {
                let side = if *target { "target" } else { "source" };
                write!(f, "the {side} reference pose has {provided} joints, its skeleton {expected}")
            }
        }
    }
}

impl std::error::Error for RetargetError {}

/// The hips of both sides and how far the source's move the target's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Hips {
    pub(crate) target: usize,
    pub(crate) source: usize,
    /// `p⁰_d`, `p⁰_s`: model positions in the references.
    pub(crate) target_reference: Vec3A,
    pub(crate) source_reference: Vec3A,
    pub(crate) k: f32,
}

/// Plays poses of one skeleton on another (module docs). Built once per
/// pair of rigs; [`Retargeter::retarget`] allocates nothing once warm.
#[derive(Debug, Clone)]
pub struct Retargeter {
    pub(crate) source_parents: Vec<u32>,
    pub(crate) target_parents: Vec<u32>,
    /// Per target joint, the source joint driving it, or `NO_JOINT`.
    pub(crate) source_of: Vec<u32>,
    /// Per target joint, `(G⁰_s)⁻¹·G⁰_d` (identity when unmapped).
    offsets: Vec<Quat>,
    /// The target's reference pose (local).
    pub(crate) reference: Pose,
    /// Per target joint, its source's reference local translation `t⁰_s`.
    pub(crate) source_translations: Vec<Vec3A>,
    pub(crate) hips: Hips,
    pub(crate) translation: Translation,
    /// The source's model space, recomputed per pose.
    source_model: Pose,
    /// The target's model space as the pass goes.
    target_model: Pose,
}

impl Retargeter {
    /// Measures both references and pairs the roles both rigs map.
    ///
    /// # Errors
    /// The rigs share no hips or fewer than [`MIN_SHARED_ROLES`] roles, or
    /// a reference pose has the wrong number of joints.
    pub fn new(source: Rig<'_>, target: Rig<'_>, options: RetargetOptions) -> Result<Retargeter, RetargetError> {
        check_reference(&source, false)?;
        check_reference(&target, true)?;
        let shared = source.roles.shared(target.roles).count();
        let (Some(source_hips), Some(target_hips)) = (source.roles.joint(Role::Hips), target.roles.joint(Role::Hips))
        else {
            return Err(unmappable(&source, &target, shared));
        };
        if shared < MIN_SHARED_ROLES {
            return Err(unmappable(&source, &target, shared));
        }
        let (source_model, target_model) = (model(&source), model(&target));
        let n = target.skeleton.len();
        let mut source_of = vec![NO_JOINT; n];
        let mut offsets = vec![Quat::IDENTITY; n];
        let mut source_translations = target.reference.translations.clone();
        for role in source.roles.shared(target.roles) {
            let (Some(s), Some(d)) = (source.roles.joint(role), target.roles.joint(role)) else { continue };
            source_of[d] = s as u32;
            offsets[d] = (source_model.rotations[s].conjugate() * target_model.rotations[d]).normalize();
            source_translations[d] = source.reference.translations[s];
        }
        let hips = Hips {
            target: target_hips,
            source: source_hips,
            target_reference: target_model.translations[target_hips],
            source_reference: source_model.translations[source_hips],
            k: hips_ratio(&source, &source_model, &target, &target_model),
        };
        Ok(Retargeter {
            source_parents: parents(source.skeleton),
            target_parents: parents(target.skeleton),
            source_of,
            offsets,
            reference: target.reference.clone(),
            source_translations,
            hips,
            translation: options.translation,
            source_model,
            target_model,
        })
    }

    /// `k = h_d / h_s`, the hips height ratio (module docs).
    pub fn k(&self) -> f32 {
        self.hips.k
    }

    /// The source joint driving target joint `joint`, if it is mapped.
    ///
    /// # Panics
    /// If `joint` is not a target joint.
    pub fn source_joint(&self, joint: usize) -> Option<usize> {
        let s = self.source_of[joint];
        (s != NO_JOINT).then_some(s as usize)
    }

    /// The source's model-space pose of the last [`Retargeter::retarget`].
    pub fn source_model(&self) -> &Pose {
        &self.source_model
    }

    /// The target's model-space pose of the last [`Retargeter::retarget`].
    pub fn target_model(&self) -> &Pose {
        &self.target_model
    }

    /// The number of target joints.
    pub fn target_len(&self) -> usize {
        self.target_parents.len()
    }

    /// Writes the target's local pose for the source's local pose `source`.
    /// `target`'s parameters are left as they are.
    ///
    /// # Panics
    /// If `source` has fewer joints than the source skeleton.
    pub fn retarget(&mut self, source: &Pose, target: &mut Pose) {
        self.source_pass(source);
        let n = self.target_parents.len();
        target.translations.resize(n, Vec3A::ZERO);
        target.rotations.resize(n, Quat::IDENTITY);
        target.scales.resize(n, Vec3A::ONE);
        let hips_position = self.hips_position();
        for j in 0..n {
            let parent = self.target_parents[j];
            let (pt, pq, ps) = if parent == NO_JOINT {
                (Vec3A::ZERO, Quat::IDENTITY, Vec3A::ONE)
            } else {
                let p = parent as usize;
                let m = &self.target_model;
                (m.translations[p], m.rotations[p], m.scales[p])
            };
            let s = self.source_of[j];
            let (q, g) = if s == NO_JOINT {
                let q = self.reference.rotations[j];
                (q, pq * q)
            } else {
                let g = self.source_model.rotations[s as usize] * self.offsets[j];
                (pq.conjugate() * g, g)
            };
            let t = if j == self.hips.target {
                divide(pq.conjugate() * (hips_position - pt), ps)
            } else if s != NO_JOINT && self.translation == Translation::All {
                let delta = source.translations[s as usize] - self.source_translations[j];
                self.reference.translations[j] + self.hips.k * delta
            } else {
                self.reference.translations[j]
            };
            let scale = self.reference.scales[j];
            target.translations[j] = t;
            target.rotations[j] = q;
            target.scales[j] = scale;
            let m = &mut self.target_model;
            m.translations[j] = pt + pq * (ps * t);
            m.rotations[j] = g;
            m.scales[j] = ps * scale;
        }
    }

    /// The hips' target model position for the source pose just measured.
    fn hips_position(&self) -> Vec3A {
        let h = &self.hips;
        match self.translation {
            Translation::None => h.target_reference,
            Translation::Hips | Translation::All => {
                h.target_reference + h.k * (self.source_model.translations[h.source] - h.source_reference)
            }
        }
    }

    /// The source's model space (docs/clip-format.md, “Skeleton and spaces”).
    fn source_pass(&mut self, local: &Pose) {
        let m = &mut self.source_model;
        for (j, &p) in self.source_parents.iter().enumerate() {
            let (t, q, s) = (local.translations[j], local.rotations[j], local.scales[j]);
            if p == NO_JOINT {
                (m.translations[j], m.rotations[j], m.scales[j]) = (t, q, s);
            } else {
                let p = p as usize;
                let (pt, pq, ps) = (m.translations[p], m.rotations[p], m.scales[p]);
                m.translations[j] = pt + pq * (ps * t);
                m.rotations[j] = pq * q;
                m.scales[j] = ps * s;
            }
        }
    }
}

/// `v ⊘ s`, with 0 where a scale is 0 (a collapsed parent).
fn divide(v: Vec3A, s: Vec3A) -> Vec3A {
    let inv = Vec3A::select(s.cmpeq(Vec3A::ZERO), Vec3A::ZERO, s.recip());
    v * inv
}

fn parents(skeleton: &Skeleton) -> Vec<u32> {
    (0..skeleton.len()).map(|j| skeleton.parent(j).map_or(NO_JOINT, |p| p as u32)).collect()
}

fn model(rig: &Rig<'_>) -> Pose {
    let mut model = Pose::default();
    rig.skeleton.to_model(rig.reference, &mut model);
    model
}

fn check_reference(rig: &Rig<'_>, target: bool) -> Result<(), RetargetError> {
    let (expected, r) = (rig.skeleton.len(), rig.reference);
    let provided = r.translations.len().min(r.rotations.len()).min(r.scales.len());
    if provided == expected && r.translations.len() == r.rotations.len() && r.rotations.len() == r.scales.len() {
        Ok(())
    } else {
        Err(RetargetError::ReferenceSize { target, expected, provided })
    }
}

fn unmappable(source: &Rig<'_>, target: &Rig<'_>, shared: usize) -> RetargetError {
    let hips_shared = source.roles.joint(Role::Hips).is_some() && target.roles.joint(Role::Hips).is_some();
    let mut missing: Vec<Role> =
        target.roles.iter().map(|(r, _)| r).filter(|&r| source.roles.joint(r).is_none()).collect();
    if !hips_shared && !missing.contains(&Role::Hips) {
        missing.insert(0, Role::Hips);
    }
    RetargetError::UnmappableSkeleton { shared, missing }
}

/// `h_d / h_s` (module docs): by feet when both sides have one, else by
/// leg chains; 1 when either height is not positive and finite.
fn hips_ratio(source: &Rig<'_>, source_model: &Pose, target: &Rig<'_>, target_model: &Pose) -> f32 {
    let by_feet = |rig: &Rig<'_>, m: &Pose| {
        let hips = rig.roles.joint(Role::Hips)?;
        let feet = [Role::LeftFoot, Role::RightFoot].into_iter().filter_map(|r| rig.roles.joint(r));
        let lowest = feet.map(|f| m.translations[f].y).reduce(f32::min)?;
        Some(m.translations[hips].y - lowest)
    };
    let ratio = match (by_feet(source, source_model), by_feet(target, target_model)) {
        (Some(s), Some(d)) => d / s,
        _ => {
            let leg = leg_side(source, target);
            leg_length(target, target_model, &leg) / leg_length(source, source_model, &leg)
        }
    };
    if ratio.is_finite() && ratio > 0.0 { ratio } else { 1.0 }
}

/// The leg joints both rigs map, hips first: the left leg's, else the right's.
fn leg_side(source: &Rig<'_>, target: &Rig<'_>) -> Vec<Role> {
    let leg = |side: Side| -> Vec<Role> {
        [Role::Hips, Role::LeftUpperLeg.on(side), Role::LeftLowerLeg.on(side), Role::LeftFoot.on(side)]
            .into_iter()
            .filter(|&r| source.roles.joint(r).is_some() && target.roles.joint(r).is_some())
            .collect()
    };
    let left = leg(Side::Left);
    if left.len() >= 2 { left } else { leg(Side::Right) }
}

/// The length of the chain through `roles`' joints.
fn leg_length(rig: &Rig<'_>, model: &Pose, roles: &[Role]) -> f32 {
    let points: Vec<Vec3A> = roles.iter().filter_map(|r| rig.roles.joint(*r)).map(|j| model.translations[j]).collect();
    points.windows(2).map(|w| w[0].distance(w[1])).sum::<f32>()
}
