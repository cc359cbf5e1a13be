//! Clip and joint names as the importers give them: within the core's
//! limits, and unique within one file.

use anim::MAX_NAME_CHARS;

/// A clip name within the core's limit (longer names are cut, by character).
pub fn clip_name(name: &str) -> String {
    let name = if name.trim().is_empty() { "clip" } else { name };
    name.chars().take(MAX_NAME_CHARS).collect()
}

/// Makes joint names unique within one file, in order: the first holder of
/// a name keeps it; a later one becomes `name#<i>` (`i` its index: the glTF
/// node or BVH joint, which tells the user which one it was), or if that is
/// taken too, `name#<n>` for the smallest free `n` from 2. Every name in the
/// file is reserved up front, so a suffix never takes a name a later node
/// has in the file. A per-name counter keeps crafted collisions linear.
pub fn unique_names(names: Vec<String>) -> Vec<String> {
    use std::collections::{HashMap, HashSet};
    let mut taken: HashSet<String> = names.iter().cloned().collect();
    let mut kept: HashSet<String> = HashSet::with_capacity(names.len());
    let mut next: HashMap<String, usize> = HashMap::new();
    names
        .into_iter()
        .enumerate()
        .map(|(i, name)| {
            if kept.insert(name.clone()) {
                return name;
            }
            let candidate = format!("{name}#{i}");
            if taken.insert(candidate.clone()) {
                return candidate;
            }
            let n = next.entry(name.clone()).or_insert(2);
            loop {
                let candidate = format!("{name}#{n}");
                *n += 1;
                if taken.insert(candidate.clone()) {
                    return candidate;
                }
            }
        })
        .collect()
}

/// Whether an animation name says nothing of the motion: what exporters
/// write when the author named nothing (`mixamo.com`, `Take 001`,
/// `Armature|…`, `ArmatureAction`, `Action`, `Action.001`, `animation_0`,
/// `Animation`, `Scene`, `default`). Such a name is replaced, with a
/// `generic_animation_name` warning.
pub fn is_generic_animation_name(name: &str) -> bool {
    let lower = name.trim().to_ascii_lowercase();
    // Blender's `.001` suffixes and trailing numbers add nothing.
    let stem =
        lower.split('.').next().unwrap_or("").trim_end_matches(|c: char| c.is_ascii_digit() || c == '_' || c == ' ');
    lower == "mixamo.com"
        || lower.starts_with("armature|")
        || lower.starts_with("armatureaction")
        || matches!(stem, "take" | "action" | "animation" | "anim" | "scene" | "default" | "clip" | "")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exporters_default_names_are_generic_and_authored_ones_are_not() {
        for generic in [
            "mixamo.com",
            "Take 001",
            "Armature|mixamo.com|Layer0",
            "Armature|Walk",
            "ArmatureAction",
            "Action",
            "Action.001",
            "animation_0",
            "Animation",
            "Scene",
            "default",
            "take",
        ] {
            assert!(is_generic_animation_name(generic), "{generic}");
        }
        for named in ["Walk", "Run", "Survey", "Take off", "Actions of a hero", "fox/walk", "wave"] {
            assert!(!is_generic_animation_name(named), "{named}");
        }
    }
}
