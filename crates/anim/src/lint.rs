//! Warnings: clips that are valid but probably not what their author meant.
//!
//! [`Clip::build`](super::Clip::build) refuses what breaks a rule; this
//! module only *notices* what is allowed yet suspicious, so an upload still
//! succeeds and its answer says what looked wrong. Each check is a rule
//! with a fixed threshold (docs/warnings.md states them), reported as data —
//! a [`Lint`] naming its track and key — which the edge renders with a
//! pointer into the document the user sent (a clip's JSON, a glTF channel,
//! a BVH header). Nothing here changes a clip, except
//! [`make_hemisphere_continuous`], which an importer applies only when asked.
//!
//! Why the `[w, x, y, z]` rule compares against the rest rotation and not
//! the track's travel or smoothness: reading a quaternion's four numbers in
//! another order is an orthogonal map of R⁴, so every dot product between
//! two keys — hence every angle between keys, the total angular travel, and
//! the size of each step — is the same both ways. (Precisely, the cyclic
//! shift is `q ↦ a·q̄·b` for fixed unit `a`, `b`: it swaps body and world
//! angular velocity up to a constant rotation, so smoothness cannot tell
//! them apart either.) What does differ is where the keys sit relative to a
//! fixed rotation: a joint's keys stay within some tens of degrees of its rest
//! rotation, and a `[w, x, y, z]` key read as `[x, y, z, w]` lands near a
//! half turn from it.

use glam::{DQuat, DVec4, Vec4};

use super::path::Path;
use super::spec::{Channel, ClipSpec, Interpolation, Keys, TrackSpec};

/// What a warning is about. Each has a stable snake_case code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LintCode {
    /// A rotation key's norm is off by more than [`NORM_TOLERANCE`].
    RotationNotUnit,
    /// Every key reads far more plausibly as `[w, x, y, z]`.
    RotationLooksWFirst,
    /// Key times are consecutive integers over a long span: frame numbers.
    TimesLookLikeFrames,
    /// A `cubic_hermite` rotation track's consecutive keys lie in opposite
    /// hemispheres, so the curve turns the long way between them.
    RotationHemisphereFlips,
}

impl LintCode {
    /// The code as reported (`rotation_not_unit`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            LintCode::RotationNotUnit => "rotation_not_unit",
            LintCode::RotationLooksWFirst => "rotation_looks_w_first",
            LintCode::TimesLookLikeFrames => "times_look_like_frames",
            LintCode::RotationHemisphereFlips => "rotation_hemisphere_flips",
        }
    }
}

/// One warning about one track of a [`ClipSpec`].
#[derive(Debug, Clone, PartialEq)]
pub struct Lint {
    pub code: LintCode,
    /// The track's index in `ClipSpec::tracks`.
    pub track: usize,
    /// `times` or `values`.
    pub field: &'static str,
    /// The first key concerned, if the warning is about keys.
    pub key: Option<usize>,
    /// What was noticed, with the figures the rule compared.
    pub detail: String,
}

impl Lint {
    /// Where it is in a clip document: `/tracks/3/values/5`.
    pub fn path(&self) -> Path {
        let path = Path::root().field("tracks").index(self.track).field(self.field);
        match self.key {
            Some(k) => path.index(k),
            None => path,
        }
    }
}

/// A rotation key whose norm differs from 1 by more than this (relative)
/// is reported: 1 %, far above f32 rounding or 16-bit quantisation.
pub const NORM_TOLERANCE: f64 = 0.01;
/// `[w, x, y, z]` rule: at least this many keys, every one at least
/// [`W_FIRST_FAR_DEG`] from the rest rotation as given and within
/// [`W_FIRST_NEAR_DEG`] of it read `[w, x, y, z]`.
pub const W_FIRST_MIN_KEYS: usize = 3;
pub const W_FIRST_FAR_DEG: f64 = 120.0;
pub const W_FIRST_NEAR_DEG: f64 = 60.0;
/// Frame-number rule: at least [`FRAMES_MIN_KEYS`] keys at evenly spaced
/// whole-number times (0, 6, 12, …) spanning at least [`FRAMES_MIN_SPAN`]
/// "seconds", or a run of at least [`FRAMES_MIN_RUN`] consecutive whole
/// numbers, however short (0, 1, 2, 3, 4: five frames, not five seconds).
pub const FRAMES_MIN_KEYS: usize = 3;
pub const FRAMES_MIN_SPAN: f64 = 10.0;
pub const FRAMES_MIN_RUN: usize = 5;

