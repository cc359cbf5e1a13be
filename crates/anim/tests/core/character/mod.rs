//! Characters (the `character` module): roles from names and structure on
//! real and synthetic rigs, and retargeting against an `f64` reference
//! written from the retargeting definition (`reference`), with its
//! properties.
//!
//! The real skeletons are read here, not through `inbetween-formats`: BVH
//! hierarchies by a reader of a few lines (joint names, parents, offsets),
//! the glTF rigs as tables of their nodes (`rigs`, copied from the files).

mod feet;
pub mod motion;
pub mod names;
mod properties;
pub mod reference;
mod rigs;
mod structure;

use std::path::PathBuf;

use anim::character::{Role, RoleMap};
use anim::{JointSpec, Skeleton, SkeletonSpec, Transform};
use glam::{Quat, Vec3};

/// A joint as a table row: name, parent, rest translation, rest rotation `[x, y, z, w]`.
pub type Row<N> = (N, Option<N>, [f64; 3], [f64; 4]);

/// A row of a constant table.
pub type Joint = Row<&'static str>;

/// A skeleton from table rows.
pub fn skeleton<N: AsRef<str>>(rows: &[Row<N>]) -> Skeleton {
    let joints = rows
        .iter()
        .map(|(name, parent, t, q)| JointSpec {
            name: name.as_ref().into(),
            parent: parent.as_ref().map(|p| p.as_ref().into()),
            rest: Transform {
                translation: Vec3::new(t[0] as f32, t[1] as f32, t[2] as f32),
                rotation: Quat::from_xyzw(q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32),
                ..Transform::IDENTITY
            },
            inverse_bind: None,
        })
        .collect();
    Skeleton::build(&SkeletonSpec { joints }).unwrap()
}

/// A skeleton of named joints with parents and offsets, identity rotations.
pub fn skeleton_of(joints: &[(String, Option<String>, Vec3)]) -> Skeleton {
    let joints = joints
        .iter()
        .map(|(name, parent, t)| JointSpec {
            name: name.clone(),
            parent: parent.clone(),
            rest: Transform { translation: *t, ..Transform::IDENTITY },
            inverse_bind: None,
        })
        .collect();
    Skeleton::build(&SkeletonSpec { joints }).unwrap()
}

/// A real third-party file (`INBETWEEN_TESTDATA`, default `shared/testdata`
/// beside the clone, as the other suites).
pub fn testdata(rel: &str) -> PathBuf {
    let root = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    let dir =
        std::env::var_os("INBETWEEN_TESTDATA").map(PathBuf::from).unwrap_or_else(|| root.join("../shared/testdata"));
    dir.join(rel)
}

/// The joints of a BVH `HIERARCHY`: names, parents and offsets (rest
/// rotations are zero in BVH). End sites are not joints.
pub fn bvh_skeleton(rel: &str) -> Skeleton {
    let path = testdata(rel);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (third-party test files: set INBETWEEN_TESTDATA)", path.display()));
    let mut joints: Vec<(String, Option<String>, Vec3)> = Vec::new();
    // The open blocks: a joint's index, or None for an end site.
    let mut open: Vec<Option<usize>> = Vec::new();
    let mut words = text.split_whitespace();
    while let Some(word) = words.next() {
        match word {
            "ROOT" | "JOINT" => {
                let parent = open.iter().rev().flatten().next().map(|&p| joints[p].0.clone());
                joints.push((words.next().unwrap().to_owned(), parent, Vec3::ZERO));
                open.push(Some(joints.len() - 1));
                assert_eq!(words.next(), Some("{"));
            }
            "End" => {
                words.next();
                open.push(None);
                assert_eq!(words.next(), Some("{"));
            }
            "OFFSET" => {
                let mut v = [0.0; 3];
                for c in &mut v {
                    *c = words.next().unwrap().parse().unwrap();
                }
                if let Some(&Some(j)) = open.last() {
                    joints[j].2 = Vec3::from(v);
                }
            }
            "}" => {
                open.pop();
            }
            "MOTION" => break,
            _ => {}
        }
    }
    skeleton_of(&joints)
}

/// The role map of `skeleton` with nothing given.
pub fn inferred(skeleton: &Skeleton) -> RoleMap {
    RoleMap::infer(skeleton, &[]).unwrap()
}

/// `role → joint name` pairs of a map, for readable assertions.
pub fn named(skeleton: &Skeleton, map: &RoleMap, roles: &[Role]) -> Vec<(Role, Option<String>)> {
    roles.iter().map(|&r| (r, map.joint(r).map(|j| skeleton.names()[j].clone()))).collect()
}

/// Expected `role → joint name` pairs.
pub fn expect(pairs: &[(Role, &str)]) -> Vec<(Role, Option<String>)> {
    pairs.iter().map(|&(r, n)| (r, Some(n.to_owned()))).collect()
}

/// The roles of [`expect`]ed pairs.
pub fn roles_of(pairs: &[(Role, &str)]) -> Vec<Role> {
    pairs.iter().map(|p| p.0).collect()
}
