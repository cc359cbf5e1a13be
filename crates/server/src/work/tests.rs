//! The prices of `price`, against counts worked out by hand, and (with
//! `INBETWEEN_SLOW=1`, in a release build) against the CPU time the work
//! really takes: the table of BENCHMARKS.md, “Work and its price”.

use std::sync::Arc;
use std::time::Instant;

use anim::ik::{AimSpec, ChainSpec, EffectorSpec, IkSpec, TwoBoneSpec};
use anim::motion::{LayerSpec, MotionOptions, MotionSpec};
use anim::{
    Channel, Clip, ClipSpec, Interpolation, JointSpec, Keys, MotionSampler, SkeletonSpec, Space, TrackSpec, Transform,
};
use glam::{Quat, Vec3, Vec4};

use super::price;
use crate::request::Wire;
use crate::stream::{Pinned, PinnedClip, StreamMotion};

/// A chain of `n` joints (each the child of the one before, one unit
/// apart) with a translation and a rotation track of 30 keys on every
/// joint, and `ik` keyed in it.
fn chain_clip(n: usize, ik: Vec<anim::KeyedIkSpec>) -> Clip {
    let joints = (0..n)
        .map(|j| JointSpec {
            name: format!("j{j}"),
            parent: j.checked_sub(1).map(|p| format!("j{p}")),
            rest: Transform { translation: Vec3::Y, rotation: Quat::IDENTITY, scale: Vec3::ONE },
            inverse_bind: None,
        })
        .collect();
    let times: Vec<f32> = (0..30).map(|k| k as f32 / 30.0).collect();
    let tracks = (0..n)
        .flat_map(|j| {
            let name = format!("j{j}");
            let v3 = Keys::Vec3(times.iter().map(|&t| Vec3::new(0.1 * t, 1.0, 0.0)).collect());
            let q = Keys::Vec4(times.iter().map(|&t| Vec4::new(0.0, 0.0, (t * 0.1).sin(), (t * 0.1).cos())).collect());
            [
                TrackSpec::new(&name, Channel::Translation, Interpolation::Linear, times.clone(), v3),
                TrackSpec::new(&name, Channel::Rotation, Interpolation::Linear, times.clone(), q),
            ]
        })
        .collect();
    let spec = ClipSpec {
        name: "chain".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks,
        ik,
        playback: anim::Playback::Loop,
        ..Default::default()
    };
    Clip::build_limited(
        &spec,
        u64::MAX,
        &anim::ik::IkLimits { max_iterations: 100_000, ..Default::default() },
        &std::sync::atomic::AtomicBool::new(false),
    )
    .unwrap()
}

/// A motion of `layers` layers of `clip`, with request-time `ik`.
fn motion(clip: Clip, layers: usize, ik: Vec<IkSpec>) -> StreamMotion {
    let pinned: Arc<dyn PinnedClip> = Arc::new(Pinned::new("c", 1, Arc::new(clip)));
    let layers = (0..layers).map(|_| LayerSpec::new(Arc::clone(&pinned))).collect();
    let limits = anim::ik::IkLimits { max_iterations: 100_000, ..Default::default() };
    anim::Motion::build_limited(MotionSpec { layers, ik, ..Default::default() }, &limits).unwrap()
}

fn chain(effectors: &[usize], target: Vec3, iterations: u32) -> IkSpec {
    IkSpec::Chain(ChainSpec {
        effectors: effectors.iter().map(|&j| EffectorSpec { joint: format!("j{j}"), target, tip: None }).collect(),
        joints: None,
        limits: Vec::new(),
        max_iterations: Some(iterations),
        tolerance: Some(1e-9),
        weight: None,
    })
}

fn two_bone(n: usize) -> IkSpec {
    let joints = [format!("j{}", n - 3), format!("j{}", n - 2), format!("j{}", n - 1)];
    IkSpec::TwoBone(TwoBoneSpec { joints, target: Vec3::new(0.5, n as f32 - 1.5, 0.0), pole: None, weight: None })
}

