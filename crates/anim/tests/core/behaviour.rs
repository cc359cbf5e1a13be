//! Clip-level behaviour of docs/clip-format.md (sections 1–2) at hand-checked points: the segment
//! search (forward, backward, random access agree), per-track key times,
//! single-key tracks, rest values, events, model space against a naive
//! composition, step boundaries, and building cost bounds.

use std::sync::mpsc;
use std::time::Duration;

use anim::{
    Channel, Clip, ClipError, ClipSpec, Cursor, Ease, EventSpec, Interpolation, JointSpec, Keys, Playback, Pose,
    SampleOptions, Sampler, SkeletonSpec, Space, Speed, TrackSpec, Transform,
};
use glam::{Mat4, Quat, Vec3, Vec3A, Vec4};

use crate::random::{Kind, Rng, skeleton_clip, track};

fn spec(tracks: Vec<TrackSpec>) -> ClipSpec {
    ClipSpec {
        name: "b".into(),
        skeleton: None,
        tracks,
        events: vec![],
        playback: Playback::Once,
        ..Default::default()
    }
}

fn v3(joint: &str, channel: Channel, interp: Interpolation, times: Vec<f32>, values: Vec<[f32; 3]>) -> TrackSpec {
    TrackSpec::new(joint, channel, interp, times, Keys::Vec3(values.into_iter().map(Vec3::from).collect()))
}

/// Builds on another thread and gives up after `limit`: a build that
/// hangs must fail its test, not the whole run.
pub fn build_within(spec: &ClipSpec, limit: Duration) -> Result<Result<Clip, ClipError>, String> {
    let (tx, rx) = mpsc::channel();
    let spec = spec.clone();
    std::thread::spawn(move || {
        let _ = tx.send(Clip::build(&spec));
    });
    rx.recv_timeout(limit).map_err(|_| format!("Clip::build did not finish within {limit:?}"))
}

/// Forward playback with one cursor, backward jumps, and a fresh cursor
/// per sample all find the same segments.
#[test]
fn cursor_order_does_not_change_the_pose() {
    let mut rng = Rng::new(900);
    for _ in 0..20 {
        let joints = 1 + rng.below(5);
        let spec = skeleton_clip(&mut rng, joints);
        let clip = Clip::build(&spec).unwrap();
        let (a, b) = (clip.start(), clip.end());
        let times: Vec<f32> = (0..=200).map(|k| a - 0.1 + (b - a + 0.2) * k as f32 / 200.0).collect();
        let fresh: Vec<Pose> = times
            .iter()
            .map(|&t| {
                let mut pose = Pose::default();
                clip.sample_into(t, &mut Cursor::default(), &mut pose);
                pose
            })
            .collect();
        let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
        for (t, expected) in times.iter().zip(&fresh) {
            clip.sample_into(*t, &mut cursor, &mut pose);
            assert_eq!(&pose, expected, "forward at t = {t}");
        }
        for (t, expected) in times.iter().zip(&fresh).rev() {
            clip.sample_into(*t, &mut cursor, &mut pose);
            assert_eq!(&pose, expected, "backward at t = {t}");
        }
        for _ in 0..200 {
            let k = rng.below(times.len());
            clip.sample_into(times[k], &mut cursor, &mut pose);
            assert_eq!(pose, fresh[k], "random access at t = {}", times[k]);
        }
    }
}

/// A cursor used with one clip, then another, re-fits itself.
#[test]
fn a_cursor_moves_between_clips() {
    let mut rng = Rng::new(901);
    let clips: Vec<Clip> = (0..4).map(|_| Clip::build(&skeleton_clip(&mut rng, 4)).unwrap()).collect();
    let mut cursor = Cursor::default();
    let mut pose = Pose::default();
    for _ in 0..50 {
        let clip = &clips[rng.below(clips.len())];
        let t = rng.range(clip.start() as f64, clip.end() as f64) as f32;
        clip.sample_into(t, &mut cursor, &mut pose);
        let mut expected = Pose::default();
        clip.sample_into(t, &mut Cursor::default(), &mut expected);
        assert_eq!(pose, expected);
    }
}

