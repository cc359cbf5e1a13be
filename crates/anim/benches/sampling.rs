//! Sampling benchmarks for the evaluation core (issue 2; BENCHMARKS.md).
//!
//! Every clip here has 64 joints with 32 non-uniformly spaced keys per track
//! (each channel with its own key times unless said otherwise), so results are
//! per pose; BENCHMARKS.md divides by 64 for ns per joint-sample. Times are
//! precomputed so the measured loop is the sampler alone.
//!
//! Run: `cargo bench --bench sampling`.

extern crate inbetween_anim as anim;

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::{Quat, Vec3, Vec4};
#[path = "ozz/kernel.rs"]
mod ozz_kernel;

use anim::{
    Channel, Clip, ClipSpec, Cursor, Ease, Interpolation, JointSpec, Keys, Playback, Pose, SkeletonSpec, Speed,
    TrackSpec, Transform, quat,
};

const JOINTS: usize = 64;
const KEYS: usize = 32;

/// xorshift64*: deterministic keys without a dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32) / (1u64 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next()
    }
}

fn times(rng: &mut Rng, uniform: bool) -> Vec<f32> {
    let mut t = 0.0;
    (0..KEYS)
        .map(|_| {
            let now = t;
            t += if uniform { 1.0 / 30.0 } else { rng.range(0.02, 0.06) };
            now
        })
        .collect()
}

/// Rotation keys that turn by up to ~40° between keys, as mocap and hand
/// keys do.
fn rotations(rng: &mut Rng) -> Vec<Vec4> {
    let mut q = Quat::IDENTITY;
    (0..KEYS)
        .map(|_| {
            let axis =
                Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)).normalize_or(Vec3::Y);
            q = (Quat::from_axis_angle(axis, rng.range(0.05, 0.7)) * q).normalize();
            Vec4::from(q)
        })
        .collect()
}

fn vectors(rng: &mut Rng, base: f32) -> Vec<Vec3> {
    (0..KEYS).map(|_| Vec3::new(base + rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0))).collect()
}

fn track(rng: &mut Rng, joint: &str, channel: Channel, interpolation: Interpolation, uniform: bool) -> TrackSpec {
    let t = times(rng, uniform);
    let values = match channel {
        Channel::Rotation => Keys::Vec4(rotations(rng)),
        Channel::Scale => Keys::Vec3(vectors(rng, 1.5)),
        Channel::Translation => Keys::Vec3(vectors(rng, 0.0)),
    };
    let mut spec = TrackSpec::new(joint, channel, interpolation, t, values.clone());
    if interpolation == Interpolation::CubicHermite {
        let tangents = match &values {
            Keys::Vec3(v) => Keys::Vec3(v.iter().map(|x| *x * 0.5).collect()),
            Keys::Vec4(v) => Keys::Vec4(v.iter().map(|x| *x * 0.1).collect()),
        };
        spec.in_tangents = Some(tangents.clone());
        spec.out_tangents = Some(tangents);
    }
    spec
}

fn skeleton() -> SkeletonSpec {
    SkeletonSpec {
        joints: (0..JOINTS)
            .map(|j| JointSpec {
                name: format!("j{j}"),
                // A chain of short branches, parents first.
                parent: (j > 0).then(|| format!("j{}", (j - 1) / 2)),
                rest: Transform { translation: Vec3::new(0.0, 0.1, 0.0), ..Transform::IDENTITY },
                inverse_bind: None,
            })
            .collect(),
    }
}

/// 64 joints, each with the given channels in the given mode.
fn clip(channels: &[Channel], interpolation: Interpolation, uniform: bool, speed: Speed) -> Clip {
    clip_with(channels, interpolation, uniform, speed, false)
}

/// As [`clip`]; `shared_times` gives every track the same key times, as
/// glTF exports (one sampler input per animation) and BVH (one frame clock) do.
fn clip_with(
    channels: &[Channel],
    interpolation: Interpolation,
    uniform: bool,
    speed: Speed,
    shared_times: bool,
) -> Clip {
    bench_clip(tracks_with(channels, interpolation, uniform, speed, shared_times))
}