fn aim(n: usize) -> IkSpec {
    let target = Vec3::new(3.0, n as f32, 1.0);
    IkSpec::Aim(AimSpec {
        joint: format!("j{}", n - 1),
        target,
        forward: None,
        up: None,
        up_direction: None,
        weight: None,
    })
}

#[test]
fn a_pose_costs_its_joints_per_layer() {
    assert_eq!(price::clip_pose(&chain_clip(16, Vec::new())), 16);
    assert_eq!(price::motion_pose(&motion(chain_clip(16, Vec::new()), 3, Vec::new())), 48);
}

#[test]
fn analytic_ik_costs_its_ancestry_and_chains_their_budget() {
    let m = motion(chain_clip(10, Vec::new()), 1, vec![two_bone(10)]);
    // The end joint j9 has 10 joints up to the root.
    let two_bone_units = price::motion_pose(&m) - 10;
    let m = motion(chain_clip(10, Vec::new()), 1, vec![aim(10)]);
    assert_eq!(price::motion_pose(&m) - 10, two_bone_units, "both walk 10 joints");
    // Two effectors on one branch share their path: j0..=j9 once.
    let one = motion(chain_clip(10, Vec::new()), 1, vec![chain(&[9], Vec3::X, 50)]);
    let two = motion(chain_clip(10, Vec::new()), 1, vec![chain(&[9, 5], Vec3::X, 50)]);
    let (one, two) = (price::motion_pose(&one) - 10, price::motion_pose(&two) - 10);
    assert_eq!(two, 2 * one, "the same 10 joints, twice the effectors");
    let long = motion(chain_clip(10, Vec::new()), 1, vec![chain(&[9], Vec3::X, 100)]);
    assert_eq!(price::motion_pose(&long) - 10, 2 * one, "twice the iterations");
    let short = motion(chain_clip(10, Vec::new()), 1, vec![chain(&[4], Vec3::X, 50)]);
    assert_eq!(2 * (price::motion_pose(&short) - 10), one, "half the joints");
}

#[test]
fn a_graphs_ik_and_springs_are_priced_as_a_motions() {
    let clip = chain_clip(10, Vec::new());
    let skeleton = clip.skeleton().clone();
    let limits = anim::ik::IkLimits { max_iterations: 100_000, ..Default::default() };
    let post = |ik: Vec<IkSpec>, springs: &anim::spring::SpringsSpec| {
        anim::graph::GraphPost::build(&ik, springs, &skeleton, &limits).unwrap()
    };
    let none = anim::spring::SpringsSpec::default();
    assert_eq!(price::graph_post(&post(Vec::new(), &none), &skeleton, 60.0), 0, "nothing to run");
    let ik_units = price::motion_pose(&motion(clip.clone(), 1, vec![two_bone(10)])) - 10;
    assert_eq!(price::graph_post(&post(vec![two_bone(10)], &none), &skeleton, 60.0), ik_units, "a motion's IK");
    // A chain j5..j9 turns 4 joints, 10 units each per substep; 120 substeps a second.
    let chain = anim::spring::ChainSpec::new("tail", &["j5", "j6", "j7", "j8", "j9"]);
    let springs = anim::spring::SpringsSpec { chains: vec![chain], ..Default::default() };
    let sprung = post(Vec::new(), &springs);
    for (fps, substeps) in [(60.0, 2), (120.0, 1), (50.0, 3), (240.0, 1)] {
        assert_eq!(price::graph_post(&sprung, &skeleton, fps), substeps * 4 * 10, "{fps} fps");
    }
}

