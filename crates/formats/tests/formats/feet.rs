//! Planted feet on real takes: two CMU takes (`131_01`, start-walk-stop,
//! and `131_03`, start-hop-stop) imported as a user would, played on
//! CesiumMan with `feet: plant`. While the source foot is in contact (the
//! planting rule, computed here on the source's own model positions), the
//! planted target foot drifts from where the contact began by at most the
//! source foot's own drift × `k` + 1 mm, on average over the contact frames
//! (docs/characters.md); without planting it drifts more.
//!
//! The rule measures height from the foot's lowest in the clip, so a take
//! whose lowest foot is an outlier finds no contact: `05_20-mb`'s first
//! frame has both feet 1 unit (4 cm on CesiumMan) below where they stand
//! for the rest of the dance.
//!
//! `FIGURE` lines (`-- --nocapture`) are the figures in BENCHMARKS.md,
//! "Retargeting".

use anim::character::{FeetOptions, FootPlanter, RetargetOptions, Retargeter, Rig, Role, RoleMap, lowest_feet};
use anim::{Clip, Cursor, Interpolation, Pose};
use formats::import::ImportOptions;
use glam::Vec3A;

use super::{build, import_file};

/// CesiumMan's joints by role (its nodes have no names: the importer calls them `node<i>`).
pub const CESIUM_MAN_ROLES: [(Role, &str); 19] = [
    (Role::Hips, "node2"),
    (Role::Spine, "node11"),
    (Role::Chest, "node12"),
    (Role::Neck, "node19"),
    (Role::Head, "node20"),
    (Role::LeftUpperArm, "node16"),
    (Role::LeftLowerArm, "node17"),
    (Role::LeftHand, "node18"),
    (Role::RightUpperArm, "node13"),
    (Role::RightLowerArm, "node14"),
    (Role::RightHand, "node15"),
    (Role::LeftUpperLeg, "node7"),
    (Role::LeftLowerLeg, "node8"),
    (Role::LeftFoot, "node9"),
    (Role::LeftToes, "node10"),
    (Role::RightUpperLeg, "node3"),
    (Role::RightLowerLeg, "node4"),
    (Role::RightFoot, "node5"),
    (Role::RightToes, "node6"),
];

fn clip(rel: &str) -> Clip {
    let options = ImportOptions { bvh_interpolation: Interpolation::Linear, ..ImportOptions::default() };
    build(import_file(rel, &options).clips.last().expect("a clip"))
}

/// One foot's contact so far: where the source and both targets began it.
#[derive(Clone, Copy)]
struct Contact {
    source: Vec3A,
    planted: Vec3A,
    free: Vec3A,
}

/// Mean drifts from the contact's start over the contact frames: the
/// source's (× k), the planted target's and the unplanted target's.
#[derive(Default)]
struct Drift {
    frames: u32,
    source: f64,
    planted: f64,
    free: f64,
}

impl Drift {
    fn add(&mut self, start: &Contact, source: Vec3A, planted: Vec3A, free: Vec3A, k: f32) {
        self.frames += 1;
        self.source += f64::from(source.distance(start.source) * k);
        self.planted += f64::from(planted.distance(start.planted));
        self.free += f64::from(free.distance(start.free));
    }

    fn means(&self) -> [f64; 3] {
        let n = f64::from(self.frames.max(1));
        [self.source / n, self.planted / n, self.free / n]
    }
}

/// The take `rel` on CesiumMan at 60 fps with planted feet: the drifts.
fn drift(rel: &str) -> (Drift, f32) {
    let take = clip(rel);
    let character = clip("gltf/CesiumMan/CesiumMan.gltf");
    let (source, target) = (take.skeleton(), character.skeleton());
    let source_roles = RoleMap::infer(source, &[]).unwrap();
    let given: Vec<_> = CESIUM_MAN_ROLES.iter().map(|(r, n)| (*r, Some(*n))).collect();
    let target_roles = RoleMap::given(target, &given).unwrap();
    // The BVH reference: its offsets with zero rotation, the hips where the first frame has them.
    let (mut reference, mut first) = (source.rest().clone(), Pose::default());
    take.sample_into(take.start(), &mut Cursor::default(), &mut first);
    let hips = source_roles.joint(Role::Hips).unwrap();
    reference.translations[hips] = first.translations[hips];
    let rig = Rig { skeleton: source, reference: &reference, roles: &source_roles };
    let mut retargeter = Retargeter::new(rig, Rig::at_rest(target, &target_roles), RetargetOptions::default()).unwrap();
    let k = retargeter.k();
    let lowest = lowest_feet(&take, &source_roles);
    let options = FeetOptions::default();
    let mut planter = FootPlanter::new(&source_roles, &target_roles, lowest, options);

    let feet = [Role::LeftFoot, Role::RightFoot];
    let source_feet = feet.map(|r| source_roles.joint(r).unwrap());
    let target_feet = feet.map(|r| target_roles.joint(r).unwrap());
    let dt = 1.0 / 60.0;
    let frames = (take.duration() / dt) as usize;
    let (mut cursor, mut pose, mut planted, mut free) =
        (Cursor::default(), Pose::default(), Pose::default(), Pose::default());
    let (mut source_model, mut planted_model, mut free_model) = (Pose::default(), Pose::default(), Pose::default());
    let mut last: [Option<Vec3A>; 2] = [None; 2];
    let mut contacts: [Option<Contact>; 2] = [None; 2];
    let mut drift = Drift::default();
    for f in 0..=frames {
        take.sample_into(take.start() + f as f32 * dt, &mut cursor, &mut pose);
        retargeter.retarget(&pose, &mut planted);
        free.clone_from(&planted);
        planter.plant(&retargeter, (f > 0).then_some(dt), target, &mut planted);
        source.to_model(&pose, &mut source_model);
        target.to_model(&planted, &mut planted_model);
        target.to_model(&free, &mut free_model);
        for side in 0..2 {
            let now = source_model.translations[source_feet[side]];
            let height = (now.y - lowest[side]) * k;
            let speed = last[side].map(|was| now.distance(was) / dt * k);
            last[side] = Some(now);
            let contact = height <= options.contact_height && speed.is_none_or(|s| s <= options.contact_speed);
            let (p, q) = (planted_model.translations[target_feet[side]], free_model.translations[target_feet[side]]);
            contacts[side] = match (contact, contacts[side]) {
                (false, _) => None,
                (true, None) => Some(Contact { source: now, planted: p, free: q }),
                (true, Some(start)) => {
                    drift.add(&start, now, p, q, k);
                    Some(start)
                }
            };
        }
    }
    (drift, k)
}

#[test]
fn planted_feet_drift_no_more_than_the_takes_own_feet() {
    for rel in ["bvh/131_01.bvh", "bvh/131_03.bvh"] {
        let (drift, k) = drift(rel);
        let [source, planted, free] = drift.means();
        println!(
            "FIGURE feet {rel} on CesiumMan (k = {k:.4}): {} contact frames, mean drift source×k {:.2} mm, \
             planted {:.2} mm, unplanted {:.2} mm",
            drift.frames,
            source * 1e3,
            planted * 1e3,
            free * 1e3
        );
        assert!(drift.frames > 60, "{rel}: the take has contacts ({} frames)", drift.frames);
        assert!(planted <= source + 1e-3, "{rel}: planted {planted} m against source×k {source} m + 1 mm");
        assert!(planted < free, "{rel}: planting helps ({planted} m against {free} m)");
    }
}
