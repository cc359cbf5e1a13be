//! Composition in the core (docs/motion.md): one full-weight layer is the clip bit
//! for bit; blends, masks, additive layers and sync groups against values
//! computed by hand; a full-weight masked layer is its clip where it covers
//! and the layers beneath elsewhere, bit for bit (the layers it hides are
//! not sampled there); refusals with their paths; no allocation once warm.

use glam::{Quat, Vec3, Vec4};
use std::sync::Arc;

use anim::motion::{LayerMode, LayerSpec, MaskSpec, MotionOptions, MotionSpec, Player};
use anim::{
    Channel, Clip, ClipSpec, Cursor, Ease, Interpolation, JointSpec, Keys, Motion, MotionSampler, Playback, Pose,
    SampleOptions, Sampler, Skeleton, SkeletonSpec, Space, TrackSpec, Transform,
};

use crate::allocations;
use crate::random::{Rng, skeleton_clip};

fn motion(layers: Vec<LayerSpec<&Clip>>) -> Motion<&Clip> {
    Motion::build(MotionSpec { layers, root_motion: None, ..Default::default() }).unwrap()
}

/// `hips → spine → arm`, plus `leg` under `hips`; `hips` moves linearly
/// along x from `from` to `to` over `[0, duration]`; `arm` turns about z
/// by `turn` radians at every time.
pub fn body(name: &str, duration: f32, from: f32, to: f32, turn: f32) -> Clip {
    let joint = |name: &str, parent: Option<&str>| JointSpec {
        name: name.into(),
        parent: parent.map(Into::into),
        rest: Transform { translation: Vec3::new(0.0, 1.0, 0.0), ..Transform::IDENTITY },
        inverse_bind: None,
    };
    let joints = vec![
        joint("hips", None),
        joint("spine", Some("hips")),
        joint("arm", Some("spine")),
        joint("leg", Some("hips")),
    ];
    let hips = TrackSpec::new(
        "hips",
        Channel::Translation,
        Interpolation::Linear,
        vec![0.0, duration],
        Keys::Vec3(vec![Vec3::new(from, 0.0, 0.0), Vec3::new(to, 0.0, 0.0)]),
    );
    let q = Quat::from_rotation_z(turn);
    let arm =
        TrackSpec::new("arm", Channel::Rotation, Interpolation::Linear, vec![0.0], Keys::Vec4(vec![Vec4::from(q)]));
    Clip::build(&ClipSpec {
        name: name.into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks: vec![hips, arm],
        events: vec![],
        playback: Playback::Loop,
        ..Default::default()
    })
    .unwrap()
}

fn sample(m: &Motion<&Clip>, tau: f64) -> MotionSampler {
    let mut sampler = MotionSampler::new();
    m.sample(tau, &MotionOptions::default(), &mut sampler);
    sampler
}

#[test]
fn one_full_weight_layer_is_the_clip_bit_for_bit() {
    let mut rng = Rng::new(616);
    for _ in 0..12 {
        let clip = Clip::build(&skeleton_clip(&mut rng, 9)).unwrap();
        for playback in [Playback::Once, Playback::Loop, Playback::PingPong] {
            let m = motion(vec![LayerSpec { playback: Some(playback), ..LayerSpec::new(&clip) }]);
            for space in [Space::Local, Space::Model] {
                for ease in [Ease::Linear, Ease::EaseInOut] {
                    let (mut plain, mut composed) = (Sampler::new(), MotionSampler::new());
                    for k in 0..60 {
                        let t = f64::from(clip.start()) - 0.7 + f64::from(k) * 0.137;
                        let options = SampleOptions { playback: Some(playback), ease, space };
                        let expected = clip.sample(t, &options, &mut plain);
                        let got = m.sample(t, &MotionOptions { ease, space }, &mut composed);
                        assert_eq!(got.to_bits(), expected.to_bits(), "clip time at {t}");
                        assert_eq!(composed.pose(), plain.pose(), "pose at {t} ({playback:?}, {space:?}, {ease:?})");
                    }
                }
            }
        }
    }
}