#[test]
fn a_graph_among_clip_layers_pays_its_clip_layers_as_a_motions_pose() {
    use anim::graph::{ClipNodeSpec, Graph, GraphPost, GraphSpec, NodeKind, NodeSpec, TopSpec};
    let pinned: Arc<dyn PinnedClip> = Arc::new(Pinned::new("c", 1, Arc::new(chain_clip(10, Vec::new()))));
    let node = NodeSpec { name: "n".into(), kind: NodeKind::Clip(ClipNodeSpec::new(0)) };
    let spec = GraphSpec { parameters: Vec::new(), nodes: vec![node], top: TopSpec::Output(0) };
    let graph = Arc::new(Graph::build(spec, std::slice::from_ref(&pinned)).unwrap());
    let layers = vec![LayerSpec::new(Arc::clone(&pinned)), LayerSpec { weight: 0.5, ..LayerSpec::new(pinned) }];
    let mixed = GraphPost::mixed(MotionSpec { layers, ..Default::default() }, 0, &graph, &Default::default()).unwrap();
    let skeleton = graph.skeleton().clone();
    // The graph's layer as its first clip's 10 joints, and the clip layer's 10: a two-layer motion's pose.
    assert_eq!(
        price::graph_post(&mixed, &skeleton, 60.0),
        price::motion_pose(&motion(chain_clip(10, Vec::new()), 2, Vec::new()))
    );
    assert_eq!(price::graph_post(&mixed, &skeleton, 60.0), 20);
    let alone: crate::built::PinnedPost =
        GraphPost::build(&[], &Default::default(), &skeleton, &Default::default()).unwrap();
    assert_eq!(price::graph_post(&alone, &skeleton, 60.0), 0, "a graph alone pays its nodes in graph_tick");
}

#[test]
fn ik_keyed_in_a_clip_is_priced_like_a_requests() {
    let keyed = anim::KeyedIkSpec {
        constraint: chain(&[9], Vec3::X, 50),
        targets: vec![anim::IkTarget::Fixed(Vec3::X)],
        weight: None,
    };
    let in_clip = price::clip_pose(&chain_clip(10, vec![keyed]));
    let in_request = price::motion_pose(&motion(chain_clip(10, Vec::new()), 1, vec![chain(&[9], Vec3::X, 50)]));
    assert_eq!(in_clip, in_request);
}

#[test]
fn encoding_is_priced_per_byte_and_compression_per_coding_and_level() {
    assert_eq!(price::encoding(0), 0);
    assert!(price::encoding(1) >= 1);
    assert_eq!(price::encoding(8000), 1000);
    let gzip = |level| Some(price::Compression { coding: price::Coding::Gzip, level });
    assert_eq!(price::compression(None, 8000), 0, "sent as it is");
    // 10 and 39 ns a byte (BENCHMARKS.md, “Compression”), in units of 10 ns.
    assert_eq!((price::compression(gzip(1), 8000), price::compression(gzip(6), 8000)), (8000, 31_200));
}

/// Pricing reads counts: a 4,096-joint clip with a chain over all of it is
/// priced in far less time than one of its poses takes.
#[test]
fn pricing_costs_less_than_a_pose() {
    let m = motion(chain_clip(4096, Vec::new()), 1, vec![chain(&[4095], Vec3::X, 1)]);
    let time = |f: &mut dyn FnMut()| {
        let started = Instant::now();
        for _ in 0..20 {
            f();
        }
        started.elapsed() / 20
    };
    let priced = time(&mut || {
        std::hint::black_box(price::motion_pose(&m));
    });
    let mut sampler = MotionSampler::new();
    let posed = time(&mut || {
        std::hint::black_box(m.sample(0.5, &MotionOptions::default(), &mut sampler));
    });
    assert!(priced * 4 < posed, "pricing took {priced:?}, a pose {posed:?}");
}

/// One case of the table: what it is, its motion, and how it is encoded.
struct Case {
    what: String,
    motion: StreamMotion,
}

