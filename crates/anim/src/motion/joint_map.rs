//! Which joint of a layer's clip feeds each joint of the output skeleton:
//! joints match by name, and a layer may lack some.

use crate::Skeleton;

/// A layer's joint absent from the output skeleton's mapping.
pub(crate) const UNMAPPED: u32 = u32::MAX;

/// Per output joint, the same-named joint of `layer` (or [`UNMAPPED`]).
pub(super) fn joint_map(output: &Skeleton, layer: &Skeleton) -> Vec<u32> {
    output.names().iter().map(|name| layer.index_of(name).map_or(UNMAPPED, |j| j as u32)).collect()
}
