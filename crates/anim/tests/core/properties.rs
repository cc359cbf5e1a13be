//! What must hold for any keys (docs/clip-format.md, “Evaluation math”), as
//! proptest properties over random non-uniform key times, random values and
//! random rotations up to 150° apart.
//!
//! Derivatives are one-sided three-point differences on the sampled `f32`
//! curve (the parabola through the samples at `t`, `t ± δ`, `t ± 2δ`, with
//! the real `f32` spacings), compared with [`slope_tol`]: truncation is
//! `δ²·|c'''|/3` and rounding `~ε·|c|/δ`, both well under it, while a
//! broken `a_i`/`b_i` or phantom key moves a slope by `O(|Δc|/h)`.

use anim::{Channel, Clip, ClipSpec, Cursor, Ends, Interpolation, Keys, Playback, Pose, Speed, TrackSpec};
use glam::{Quat, Vec3, Vec4};
use proptest::prelude::*;

use std::time::Duration;

use crate::behaviour::build_within;
use crate::reference::RefTrack;

const DELTA: f32 = 5e-4;
/// Values at keys (docs/clip-format.md, “Accuracy”).
const VALUE_TOL: f32 = 1e-5;

/// Allowed difference between two slopes of magnitude about `v`.
fn slope_tol(v: f32) -> f32 {
    1e-2 + 2e-3 * v
}

fn times_strategy(min: usize, max: usize) -> impl Strategy<Value = Vec<f32>> {
    (-1.0f32..1.0, prop::collection::vec(0.15f32..1.0, min..=max)).prop_map(|(t0, gaps)| {
        let mut t = t0;
        gaps.iter()
            .map(|g| {
                let now = t;
                t += g;
                now
            })
            .collect()
    })
}

