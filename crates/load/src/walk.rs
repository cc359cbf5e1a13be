//! The motion `--motion foot-ik` streams play (issue 17): a walk in place
//! whose two feet two-bone IK plants on the ground every frame — what a game
//! does to keep a character's feet on uneven ground while the walk plays.
//!
//! The walk has two legs (hips → thigh → knee → foot, left and right) and a
//! spine from the hips making up the run's joint count, so a foot-ik run
//! streams as many joints as a clip run, with as many tracks (a rotation
//! per joint and the hips' translation): the two differ in the two solves
//! per tick (and the frames' `ik` reports). The hips bob, sway and turn and
//! the legs swing, so the legs' unsolved poses miss the targets by
//! centimetres and every solve does real work.

use glam::Vec3;
use serde_json::{Value, json};

use anim::ik::{IkSpec, TwoBoneSpec};
use formats::wire::ik::IkDoc;
use formats::wire::motion::{LayerDoc, MotionDoc};

/// The hips and the two legs: the fewest joints a walk has.
pub const MIN_JOINTS: usize = 7;
/// One walk cycle (two steps), looping.
pub const CYCLE_SECONDS: f64 = 1.2;
/// Each leg's `[thigh, knee, foot]`, left then right.
pub const LEGS: [[&str; 3]; 2] = [["thigh_l", "knee_l", "foot_l"], ["thigh_r", "knee_r", "foot_r"]];
/// Where the feet are planted (model space, y up): a step apart, left
/// forward, right back, 10 cm off the ground (the ankles).
///
/// Reachable over the whole cycle: a thigh sits at the hips plus
/// `R_y(yaw)·(±0.1, −0.05, 0)`, so with the hips at height 0.95 ± 0.03, x
/// within ±0.02 and a yaw within ±0.08 rad it is at height 0.87–0.93,
/// within 0.021 of x = ±0.1 and 0.008 of z = 0; its foot target is then
/// 0.77–0.84 away (√(0.83² + 0.128² + 0.021²) at most), inside the leg's
/// reach (|l1 − l2|, l1 + l2) = (0, 0.9) with 6 cm to spare — more than
/// the Catmull-Rom keys overshoot between them. So the two-bone solve
/// lands the foot on its target every frame and reports `converged`.
pub const FOOT_TARGETS: [[f32; 3]; 2] = [[0.1, 0.1, 0.12], [-0.1, 0.1, -0.12]];
/// Points well in front of the knees, so the knees bend forward.
pub const POLES: [[f32; 3]; 2] = [[0.1, 0.5, 1.0], [-0.1, 0.5, 1.0]];
/// Thigh and shin length.
pub const BONE: f64 = 0.45;

const HIPS_HEIGHT: f64 = 0.95;
/// The hips rise and fall by this, twice a cycle (once a step).
const BOB: f64 = 0.03;
const SWAY: f64 = 0.02;
const YAW: f64 = 0.08;
const HIP_WIDTH: f64 = 0.1;
const HIP_DROP: f64 = 0.05;
/// Amplitudes in radians: the thighs' swing, the knees' largest bend, the
/// ankles' roll, the spine's twist.
const SWING: f64 = 0.4;
const KNEE: f64 = 0.6;
const ANKLE: f64 = 0.2;
const TWIST: f64 = 0.05;
/// Keys per track, the last equal to the first (a seamless loop).
const KEYS: u32 = 31;

/// The walk's clip document: [`MIN_JOINTS`] leg joints and `joints − 7`
/// spine joints, `joints` rotation tracks and the hips' translation, 31
/// Catmull-Rom keys each over [`CYCLE_SECONDS`], looping.
pub fn walk_clip(joints: usize) -> Value {
    let spine = joints.saturating_sub(MIN_JOINTS);
    let mut skeleton = vec![joint("hips", None, [0.0, HIPS_HEIGHT, 0.0])];
    for (leg, side) in LEGS.iter().zip([1.0, -1.0]) {
        skeleton.push(joint(leg[0], Some("hips"), [side * HIP_WIDTH, -HIP_DROP, 0.0]));
        skeleton.push(joint(leg[1], Some(leg[0]), [0.0, -BONE, 0.0]));
        skeleton.push(joint(leg[2], Some(leg[1]), [0.0, -BONE, 0.0]));
    }
    let spine_name = |i: usize| format!("spine_{i}");
    for i in 0..spine {
        let parent = if i == 0 { "hips".to_owned() } else { spine_name(i - 1) };
        skeleton.push(joint(&spine_name(i), Some(&parent), [0.0, 0.1, 0.0]));
    }
    let mut tracks = vec![
        translation("hips", |p| [SWAY * p.sin(), HIPS_HEIGHT + BOB * (2.0 * p).cos(), 0.0]),
        rotation("hips", Axis::Y, |p| YAW * p.sin()),
    ];
    for (leg, shift) in LEGS.iter().zip([0.0, std::f64::consts::PI]) {
        tracks.push(rotation(leg[0], Axis::X, move |p| SWING * (p + shift).sin()));
        tracks.push(rotation(leg[1], Axis::X, move |p| KNEE * (1.0 + (p + shift + 1.0).sin()) / 2.0));
        tracks.push(rotation(leg[2], Axis::X, move |p| -ANKLE * (p + shift).sin()));
    }
    for i in 0..spine {
        tracks.push(rotation(&spine_name(i), Axis::Y, move |p| -TWIST * (p + 0.3 * i as f64).sin()));
    }
    json!({"name": format!("load-walk-{joints}"), "skeleton": {"joints": skeleton}, "tracks": tracks,
           "playback": "loop"})
}