#[test]
fn walk_then_run_at_three_tenths_is_seventy_thirty() {
    let walk = body("walk", 1.0, 0.0, 2.0, 0.0);
    let run = body("run", 1.0, 0.0, 6.0, 1.0);
    let m = motion(vec![LayerSpec::new(&walk), LayerSpec { weight: 0.3, ..LayerSpec::new(&run) }]);
    let s = sample(&m, 0.5);
    // hips: walk at x = 1, run at x = 3 → 0.7·1 + 0.3·3 = 1.6.
    assert!((s.pose().translations[0].x - 1.6).abs() < 1e-6, "{:?}", s.pose().translations[0]);
    // arm: slerp(identity, 1 rad about z, 0.3) = 0.3 rad about z.
    let expected = Quat::from_rotation_z(0.3);
    assert!(s.pose().rotations[2].dot(expected).abs() > 1.0 - 1e-6, "{:?}", s.pose().rotations[2]);
}

#[test]
fn a_mask_with_descendants_replaces_the_upper_body_only() {
    let walk = body("walk", 1.0, 0.0, 2.0, 0.0);
    let wave = body("wave", 1.0, 5.0, 5.0, 1.2);
    let mask = MaskSpec { joints: vec![("spine".into(), 1.0)], descendants: true, default: None };
    let m = motion(vec![LayerSpec::new(&walk), LayerSpec { mask: Some(mask), ..LayerSpec::new(&wave) }]);
    let s = sample(&m, 0.25);
    // hips and leg are not covered (default 0 when joints are named): the walk's.
    assert!((s.pose().translations[0].x - 0.5).abs() < 1e-6);
    // arm is spine's descendant: the wave's turn, exactly.
    assert_eq!(s.pose().rotations[2], Quat::from_rotation_z(1.2).normalize());
}

#[test]
fn an_additive_layer_adds_its_motion_from_the_reference() {
    let walk = body("walk", 1.0, 0.0, 2.0, 0.5);
    // The breathing layer moves the hips from 10 to 14 and turns the arm by 0.4 (at every time).
    let breathe = body("breathe", 1.0, 10.0, 14.0, 0.4);
    let layer =
        LayerSpec { mode: LayerMode::Additive, weight: 0.5, reference_time: Some(0.0), ..LayerSpec::new(&breathe) };
    let m = motion(vec![LayerSpec::new(&walk), layer]);
    let s = sample(&m, 0.5);
    // hips: walk 1.0 + 0.5·(12 − 10) = 2.0.
    assert!((s.pose().translations[0].x - 2.0).abs() < 1e-6, "{:?}", s.pose().translations[0]);
    // arm: the reference is the same turn as the layer, so no change.
    assert!(s.pose().rotations[2].dot(Quat::from_rotation_z(0.5)).abs() > 1.0 - 1e-6);
}

#[test]
fn synced_layers_share_a_phase_whatever_their_lengths() {
    let walk = body("walk", 1.0, 0.0, 1.0, 0.0);
    let run = body("run", 0.5, 0.0, 1.0, 0.0);
    let synced = |clip, weight| LayerSpec { sync: Some("locomotion".into()), weight, ..LayerSpec::new(clip) };
    let m = motion(vec![synced(&walk, 1.0), synced(&run, 0.5)]);
    // Shares 0.5 and 0.5: D = 0.75 s. At τ = 0.375 the phase is 0.5: walk at 0.5 s, run at 0.25 s.
    let s = sample(&m, 0.375);
    assert!((s.clip_times()[0] - 0.5).abs() < 1e-6, "{:?}", s.clip_times());
    assert!((s.clip_times()[1] - 0.25).abs() < 1e-6, "{:?}", s.clip_times());
    // Both at mid-cycle: hips at 0.5 in each, blended 50/50.
    assert!((s.pose().translations[0].x - 0.5).abs() < 1e-6);
    // A whole group cycle later both are back at the start of theirs.
    let s = sample(&m, 0.75 * 3.0);
    assert!(s.clip_times()[0].abs() < 1e-5 && s.clip_times()[1].abs() < 1e-5, "{:?}", s.clip_times());
}