/// Every warning about `spec`, track by track, in track order.
pub fn lint(spec: &ClipSpec) -> Vec<Lint> {
    let mut out = rotations(spec);
    out.extend(times(spec));
    out.sort_by_key(|l| l.track);
    out
}

/// The rotation warnings: norms, `[w, x, y, z]` order, hemisphere flips.
pub fn rotations(spec: &ClipSpec) -> Vec<Lint> {
    let mut out = Vec::new();
    for (i, track) in spec.tracks.iter().enumerate() {
        let (Channel::Rotation, Keys::Vec4(keys)) = (track.channel, &track.values) else { continue };
        out.extend(not_unit(i, track, keys));
        out.extend(w_first(i, track, keys, rest_rotation(spec, &track.joint)));
        if track.interpolation == Interpolation::CubicHermite {
            out.extend(hemisphere_flips(i, keys));
        }
    }
    out
}

/// The time warning, once per clip: the first track whose times look like
/// frame numbers, and how many do.
pub fn times(spec: &ClipSpec) -> Option<Lint> {
    let mut frames = spec.tracks.iter().enumerate().filter(|(_, t)| looks_like_frames(&t.times));
    let (first, track) = frames.next()?;
    let others = frames.count();
    let (t0, tn) = (track.times[0], track.times[track.times.len() - 1]);
    let also = if others > 0 { format!(" (and {others} other tracks)") } else { String::new() };
    Some(Lint {
        code: LintCode::TimesLookLikeFrames,
        track: first,
        field: "times",
        key: None,
        detail: format!(
            "the {} keys of the '{}' {} track{also} sit at {} whole numbers {t0}, {}, …, {tn}: these look like \
             frame numbers, not seconds, so the clip lasts {} s; divide the times by the frame rate",
            track.times.len(),
            track.joint,
            track.channel.as_str(),
            if track.times[1] - t0 == 1.0 { "consecutive" } else { "evenly spaced" },
            track.times[1],
            tn - t0
        ),
    })
}

/// Whole-number times a whole step apart: at least [`FRAMES_MIN_KEYS`]
/// spanning at least [`FRAMES_MIN_SPAN`], or at least [`FRAMES_MIN_RUN`]
/// one apart.
fn looks_like_frames(times: &[f32]) -> bool {
    let (Some(&first), Some(&last)) = (times.first(), times.last()) else { return false };
    if times.len() < FRAMES_MIN_KEYS || !times.iter().all(|t| t.fract() == 0.0) {
        return false;
    }
    let step = times[1] - first;
    let even = step >= 1.0 && times.windows(2).all(|w| w[1] - w[0] == step);
    even && (f64::from(last - first) >= FRAMES_MIN_SPAN || (step == 1.0 && times.len() >= FRAMES_MIN_RUN))
}

/// The joint's rest rotation as given (identity without a skeleton entry).
fn rest_rotation(spec: &ClipSpec, joint: &str) -> DQuat {
    let rest = spec.skeleton.as_ref().and_then(|s| s.joints.iter().find(|j| j.name == joint)).map(|j| j.rest.rotation);
    rest.map_or(DQuat::IDENTITY, |q| q.as_dquat())
}

fn not_unit(track: usize, spec: &TrackSpec, keys: &[Vec4]) -> Option<Lint> {
    let off = |q: &Vec4| (q.as_dvec4().length() - 1.0).abs() > NORM_TOLERANCE;
    let first = keys.iter().position(off)?;
    let count = keys.iter().filter(|q| off(q)).count();
    let how = if spec.interpolation == Interpolation::CubicHermite {
        "cubic_hermite keys are interpolated as given and the result normalised (glTF's rule), \
         so the curve between them is not the one a unit key would give"
    } else {
        "they are normalised before use"
    };
    Some(Lint {
        code: LintCode::RotationNotUnit,
        track,
        field: "values",
        key: Some(first),
        detail: format!(
            "{count} of {} rotation keys of '{}' have a norm off by more than 1 % (key {first}: {:.4}); {how}",
            keys.len(),
            spec.joint,
            keys[first].as_dvec4().length()
        ),
    })
}

