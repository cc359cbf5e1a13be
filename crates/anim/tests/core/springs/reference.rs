//! An independent `f64` run of docs/springs.md, “Integration”, written the
//! way VRM 1.0's spring bone specification states it: world matrices by
//! forward kinematics from scratch for every joint it needs, the tail's
//! rest position as a point of the joint's initial local matrix, the
//! rotation from `inverse(parentWorld · initialLocal) · tail`, and its own
//! shortest-arc quaternion. Shares nothing with `anim::spring` but the
//! authoring types; glam's `f64` types serve as plain arithmetic.

use anim::spring::{ChainSpec, ColliderShape, SpringParams};
use glam::{DMat4, DQuat, DVec3};

/// A skeleton in `f64`: names, parents, rest translations and rotations
/// (unit scales).
#[derive(Debug, Clone)]
pub struct RefSkeleton {
    pub names: Vec<String>,
    pub parents: Vec<Option<usize>>,
    pub rest_t: Vec<DVec3>,
    pub rest_q: Vec<DQuat>,
}

/// A local pose in `f64`.
#[derive(Debug, Clone)]
pub struct RefPose {
    pub t: Vec<DVec3>,
    pub q: Vec<DQuat>,
}

impl RefSkeleton {
    fn index(&self, name: &str) -> usize {
        self.names.iter().position(|n| n == name).expect("a joint of the rig")
    }

    /// The world matrix of `joint` under `pose`.
    pub fn world(&self, pose: &RefPose, joint: usize) -> DMat4 {
        let local = DMat4::from_rotation_translation(pose.q[joint], pose.t[joint]);
        match self.parents[joint] {
            Some(p) => self.world(pose, p) * local,
            None => local,
        }
    }

    fn rest_pose(&self) -> RefPose {
        RefPose { t: self.rest_t.clone(), q: self.rest_q.clone() }
    }
}

/// The shortest rotation taking unit `a` to unit `b`.
fn from_to(a: DVec3, b: DVec3) -> DQuat {
    let c = a.cross(b);
    let w = 1.0 + a.dot(b);
    if w < 1e-12 {
        let axis = if a.x.abs() < 0.9 { DVec3::X.cross(a) } else { DVec3::Y.cross(a) }.normalize();
        return DQuat::from_xyzw(axis.x, axis.y, axis.z, 0.0);
    }
    DQuat::from_xyzw(c.x, c.y, c.z, w).normalize()
}

#[derive(Debug, Clone)]
enum Shape {
    Sphere { offset: DVec3, radius: f64 },
    Capsule { offset: DVec3, tail: DVec3, radius: f64 },
}

#[derive(Debug, Clone)]
struct Joint {
    node: usize,
    child_local: DVec3,
    axis: DVec3,
    length: f64,
    params: SpringParams,
    current: DVec3,
    previous: DVec3,
    rotation: DQuat,
}

/// The chains of one rig, simulated in `f64`.
#[derive(Debug, Clone)]
pub struct RefSprings {
    skeleton: RefSkeleton,
    joints: Vec<Joint>,
    colliders: Vec<Vec<(usize, Shape)>>,
    /// Per joint: its chain.
    chain_of: Vec<usize>,
    pub h: f64,
    /// Collider pushes so far (so a test knows its colliders were hit).
    pub pushes: usize,
}

