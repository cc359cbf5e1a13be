//! What a motion that builds may still get wrong: a layer whose clip has
//! joints the output skeleton lacks plays only the joints both share, and
//! the answer says so (docs/warnings.md, `joints_not_in_skeleton`).

use std::fmt;

use super::error::{NAMES_SHOWN, listed};
use crate::{Path, Skeleton};

/// A layer's joints that play nothing, at the layer's `clip`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MotionWarning {
    /// `layers/i/clip`, relative to the motion.
    pub path: Path,
    /// The first few such joints, in the layer clip's order (one more than
    /// shown when there are more).
    pub joints: Vec<String>,
    /// How many there are.
    pub count: usize,
}

impl MotionWarning {
    /// The stable code.
    pub const CODE: &'static str = "joints_not_in_skeleton";

    /// The warning for a layer whose `layer` skeleton has joints `output`
    /// lacks, if it has any.
    pub(super) fn for_layer(path: Path, output: &Skeleton, layer: &Skeleton) -> Option<MotionWarning> {
        let mut missing = layer.names().iter().filter(|name| output.index_of(name).is_none());
        let joints: Vec<String> = missing.by_ref().take(NAMES_SHOWN + 1).cloned().collect();
        let count = joints.len() + missing.count();
        (count > 0).then_some(MotionWarning { path, joints, count })
    }

    /// Bytes it holds on the heap.
    pub(super) fn heap_bytes(&self) -> usize {
        self.joints.iter().map(String::capacity).sum::<usize>() + self.joints.capacity() * size_of::<String>()
    }
}

impl fmt::Display for MotionWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (count, names) = (self.count, listed(&self.joints));
        let joints = if count == 1 { "joint" } else { "joints" };
        write!(
            f,
            "this layer's clip has {count} {joints} the output skeleton (the first layer's clip) lacks ({names}); \
             they play nothing. If the clip is another rig, give the motion a `character`"
        )
    }
}
