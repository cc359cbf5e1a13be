//! Parameters (docs/clip-format.md, “Parameters”) in the core: each
//! interpolation against values worked out by hand from docs/clip-format.md,
//! “Evaluation math”, widths that span several entries (and a padded one), the
//! time range, every refusal with its code and path, a clip of parameters
//! alone, and composition (docs/motion.md: blend, additive, a parameter a layer
//! lacks, crossfade needs the same parameters).

use std::sync::Arc;

use glam::Vec3;

use anim::motion::{LayerMode, LayerSpec, MotionOptions, MotionSpec, Player};
use anim::{
    Channel, Clip, ClipSpec, Ease, Ends, Interpolation, Keys, Motion, MotionSampler, ParameterSpec, Playback,
    SampleOptions, Sampler, TrackSpec,
};

/// The tolerance of docs/clip-format.md, “Accuracy”, for values of magnitude up to a few units.
const TOL: f64 = 1e-5;

fn rows(rows: &[&[f32]]) -> Vec<Vec<f32>> {
    rows.iter().map(|r| r.to_vec()).collect()
}

/// A clip with one joint `a` (a linear translation over [0, 1]) and `parameters`.
fn spec(parameters: Vec<ParameterSpec>) -> ClipSpec {
    let track = TrackSpec::new(
        "a",
        Channel::Translation,
        Interpolation::Linear,
        vec![0.0, 1.0],
        Keys::Vec3(vec![Vec3::ZERO, Vec3::X]),
    );
    ClipSpec { name: "p".into(), tracks: vec![track], parameters, playback: Playback::Once, ..Default::default() }
}

fn build(parameters: Vec<ParameterSpec>) -> Clip {
    Clip::build(&spec(parameters)).unwrap()
}

/// Parameter `name`'s values at clip time `t`.
fn values(clip: &Clip, name: &str, t: f64) -> Vec<f64> {
    let mut sampler = Sampler::new();
    clip.sample(t, &SampleOptions::default(), &mut sampler);
    let p = clip.parameters().index_of(name).unwrap();
    clip.parameters().values(sampler.pose(), p).map(f64::from).collect()
}

fn check(got: &[f64], expected: &[f64], what: &str) {
    assert_eq!(got.len(), expected.len(), "{what}: width");
    for (k, (g, e)) in got.iter().zip(expected).enumerate() {
        assert!((g - e).abs() <= TOL * e.abs().max(1.0), "{what}[{k}]: got {g}, expected {e}");
    }
}

#[test]
fn step_holds_each_key_until_the_next() {
    let clip = build(vec![ParameterSpec::new(
        "s",
        Interpolation::Step,
        vec![0.0, 1.0, 2.0],
        rows(&[&[1.0, 2.0], &[3.0, 4.0], &[5.0, 6.0]]),
    )]);
    check(&values(&clip, "s", 0.5), &[1.0, 2.0], "t = 0.5");
    check(&values(&clip, "s", 1.0), &[3.0, 4.0], "t = 1 switches exactly at the key");
    check(&values(&clip, "s", 2.5), &[5.0, 6.0], "after the last key");
}

#[test]
fn linear_lerps_every_component() {
    let clip = build(vec![ParameterSpec::new(
        "l",
        Interpolation::Linear,
        vec![0.0, 2.0],
        rows(&[&[0.0, 0.0, 0.0, 0.0], &[4.0, 8.0, -4.0, 1.0]]),
    )]);
    // u = 0.25 at t = 0.5.
    check(&values(&clip, "l", 0.5), &[1.0, 2.0, -1.0, 0.25], "t = 0.5");
    check(&values(&clip, "l", -1.0), &[0.0; 4], "held before the first key");
}

