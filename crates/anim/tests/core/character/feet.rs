//! Planted feet: a walk-like take whose left foot is held still by IK on
//! the source, retargeted onto a rig with a longer thigh, slides unless
//! planted, and stays on its anchor when planted.

use anim::character::{FeetOptions, FootPlanter, RetargetOptions, Retargeter, Rig, Role, RoleMap, Side, Translation};
use anim::ik::{ChainStart, IkConstraint, IkSolver, TwoBone};
use anim::{Pose, Skeleton};
use glam::{Quat, Vec3, Vec3A};

use super::names::{SLOT_ROLES, SLOTS};
use super::skeleton_of;

/// The names tests' humanoid, each slot's offset scaled by `size(slot)`, its roles given.
fn rig(size: impl Fn(usize) -> f32) -> (Skeleton, RoleMap) {
    let name = |slot: usize| format!("slot{slot}");
    let joints: Vec<_> = SLOTS
        .iter()
        .enumerate()
        .map(|(i, (parent, t))| (name(i), parent.map(name), Vec3::from(*t) * size(i)))
        .collect();
    let skeleton = skeleton_of(&joints);
    let names: Vec<String> = (0..SLOTS.len()).map(name).collect();
    let given: Vec<_> = SLOT_ROLES.iter().zip(&names).map(|(r, n)| (*r, Some(n.as_str()))).collect();
    let roles = RoleMap::given(&skeleton, &given).unwrap();
    (skeleton, roles)
}

fn model(skeleton: &Skeleton, local: &Pose) -> Pose {
    let mut m = Pose::default();
    skeleton.to_model(local, &mut m);
    m
}

const FRAMES: usize = 30;
const DT: f32 = 1.0 / 30.0;

/// The take: the hips walk forward 5 mm a frame and bob, the left foot
/// held on the ground by a two-bone solve, the right leg swinging up.
fn take(source: &Skeleton, roles: &RoleMap) -> Vec<Pose> {
    let leg = [Role::LeftUpperLeg, Role::LeftLowerLeg, Role::LeftFoot].map(|r| roles.joint(r).unwrap());
    let (hips, right) = (roles.joint(Role::Hips).unwrap(), roles.joint(Role::RightUpperLeg).unwrap());
    let ground = model(source, source.rest()).translations[leg[2]] + Vec3A::new(0.0, 0.0, 0.1);
    let mut solver = IkSolver::new();
    let mut reports = Vec::new();
    (0..FRAMES)
        .map(|f| {
            let mut pose = source.rest().clone();
            pose.translations[hips] += Vec3A::new(0.0, -0.03 - 0.01 * (f as f32 * 0.4).sin(), 0.005 * f as f32);
            pose.rotations[right] = Quat::from_rotation_x(-0.4 - 0.02 * f as f32);
            let hold = [IkConstraint::TwoBone(TwoBone::new(leg, ground))];
            solver.solve(source, &mut pose, &hold, ChainStart::Cold, &mut reports);
            assert!(reports[0].converged, "frame {f}: the source foot is held");
            pose
        })
        .collect()
}

#[test]
fn a_planted_foot_stays_on_its_anchor_where_an_unplanted_one_slides() {
    let (source, source_roles) = rig(|_| 1.0);
    // A longer thigh: the hips ratio no longer says how the foot moves.
    let (target, target_roles) = rig(|slot| if slot == 15 || slot == 19 { 1.6 } else { 1.0 });
    let frames = take(&source, &source_roles);
    let feet = [Role::LeftFoot, Role::RightFoot].map(|r| source_roles.joint(r).unwrap());
    // The lowest in the clip, which also stands at rest somewhere: the right foot is raised throughout.
    let lowest = feet.map(|f| {
        let rest = model(&source, source.rest()).translations[f].y;
        frames.iter().map(|p| model(&source, p).translations[f].y).fold(rest, f32::min)
    });
    let rigs = (Rig::at_rest(&source, &source_roles), Rig::at_rest(&target, &target_roles));
    let mut retargeter = Retargeter::new(rigs.0, rigs.1, RetargetOptions { translation: Translation::Hips }).unwrap();
    assert!((retargeter.k() - (0.05 + 0.45 * 1.6 + 0.42) / 0.92).abs() < 1e-5, "k = {}", retargeter.k());
    let mut planter = FootPlanter::new(&source_roles, &target_roles, lowest, FeetOptions::default());
    let left = target_roles.joint(Role::LeftFoot).unwrap();
    let (mut out, mut first_free, mut first_planted) = (Pose::default(), None, None);
    let (mut slid, mut drift) = (0.0_f32, 0.0_f32);
    for (f, pose) in frames.iter().enumerate() {
        retargeter.retarget(pose, &mut out);
        let free = model(&target, &out).translations[left];
        slid = slid.max(free.distance(*first_free.get_or_insert(free)));
        planter.plant(&retargeter, (f > 0).then_some(DT), &target, &mut out);
        let planted = model(&target, &out).translations[left];
        let off = planted.distance(*first_planted.get_or_insert(planted));
        drift = drift.max(off);
        let reports = planter.reports();
        assert_eq!(
            reports.iter().map(|r| (r.side, r.planted)).collect::<Vec<_>>(),
            [(Side::Left, true), (Side::Right, false)]
        );
        assert!((reports[0].slide - off).abs() < 1e-5, "frame {f}: reported slide {} for {off}", reports[0].slide);
    }
    assert!(slid > 0.02, "unplanted, the foot slides ({slid}): a test that cannot fail is a defect");
    assert!(drift < 1e-4, "planted, the foot drifts {drift}");
}

#[test]
fn a_foot_lifted_or_moving_fast_is_not_planted() {
    let (source, roles) = rig(|_| 1.0);
    let mut retargeter =
        Retargeter::new(Rig::at_rest(&source, &roles), Rig::at_rest(&source, &roles), RetargetOptions::default())
            .unwrap();
    let foot = roles.joint(Role::LeftFoot).unwrap();
    let rest_y = model(&source, source.rest()).translations[foot].y;
    let mut planter = FootPlanter::new(&roles, &roles, [rest_y, rest_y], FeetOptions::default());
    let hips = roles.joint(Role::Hips).unwrap();
    let mut out = Pose::default();
    let planted = |planter: &FootPlanter| planter.reports().iter().map(|r| r.planted).collect::<Vec<_>>();
    // At rest: both feet on their lowest.
    retargeter.retarget(source.rest(), &mut out);
    planter.plant(&retargeter, None, &source, &mut out);
    assert_eq!(planted(&planter), [true, true]);
    // 3 cm up: above the 2 cm threshold.
    let mut up = source.rest().clone();
    up.translations[hips].y += 0.03;
    retargeter.retarget(&up, &mut out);
    planter.plant(&retargeter, Some(DT), &source, &mut out);
    assert_eq!(planted(&planter), [false, false]);
    // 1 cm up and back within a frame: low enough, but 0.3 m/s is too fast.
    let mut low = source.rest().clone();
    low.translations[hips].y += 0.01;
    retargeter.retarget(&low, &mut out);
    planter.plant(&retargeter, Some(DT), &source, &mut out);
    assert_eq!(planted(&planter), [false, false]);
    retargeter.retarget(&low, &mut out);
    planter.plant(&retargeter, Some(DT), &source, &mut out);
    assert_eq!(planted(&planter), [true, true], "still, 1 cm up");
}
