//! Roles from joint names, one table per naming family.
//!
//! A name is read case-, separator- and prefix-insensitively: the namespace
//! before the last `:` or `|` goes (`mixamorig:`, `mixamorig1:`,
//! `Armature|`), the rest is split into tokens at `_ . - ␠`, and each
//! reading tries the whole name, the name without a trailing number token
//! (`Hip_01`) and without a leading token (`b_`, `J_Bip_`). A side is a token
//! `L`/`R`/`Left`/`Right` anywhere (`thigh_l`, `upper_arm.L`, `J_Bip_L_Hand`),
//! a `left`/`right` at either end (`LeftArm`, `HandLeft`), or a single
//! `l`/`r` in front of a capital (`lShldr`, `LThumb`); a bare lower-case
//! `l`/`r` in front (`lhand`) is the last reading tried. A centre token `C`
//! (`J_Bip_C_Hips`) is dropped.
//!
//! Families clash (`Spine` is the chest in MotionBuilder BVH and the spine
//! in Mixamo; `LeftShoulder` is the upper arm in CMU's ASF-style BVH and the
//! clavicle elsewhere), so a skeleton is read by one family first: the one
//! whose table matches the most roles, ties going to the earlier table in
//! [`FAMILIES`]. So `LowerBack` (mb only) makes a rig mb, `Spine2` (Mixamo
//! only) makes it Mixamo, and with neither, Mixamo's reading wins. Roles
//! that family leaves empty are then filled from the other families in the
//! same order, with joints no role has yet.

use super::roles::{Role, Side};

/// One naming family: normalised keys (lower case, no separators, no side)
/// and their roles (the left one for sided bones).
pub(crate) struct Family {
    pub name: &'static str,
    pub table: &'static [(&'static str, Role)],
}

use Role::*;

const MIXAMO: Family = Family {
    name: "mixamo",
    table: &[
        ("hips", Hips),
        ("spine", Spine),
        ("spine1", Chest),
        ("spine2", UpperChest),
        ("neck", Neck),
        ("head", Head),
        ("shoulder", LeftShoulder),
        ("arm", LeftUpperArm),
        ("forearm", LeftLowerArm),
        ("hand", LeftHand),
        ("upleg", LeftUpperLeg),
        ("leg", LeftLowerLeg),
        ("foot", LeftFoot),
        ("toebase", LeftToes),
        ("handthumb1", LeftThumbMetacarpal),
        ("handthumb2", LeftThumbProximal),
        ("handthumb3", LeftThumbDistal),
        ("handindex1", LeftIndexProximal),
        ("handindex2", LeftIndexIntermediate),
        ("handindex3", LeftIndexDistal),
        ("handmiddle1", LeftMiddleProximal),
        ("handmiddle2", LeftMiddleIntermediate),
        ("handmiddle3", LeftMiddleDistal),
        ("handring1", LeftRingProximal),
        ("handring2", LeftRingIntermediate),
        ("handring3", LeftRingDistal),
        ("handpinky1", LeftLittleProximal),
        ("handpinky2", LeftLittleIntermediate),
        ("handpinky3", LeftLittleDistal),
    ],
};

/// CMU's MotionBuilder-friendly BVH (`05_20-mb`).
const MOTIONBUILDER: Family = Family {
    name: "motionbuilder",
    table: &[
        ("hips", Hips),
        ("lowerback", Spine),
        ("spine", Chest),
        ("spine1", UpperChest),
        ("neck", Neck),
        ("head", Head),
        ("shoulder", LeftShoulder),
        ("arm", LeftUpperArm),
        ("forearm", LeftLowerArm),
        ("hand", LeftHand),
        ("upleg", LeftUpperLeg),
        ("leg", LeftLowerLeg),
        ("foot", LeftFoot),
        ("toebase", LeftToes),
        ("handindex1", LeftIndexProximal),
    ],
};

