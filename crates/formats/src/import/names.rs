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
