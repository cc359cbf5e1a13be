//! The 20-joint body of the IK benchmarks, shared with the tests
//! (`tests/core/ik/chain.rs` holds the chain solver to its convergence
//! rate on exactly the problems the benchmark times): hips, three spine
//! joints, neck, head, two arms of shoulder–upper–fore–hand held out
//! straight, two legs of thigh–shin–foot, every joint turned a little.
//! Each user takes the parts it needs.
#![allow(dead_code)]

use anim::ik::{Chain, Effector, JointLimits};
use anim::{
    Channel, Clip, ClipSpec, Interpolation, JointSpec, Keys, Playback, Pose, Skeleton, SkeletonSpec, TrackSpec,
    Transform,
};
use glam::{Quat, Vec3, Vec3A, Vec4};

pub const HIPS: usize = 0;
pub const HEAD: usize = 5;
pub const LEFT_HAND: usize = 9;
pub const RIGHT_HAND: usize = 13;
pub const LEFT_LEG: [usize; 3] = [14, 15, 16];

/// xorshift64*: deterministic targets without a dependency.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let bits = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40;
        bits as f32 / (1u64 << 24) as f32
    }

    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next()
    }

    pub fn vec3(&mut self, r: f32) -> Vec3A {
        Vec3A::new(self.range(-r, r), self.range(-r, r), self.range(-r, r))
    }
}

/// The body, its joints slightly turned so no chain starts straight.
pub fn body() -> Clip {
    let v = Vec3::new;
    #[rustfmt::skip]
    let joints: [(&str, Option<usize>, Vec3); 20] = [
        ("hips", None, v(0.0, 1.0, 0.0)),
        ("spine1", Some(0), v(0.0, 0.12, 0.0)), ("spine2", Some(1), v(0.0, 0.12, 0.0)),
        ("spine3", Some(2), v(0.0, 0.12, 0.0)), ("neck", Some(3), v(0.0, 0.15, 0.0)),
        ("head", Some(4), v(0.0, 0.1, 0.0)),
        ("l_shoulder", Some(3), v(0.15, 0.1, 0.0)), ("l_upper", Some(6), v(0.12, 0.0, 0.0)),
        ("l_fore", Some(7), v(0.28, 0.0, 0.0)), ("l_hand", Some(8), v(0.25, 0.0, 0.0)),
        ("r_shoulder", Some(3), v(-0.15, 0.1, 0.0)), ("r_upper", Some(10), v(-0.12, 0.0, 0.0)),
        ("r_fore", Some(11), v(-0.28, 0.0, 0.0)), ("r_hand", Some(12), v(-0.25, 0.0, 0.0)),
        ("l_thigh", Some(0), v(0.1, -0.05, 0.0)), ("l_shin", Some(14), v(0.0, -0.45, 0.0)),
        ("l_foot", Some(15), v(0.0, -0.42, 0.0)),
        ("r_thigh", Some(0), v(-0.1, -0.05, 0.0)), ("r_shin", Some(17), v(0.0, -0.45, 0.0)),
        ("r_foot", Some(18), v(0.0, -0.42, 0.0)),
    ];
    let mut rng = Rng(0x1517);
    let spec_joints = joints
        .iter()
        .map(|&(name, parent, translation)| {
            let turn = Vec3::from(rng.vec3(0.15));
            JointSpec {
                name: name.into(),
                parent: parent.map(|p| joints[p].0.to_owned()),
                rest: Transform { translation, rotation: Quat::from_scaled_axis(turn), ..Transform::IDENTITY },
                inverse_bind: None,
            }
        })
        .collect();
    let track = TrackSpec::new(
        "hips",
        Channel::Rotation,
        Interpolation::Linear,
        vec![0.0],
        Keys::Vec4(vec![Vec4::from(Quat::IDENTITY)]),
    );
    let spec = ClipSpec {
        name: "body".into(),
        skeleton: Some(SkeletonSpec { joints: spec_joints }),
        tracks: vec![track],
        events: vec![],
        playback: Playback::Once,
        ..Default::default()
    };
    Clip::build(&spec).expect("bench body builds")
}

pub fn model(skeleton: &Skeleton, pose: &Pose) -> Pose {
    let mut out = Pose::default();
    skeleton.to_model(pose, &mut out);
    out
}

/// Both hands, every ancestor movable within ±1.5 rad.
pub fn hands_chain(targets: [Vec3A; 2]) -> Chain {
    let movable = [HIPS, 1, 2, 3, 6, 7, 8, 10, 11, 12];
    let limits = movable.iter().map(|&joint| JointLimits { joint, min: [-1.5; 3], max: [1.5; 3] }).collect();
    let effectors = vec![
        Effector { joint: LEFT_HAND, target: targets[0], tip: Vec3A::ZERO },
        Effector { joint: RIGHT_HAND, target: targets[1], tip: Vec3A::ZERO },
    ];
    Chain { limits, ..Chain::new(effectors) }
}

/// Hand positions for random angles `|a| ≤ 0.6` on the chain's joints
/// (reachable by construction), found by applying them to the pose.
pub fn reachable_targets(skeleton: &Skeleton, rest: &Pose, rng: &mut Rng) -> [Vec3A; 2] {
    let mut pose = rest.clone();
    for j in [HIPS, 1, 2, 3, 6, 7, 8, 10, 11, 12] {
        let (x, y, z) = (rng.range(-0.6, 0.6), rng.range(-0.6, 0.6), rng.range(-0.6, 0.6));
        pose.rotations[j] =
            rest.rotations[j] * Quat::from_rotation_x(x) * Quat::from_rotation_y(y) * Quat::from_rotation_z(z);
    }
    let m = model(skeleton, &pose);
    [m.translations[LEFT_HAND], m.translations[RIGHT_HAND]]
}
