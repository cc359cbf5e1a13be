//! Layers played on a motion's character (docs/motion.md, “Characters”): a
//! layer whose clip is of another skeleton gets a [`Retargeter`] onto the
//! character, built once with the motion; its poses are then in the
//! character's joints, so masks, layering, root motion and IK see one rig.

use super::error::{MotionError, MotionErrorKind as K};
use super::spec::{CharacterSpec, RetargetSpec, SourcePose};
use crate::character::{
    FootPlanter, RetargetOptions, Retargeter, Rig, Role, RoleMap, lowest_feet, rest_with_rotations,
};
use crate::{Clip, Cursor, Path, Pose, Skeleton};
use glam::Quat;

/// Whether `clip` is of the character's own skeleton (the same joints in
/// the same order under the same parents): it plays as it is.
pub(super) fn same_rig(character: &CharacterSpec, clip: &Clip) -> bool {
    let (a, b) = (&character.skeleton, clip.skeleton());
    a.names() == b.names() && (0..a.len()).all(|j| a.parent(j) == b.parent(j))
}

/// The retargeter of a layer's `clip` onto `character`, and its foot
/// planter when the options plant feet; `path` is the layer's, `at` where
/// its retarget options came from (for pointers).
///
/// # Errors
/// `unmappable_skeleton` at the layer's `clip` when the clip's roles and
/// the character's share no hips or too few roles; `unknown_joint` for a
/// source pose rotating a joint the clip lacks.
pub(super) fn layer_retargeter(
    character: &CharacterSpec,
    clip: &Clip,
    spec: &RetargetSpec,
    path: &Path,
    at: &Path,
) -> Result<(Retargeter, Option<FootPlanter>), MotionError> {
    let roles = RoleMap::infer(clip.skeleton(), &[]).unwrap_or_else(|_| RoleMap::empty());
    let reference = source_reference(clip, &roles, &spec.source_pose, at)?;
    let source = Rig { skeleton: clip.skeleton(), reference: &reference, roles: &roles };
    let target_reference = target_reference(character, &spec.target_pose, at)?;
    let target = Rig { skeleton: &character.skeleton, reference: &target_reference, roles: &character.roles };
    let options = RetargetOptions { translation: spec.translation };
    let retargeter = Retargeter::new(source, target, options)
        .map_err(|e| MotionError::new(path.clone().field("clip"), K::Retarget(e)))?;
    let planter = spec.feet.map(|feet| FootPlanter::new(&roles, &character.roles, lowest_feet(clip, &roles), feet));
    Ok((retargeter, planter))
}

/// The character's reference pose (local): its own (the rest), the joints
/// `rotations` names turned to the local rotations given.
///
/// # Errors
/// `unknown_joint` at `target_pose/rotations/{name}` for a joint the
/// character lacks. The rotations are unit (the document normalised them).
fn target_reference(character: &CharacterSpec, rotations: &[(String, Quat)], at: &Path) -> Result<Pose, MotionError> {
    let skeleton = &character.skeleton;
    let mut pose = character.reference.clone().unwrap_or_else(|| skeleton.rest().clone());
    for (name, q) in rotations {
        let joint = skeleton.index_of(name).ok_or_else(|| {
            let path = at.clone().field("target_pose").field("rotations").key(name);
            MotionError::new(path, K::UnknownJoint { joint: name.clone() })
        })?;
        pose.rotations[joint] = *q;
    }
    Ok(pose)
}

/// The source side's reference pose (local): as asked, by default the rest
/// pose with a root at the origin that has a translation track (a BVH's
/// hips, whose offset is usually 0) at its first frame's position.
fn source_reference(clip: &Clip, roles: &RoleMap, pose: &SourcePose, at: &Path) -> Result<Pose, MotionError> {
    let skeleton = clip.skeleton();
    match pose {
        SourcePose::Rest => Ok(rest_with_first_frame_root(clip, roles)),
        SourcePose::Time(t) => {
            let t = (*t as f32).clamp(clip.start(), clip.end());
            let mut pose = Pose::default();
            clip.sample_into(t, &mut Cursor::default(), &mut pose);
            Ok(pose)
        }
        SourcePose::Rotations(rotations) => {
            let joints = rotations
                .iter()
                .map(|(name, q)| {
                    let joint = skeleton.index_of(name).ok_or_else(|| {
                        let path = at.clone().field("source_pose").field("rotations").key(name);
                        MotionError::new(path, K::UnknownJoint { joint: name.clone() })
                    })?;
                    Ok((joint, *q))
                })
                .collect::<Result<Vec<_>, _>>()?;
            Ok(rest_with_rotations(skeleton, &joints))
        }
    }
}

/// The rest pose, the hips (else the first root) moved to the clip's
/// first frame when its rest translation is zero and it has a translation
/// track.
fn rest_with_first_frame_root(clip: &Clip, roles: &RoleMap) -> Pose {
    let skeleton: &Skeleton = clip.skeleton();
    let mut pose = skeleton.rest().clone();
    let root = roles.joint(Role::Hips).or_else(|| (0..skeleton.len()).find(|&j| skeleton.parent(j).is_none()));
    let Some(root) = root else { return pose };
    if pose.translations[root] == glam::Vec3A::ZERO && clip.has_translation_track(root) {
        let mut first = Pose::default();
        clip.sample_joints_into(clip.start(), &mut Cursor::default(), &mut first, |j| j as usize == root);
        pose.translations[root] = first.translations[root];
    }
    pose
}