/// Catmull-Rom on unit spacing, k = 0.5 (docs/clip-format.md, “Catmull-Rom”):
/// component j's keys are `(j + 1)·[0, 1, 3, 2]`, so each is the same scalar
/// curve scaled. Width 5 spans two entries, the second padded.
#[test]
fn catmull_rom_matches_the_lecture_on_every_component() {
    let base = [0.0f32, 1.0, 3.0, 2.0];
    let keys: Vec<Vec<f32>> = base.iter().map(|c| (0..5).map(|j| c * (j + 1) as f32).collect()).collect();
    let clip = build(vec![ParameterSpec::new("c", Interpolation::CatmullRom, vec![0.0, 1.0, 2.0, 3.0], keys)]);
    // Segment 1 at u = ½: d = 1 + (3 − 0)/6 = 1.5, e = 3 − (2 − 1)/6 = 17/6,
    // p = (1 + 3·1.5 + 3·17/6 + 3)/8 = 17/8.
    let mid: Vec<f64> = (0..5).map(|j| 17.0 / 8.0 * (j + 1) as f64).collect();
    check(&values(&clip, "c", 1.5), &mid, "segment 1");
    // Segment 0 with reflect ends: c₋₁ = 2·0 − 1 = −1 at t = −1, so
    // d = 0 + (1 − (−1))/6 = 1/3, e = 1 − (3 − 0)/6 = ½, p(½) = (0 + 1 + 1.5 + 1)/8.
    let first: Vec<f64> = (0..5).map(|j| 3.5 / 8.0 * (j + 1) as f64).collect();
    check(&values(&clip, "c", 0.5), &first, "segment 0, reflect ends");
    // Keys are interpolated exactly.
    check(&values(&clip, "c", 2.0), &(0..5).map(|j| 3.0 * (j + 1) as f64).collect::<Vec<_>>(), "at a key");
}

#[test]
fn catmull_rom_takes_tension_and_zero_slope_ends() {
    let mut p =
        ParameterSpec::new("c", Interpolation::CatmullRom, vec![0.0, 1.0, 2.0], rows(&[&[0.0], &[1.0], &[0.0]]));
    (p.tension, p.ends) = (Some(1.0), Some(Ends::ZeroSlope));
    let clip = build(vec![p]);
    // Segment 0, zero slope: d = c₀ = 0; e = c₁ − (2k/3)·½·(c₂ − c₀) = 1 (k = 1,
    // a = 2·1·1/(3·2) = 1/3): p(½) = (0 + 0 + 3·1 + 1)/8 = ½.
    check(&values(&clip, "c", 0.5), &[0.5], "zero slope, tension 1");
}

/// glTF CUBICSPLINE (docs/clip-format.md, “Other interpolation modes”): `h =
/// 2`, at `u = ½` the Hermite basis is (½, ⅛, ½, −⅛).
#[test]
fn cubic_hermite_uses_the_tangents_per_component() {
    let mut p = ParameterSpec::new("h", Interpolation::CubicHermite, vec![0.0, 2.0], rows(&[&[0.0, 1.0], &[1.0, 0.0]]));
    p.out_tangents = Some(rows(&[&[1.0, 0.0], &[0.0, 0.0]]));
    p.in_tangents = Some(rows(&[&[0.0, 0.0], &[0.5, -1.0]]));
    let clip = build(vec![p]);
    // x: ½·0 + ⅛·2·1 + ½·1 − ⅛·2·0.5 = 0.625; y: ½·1 + 0 + 0 − ⅛·2·(−1) = 0.75.
    check(&values(&clip, "h", 1.0), &[0.625, 0.75], "u = ½");
}

#[test]
fn parameter_keys_count_toward_the_time_range() {
    let clip = build(vec![ParameterSpec::new("r", Interpolation::Linear, vec![-1.0, 3.0], rows(&[&[0.0], &[4.0]]))]);
    assert_eq!((clip.start(), clip.end()), (-1.0, 3.0));
    check(&values(&clip, "r", 2.0), &[3.0], "inside the widened range");
}

#[test]
fn a_clip_may_animate_parameters_alone() {
    let p = ParameterSpec::new("fov", Interpolation::Linear, vec![0.0, 1.0], rows(&[&[40.0], &[60.0]]));
    let clip = Clip::build(&ClipSpec { name: "camera".into(), parameters: vec![p], ..Default::default() }).unwrap();
    assert_eq!(clip.joint_count(), 0);
    check(&values(&clip, "fov", 0.25), &[45.0], "t = 0.25");
    let none = Clip::build(&ClipSpec { name: "empty".into(), ..Default::default() }).unwrap_err();
    assert_eq!(none.kind.code(), "no_tracks");
}

