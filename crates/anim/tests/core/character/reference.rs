//! An independent `f64` retarget, written from the definition alone
//! (per mapped role `G_d(t) = G_s(t)·(G⁰_s)⁻¹·G⁰_d`, local rotations top-down
//! through the target, reference rotations for unmapped joints, reference
//! scales, the hips at `p⁰_d + k·(p_s(t) − p⁰_s)` with `k = h_d/h_s`), with
//! its own quaternion arithmetic, and the core held to it on random rigs and
//! poses in every translation mode.

use anim::character::{RetargetOptions, Retargeter, Rig, Role, RoleMap, Translation, rest_with_rotations};
use anim::{Pose, Skeleton};
use glam::{Quat, Vec3, Vec3A};

use super::names::{SLOT_ROLES, SLOTS};
use super::skeleton;
use crate::random::Rng;

type V = [f64; 3];
/// `[x, y, z, w]`.
type Q = [f64; 4];

fn mul(a: Q, b: Q) -> Q {
    let [ax, ay, az, aw] = a;
    let [bx, by, bz, bw] = b;
    [
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ]
}

fn conj(q: Q) -> Q {
    [-q[0], -q[1], -q[2], q[3]]
}

/// `q·v·q⁻¹`.
fn rotate(q: Q, v: V) -> V {
    let r = mul(mul(q, [v[0], v[1], v[2], 0.0]), conj(q));
    [r[0], r[1], r[2]]
}

