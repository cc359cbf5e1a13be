//! Every rule of `Clip::build`: each `ClipErrorKind` from a minimal bad
//! spec, with its stable `code()` and the JSON pointer of the culprit, and
//! the same through the JSON edge (`parse_clip` + `DocError`).

use anim::{
    Channel, Clip, ClipSpec, Ends, EventSpec, Interpolation, JointSpec, Keys, Playback, SkeletonSpec, Speed, TrackSpec,
    Transform,
};
use formats::wire::json::{DocError, parse_clip};
use glam::{Mat4, Quat, Vec3, Vec4};

fn translation(joint: &str) -> TrackSpec {
    TrackSpec::new(
        joint,
        Channel::Translation,
        Interpolation::Linear,
        vec![0.0, 1.0],
        Keys::Vec3(vec![Vec3::ZERO, Vec3::X]),
    )
}

fn rotation(values: Vec<Vec4>) -> TrackSpec {
    let times = (0..values.len()).map(|i| i as f32).collect();
    TrackSpec::new("a", Channel::Rotation, Interpolation::Linear, times, Keys::Vec4(values))
}

fn clip(tracks: Vec<TrackSpec>) -> ClipSpec {
    ClipSpec {
        name: "c".into(),
        skeleton: None,
        tracks,
        events: vec![],
        playback: Playback::Once,
        ..Default::default()
    }
}

fn joint(name: &str, parent: Option<&str>) -> JointSpec {
    JointSpec { name: name.into(), parent: parent.map(Into::into), rest: Transform::IDENTITY, inverse_bind: None }
}

fn with_skeleton(joints: Vec<JointSpec>, tracks: Vec<TrackSpec>) -> ClipSpec {
    ClipSpec { skeleton: Some(SkeletonSpec { joints }), ..clip(tracks) }
}

#[track_caller]
fn refused(spec: ClipSpec, code: &str, pointer: &str) {
    let err = Clip::build(&spec).expect_err("a bad spec must be refused");
    assert_eq!((err.kind.code(), err.path.to_pointer().as_str()), (code, pointer), "{err}");
    // The edge keeps code and pointer, and says something human.
    let doc = DocError::from(err);
    assert_eq!((doc.code, doc.pointer.as_str()), (code, pointer));
    assert!(!doc.detail.is_empty());
}

fn track_with(f: impl FnOnce(&mut TrackSpec)) -> ClipSpec {
    let mut t = translation("a");
    f(&mut t);
    clip(vec![t])
}

#[test]
fn clip_level_rules() {
    refused(ClipSpec { name: String::new(), ..clip(vec![translation("a")]) }, "bad_name", "/name");
    refused(ClipSpec { name: "x".repeat(257), ..clip(vec![translation("a")]) }, "bad_name", "/name");
    refused(clip(vec![]), "no_tracks", "/tracks");
    let event = |time: f32, name: &str| EventSpec { time, name: name.into() };
    let mut spec = clip(vec![translation("a")]);
    spec.events = vec![event(0.5, "ok"), event(f32::NAN, "step")];
    refused(spec.clone(), "non_finite", "/events/1/time");
    spec.events = vec![event(0.5, "")];
    refused(spec, "bad_name", "/events/0/name");
}

