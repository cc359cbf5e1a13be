//! Roles from the shape of the rest pose, for rigs whose names say nothing
//! (CesiumMan's joints are `node2`, `node11`, …).
//!
//! In the rest pose's model space (`+Y` up):
//! - the **hips** are the first joint (parents come first, so the root-most)
//!   with three or more children whose subtrees hold two joints or more;
//! - the **legs** are the two of those subtrees reaching lowest, below the
//!   hips, on opposite sides of them; each is its main chain (the largest
//!   child at each fork) past the joints at the hips: upper leg, lower leg,
//!   foot and toes. Their sides come from the character's left, `up ×
//!   forward` with forward the way the toes point from the feet (glTF's
//!   `+Z` without toes, so the left is `+X`);
//! - the **spine** is the subtree reaching highest; its chain runs to the
//!   first joint with more than one child (the chest, where the arms
//!   branch): one joint is the spine, two are spine and chest, three add the
//!   upper chest, more leave the ones between chest and upper chest unmapped;
//! - of the branch's children, the one nearest the middle is the **neck**
//!   (its chain's last joint the head, or the head alone if it has one
//!   joint), and two lateral ones on opposite sides the **arms**, each
//!   followed to its first fork or leaf (the hand), the three joints above
//!   it the lower and upper arm and the shoulder.
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
        let hips_at = self.positions[hips];
        let mut left = Vec3A::X;
        if let [a, b, ..] = limbs[..]
            && self.lowest(b) < hips_at.y
            && let (Some(leg_a), Some(leg_b)) = (self.leg(a, hips_at), self.leg(b, hips_at))
        {
            left = self.left(&leg_a, &leg_b);
            if let Some(a_is_left) = self.opposite(a, b, hips_at, left) {
                let (l, r) = if a_is_left { (leg_a, leg_b) } else { (leg_b, leg_a) };
                put(roles, &LEG, &l, Side::Left);
                put(roles, &LEG, &r, Side::Right);
                limbs.drain(..2);
            }
        }
        let top = limbs.iter().copied().max_by(|&a, &b| self.highest(a).total_cmp(&self.highest(b)));
        if let Some(spine) = top.filter(|&s| self.highest(s) > hips_at.y) {
            self.torso(spine, left, roles);
        }
    }

    /// The root-most joint with three children of two joints or more.
    fn hips(&self) -> Option<usize> {
        (0..self.children.len()).find(|&j| self.children[j].iter().filter(|&&c| self.size(c) >= 2).count() >= 3)
    }

    /// The character's left: up × forward, forward being the way the toes
    /// point from the feet (else glTF's `+Z`).
    fn left(&self, a: &[usize], b: &[usize]) -> Vec3A {
        let toes = |leg: &[usize]| match leg {
            [_, _, foot, toes] => self.positions[*toes] - self.positions[*foot],
            _ => Vec3A::ZERO,
        };
        let forward = toes(a) + toes(b);
        let forward = Vec3A::new(forward.x, 0.0, forward.z).try_normalize().unwrap_or(Vec3A::Z);
        Vec3A::Y.cross(forward)
    }

    /// Whether subtree `a` is on the left of `b`, when they lie on opposite
    /// sides of `centre`.
    fn opposite(&self, a: usize, b: usize, centre: Vec3A, left: Vec3A) -> Option<bool> {
        let (sa, sb) = ((self.mean(a) - centre).dot(left), (self.mean(b) - centre).dot(left));
        match (sa > 0.0, sb > 0.0) {
            (true, false) if sb < 0.0 => Some(true),
            (false, true) if sa < 0.0 => Some(false),
            _ => None,
        }
    }

    /// A leg's upper, lower, foot and toes (the last when there is one):
    /// from `start` down its main chain, past joints at the hips.
    fn leg(&self, start: usize, hips: Vec3A) -> Option<Vec<usize>> {
        let chain = self.chain(start, false);
        let low = chain.iter().map(|&j| self.positions[j].y).fold(f32::INFINITY, f32::min);
        let near = 0.05 * (hips.y - low);
        let first = chain.iter().position(|&j| self.positions[j].distance(hips) > near)?;
        let leg: Vec<usize> = chain[first..].iter().copied().take(4).collect();
        (leg.len() >= 3).then_some(leg)
    }

    fn torso(&self, start: usize, left: Vec3A, roles: &mut [Option<usize>; Role::COUNT]) {
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
        let centre = self.positions[branch];
        let lateral = |k: usize| (self.mean(k) - centre).dot(left).abs();
        let mut kids = self.children[branch].clone();
        kids.sort_by(|&a, &b| lateral(a).total_cmp(&lateral(b)));
        let neck = self.chain(kids[0], false);
        if let [head] = neck[..] {
            roles[Role::Head.index()] = Some(head);
        } else if let (Some(&n), Some(&h)) = (neck.first(), neck.last()) {
            roles[Role::Neck.index()] = Some(n);
            roles[Role::Head.index()] = Some(h);
        }
        if let [_, a, b, ..] = kids[..]
            && let Some(a_is_left) = self.opposite(a, b, centre, left)
        {
            let (l, r) = if a_is_left { (a, b) } else { (b, a) };
            self.arm(l, Side::Left, roles);
            self.arm(r, Side::Right, roles);
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

    /// The mean position of the subtree of `j`.
    fn mean(&self, j: usize) -> Vec3A {
        let mut stack = vec![j];
        let (mut sum, mut n) = (Vec3A::ZERO, 0.0);
        while let Some(k) = stack.pop() {
            sum += self.positions[k];
            n += 1.0;
            stack.extend(&self.children[k]);
        }
        sum / n
    }
}

/// The roles of a leg's joints, upper first (the left ones).
const LEG: [Role; 4] = [Role::LeftUpperLeg, Role::LeftLowerLeg, Role::LeftFoot, Role::LeftToes];

/// Gives `joints` the roles `slots` on `side`, in order.
fn put(roles: &mut [Option<usize>; Role::COUNT], slots: &[Role], joints: &[usize], side: Side) {
    for (role, &joint) in slots.iter().zip(joints) {
        roles[role.on(side).index()] = Some(joint);
    }
}
