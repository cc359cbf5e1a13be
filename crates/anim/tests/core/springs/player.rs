//! Springs on a motion and its stream player (docs/springs.md, “Time”):
//! frames at any rate agree at shared instants, a restored player steps on
//! bit for bit, a seek or `reset_springs` shows the rest pose, a stateless
//! pose is the frame of a stream started a warmup before, and a motion
//! without chains is exactly the layered pose.

use std::sync::Arc;

use anim::TrackSpec;
use anim::motion::{LayerSpec, MotionOptions, MotionSpec, Player};
use anim::spring::{ChainSpec, SpringsSpec};
use anim::{Channel, Clip, ClipSpec, Interpolation, Keys, Motion, MotionSampler, Playback, Pose, SkeletonSpec, Space};
use glam::{Quat, Vec3};

/// `body` swinging along x (0 → 0.3 → 0 over 1 s, looping) and turning;
/// a tail of three 0.1 m bones behind it.
pub(super) fn swinging() -> Clip {
    let joint = crate::rest_joint;
    let joints = vec![
        joint("body", None, [0.0, 1.0, 0.0]),
        joint("tail0", Some("body"), [0.0, 0.0, -0.1]),
        joint("tail1", Some("tail0"), [0.0, 0.0, -0.1]),
        joint("tail2", Some("tail1"), [0.0, 0.0, -0.1]),
        joint("tip", Some("tail2"), [0.0, 0.0, -0.1]),
    ];
    let at = |x: f32| Vec3::new(x, 1.0, 0.0);
    let moves = Keys::Vec3(vec![at(0.0), at(0.3), at(0.0)]);
    let turn = |a: f32| glam::Vec4::from(Quat::from_rotation_y(a));
    let turns = Keys::Vec4(vec![turn(0.0), turn(0.6), turn(0.0)]);
    let times = vec![0.0, 0.5, 1.0];
    let spec = ClipSpec {
        name: "swing".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks: vec![
            TrackSpec::new("body", Channel::Translation, Interpolation::Linear, times.clone(), moves),
            TrackSpec::new("body", Channel::Rotation, Interpolation::Linear, times, turns),
        ],
        playback: Playback::Loop,
        ..Default::default()
    };
    Clip::build(&spec).unwrap()
}

const TAIL: [usize; 3] = [1, 2, 3];

pub(super) fn motion(clip: &Clip, springs: bool) -> Arc<Motion<&Clip>> {
    layer_motion(clip, springs, 0.0, 1.0)
}

fn chain() -> ChainSpec {
    let mut chain = ChainSpec::new("tail", &["tail0", "tail1", "tail2", "tip"]);
    chain.params.gravity = Vec3::new(0.0, -9.81, 0.0);
    chain
}

/// One layer of `clip` at `offset` and `speed`, with the tail's chain or none.
fn layer_motion(clip: &Clip, springs: bool, offset: f64, speed: f64) -> Arc<Motion<&Clip>> {
    let chains = if springs { vec![chain()] } else { Vec::new() };
    let spec = MotionSpec {
        layers: vec![LayerSpec { offset, speed, ..LayerSpec::new(clip) }],
        springs: SpringsSpec { chains, ..SpringsSpec::default() },
        ..MotionSpec::default()
    };
    Arc::new(Motion::build(spec).unwrap())
}

fn options(space: Space) -> MotionOptions {
    MotionOptions { space, ..MotionOptions::default() }
}

/// Model positions of every joint.
pub(super) fn model(clip: &Clip, local: &Pose) -> Vec<Vec3> {
    let mut out = Pose::default();
    clip.skeleton().to_model(local, &mut out);
    out.translations.iter().map(|t| Vec3::from(*t)).collect()
}

pub(super) fn farthest(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter().zip(b).map(|(p, q)| p.distance(*q)).fold(0.0, f32::max)
}

/// A stream of `motion` at `fps` from motion time `start`: each tick's local pose.
pub(super) fn stream(motion: &Arc<Motion<&Clip>>, fps: u32, start: f64, ticks: u32) -> Vec<Pose> {
    let mut player = Player::new(Arc::clone(motion));
    (0..=ticks)
        .map(|n| {
            let clock = f64::from(n) / f64::from(fps);
            player.sample_clocked(start + clock, clock, &options(Space::Local));
            player.pose().clone()
        })
        .collect()
}

#[test]
fn stream_frames_at_any_rate_agree_at_shared_instants() {
    let clip = swinging();
    let sprung = motion(&clip, true);
    let rates = [30u32, 60, 120, 24];
    let runs: Vec<Vec<Pose>> = rates.iter().map(|&fps| stream(&sprung, fps, 0.0, 2 * fps)).collect();
    for k in 1..=12u32 {
        let at: Vec<Vec<Vec3>> =
            rates.iter().zip(&runs).map(|(fps, run)| model(&clip, &run[(k * fps / 6) as usize])).collect();
        for other in &at[1..] {
            assert!(farthest(&at[0], other) <= 1e-5 * 0.5, "at {k}/6 s: {:?} vs {other:?}", at[0]);
        }
        let tail_turned = TAIL.iter().any(|&j| runs[0][(k * 5) as usize].rotations[j] != Quat::IDENTITY);
        assert!(tail_turned, "the tail swings at {k}/6 s");
    }
}