/// A looping clip of `tracks` on the 64-joint skeleton.
fn bench_clip(tracks: Vec<TrackSpec>) -> Clip {
    let spec = ClipSpec {
        name: "bench".into(),
        skeleton: Some(skeleton()),
        tracks,
        events: vec![],
        playback: Playback::Loop,
        ..Default::default()
    };
    // Unbounded: 64 constant-speed tracks of 32 keys need far more than the server's default build budget, and
    // this measures sampling, not building.
    // (The constant-speed one costs about 77 M units; the default budget is 16 M.)
    Clip::build_within(&spec, u64::MAX).expect("bench clip builds")
}

/// The tracks of [`clip_with`] (the ozz-style kernel is built from the same keys).
fn tracks_with(
    channels: &[Channel],
    interpolation: Interpolation,
    uniform: bool,
    speed: Speed,
    shared_times: bool,
) -> Vec<TrackSpec> {
    tracks_seeded(channels, interpolation, uniform, speed, shared_times, 0x9e37_79b9_7f4a_7c15)
}

/// [`tracks_with`] from the key generator seeded with `seed` (other keys, same shape).
fn tracks_seeded(
    channels: &[Channel],
    interpolation: Interpolation,
    uniform: bool,
    speed: Speed,
    shared_times: bool,
    seed: u64,
) -> Vec<TrackSpec> {
    let mut rng = Rng(seed);
    let shared = times(&mut Rng(5), uniform);
    let mut tracks = Vec::new();
    for j in 0..JOINTS {
        for &c in channels {
            let mut t = track(&mut rng, &format!("j{j}"), c, interpolation, uniform);
            if c == Channel::Translation {
                t.speed = speed;
            }
            if shared_times {
                t.times = shared.clone();
            }
            tracks.push(t);
        }
    }
    tracks
}

fn random_times(clip: &Clip, n: usize) -> Vec<f32> {
    let mut rng = Rng(42);
    (0..n).map(|_| rng.range(clip.start(), clip.end())).collect()
}

fn forward_times(clip: &Clip, n: usize) -> Vec<f32> {
    (0..n).map(|k| clip.start() + (k as f32 / 60.0) % clip.duration()).collect()
}

fn run_pose(c: &mut Criterion, group: &str, id: &str, clip: &Clip, times: &[f32], model: bool) {
    let mut g = c.benchmark_group(group);
    g.throughput(Throughput::Elements(JOINTS as u64));
    let (mut cursor, mut pose, mut out) = (Cursor::default(), Pose::default(), Pose::default());
    let mut k = 0;
    g.bench_function(id, |b| {
        b.iter(|| {
            k = (k + 1) % times.len();
            clip.sample_into(black_box(times[k]), &mut cursor, &mut pose);
            if model {
                clip.skeleton().to_model(&pose, &mut out);
            }
            black_box(&pose);
        })
    });
    g.finish();
}

fn per_mode(c: &mut Criterion) {
    use Channel::*;
    use Interpolation::*;
    let cases: [(&str, Channel, Interpolation, Speed); 9] = [
        ("vec3_step", Translation, Step, Speed::Keyed),
        ("vec3_linear", Translation, Linear, Speed::Keyed),
        ("vec3_catmull_rom", Translation, CatmullRom, Speed::Keyed),
        ("vec3_hermite", Translation, CubicHermite, Speed::Keyed),
        ("vec3_catmull_rom_constant_speed", Translation, CatmullRom, Speed::Constant),
        ("quat_step", Rotation, Step, Speed::Keyed),
        ("quat_slerp", Rotation, Linear, Speed::Keyed),
        ("quat_catmull_rom", Rotation, CatmullRom, Speed::Keyed),
        ("quat_hermite", Rotation, CubicHermite, Speed::Keyed),
    ];
    for (name, channel, interpolation, speed) in cases {
        let clip = clip(&[channel], interpolation, false, speed);
        run_pose(c, "mode_64_joints_forward", name, &clip, &forward_times(&clip, 4096), false);
    }
}