#[test]
fn skeleton_rules() {
    let t = || vec![translation("a")];
    refused(with_skeleton(vec![joint("a", None), joint("", None)], t()), "empty_joint_name", "/skeleton/joints/1/name");
    refused(with_skeleton(vec![joint("a", None), joint("a", None)], t()), "duplicate_joint", "/skeleton/joints/1/name");
    refused(with_skeleton(vec![joint("a", Some("zz"))], t()), "unknown_parent", "/skeleton/joints/0/parent");
    refused(with_skeleton(vec![joint("a", Some("a"))], t()), "parent_cycle", "/skeleton/joints/0/parent");
    refused(
        with_skeleton(vec![joint("a", Some("b")), joint("b", Some("a"))], t()),
        "parent_cycle",
        "/skeleton/joints/0/parent",
    );
    refused(
        with_skeleton(vec![joint("a", Some("b")), joint("b", None)], t()),
        "parent_after_child",
        "/skeleton/joints/0/parent",
    );
    refused(with_skeleton(vec![joint("b", None)], t()), "unknown_joint", "/tracks/0/joint");
    let mut bad = joint("a", None);
    bad.rest.translation = Vec3::new(0.0, f32::INFINITY, 0.0);
    refused(with_skeleton(vec![bad], t()), "non_finite", "/skeleton/joints/0/rest/translation");
    let mut bad = joint("a", None);
    bad.rest.scale = Vec3::NAN;
    refused(with_skeleton(vec![bad], t()), "non_finite", "/skeleton/joints/0/rest/scale");
    let mut bad = joint("a", None);
    bad.rest.rotation = Quat::from_xyzw(0.0, 0.0, 0.0, f32::NAN);
    refused(with_skeleton(vec![bad], t()), "non_finite", "/skeleton/joints/0/rest/rotation");
    let mut bad = joint("a", None);
    bad.rest.rotation = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0);
    refused(with_skeleton(vec![bad], t()), "zero_quaternion", "/skeleton/joints/0/rest/rotation");
    let mut bad = joint("a", None);
    bad.inverse_bind = Some(Mat4::NAN);
    refused(with_skeleton(vec![bad], t()), "non_finite", "/skeleton/joints/0/inverse_bind");
    // Without a skeleton, the track's own joint name is checked.
    refused(clip(vec![translation("")]), "empty_joint_name", "/tracks/0/joint");
    // Joint names are capped as clip names are: 256 characters (not bytes).
    let long = "é".repeat(257);
    refused(clip(vec![translation(&long)]), "joint_name_too_long", "/tracks/0/joint");
    let at_cap = "é".repeat(256);
    Clip::build(&with_skeleton(vec![joint(&at_cap, None)], vec![translation(&at_cap)])).expect("256 characters");
    refused(
        with_skeleton(vec![joint("a", None), joint(&long, None)], t()),
        "joint_name_too_long",
        "/skeleton/joints/1/name",
    );
}

#[test]
fn track_shape_rules() {
    refused(clip(vec![translation("a"), translation("a")]), "duplicate_track", "/tracks/1/channel");
    refused(
        track_with(|t| {
            t.times.clear();
            t.values = Keys::Vec3(vec![]);
        }),
        "no_keys",
        "/tracks/0/times",
    );
    refused(track_with(|t| t.values = Keys::Vec3(vec![Vec3::ZERO])), "length_mismatch", "/tracks/0/values");
    refused(track_with(|t| t.times = vec![0.0, 0.0]), "times_not_increasing", "/tracks/0/times/1");
    refused(track_with(|t| t.times = vec![1.0, 0.5]), "times_not_increasing", "/tracks/0/times/1");
    refused(track_with(|t| t.times = vec![0.0, f32::NAN]), "non_finite", "/tracks/0/times/1");
    refused(
        track_with(|t| t.values = Keys::Vec3(vec![Vec3::ZERO, Vec3::INFINITY])),
        "non_finite",
        "/tracks/0/values/1",
    );
    refused(track_with(|t| t.values = Keys::Vec4(vec![Vec4::W, Vec4::W])), "wrong_width", "/tracks/0/values");
    let mut r = rotation(vec![Vec4::W, Vec4::W]);
    r.values = Keys::Vec3(vec![Vec3::X, Vec3::Y]);
    refused(clip(vec![r]), "wrong_width", "/tracks/0/values");
    refused(clip(vec![rotation(vec![Vec4::W, Vec4::splat(1e-7)])]), "zero_quaternion", "/tracks/0/values/1");
    refused(
        clip(vec![rotation(vec![Vec4::W, Vec4::new(0.0, f32::NAN, 0.0, 1.0)])]),
        "non_finite",
        "/tracks/0/values/1",
    );
}