/// Each track keeps its own key times and holds its ends outside them;
/// the clip spans the union.
#[test]
fn tracks_with_different_key_times() {
    let tracks = vec![
        v3("a", Channel::Translation, Interpolation::Linear, vec![0.0, 1.0], vec![[0.0; 3], [1.0, 0.0, 0.0]]),
        v3("a", Channel::Scale, Interpolation::Linear, vec![0.5, 3.0], vec![[1.0; 3], [3.5, 1.0, 1.0]]),
        v3("b", Channel::Translation, Interpolation::Step, vec![-1.0, 2.0], vec![[5.0; 3], [6.0; 3]]),
    ];
    let clip = Clip::build(&spec(tracks)).unwrap();
    assert_eq!((clip.start(), clip.end(), clip.duration()), (-1.0, 3.0, 4.0));
    assert_eq!(clip.track_count(), 3);
    let mut pose = Pose::default();
    let mut cursor = Cursor::default();
    let cases: [(f32, f32, f32, f32); 5] = [
        // t, a.translation.x, a.scale.x, b.translation.x
        (-1.0, 0.0, 1.0, 5.0),
        (0.25, 0.25, 1.0, 5.0),
        (0.75, 0.75, 1.25, 5.0),
        (2.0, 1.0, 2.5, 6.0),
        (3.0, 1.0, 3.5, 6.0),
    ];
    for (t, ax, asx, bx) in cases {
        clip.sample_into(t, &mut cursor, &mut pose);
        let got = (pose.translations[0].x, pose.scales[0].x, pose.translations[1].x);
        assert!(
            (got.0 - ax).abs() < 1e-6 && (got.1 - asx).abs() < 1e-6 && (got.2 - bx).abs() < 1e-6,
            "t = {t}: {got:?}"
        );
        assert_eq!(pose.rotations[0], Quat::IDENTITY, "no rotation track: rest");
    }
}

/// A single-key track is constant everywhere, in every mode.
#[test]
fn single_key_tracks_are_constant() {
    let q = Quat::from_rotation_z(0.8);
    for interp in [Interpolation::Step, Interpolation::Linear, Interpolation::CatmullRom, Interpolation::CubicHermite] {
        let mut t = v3("a", Channel::Translation, interp, vec![2.0], vec![[1.0, 2.0, 3.0]]);
        let mut r = TrackSpec::new("a", Channel::Rotation, interp, vec![5.0], Keys::Vec4(vec![Vec4::from(q) * -3.0]));
        if interp == Interpolation::CubicHermite {
            t.in_tangents = Some(Keys::Vec3(vec![Vec3::X]));
            t.out_tangents = Some(Keys::Vec3(vec![Vec3::Y]));
            r.values = Keys::Vec4(vec![Vec4::from(q)]);
            r.in_tangents = Some(Keys::Vec4(vec![Vec4::X]));
            r.out_tangents = Some(Keys::Vec4(vec![Vec4::Y]));
        }
        let clip = Clip::build(&spec(vec![t, r])).unwrap();
        assert_eq!((clip.start(), clip.end()), (2.0, 5.0));
        let mut sampler = Sampler::new();
        for time in [-10.0, 2.0, 3.3, 5.0, 100.0] {
            clip.sample(time, &SampleOptions::default(), &mut sampler);
            let pose = sampler.pose();
            assert_eq!(pose.translations[0], Vec3A::new(1.0, 2.0, 3.0), "{interp:?} at {time}");
            let got = pose.rotations[0];
            assert!(got.abs_diff_eq(q, 1e-6) || got.abs_diff_eq(-q, 1e-6), "{interp:?} at {time}: {got}");
        }
    }
}

/// Joints without a track keep their (normalised) rest values, and without
/// a skeleton each animated joint is a root, in order of first appearance.
#[test]
fn rest_values_and_implicit_joints() {
    let rest = Transform {
        translation: Vec3::new(1.0, 2.0, 3.0),
        rotation: Quat::from_xyzw(0.0, 0.0, 2.0, 2.0),
        scale: Vec3::splat(2.0),
    };
    let joints = vec![
        JointSpec { name: "root".into(), parent: None, rest, inverse_bind: None },
        JointSpec { name: "tip".into(), parent: Some("root".into()), rest: Transform::IDENTITY, inverse_bind: None },
    ];
    let tracks =
        vec![v3("tip", Channel::Translation, Interpolation::Linear, vec![0.0, 1.0], vec![[0.0; 3], [1.0, 0.0, 0.0]])];
    let clip = Clip::build(&ClipSpec { skeleton: Some(SkeletonSpec { joints }), ..spec(tracks) }).unwrap();
    let mut pose = Pose::default();
    clip.sample_into(0.5, &mut Cursor::default(), &mut pose);
    assert_eq!(pose.translations[0], Vec3A::new(1.0, 2.0, 3.0));
    let r = std::f32::consts::FRAC_1_SQRT_2;
    assert!(pose.rotations[0].abs_diff_eq(Quat::from_xyzw(0.0, 0.0, r, r), 1e-6), "{}", pose.rotations[0]);
    assert_eq!(pose.scales[0], Vec3A::splat(2.0));
    assert_eq!(clip.skeleton().parent(1), Some(0));

    let implicit = spec(vec![
        v3("b", Channel::Scale, Interpolation::Linear, vec![0.0], vec![[1.0; 3]]),
        v3("a", Channel::Translation, Interpolation::Linear, vec![0.0], vec![[1.0; 3]]),
        v3("b", Channel::Translation, Interpolation::Linear, vec![0.0], vec![[1.0; 3]]),
    ]);
    let clip = Clip::build(&implicit).unwrap();
    assert_eq!(clip.skeleton().names(), ["b", "a"]);
    assert_eq!((clip.skeleton().parent(0), clip.skeleton().parent(1)), (None, None));
}