fn full_joint(c: &mut Criterion) {
    let trs = [Channel::Translation, Channel::Rotation, Channel::Scale];
    let cr = clip(&trs, Interpolation::CatmullRom, false, Speed::Keyed);
    let lin = clip(&trs, Interpolation::Linear, false, Speed::Keyed);
    let cr_uniform = clip(&trs, Interpolation::CatmullRom, true, Speed::Keyed);
    let cr_shared = clip_with(&trs, Interpolation::CatmullRom, false, Speed::Keyed, true);
    let lin_shared = clip_with(&trs, Interpolation::Linear, false, Speed::Keyed, true);
    let fwd = forward_times(&cr, 4096);
    let rnd = random_times(&cr, 4096);
    run_pose(c, "rbt_64_joints", "catmull_rom_local_forward", &cr, &fwd, false);
    run_pose(c, "rbt_64_joints", "catmull_rom_local_random", &cr, &rnd, false);
    run_pose(c, "rbt_64_joints", "catmull_rom_model_forward", &cr, &fwd, true);
    run_pose(c, "rbt_64_joints", "catmull_rom_model_random", &cr, &rnd, true);
    run_pose(
        c,
        "rbt_64_joints",
        "catmull_rom_uniform_keys_random",
        &cr_uniform,
        &random_times(&cr_uniform, 4096),
        false,
    );
    run_pose(
        c,
        "rbt_64_joints",
        "catmull_rom_shared_times_forward",
        &cr_shared,
        &forward_times(&cr_shared, 4096),
        false,
    );
    run_pose(c, "rbt_64_joints", "catmull_rom_shared_times_random", &cr_shared, &random_times(&cr_shared, 4096), false);
    run_pose(
        c,
        "rbt_64_joints",
        "catmull_rom_shared_times_model_random",
        &cr_shared,
        &random_times(&cr_shared, 4096),
        true,
    );
    run_pose(c, "rbt_64_joints", "linear_shared_times_forward", &lin_shared, &forward_times(&lin_shared, 4096), false);
    run_pose(c, "rbt_64_joints", "linear_shared_times_random", &lin_shared, &random_times(&lin_shared, 4096), false);
    run_pose(c, "rbt_64_joints", "linear_local_forward", &lin, &forward_times(&lin, 4096), false);
    run_pose(c, "rbt_64_joints", "linear_local_random", &lin, &random_times(&lin, 4096), false);
}

/// Real clips from `../shared/testdata`, imported as a user would: CMU
/// motion capture (31 joints, 120 fps keys) as Catmull-Rom and as linear,
/// and glTF walk cycles (linear keys, as exported).
fn real_clips(c: &mut Criterion) {
    use formats::import::{Format, ImportOptions, import};
    let dir = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join("../shared/testdata");
    let load = |file: &str, format: Format, interpolation: Interpolation| -> Option<Clip> {
        let bytes = std::fs::read(dir.join(file)).ok()?;
        let options = ImportOptions { bvh_interpolation: interpolation, ..ImportOptions::default() };
        let spec = import(&bytes, format, &options).ok()?.clips.into_iter().last()?;
        Clip::build(&spec).ok()
    };
    let cases = [
        ("bvh_131_01_catmull_rom", "bvh/131_01.bvh", Format::Bvh, Interpolation::CatmullRom),
        ("bvh_131_01_linear", "bvh/131_01.bvh", Format::Bvh, Interpolation::Linear),
        ("gltf_fox_run_linear", "gltf/Fox/Fox.glb", Format::Glb, Interpolation::Linear),
        ("gltf_cesium_man_linear", "gltf/CesiumMan/CesiumMan.gltf", Format::Gltf, Interpolation::Linear),
    ];
    let mut g = c.benchmark_group("real_clips");
    for (name, file, format, interpolation) in cases {
        let Some(clip) = load(file, format, interpolation) else {
            eprintln!("skipping {name}: ../shared/testdata/{file} not found");
            continue;
        };
        g.throughput(Throughput::Elements(clip.joint_count() as u64));
        for (mode, times) in [("forward", forward_times(&clip, 4096)), ("random", random_times(&clip, 4096))] {
            let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
            let mut k = 0;
            g.bench_function(format!("{name}_{mode}_{}_joints", clip.joint_count()), |b| {
                b.iter(|| {
                    k = (k + 1) % times.len();
                    clip.sample_into(black_box(times[k]), &mut cursor, &mut pose);
                    black_box(&pose);
                })
            });
        }
    }
    g.finish();
}