impl RefSprings {
    /// The chains at rest on `pose`.
    pub fn new(skeleton: &RefSkeleton, chains: &[ChainSpec], hz: f64, pose: &RefPose) -> Self {
        let rest = skeleton.rest_pose();
        let (mut joints, mut colliders, mut chain_of) = (Vec::new(), Vec::new(), Vec::new());
        for (c, chain) in chains.iter().enumerate() {
            for pair in chain.joints.windows(2) {
                let (node, tail) = (skeleton.index(&pair[0]), skeleton.index(&pair[1]));
                let head_world = skeleton.world(&rest, node);
                let tail_world = skeleton.world(&rest, tail).w_axis.truncate();
                let child_local = head_world.inverse().transform_point3(tail_world);
                let params = chain
                    .joint_params
                    .iter()
                    .find(|(n, _)| *n == pair[0])
                    .map_or(chain.params, |(_, p)| p.over(chain.params));
                let length = (tail_world - head_world.w_axis.truncate()).length();
                joints.push(Joint {
                    node,
                    child_local,
                    axis: child_local.normalize(),
                    length,
                    params,
                    current: DVec3::ZERO,
                    previous: DVec3::ZERO,
                    rotation: skeleton.rest_q[node],
                });
                chain_of.push(c);
            }
            colliders.push(
                chain
                    .colliders
                    .iter()
                    .map(|k| {
                        let shape = match k.shape {
                            ColliderShape::Sphere { offset, radius } => {
                                Shape::Sphere { offset: offset.as_dvec3(), radius: radius.into() }
                            }
                            ColliderShape::Capsule { offset, tail, radius } => Shape::Capsule {
                                offset: offset.as_dvec3(),
                                tail: tail.as_dvec3(),
                                radius: radius.into(),
                            },
                        };
                        (skeleton.index(&k.joint), shape)
                    })
                    .collect(),
            );
        }
        // Root to tip: ancestors (earlier joints) first.
        let mut order: Vec<usize> = (0..joints.len()).collect();
        order.sort_by_key(|&i| joints[i].node);
        let joints: Vec<Joint> = order.iter().map(|&i| joints[i].clone()).collect();
        let chain_of = order.iter().map(|&i| chain_of[i]).collect();
        let mut springs =
            RefSprings { skeleton: skeleton.clone(), joints, colliders, chain_of, h: 1.0 / hz, pushes: 0 };
        let posed = springs.posed(pose);
        for i in 0..springs.joints.len() {
            let tail =
                springs.skeleton.world(&posed, springs.joints[i].node).transform_point3(springs.joints[i].child_local);
            springs.joints[i].current = tail;
            springs.joints[i].previous = tail;
        }
        springs
    }

    /// `pose` with each spring joint at its simulated rotation.
    pub fn posed(&self, pose: &RefPose) -> RefPose {
        let mut posed = pose.clone();
        for j in &self.joints {
            posed.q[j.node] = j.rotation;
        }
        posed
    }

    /// One substep on `pose`, the motion at the substep's time.
    pub fn step(&mut self, pose: &RefPose) {
        for i in 0..self.joints.len() {
            let posed = self.posed(pose);
            let j = &self.joints[i];
            let parent_world =
                self.skeleton.parents[j.node].map_or(DMat4::IDENTITY, |p| self.skeleton.world(&posed, p));
            let initial_local = DMat4::from_rotation_translation(self.skeleton.rest_q[j.node], pose.t[j.node]);
            let frame = parent_world * initial_local;
            let position = frame.w_axis.truncate();
            let h = self.h;
            let p = j.params;
            let direction = (frame.transform_point3(j.axis) - position).normalize();
            let mut next = j.current
                + (j.current - j.previous) * (1.0 - f64::from(p.drag))
                + direction * (f64::from(p.stiffness) * h)
                + p.gravity.as_dvec3() * (h * h);
            next = position + (next - position).normalize() * j.length;
            for (node, shape) in &self.colliders[self.chain_of[i]] {
                let world = self.skeleton.world(&posed, *node);
                let (nearest, radius) = match shape {
                    Shape::Sphere { offset, radius } => (world.transform_point3(*offset), *radius),
                    Shape::Capsule { offset, tail, radius } => {
                        let (a, b) = (world.transform_point3(*offset), world.transform_point3(*tail));
                        let u = ((next - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
                        (a + (b - a) * u, *radius)
                    }
                };
                let distance = (next - nearest).length() - (radius + f64::from(p.radius));
                if distance < 0.0 {
                    self.pushes += 1;
                    next -= (next - nearest).normalize() * distance;
                    next = position + (next - position).normalize() * j.length;
                }
            }
            let to = frame.inverse().transform_point3(next).normalize();
            let j = &mut self.joints[i];
            j.previous = j.current;
            j.current = next;
            j.rotation = self.skeleton.rest_q[j.node] * from_to(j.axis, to);
        }
    }

    /// Model positions of every joint under `pose` with the simulated rotations.
    pub fn positions(&self, pose: &RefPose) -> Vec<DVec3> {
        let posed = self.posed(pose);
        (0..self.skeleton.names.len()).map(|j| self.skeleton.world(&posed, j).w_axis.truncate()).collect()
    }
}
