//! One substep of docs/springs.md, “Integration”: the free joints placed,
//! the colliders with them, then root to tip each turning joint's tail
//! moved by Verlet, kept at its length, pushed out of the colliders and
//! the joint turned the smallest way toward it.

use glam::{Quat, Vec3A};

use super::build::{Bone, Collider, Link, NONE, Springs};
use crate::Pose;
use crate::ik::model::{Xform, arc, rotate, unit};

/// A collider placed in model space for one substep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Placed {
    a: Vec3A,
    b: Vec3A,
    radius: f32,
    capsule: bool,
}

impl Placed {
    pub const NOWHERE: Placed = Placed { a: Vec3A::ZERO, b: Vec3A::ZERO, radius: 0.0, capsule: false };
}

/// The per-bone values a substep moves (the solver's state, borrowed).
pub(super) struct Tails<'a> {
    pub current: &'a mut [Vec3A],
    pub previous: &'a mut [Vec3A],
    pub rotations: &'a mut [Quat],
}

/// What a pass does at each turning joint.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Pass {
    /// Integrate (a substep).
    Step,
    /// Put the tail at rest, unmoving (a reset).
    Rest,
}

/// Runs one pass over `local` (the animated pose of the substep's time).
pub(super) fn run(
    springs: &Springs,
    local: &Pose,
    model: &mut [Xform],
    placed: &mut [Placed],
    tails: Tails<'_>,
    pass: Pass,
) {
    let (t, q, s) = (&local.translations, &local.rotations, &local.scales);
    let (free, driven) = springs.links.split_at(springs.free);
    for (slot, link) in free.iter().enumerate() {
        let j = link.joint as usize;
        model[slot] = parent(model, link).child(t[j], q[j], s[j]);
    }
    for (c, p) in springs.colliders.iter().zip(placed.iter_mut()) {
        *p = place(c, &model[c.slot as usize]);
    }
    for (k, link) in driven.iter().enumerate() {
        let j = link.joint as usize;
        let up = parent(model, link);
        let rotation = if link.bone == NONE {
            q[j]
        } else {
            let b = link.bone as usize;
            let bone = &springs.bones[b];
            let pos = up.point(t[j]);
            let frame = up.q * bone.rest;
            let d = rotate(frame, bone.axis);
            let turned = match pass {
                Pass::Rest => {
                    let rest = pos + d * bone.length;
                    (tails.current[b], tails.previous[b]) = (rest, rest);
                    bone.rest
                }
                Pass::Step => {
                    let (cur, prev) = (tails.current[b], tails.previous[b]);
                    let verlet = cur + (cur - prev) * bone.keep + d * bone.pull + bone.fall;
                    let mut next = at_length(pos, verlet, d, bone.length);
                    let (from, to) = (bone.colliders.0 as usize, bone.colliders.1 as usize);
                    for c in &placed[from..to] {
                        next = collide(c, next, pos, d, bone);
                    }
                    (tails.current[b], tails.previous[b]) = (next, cur);
                    bone.rest * arc(bone.axis, rotate(frame.conjugate(), next - pos))
                }
            };
            tails.rotations[b] = turned;
            turned
        };
        if link.parent {
            model[springs.free + k] = up.child(t[j], rotation, s[j]);
        }
    }
}

#[inline]
fn parent(model: &[Xform], link: &Link) -> Xform {
    if link.parent_slot == NONE { Xform::IDENTITY } else { model[link.parent_slot as usize] }
}

fn place(c: &Collider, at: &Xform) -> Placed {
    Placed { a: at.point(c.a), b: at.point(c.b), radius: c.radius, capsule: c.capsule }
}

/// `tail` moved along the ray from `pos` to `length` from it (`d`'s way if
/// it sits on `pos`).
#[inline]
fn at_length(pos: Vec3A, tail: Vec3A, d: Vec3A, length: f32) -> Vec3A {
    pos + unit(tail - pos).unwrap_or(d) * length
}

/// `tail` pushed out of `c` grown by the bone's radius, then back at the
/// bone's length (VRM's order: the push may leave it a little inside).
#[inline]
fn collide(c: &Placed, tail: Vec3A, pos: Vec3A, d: Vec3A, bone: &Bone) -> Vec3A {
    let nearest = if c.capsule { nearest_on_segment(c.a, c.b, tail) } else { c.a };
    let delta = tail - nearest;
    let reach = c.radius + bone.radius;
    let squared = delta.length_squared();
    if squared >= reach * reach || squared == 0.0 {
        return tail;
    }
    let distance = squared.sqrt();
    let pushed = tail + delta * ((reach - distance) / distance);
    at_length(pos, pushed, d, bone.length)
}

/// The point of segment `a`–`b` nearest to `p`.
#[inline]
fn nearest_on_segment(a: Vec3A, b: Vec3A, p: Vec3A) -> Vec3A {
    let segment = b - a;
    let along = (p - a).dot(segment);
    let squared = segment.length_squared();
    if along <= 0.0 || squared == 0.0 {
        a
    } else if along >= squared {
        b
    } else {
        a + segment * (along / squared)
    }
}
