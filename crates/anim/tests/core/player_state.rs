//! A [`Player`]'s state taken and put back (`Player::state`,
//! `Player::from_state`): a player restored from the state of another at
//! any tick steps on bit for bit as the original — through crossfades
//! nested in crossfades, layer ramps, sync-group phases, seeks, pauses,
//! reversed speed, root motion and warm-started IK chains — and a state
//! that does not fit its motion is refused.

use std::sync::Arc;

use anim::ik::{ChainSpec, EffectorSpec, IkLimits, IkReport, IkSpec, build_constraints};
use anim::motion::{LayerSpec, MotionOptions, MotionSpec, Player, PlayerError, RootMotion, RootMotionSpec};
use anim::{
    Channel, Clip, ClipSpec, Ease, Interpolation, Keys, Motion, Playback, Pose, SkeletonSpec, Space, TrackSpec,
};
use glam::{Quat, Vec3, Vec4};

type Shared<'a> = Arc<Motion<&'a Clip>>;

/// hips → thigh → knee → foot; hips travel to `to` and turn by `turn`
/// about y over `duration`, looping (root motion with a turn).
fn leg(duration: f32, to: Vec3, turn: f32) -> Clip {
    let joint = crate::rest_joint;
    let joints = vec![
        joint("hips", None, [0.0, 0.9, 0.0]),
        joint("thigh", Some("hips"), [0.1, 0.0, 0.0]),
        joint("knee", Some("thigh"), [0.0, -0.45, 0.0]),
        joint("foot", Some("knee"), [0.0, -0.45, 0.0]),
    ];
    let base = Vec3::new(0.0, 0.9, 0.0);
    let t = TrackSpec::new(
        "hips",
        Channel::Translation,
        Interpolation::Linear,
        vec![0.0, duration],
        Keys::Vec3(vec![base, base + to]),
    );
    let q = |a: f32| Vec4::from(Quat::from_rotation_y(a));
    let r = TrackSpec::new(
        "hips",
        Channel::Rotation,
        Interpolation::Linear,
        vec![0.0, duration],
        Keys::Vec4(vec![q(0.0), q(turn)]),
    );
    let knee = TrackSpec::new(
        "knee",
        Channel::Rotation,
        Interpolation::Linear,
        vec![0.0, duration * 0.5, duration],
        Keys::Vec4(vec![
            Vec4::from(Quat::IDENTITY),
            Vec4::from(Quat::from_rotation_x(0.7)),
            Vec4::from(Quat::IDENTITY),
        ]),
    );
    let spec = ClipSpec {
        name: "leg".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks: vec![t, r, knee],
        playback: Playback::Loop,
        ..Default::default()
    };
    Clip::build(&spec).expect("the leg builds")
}

/// Two layers in one sync group (phases accumulate tick by tick), with root motion.
fn synced<'a>(a: &'a Clip, b: &'a Clip, weight: f32) -> Shared<'a> {
    let layer = |clip, weight| LayerSpec { sync: Some("gait".into()), weight, ..LayerSpec::new(clip) };
    let spec = MotionSpec {
        layers: vec![layer(a, 1.0), layer(b, weight)],
        root_motion: Some(RootMotionSpec::default()),
        ..Default::default()
    };
    Arc::new(Motion::build(spec).expect("the motion builds"))
}

fn chain(clip: &Clip, target: Vec3) -> Vec<anim::ik::IkConstraint> {
    let spec = IkSpec::Chain(ChainSpec {
        effectors: vec![EffectorSpec { joint: "foot".into(), target, tip: None }],
        joints: None,
        limits: Vec::new(),
        max_iterations: Some(6),
        tolerance: None,
        weight: None,
    });
    build_constraints(&[spec], clip.skeleton(), &IkLimits::default()).expect("the chain builds")
}

/// What one tick shows, compared bit for bit.
#[derive(Debug, Clone, PartialEq)]
struct Frame {
    pose: Pose,
    clip_time: f32,
    root: Option<RootMotion>,
    ik: Vec<IkReport>,
    alpha: f32,
    motion_time: f64,
}

/// A broadcast's worth of changes: the controls at tick `k`, then the
/// stream time `s` the tick shows (pause: the same `s`; reverse: falling).
struct Script<'a> {
    motions: Vec<Shared<'a>>,
    clips: &'a [Clip],
}

