//! Masks (docs/motion.md): named joint weights resolved once, at build, into one
//! weight per joint of the output skeleton.

use std::collections::HashMap;

use super::error::{MotionError, MotionErrorKind as K};
use super::spec::MaskSpec;
use crate::{Path, Skeleton};

/// One weight per joint of `skeleton`; `None` (no mask) is all ones.
/// `path` is the mask's own (`layers/2/mask`).
pub(super) fn resolve(mask: Option<&MaskSpec>, skeleton: &Skeleton, path: &Path) -> Result<Vec<f32>, MotionError> {
    let Some(mask) = mask else {
        return Ok(vec![1.0; skeleton.len()]);
    };
    let mut named: HashMap<usize, f32> = HashMap::with_capacity(mask.joints.len());
    for (name, weight) in &mask.joints {
        let at = path.clone().field("joints").key(name);
        let joint = skeleton
            .index_of(name)
            .ok_or_else(|| MotionError::new(at.clone(), K::UnknownJoint { joint: name.clone() }))?;
        check_weight(*weight, &at)?;
        if named.insert(joint, *weight).is_some() {
            return Err(MotionError::new(at, K::DuplicateMaskJoint { joint: name.clone() }));
        }
    }
    let default = match mask.default {
        Some(weight) => check_weight(weight, &path.clone().field("default"))?,
        None if mask.joints.is_empty() => 1.0,
        None => 0.0,
    };
    // Parents come first, so one pass carries a named weight down the tree.
    let mut inherited: Vec<Option<f32>> = vec![None; skeleton.len()];
    let weights = (0..skeleton.len())
        .map(|j| {
            let from_parent = skeleton.parent(j).and_then(|p| inherited[p]).filter(|_| mask.descendants);
            let own = named.get(&j).copied().or(from_parent);
            inherited[j] = own;
            own.unwrap_or(default)
        })
        .collect();
    Ok(weights)
}

/// `weight` if it is in `[0, 1]`.
pub(super) fn check_weight(weight: f32, path: &Path) -> Result<f32, MotionError> {
    if !weight.is_finite() {
        return Err(MotionError::new(path.clone(), K::NonFinite));
    }
    if !(0.0..=1.0).contains(&weight) {
        return Err(MotionError::new(path.clone(), K::WeightOutOfRange { weight }));
    }
    Ok(weight)
}