fn versus_splines_crate(c: &mut Criterion) {
    // Uniform keys: the splines crate's Catmull-Rom is the uniform one.
    let mut rng = Rng(7);
    let values: Vec<Vec3> = vectors(&mut rng, 0.0);
    let times: Vec<f32> = (0..KEYS).map(|i| i as f32).collect();
    let ours = Clip::build(&ClipSpec {
        name: "one".into(),
        skeleton: None,
        tracks: vec![TrackSpec::new(
            "a",
            Channel::Translation,
            Interpolation::CatmullRom,
            times.clone(),
            Keys::Vec3(values.clone()),
        )],
        events: vec![],
        playback: Playback::Once,
        ..Default::default()
    })
    .unwrap();
    let theirs = splines::Spline::from_vec(
        times
            .iter()
            .zip(&values)
            .map(|(&t, v)| {
                splines::Key::new(t, glam_splines::Vec3::new(v.x, v.y, v.z), splines::Interpolation::CatmullRom)
            })
            .collect(),
    );
    // splines needs a key on each side: sample inside [1, n-2].
    let mut r = Rng(3);
    let ts: Vec<f32> = (0..4096).map(|_| r.range(1.0, (KEYS - 2) as f32)).collect();
    let mut g = c.benchmark_group("vec3_catmull_rom_one_curve_random");
    g.throughput(Throughput::Elements(1));
    let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
    let mut k = 0;
    g.bench_function("inbetween", |b| {
        b.iter(|| {
            k = (k + 1) % ts.len();
            ours.sample_into(black_box(ts[k]), &mut cursor, &mut pose);
            black_box(pose.translations[0])
        })
    });
    g.bench_function("splines_crate", |b| {
        b.iter(|| {
            k = (k + 1) % ts.len();
            black_box(theirs.sample(black_box(ts[k])))
        })
    });
    g.finish();
}

fn versus_glam_slerp(c: &mut Criterion) {
    let mut rng = Rng(11);
    let pairs: Vec<(Quat, Quat, f32)> = (0..1024)
        .map(|_| {
            let r = rotations(&mut rng);
            (Quat::from_vec4(r[0]), Quat::from_vec4(r[3]), rng.next())
        })
        .collect();
    let mut g = c.benchmark_group("slerp");
    g.throughput(Throughput::Elements(1));
    for (name, f) in [
        ("inbetween_slerp_fast", quat::slerp_fast as fn(Quat, Quat, f32) -> Quat),
        ("glam_quat_slerp", |a: Quat, b: Quat, t: f32| a.slerp(b, t)),
    ] {
        let mut k = 0;
        g.bench_with_input(BenchmarkId::from_parameter(name), &pairs, |b, pairs| {
            b.iter(|| {
                k = (k + 1) % pairs.len();
                let (p, q, t) = pairs[k];
                black_box(f(black_box(p), black_box(q), black_box(t)))
            })
        });
    }
    g.finish();
}