#[test]
fn mode_option_rules() {
    let cr = |f: &dyn Fn(&mut TrackSpec)| {
        track_with(|t| {
            t.interpolation = Interpolation::CatmullRom;
            f(t)
        })
    };
    refused(cr(&|t| t.tension = Some(1.5)), "tension_out_of_range", "/tracks/0/tension");
    refused(cr(&|t| t.tension = Some(-0.1)), "tension_out_of_range", "/tracks/0/tension");
    refused(cr(&|t| t.tension = Some(f32::NAN)), "tension_out_of_range", "/tracks/0/tension");
    refused(track_with(|t| t.ends = Some(Ends::Reflect)), "only_catmull_rom", "/tracks/0/ends");
    refused(track_with(|t| t.tension = Some(0.5)), "only_catmull_rom", "/tracks/0/tension");
    refused(
        track_with(|t| t.in_tangents = Some(Keys::Vec3(vec![Vec3::ZERO; 2]))),
        "only_cubic_hermite",
        "/tracks/0/in_tangents",
    );
    refused(
        track_with(|t| t.out_tangents = Some(Keys::Vec3(vec![Vec3::ZERO; 2]))),
        "only_cubic_hermite",
        "/tracks/0/out_tangents",
    );
    let hermite = |f: &dyn Fn(&mut TrackSpec)| {
        track_with(|t| {
            t.interpolation = Interpolation::CubicHermite;
            t.in_tangents = Some(Keys::Vec3(vec![Vec3::ZERO; 2]));
            t.out_tangents = Some(Keys::Vec3(vec![Vec3::ZERO; 2]));
            f(t)
        })
    };
    refused(hermite(&|t| t.in_tangents = None), "missing_tangents", "/tracks/0/in_tangents");
    refused(hermite(&|t| t.out_tangents = None), "missing_tangents", "/tracks/0/out_tangents");
    refused(
        hermite(&|t| t.out_tangents = Some(Keys::Vec3(vec![Vec3::ZERO]))),
        "length_mismatch",
        "/tracks/0/out_tangents",
    );
    refused(
        hermite(&|t| t.in_tangents = Some(Keys::Vec4(vec![Vec4::ZERO; 2]))),
        "wrong_width",
        "/tracks/0/in_tangents",
    );
    refused(
        hermite(&|t| t.in_tangents = Some(Keys::Vec3(vec![Vec3::ZERO, Vec3::NAN]))),
        "non_finite",
        "/tracks/0/in_tangents/1",
    );
    refused(cr(&|t| t.ends = Some(Ends::Wrap)), "wrap_ends_differ", "/tracks/0/values/1");
    let mut r = rotation(vec![Vec4::W, Vec4::from(Quat::from_rotation_x(0.5)), Vec4::from(Quat::from_rotation_x(0.1))]);
    r.interpolation = Interpolation::CatmullRom;
    r.ends = Some(Ends::Wrap);
    refused(clip(vec![r]), "wrap_ends_differ", "/tracks/0/values/2");
    refused(
        cr(&|t| {
            t.times = vec![0.0, 1.0, 2.0];
            t.values = Keys::Vec3(vec![Vec3::ZERO; 3]);
            t.ends = Some(Ends::Phantom);
        }),
        "phantom_too_few_keys",
        "/tracks/0/ends",
    );
    let mut r = rotation(vec![Vec4::W, Vec4::W]);
    r.speed = Speed::Constant;
    refused(clip(vec![r]), "speed_not_applicable", "/tracks/0/speed");
    refused(
        track_with(|t| {
            t.interpolation = Interpolation::Step;
            t.speed = Speed::Constant;
        }),
        "speed_not_applicable",
        "/tracks/0/speed",
    );
    let mut s = translation("a");
    s.channel = Channel::Scale;
    s.speed = Speed::Constant;
    refused(clip(vec![s]), "speed_not_applicable", "/tracks/0/speed");
}