/// CMU's ASF-style BVH (`131_03`), where the shoulder is the upper arm.
const CMU_ASF: Family = Family {
    name: "cmu_asf",
    table: &[
        ("hips", Hips),
        ("lowerback", Spine),
        ("chest", Chest),
        ("chest2", UpperChest),
        ("lowerneck", Neck),
        ("head", Head),
        ("collar", LeftShoulder),
        ("shoulder", LeftUpperArm),
        ("elbow", LeftLowerArm),
        ("wrist", LeftHand),
        ("hip", LeftUpperLeg),
        ("knee", LeftLowerLeg),
        ("ankle", LeftFoot),
        ("toe", LeftToes),
    ],
};

const DAZ: Family = Family {
    name: "daz",
    table: &[
        ("hip", Hips),
        ("abdomen", Spine),
        ("chest", Chest),
        ("neck", Neck),
        ("head", Head),
        ("eye", LeftEye),
        ("collar", LeftShoulder),
        ("shldr", LeftUpperArm),
        ("forearm", LeftLowerArm),
        ("hand", LeftHand),
        ("thigh", LeftUpperLeg),
        ("shin", LeftLowerLeg),
        ("foot", LeftFoot),
        ("toe", LeftToes),
        ("thumb1", LeftThumbMetacarpal),
        ("thumb2", LeftThumbProximal),
        ("thumb3", LeftThumbDistal),
        ("index1", LeftIndexProximal),
        ("index2", LeftIndexIntermediate),
        ("index3", LeftIndexDistal),
        ("mid1", LeftMiddleProximal),
        ("mid2", LeftMiddleIntermediate),
        ("mid3", LeftMiddleDistal),
        ("ring1", LeftRingProximal),
        ("ring2", LeftRingIntermediate),
        ("ring3", LeftRingDistal),
        ("pinky1", LeftLittleProximal),
        ("pinky2", LeftLittleIntermediate),
        ("pinky3", LeftLittleDistal),
    ],
};

/// The Unreal mannequin (`spine_01`, `thigh_l`).
const UNREAL: Family = Family {
    name: "unreal",
    table: &[
        ("pelvis", Hips),
        ("spine01", Spine),
        ("spine02", Chest),
        ("spine03", UpperChest),
        ("neck01", Neck),
        ("head", Head),
        ("clavicle", LeftShoulder),
        ("upperarm", LeftUpperArm),
        ("lowerarm", LeftLowerArm),
        ("hand", LeftHand),
        ("thigh", LeftUpperLeg),
        ("calf", LeftLowerLeg),
        ("foot", LeftFoot),
        ("ball", LeftToes),
        ("thumb01", LeftThumbMetacarpal),
        ("thumb02", LeftThumbProximal),
        ("thumb03", LeftThumbDistal),
        ("index01", LeftIndexProximal),
        ("index02", LeftIndexIntermediate),
        ("index03", LeftIndexDistal),
        ("middle01", LeftMiddleProximal),
        ("middle02", LeftMiddleIntermediate),
        ("middle03", LeftMiddleDistal),
        ("ring01", LeftRingProximal),
        ("ring02", LeftRingIntermediate),
        ("ring03", LeftRingDistal),
        ("pinky01", LeftLittleProximal),
        ("pinky02", LeftLittleIntermediate),
        ("pinky03", LeftLittleDistal),
    ],
};

/// VRM's own names (and VRoid's `J_Bip_L_UpperArm`, `J_Bip_L_ToeBase`).
const VRM: Family = Family {
    name: "vrm",
    table: &[
        ("hips", Hips),
        ("spine", Spine),
        ("chest", Chest),
        ("upperchest", UpperChest),
        ("neck", Neck),
        ("head", Head),
        ("jaw", Jaw),
        ("eye", LeftEye),
        ("shoulder", LeftShoulder),
        ("upperarm", LeftUpperArm),
        ("lowerarm", LeftLowerArm),
        ("hand", LeftHand),
        ("upperleg", LeftUpperLeg),
        ("lowerleg", LeftLowerLeg),
        ("foot", LeftFoot),
        ("toes", LeftToes),
        ("toebase", LeftToes),
        ("thumbmetacarpal", LeftThumbMetacarpal),
        ("thumbproximal", LeftThumbProximal),
        ("thumbdistal", LeftThumbDistal),
        ("indexproximal", LeftIndexProximal),
        ("indexintermediate", LeftIndexIntermediate),
        ("indexdistal", LeftIndexDistal),
        ("middleproximal", LeftMiddleProximal),
        ("middleintermediate", LeftMiddleIntermediate),
        ("middledistal", LeftMiddleDistal),
        ("ringproximal", LeftRingProximal),
        ("ringintermediate", LeftRingIntermediate),
        ("ringdistal", LeftRingDistal),
        ("littleproximal", LeftLittleProximal),
        ("littleintermediate", LeftLittleIntermediate),
        ("littledistal", LeftLittleDistal),
    ],
};