fn cases() -> Vec<Case> {
    let case = |what: String, motion| Case { what, motion };
    let mut cases = Vec::new();
    for n in [16, 64, 256, 1024, 4096] {
        cases.push(case(format!("clip, {n} joints"), motion(chain_clip(n, Vec::new()), 1, Vec::new())));
    }
    for n in [64, 1024] {
        cases.push(case(format!("3 layers × {n} joints"), motion(chain_clip(n, Vec::new()), 3, Vec::new())));
    }
    for n in [16, 256] {
        cases.push(case(format!("{n} joints + two-bone IK"), motion(chain_clip(n, Vec::new()), 1, vec![two_bone(n)])));
        cases.push(case(format!("{n} joints + aim IK"), motion(chain_clip(n, Vec::new()), 1, vec![aim(n)])));
    }
    let far = Vec3::new(1e4, 1e4, 0.0);
    for (n, iterations) in [(20, 100), (64, 100), (256, 50), (1024, 10)] {
        let ik = vec![chain(&[n - 1], far, iterations)];
        cases.push(case(
            format!("chain IK, {n} joints, {iterations} iterations"),
            motion(chain_clip(n, Vec::new()), 1, ik),
        ));
    }
    let ik = vec![chain(&[63, 40, 20], far, 100)];
    cases.push(case(
        "chain IK, 64 joints, 3 effectors, 100 iterations".into(),
        motion(chain_clip(64, Vec::new()), 1, ik),
    ));
    for (n, chains, length) in [(64, 1, 8), (64, 3, 8), (1024, 8, 16)] {
        cases.push(case(
            format!("{n} joints + {chains} spring chains of {length}, 1 s warm-up at 120 Hz"),
            sprung(chain_clip(n, Vec::new()), chains, length),
        ));
    }
    cases
}

/// A one-layer motion of `clip` (a chain) with `chains` spring chains of
/// `length` joints each, end to end from the chain's tip upwards.
fn sprung(clip: Clip, chains: usize, length: usize) -> StreamMotion {
    let n = clip.skeleton().len();
    let pinned: Arc<dyn PinnedClip> = Arc::new(Pinned::new("c", 1, Arc::new(clip)));
    let chain_specs = (0..chains)
        .map(|c| {
            let first = n - (c + 1) * length;
            let names: Vec<String> = (first..first + length).map(|j| format!("j{j}")).collect();
            let names: Vec<&str> = names.iter().map(String::as_str).collect();
            anim::spring::ChainSpec::new(&format!("chain{c}"), &names)
        })
        .collect();
    let springs = anim::spring::SpringsSpec { chains: chain_specs, ..Default::default() };
    let spec = MotionSpec { layers: vec![LayerSpec::new(pinned)], springs, ..Default::default() };
    anim::Motion::build_limited(spec, &anim::ik::IkLimits::default()).unwrap()
}

/// The motion time a measured pose is sampled at: over a second in, so a
/// pose with spring chains runs their whole warm-up.
const MEASURED_AT: f64 = 1.37;

/// Nanoseconds of the fastest of a few runs of one pose, sampled and
/// written as JSON, and the iterations its chain solves ran.
fn measure(m: &StreamMotion) -> (f64, u32) {
    let mut sampler = MotionSampler::new();
    let mut out = Vec::with_capacity(1 << 20);
    let mut best = f64::INFINITY;
    let options = MotionOptions { space: Space::Model, ..MotionOptions::default() };
    for run in 0..7 {
        out.clear();
        // Each run is a stateless pose: its springs from rest, warm-up included.
        sampler.restart_springs();
        let started = Instant::now();
        let clip_time = m.sample(MEASURED_AT + run as f64 * 0.01, &options, &mut sampler);
        let extras = formats::wire::json::Extras { ik: sampler.ik_reports(), ..Default::default() };
        let (skeleton, pose) = (m.skeleton(), sampler.pose());
        formats::wire::json::PoseJson { clip: "c", time: MEASURED_AT, clip_time, space: Space::Model, skeleton, pose }
            .write_with(&mut out, extras);
        best = best.min(started.elapsed().as_nanos() as f64);
    }
    let iterations = sampler.ik_reports().iter().map(|r| r.iterations).max().unwrap_or(0);
    (best, iterations)
}

