//! Ranges of layers whose poses are not their clip's (docs/compact-frames.md,
//! “What a compact stream plays”): a layer retargeted onto a character, and
//! a blend layer whose root root motion `extract` keeps in place. Both are
//! derived from the clip's own ranges by following what the retargeter
//! (`character::retarget`) and the extraction (`motion::root`) compute.

use glam::{Mat3A, Quat, Vec3A};

use super::{JointRange, ROUNDING_MARGIN, Ranges, Unbounded};
use crate::Pose;
use crate::character::{FootPlanter, NO_JOINT, Retargeter, Translation};
use crate::motion::{LayerExtract, UpAxis};

/// A box of vectors, per axis `[min, max]`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Bounds {
    min: Vec3A,
    max: Vec3A,
}

impl Bounds {
    fn point(v: Vec3A) -> Bounds {
        Bounds { min: v, max: v }
    }

    /// The largest magnitude of any vector in the box, per axis.
    fn reach(self) -> Vec3A {
        self.min.abs().max(self.max.abs())
    }

    fn add(self, other: Bounds) -> Bounds {
        Bounds { min: self.min + other.min, max: self.max + other.max }
    }

    /// `a ⊙ b` for `a` in `self`, `b` in `other`: per axis, the hull of the
    /// four corner products.
    fn times(self, other: Bounds) -> Bounds {
        let corners = [self.min * other.min, self.min * other.max, self.max * other.min, self.max * other.max];
        let min = corners.iter().fold(Vec3A::INFINITY, |m, c| m.min(*c));
        let max = corners.iter().fold(Vec3A::NEG_INFINITY, |m, c| m.max(*c));
        Bounds { min, max }
    }

    /// `q·v` for `v` in the box: a constant rotation is linear, so the box
    /// of the image is its centre turned, its half extents through `|R|`;
    /// any rotation (`None`) keeps `|v|`, so the ball of the farthest corner.
    fn turned(self, q: Option<Quat>) -> Bounds {
        match q {
            Some(q) => {
                let (centre, half) = ((self.min + self.max) * 0.5, (self.max - self.min) * 0.5);
                let m = Mat3A::from_quat(q);
                let abs = Mat3A::from_cols(m.x_axis.abs(), m.y_axis.abs(), m.z_axis.abs());
                let (c, h) = (q * centre, abs * half);
                Bounds { min: c - h, max: c + h }
            }
            None => {
                let r = Vec3A::splat(self.reach().length());
                Bounds { min: -r, max: r }
            }
        }
    }
}

/// A joint's model transform as boxes: translation, rotation (`None`: any),
/// scale.
#[derive(Debug, Clone, Copy)]
struct Model {
    t: Bounds,
    q: Option<Quat>,
    s: Bounds,
}

impl Model {
    const IDENTITY: Model = Model {
        t: Bounds { min: Vec3A::ZERO, max: Vec3A::ZERO },
        q: Some(Quat::IDENTITY),
        s: Bounds { min: Vec3A::ONE, max: Vec3A::ONE },
    };

    /// The child's model transform, `t = t_p + q_p·(s_p ⊙ t)`, `q = q_p·q`,
    /// `s = s_p ⊙ s` (docs/clip-format.md, “Skeleton and spaces”).
    fn child(&self, local: &JointRange) -> Model {
        let t = self.s.times(Bounds { min: local.t_min, max: local.t_max }).turned(self.q);
        let q = match (self.q, local.constant_rotation()) {
            (Some(p), Some(q)) => Some(p * q),
            _ => None,
        };
        Model { t: self.t.add(t), q, s: self.s.times(Bounds { min: local.s_min, max: local.s_max }) }
    }
}

/// The model transform of `joint` of a skeleton of `parents` whose local
/// poses lie in `ranges`.
fn model_of(parents: &[u32], ranges: &Ranges, joint: usize) -> Model {
    let mut chain = vec![joint];
    while let Some(&j) = chain.last() {
        match parents[j] {
            NO_JOINT => break,
            p => chain.push(p as usize),
        }
    }
    chain.iter().rev().fold(Model::IDENTITY, |m, &j| m.child(&ranges.joints[j]))
}

impl Ranges {
    /// Ranges holding every pose `retargeter` (with its foot `planter`)
    /// makes of source poses within `source` (docs/characters.md): each
    /// target joint keeps its reference scale, an unmapped one its reference
    /// rotation, and all but the hips their reference translation (with
    /// `translation: all`, a mapped one's moves by `k` times its source's
    /// change); a mapped joint's rotation, and any a planted foot turns, is
    /// any. The hips' model position `p⁰_d + k·(p_s − p⁰_s)` is a box through
    /// an affine map, `p_s` bounded through the source's chain of ranges.
    ///
    /// # Errors
    /// A target hips below a mapped joint, whose model transform the box
    /// arithmetic does not follow.
    pub(crate) fn retargeted(
        retargeter: &Retargeter,
        planter: Option<&FootPlanter>,
        source: &Ranges,
    ) -> Result<Ranges, Unbounded> {
        let reference: &Pose = &retargeter.reference;
        let mut ranges = Ranges::new(retargeter.target_parents.len());
        ranges.observe(reference);
        for (j, r) in ranges.joints.iter_mut().enumerate() {
            let s = retargeter.source_of[j];
            if s == NO_JOINT {
                continue;
            }
            r.free_rotation();
            if j != retargeter.hips.target && retargeter.translation == Translation::All {
                let from = &source.joints[s as usize];
                let (k, t0, st) = (retargeter.hips.k, reference.translations[j], retargeter.source_translations[j]);
                (r.t_min, r.t_max) = (t0 + k * (from.t_min - st), t0 + k * (from.t_max - st));
                r.magnitude = r.magnitude.max(from.magnitude * k).max(r.t_min.abs().max(r.t_max.abs()).max_element());
            }
        }
        planter.into_iter().flat_map(FootPlanter::legs).flatten().for_each(|j| ranges.free_rotation(j));
        let hips = hips_translation(retargeter, source)?;
        let r = &mut ranges.joints[retargeter.hips.target];
        (r.t_min, r.t_max) = (hips.t.min, hips.t.max);
        r.magnitude = r.magnitude.max(hips.magnitude);
        Ok(ranges)
    }