/// The foot-ik motion over the uploaded walk `clip`: the walk, then one
/// `two_bone` constraint per leg planting its foot on [`FOOT_TARGETS`]
/// with the knee toward [`POLES`].
pub fn foot_ik(clip: &str) -> MotionDoc {
    let plant = |(leg, (target, pole)): (&[&str; 3], (&[f32; 3], &[f32; 3]))| {
        IkDoc::from_spec(&IkSpec::TwoBone(TwoBoneSpec {
            joints: leg.map(str::to_owned),
            target: Vec3::from(*target),
            pole: Some(Vec3::from(*pole)),
            weight: None,
        }))
    };
    let ik = LEGS.iter().zip(FOOT_TARGETS.iter().zip(&POLES)).map(plant).collect();
    MotionDoc {
        layers: vec![LayerDoc::new(clip)],
        root_motion: None,
        ik,
        springs: Vec::new(),
        spring_substep_hz: None,
        character: None,
        retarget: None,
    }
}

fn joint(name: &str, parent: Option<&str>, rest: [f64; 3]) -> Value {
    json!({"name": name, "parent": parent, "rest": {"translation": rest}})
}

#[derive(Clone, Copy)]
enum Axis {
    X,
    Y,
}

/// The key times of every track.
fn times() -> Vec<f64> {
    let last = f64::from(KEYS - 1);
    (0..KEYS).map(|k| f64::from(k) * CYCLE_SECONDS / last).collect()
}

/// The cycle's phase (radians) at each key.
fn phases() -> impl Iterator<Item = f64> {
    let last = f64::from(KEYS - 1);
    (0..KEYS).map(move |k| std::f64::consts::TAU * f64::from(k) / last)
}

/// A rotation track turning `joint` about `axis` by `angle(phase)`.
fn rotation(joint: &str, axis: Axis, angle: impl Fn(f64) -> f64) -> Value {
    let values: Vec<[f64; 4]> = phases()
        .map(|p| {
            let (s, c) = (angle(p) / 2.0).sin_cos();
            match axis {
                Axis::X => [s, 0.0, 0.0, c],
                Axis::Y => [0.0, s, 0.0, c],
            }
        })
        .collect();
    json!({"joint": joint, "channel": "rotation", "interpolation": "catmull_rom", "times": times(), "values": values})
}

/// A translation track of `joint` at `at(phase)`.
fn translation(joint: &str, at: impl Fn(f64) -> [f64; 3]) -> Value {
    let values: Vec<[f64; 3]> = phases().map(at).collect();
    json!({"joint": joint, "channel": "translation", "interpolation": "catmull_rom", "times": times(),
           "values": values})
}

#[cfg(test)]
mod tests {
    use glam::Vec3A;

    use super::*;
    use anim::ik::{IkKind, TWO_BONE_TOLERANCE};
    use anim::motion::{MotionOptions, MotionSampler};
    use anim::{Clip, Cursor, Motion, Pose, Space};
    use formats::wire::json::parse_clip;

    const JOINTS: usize = 20;
    /// Sample times: 2.5 cycles at 60 fps and a few off the grid.
    const FRAMES: usize = 180;

    fn walk(joints: usize) -> Clip {
        let (_, spec) = parse_clip(&serde_json::to_vec(&walk_clip(joints)).unwrap()).expect("a valid clip");
        Clip::build(&spec).expect("builds")
    }

    fn taus() -> impl Iterator<Item = f64> {
        (0..FRAMES).map(|i| i as f64 / 60.0).chain([0.0123, 0.6001, 1.1999, 7.77])
    }

