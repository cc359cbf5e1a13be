//! Spring chain benchmarks (docs/springs.md, issue 33; BENCHMARKS.md).
//!
//! A body (root, hips, spine, chest, neck, head) carrying three chains of
//! eight turning joints each (a tail on the hips, two ears on the head),
//! 24 turning joints in all. Each measured call is one frame 1/120 s after
//! the last at the default 120 Hz substep, so exactly one substep of all 24
//! joints (the frame's own pose is the substep's, so the motion is not
//! evaluated again): the time per call divided by 24 is the figure per
//! joint-substep. Cases: `free` (no colliders), and `spheres_8` (every
//! chain tested against 8 spheres on the hips, chest and head).
//!
//! Run: `cargo bench -p inbetween-anim --bench springs`.

extern crate inbetween_anim as anim;

use std::hint::black_box;

use anim::spring::{ChainSpec, ColliderShape, ColliderSpec, SpringParams, SpringSolver, Springs, SpringsSpec};
use anim::{Channel, Clip, ClipSpec, Interpolation, JointSpec, Keys, Pose, SkeletonSpec, TrackSpec, Transform};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::{Quat, Vec3};

const LINKS: usize = 8;

fn joint(name: &str, parent: Option<&str>, t: [f32; 3]) -> JointSpec {
    JointSpec {
        name: name.into(),
        parent: parent.map(Into::into),
        rest: Transform { translation: Vec3::from(t), ..Transform::IDENTITY },
        inverse_bind: None,
    }
}

/// The body and its chains' joint names.
fn body() -> (Clip, Vec<Vec<String>>) {
    let mut joints = vec![
        joint("root", None, [0.0, 0.0, 0.0]),
        joint("hips", Some("root"), [0.0, 1.0, 0.0]),
        joint("spine", Some("hips"), [0.0, 0.15, 0.0]),
        joint("chest", Some("spine"), [0.0, 0.2, 0.0]),
        joint("neck", Some("chest"), [0.0, 0.2, 0.0]),
        joint("head", Some("neck"), [0.0, 0.1, 0.0]),
    ];
    let mut chains = Vec::new();
    for (name, parent, step) in [
        ("tail", "hips", [0.0, -0.02, -0.08]),
        ("ear_l", "head", [0.03, 0.05, 0.0]),
        ("ear_r", "head", [-0.03, 0.05, 0.0]),
    ] {
        let names: Vec<String> = (0..=LINKS).map(|k| format!("{name}{k}")).collect();
        for (k, n) in names.iter().enumerate() {
            let up = if k == 0 { parent } else { &names[k - 1] };
            joints.push(joint(n, Some(up), step));
        }
        chains.push(names);
    }
    let keys = Keys::Vec4(vec![Quat::IDENTITY.into(), Quat::from_rotation_y(1.0).into()]);
    let turn = TrackSpec::new("root", Channel::Rotation, Interpolation::Linear, vec![0.0, 1.0], keys);
    let spec = ClipSpec {
        name: "body".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks: vec![turn],
        ..Default::default()
    };
    (Clip::build(&spec).unwrap(), chains)
}

fn springs(clip: &Clip, chains: &[Vec<String>], spheres: usize) -> Springs {
    let anchors = ["hips", "chest", "head"];
    let chains = chains
        .iter()
        .map(|names| {
            let joints: Vec<&str> = names.iter().map(String::as_str).collect();
            let colliders = (0..spheres)
                .map(|k| ColliderSpec {
                    joint: anchors[k % 3].into(),
                    shape: ColliderShape::Sphere { offset: Vec3::new(0.05 * k as f32 - 0.2, -0.1, -0.2), radius: 0.08 },
                })
                .collect();
            let params = SpringParams { gravity: Vec3::new(0.0, -9.81, 0.0), ..SpringParams::default() };
            ChainSpec { params, colliders, ..ChainSpec::new(&names[0], &joints) }
        })
        .collect();
    Springs::build(&SpringsSpec { chains, ..SpringsSpec::default() }, clip.skeleton()).unwrap()
}

fn bench(c: &mut Criterion) {
    let (clip, chains) = body();
    let mut pose = Pose::default();
    clip.sample_into(0.5, &mut anim::Cursor::default(), &mut pose);
    let mut g = c.benchmark_group("springs");
    for (case, spheres) in [("free", 0), ("spheres_8", 8)] {
        let springs = springs(&clip, &chains, spheres);
        let joints = springs.spring_joints().len() as u64;
        g.throughput(Throughput::Elements(joints));
        let mut solver = SpringSolver::new(&springs);
        let mut n = 0u64;
        g.bench_function(case, |b| {
            b.iter(|| {
                n += 1;
                let t = n as f64 / 120.0;
                solver.frame(&springs, black_box(t), &mut pose, |_, _| unreachable!("the frame's own pose serves"));
                black_box(&pose);
            })
        });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(std::time::Duration::from_millis(500)).measurement_time(std::time::Duration::from_secs(2)).sample_size(50);
    targets = bench
}
criterion_main!(benches);