#[test]
fn a_weight_change_mid_stream_carries_the_phase_on() {
    let walk = body("walk", 1.0, 0.0, 1.0, 0.0);
    let run = body("run", 0.5, 0.0, 1.0, 0.0);
    let synced = |clip| LayerSpec { sync: Some("g".into()), ..LayerSpec::new(clip) };
    let m = motion(vec![synced(&walk), synced(&run)]);
    let mut phases = Vec::new();
    m.phases_at(0.0, &[1.0, 0.0], &mut phases);
    m.advance_phases(&mut phases, 0.25, &[1.0, 0.0]); // walk only: D = 1, phase 0.25
    m.advance_phases(&mut phases, 0.125, &[1.0, 1.0]); // run only: D = 0.5, phase + 0.25
    assert!((phases[0] - 0.5).abs() < 1e-12, "{phases:?}");
}

/// Whether joint `j` of `skeleton` is `named` or one of its descendants.
fn under(skeleton: &Skeleton, named: usize, j: usize) -> bool {
    let mut at = Some(j);
    while let Some(k) = at {
        if k == named {
            return true;
        }
        at = skeleton.parent(k);
    }
    false
}

/// Three random 12-joint clips (the same joint names, their own
/// hierarchies; the second and third name their joints in a shuffled
/// order, so layers map onto the output skeleton by name, not by index)
/// and the joint a top layer's mask names.
fn hiding_case(rng: &mut Rng) -> (Vec<Clip>, usize) {
    let clips = (0..3)
        .map(|i| {
            let mut spec = skeleton_clip(rng, 12);
            if i > 0 {
                shuffle_names(&mut spec, rng);
            }
            Clip::build(&spec).unwrap()
        })
        .collect();
    (clips, rng.below(12))
}

/// Renames `spec`'s joints `j0..` by a random permutation of their names.
fn shuffle_names(spec: &mut ClipSpec, rng: &mut Rng) {
    let mut names: Vec<usize> = (0..12).collect();
    for i in (1..names.len()).rev() {
        names.swap(i, rng.below(i + 1));
    }
    let rename = |name: &mut String| *name = format!("j{}", names[name[1..].parse::<usize>().unwrap()]);
    for joint in &mut spec.skeleton.as_mut().unwrap().joints {
        rename(&mut joint.name);
        joint.parent.as_mut().map(rename);
    }
    spec.tracks.iter_mut().for_each(|t| rename(&mut t.joint));
}

/// Walk and run at 0.3, synced.
fn beneath(clips: &[Clip]) -> Vec<LayerSpec<&Clip>> {
    let synced = |clip| LayerSpec { sync: Some("g".into()), ..LayerSpec::new(clip) };
    vec![synced(&clips[0]), LayerSpec { weight: 0.3, ..synced(&clips[1]) }]
}

/// [`beneath`] with the third clip on top at weight 1, masked to `named`
/// and its descendants.
fn with_top(clips: &[Clip], named: usize) -> Vec<LayerSpec<&Clip>> {
    let mask = MaskSpec { joints: vec![(format!("j{named}"), 1.0)], descendants: true, default: None };
    let mut layers = beneath(clips);
    layers.push(LayerSpec { mask: Some(mask), offset: 0.37, ..LayerSpec::new(&clips[2]) });
    layers
}

#[test]
fn a_full_weight_masked_layer_is_its_clip_where_it_covers_and_leaves_the_rest_as_beneath() {
    // Bit for bit: where the top layer covers, the layers beneath it are not
    // sampled at all, and where its mask is 0 it is not sampled; neither may show.
    let mut rng = Rng::new(1616);
    for _ in 0..10 {
        let (clips, named) = hiding_case(&mut rng);
        let (whole, lower) = (motion(with_top(&clips, named)), motion(beneath(&clips)));
        let skeleton = clips[0].skeleton();
        let (mut a, mut b) = (MotionSampler::new(), MotionSampler::new());
        let (mut top, mut cursor) = (Pose::default(), Cursor::default());
        let mut covered = 0;
        for k in 0..40 {
            let tau = f64::from(k) * 0.093 - 0.5;
            whole.sample(tau, &MotionOptions::default(), &mut a);
            lower.sample(tau, &MotionOptions::default(), &mut b);
            clips[2].sample_into(a.clip_times()[2], &mut cursor, &mut top);
            for j in 0..skeleton.len() {
                let (expected, e) = if under(skeleton, named, j) {
                    (&top, clips[2].skeleton().index_of(&skeleton.names()[j]).unwrap())
                } else {
                    (b.pose(), j)
                };
                covered += usize::from(under(skeleton, named, j));
                let got = a.pose();
                assert_eq!(
                    (got.translations[j], got.rotations[j], got.scales[j]),
                    (expected.translations[e], expected.rotations[e], expected.scales[e]),
                    "joint {j} at {tau} (mask on j{named}: {})",
                    under(skeleton, named, j)
                );
            }
        }
        assert!(covered > 0);
    }
}