fn refusal(parameters: Vec<ParameterSpec>) -> (&'static str, String) {
    let e = Clip::build(&spec(parameters)).expect_err("refused");
    (e.kind.code(), e.path.to_pointer())
}

#[test]
fn every_rule_is_refused_with_its_code_and_pointer() {
    let p = |values: Vec<Vec<f32>>| ParameterSpec::new("p", Interpolation::Linear, vec![0.0, 1.0], values);
    assert_eq!(refusal(vec![p(vec![vec![], vec![]])]), ("parameter_width", "/parameters/0/values/0".into()));
    assert_eq!(refusal(vec![p(vec![vec![0.0; 257]; 2])]), ("parameter_width", "/parameters/0/values/0".into()));
    assert!(Clip::build(&spec(vec![p(vec![vec![0.0; 256]; 2])])).is_ok(), "256 numbers are allowed");
    assert_eq!(refusal(vec![p(rows(&[&[0.0, 1.0], &[0.0]]))]), ("wrong_width", "/parameters/0/values/1".into()));
    assert_eq!(refusal(vec![p(rows(&[&[0.0]]))]), ("length_mismatch", "/parameters/0/values".into()));
    let nan = rows(&[&[0.0, 1.0, 2.0], &[0.0, 1.0, f32::NAN]]);
    assert_eq!(refusal(vec![p(nan)]), ("non_finite", "/parameters/0/values/1/2".into()));
    assert_eq!(refusal(vec![p(rows(&[&[0.0], &[1.0]])), p(rows(&[&[0.0], &[1.0]]))]), {
        ("duplicate_parameter", "/parameters/1/name".into())
    });
    let mut back = p(rows(&[&[0.0], &[1.0]]));
    back.times = vec![1.0, 1.0];
    assert_eq!(refusal(vec![back]), ("times_not_increasing", "/parameters/0/times/1".into()));
    let mut tension = p(rows(&[&[0.0], &[1.0]]));
    tension.tension = Some(0.3);
    assert_eq!(refusal(vec![tension]), ("only_catmull_rom", "/parameters/0/tension".into()));
    let mut hermite = p(rows(&[&[0.0], &[1.0]]));
    hermite.interpolation = Interpolation::CubicHermite;
    assert_eq!(refusal(vec![hermite.clone()]), ("missing_tangents", "/parameters/0/in_tangents".into()));
    hermite.in_tangents = Some(rows(&[&[0.0], &[1.0, 2.0]]));
    hermite.out_tangents = Some(rows(&[&[0.0], &[1.0]]));
    assert_eq!(refusal(vec![hermite]), ("wrong_width", "/parameters/0/in_tangents/1".into()));
    let mut unnamed = p(rows(&[&[0.0], &[1.0]]));
    unnamed.name.clear();
    assert_eq!(refusal(vec![unnamed]), ("bad_parameter_name", "/parameters/0/name".into()));
    let mut wrap = p(rows(&[&[0.0], &[1.0]]));
    (wrap.interpolation, wrap.ends) = (Interpolation::CatmullRom, Some(Ends::Wrap));
    assert_eq!(refusal(vec![wrap]), ("wrap_ends_differ", "/parameters/0/values/1".into()));
}

/// A one-joint clip over [0, 2] whose parameters are constant: `(name, value)`.
fn constant(name: &str, parameters: &[(&str, &[f32])]) -> Clip {
    let parameters = parameters
        .iter()
        .map(|(n, v)| ParameterSpec::new(n, Interpolation::Linear, vec![0.0, 2.0], vec![v.to_vec(), v.to_vec()]))
        .collect();
    Clip::build(&ClipSpec { name: name.into(), ..spec(parameters) }).unwrap()
}

fn motion_values(m: &Motion<&Clip>, name: &str) -> Vec<f64> {
    let mut sampler = MotionSampler::new();
    m.sample(0.5, &MotionOptions::default(), &mut sampler);
    let p = m.parameters().index_of(name).unwrap();
    m.parameters().values(sampler.pose(), p).map(f64::from).collect()
}

