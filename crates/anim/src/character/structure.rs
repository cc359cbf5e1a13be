//! Roles from the shape of the rest pose, for rigs whose names say nothing
//! (CesiumMan's joints are `node2`, `node11`, …).
//!
//! In the rest pose's model space (glTF's frame: `+Y` up, the character's
//! left at `+X`):
//! - the **hips** are the first joint (parents come first, so the root-most)
//!   with three or more children whose subtrees hold two joints or more;
//! - the **legs** are the two of those subtrees reaching lowest, below the
//!   hips, on opposite sides; along each one's main chain the **foot** is the
//!   first joint within a quarter of the leg's height of its lowest point,
//!   the two joints above it the lower and upper leg, the one after it the
//!   toes;
//! - the **spine** is the subtree reaching highest; its chain runs to the
//!   first joint with more than one child (the chest, where the arms
//!   branch): one joint is the spine, two are spine and chest, three add the
//!   upper chest, more leave the middle ones unmapped;
//! - of the branch's children, the one nearest the middle is the **neck**
//!   (its chain's last joint the head, or the head alone if it has one
//!   joint), and the lateral two the **arms**, each followed to its first
//!   fork or leaf (the hand), the three joints above it the lower and upper
//!   arm and the shoulder.
//!
//! Each step needs the one before it; where the shape is not what a step
//! expects, it and the steps after it give nothing.

use glam::Vec3A;

use super::roles::{Role, Side};
use crate::{Pose, Skeleton};

/// The roles the rest pose's shape gives, per role.
pub(crate) fn roles_from_structure(skeleton: &Skeleton) -> [Option<usize>; Role::COUNT] {
    let mut model = Pose::default();
    skeleton.to_model(skeleton.rest(), &mut model);
    let shape = Shape::new(skeleton, &model.translations);
    let mut roles = [None; Role::COUNT];
    shape.fill(&mut roles);
    roles
}

struct Shape<'a> {
    children: Vec<Vec<usize>>,
    positions: &'a [Vec3A],
}