#[test]
fn a_restored_player_steps_on_bit_for_bit() {
    let clip = swinging();
    let sprung = motion(&clip, true);
    let mut player = Player::new(Arc::clone(&sprung));
    let tick = |player: &mut Player<&Clip>, n: u32| {
        let clock = f64::from(n) / 30.0;
        // Paused from tick 10 to 20: the motion time holds, the chain settles.
        let s = f64::from(n.min(10) + n.saturating_sub(20)) / 30.0;
        player.sample_clocked(s, clock, &options(Space::Model));
        player.pose().clone()
    };
    for n in 0..25 {
        tick(&mut player, n);
    }
    let mut restored = Player::from_state(player.state()).unwrap();
    for n in 25..60 {
        assert_eq!(tick(&mut player, n), tick(&mut restored, n), "tick {n}");
    }
}

#[test]
fn a_reset_or_a_seek_shows_the_rest_pose_on_its_tick_and_the_chain_runs_on() {
    let clip = swinging();
    let sprung = motion(&clip, true);
    let mut player = Player::new(Arc::clone(&sprung));
    let tick = |player: &mut Player<&Clip>, n: u32| {
        let s = f64::from(n) / 30.0;
        player.sample_clocked(s, s, &options(Space::Local));
        TAIL.map(|j| player.pose().rotations[j])
    };
    assert_eq!(tick(&mut player, 0), [Quat::IDENTITY; 3], "a stream starts at rest");
    for n in 1..10 {
        assert_ne!(tick(&mut player, n), [Quat::IDENTITY; 3], "tick {n} swings");
    }
    player.reset_springs();
    assert_eq!(tick(&mut player, 10), [Quat::IDENTITY; 3], "reset_springs' tick is the rest pose");
    assert_ne!(tick(&mut player, 11), [Quat::IDENTITY; 3], "and the chain runs on");
    player.seek(0.2);
    assert_eq!(tick(&mut player, 12), [Quat::IDENTITY; 3], "a seek's tick is the rest pose");
    assert_ne!(tick(&mut player, 13), [Quat::IDENTITY; 3]);
}

#[test]
fn a_pose_is_the_frame_of_a_stream_started_a_warmup_before() {
    let clip = swinging();
    let sprung = motion(&clip, true);
    for tau in [1.0, 1.7, 2.35] {
        let mut sampler = MotionSampler::new();
        sprung.sample(tau, &options(Space::Local), &mut sampler);
        let posed = model(&clip, sampler.local());
        let run = stream(&sprung, 60, tau - 1.0, 60);
        let framed = model(&clip, &run[60]);
        assert!(farthest(&posed, &framed) <= 1e-5 * 0.5, "at {tau}: {posed:?} vs {framed:?}");
        // Samples in order continue the one run: the next at τ + 0.5 is the stream 30 ticks on.
        sprung.sample(tau + 0.5, &options(Space::Local), &mut sampler);
        let later = stream(&sprung, 60, tau - 1.0, 90);
        assert!(farthest(&model(&clip, sampler.local()), &model(&clip, &later[90])) <= 1e-5 * 0.5);
    }
}

#[test]
fn without_chains_the_motion_is_the_layered_pose_and_chains_turn_only_their_joints() {
    let clip = swinging();
    let (plain, sprung) = (motion(&clip, false), motion(&clip, true));
    let (mut a, mut b) = (MotionSampler::new(), MotionSampler::new());
    let mut direct = (anim::Cursor::default(), Pose::default());
    // Within the clip's first cycle, where its clip time is the motion time.
    for t in [0.1, 0.45, 0.8, 0.95] {
        plain.sample(t, &options(Space::Local), &mut a);
        clip.sample_into(t as f32, &mut direct.0, &mut direct.1);
        assert_eq!(a.local(), &direct.1, "no chains: the clip's own pose, bit for bit at {t}");
        sprung.sample(t, &options(Space::Local), &mut b);
        for j in 0..clip.joint_count() {
            let changed = (a.local().rotations[j], a.local().translations[j])
                != (b.local().rotations[j], b.local().translations[j]);
            assert_eq!(changed, TAIL.contains(&j), "joint {j} at {t}");
        }
    }
}

/// The crossfade of the tests below: from the swinging motion to the same
/// clip a third of a cycle on and 1.5 times as fast (the same chains, so
/// they run on), asked for just before the tick at 0.5 s, over 0.75 s.
const FADE_AT: f64 = 0.5;
const FADE_FOR: f64 = 0.75;
const FADE_EASE: anim::Ease = anim::Ease::EaseInOut;
const HURRIED: (f64, f64) = (0.3, 1.5);