#[test]
fn layers_blend_and_add_parameters_like_translations() {
    let a = constant("a", &[("face", &[1.0, 2.0, 3.0, 4.0]), ("fov", &[40.0])]);
    let b = constant("b", &[("face", &[5.0, 6.0, 7.0, 8.0])]);
    let build = |layers| Motion::build(MotionSpec { layers, ..Default::default() }).unwrap();
    // A blend at 0.25 lerps; `fov`, which b lacks, stays a's.
    let m = build(vec![LayerSpec::new(&a), LayerSpec { weight: 0.25, ..LayerSpec::new(&b) }]);
    check(&motion_values(&m, "face"), &[2.0, 3.0, 4.0, 5.0], "blend at ¼");
    check(&motion_values(&m, "fov"), &[40.0], "a parameter the layer lacks");
    // The first layer at 0.5 blends from 0, a parameter's rest value.
    let m = build(vec![LayerSpec { weight: 0.5, ..LayerSpec::new(&a) }]);
    check(&motion_values(&m, "fov"), &[20.0], "half the first layer over rest");
    // An additive layer adds w·(value − reference): c moves from its t = 0 value.
    let ramp =
        ParameterSpec::new("face", Interpolation::Linear, vec![0.0, 2.0], rows(&[&[0.0; 4], &[2.0, 0.0, -2.0, 4.0]]));
    let c = Clip::build(&ClipSpec { name: "c".into(), ..spec(vec![ramp]) }).unwrap();
    let additive =
        LayerSpec { mode: LayerMode::Additive, weight: 0.5, reference_time: Some(0.0), ..LayerSpec::new(&c) };
    let m = build(vec![LayerSpec::new(&a), additive]);
    // At t = 0.5 c is ¼ of the way: [0.5, 0, −0.5, 1]; half of it added.
    check(&motion_values(&m, "face"), &[1.25, 2.0, 2.75, 4.5], "additive at ½");
}

#[test]
fn layers_whose_parameter_widths_differ_are_refused() {
    let a = constant("a", &[("face", &[1.0, 2.0])]);
    let b = constant("b", &[("face", &[1.0, 2.0, 3.0])]);
    let e = Motion::build(MotionSpec { layers: vec![LayerSpec::new(&a), LayerSpec::new(&b)], ..Default::default() })
        .unwrap_err();
    assert_eq!((e.kind.code(), e.path.to_pointer()), ("parameter_width_mismatch", "/layers/1/clip".into()));
}

#[test]
fn a_crossfade_lerps_parameters_and_needs_the_same_ones() {
    let a = Arc::new(constant("a", &[("fov", &[40.0])]));
    let b = Arc::new(constant("b", &[("fov", &[60.0])]));
    let other = Arc::new(constant("c", &[("zoom", &[1.0])]));
    let one = |clip: &Arc<Clip>| {
        Arc::new(
            Motion::build(MotionSpec { layers: vec![LayerSpec::new(Arc::clone(clip))], ..Default::default() }).unwrap(),
        )
    };
    let mut player = Player::new(one(&a));
    let options = MotionOptions::default();
    player.sample(0.0, &options);
    assert!(player.crossfade(one(&other), 1.0, Ease::Linear).is_err(), "other parameters are refused");
    player.crossfade(one(&b), 1.0, Ease::Linear).unwrap();
    player.sample(0.0, &options);
    player.sample(0.25, &options);
    let fov = player.pose().parameters[0].x as f64;
    assert!((fov - 45.0).abs() < TOL * 45.0, "a quarter into the fade: {fov}");
}

#[test]
fn sampling_parameters_does_not_allocate_once_warm() {
    let wide = ParameterSpec::new("w", Interpolation::CatmullRom, vec![0.0, 1.0, 2.0], vec![vec![0.5; 64]; 3]);
    let clip = build(vec![wide]);
    let mut sampler = Sampler::new();
    clip.sample(0.3, &SampleOptions::default(), &mut sampler);
    let before = crate::allocations();
    for k in 0..100 {
        clip.sample(k as f64 * 0.02, &SampleOptions::default(), &mut sampler);
    }
    assert_eq!(crate::allocations() - before, 0);
}
