//! Retargeting benchmark (the `character` module): a CMU take (`131_01.bvh`,
//! 38 joints as imported, end sites included; roles by name) played on
//! CesiumMan (`CesiumMan.gltf`, 21 joints in its clip's skeleton; roles given
//! by node name), both imported as a user would from `../shared/testdata`.
//!
//! - `sample_and_retarget`: sampling the take and retargeting the pose, what
//!   a stream of the take on the character does per frame;
//! - `sample_and_model_passes`: sampling the take plus one local → model pass
//!   of each skeleton, the yardstick (a retargeted pose should cost at most
//!   1.5× this);
//! - `retarget_only`: the retarget of an already sampled pose.
//!
//! Run: `cargo bench -p inbetween-anim --bench retarget`.

extern crate inbetween_anim as anim;

use std::hint::black_box;

use anim::character::{RetargetOptions, Retargeter, Rig, Role, RoleMap};
use anim::{Clip, Cursor, Interpolation, Pose};
use criterion::{Criterion, criterion_group, criterion_main};

fn load(file: &str, format: formats::import::Format) -> Option<Clip> {
    use formats::import::{ImportOptions, import};
    let dir = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join("../shared/testdata");
    let bytes = std::fs::read(dir.join(file)).ok()?;
    let options = ImportOptions { bvh_interpolation: Interpolation::Linear, ..ImportOptions::default() };
    let spec = import(&bytes, format, &options).ok()?.clips.into_iter().last()?;
    Clip::build(&spec).ok()
}

/// CesiumMan's joints by role (its nodes have no names; the importer calls them `node<i>`).
const CESIUM_MAN_ROLES: [(Role, &str); 19] = [
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

fn retarget(c: &mut Criterion) {
    use formats::import::Format;
    let (Some(take), Some(character)) =
        (load("bvh/131_01.bvh", Format::Bvh), load("gltf/CesiumMan/CesiumMan.gltf", Format::Gltf))
    else {
        eprintln!("skipping: ../shared/testdata/bvh/131_01.bvh or gltf/CesiumMan/CesiumMan.gltf not found");
        return;
    };
    let (source, target) = (take.skeleton(), character.skeleton());
    let source_roles = RoleMap::infer(source, &[]).unwrap();
    let given: Vec<_> = CESIUM_MAN_ROLES.iter().map(|(r, n)| (*r, Some(*n))).collect();
    let target_roles = RoleMap::given(target, &given).unwrap();
    // The BVH reference: its offsets with zero rotation, the hips where the first frame has them.
    let mut source_reference = source.rest().clone();
    let mut first = Pose::default();
    take.sample_into(take.start(), &mut Cursor::default(), &mut first);
    let hips = source_roles.joint(Role::Hips).unwrap();
    source_reference.translations[hips] = first.translations[hips];
    let source_rig = Rig { skeleton: source, reference: &source_reference, roles: &source_roles };
    let mut retargeter =
        Retargeter::new(source_rig, Rig::at_rest(target, &target_roles), RetargetOptions::default()).unwrap();
    eprintln!(
        "{} source joints ({} roles), {} target joints ({} roles), k = {}",
        source.len(),
        source_roles.len(),
        target.len(),
        target_roles.len(),
        retargeter.k()
    );

    let times: Vec<f32> = (0..4096).map(|k| take.start() + take.duration() * k as f32 / 4096.0).collect();
    let (mut cursor, mut pose, mut out) = (Cursor::default(), Pose::default(), Pose::default());
    let (mut source_model, mut target_model) = (Pose::default(), Pose::default());
    let mut g = c.benchmark_group("retarget_cmu_131_01_to_cesium_man");
    let mut k = 0;
    g.bench_function("sample_and_retarget", |b| {
        b.iter(|| {
            k = (k + 1) % times.len();
            take.sample_into(black_box(times[k]), &mut cursor, &mut pose);
            retargeter.retarget(&pose, &mut out);
            black_box(&out);
        })
    });
    g.bench_function("sample_and_model_passes", |b| {
        b.iter(|| {
            k = (k + 1) % times.len();
            take.sample_into(black_box(times[k]), &mut cursor, &mut pose);
            source.to_model(&pose, &mut source_model);
            target.to_model(target.rest(), &mut target_model);
            black_box((&source_model, &target_model));
        })
    });
    g.bench_function("retarget_only", |b| {
        b.iter(|| {
            retargeter.retarget(black_box(&pose), &mut out);
            black_box(&out);
        })
    });
    g.finish();
}

criterion_group!(benches, retarget);
criterion_main!(benches);
