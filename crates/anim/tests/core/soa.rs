//! The SIMD groups (`src/anim/soa.rs`: tracks sharing key times, four per
//! SSE lane set) against the scalar kernel (`Clip::build_scalar`), on random
//! clips whose tracks share timelines: every value within 1e-6, forward,
//! at random times and across loop seams, in every spline mode the groups
//! take (Catmull-Rom with each end condition and tension, the B-spline),
//! rotations wide enough to need the exact-slerp lanes; and no allocation.

use anim::{
    Channel, Clip, ClipSpec, Cursor, Ends, Interpolation, JointSpec, Playback, Pose, SampleOptions, Sampler,
    SkeletonSpec, Transform,
};
use glam::Vec4;

use crate::allocations;
use crate::random::{Kind, Rng, track};

/// A clip of `joints` joints whose tracks of each channel share one of two
/// key-time arrays (in half the clips, about half of them keep their own
/// times instead), all in one spline mode per channel.
fn shared_clip(rng: &mut Rng, joints: usize) -> ClipSpec {
    let own_times = rng.chance(0.5);
    let ends = [None, Some(Ends::Reflect), Some(Ends::ZeroSlope), Some(Ends::Wrap), Some(Ends::Phantom)];
    let mut tracks = Vec::new();
    for channel in Channel::ALL {
        let interpolation = if rng.chance(0.75) { Interpolation::CatmullRom } else { Interpolation::BSpline };
        let mut kind = Kind::new(channel, interpolation).max_deg([20.0, 60.0, 150.0][rng.below(3)]);
        kind.ends = ends[rng.below(ends.len())];
        let keys = 4 + rng.below(6);
        let clocks = [track(rng, "j0", kind, keys).times, track(rng, "j0", kind, keys).times];
        for j in 0..joints {
            if rng.chance(0.1) {
                continue;
            }
            let mut t = track(rng, &format!("j{j}"), kind, keys);
            // Most share a clock; the rest keep their own times (gathered lanes).
            if !own_times || rng.chance(0.5) {
                t.times = clocks[usize::from(rng.chance(0.3))].clone();
            }
            tracks.push(t);
        }
    }
    let joint = |j: usize| JointSpec {
        name: format!("j{j}"),
        parent: (j > 0).then(|| format!("j{}", (j - 1) / 2)),
        rest: Transform::IDENTITY,
        inverse_bind: None,
    };
    ClipSpec {
        name: "shared".into(),
        skeleton: Some(SkeletonSpec { joints: (0..joints).map(joint).collect() }),
        tracks,
        playback: Playback::Loop,
        ..Default::default()
    }
}

/// Request times: forward at 60 fps over three cycles, at and around each
/// loop seam, and at random.
fn times(rng: &mut Rng, clip: &Clip) -> Vec<f64> {
    let (a, d) = (clip.start() as f64, clip.duration() as f64);
    let mut t: Vec<f64> = (0..(3.0 * d * 60.0) as usize).map(|k| a + k as f64 / 60.0).collect();
    for cycle in 0..4 {
        let seam = a + cycle as f64 * d;
        t.extend([seam, seam - 1e-4, seam + 1e-4, seam - 1e-7, seam + 1e-7]);
    }
    t.extend((0..300).map(|_| rng.range(a - d, a + 4.0 * d)));
    t
}

fn close(a: Vec4, b: Vec4, tolerance: f32) -> bool {
    (a - b).abs().max_element() <= tolerance * a.abs().max_element().max(1.0)
}

#[test]
fn simd_groups_agree_with_the_scalar_kernel() {
    let mut rng = Rng::new(1919);
    let (mut lanes, mut worst) = (0, 0.0f32);
    for case in 0..60 {
        let joints = 2 + rng.below(14);
        let spec = shared_clip(&mut rng, joints);
        let (grouped, scalar) = (Clip::build(&spec).unwrap(), Clip::build_scalar(&spec).unwrap());
        assert_eq!(scalar.simd_lanes(), 0);
        lanes += grouped.simd_lanes();
        let (mut a, mut b) = (Sampler::new(), Sampler::new());
        for t in times(&mut rng, &grouped) {
            let options = SampleOptions::default();
            assert_eq!(grouped.sample(t, &options, &mut a), scalar.sample(t, &options, &mut b));
            let (p, q) = (a.pose(), b.pose());
            for j in 0..p.len() {
                let pairs = [
                    (p.translations[j].extend(0.0), q.translations[j].extend(0.0)),
                    (p.scales[j].extend(0.0), q.scales[j].extend(0.0)),
                    (Vec4::from(p.rotations[j]), Vec4::from(q.rotations[j])),
                ];
                for (x, y) in pairs {
                    worst = worst.max((x - y).abs().max_element());
                    assert!(close(x, y, 1e-6), "case {case}, joint {j}, t = {t}: {x} vs {y}");
                }
            }
        }
    }
    assert!(lanes > 500, "the clips must exercise the groups: {lanes} lanes");
    eprintln!("SIMD groups vs scalar kernel: worst difference {worst:e} over {lanes} lanes");
}

#[test]
fn grouped_sampling_allocates_nothing_once_warm() {
    let mut rng = Rng::new(20);
    let clip = Clip::build(&shared_clip(&mut rng, 12)).unwrap();
    assert!(clip.simd_lanes() > 0);
    let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
    clip.sample_into(clip.start(), &mut cursor, &mut pose);
    let times = times(&mut rng, &clip);
    let before = allocations();
    for &t in &times {
        clip.sample_into(t as f32, &mut cursor, &mut pose);
    }
    assert_eq!(allocations() - before, 0);
}

#[test]
fn a_masked_layer_writes_only_its_joints_lanes_and_each_as_the_whole_pose_does() {
    // A mask samples part of a pose (`sample_joints_into`): a group whose
    // lanes are partly kept must write those lanes, bit for bit as the
    // whole-pose sample, whichever lanes the mask leaves out.
    use anim::Motion;
    use anim::motion::{LayerSpec, MaskSpec, MotionOptions, MotionSpec};
    let mut rng = Rng::new(1920);
    for _ in 0..8 {
        let clip = Clip::build(&shared_clip(&mut rng, 13)).unwrap();
        assert!(clip.simd_lanes() > 0);
        let named = 1 + rng.below(12);
        let mask = MaskSpec { joints: vec![(format!("j{named}"), 1.0)], descendants: true, default: None };
        let layer = LayerSpec { mask: Some(mask), ..LayerSpec::new(&clip) };
        let motion =
            Motion::build(MotionSpec { layers: vec![layer], root_motion: None, ..Default::default() }).unwrap();
        let under = |mut j: usize| loop {
            if j == named {
                return true;
            }
            match clip.skeleton().parent(j) {
                Some(p) => j = p,
                None => return false,
            }
        };
        let (mut sampler, mut cursor, mut whole) = (anim::MotionSampler::new(), Cursor::default(), Pose::default());
        for t in times(&mut rng, &clip) {
            motion.sample(t, &MotionOptions::default(), &mut sampler);
            clip.sample_into(sampler.clip_times()[0], &mut cursor, &mut whole);
            let got = sampler.pose();
            for j in (0..clip.joint_count()).filter(|&j| under(j)) {
                assert_eq!(
                    (got.translations[j], got.rotations[j], got.scales[j]),
                    (whole.translations[j], whole.rotations[j], whole.scales[j]),
                    "joint {j} at {t} (mask on j{named})"
                );
            }
        }
    }
}