#[test]
fn events_are_sorted_by_time() {
    let mut s = spec(vec![v3("a", Channel::Translation, Interpolation::Linear, vec![0.0], vec![[0.0; 3]])]);
    s.events = [(2.0, "c"), (-1.0, "a"), (0.5, "b"), (2.0, "d")]
        .iter()
        .map(|&(time, name)| EventSpec { time, name: name.into() })
        .collect();
    let clip = Clip::build(&s).unwrap();
    let got: Vec<(f32, &str)> = clip.events().iter().map(|e| (e.time, e.name.as_str())).collect();
    assert_eq!(got, [(-1.0, "a"), (0.5, "b"), (2.0, "c"), (2.0, "d")], "sorted, ties in given order");
}

/// Model space against a naive chain walk written out per joint:
/// root ← mid ← tip, with a uniform scale on the root.
#[test]
fn model_space_matches_a_hand_composition() {
    let joint = |name: &str, parent: Option<&str>, t: Vec3, r: Quat, s: f32| JointSpec {
        name: name.into(),
        parent: parent.map(Into::into),
        rest: Transform { translation: t, rotation: r, scale: Vec3::splat(s) },
        inverse_bind: None,
    };
    let joints = vec![
        joint("root", None, Vec3::new(0.0, 0.0, 1.0), Quat::from_rotation_z(std::f32::consts::FRAC_PI_2), 2.0),
        joint("mid", Some("root"), Vec3::new(1.0, 0.0, 0.0), Quat::from_rotation_x(std::f32::consts::FRAC_PI_2), 1.0),
        joint("tip", Some("mid"), Vec3::new(0.0, 1.0, 0.0), Quat::IDENTITY, 0.5),
    ];
    let tracks = vec![v3("tip", Channel::Scale, Interpolation::Step, vec![0.0], vec![[0.5; 3]])];
    let clip = Clip::build(&ClipSpec { skeleton: Some(SkeletonSpec { joints }), ..spec(tracks) }).unwrap();
    let mut sampler = Sampler::new();
    clip.sample(0.0, &SampleOptions { space: Space::Model, ..Default::default() }, &mut sampler);
    let pose = sampler.pose();
    // root: at (0,0,1), turned 90° about z, scale 2.
    // mid: root + Rz90·(2·(1,0,0)) = (0,0,1) + (0,2,0) = (0,2,1); rotation Rz90·Rx90; scale 2.
    // tip: mid + Rz90·Rx90·(2·(0,1,0)): Rx90 takes y to z, Rz90 keeps z: (0,2,1) + (0,0,2) = (0,2,3); scale 1.
    let expected = [[0.0, 0.0, 1.0], [0.0, 2.0, 1.0], [0.0, 2.0, 3.0]];
    for (j, e) in expected.iter().enumerate() {
        assert!(
            (pose.translations[j] - Vec3A::from(*e)).abs().max_element() < 1e-6,
            "joint {j}: {}",
            pose.translations[j]
        );
    }
    assert_eq!(pose.scales[2], Vec3A::ONE);
    let rz = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
    assert!(pose.rotations[2].abs_diff_eq(rz * Quat::from_rotation_x(std::f32::consts::FRAC_PI_2), 1e-6));
    // The model matrices say the same: the tip's origin.
    let mut m = Vec::new();
    assert!(clip.matrices(0.0, &SampleOptions::default(), false, &mut sampler, &mut m));
    assert!((m[2].w_axis.truncate() - Vec3::new(0.0, 2.0, 3.0)).abs().max_element() < 1e-6, "{}", m[2]);
}

/// docs/clip-format.md, 2.5: `step` holds `c_i` on the half-open `[t_i, t_{i+1})`, so just
/// before a key (by one `f32` ulp) it still holds the previous value.
#[test]
fn step_holds_until_the_next_key() {
    for (times, values) in
        [(vec![0.0, 3.0], vec![[1.0; 3], [2.0; 3]]), (vec![0.0, 0.7, 2.1], vec![[1.0; 3], [2.0; 3], [3.0; 3]])]
    {
        let n = times.len();
        let clip =
            Clip::build(&spec(vec![v3("a", Channel::Translation, Interpolation::Step, times.clone(), values.clone())]))
                .unwrap();
        let mut pose = Pose::default();
        for i in 1..n {
            let before = f32::from_bits(times[i].to_bits() - 1);
            clip.sample_into(before, &mut Cursor::default(), &mut pose);
            assert_eq!(pose.translations[0].x, values[i - 1][0], "just before key {i} (t = {before})");
            clip.sample_into(times[i], &mut Cursor::default(), &mut pose);
            assert_eq!(pose.translations[0].x, values[i][0], "at key {i}");
        }
    }
}