#[test]
fn a_ramp_that_lowers_a_hiding_layer_shows_the_layers_beneath_again() {
    let (clips, named) = hiding_case(&mut Rng::new(1617));
    let (whole, lower) = (Arc::new(motion(with_top(&clips, named))), motion(beneath(&clips)));
    let skeleton = clips[0].skeleton();
    let mut player = Player::new(whole);
    let options = MotionOptions::default();
    for k in 0..10 {
        player.sample(f64::from(k) / 60.0, &options);
    }
    player.ramp(2, 0.0, 0.0).unwrap();
    let s = 10.0 / 60.0;
    player.sample(s, &options);
    let mut reference = MotionSampler::new();
    lower.sample(s, &options, &mut reference);
    for j in 0..skeleton.len() {
        let (got, expected) = (player.pose(), reference.pose());
        // The player's phase is advanced tick by tick: equal to rounding.
        assert!((got.translations[j] - expected.translations[j]).length() < 1e-4, "joint {j}");
        assert!(got.rotations[j].dot(expected.rotations[j]).abs() > 1.0 - 1e-5, "joint {j}");
        assert!((got.scales[j] - expected.scales[j]).length() < 1e-4, "joint {j}");
    }
}

#[test]
fn refusals_name_the_field() {
    let walk = body("walk", 1.0, 0.0, 2.0, 0.0);
    let mask = MaskSpec { joints: vec![("tail".into(), 1.0)], ..MaskSpec::default() };
    let cases: Vec<(LayerSpec<&Clip>, &str, &str)> = vec![
        (LayerSpec { weight: 1.5, ..LayerSpec::new(&walk) }, "/layers/1/weight", "weight_out_of_range"),
        (LayerSpec { speed: 2000.0, ..LayerSpec::new(&walk) }, "/layers/1/speed", "speed_out_of_range"),
        (LayerSpec { offset: f64::NAN, ..LayerSpec::new(&walk) }, "/layers/1/offset", "non_finite"),
        (LayerSpec { mask: Some(mask), ..LayerSpec::new(&walk) }, "/layers/1/mask/joints/tail", "unknown_joint"),
    ];
    for (layer, pointer, code) in cases {
        let err = Motion::build(MotionSpec {
            layers: vec![LayerSpec::new(&walk), layer],
            root_motion: None,
            ..Default::default()
        })
        .unwrap_err();
        assert_eq!((err.path.to_pointer().as_str(), err.kind.code()), (pointer, code));
    }
    let err =
        Motion::<&Clip>::build(MotionSpec { layers: vec![], root_motion: None, ..Default::default() }).unwrap_err();
    assert_eq!(err.kind.code(), "no_layers");
}

/// A clip over joints `names` (each a root, each with a one-key
/// translation track).
fn rig(names: &[&str]) -> Clip {
    let track = |name: &&str| {
        TrackSpec::new(name, Channel::Translation, Interpolation::Linear, vec![0.0], Keys::Vec3(vec![Vec3::X]))
    };
    Clip::build(&ClipSpec { name: "rig".into(), tracks: names.iter().map(track).collect(), ..Default::default() })
        .unwrap()
}

