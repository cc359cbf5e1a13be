//! The humanoid roles: the bones of VRM 1.0's humanoid, by their camelCase
//! names, so a take and a rig can be matched bone for bone whatever each
//! calls its joints.
//!
//! The order is fixed so that mirroring is arithmetic: the seven centre
//! bones, then the 24 left ones, then the 24 right ones in the same order.

/// A side of the body. Left is the character's own left: `+X` in glTF's frame,
/// where a character faces `+Z`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    Left,
    Right,
}

macro_rules! roles {
    ($($variant:ident = $name:literal,)*) => {
        /// A humanoid bone of VRM 1.0.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum Role {
            $($variant,)*
        }

        impl Role {
            /// Every role, centre bones first, then left, then right.
            pub const ALL: &'static [Role] = &[$(Role::$variant,)*];

            /// The VRM 1.0 name (`hips`, `leftUpperArm`, `rightIndexDistal`).
            pub fn name(self) -> &'static str {
                match self {
                    $(Role::$variant => $name,)*
                }
            }
        }
    };
}

roles! {
    Hips = "hips",
    Spine = "spine",
    Chest = "chest",
    UpperChest = "upperChest",
    Neck = "neck",
    Head = "head",
    Jaw = "jaw",
    LeftEye = "leftEye",
    LeftShoulder = "leftShoulder",
    LeftUpperArm = "leftUpperArm",
    LeftLowerArm = "leftLowerArm",
    LeftHand = "leftHand",
    LeftUpperLeg = "leftUpperLeg",
    LeftLowerLeg = "leftLowerLeg",
    LeftFoot = "leftFoot",
    LeftToes = "leftToes",
    LeftThumbMetacarpal = "leftThumbMetacarpal",
    LeftThumbProximal = "leftThumbProximal",
    LeftThumbDistal = "leftThumbDistal",
    LeftIndexProximal = "leftIndexProximal",
    LeftIndexIntermediate = "leftIndexIntermediate",
    LeftIndexDistal = "leftIndexDistal",
    LeftMiddleProximal = "leftMiddleProximal",
    LeftMiddleIntermediate = "leftMiddleIntermediate",
    LeftMiddleDistal = "leftMiddleDistal",
    LeftRingProximal = "leftRingProximal",
    LeftRingIntermediate = "leftRingIntermediate",
    LeftRingDistal = "leftRingDistal",
    LeftLittleProximal = "leftLittleProximal",
    LeftLittleIntermediate = "leftLittleIntermediate",
    LeftLittleDistal = "leftLittleDistal",
    RightEye = "rightEye",
    RightShoulder = "rightShoulder",
    RightUpperArm = "rightUpperArm",
    RightLowerArm = "rightLowerArm",
    RightHand = "rightHand",
    RightUpperLeg = "rightUpperLeg",
    RightLowerLeg = "rightLowerLeg",
    RightFoot = "rightFoot",
    RightToes = "rightToes",
    RightThumbMetacarpal = "rightThumbMetacarpal",
    RightThumbProximal = "rightThumbProximal",
    RightThumbDistal = "rightThumbDistal",
    RightIndexProximal = "rightIndexProximal",
    RightIndexIntermediate = "rightIndexIntermediate",
    RightIndexDistal = "rightIndexDistal",
    RightMiddleProximal = "rightMiddleProximal",
    RightMiddleIntermediate = "rightMiddleIntermediate",
    RightMiddleDistal = "rightMiddleDistal",
    RightRingProximal = "rightRingProximal",
    RightRingIntermediate = "rightRingIntermediate",
    RightRingDistal = "rightRingDistal",
    RightLittleProximal = "rightLittleProximal",
    RightLittleIntermediate = "rightLittleIntermediate",
    RightLittleDistal = "rightLittleDistal",
}

/// Centre bones before the left block.
const CENTRE: usize = 7;
/// Bones per side.
const SIDED: usize = 24;

impl Role {
    /// The number of roles.
    pub const COUNT: usize = CENTRE + 2 * SIDED;

    /// The role whose VRM name is `name`, exactly (`leftUpperArm`).
    pub fn from_name(name: &str) -> Option<Role> {
        Role::ALL.iter().copied().find(|r| r.name() == name)
    }

    /// Its position in [`Role::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// Its side, `None` for the centre bones.
    pub fn side(self) -> Option<Side> {
        match self.index() {
            i if i < CENTRE => None,
            i if i < CENTRE + SIDED => Some(Side::Left),
            _ => Some(Side::Right),
        }
    }

    /// The same bone on the given side (a centre bone is itself).
    pub fn on(self, side: Side) -> Role {
        match (self.side(), side) {
            (Some(Side::Left), Side::Right) | (Some(Side::Right), Side::Left) => self.mirror(),
            _ => self,
        }
    }

    /// The same bone on the other side (a centre bone is itself).
    pub fn mirror(self) -> Role {
        let i = self.index();
        match self.side() {
            None => self,
            Some(Side::Left) => Role::ALL[i + SIDED],
            Some(Side::Right) => Role::ALL[i - SIDED],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_blocks_mirror_bone_for_bone() {
        assert_eq!(Role::ALL.len(), Role::COUNT);
        assert_eq!(Role::COUNT, 55, "VRM 1.0 has 55 humanoid bones");
        for &role in Role::ALL {
            assert_eq!(Role::ALL[role.index()], role);
            assert_eq!(role.mirror().mirror(), role);
            if let Some(side) = role.side() {
                let other = role.mirror().name();
                let (own, theirs) = if side == Side::Left { ("left", "right") } else { ("right", "left") };
                assert_eq!(role.name().strip_prefix(own), other.strip_prefix(theirs), "{role:?}");
            }
            assert_eq!(Role::from_name(role.name()), Some(role));
        }
        assert_eq!(Role::LeftToes.on(Side::Right), Role::RightToes);
        assert_eq!(Role::Hips.on(Side::Left), Role::Hips);
    }
}