/// Building a constant-speed track is bounded work, whatever its keys: a
/// track that does not move must not take minutes to build. Equal keys
/// `x = -0.9797239` are the trap: the linear track's inner control points
/// `lerp(c, c, 1/3)` differ from `c` by rounding (1e-16), so the path has a
/// length of ~1e-16 made of noise, and splitting to a tolerance of 1e-6 of
/// *that* never converges.
#[test]
fn constant_speed_builds_quickly_even_when_nothing_moves() {
    for values in
        [vec![[-0.979_723_9, 0.0, 0.0]; 2], vec![[0.1, 0.2, 0.7]; 3], vec![[1.0, 2.0, 3.0], [1.0, 2.0, 3.0 + 1e-6]]]
    {
        let times = (0..values.len()).map(|i| i as f32).collect();
        let mut t = v3("a", Channel::Translation, Interpolation::Linear, times, values.clone());
        t.speed = Speed::Constant;
        let built = build_within(&spec(vec![t]), Duration::from_secs(10));
        let clip = built.unwrap_or_else(|e| panic!("{e} for keys {values:?}")).unwrap();
        let mut pose = Pose::default();
        clip.sample_into(0.5, &mut Cursor::default(), &mut pose);
        assert!((pose.translations[0] - Vec3A::from(values[0])).abs().max_element() < 1e-5);
    }
}

/// Ease and playback agree between `clip_time` and `sample`.
#[test]
fn sample_reports_the_clip_time_it_used() {
    let mut rng = Rng::new(902);
    let s = crate::random::one_track_clip(track(
        &mut rng,
        "j",
        Kind::new(Channel::Translation, Interpolation::CatmullRom),
        5,
    ));
    let clip = Clip::build(&s).unwrap();
    let mut sampler = Sampler::new();
    for _ in 0..100 {
        let t = rng.range(-5.0, 10.0);
        let ease = [Ease::Linear, Ease::EaseIn, Ease::EaseOut, Ease::EaseInOut][rng.below(4)];
        let playback = [Playback::Once, Playback::Loop, Playback::PingPong][rng.below(3)];
        let ct = clip.sample(t, &SampleOptions { playback: Some(playback), ease, space: Space::Local }, &mut sampler);
        assert_eq!(ct, clip.clip_time(t, playback, ease));
        let mut pose = Pose::default();
        clip.sample_into(ct, &mut Cursor::default(), &mut pose);
        assert_eq!(sampler.pose(), &pose);
    }
}

/// `format=skinning`: `M_j · invBind_j`, identity for joints without one.
#[test]
fn skinning_matrices_apply_the_inverse_binds() {
    let bind = Mat4::from_translation(Vec3::new(0.0, -1.0, 0.0));
    let joints = vec![
        JointSpec { name: "root".into(), parent: None, rest: Transform::IDENTITY, inverse_bind: None },
        JointSpec {
            name: "arm".into(),
            parent: Some("root".into()),
            rest: Transform { translation: Vec3::Y, ..Transform::IDENTITY },
            inverse_bind: Some(bind),
        },
    ];
    let tracks =
        vec![v3("root", Channel::Translation, Interpolation::Linear, vec![0.0, 1.0], vec![[0.0; 3], [2.0, 0.0, 0.0]])];
    let clip = Clip::build(&ClipSpec { skeleton: Some(SkeletonSpec { joints }), ..spec(tracks) }).unwrap();
    assert!(clip.skeleton().has_inverse_binds());
    let (mut sampler, mut model, mut skin) = (Sampler::new(), Vec::new(), Vec::new());
    let options = SampleOptions::default();
    assert!(clip.matrices(0.5, &options, false, &mut sampler, &mut model));
    assert!(clip.matrices(0.5, &options, true, &mut sampler, &mut skin));
    assert_eq!(skin[0], model[0], "no inverse bind: identity");
    assert!(skin[1].abs_diff_eq(model[1] * bind, 1e-6));
    // The arm sits at root (1, 0, 0) + (0, 1, 0); its skinning matrix moves
    // the bind-pose point (0, 1, 0) to there.
    assert!(skin[1].transform_point3(Vec3::Y).abs_diff_eq(Vec3::new(1.0, 1.0, 0.0), 1e-6));
}
