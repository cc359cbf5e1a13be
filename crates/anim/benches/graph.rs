//! Graph benchmark (docs/graphs.md): a 2D blend of four clips played tick by
//! tick against the same four clips as a motion (docs/motion.md) with given weights on a
//! stream's `Player`, the yardstick (a blend should cost at most 2.5× it).
//!
//! The clips: 64 joints of Catmull-Rom translation, rotation and scale (32
//! keys each, own key times), looping, in one sync group; 60 ticks a second.
//!
//! - `motion_4_layers`: `Player::sample` of the four layers at the weights
//!   the blend gives at (direction −30, speed 1): three non-zero;
//! - `blend2d_4_clips`: `GraphPlayer::tick` of the blend at that point;
//! - `blend2d_4_clips_moving`: the same with both parameters set every tick
//!   (the weights found afresh in the triangulation each time).
//!
//! Run: `cargo bench -p inbetween-anim --bench graph`.

extern crate inbetween_anim as anim;

use std::hint::black_box;
use std::sync::Arc;

use anim::graph::{Blend2dSpec, Graph, GraphPlayer, GraphSpec, NodeKind, NodeSpec, ParameterKind, ParameterSpec};
use anim::graph::{TopSpec, Value};
use anim::motion::{LayerSpec, MotionOptions, MotionSpec, Player};
use anim::{Channel, Clip, ClipSpec, Interpolation, JointSpec, Keys, Motion, Playback, SkeletonSpec, TrackSpec};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::{Quat, Vec3, Vec4};

const JOINTS: usize = 64;
const KEYS: usize = 32;

/// xorshift64*: deterministic keys without a dependency.
struct Rng(u64);

impl Rng {
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        lo + (hi - lo) * ((self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32 / (1u64 << 24) as f32)
    }
}

/// A looping 64-joint chain clip of random keys (seeded).
fn bench_clip(seed: u64) -> Clip {
    let mut rng = Rng(seed);
    let joints = (0..JOINTS)
        .map(|j| JointSpec {
            name: format!("j{j}"),
            parent: (j > 0).then(|| format!("j{}", j - 1)),
            rest: anim::Transform { translation: Vec3::new(0.0, 0.1, 0.0), ..anim::Transform::IDENTITY },
            inverse_bind: None,
        })
        .collect();
    let mut tracks = Vec::new();
    for j in 0..JOINTS {
        let mut t = 0.0;
        let times: Vec<f32> = (0..KEYS)
            .map(|_| {
                let now = t;
                t += rng.range(0.02, 0.06);
                now
            })
            .collect();
        let v3 = |rng: &mut Rng, lo, hi| {
            Keys::Vec3((0..KEYS).map(|_| Vec3::new(rng.range(lo, hi), rng.range(lo, hi), rng.range(lo, hi))).collect())
        };
        let translations = v3(&mut rng, -1.0, 1.0);
        let scales = v3(&mut rng, 0.8, 1.2);
        let rotations = Keys::Vec4(
            (0..KEYS)
                .map(|_| {
                    Vec4::from(Quat::from_euler(
                        glam::EulerRot::XYZ,
                        rng.range(-1.0, 1.0),
                        rng.range(-1.0, 1.0),
                        rng.range(-1.0, 1.0),
                    ))
                })
                .collect(),
        );
        let name = format!("j{j}");
        for (channel, keys) in
            [(Channel::Translation, translations), (Channel::Rotation, rotations), (Channel::Scale, scales)]
        {
            tracks.push(TrackSpec::new(&name, channel, Interpolation::CatmullRom, times.clone(), keys));
        }
    }
    let spec = ClipSpec {
        name: "bench".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks,
        playback: Playback::Loop,
        ..Default::default()
    };
    Clip::build_within(&spec, u64::MAX).expect("bench clip builds")
}

fn float(name: &str, min: f64, max: f64) -> ParameterSpec {
    ParameterSpec { name: name.into(), kind: ParameterKind::Float { default: 0.0_f64.clamp(min, max), min, max } }
}

fn graph(c: &mut Criterion) {
    let clips: Vec<Clip> = (0..4).map(|i| bench_clip(0x9e37_79b9_7f4a_7c15 ^ i)).collect();
    let refs: Vec<&Clip> = clips.iter().collect();
    let points = vec![(0, [0.0, 0.0]), (1, [0.0, 1.5]), (2, [-90.0, 1.5]), (3, [90.0, 1.5])];
    let spec = GraphSpec {
        parameters: vec![float("direction", -180.0, 180.0), float("speed", 0.0, 6.0)],
        nodes: vec![NodeSpec {
            name: "strafe".into(),
            kind: NodeKind::Blend2d(Blend2dSpec { x: 0, y: 1, points, sync: true }),
        }],
        top: TopSpec::Output(0),
    };
    let graph = Arc::new(Graph::build(spec, &refs).expect("the bench graph builds"));
    let mut blend = GraphPlayer::new(Arc::clone(&graph));
    blend.set(0, Value::Float(-30.0)).unwrap();
    blend.set(1, Value::Float(1.0)).unwrap();
    blend.tick(0.0);
    let weights = blend.report().weights().next().expect("the blend played").1.to_vec();

    // The same clips as a motion at the blend's layer weights, w_k / Σ_{j≤k} w_j.
    let mut sum = 0.0;
    let layers = refs
        .iter()
        .zip(&weights)
        .map(|(&clip, w)| {
            sum += w;
            LayerSpec {
                weight: if sum > 0.0 { (w / sum) as f32 } else { 0.0 },
                sync: Some("g".into()),
                ..LayerSpec::new(clip)
            }
        })
        .collect();
    let motion = Arc::new(Motion::build(MotionSpec { layers, ..Default::default() }).expect("the motion builds"));
    let mut player = Player::new(motion);

    let mut g = c.benchmark_group("graph_64_joints");
    g.throughput(Throughput::Elements(JOINTS as u64));
    let options = MotionOptions::default();
    let mut s = 0.0;
    g.bench_function("motion_4_layers", |b| {
        b.iter(|| {
            s += 1.0 / 60.0;
            black_box(player.sample(black_box(s), &options));
        })
    });
    g.bench_function("blend2d_4_clips", |b| {
        b.iter(|| {
            blend.tick(black_box(1.0 / 60.0));
            black_box(blend.pose());
        })
    });
    let mut moving = GraphPlayer::new(graph);
    let mut k = 0u32;
    g.bench_function("blend2d_4_clips_moving", |b| {
        b.iter(|| {
            k = (k + 1) % 600;
            let t = f64::from(k) / 600.0;
            moving.set(0, Value::Float(-60.0 + 60.0 * t)).unwrap();
            moving.set(1, Value::Float(0.5 + t)).unwrap();
            moving.tick(black_box(1.0 / 60.0));
            black_box(moving.pose());
        })
    });
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default();
    targets = graph
}
criterion_main!(benches);