/// The table of BENCHMARKS.md: each case's price (in units and in the
/// nanoseconds they stand for) against its measured time. How many
/// nanoseconds a unit takes depends on the machine, so what must hold is
/// that prices are right relative to each other: every ratio within 2× of
/// the median. Release builds only, with `INBETWEEN_SLOW=1`:
/// `INBETWEEN_SLOW=1 cargo test --release -p inbetween-server --lib work::tests::price_table -- --nocapture`.
#[test]
fn price_table() {
    if std::env::var_os("INBETWEEN_SLOW").is_none() || cfg!(debug_assertions) {
        return;
    }
    println!(
        "| work (one pose, model space, JSON) | price (units) | price × {} ns | measured | ratio | chain iterations run |",
        price::NS_PER_UNIT
    );
    println!("|---|---:|---:|---:|---:|---:|");
    let mut ratios = Vec::new();
    for case in cases() {
        let first = case.motion.first_clip().clip();
        let bytes = crate::request::Estimate::pose(first, "c", crate::request::Format::Trs, Wire::Json).total(1);
        let springs = price::spring_run(&case.motion, &[MEASURED_AT]);
        let units = price::motion_pose(&case.motion) + springs + price::encoding(bytes);
        let (ns, iterations) = measure(&case.motion);
        let priced = (units * price::NS_PER_UNIT) as f64;
        let ratio = priced / ns;
        ratios.push((ratio, case.what.clone()));
        println!(
            "| {} | {units} | {:.1} µs | {:.1} µs | {ratio:.2} | {} |",
            case.what,
            priced / 1e3,
            ns / 1e3,
            if iterations > 0 { iterations.to_string() } else { "–".into() }
        );
    }
    ratios.sort_by(|a, b| a.0.total_cmp(&b.0));
    let median = ratios[ratios.len() / 2].0;
    println!("median ratio {median:.2}: a unit took {:.2} ns here", price::NS_PER_UNIT as f64 / median);
    for (ratio, what) in &ratios {
        let off = ratio / median;
        assert!((0.5..=2.0).contains(&off), "{what}: its price is off the others' by {off:.2}×");
    }
}

#[test]
fn a_crossfades_spring_substeps_evaluate_both_motions() {
    // A: one layer of a 10-joint chain, no springs. B: two layers (20 joints)
    // with a chain j5..j9 turning 4 joints (10 units each per substep).
    let plain = motion(chain_clip(10, Vec::new()), 1, Vec::new());
    let pinned: Arc<dyn PinnedClip> = Arc::new(Pinned::new("c", 1, Arc::new(chain_clip(10, Vec::new()))));
    let springs = anim::spring::SpringsSpec {
        chains: vec![anim::spring::ChainSpec::new("tail", &["j5", "j6", "j7", "j8", "j9"])],
        ..Default::default()
    };
    let layers = vec![LayerSpec::new(Arc::clone(&pinned)), LayerSpec::new(pinned)];
    let sprung = anim::Motion::build(MotionSpec { layers, springs, ..Default::default() }).unwrap();
    assert_eq!(price::broadcast_frame(&[&plain], 0, 60), 10, "no springs: the pose");
    // 120 Hz at 60 fps: 2 substeps of the pose (20) and the chain (40).
    assert_eq!(price::broadcast_frame(&[&sprung], 0, 60), 20 + 2 * (20 + 40));
    // Fading into B with 7 units of stream IK: each substep evaluates A, B and the IK (37), then the chain.
    assert_eq!(price::broadcast_frame(&[&plain, &sprung], 7, 60), 37 + 2 * (37 + 40));
    assert_eq!(price::broadcast_frame(&[&plain, &sprung], 0, 50), 30 + 3 * (30 + 40), "3 substeps at 50 fps");
    // Fading into A: its springs (none) run, B's stop.
    assert_eq!(price::broadcast_frame(&[&sprung, &plain], 0, 60), 30);
}