/// Our sampling against an ozz-animation-style SoA kernel (benches/ozz/kernel.rs)
/// on the same keys: 64 joints, translation + rotation + scale, 32 keys per
/// track with each track's own times, forward at 60 fps and at random times.
/// ozz samples linear keys only; our linear and Catmull-Rom rows sit beside it.
fn versus_ozz(c: &mut Criterion) {
    let trs = [Channel::Translation, Channel::Rotation, Channel::Scale];
    let tracks = tracks_with(&trs, Interpolation::Linear, false, Speed::Keyed, false);
    let of = |ch: Channel| tracks.iter().filter(move |t| t.channel == ch);
    let vec3 = |t: &TrackSpec| match &t.values {
        Keys::Vec3(v) => (t.times.clone(), v.iter().map(|x| x.to_array()).collect::<Vec<_>>()),
        Keys::Vec4(_) => unreachable!("vector channel"),
    };
    let vec4 = |t: &TrackSpec| match &t.values {
        Keys::Vec4(v) => (t.times.clone(), v.iter().map(|x| x.to_array()).collect::<Vec<_>>()),
        Keys::Vec3(_) => unreachable!("rotation channel"),
    };
    let ozz = ozz_kernel::Animation::new(
        &of(Channel::Translation).map(vec3).collect::<Vec<_>>(),
        &of(Channel::Rotation).map(vec4).collect::<Vec<_>>(),
        &of(Channel::Scale).map(vec3).collect::<Vec<_>>(),
    );
    let lin = clip(&trs, Interpolation::Linear, false, Speed::Keyed);
    let cr = clip(&trs, Interpolation::CatmullRom, false, Speed::Keyed);
    // The kernel samples inside the keys' common range only (no looping).
    let end = tracks.iter().map(|t| *t.times.last().unwrap()).fold(f32::MAX, f32::min);
    let fwd: Vec<f32> = (0..4096).map(|k| (k as f32 / 60.0) % end).collect();
    let rnd: Vec<f32> = {
        let mut rng = Rng(42);
        (0..4096).map(|_| rng.range(0.0, end)).collect()
    };
    // The kernel is checked against our linear translations before it is timed.
    let (mut ctx, mut soa) = (ozz.context(), vec![ozz_kernel::SoaTransform::default(); JOINTS / 4]);
    let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
    for &t in rnd.iter().take(64) {
        ozz.sample(&mut ctx, t, &mut soa);
        lin.sample_into(t, &mut cursor, &mut pose);
        for j in 0..JOINTS {
            let (g, lane) = (j / 4, j % 4);
            let ours = Vec3::from(pose.translations[j]);
            let theirs =
                Vec3::new(soa[g].translation[0][lane], soa[g].translation[1][lane], soa[g].translation[2][lane]);
            assert!((ours - theirs).abs().max_element() < 1e-4, "joint {j} at {t}: {ours} vs {theirs}");
        }
    }
    for (id, times) in [("ozz_style_linear_forward", &fwd), ("ozz_style_linear_random", &rnd)] {
        let mut g = c.benchmark_group("versus_ozz_64_joints");
        g.throughput(Throughput::Elements(JOINTS as u64));
        let mut k = 0;
        g.bench_function(id, |b| {
            b.iter(|| {
                k = (k + 1) % times.len();
                ozz.sample(&mut ctx, black_box(times[k]), &mut soa);
                black_box(&soa);
            })
        });
        g.finish();
    }
    run_pose(c, "versus_ozz_64_joints", "inbetween_linear_forward", &lin, &fwd, false);
    run_pose(c, "versus_ozz_64_joints", "inbetween_linear_random", &lin, &rnd, false);
    run_pose(c, "versus_ozz_64_joints", "inbetween_catmull_rom_forward", &cr, &fwd, false);
    run_pose(c, "versus_ozz_64_joints", "inbetween_catmull_rom_random", &cr, &rnd, false);
}

/// Composition (docs/motion.md): the same 64-joint Catmull-Rom clips (translation,
/// rotation, scale) sampled forward as a clip, as a one-layer motion (its
/// fast path), as two blended layers, as two synced layers plus an additive
/// one, as one layer with root motion, as three layers (two synced blends
/// and a masked upper body) through `Motion::sample` and through a stream's
/// `Player`, and as a `Player` crossfading between two such motions: the
/// cost of each layer and of a fade.
fn composition(c: &mut Criterion) {
    use anim::motion::{LayerMode, LayerSpec, MotionOptions, MotionSpec, RootMotionSpec};
    use anim::{Motion, MotionSampler, SampleOptions, Sampler};
    let trs = [Channel::Translation, Channel::Rotation, Channel::Scale];
    let walk = clip(&trs, Interpolation::CatmullRom, false, Speed::Keyed);
    let run = clip_with(&trs, Interpolation::CatmullRom, true, Speed::Keyed, true);
    let wave = bench_clip(tracks_seeded(&trs, Interpolation::CatmullRom, false, Speed::Keyed, false, 0x5eed_0016));
    let times: Vec<f64> = forward_times(&walk, 4096).into_iter().map(f64::from).collect();
    let mut g = c.benchmark_group("composition_64_joints_forward");
    g.throughput(Throughput::Elements(JOINTS as u64));
    let (mut sampler, mut k) = (Sampler::new(), 0);
    g.bench_function("clip", |b| {
        b.iter(|| {
            k = (k + 1) % times.len();
            black_box(walk.sample(black_box(times[k]), &SampleOptions::default(), &mut sampler));
        })
    });
    let synced = |clip| LayerSpec { sync: Some("g".into()), ..LayerSpec::new(clip) };
    let cases: Vec<(&str, MotionSpec<&Clip>)> = vec![
        ("one_layer", MotionSpec { layers: vec![LayerSpec::new(&walk)], root_motion: None, ..Default::default() }),
        (
            "two_layers_blend",
            MotionSpec {
                layers: vec![LayerSpec::new(&walk), LayerSpec { weight: 0.3, ..LayerSpec::new(&run) }],
                ..MotionSpec::default()
            },
        ),
        (
            "two_synced_plus_additive",
            MotionSpec {
                layers: vec![
                    synced(&walk),
                    LayerSpec { weight: 0.3, ..synced(&run) },
                    LayerSpec { mode: LayerMode::Additive, weight: 0.5, ..LayerSpec::new(&run) },
                ],
                ..MotionSpec::default()
            },
        ),
        (
            "one_layer_root_motion",
            MotionSpec {
                layers: vec![LayerSpec::new(&walk)],
                root_motion: Some(RootMotionSpec::default()),
                ..Default::default()
            },
        ),
        ("three_layers", three_layers(&walk, &run, &wave, 0.3, 0.0)),
    ];
    for (name, spec) in cases {
        let motion = Motion::build(spec).expect("bench motion builds");
        let (mut sampler, mut k) = (MotionSampler::new(), 0);
        g.bench_function(name, |b| {
            b.iter(|| {
                k = (k + 1) % times.len();
                black_box(motion.sample(black_box(times[k]), &MotionOptions::default(), &mut sampler));
            })
        });
    }
    player_cases(&mut g, &walk, &run, &wave);
    g.finish();
}