    /// Widens joint `extract.joint` to hold what root motion `extract` makes
    /// of it (docs/motion.md, “Root motion”): the local transform `(t, q)` is
    /// turned by `yaw(start) − yaw(q)` about up and moved so its ground
    /// position is `M(start)`'s, which leaves `t`'s height and puts it at
    /// `start`'s ground position; the rotation is constant while the clip's
    /// is (it is turned by zero), else any. Every axis is widened by the
    /// rounding margin (the turn is computed in f64 and rounded once).
    pub(crate) fn extracted(&mut self, extract: &LayerExtract) {
        let r = &mut self.joints[extract.joint];
        let up = match extract.up {
            UpAxis::Y => 1,
            UpAxis::Z => 2,
        };
        let ground = extract.start.translation.as_vec3a();
        for a in (0..3).filter(|&a| a != up) {
            (r.t_min[a], r.t_max[a]) = (ground[a], ground[a]);
        }
        r.magnitude = r.magnitude.max(ground.abs().max_element());
        let margin = ROUNDING_MARGIN * r.magnitude.max(r.t_min.abs().max(r.t_max.abs()).max_element());
        (r.t_min, r.t_max) = (r.t_min - Vec3A::splat(margin), r.t_max + Vec3A::splat(margin));
        if r.constant_rotation().is_none() {
            r.free_rotation();
        }
    }
}

/// The target hips' local translation, and the largest magnitude that went
/// into it (what the rounding margin scales with).
struct HipsRange {
    t: Bounds,
    magnitude: f32,
}

/// Whether [`Ranges::retargeted`] can bound `retargeter`'s poses: no joint
/// above the character's hips is mapped (its model transform is then the
/// reference's).
///
/// # Errors
/// The first joint above the hips that is mapped.
pub(crate) fn retarget_boundable(retargeter: &Retargeter) -> Result<(), Unbounded> {
    let parents = &retargeter.target_parents;
    let mut above = parents[retargeter.hips.target];
    while above != NO_JOINT {
        if retargeter.source_of[above as usize] != NO_JOINT {
            return Err(Unbounded("a character whose hips are below a joint of another role"));
        }
        above = parents[above as usize];
    }
    Ok(())
}

/// The hips' local translation as the retargeter computes it:
/// `s_p⁻¹ ⊙ q_p⁻¹·(H − t_p)` with the parent's model transform (constant: the
/// reference's, when no joint above the hips is mapped) and `H` its model
/// position (module docs).
fn hips_translation(retargeter: &Retargeter, source: &Ranges) -> Result<HipsRange, Unbounded> {
    retarget_boundable(retargeter)?;
    let h = &retargeter.hips;
    let parents = &retargeter.target_parents;
    let (position, magnitude) = match retargeter.translation {
        Translation::None => (Bounds::point(h.target_reference), h.target_reference.abs().max_element()),
        Translation::Hips | Translation::All => {
            let p = model_of(&retargeter.source_parents, source, h.source).t;
            let min = h.target_reference + h.k * (p.min - h.source_reference);
            let max = h.target_reference + h.k * (p.max - h.source_reference);
            let reach = p.reach().max(h.source_reference.abs()).max_element() * h.k;
            (Bounds { min, max }, reach.max(h.target_reference.abs().max_element()))
        }
    };
    let Some(parent) = (parents[h.target] != NO_JOINT).then(|| parents[h.target] as usize) else {
        return Ok(HipsRange { t: position, magnitude });
    };
    let mut reference = Ranges::new(parents.len());
    reference.observe(&retargeter.reference);
    let m = model_of(parents, &reference, parent);
    let (pt, pq, ps) = (m.t.min, m.q.unwrap_or(Quat::IDENTITY), m.s.min);
    let inverse = Vec3A::select(ps.cmpeq(Vec3A::ZERO), Vec3A::ZERO, ps.recip());
    let relative = Bounds { min: position.min - pt, max: position.max - pt };
    let t = relative.turned(Some(pq.conjugate())).times(Bounds::point(inverse));
    let magnitude = magnitude.max(pt.abs().max_element()) * inverse.abs().max_element().max(1.0);
    Ok(HipsRange { t, magnitude: magnitude.max(t.reach().max_element()) })
}