impl Shape<'_> {
    fn new<'a>(skeleton: &Skeleton, positions: &'a [Vec3A]) -> Shape<'a> {
        let mut children = vec![Vec::new(); skeleton.len()];
        for j in 0..skeleton.len() {
            if let Some(p) = skeleton.parent(j) {
                children[p].push(j);
            }
        }
        Shape { children, positions }
    }

    fn fill(&self, roles: &mut [Option<usize>; Role::COUNT]) {
        let Some(hips) = self.hips() else { return };
        roles[Role::Hips.index()] = Some(hips);
        let mut limbs: Vec<usize> = self.children[hips].iter().copied().filter(|&c| self.size(c) >= 2).collect();
        limbs.sort_by(|&a, &b| self.lowest(a).total_cmp(&self.lowest(b)));
        let hips_y = self.positions[hips].y;
        if let [a, b, ..] = limbs[..]
            && self.lowest(b) < hips_y
            && let Some((left, right)) = self.sides(a, b, self.positions[hips].x)
        {
            self.leg(left, Side::Left, roles);
            self.leg(right, Side::Right, roles);
            limbs.drain(..2);
        }
        let top = limbs.iter().copied().max_by(|&a, &b| self.highest(a).total_cmp(&self.highest(b)));
        if let Some(spine) = top.filter(|&s| self.highest(s) > hips_y) {
            self.torso(spine, roles);
        }
    }

    /// The root-most joint with three children of two joints or more.
    fn hips(&self) -> Option<usize> {
        (0..self.children.len()).find(|&j| self.children[j].iter().filter(|&&c| self.size(c) >= 2).count() >= 3)
    }

    /// `(left, right)` of two subtrees on opposite sides of `x = x0`.
    fn sides(&self, a: usize, b: usize, x0: f32) -> Option<(usize, usize)> {
        let (xa, xb) = (self.mean_x(a) - x0, self.mean_x(b) - x0);
        match (xa > 0.0, xb > 0.0) {
            (true, false) if xb < 0.0 => Some((a, b)),
            (false, true) if xa < 0.0 => Some((b, a)),
            _ => None,
        }
    }

    fn leg(&self, start: usize, side: Side, roles: &mut [Option<usize>; Role::COUNT]) {
        let chain = self.chain(start, false);
        let ys: Vec<f32> = chain.iter().map(|&j| self.positions[j].y).collect();
        let low = ys.iter().copied().fold(f32::INFINITY, f32::min);
        let high = ys.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let Some(foot) = ys.iter().position(|&y| y <= low + 0.25 * (high - low)) else { return };
        if foot < 2 {
            return;
        }
        let mut put = |role: Role, j: usize| roles[role.on(side).index()] = Some(chain[j]);
        put(Role::LeftUpperLeg, foot - 2);
        put(Role::LeftLowerLeg, foot - 1);
        put(Role::LeftFoot, foot);
        if foot + 1 < chain.len() {
            put(Role::LeftToes, foot + 1);
        }
    }

    fn torso(&self, start: usize, roles: &mut [Option<usize>; Role::COUNT]) {
        let spine = self.chain(start, true);
        let Some(&branch) = spine.last().filter(|&&b| self.children[b].len() >= 2) else { return };
        let slots: &[Role] = match spine.len() {
            1 => &[Role::Spine],
            2 => &[Role::Spine, Role::Chest],
            _ => &[Role::Spine, Role::Chest, Role::UpperChest],
        };
        for (k, role) in slots.iter().enumerate() {
            let j = if k + 1 == slots.len() { spine.len() - 1 } else { k };
            roles[role.index()] = Some(spine[j]);
        }
        let x0 = self.positions[branch].x;
        let mut kids = self.children[branch].clone();
        kids.sort_by(|&a, &b| (self.mean_x(a) - x0).abs().total_cmp(&(self.mean_x(b) - x0).abs()));
        let neck = self.chain(kids[0], false);
        if let [head] = neck[..] {
            roles[Role::Head.index()] = Some(head);
        } else if let (Some(&n), Some(&h)) = (neck.first(), neck.last()) {
            roles[Role::Neck.index()] = Some(n);
            roles[Role::Head.index()] = Some(h);
        }
        if let [_, a, b, ..] = kids[..]
            && let Some((left, right)) = self.sides(a, b, x0)
        {
            self.arm(left, Side::Left, roles);
            self.arm(right, Side::Right, roles);
        }
    }

    fn arm(&self, start: usize, side: Side, roles: &mut [Option<usize>; Role::COUNT]) {
        let chain = self.chain(start, true);
        let slots = [Role::LeftShoulder, Role::LeftUpperArm, Role::LeftLowerArm, Role::LeftHand];
        let used = slots.len().min(chain.len());
        for (role, &joint) in slots[slots.len() - used..].iter().zip(&chain[chain.len() - used..]) {
            roles[role.on(side).index()] = Some(joint);
        }
    }

    /// From `start` down: to the first fork (`stop_at_fork`) or a leaf,
    /// else down the largest child at each fork.
    fn chain(&self, start: usize, stop_at_fork: bool) -> Vec<usize> {
        let mut chain = vec![start];
        let mut at = start;
        loop {
            let kids = &self.children[at];
            if kids.is_empty() || (stop_at_fork && kids.len() > 1) {
                return chain;
            }
            at = kids.iter().copied().max_by_key(|&c| self.size(c)).unwrap_or(at);
            chain.push(at);
        }
    }

    /// Joints in the subtree of `j`, itself included.
    fn size(&self, j: usize) -> usize {
        1 + self.children[j].iter().map(|&c| self.size(c)).sum::<usize>()
    }

    fn fold(&self, j: usize, f: &impl Fn(f32, f32) -> f32, init: f32) -> f32 {
        self.children[j].iter().fold(f(init, self.positions[j].y), |acc, &c| self.fold(c, f, acc))
    }

    fn lowest(&self, j: usize) -> f32 {
        self.fold(j, &f32::min, f32::INFINITY)
    }

    fn highest(&self, j: usize) -> f32 {
        self.fold(j, &f32::max, f32::NEG_INFINITY)
    }

    /// The mean `x` of the subtree of `j`.
    fn mean_x(&self, j: usize) -> f32 {
        let mut stack = vec![j];
        let (mut sum, mut n) = (0.0, 0.0);
        while let Some(k) = stack.pop() {
            sum += self.positions[k].x;
            n += 1.0;
            stack.extend(&self.children[k]);
        }
        sum / n
    }
}
