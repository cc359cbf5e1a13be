//! The hot path allocates nothing (sampling into caller-owned
//! buffers). Counted with the per-thread counting allocator of `main.rs`,
//! so tests on other threads cannot disturb the count.

use std::sync::Arc;

use anim::motion::{LayerSpec, MaskSpec, MotionOptions, MotionSpec, Player};
use anim::{Clip, Cursor, Ease, Motion, Playback, Pose, SampleOptions, Sampler, Space};
use glam::Mat4;

use crate::random::{Rng, skeleton_clip};
use crate::{allocations, live_bytes};

/// Clips with every interpolation mode, some with hierarchies.
fn clips() -> Vec<Clip> {
    let mut rng = Rng::new(700);
    (0..8).map(|_| Clip::build(&skeleton_clip(&mut rng, 8)).unwrap()).collect()
}

/// Times across and beyond each clip, forwards, then jumping about.
fn times(clip: &Clip) -> Vec<f64> {
    let (a, b) = (clip.start() as f64, clip.end() as f64);
    let mut t: Vec<f64> = (0..=100).map(|k| a - 0.5 + (b - a + 1.0) * k as f64 / 100.0).collect();
    t.extend((0..50).map(|k| b + 3.7 - (k as f64 * 0.731) % (b - a + 5.0)));
    t
}

/// Runs `f` and returns how many allocations it made on this thread.
fn count(f: impl FnOnce()) -> u64 {
    let before = allocations();
    f();
    allocations() - before
}

#[test]
fn the_counter_sees_allocations() {
    assert!(count(|| drop(std::hint::black_box(vec![1u8; 10]))) >= 1, "a test that cannot fail is a defect");
}

#[test]
fn sample_into_allocates_nothing_once_warm() {
    for clip in clips() {
        let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
        clip.sample_into(clip.start(), &mut cursor, &mut pose); // warm: buffers take their size
        let times = times(&clip);
        let n = count(|| {
            for &t in &times {
                clip.sample_into(t as f32, &mut cursor, &mut pose);
            }
        });
        assert_eq!(n, 0, "sample_into allocated {n} times over {} samples", times.len());
    }
}

#[test]
fn sample_allocates_nothing_once_warm_in_both_spaces() {
    for clip in clips() {
        let mut sampler = Sampler::new();
        let times = times(&clip);
        for space in [Space::Local, Space::Model] {
            for playback in [Playback::Once, Playback::Loop, Playback::PingPong] {
                let options = SampleOptions { playback: Some(playback), ease: Ease::EaseInOut, space };
                clip.sample(0.0, &options, &mut sampler); // warm
                let n = count(|| {
                    for &t in &times {
                        clip.sample(t, &options, &mut sampler);
                        std::hint::black_box(sampler.pose());
                    }
                });
                assert_eq!(n, 0, "sample ({space:?}, {playback:?}) allocated {n} times");
            }
        }
    }
}

#[test]
fn matrices_allocate_nothing_once_warm() {
    for clip in clips() {
        let mut sampler = Sampler::new();
        let mut out: Vec<Mat4> = Vec::new();
        let options = SampleOptions::default();
        clip.matrices(0.0, &options, false, &mut sampler, &mut out); // warm
        let times = times(&clip);
        let n = count(|| {
            for &t in &times {
                clip.matrices(t, &options, false, &mut sampler, &mut out);
            }
        });
        assert_eq!(n, 0, "matrices allocated {n} times");
    }
}

/// Walk and run (`run_weight`) in one sync group under a wave masked to
/// `j1` and its descendants: issue 16's three layers.
fn three_layers(clips: &[Clip], run_weight: f32, wave_offset: f64) -> Arc<Motion<&Clip>> {
    let synced = |clip| LayerSpec { sync: Some("locomotion".into()), ..LayerSpec::new(clip) };
    let upper = MaskSpec { joints: vec![("j1".into(), 1.0)], descendants: true, default: None };
    let layers = vec![
        synced(&clips[0]),
        LayerSpec { weight: run_weight, ..synced(&clips[1]) },
        LayerSpec { mask: Some(upper), offset: wave_offset, ..LayerSpec::new(&clips[2]) },
    ];
    Arc::new(Motion::build(MotionSpec { layers, root_motion: None, ..Default::default() }).unwrap())
}