fn vec3_strategy() -> impl Strategy<Value = Vec3> {
    (-2.0f32..2.0, -2.0f32..2.0, -2.0f32..2.0).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// A rotation step: an axis (not normalised yet) and an angle up to 150°.
fn turn_strategy() -> impl Strategy<Value = Quat> {
    (vec3_strategy(), 0.0f32..150f32.to_radians()).prop_map(|(axis, angle)| {
        let axis = if axis.length() < 0.1 { Vec3::X } else { axis.normalize() };
        Quat::from_axis_angle(axis, angle)
    })
}

/// Rotation keys as a random walk of turns, each key given a random sign.
fn quat_keys(n: usize) -> impl Strategy<Value = Vec<Vec4>> {
    prop::collection::vec((turn_strategy(), any::<bool>()), n).prop_map(|steps| {
        let mut q = Quat::IDENTITY;
        steps
            .iter()
            .map(|&(turn, flip)| {
                q = (turn * q).normalize();
                Vec4::from(q) * if flip { -1.0 } else { 1.0 }
            })
            .collect()
    })
}

#[derive(Debug, Clone)]
struct Track {
    spec: TrackSpec,
}

/// A random track of `channel`/`interpolation` (and `ends`), `n_min..=n_max` keys.
fn track_strategy(
    channel: Channel,
    interpolation: Interpolation,
    ends: Option<Ends>,
    n_min: usize,
    n_max: usize,
) -> impl Strategy<Value = Track> {
    times_strategy(n_min, n_max).prop_flat_map(move |times| {
        let n = times.len();
        let values: BoxedStrategy<Keys> = if channel == Channel::Rotation {
            quat_keys(n).prop_map(Keys::Vec4).boxed()
        } else {
            prop::collection::vec(vec3_strategy(), n).prop_map(Keys::Vec3).boxed()
        };
        let tangents: BoxedStrategy<Keys> = if channel == Channel::Rotation {
            prop::collection::vec(vec3_strategy(), n)
                .prop_map(|v| Keys::Vec4(v.iter().map(|x| Vec4::from((*x * 0.3, 0.0))).collect()))
                .boxed()
        } else {
            prop::collection::vec(vec3_strategy(), n).prop_map(Keys::Vec3).boxed()
        };
        (Just(times), values, tangents.clone(), tangents, prop::option::of(0.0f32..=1.0)).prop_map(
            move |(times, mut values, a, b, tension)| {
                if ends == Some(Ends::Wrap) {
                    match &mut values {
                        Keys::Vec3(v) => v[n - 1] = v[0],
                        Keys::Vec4(v) => v[n - 1] = -v[0],
                    }
                }
                let mut spec = TrackSpec::new("j", channel, interpolation, times, values);
                if interpolation == Interpolation::CatmullRom {
                    spec.ends = ends;
                    spec.tension = tension;
                }
                if interpolation == Interpolation::BSpline {
                    spec.ends = ends;
                }
                if interpolation == Interpolation::CubicHermite {
                    spec.in_tangents = Some(a);
                    spec.out_tangents = Some(b);
                }
                Track { spec }
            },
        )
    })
}

struct Sampled {
    clip: Clip,
    cursor: Cursor,
    pose: Pose,
    channel: Channel,
}

impl Sampled {
    fn new(spec: &TrackSpec) -> Self {
        let clip_spec = ClipSpec {
            name: "p".into(),
            skeleton: None,
            tracks: vec![spec.clone()],
            events: vec![],
            playback: Playback::Loop,
            ..Default::default()
        };
        // A build that hangs (see `behaviour::constant_speed_builds_quickly…`)
        // fails the property instead of stalling the run.
        let clip = build_within(&clip_spec, Duration::from_secs(10))
            .unwrap_or_else(|e| panic!("{e}: {spec:?}"))
            .unwrap_or_else(|e| panic!("valid track refused: {e}"));
        Sampled { clip, cursor: Cursor::default(), pose: Pose::default(), channel: spec.channel }
    }

    /// The track's value at clip time `t` as a 4-vector (`w = 0` for vectors).
    fn at(&mut self, t: f32) -> Vec4 {
        self.clip.sample_into(t, &mut self.cursor, &mut self.pose);
        match self.channel {
            Channel::Rotation => Vec4::from(self.pose.rotations[0]),
            Channel::Translation => Vec4::from((Vec3::from(self.pose.translations[0]), 0.0)),
            Channel::Scale => Vec4::from((Vec3::from(self.pose.scales[0]), 0.0)),
        }
    }

    /// The one-sided slope at `t` from the side `dir` (+1 right, −1 left),
    /// with samples sign-aligned to the one at `t`.
    fn slope(&mut self, t: f32, dir: f32) -> Vec4 {
        let x = [t, t + dir * DELTA, t + dir * 2.0 * DELTA];
        let f0 = self.at(x[0]);
        let align = |v: Vec4| if v.dot(f0) < 0.0 { -v } else { v };
        let (f1, f2) = (align(self.at(x[1])), align(self.at(x[2])));
        let (h1, h2) = (x[1] - x[0], x[2] - x[0]);
        // Derivative at x0 of the parabola through the three samples.
        f0 * (-(h1 + h2) / (h1 * h2)) + f1 * (h2 / (h1 * (h2 - h1))) - f2 * (h1 / (h2 * (h2 - h1)))
    }
}

/// The key values as the core must reproduce them: rotations normalised.
fn key_values(spec: &TrackSpec) -> Vec<Vec4> {
    match &spec.values {
        Keys::Vec3(v) => v.iter().map(|x| Vec4::from((*x, 0.0))).collect(),
        Keys::Vec4(v) => v.iter().map(|q| q.normalize()).collect(),
    }
}

fn same_value(a: Vec4, b: Vec4) -> bool {
    (a - b).abs().max_element() <= VALUE_TOL || (a + b).abs().max_element() <= VALUE_TOL
}

fn all_kinds() -> Vec<(Interpolation, Option<Ends>)> {
    vec![
        (Interpolation::Step, None),
        (Interpolation::Linear, None),
        (Interpolation::CubicHermite, None),
        (Interpolation::CatmullRom, Some(Ends::Reflect)),
        (Interpolation::CatmullRom, Some(Ends::ZeroSlope)),
        (Interpolation::CatmullRom, Some(Ends::Wrap)),
        (Interpolation::CatmullRom, Some(Ends::Phantom)),
    ]
    .into_iter()
    .collect()
}

fn any_track(min_keys: usize) -> impl Strategy<Value = Track> {
    let mut options = Vec::new();
    for channel in Channel::ALL {
        for (interpolation, ends) in all_kinds() {
            let min = if ends == Some(Ends::Phantom) { min_keys.max(4) } else { min_keys };
            options.push(track_strategy(channel, interpolation, ends, min, 7).boxed());
        }
    }
    proptest::strategy::Union::new(options)
}

fn catmull_rom_track(min_keys: usize) -> impl Strategy<Value = Track> {
    let mut options = Vec::new();
    for channel in [Channel::Translation, Channel::Rotation] {
        for ends in [Ends::Reflect, Ends::ZeroSlope, Ends::Wrap, Ends::Phantom] {
            let min = if ends == Ends::Phantom { min_keys.max(4) } else { min_keys };
            options.push(track_strategy(channel, Interpolation::CatmullRom, Some(ends), min, 7).boxed());
        }
    }
    proptest::strategy::Union::new(options)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// Every mode passes through its keys (phantom ends: the inner keys);
    /// rotation keys come back normalised, either sign.
    #[test]
    fn keys_are_interpolated_exactly(track in any_track(2)) {
        let spec = &track.spec;
        let mut s = Sampled::new(spec);
        let values = key_values(spec);
        let n = values.len();
        let inner = if spec.ends == Some(Ends::Phantom) { 1..n - 1 } else { 0..n };
        for i in inner {
            let got = s.at(spec.times[i]);
            prop_assert!(same_value(got, values[i]), "key {} at t = {}: {} vs {}", i, spec.times[i], got, values[i]);
        }
    }

    /// Catmull-Rom is C1 at interior keys, for vectors and quaternions.
    #[test]
    fn catmull_rom_is_c1_at_interior_keys(track in catmull_rom_track(3)) {
        let spec = &track.spec;
        let mut s = Sampled::new(spec);
        let n = spec.times.len();
        let interior = if spec.ends == Some(Ends::Phantom) { 2..n - 2 } else { 1..n - 1 };
        for i in interior {
            let t = spec.times[i];
            let (left, right) = (s.slope(t, -1.0), s.slope(t, 1.0));
            let scale = left.length().max(right.length());
            prop_assert!(
                (left - right).abs().max_element() <= slope_tol(scale),
                "slopes at key {} (t = {}): left {} right {}", i, t, left, right
            );
        }
    }

    /// Looping a `wrap` track is C0 and C1 across the seam.
    #[test]
    fn wrap_is_c1_across_the_loop_seam(
        track in prop_oneof![
            track_strategy(Channel::Translation, Interpolation::CatmullRom, Some(Ends::Wrap), 3, 7),
            track_strategy(Channel::Rotation, Interpolation::CatmullRom, Some(Ends::Wrap), 3, 7),
        ]
    ) {
        let spec = &track.spec;
        let mut s = Sampled::new(spec);
        let (t0, tn) = (spec.times[0], spec.times[spec.times.len() - 1]);
        prop_assert!(same_value(s.at(t0), s.at(tn)), "C0 at the seam");
        let mut end = s.slope(tn, -1.0);
        let start = s.slope(t0, 1.0);
        if s.at(t0).dot(s.at(tn)) < 0.0 {
            end = -end;
        }
        let scale = start.length().max(end.length());
        prop_assert!((start - end).abs().max_element() <= slope_tol(scale), "slope at end {} vs start {}", end, start);
    }

    /// Every rotation output is a unit quaternion, including glTF cubic
    /// splines (normalised after the cubic) and B-splines (by slerp).
    #[test]
    fn rotations_are_unit_quaternions(
        track in prop_oneof![
            track_strategy(Channel::Rotation, Interpolation::CubicHermite, None, 2, 7),
            track_strategy(Channel::Rotation, Interpolation::CatmullRom, Some(Ends::Reflect), 2, 7),
            track_strategy(Channel::Rotation, Interpolation::Linear, None, 2, 7),
            track_strategy(Channel::Rotation, Interpolation::BSpline, Some(Ends::Reflect), 2, 7),
            track_strategy(Channel::Rotation, Interpolation::BSpline, Some(Ends::Phantom), 4, 7),
        ],
        at in prop::collection::vec(0.0f32..1.0, 20)
    ) {
        let spec = &track.spec;
        let mut s = Sampled::new(spec);
        let (a, b) = (spec.times[0], spec.times[spec.times.len() - 1]);
        for x in at {
            let q = s.at(a + (b - a) * x);
            prop_assert!((q.length() - 1.0).abs() <= 1e-5, "|q| = {} at {}", q.length(), x);
        }
    }

    /// Equal keys (and zero tangents) give a constant curve in every mode.
    /// (`speed: constant` on equal keys is pinned by
    /// `behaviour::constant_speed_builds_quickly_even_when_nothing_moves`:
    /// today such a build can run for minutes, which would stall this run.)
    #[test]
    fn constant_keys_give_a_constant_curve(
        track in any_track(1),
        at in prop::collection::vec(-0.2f32..1.2, 20),
    ) {
        let mut spec = track.spec.clone();
        let first = key_values(&spec)[0];
        let n = spec.times.len();
        spec.values = match &spec.values {
            Keys::Vec3(v) => Keys::Vec3(vec![v[0]; n]),
            // glTF cubic splines use keys as given: the same 4-vector.
            Keys::Vec4(v) if spec.interpolation == Interpolation::CubicHermite => Keys::Vec4(vec![v[0]; n]),
            // Otherwise the same rotation, assorted signs and norms.
            Keys::Vec4(v) => Keys::Vec4((0..n).map(|i| v[0] * [1.0, -2.0, 0.5][i % 3]).collect()),
        };
        let zero = |k: &Option<Keys>| k.as_ref().map(|k| match k {
            Keys::Vec3(_) => Keys::Vec3(vec![Vec3::ZERO; n]),
            Keys::Vec4(_) => Keys::Vec4(vec![Vec4::ZERO; n]),
        });
        spec.in_tangents = zero(&spec.in_tangents);
        spec.out_tangents = zero(&spec.out_tangents);
        let mut s = Sampled::new(&spec);
        let (a, b) = (spec.times[0], spec.times[n - 1]);
        for x in at {
            let got = s.at(a + (b - a) * x);
            prop_assert!(same_value(got, first), "{} vs {} at {}", got, first, x);
        }
    }
}

proptest! {
    // Constant-speed builds are the heaviest part of this suite in debug.
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// `speed: constant`: the point is where arc length `L·(t − t_0)/(t_n −
    /// t_0)` along the same path puts it, to within `1e-4·L`
    /// (docs/clip-format.md, “Speed control”). The path and its arc length come
    /// from the reference evaluator.
    #[test]
    fn constant_speed_tracks_move_at_constant_speed(
        track in prop_oneof![
            track_strategy(Channel::Translation, Interpolation::Linear, None, 2, 6),
            track_strategy(Channel::Translation, Interpolation::CubicHermite, None, 2, 6),
            track_strategy(Channel::Translation, Interpolation::CatmullRom, Some(Ends::Reflect), 2, 6),
            track_strategy(Channel::Translation, Interpolation::CatmullRom, Some(Ends::ZeroSlope), 2, 6),
            track_strategy(Channel::Translation, Interpolation::CatmullRom, Some(Ends::Phantom), 4, 6),
        ],
    ) {
        let mut spec = track.spec.clone();
        spec.speed = Speed::Constant;
        let mut s = Sampled::new(&spec);
        let reference = RefTrack::new(&spec);
        let length = reference.arc_length().unwrap();
        let (a, b) = reference.domain().unwrap();
        for k in 0..=50 {
            let t = a + (b - a) * k as f64 / 50.0;
            let got = s.at(t as f32);
            let expected = reference.vec3(t).as_vec3();
            let err = (got.truncate() - expected).abs().max_element();
            prop_assert!(err as f64 <= 1e-4 * length, "error {} > 1e-4·L (L = {}) at t = {}", err, length, t);
        }
    }
}