impl<'a> Script<'a> {
    const TICKS: u32 = 240;
    const DT: f64 = 1.0 / 30.0;

    fn stream_time(k: u32) -> f64 {
        let k = f64::from(k);
        match k {
            _ if k < 100.0 => k * Self::DT,
            _ if k < 120.0 => 100.0 * Self::DT, // paused
            _ if k < 170.0 => 100.0 * Self::DT - (k - 120.0) * Self::DT * 0.5, // speed −0.5
            _ => 100.0 * Self::DT - 25.0 * Self::DT + (k - 170.0) * Self::DT * 2.0, // speed 2
        }
    }

    fn controls(&self, k: u32, player: &mut Player<&'a Clip>) {
        let m = &self.motions;
        match k {
            10 => player.ramp(1, 0.2, 0.4).unwrap(),
            30 => player.crossfade(Arc::clone(&m[1]), 0.6, Ease::EaseInOut).unwrap(),
            38 => player.crossfade(Arc::clone(&m[2]), 0.5, Ease::Linear).unwrap(),
            45 => player.set_ik(chain(&self.clips[0], Vec3::new(0.3, 0.2, 0.1))),
            60 => player.seek(0.25),
            64 => player.ramp(0, 0.5, 0.3).unwrap(),
            110 => player.crossfade(Arc::clone(&m[0]), 0.4, Ease::EaseIn).unwrap(),
            150 => player.set_ik(chain(&self.clips[0], Vec3::new(-0.2, 0.3, 0.2))),
            175 => player.seek(1.5),
            180 => player.crossfade(Arc::clone(&m[1]), 1.0, Ease::EaseOut).unwrap(),
            _ => {}
        }
    }

    fn step(&self, k: u32, player: &mut Player<&'a Clip>) -> Frame {
        self.controls(k, player);
        let options = MotionOptions { ease: Ease::Linear, space: Space::Model };
        let clip_time = player.sample(Self::stream_time(k), &options);
        Frame {
            pose: player.pose().clone(),
            clip_time,
            root: player.root_motion(),
            ik: player.ik_reports().to_vec(),
            alpha: player.alpha(),
            motion_time: player.motion_time(),
        }
    }
}

#[test]
fn a_player_restored_at_any_tick_steps_on_bit_for_bit() {
    let clips = [leg(1.0, Vec3::new(1.0, 0.0, 0.2), 0.4), leg(0.6, Vec3::new(0.0, 0.0, 1.2), -0.9)];
    let motions =
        vec![synced(&clips[0], &clips[1], 0.6), synced(&clips[1], &clips[0], 0.3), synced(&clips[0], &clips[0], 1.0)];
    let script = Script { motions, clips: &clips };
    let mut player = Player::new(Arc::clone(&script.motions[0]));
    let mut frames = Vec::new();
    let mut states = Vec::new();
    for k in 0..Script::TICKS {
        frames.push(script.step(k, &mut player));
        states.push(player.state());
    }
    assert!(frames.iter().any(|f| f.alpha < 1.0), "the script fades");
    assert!(frames.iter().any(|f| f.ik.iter().any(|r| r.iterations > 0)), "the script solves IK");
    for checkpoint in [0, 9, 10, 31, 40, 47, 61, 105, 115, 151, 176, 181, 200] {
        let mut restored = Player::from_state(states[checkpoint as usize].clone()).expect("the state fits");
        for k in checkpoint + 1..Script::TICKS {
            let got = script.step(k, &mut restored);
            assert_eq!(got, frames[k as usize], "tick {k} after a restore at tick {checkpoint}");
        }
    }
}

#[test]
fn a_state_that_does_not_fit_its_motion_is_refused() {
    let clip = leg(1.0, Vec3::X, 0.0);
    let motion = synced(&clip, &clip, 0.5);
    let mut player = Player::new(Arc::clone(&motion));
    player.sample(0.0, &MotionOptions::default());
    let mut state = player.state();
    state.top.weights.pop();
    assert!(matches!(Player::from_state(state), Err(PlayerError::State(_))));
    let mut state = player.state();
    state.top.phases.clear();
    assert!(matches!(Player::from_state(state), Err(PlayerError::State(_))));
    let mut state = player.state();
    state.top.roots.push(None);
    assert!(matches!(Player::from_state(state), Err(PlayerError::State(_))));
}
