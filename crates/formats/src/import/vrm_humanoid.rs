//! VRM 1.0's `VRMC_vrm.humanoid.humanBones` → the roles of the file's
//! characters (docs/characters.md, “Import”). VRM's bone names are the
//! roles' own names, so each bone is its role; the file says which node
//! plays it, so nothing is guessed from names or shape. A bone the roles do
//! not know, a node that already plays a role, or a node outside a skin's
//! skeleton is left out with a warning.

use std::collections::BTreeMap;

use serde::Deserialize;

use super::error::ImportError;
use super::vrm_extension::{extensions, invalid};
use super::warning::{NOT_IMPORTED, Warning};
use anim::character::Role;

/// Where the humanoid's bones sit in a glTF document.
pub const POINTER: &str = "/extensions/VRMC_vrm/humanoid/humanBones";

#[derive(Deserialize)]
struct Extensions {
    #[serde(rename = "VRMC_vrm")]
    vrm: Option<Vrm>,
}

#[derive(Deserialize)]
struct Vrm {
    humanoid: Option<Humanoid>,
}

#[derive(Deserialize)]
struct Humanoid {
    #[serde(default, rename = "humanBones")]
    human_bones: BTreeMap<String, HumanBone>,
}

#[derive(Deserialize)]
struct HumanBone {
    node: usize,
}

/// The file's humanoid: each role and the node playing it, in the roles'
/// order; empty when the file has no `VRMC_vrm` humanoid. `nodes` is the
/// document's node count.
///
/// # Errors
/// The extension is malformed or names a node that does not exist.
pub fn human_bones(json: &[u8], nodes: usize, warnings: &mut Vec<Warning>) -> Result<Vec<(Role, usize)>, ImportError> {
    let extensions = extensions::<Extensions>(json, "VRMC_vrm", POINTER)?;
    let Some(humanoid) = extensions.and_then(|e| e.vrm).and_then(|v| v.humanoid) else { return Ok(Vec::new()) };
    let mut named: Vec<(Role, usize)> = Vec::with_capacity(humanoid.human_bones.len());
    for (name, bone) in &humanoid.human_bones {
        let at = format!("{POINTER}/{name}");
        if bone.node >= nodes {
            return Err(invalid(format!("{at}/node: node {} does not exist", bone.node)));
        }
        match Role::from_name(name) {
            Some(role) => named.push((role, bone.node)),
            None => {
                let detail = format!("humanoid bone '{name}' is not a VRM 1.0 humanoid bone; its node plays no role");
                warnings.push(Warning::new(NOT_IMPORTED, at, detail));
            }
        }
    }
    // Of two bones on one node, the first in the roles' order keeps it.
    named.sort_by_key(|(role, _)| role.index());
    let mut bones: Vec<(Role, usize)> = Vec::with_capacity(named.len());
    for (role, node) in named {
        if let Some((other, _)) = bones.iter().find(|(_, n)| *n == node) {
            let detail =
                format!("humanoid bone '{}' names the node of '{}'; a joint plays one role", role.name(), other.name());
            warnings.push(Warning::new(NOT_IMPORTED, format!("{POINTER}/{}", role.name()), detail));
            continue;
        }
        bones.push((role, node));
    }
    Ok(bones)
}

/// The roles of a character whose skeleton is `skeleton_nodes` (the nodes of
/// its joints): role name → joint name, for the character document's
/// `roles`. A bone on a node outside it is left out with a warning.
pub fn character_roles(
    bones: &[(Role, usize)],
    skeleton_nodes: &[usize],
    names: &[String],
    warnings: &mut Vec<Warning>,
) -> BTreeMap<String, Option<String>> {
    let mut roles = BTreeMap::new();
    for &(role, node) in bones {
        if skeleton_nodes.contains(&node) {
            roles.insert(role.name().to_owned(), Some(names[node].clone()));
        } else {
            let detail = format!("humanoid bone '{}' is node {node}, outside the skin's skeleton", role.name());
            warnings.push(Warning::new(NOT_IMPORTED, format!("{POINTER}/{}", role.name()), detail));
        }
    }
    roles
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bones(json: &str) -> (Vec<(Role, usize)>, Vec<Warning>) {
        let mut warnings = Vec::new();
        (human_bones(json.as_bytes(), 4, &mut warnings).unwrap(), warnings)
    }

    #[test]
    fn each_bone_is_its_role_and_strangers_are_warned_about() {
        let json = r#"{"extensions":{"VRMC_vrm":{"humanoid":{"humanBones":{
            "spine":{"node":1},"hips":{"node":0},"tail":{"node":2},"chest":{"node":1}}}}}}"#;
        let (got, warnings) = bones(json);
        assert_eq!(got, vec![(Role::Hips, 0), (Role::Spine, 1)]);
        let pointers: Vec<&str> = warnings.iter().map(|w| w.pointer.as_str()).collect();
        // Spine comes before chest among the roles: it keeps node 1.
        assert_eq!(pointers, [format!("{POINTER}/tail"), format!("{POINTER}/chest")]);
    }

    #[test]
    fn no_extension_is_no_roles_and_a_missing_node_is_refused() {
        assert_eq!(bones(r#"{"asset":{"version":"2.0"}}"#).0, Vec::new());
        let json = r#"{"extensions":{"VRMC_vrm":{"humanoid":{"humanBones":{"hips":{"node":9}}}}}}"#;
        let err = human_bones(json.as_bytes(), 4, &mut Vec::new()).unwrap_err();
        assert!(err.to_string().contains("hips/node: node 9"), "{err}");
    }
}