/// A stream of the swinging motion at `fps` for `ticks`, crossfading as
/// above: each tick's local pose.
fn fading_stream(clip: &Clip, fps: u32, ticks: u32) -> Vec<Pose> {
    let mut player = Player::new(motion(clip, true));
    let to = layer_motion(clip, true, HURRIED.0, HURRIED.1);
    (0..=ticks)
        .map(|n| {
            if f64::from(n) == FADE_AT * f64::from(fps) {
                player.crossfade(Arc::clone(&to), FADE_FOR, FADE_EASE).unwrap();
            }
            let s = f64::from(n) / f64::from(fps);
            player.sample_clocked(s, s, &options(Space::Local));
            player.pose().clone()
        })
        .collect()
}

#[test]
fn during_a_crossfade_stream_frames_at_any_rate_agree_at_shared_instants() {
    let clip = swinging();
    let rates = [30u32, 120, 60, 24];
    let runs: Vec<Vec<Pose>> = rates.iter().map(|&fps| fading_stream(&clip, fps, 2 * fps)).collect();
    // Every 1/6 s from the fade's start to past its end (0.5 s to 1.5 s).
    for k in 3..=9u32 {
        let at: Vec<Vec<Vec3>> =
            rates.iter().zip(&runs).map(|(fps, run)| model(&clip, &run[(k * fps / 6) as usize])).collect();
        for (fps, other) in rates.iter().zip(&at).skip(1) {
            assert!(farthest(&at[0], other) <= 1e-5 * 0.5, "at {k}/6 s, 30 vs {fps} fps: {:?} vs {other:?}", at[0]);
        }
    }
}

/// The swinging clip in `f64` for the reference.
fn reference_rig(clip: &Clip) -> super::reference::RefSkeleton {
    let skeleton = clip.skeleton();
    let rest = skeleton.rest();
    super::reference::RefSkeleton {
        names: skeleton.names().to_vec(),
        parents: (0..skeleton.len()).map(|j| skeleton.parent(j)).collect(),
        rest_t: rest.translations.iter().map(|t| Vec3::from(*t).as_dvec3()).collect(),
        rest_q: rest.rotations.iter().map(|q| q.as_dquat()).collect(),
    }
}

/// The clip's keyed pose at clip time `t` (looping), in `f64`.
fn keyed(clip: &Clip, t: f64) -> super::reference::RefPose {
    let (mut cursor, mut pose) = (anim::Cursor::default(), Pose::default());
    clip.sample_into(t.rem_euclid(1.0) as f32, &mut cursor, &mut pose);
    super::reference::RefPose {
        t: pose.translations.iter().map(|t| Vec3::from(*t).as_dvec3()).collect(),
        q: pose.rotations.iter().map(|q| q.as_dquat()).collect(),
    }
}

/// The crossfade's input at stream time `s`, mixed in `f64`: the swinging
/// motion at `s`, the hurried one at `s − 0.5`, `α` the eased share of
/// the fade (docs/motion.md, “Crossfades”).
fn faded(clip: &Clip, s: f64) -> super::reference::RefPose {
    let from = keyed(clip, s);
    if s <= FADE_AT {
        return from;
    }
    let to = keyed(clip, HURRIED.0 + HURRIED.1 * (s - FADE_AT));
    let x = ((s - FADE_AT) / FADE_FOR).min(1.0);
    let alpha = x * x * (3.0 - 2.0 * x);
    let t = from.t.iter().zip(&to.t).map(|(a, b)| a.lerp(*b, alpha)).collect();
    let q = from.q.iter().zip(&to.q).map(|(a, b)| a.slerp(*b, alpha)).collect();
    super::reference::RefPose { t, q }
}

#[test]
fn a_crossfade_s_substeps_see_the_mix_at_their_own_time_as_an_f64_run_does() {
    let clip = swinging();
    let rig = reference_rig(&clip);
    let hz = 120.0;
    let mut reference = super::reference::RefSprings::new(&rig, &[chain()], hz, &faded(&clip, 0.0));
    let fps = 30u32;
    let frames = fading_stream(&clip, fps, 2 * fps);
    let mut k = 1u32;
    for (n, frame) in frames.iter().enumerate().skip(1) {
        let s = n as f64 / f64::from(fps);
        // Every substep up to the frame, each on the mix at its own time.
        while f64::from(k) / hz <= s + 1e-9 {
            reference.step(&faded(&clip, f64::from(k) / hz));
            k += 1;
        }
        let expected = reference.positions(&faded(&clip, s));
        let core: Vec<Vec3> = model(&clip, frame);
        for &j in &[2usize, 3, 4] {
            let error = (core[j].as_dvec3() - expected[j]).length();
            assert!(error <= 2e-5, "frame {n} ({s} s), joint {j}: {:?} vs {:?} ({error} m)", core[j], expected[j]);
        }
    }
}