/// `b_spline` takes `ends` with Catmull-Rom's rules (docs/clip-format.md §2.5), but no
/// `tension`: its basis is fixed. The refusal keeps the stable code and
/// names the modes the field belongs to.
#[test]
fn b_spline_option_rules() {
    let bs = |f: &dyn Fn(&mut TrackSpec)| {
        track_with(|t| {
            t.interpolation = Interpolation::BSpline;
            f(t)
        })
    };
    refused(bs(&|t| t.tension = Some(0.5)), "only_catmull_rom", "/tracks/0/tension");
    let err = Clip::build(&bs(&|t| t.tension = Some(0.5))).unwrap_err();
    assert_eq!(err.to_string(), "/tracks/0/tension: 'tension' applies only to catmull_rom tracks");
    let err = Clip::build(&track_with(|t| t.ends = Some(Ends::Reflect))).unwrap_err();
    assert!(err.to_string().ends_with("'ends' applies only to catmull_rom and b_spline tracks"), "{err}");
    refused(bs(&|t| t.ends = Some(Ends::Wrap)), "wrap_ends_differ", "/tracks/0/values/1");
    let mut r = rotation(vec![Vec4::W, Vec4::from(Quat::from_rotation_x(0.5)), Vec4::from(Quat::from_rotation_x(0.1))]);
    r.interpolation = Interpolation::BSpline;
    r.ends = Some(Ends::Wrap);
    refused(clip(vec![r]), "wrap_ends_differ", "/tracks/0/values/2");
    refused(
        bs(&|t| {
            t.times = vec![0.0, 1.0, 2.0];
            t.values = Keys::Vec3(vec![Vec3::ZERO; 3]);
            t.ends = Some(Ends::Phantom);
        }),
        "phantom_too_few_keys",
        "/tracks/0/ends",
    );
    for ends in [Ends::Reflect, Ends::ZeroSlope, Ends::Phantom] {
        let spec = bs(&|t| {
            t.times = vec![0.0, 1.0, 2.0, 3.0];
            t.values = Keys::Vec3(vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z]);
            t.ends = Some(ends);
            t.speed = Speed::Constant;
        });
        assert!(Clip::build(&spec).is_ok(), "{ends:?}");
    }
    let q = Vec4::from(Quat::from_rotation_y(0.7));
    let mut r = rotation(vec![q, Vec4::from(Quat::from_rotation_y(1.5)), -2.0 * q]);
    r.interpolation = Interpolation::BSpline;
    r.ends = Some(Ends::Wrap);
    assert!(Clip::build(&clip(vec![r])).is_ok(), "the same rotation, other sign and norm, closes a wrap");
}

/// What is allowed stays allowed: the same rotation with the other sign and
/// another norm closes a `wrap` track; a single key needs no second one.
#[test]
fn near_misses_are_accepted() {
    let q = Vec4::from(Quat::from_rotation_y(0.7));
    let mut r = rotation(vec![q, Vec4::from(Quat::from_rotation_y(1.5)), -2.0 * q]);
    r.interpolation = Interpolation::CatmullRom;
    r.ends = Some(Ends::Wrap);
    assert!(Clip::build(&clip(vec![r])).is_ok());
    let single = TrackSpec::new("a", Channel::Scale, Interpolation::Step, vec![3.0], Keys::Vec3(vec![Vec3::ONE]));
    assert!(Clip::build(&clip(vec![single])).is_ok());
    let mut tension = translation("a");
    tension.interpolation = Interpolation::CatmullRom;
    tension.tension = Some(1.0);
    assert!(Clip::build(&clip(vec![tension])).is_ok());
}

/// Through the JSON edge: type errors and the core's rules alike carry a
/// code and a pointer into the document.
#[test]
fn json_documents_report_codes_and_pointers() {
    let cases = [
        (r#"{"name": "c", "tracks": [}"#, "malformed_json", None),
        (r#"{"name": "c", "tracks": [], "bogus": 1}"#, "invalid_field", None),
        (
            r#"{"name": "c", "tracks": [{"joint": "a", "channel": "sideways", "times": [0], "values": [[0,0,0]]}]}"#,
            "invalid_field",
            Some("/tracks/0/channel"),
        ),
        (
            r#"{"name": "c", "tracks": [{"joint": "a", "channel": "rotation", "times": [0, 1], "values": [[0,0,0,1],[0,0,1]]}]}"#,
            "wrong_width",
            Some("/tracks/0/values/1"),
        ),
        (
            r#"{"name": "c", "tracks": [{"joint": "a", "channel": "translation", "times": [0, 2, 1], "values": [[0,0,0],[1,0,0],[2,0,0]]}]}"#,
            "times_not_increasing",
            Some("/tracks/0/times/2"),
        ),
    ];
    for (body, code, pointer) in cases {
        let err = match parse_clip(body.as_bytes()) {
            Err(e) => e,
            Ok((_, spec)) => DocError::from(Clip::build(&spec).expect_err(body)),
        };
        assert_eq!(err.code, code, "{body}: {err}");
        if let Some(p) = pointer {
            assert_eq!(err.pointer, p, "{body}");
        }
    }
}