/// Blender's human metarig names (`thigh.L`, `upper_arm.L`).
const BLENDER: Family = Family {
    name: "blender",
    table: &[
        ("hips", Hips),
        ("pelvis", Hips),
        ("spine", Spine),
        ("chest", Chest),
        ("neck", Neck),
        ("head", Head),
        ("shoulder", LeftShoulder),
        ("upperarm", LeftUpperArm),
        ("forearm", LeftLowerArm),
        ("hand", LeftHand),
        ("thigh", LeftUpperLeg),
        ("shin", LeftLowerLeg),
        ("foot", LeftFoot),
        ("toe", LeftToes),
        ("thumb01", LeftThumbMetacarpal),
        ("thumb02", LeftThumbProximal),
        ("thumb03", LeftThumbDistal),
        ("findex01", LeftIndexProximal),
        ("findex02", LeftIndexIntermediate),
        ("findex03", LeftIndexDistal),
        ("fmiddle01", LeftMiddleProximal),
        ("fmiddle02", LeftMiddleIntermediate),
        ("fmiddle03", LeftMiddleDistal),
        ("fring01", LeftRingProximal),
        ("fring02", LeftRingIntermediate),
        ("fring03", LeftRingDistal),
        ("fpinky01", LeftLittleProximal),
        ("fpinky02", LeftLittleIntermediate),
        ("fpinky03", LeftLittleDistal),
    ],
};

/// Every family, in the order that breaks ties.
pub(crate) const FAMILIES: &[Family] = &[MIXAMO, MOTIONBUILDER, CMU_ASF, DAZ, UNREAL, VRM, BLENDER];

impl Family {
    /// The role `reading` names in this family, if any.
    fn role(&self, (side, key): &(Option<Side>, String)) -> Option<Role> {
        let role = self.table.iter().find(|(k, _)| k == key)?.1;
        match (role.side(), side) {
            (None, None) => Some(role),
            (Some(_), Some(side)) => Some(role.on(*side)),
            _ => None,
        }
    }

    /// Per role, the first joint (in joint order) whose first matching
    /// reading names it.
    fn read(&self, readings: &[Vec<(Option<Side>, String)>]) -> [Option<usize>; Role::COUNT] {
        let mut found = [None; Role::COUNT];
        for (joint, joint_readings) in readings.iter().enumerate() {
            if let Some(role) = joint_readings.iter().find_map(|r| self.role(r)) {
                found[role.index()].get_or_insert(joint);
            }
        }
        found
    }
}

/// The roles `names` give: the best-matching family first, then the
/// others filling its gaps (module docs). Also returns the family read first.
pub(crate) fn roles_from_names<S: AsRef<str>>(names: &[S]) -> ([Option<usize>; Role::COUNT], Option<&'static str>) {
    let readings: Vec<_> = names.iter().map(|n| readings(n.as_ref())).collect();
    let mut reads: Vec<(&Family, [Option<usize>; Role::COUNT])> =
        FAMILIES.iter().map(|f| (f, f.read(&readings))).collect();
    // A stable sort keeps the table order among equal scores.
    reads.sort_by_key(|(_, found)| std::cmp::Reverse(found.iter().flatten().count()));
    let best = reads.first().filter(|(_, found)| found.iter().any(Option::is_some)).map(|(f, _)| f.name);
    let mut roles = [None; Role::COUNT];
    let mut taken = vec![false; names.len()];
    for (_, found) in &reads {
        for (slot, joint) in roles.iter_mut().zip(found) {
            if let (None, Some(j)) = (*slot, *joint)
                && !taken[j]
            {
                *slot = Some(j);
                taken[j] = true;
            }
        }
    }
    (roles, best)
}