/// The rotation the unit 4-vector `[a, b, c, d]` is when read as
/// `[w, x, y, z]`, as an `[x, y, z, w]` quaternion.
fn read_w_first(q: DVec4) -> DQuat {
    DQuat::from_xyzw(q.y, q.z, q.w, q.x)
}

/// The angle in degrees of the rotation between unit `p` and `q`.
fn angle_deg(p: DQuat, q: DQuat) -> f64 {
    2.0 * p.dot(q).abs().min(1.0).acos().to_degrees()
}

/// [`LintCode::RotationLooksWFirst`]: every key is at least
/// [`W_FIRST_FAR_DEG`] from the joint's rest rotation as given, and within
/// [`W_FIRST_NEAR_DEG`] of it read `[w, x, y, z]`, over at least
/// [`W_FIRST_MIN_KEYS`] keys. Angles between keys cannot tell the two
/// readings apart (module doc), the distance to the rest can.
fn w_first(track: usize, spec: &TrackSpec, keys: &[Vec4], rest: DQuat) -> Option<Lint> {
    if keys.len() < W_FIRST_MIN_KEYS || rest.length() < 1e-6 {
        return None;
    }
    let rest = rest.normalize();
    let (mut nearest_given, mut farthest_w_first) = (180.0f64, 0.0f64);
    for q in keys {
        let v = q.as_dvec4();
        if v.length() < 1e-6 {
            return None;
        }
        let v = v.normalize();
        nearest_given = nearest_given.min(angle_deg(DQuat::from_vec4(v), rest));
        farthest_w_first = farthest_w_first.max(angle_deg(read_w_first(v), rest));
    }
    (nearest_given >= W_FIRST_FAR_DEG && farthest_w_first <= W_FIRST_NEAR_DEG).then(|| Lint {
        code: LintCode::RotationLooksWFirst,
        track,
        field: "values",
        key: None,
        detail: format!(
            "the {} rotation keys of '{}' are all {nearest_given:.0}° or more from the joint's rest rotation as \
             [x, y, z, w], but all within {farthest_w_first:.0}° of it read as [w, x, y, z]: they were probably \
             written w first; quaternions here are [x, y, z, w]",
            keys.len(),
            spec.joint
        ),
    })
}

/// [`LintCode::RotationHemisphereFlips`]: consecutive `cubic_hermite`
/// keys with a negative dot product, which glTF's rule (interpolate the
/// 4-vectors as given) turns the long way round.
fn hemisphere_flips(track: usize, keys: &[Vec4]) -> Option<Lint> {
    let flipped = |i: usize| keys[i - 1].as_dvec4().dot(keys[i].as_dvec4()) < 0.0;
    let first = (1..keys.len()).find(|&i| flipped(i))?;
    let count = (1..keys.len()).filter(|&i| flipped(i)).count();
    Some(Lint {
        code: LintCode::RotationHemisphereFlips,
        track,
        field: "values",
        key: Some(first),
        detail: format!(
            "{count} of {} cubic_hermite rotation keys are in the opposite hemisphere to the key before (first: \
             key {first}); keys are used as given, so the rotation turns the long way between them",
            keys.len()
        ),
    })
}