#[test]
fn a_stream_frame_pays_its_share_of_the_substeps_late_frames_catch_up() {
    use crate::stream::MAX_CATCH_UP;
    assert_eq!(MAX_CATCH_UP, 4, "the sums below catch up 4 ticks");
    let plain = motion(chain_clip(10, Vec::new()), 1, Vec::new());
    let pinned: Arc<dyn PinnedClip> = Arc::new(Pinned::new("c", 1, Arc::new(chain_clip(10, Vec::new()))));
    let springs = anim::spring::SpringsSpec {
        chains: vec![anim::spring::ChainSpec::new("tail", &["j5", "j6", "j7", "j8", "j9"])],
        ..Default::default()
    };
    let sprung =
        anim::Motion::build(MotionSpec { layers: vec![LayerSpec::new(pinned)], springs, ..Default::default() })
            .unwrap();
    assert_eq!(price::stream_frame(&[&plain], 0, 60), 10, "no springs: nothing to catch up");
    // 2 substeps of the pose (10) and the chain (40) a tick: 100; a second of
    // 60 frames catches up 4 ticks more, ⌈400 / 60⌉ = 7 a frame.
    assert_eq!(price::stream_frame(&[&sprung], 0, 60), 10 + 100 + 7);
    assert_eq!(price::motion_frame(&sprung, 60), 117, "a motion's frame is its stream's");
    // At 10 fps: 12 substeps of 50, 600 a tick, 4 × 600 / 10 = 240 a frame.
    assert_eq!(price::stream_frame(&[&sprung], 0, 10), 10 + 600 + 240);
    assert_eq!(price::catch_up(600, 10), 240);
    // A clip stream's chains: the 10-joint chain's own frame, priced alike.
    let chains = anim::spring::SpringsSpec {
        chains: vec![anim::spring::ChainSpec::new("tail", &["j5", "j6", "j7", "j8", "j9"])],
        ..Default::default()
    };
    assert_eq!(price::clip_frame(&chain_clip(10, Vec::new()), &chains, 60), 10 + 100 + 7);
}

#[test]
fn a_stateless_spring_warmup_pays_only_the_joints_its_chains_read() {
    let springs = |joints: &[&str]| anim::spring::SpringsSpec {
        chains: vec![anim::spring::ChainSpec::new("tail", joints)],
        ..Default::default()
    };
    // A 64-joint chain; springs j1..j3 turn 2 joints (20 units a substep)
    // and read j0..j2 (3 joints: the turning ones and their ancestors, not
    // the tip). The layer pays those 3 and a copy of its clip (⌈64 / 4⌉ =
    // 16), the output its copy (16): 35, not the whole pose's 64.
    let pinned: Arc<dyn PinnedClip> = Arc::new(Pinned::new("c", 1, Arc::new(chain_clip(64, Vec::new()))));
    let layers = vec![LayerSpec::new(Arc::clone(&pinned))];
    let near = MotionSpec { layers, springs: springs(&["j1", "j2", "j3"]), ..Default::default() };
    let near = anim::Motion::build(near).unwrap();
    assert_eq!(price::warmup_substep(&near), 35 + 20);
    // A pose at 1.5: 1 s of warm-up at 120 Hz (120 substeps) and its own.
    assert_eq!(price::spring_run(&near, &[1.5]), 121 * 55);
    // Samples at 0.25 then 0.75: from 0 (the warm-up stops at the start),
    // 0.75 s in all, 90 substeps and one per pose.
    assert_eq!(price::spring_run(&near, &[0.25, 0.75]), 92 * 55);
    // Two layers of a 20-joint chain, springs j15..j19 (4 turning joints,
    // 40 units) reading 19 joints: 19 + 5 per layer + 5 is more than the
    // whole pose's 40, which bounds it.
    let pinned: Arc<dyn PinnedClip> = Arc::new(Pinned::new("c", 1, Arc::new(chain_clip(20, Vec::new()))));
    let tip = || springs(&["j15", "j16", "j17", "j18", "j19"]);
    let layers = vec![LayerSpec::new(Arc::clone(&pinned)), LayerSpec::new(Arc::clone(&pinned))];
    let far = anim::Motion::build(MotionSpec { layers, springs: tip(), ..Default::default() }).unwrap();
    assert_eq!(price::warmup_substep(&far), 40 + 40);
    // The motion's own IK reads whole chains: the whole pose, with the
    // aim at j19 (4 + its 20 joints of ancestry).
    let layers = vec![LayerSpec::new(Arc::clone(&pinned)), LayerSpec::new(pinned)];
    let spec = MotionSpec { layers, springs: tip(), ik: vec![aim(20)], ..Default::default() };
    let aimed = anim::Motion::build(spec).unwrap();
    assert_eq!(price::warmup_substep(&aimed), 40 + 24 + 40);
}