/// Walk (weight 1) and run (`run_weight`) in one sync group, then `wave`
/// at `wave_offset` masked to `j1` and its descendants: 32 of the 64
/// joints, half the binary tree.
fn three_layers<'a>(
    walk: &'a Clip,
    run: &'a Clip,
    wave: &'a Clip,
    run_weight: f32,
    wave_offset: f64,
) -> anim::motion::MotionSpec<&'a Clip> {
    use anim::motion::{LayerSpec, MaskSpec, MotionSpec};
    let synced = |clip| LayerSpec { sync: Some("locomotion".into()), ..LayerSpec::new(clip) };
    let upper = MaskSpec { joints: vec![("j1".into(), 1.0)], descendants: true, default: None };
    MotionSpec {
        layers: vec![
            synced(walk),
            LayerSpec { weight: run_weight, ..synced(run) },
            LayerSpec { mask: Some(upper), offset: wave_offset, ..LayerSpec::new(wave) },
        ],
        ..MotionSpec::default()
    }
}

/// The three-layer motion through a stream's `Player` (stream times 1/60
/// apart, the phase advanced per tick), and a `Player` held mid-way through
/// a crossfade between two three-layer motions.
fn player_cases(
    g: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    walk: &Clip,
    run: &Clip,
    wave: &Clip,
) {
    use std::sync::Arc;

    use anim::Motion;
    use anim::motion::{MotionOptions, Player};
    let build = |run_weight, wave_offset| {
        Arc::new(Motion::build(three_layers(walk, run, wave, run_weight, wave_offset)).expect("bench motion builds"))
    };
    let options = MotionOptions::default();
    let mut player = Player::new(build(0.3, 0.0));
    let mut s = 0.0;
    g.bench_function("three_layers_player", |b| {
        b.iter(|| {
            s += 1.0 / 60.0;
            black_box(player.sample(black_box(s), &options));
        })
    });
    // A fade of 1e9 s, moved to its middle by one long tick: α stays near
    // 0.5 however many ticks criterion runs (1/60 s each).
    const FADE: f64 = 1e9;
    let mut fading = Player::new(build(0.3, 0.0));
    fading.sample(0.0, &options);
    fading.crossfade(build(0.6, 0.4), FADE, Ease::Linear).expect("same skeleton");
    fading.sample(1.0 / 60.0, &options);
    let mut s = FADE / 2.0;
    fading.sample(s, &options);
    g.bench_function("crossfade_three_layers", |b| {
        b.iter(|| {
            s += 1.0 / 60.0;
            black_box(fading.sample(black_box(s), &options));
        })
    });
    let alpha = fading.alpha();
    assert!(fading.fades() == 1 && alpha > 0.0 && alpha < 1.0, "still mid-fade after the measurement: α = {alpha}");
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(std::time::Duration::from_millis(500)).measurement_time(std::time::Duration::from_secs(2)).sample_size(50);
    targets = per_mode, full_joint, real_clips, versus_splines_crate, versus_glam_slerp, versus_ozz, composition
}
criterion_main!(benches);