fn add(a: V, b: V) -> V {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn scale(a: V, k: f64) -> V {
    [a[0] * k, a[1] * k, a[2] * k]
}

fn hadamard(a: V, b: V) -> V {
    [a[0] * b[0], a[1] * b[1], a[2] * b[2]]
}

fn dist(a: V, b: V) -> f64 {
    let d = sub(a, b);
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

/// A joint transform `(t, q, s)`.
#[derive(Clone, Copy)]
pub struct T {
    pub t: V,
    pub q: Q,
    pub s: V,
}

pub fn from_pose(pose: &Pose) -> Vec<T> {
    (0..pose.len())
        .map(|j| {
            let (t, q, s) = (pose.translations[j], pose.rotations[j], pose.scales[j]);
            T { t: t.as_dvec3().into(), q: q.as_dquat().into(), s: s.as_dvec3().into() }
        })
        .collect()
}

/// docs/clip-format.md, “Skeleton and spaces”: `t_m = t_p + q_p·(s_p ⊙ t_l)`,
/// `q_m = q_p·q_l`, `s_m = s_p ⊙ s_l`.
pub fn model(parents: &[Option<usize>], local: &[T]) -> Vec<T> {
    let mut m: Vec<T> = Vec::with_capacity(local.len());
    for (j, l) in local.iter().enumerate() {
        m.push(match parents[j] {
            None => *l,
            Some(p) => {
                let p = m[p];
                T { t: add(p.t, rotate(p.q, hadamard(p.s, l.t))), q: mul(p.q, l.q), s: hadamard(p.s, l.s) }
            }
        });
    }
    m
}

/// One side: parents, reference (local) and role → joint.
pub struct Side {
    pub parents: Vec<Option<usize>>,
    pub reference: Vec<T>,
    pub roles: Vec<Option<usize>>,
}

impl Side {
    pub fn new(skeleton: &Skeleton, reference: &Pose, roles: &RoleMap) -> Side {
        Side {
            parents: (0..skeleton.len()).map(|j| skeleton.parent(j)).collect(),
            reference: from_pose(reference),
            roles: Role::ALL.iter().map(|&r| roles.joint(r)).collect(),
        }
    }

    fn joint(&self, role: Role) -> Option<usize> {
        self.roles[role.index()]
    }

    /// `h`: the hips above the lower foot, `None` without a foot.
    fn hips_height(&self, m: &[T]) -> Option<f64> {
        let hips = self.joint(Role::Hips)?;
        let feet = [Role::LeftFoot, Role::RightFoot].into_iter().filter_map(|r| self.joint(r));
        let lowest = feet.map(|f| m[f].t[1]).reduce(f64::min)?;
        Some(m[hips].t[1] - lowest)
    }

    /// The length of the chain through `roles`' joints.
    fn chain_length(&self, m: &[T], roles: &[Role]) -> f64 {
        let points: Vec<V> = roles.iter().filter_map(|r| self.joint(*r)).map(|j| m[j].t).collect();
        points.windows(2).map(|w| dist(w[0], w[1])).sum()
    }
}

/// `k = h_d / h_s`.
pub fn hips_ratio(source: &Side, target: &Side) -> f64 {
    let (ms, md) = (model(&source.parents, &source.reference), model(&target.parents, &target.reference));
    let k = match (source.hips_height(&ms), target.hips_height(&md)) {
        (Some(s), Some(d)) => d / s,
        _ => {
            // The leg joints both sides map, hips first: the left leg's, else the right's.
            let both = |roles: [Role; 4]| -> Vec<Role> {
                roles.into_iter().filter(|r| source.joint(*r).is_some() && target.joint(*r).is_some()).collect()
            };
            let left = both([Role::Hips, Role::LeftUpperLeg, Role::LeftLowerLeg, Role::LeftFoot]);
            let leg = if left.len() >= 2 {
                left
            } else {
                both([Role::Hips, Role::RightUpperLeg, Role::RightLowerLeg, Role::RightFoot])
            };
            target.chain_length(&md, &leg) / source.chain_length(&ms, &leg)
        }
    };
    if k.is_finite() && k > 0.0 { k } else { 1.0 }
}

/// The target's local pose for the source's local pose `pose`.
pub fn retarget(source: &Side, target: &Side, pose: &[T], mode: Translation) -> Vec<T> {
    let (s0, d0) = (model(&source.parents, &source.reference), model(&target.parents, &target.reference));
    let s = model(&source.parents, pose);
    let k = hips_ratio(source, target);
    let (sh, dh) = (source.joint(Role::Hips).unwrap(), target.joint(Role::Hips).unwrap());
    let hips_at = match mode {
        Translation::None => d0[dh].t,
        _ => add(d0[dh].t, scale(sub(s[sh].t, s0[sh].t), k)),
    };
    let mut out: Vec<T> = Vec::new();
    let mut m: Vec<T> = Vec::new();
    for (j, parent) in target.parents.iter().enumerate() {
        let parent = parent.map_or(T { t: [0.0; 3], q: [0.0, 0.0, 0.0, 1.0], s: [1.0; 3] }, |p| m[p]);
        let source_joint = Role::ALL.iter().find(|r| target.joint(**r) == Some(j)).and_then(|r| source.joint(*r));
        let reference = target.reference[j];
        let g = match source_joint {
            Some(i) => mul(mul(s[i].q, conj(s0[i].q)), d0[j].q),
            None => mul(parent.q, reference.q),
        };
        let t = if j == dh {
            let v = rotate(conj(parent.q), sub(hips_at, parent.t));
            [v[0] / parent.s[0], v[1] / parent.s[1], v[2] / parent.s[2]]
        } else if let (Some(i), Translation::All) = (source_joint, mode) {
            add(reference.t, scale(sub(pose[i].t, source.reference[i].t), k))
        } else {
            reference.t
        };
        let local = T { t, q: mul(conj(parent.q), g), s: reference.s };
        m.push(T {
            t: add(parent.t, rotate(parent.q, hadamard(parent.s, t))),
            q: g,
            s: hadamard(parent.s, reference.s),
        });
        out.push(local);
    }
    out
}

/// A random humanoid: the 22 slots of the names tests with random offsets
/// and rest rotations; with `extras`, a root above the hips and joints
/// without a role between some slots, and scales on a few joints.
pub fn random_rig(rng: &mut Rng, extras: bool) -> (Skeleton, RoleMap) {
    let mut rows: Vec<super::Row<String>> = Vec::new();
    let rotation = |rng: &mut Rng, max: f64| -> [f64; 4] {
        let q = Quat::from_axis_angle(rng.axis(), rng.range(0.0, max) as f32);
        [q.x as f64, q.y as f64, q.z as f64, q.w as f64]
    };
    let mut names: Vec<String> = Vec::new();
    if extras {
        rows.push(("root".into(), None, rng.vec3(0.5).as_dvec3().into(), rotation(rng, 0.5)));
    }
    for (slot, (parent, offset)) in SLOTS.iter().enumerate() {
        let mut parent = parent.map(|p| names[p].clone()).or_else(|| extras.then(|| "root".to_owned()));
        if extras && slot > 0 && rng.chance(0.3) {
            let extra = format!("extra{slot}");
            rows.push((extra.clone(), parent, rng.vec3(0.05).as_dvec3().into(), rotation(rng, 1.0)));
            parent = Some(extra);
        }
        let size = rng.range(0.6, 1.6) as f32;
        let t = (Vec3::from(*offset) * size + rng.vec3(0.02)).as_dvec3().into();
        let name = format!("slot{slot}");
        rows.push((name.clone(), parent, t, rotation(rng, 1.2)));
        names.push(name);
    }
    let mut skeleton_spec = skeleton(&rows);
    if extras {
        skeleton_spec = with_scales(rng, &skeleton_spec);
    }
    let given: Vec<(Role, Option<&str>)> = SLOT_ROLES.iter().zip(&names).map(|(r, n)| (*r, Some(n.as_str()))).collect();
    let map = RoleMap::given(&skeleton_spec, &given).unwrap();
    (skeleton_spec, map)
}

/// `skeleton` with uniform scales on a few joints.
fn with_scales(rng: &mut Rng, skeleton: &Skeleton) -> Skeleton {
    let rest = skeleton.rest();
    let joints = (0..skeleton.len())
        .map(|j| anim::JointSpec {
            name: skeleton.names()[j].clone(),
            parent: skeleton.parent(j).map(|p| skeleton.names()[p].clone()),
            rest: anim::Transform {
                translation: rest.translations[j].into(),
                rotation: rest.rotations[j],
                scale: Vec3::splat(if rng.chance(0.2) { rng.range(0.7, 1.4) as f32 } else { 1.0 }),
            },
            inverse_bind: None,
        })
        .collect();
    Skeleton::build(&anim::SkeletonSpec { joints }).unwrap()
}

/// A random local pose of `skeleton`: every rotation turned up to `max`
/// radians from the rest, the roots and the hips (with `all`, every joint) moved.
pub fn random_pose(rng: &mut Rng, skeleton: &Skeleton, max: f64, all: bool) -> Pose {
    let mut pose = skeleton.rest().clone();
    for j in 0..skeleton.len() {
        let turn = Quat::from_axis_angle(rng.axis(), rng.range(0.0, max) as f32);
        pose.rotations[j] = (turn * pose.rotations[j]).normalize();
        if all || skeleton.parent(j).is_none() || skeleton.names()[j] == "slot0" {
            pose.translations[j] += Vec3A::from(rng.vec3(0.3));
        }
    }
    pose
}

/// The worst difference between the core's pose and the reference's, each
/// component against `1e-5·max(1, |reference|)` (docs/clip-format.md,
/// “Accuracy”): translations, scales and rotations (sign chosen with `w ≥ 0`).
pub fn worst_error(core: &Pose, reference: &[T]) -> f64 {
    let mut worst: f64 = 0.0;
    let mut check = |a: f32, b: f64| worst = worst.max((a as f64 - b).abs() / b.abs().max(1.0));
    for (j, r) in reference.iter().enumerate() {
        let q = core.rotations[j];
        let (qs, rs) = (if q.w < 0.0 { -1.0 } else { 1.0 }, if r.q[3] < 0.0 { -1.0 } else { 1.0 });
        for c in 0..3 {
            check(core.translations[j][c], r.t[c]);
            check(core.scales[j][c], r.s[c]);
        }
        for (c, &v) in q.to_array().iter().enumerate() {
            check(v * qs, r.q[c] * rs);
        }
    }
    worst
}

#[test]
fn the_core_agrees_with_the_f64_reference_on_random_rigs_and_poses() {
    let mut rng = Rng::new(1010);
    let mut worst: f64 = 0.0;
    for case in 0..60 {
        let (source, source_roles) = random_rig(&mut rng, case % 3 == 0);
        let (target, target_roles) = random_rig(&mut rng, case % 2 == 0);
        // Half the cases align the source's reference by replacing rotations.
        let mut overrides: Vec<(usize, Quat)> = Vec::new();
        for j in (0..source.len()).filter(|_| case % 4 < 2) {
            if rng.chance(0.3) {
                overrides.push((j, Quat::from_axis_angle(rng.axis(), 0.7)));
            }
        }
        let source_reference = rest_with_rotations(&source, &overrides);
        let mode = [Translation::Hips, Translation::None, Translation::All][case % 3];
        let source_rig = Rig { skeleton: &source, reference: &source_reference, roles: &source_roles };
        let target_rig = Rig::at_rest(&target, &target_roles);
        let mut retargeter = Retargeter::new(source_rig, target_rig, RetargetOptions { translation: mode }).unwrap();
        let (s, d) =
            (Side::new(&source, &source_reference, &source_roles), Side::new(&target, target.rest(), &target_roles));
        assert!((retargeter.k() as f64 - hips_ratio(&s, &d)).abs() < 1e-5 * hips_ratio(&s, &d), "case {case}: k");
        let mut out = Pose::default();
        for _ in 0..5 {
            let pose = random_pose(&mut rng, &source, 2.0, mode == Translation::All);
            retargeter.retarget(&pose, &mut out);
            let expected = retarget(&s, &d, &from_pose(&pose), mode);
            let error = worst_error(&out, &expected);
            assert!(error <= 1e-5, "case {case} ({mode:?}): worst scaled error {error:e}");
            worst = worst.max(error);
        }
    }
    eprintln!("retarget vs f64 reference: worst scaled error {worst:e}");
}
