//! A skeleton's role map: which joint plays each humanoid role, and how that
//! was found.

use std::fmt;

use super::names::roles_from_names;
use super::roles::Role;
use super::structure::roles_from_structure;
use crate::Skeleton;

/// How a role's joint was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FoundBy {
    /// Given by the caller.
    Given,
    /// Read from the joint names.
    Name,
    /// Read from the rest pose's shape.
    Structure,
}

impl FoundBy {
    /// The stable name (`given`, `name`, `structure`).
    pub fn as_str(self) -> &'static str {
        match self {
            FoundBy::Given => "given",
            FoundBy::Name => "name",
            FoundBy::Structure => "structure",
        }
    }
}

/// The joint a role maps to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RoleJoint {
    pub joint: usize,
    pub by: FoundBy,
}

/// The roles a retarget cannot do well without: a skeleton lacking one of
/// these is reported (`missing_role`).
pub const ESSENTIAL_ROLES: [Role; 6] =
    [Role::Hips, Role::Spine, Role::LeftUpperLeg, Role::LeftLowerLeg, Role::RightUpperLeg, Role::RightLowerLeg];

/// Role → joint for one skeleton. No joint plays two roles.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RoleMap {
    entries: [Option<RoleJoint>; Role::COUNT],
    /// The naming family whose table read the names first, if any matched.
    family: Option<&'static str>,
}

/// A given role the skeleton cannot take.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RoleError {
    /// The role names a joint the skeleton does not have.
    UnknownJoint { role: Role, joint: String },
    /// The role is given twice.
    DuplicateRole { role: Role },
    /// Two roles name the same joint.
    JointHasTwoRoles { joint: String, roles: [Role; 2] },
}

impl RoleError {
    /// A stable machine-readable code.
    pub fn code(&self) -> &'static str {
        match self {
            RoleError::UnknownJoint { .. } => "unknown_joint",
            RoleError::DuplicateRole { .. } => "duplicate_role",
            RoleError::JointHasTwoRoles { .. } => "joint_has_two_roles",
        }
    }

    /// The role at fault (for a pointer such as `/roles/leftHand`).
    pub fn role(&self) -> Role {
        match self {
            RoleError::UnknownJoint { role, .. } | RoleError::DuplicateRole { role } => *role,
            RoleError::JointHasTwoRoles { roles, .. } => roles[1],
        }
    }
}

impl fmt::Display for RoleError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RoleError::UnknownJoint { role, joint } => {
                write!(f, "role {} names joint {joint:?}, which the skeleton does not have", role.name())
            }
            RoleError::DuplicateRole { role } => write!(f, "role {} is given twice", role.name()),
            RoleError::JointHasTwoRoles { joint, roles: [a, b] } => {
                write!(f, "joint {joint:?} is given two roles, {} and {}", a.name(), b.name())
            }
        }
    }
}

impl std::error::Error for RoleError {}

impl RoleMap {
    /// A map with no roles.
    pub fn empty() -> RoleMap {
        RoleMap { entries: [None; Role::COUNT], family: None }
    }

    /// The roles of `skeleton`: `given` first (a joint name, or `None` to
    /// leave the role unmapped), then the names (`names` module), then the
    /// rest pose's shape (`structure` module) fill the roles left, each
    /// with joints no role has yet.
    ///
    /// # Errors
    /// A given role names a joint the skeleton lacks, a role is given
    /// twice, or two roles are given one joint.
    pub fn infer(skeleton: &Skeleton, given: &[(Role, Option<&str>)]) -> Result<RoleMap, RoleError> {
        let mut map = RoleMap::given(skeleton, given)?;
        let decided: Vec<Role> = given.iter().map(|(r, _)| *r).collect();
        let (by_name, family) = roles_from_names(skeleton.names());
        map.family = family;
        map.fill(&by_name, FoundBy::Name, &decided);
        map.fill(&roles_from_structure(skeleton), FoundBy::Structure, &decided);
        Ok(map)
    }

    /// Only the given roles, nothing inferred.
    ///
    /// # Errors
    /// As [`RoleMap::infer`].
    pub fn given(skeleton: &Skeleton, given: &[(Role, Option<&str>)]) -> Result<RoleMap, RoleError> {
        let mut map = RoleMap::empty();
        let mut seen = [false; Role::COUNT];
        for &(role, joint) in given {
            if std::mem::replace(&mut seen[role.index()], true) {
                return Err(RoleError::DuplicateRole { role });
            }
            let Some(name) = joint else { continue };
            let unknown = || RoleError::UnknownJoint { role, joint: name.to_owned() };
            let joint = skeleton.index_of(name).ok_or_else(unknown)?;
            if let Some(other) = map.role_of(joint) {
                return Err(RoleError::JointHasTwoRoles { joint: name.to_owned(), roles: [other, role] });
            }
            map.entries[role.index()] = Some(RoleJoint { joint, by: FoundBy::Given });
        }
        Ok(map)
    }

    /// Puts `found`'s roles where the map has none, the role is not
    /// `decided` and the joint has no role.
    fn fill(&mut self, found: &[Option<usize>; Role::COUNT], by: FoundBy, decided: &[Role]) {
        for (&role, &joint) in Role::ALL.iter().zip(found) {
            let Some(joint) = joint else { continue };
            if self.entries[role.index()].is_none() && !decided.contains(&role) && self.role_of(joint).is_none() {
                self.entries[role.index()] = Some(RoleJoint { joint, by });
            }
        }
    }

    /// The joint playing `role`.
    pub fn joint(&self, role: Role) -> Option<usize> {
        self.entries[role.index()].map(|e| e.joint)
    }

    /// The joint playing `role`, and how it was found.
    pub fn get(&self, role: Role) -> Option<RoleJoint> {
        self.entries[role.index()]
    }

    /// The role joint `joint` plays, if any.
    pub fn role_of(&self, joint: usize) -> Option<Role> {
        Role::ALL.iter().copied().find(|r| self.joint(*r) == Some(joint))
    }

    /// The mapped roles, in [`Role::ALL`] order.
    pub fn iter(&self) -> impl Iterator<Item = (Role, RoleJoint)> + '_ {
        Role::ALL.iter().zip(&self.entries).filter_map(|(r, e)| e.map(|e| (*r, e)))
    }

    /// How many roles are mapped.
    pub fn len(&self) -> usize {
        self.entries.iter().flatten().count()
    }

    /// Whether no role is mapped.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The roles both maps have.
    pub fn shared<'a>(&'a self, other: &'a RoleMap) -> impl Iterator<Item = Role> + 'a {
        Role::ALL.iter().copied().filter(|r| self.joint(*r).is_some() && other.joint(*r).is_some())
    }

    /// The [`ESSENTIAL_ROLES`] this map lacks (each a `missing_role` warning).
    pub fn missing(&self) -> Vec<Role> {
        ESSENTIAL_ROLES.iter().copied().filter(|r| self.joint(*r).is_none()).collect()
    }

    /// The naming family that read the names first (`mixamo`,
    /// `motionbuilder`, `cmu_asf`, `daz`, `unreal`, `vrm`, `blender`).
    pub fn family(&self) -> Option<&'static str> {
        self.family
    }
}