/// Flips each rotation key of a `cubic_hermite` track, with its two
/// tangents, whose dot product with the key before (as already flipped) is
/// negative, so every segment turns the short way. `q` and `-q` are the
/// same rotation, and negating a key's value and tangents together only
/// moves its piece of the curve to the other hemisphere. Returns how many
/// keys were flipped; other tracks are left alone.
pub fn make_hemisphere_continuous(track: &mut TrackSpec) -> usize {
    let Keys::Vec4(values) = &mut track.values else { return 0 };
    if track.channel != Channel::Rotation || track.interpolation != Interpolation::CubicHermite {
        return 0;
    }
    let mut flipped = Vec::new();
    for i in 1..values.len() {
        if values[i - 1].dot(values[i]) < 0.0 {
            values[i] = -values[i];
            flipped.push(i);
        }
    }
    for tangents in [&mut track.in_tangents, &mut track.out_tangents].into_iter().flatten() {
        if let Keys::Vec4(t) = tangents {
            for &i in &flipped {
                if let Some(t) = t.get_mut(i) {
                    *t = -*t;
                }
            }
        }
    }
    flipped.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rotation_track(interpolation: Interpolation, values: Vec<[f32; 4]>) -> TrackSpec {
        let times = (0..values.len()).map(|i| i as f32 * 0.5).collect();
        let keys = Keys::Vec4(values.into_iter().map(Vec4::from).collect());
        TrackSpec::new("j", Channel::Rotation, interpolation, times, keys)
    }

    fn clip(tracks: Vec<TrackSpec>) -> ClipSpec {
        ClipSpec { name: "c".into(), tracks, ..Default::default() }
    }

    fn codes(spec: &ClipSpec) -> Vec<(&'static str, String)> {
        lint(spec).iter().map(|l| (l.code.as_str(), l.path().to_pointer())).collect()
    }

    #[test]
    fn a_norm_off_by_more_than_one_percent_is_reported_at_its_first_key() {
        let s = clip(vec![rotation_track(Interpolation::Linear, vec![[0., 0., 0., 1.005], [0., 0., 0., 1.02]])]);
        assert_eq!(codes(&s), [("rotation_not_unit", "/tracks/0/values/1".into())]);
    }

    #[test]
    fn w_first_keys_near_identity_are_reported_and_x_y_z_w_ones_are_not() {
        // 10°, 20°, 30° about z written [w, x, y, z].
        let w_first: Vec<[f32; 4]> = [10f32, 20., 30.]
            .iter()
            .map(|d| {
                let h = d.to_radians() / 2.0;
                [h.cos(), 0., 0., h.sin()]
            })
            .collect();
        let fixed: Vec<[f32; 4]> = w_first.iter().map(|q| [q[1], q[2], q[3], q[0]]).collect();
        assert_eq!(
            codes(&clip(vec![rotation_track(Interpolation::Linear, w_first)])),
            [("rotation_looks_w_first", "/tracks/0/values".into())]
        );
        assert_eq!(codes(&clip(vec![rotation_track(Interpolation::Linear, fixed)])), []);
    }

    #[test]
    fn evenly_spaced_whole_numbers_and_short_runs_look_like_frames() {
        let track = |n: usize, step: f32| {
            let times = (0..n).map(|i| i as f32 * step).collect();
            TrackSpec::new(
                "j",
                Channel::Translation,
                Interpolation::Linear,
                times,
                Keys::Vec3(vec![glam::Vec3::ZERO; n]),
            )
        };
        let frames = [("times_look_like_frames", "/tracks/0/times".into())];
        assert_eq!(codes(&clip(vec![track(11, 1.0)])), frames);
        assert_eq!(codes(&clip(vec![track(5, 1.0)])), frames, "a short run: 0..4");
        assert_eq!(codes(&clip(vec![track(3, 6.0)])), frames, "0, 6, 12: every sixth frame");
        assert_eq!(codes(&clip(vec![track(11, 2.0)])), frames, "every other frame");
        assert_eq!(codes(&clip(vec![track(4, 1.0)])), [], "0..3: a few seconds, keyed each second");
        assert_eq!(codes(&clip(vec![track(3, 4.0)])), [], "0, 4, 8: under 10 s");
        assert_eq!(codes(&clip(vec![track(2, 20.0)])), [], "two keys say nothing");
        assert_eq!(codes(&clip(vec![track(30, 0.5)])), []);
    }

    #[test]
    fn hemisphere_flips_are_reported_and_fixed_with_their_tangents() {
        let mut t = rotation_track(
            Interpolation::CubicHermite,
            vec![[0., 0., 0., 1.], [0., 0., -0.6, -0.8], [0., 0., 0.8, 0.6]],
        );
        t.in_tangents = Some(Keys::Vec4(vec![Vec4::ZERO, Vec4::ONE, Vec4::ONE]));
        t.out_tangents = Some(Keys::Vec4(vec![Vec4::ZERO, Vec4::ONE, Vec4::ONE]));
        assert_eq!(codes(&clip(vec![t.clone()])), [("rotation_hemisphere_flips", "/tracks/0/values/1".into())]);
        assert_eq!(make_hemisphere_continuous(&mut t), 1, "key 2 is on key 1's side once key 1 is flipped");
        assert_eq!(t.values, Keys::Vec4(vec![Vec4::W, Vec4::new(0., 0., 0.6, 0.8), Vec4::new(0., 0., 0.8, 0.6)]));
        assert_eq!(t.in_tangents, Some(Keys::Vec4(vec![Vec4::ZERO, -Vec4::ONE, Vec4::ONE])));
        assert_eq!(codes(&clip(vec![t])), []);
    }
}
