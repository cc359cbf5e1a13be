//! Joints, their hierarchy and rest pose; local → model space
//! (docs/clip-format.md, “Skeleton and spaces”).
//!
//! Joints are stored parents-first (docs/clip-format.md, “Data model”,
//! requires each parent to be an earlier joint), so local-to-model is one linear pass with no recursion
//! and no stack, as in ozz-animation.

use glam::{Mat4, Quat, Vec3A};

use super::heap::vec_bytes;

/// Joint transforms in structure-of-arrays form, caller-owned so sampling
/// never allocates. Index `j` of each array is joint `j` of the skeleton.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Pose {
    pub translations: Vec<Vec3A>,
    pub rotations: Vec<Quat>,
    pub scales: Vec<Vec3A>,
    /// The clip's parameters (docs/clip-format.md, “Parameters”), three components per entry: a
    /// parameter of width `W` takes `⌈W/3⌉` entries, its last one padded
    /// with zeros (see `ParameterLayout`), so they are sampled and blended
    /// with the translations' code. Empty for a clip without parameters.
    pub parameters: Vec<Vec3A>,
}

impl Pose {
    /// `n` identity transforms.
    pub fn identity(n: usize) -> Self {
        Pose {
            translations: vec![Vec3A::ZERO; n],
            rotations: vec![Quat::IDENTITY; n],
            scales: vec![Vec3A::ONE; n],
            parameters: Vec::new(),
        }
    }

    /// The number of joints.
    pub fn len(&self) -> usize {
        self.translations.len()
    }

    /// Whether there are no joints.
    pub fn is_empty(&self) -> bool {
        self.translations.is_empty()
    }

    /// Bytes of the three arrays' allocations.
    pub fn heap_bytes(&self) -> usize {
        vec_bytes(&self.translations)
            + vec_bytes(&self.rotations)
            + vec_bytes(&self.scales)
            + vec_bytes(&self.parameters)
    }

    /// Copies `other` into `self`, reusing `self`'s storage.
    #[inline]
    pub fn copy_from(&mut self, other: &Pose) {
        self.translations.clone_from(&other.translations);
        self.rotations.clone_from(&other.rotations);
        self.scales.clone_from(&other.scales);
        self.parameters.clone_from(&other.parameters);
    }
}

/// The validated hierarchy: names, parents (always earlier joints) and the
/// rest pose, plus inverse bind matrices when the clip came with a skin.
#[derive(Debug, Clone, PartialEq)]
pub struct Skeleton {
    names: Vec<String>,
    /// `NO_PARENT` for roots, else an index smaller than the joint's own.
    parents: Vec<u32>,
    rest: Pose,
    inverse_binds: Option<Vec<Mat4>>,
}

pub(crate) const NO_PARENT: u32 = u32::MAX;

impl Skeleton {
    /// Joints must already be checked (`Clip::build` does): parents earlier.
    pub(crate) fn new(names: Vec<String>, parents: Vec<u32>, rest: Pose, inverse_binds: Option<Vec<Mat4>>) -> Self {
        debug_assert!(parents.iter().enumerate().all(|(j, &p)| p == NO_PARENT || (p as usize) < j));
        Skeleton { names, parents, rest, inverse_binds }
    }

    /// The number of joints.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Bytes of its names, parents, rest pose and inverse binds.
    pub fn heap_bytes(&self) -> usize {
        let names = self.names.iter().map(String::capacity).sum::<usize>();
        vec_bytes(&self.names)
            + names
            + vec_bytes(&self.parents)
            + self.rest.heap_bytes()
            + self.inverse_binds.as_ref().map_or(0, vec_bytes)
    }

    /// Whether there are no joints.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Joint names, in joint order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The index of the joint called `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Whether `other` has the same joints, by name and parent, in the same
    /// order: poses of one fit the other.
    pub fn same_joints(&self, other: &Skeleton) -> bool {
        self.len() == other.len()
            && self.names() == other.names()
            && (0..self.len()).all(|j| self.parent(j) == other.parent(j))
    }

    /// The parent of joint `j`, if any.
    ///
    /// # Panics
    /// If `j` is not a joint of this skeleton.
    pub fn parent(&self, j: usize) -> Option<usize> {
        let p = self.parents[j];
        (p != NO_PARENT).then_some(p as usize)
    }

    /// The rest pose (local space).
    pub fn rest(&self) -> &Pose {
        &self.rest
    }

    /// Joint `j`'s inverse bind matrix, when the clip has a skin.
    ///
    /// # Panics
    /// If the clip has a skin and `j` is not a joint of this skeleton.
    pub fn inverse_bind(&self, j: usize) -> Option<&Mat4> {
        self.inverse_binds.as_ref().map(|b| &b[j])
    }

    /// Whether the clip has a skin (inverse bind matrices).
    pub fn has_inverse_binds(&self) -> bool {
        self.inverse_binds.is_some()
    }

    /// Composes local transforms down the hierarchy (docs/clip-format.md, “Skeleton and spaces”):
    /// `t_m = t_p + q_p·(s_p ⊙ t_l)`, `q_m = q_p·q_l`, `s_m = s_p ⊙ s_l`.
    /// Exact for uniform scale; use [`Skeleton::model_matrices`] otherwise.
    ///
    /// # Panics
    /// If `local` has fewer joints than the skeleton.
    pub fn to_model(&self, local: &Pose, model: &mut Pose) {
        model.copy_from(local);
        let (t, q, s) = (&mut model.translations, &mut model.rotations, &mut model.scales);
        for (j, &p) in self.parents.iter().enumerate() {
            if p == NO_PARENT {
                continue;
            }
            let p = p as usize;
            let (tp, qp, sp) = (t[p], q[p], s[p]);
            t[j] = tp + qp * (sp * t[j]);
            q[j] = qp * q[j];
            s[j] = sp * s[j];
        }
    }

    /// Column-major model matrices `M_j = M_parent · T·R·S`.
    ///
    /// # Panics
    /// If `local` has fewer joints than the skeleton.
    pub fn model_matrices(&self, local: &Pose, out: &mut Vec<Mat4>) {
        out.clear();
        for (j, &p) in self.parents.iter().enumerate() {
            let m = Mat4::from_scale_rotation_translation(
                local.scales[j].into(),
                local.rotations[j],
                local.translations[j].into(),
            );
            out.push(if p == NO_PARENT { m } else { out[p as usize] * m });
        }
    }

    /// Skinning matrices `M_j · invBind_j`; `false` (and `out` untouched
    /// beyond the model matrices) when the clip has no inverse binds.
    ///
    /// # Panics
    /// If `local` has fewer joints than the skeleton.
    pub fn skinning_matrices(&self, local: &Pose, out: &mut Vec<Mat4>) -> bool {
        let Some(binds) = &self.inverse_binds else { return false };
        self.model_matrices(local, out);
        for (m, b) in out.iter_mut().zip(binds) {
            *m *= *b;
        }
        true
    }
}
