//! Characters: any take on any rig.
//!
//! Skeletons name their joints in many ways (Mixamo, CMU's BVH conversions,
//! DAZ, Unreal, VRM, Blender) and hold them in different rest poses. This
//! module finds each skeleton's humanoid [`Role`]s (the bones of VRM 1.0)
//! and retargets poses from one skeleton onto another through them:
//!
//! - [`RoleMap::infer`]: roles as given, then read from the joint names
//!   (`names`: one table per naming family, the best-matching family
//!   first), then from the rest pose's shape (`structure`), each entry
//!   saying how it was found ([`FoundBy`]); [`RoleMap::missing`] lists the
//!   essential roles it lacks.
//! - [`Retargeter`]: built once from two [`Rig`]s (skeleton, reference
//!   pose, role map), then [`Retargeter::retarget`] turns each source pose
//!   into a target pose, allocation-free; a [`FootPlanter`] then keeps the
//!   feet still while the source's are in contact.
//!
//! Module map: `roles` the role enum; `names` and `structure` the two
//! inferences; `map` the role map; `retarget` the retargeter;
//! `feet` planted feet.

mod feet;
mod map;
mod names;
mod retarget;
mod roles;
mod structure;

pub use self::feet::{FeetOptions, FootPlanter, FootReport, lowest_feet};
pub use self::map::{ESSENTIAL_ROLES, FoundBy, RoleError, RoleJoint, RoleMap};
pub(crate) use self::retarget::NO_JOINT;
pub use self::retarget::{
    MIN_SHARED_ROLES, RetargetError, RetargetOptions, Retargeter, Rig, Translation, rest_with_rotations,
};
pub use self::roles::{Role, Side};

/// The roles the joint names alone give, per role (the names inference of
/// [`RoleMap::infer`], without given roles or structure), and the family
/// read first.
pub fn roles_from_names<S: AsRef<str>>(names: &[S]) -> ([Option<usize>; Role::COUNT], Option<&'static str>) {
    names::roles_from_names(names)
}