/// The readings of one joint name, most specific first (module docs).
pub(crate) fn readings(name: &str) -> Vec<(Option<Side>, String)> {
    let base = name.rsplit([':', '|']).next().unwrap_or(name);
    let tokens: Vec<&str> = base.split(['_', '.', '-', ' ']).filter(|t| !t.is_empty()).collect();
    let mut out = Vec::new();
    for variant in variants(&tokens) {
        read_tokens(&variant, &mut out);
    }
    for variant in variants(&tokens) {
        let joined = join(&variant);
        if let Some(rest) = joined.strip_prefix('l').filter(|r| !r.is_empty()) {
            out.push((Some(Side::Left), rest.to_owned()));
        } else if let Some(rest) = joined.strip_prefix('r').filter(|r| !r.is_empty()) {
            out.push((Some(Side::Right), rest.to_owned()));
        }
    }
    out
}

/// The token lists a name is read as: whole, without a trailing number,
/// without a leading token, without both.
fn variants<'a>(tokens: &[&'a str]) -> Vec<Vec<&'a str>> {
    let numbered = tokens.len() > 1 && tokens.last().is_some_and(|t| t.bytes().all(|b| b.is_ascii_digit()));
    let unnumbered = if numbered { &tokens[..tokens.len() - 1] } else { tokens };
    let mut out = vec![tokens.to_vec()];
    if numbered {
        out.push(unnumbered.to_vec());
    }
    for t in [tokens, unnumbered] {
        for skip in 1..t.len() {
            out.push(t[skip..].to_vec());
        }
    }
    out
}

/// The readings of one token list: without a side, then with each way a
/// side may be written.
fn read_tokens(tokens: &[&str], out: &mut Vec<(Option<Side>, String)>) {
    let tokens: Vec<&str> = tokens.iter().copied().filter(|t| !t.eq_ignore_ascii_case("c")).collect();
    if tokens.is_empty() {
        return;
    }
    let joined = join(&tokens);
    out.push((None, joined.clone()));
    let side_of = |t: &str| match t.to_ascii_lowercase().as_str() {
        "l" | "left" => Some(Side::Left),
        "r" | "right" => Some(Side::Right),
        _ => None,
    };
    let sided: Vec<usize> = (0..tokens.len()).filter(|&i| side_of(tokens[i]).is_some()).collect();
    if let [i] = sided[..]
        && tokens.len() > 1
    {
        let rest: Vec<&str> = tokens.iter().enumerate().filter(|&(k, _)| k != i).map(|(_, t)| *t).collect();
        out.push((side_of(tokens[i]), join(&rest)));
    }
    for (word, side) in [("left", Side::Left), ("right", Side::Right)] {
        if let Some(rest) = joined.strip_prefix(word).filter(|r| !r.is_empty()) {
            out.push((Some(side), rest.to_owned()));
        }
        if let Some(rest) = joined.strip_suffix(word).filter(|r| !r.is_empty()) {
            out.push((Some(side), rest.to_owned()));
        }
    }
    let first = tokens[0].as_bytes();
    if first.len() > 1 && first[1].is_ascii_uppercase() {
        let side = match first[0] {
            b'l' | b'L' => Some(Side::Left),
            b'r' | b'R' => Some(Side::Right),
            _ => None,
        };
        if side.is_some() {
            out.push((side, joined[1..].to_owned()));
        }
    }
}

/// Tokens as one lower-case key without separators.
fn join(tokens: &[&str]) -> String {
    tokens.iter().flat_map(|t| t.chars()).filter(char::is_ascii_alphanumeric).map(|c| c.to_ascii_lowercase()).collect()
}