#[test]
fn a_layer_of_another_rig_is_refused_and_one_that_shares_some_joints_warns_naming_the_rest() {
    let walk = body("walk", 1.0, 0.0, 2.0, 0.0);
    let (other, partial) = (rig(&["Hips", "Spine"]), rig(&["hips", "tail", "ear"]));
    fn build<'a>(walk: &'a Clip, top: &'a Clip) -> Result<Motion<&'a Clip>, anim::motion::MotionError> {
        Motion::build(MotionSpec { layers: vec![LayerSpec::new(walk), LayerSpec::new(top)], ..Default::default() })
    }
    let err = build(&walk, &other).unwrap_err();
    assert_eq!((err.path.to_pointer().as_str(), err.kind.code()), ("/layers/1/clip", "incompatible_skeleton"));
    let detail = err.kind.to_string();
    assert!(detail.contains("'Hips', 'Spine'") && detail.contains("'hips'") && detail.contains("`character`"));
    let motion = build(&walk, &partial).unwrap();
    let [warning] = motion.warnings() else { panic!("one warning: {:?}", motion.warnings()) };
    assert_eq!(warning.path.to_pointer(), "/layers/1/clip");
    assert_eq!((warning.joints.as_slice(), warning.count), (&["tail".to_owned(), "ear".to_owned()][..], 2));
    assert!(warning.to_string().contains("2 joints") && warning.to_string().contains("'tail', 'ear'"));
    // The layer still plays the joint it shares; the first layer never warns.
    assert_eq!(sample(&motion, 0.0).pose().translations[0], Vec3::X.into());
    assert!(build(&walk, &walk).unwrap().warnings().is_empty());
    // Many missing joints: the first five are named, and the count is exact.
    let names: Vec<String> = (0..9).map(|i| format!("j{i}")).collect();
    let wide = rig(&names.iter().map(String::as_str).chain(["arm"]).collect::<Vec<_>>());
    let motion = build(&walk, &wide).unwrap();
    assert_eq!(motion.warnings()[0].count, 9);
    assert!(motion.warnings()[0].to_string().contains("'j0', 'j1', 'j2', 'j3', 'j4', …"));
}

#[test]
fn no_root_joint_names_the_candidates() {
    let walk = body("walk", 1.0, 0.0, 2.0, 0.0);
    let rooted = rig(&["a"]);
    // `walk`'s root, hips, has a translation track; a clip whose only
    // translated joint is not a root is refused, naming both kinds.
    let arm = TrackSpec::new("arm", Channel::Translation, Interpolation::Linear, vec![0.0], Keys::Vec3(vec![Vec3::X]));
    let mut spec = ClipSpec { name: "arm".into(), tracks: vec![arm], ..Default::default() };
    spec.skeleton = Some(SkeletonSpec {
        joints: ["hips", "arm"]
            .iter()
            .enumerate()
            .map(|(i, name)| JointSpec {
                name: (*name).into(),
                parent: (i > 0).then(|| "hips".into()),
                rest: Transform::IDENTITY,
                inverse_bind: None,
            })
            .collect(),
    });
    let clip = Clip::build(&spec).unwrap();
    let root = Some(anim::motion::RootMotionSpec::default());
    let err = Motion::build(MotionSpec {
        layers: vec![LayerSpec::new(&clip)],
        root_motion: root.clone(),
        ..Default::default()
    })
    .unwrap_err();
    assert_eq!((err.path.to_pointer().as_str(), err.kind.code()), ("/root_motion", "no_root_joint"));
    let detail = err.kind.to_string();
    assert!(detail.contains("root joints: 'hips'") && detail.contains("`root_motion.joint`: 'arm'"), "{detail}");
    for ok in [&walk, &rooted] {
        let spec = MotionSpec { layers: vec![LayerSpec::new(ok)], root_motion: root.clone(), ..Default::default() };
        assert!(Motion::build(spec).is_ok());
    }
}

#[test]
fn sampling_a_warm_motion_allocates_nothing() {
    let walk = body("walk", 1.0, 0.0, 2.0, 0.0);
    let run = body("run", 0.5, 0.0, 6.0, 1.0);
    let breathe = body("breathe", 2.0, 0.0, 1.0, 0.1);
    let m = motion(vec![
        LayerSpec { sync: Some("g".into()), ..LayerSpec::new(&walk) },
        LayerSpec { sync: Some("g".into()), weight: 0.4, ..LayerSpec::new(&run) },
        LayerSpec { mode: LayerMode::Additive, ..LayerSpec::new(&breathe) },
    ]);
    let mut sampler = MotionSampler::new();
    let options = MotionOptions { space: Space::Model, ..MotionOptions::default() };
    m.sample(0.0, &options, &mut sampler);
    let before = allocations();
    for k in 0..200 {
        m.sample(f64::from(k) * 0.013, &options, &mut sampler);
    }
    assert_eq!(allocations() - before, 0);
}