    /// The walk's model pose at `tau` without IK.
    fn unsolved(clip: &Clip, tau: f64) -> Pose {
        let n = clip.joint_count();
        let (mut local, mut model) = (Pose::identity(n), Pose::identity(n));
        clip.sample_into((tau % CYCLE_SECONDS) as f32, &mut Cursor::default(), &mut local);
        clip.skeleton().to_model(&local, &mut model);
        model
    }

    fn index(clip: &Clip, name: &str) -> usize {
        clip.skeleton().index_of(name).unwrap_or_else(|| panic!("no {name}"))
    }

    #[test]
    fn the_walk_has_two_legs_and_the_asked_joints() {
        for joints in [MIN_JOINTS, JOINTS, 64] {
            let clip = walk(joints);
            assert_eq!(clip.joint_count(), joints);
            assert_eq!(clip.track_count(), joints + 1, "a rotation per joint and the hips' translation");
            assert!((f64::from(clip.duration()) - CYCLE_SECONDS).abs() < 1e-6);
            for [thigh, knee, foot] in LEGS {
                let s = clip.skeleton();
                let (t, k, f) = (index(&clip, thigh), index(&clip, knee), index(&clip, foot));
                assert_eq!((s.parent(t), s.parent(k), s.parent(f)), (Some(0), Some(t), Some(k)));
            }
        }
    }

    /// The comment on [`FOOT_TARGETS`], measured: at every sample the
    /// target is within the leg's reach (from the thigh's model position,
    /// with room), and the unsolved foot misses it by centimetres at some
    /// time (so the solve is real).
    #[test]
    fn the_targets_are_reachable_all_cycle_and_the_walk_misses_them() {
        let clip = walk(JOINTS);
        let reach = 2.0 * BONE as f32;
        for (leg, target) in LEGS.iter().zip(FOOT_TARGETS) {
            let (thigh, foot, target) = (index(&clip, leg[0]), index(&clip, leg[2]), Vec3A::from(target));
            let mut worst_miss = 0.0f32;
            for tau in taus() {
                let model = unsolved(&clip, tau);
                let d = (target - model.translations[thigh]).length();
                assert!((0.7..reach - 0.05).contains(&d), "{leg:?} at τ {tau}: the target is {d} away");
                worst_miss = worst_miss.max((target - model.translations[foot]).length());
            }
            assert!(worst_miss > 0.1, "{leg:?}: the walk's foot strays only {worst_miss} from its target");
        }
    }

    /// The motion as the server builds it (the JSON document through
    /// `MotionDoc`, the clip by id): every sample reports both two-bone
    /// constraints converged, and the feet's model positions, computed
    /// from the output pose, sit on the targets within the documented
    /// `1e-5·(l1 + l2)`.
    #[test]
    fn every_frame_plants_both_feet() {
        let clip = walk(JOINTS);
        let text = serde_json::to_string(&foot_ik("W")).unwrap();
        let spec = serde_json::from_str::<MotionDoc>(&text).unwrap().to_spec("/motion").unwrap();
        let spec = spec.try_map(|_, id| if id == "W" { Ok(&clip) } else { Err(id) }).unwrap();
        let motion = Motion::build(spec).expect("a valid motion");
        assert_eq!(motion.ik_report_count(), 2);
        let options = MotionOptions { space: Space::Model, ..MotionOptions::default() };
        let mut sampler = MotionSampler::new();
        let tolerance = TWO_BONE_TOLERANCE * 2.0 * BONE as f32;
        for tau in taus() {
            motion.sample(tau, &options, &mut sampler);
            let reports = sampler.ik_reports();
            assert_eq!(reports.len(), 2, "τ {tau}");
            for (r, (leg, target)) in reports.iter().zip(LEGS.iter().zip(FOOT_TARGETS)) {
                assert_eq!(r.kind, IkKind::TwoBone);
                assert!(r.converged && r.residual <= tolerance, "{leg:?} at τ {tau}: {r:?}");
                let foot = sampler.pose().translations[index(&clip, leg[2])];
                let miss = (foot - Vec3A::from(target)).length();
                assert!(miss <= tolerance, "{leg:?} at τ {tau}: the foot is {miss} from its target");
            }
        }
    }

    #[test]
    fn the_motion_document_names_the_legs() {
        let v = serde_json::to_value(foot_ik("W")).unwrap();
        assert_eq!(v["layers"], json!([{"clip": "W", "weight": 1.0, "mode": "blend", "offset": 0.0, "speed": 1.0}]));
        for (i, leg) in LEGS.iter().enumerate() {
            assert_eq!(v["ik"][i]["kind"], "two_bone");
            assert_eq!(v["ik"][i]["joints"], json!(leg));
            assert_eq!(v["ik"][i]["target"], json!(FOOT_TARGETS[i]));
            assert_eq!(v["ik"][i]["pole"], json!(POLES[i]));
        }
    }
}