/// Allocations and bytes still held after `ticks` ticks of `player` 1/60 s
/// apart from `from`, alternating local and model space.
fn count_ticks(player: &mut Player<&Clip>, from: f64, ticks: u32) -> (u64, i64) {
    let (before, bytes) = (allocations(), live_bytes());
    for k in 0..ticks {
        let space = if k % 2 == 0 { Space::Local } else { Space::Model };
        player.sample(from + f64::from(k) / 60.0, &MotionOptions { ease: Ease::Linear, space });
        std::hint::black_box(player.pose());
    }
    (allocations() - before, live_bytes() - bytes)
}

#[test]
fn a_warm_player_allocates_nothing_per_tick_through_a_ramp_and_mid_crossfade() {
    let mut rng = Rng::new(1616);
    let clips: Vec<Clip> = (0..3).map(|_| Clip::build(&skeleton_clip(&mut rng, 16)).unwrap()).collect();
    let mut player = Player::new(three_layers(&clips, 0.3, 0.0));
    count_ticks(&mut player, 0.0, 3); // warm: buffers take their size
    player.ramp(1, 0.9, 1.0).unwrap();
    let ramping = count_ticks(&mut player, 3.0 / 60.0, 30);
    assert_eq!(ramping, (0, 0), "a three-layer motion mid-ramp: (allocations, bytes) over 30 ticks");

    // The crossfade itself may allocate (the new motion's buffers); its first ticks size them.
    player.crossfade(three_layers(&clips, 0.6, 0.4), 10.0, Ease::EaseInOut).unwrap();
    count_ticks(&mut player, 33.0 / 60.0, 3);
    let fading = count_ticks(&mut player, 36.0 / 60.0, 30);
    assert_eq!(fading, (0, 0), "mid-crossfade: (allocations, bytes) over 30 ticks");
    assert_eq!(player.fades(), 1);
    assert!(player.alpha() > 0.0 && player.alpha() < 1.0, "still mid-fade: α = {}", player.alpha());
}

#[test]
fn a_warm_retargeter_and_foot_planter_allocate_nothing_per_pose() {
    use crate::character::reference::{random_pose, random_rig};
    use anim::character::{FeetOptions, FootPlanter, RetargetOptions, Retargeter, Rig, Translation};
    let mut rng = Rng::new(3131);
    for translation in [Translation::Hips, Translation::None, Translation::All] {
        let (source, source_roles) = random_rig(&mut rng, true);
        let (target, target_roles) = random_rig(&mut rng, true);
        let (source_rig, target_rig) = (Rig::at_rest(&source, &source_roles), Rig::at_rest(&target, &target_roles));
        let mut retargeter = Retargeter::new(source_rig, target_rig, RetargetOptions { translation }).unwrap();
        let poses: Vec<Pose> = (0..50).map(|_| random_pose(&mut rng, &source, 2.0, true)).collect();
        // Thresholds no foot exceeds: both legs are solved every frame.
        let always = FeetOptions { contact_height: f32::MAX, contact_speed: f32::MAX };
        let mut planter = FootPlanter::new(&source_roles, &target_roles, [0.0; 2], always);
        let mut out = Pose::default();
        retargeter.retarget(&poses[0], &mut out); // warm: the output and the solver take their size
        planter.plant(&retargeter, None, &target, &mut out);
        let (before, bytes) = (allocations(), live_bytes());
        for pose in &poses {
            retargeter.retarget(pose, &mut out);
            planter.plant(&retargeter, Some(1.0 / 60.0), &target, &mut out);
            std::hint::black_box(&out);
        }
        assert_eq!(planter.reports().iter().filter(|r| r.planted).count(), 2);
        assert_eq!((allocations() - before, live_bytes() - bytes), (0, 0), "{translation:?}: (allocations, bytes)");
    }
}
