//! From a [`TrackSpec`] to its runtime curve: every per-track rule of
//! docs/clip-format.md (“Data model”, “Evaluation math”) is checked here, once,
//! and every control point is computed here, once, in `f64`.
//!
//! Catmull-Rom and the uniform B-spline are written once for vectors and
//! quaternions through [`Key::offset`], the lecture's "hack by association":
//! `x + s·(y − z)` for vectors becomes `pow(short(y·z⁻¹), s)·x` for
//! quaternions (and so `lerp` becomes the short-way `slerp`).

use glam::{DQuat, DVec3, DVec4, Quat, Vec3, Vec3A, Vec4};

use super::arc::{self, Meter};
use super::curve::{QuatCurve, QuatSegment, SlerpCurve, SlerpTier, Vec3Curve};
use super::error::{ClipError, ClipErrorKind as K};
use super::path::Path;
use super::quat::{
    FAST_SLERP_MIN_COS, NARROW_SLERP_MIN_COS, SERIES_MAX_ANGLE, TINY_SLERP_MIN_COS, align, make_continuous, pow, short,
    sine_ratio_series,
};
use super::spec::{Channel, Ends, Interpolation, Keys, Speed, TrackSpec};

/// A validated, compiled track: the times its curve is indexed by and the
/// time range it covers.
pub(crate) struct Compiled<C> {
    pub times: Vec<f32>,
    pub curve: C,
    pub domain: (f32, f32),
}

const DEFAULT_TENSION: f32 = 0.5;

/// Checks the rules every channel shares and returns the key times.
fn check_common(spec: &TrackSpec, path: &Path) -> Result<(), ClipError> {
    let err = |p: Path, k| Err(ClipError::new(p, k));
    let times = &spec.times;
    if times.is_empty() {
        return err(path.clone().field("times"), K::NoKeys);
    }
    let width = spec.channel.width();
    if spec.values.width() != width {
        return err(
            path.clone().field("values"),
            K::WrongWidth { channel: spec.channel.as_str(), expected: width, provided: spec.values.width() },
        );
    }
    if spec.values.len() != times.len() {
        return err(
            path.clone().field("values"),
            K::LengthMismatch { expected: times.len(), provided: spec.values.len() },
        );
    }
    for (i, &t) in times.iter().enumerate() {
        if !t.is_finite() {
            return err(path.clone().field("times").index(i), K::NonFinite);
        }
        if i > 0 && t <= times[i - 1] {
            return err(
                path.clone().field("times").index(i),
                K::TimesNotIncreasing { previous: times[i - 1], current: t },
            );
        }
    }
    check_finite(&spec.values, &path.clone().field("values"))?;
    let hermite = spec.interpolation == Interpolation::CubicHermite;
    for (field, tangents) in [("in_tangents", &spec.in_tangents), ("out_tangents", &spec.out_tangents)] {
        let p = path.clone().field(field);
        match (hermite, tangents) {
            (false, Some(_)) => return err(p, K::OnlyHermite { field }),
            (true, None) => return err(p, K::MissingTangents),
            (true, Some(k)) => {
                if k.width() != width {
                    return err(
                        p,
                        K::WrongWidth { channel: spec.channel.as_str(), expected: width, provided: k.width() },
                    );
                }
                if k.len() != times.len() {
                    return err(p, K::LengthMismatch { expected: times.len(), provided: k.len() });
                }
                check_finite(k, &p)?;
            }
            (false, None) => {}
        }
    }
    let catmull = spec.interpolation == Interpolation::CatmullRom;
    if spec.ends.is_some() && !(catmull || spec.interpolation == Interpolation::BSpline) {
        let kind = K::OnlyCatmullRom { field: "ends", modes: "catmull_rom and b_spline" };
        return err(path.clone().field("ends"), kind);
    }
    // The uniform B-spline's basis is fixed: it has no tension.
    if spec.tension.is_some() && !catmull {
        return err(path.clone().field("tension"), K::OnlyCatmullRom { field: "tension", modes: "catmull_rom" });
    }
    if let Some(k) = spec.tension
        && !(0.0..=1.0).contains(&k)
    {
        return err(path.clone().field("tension"), K::TensionOutOfRange { tension: k });
    }
    if spec.ends == Some(Ends::Phantom) && times.len() < 4 {
        return err(path.clone().field("ends"), K::PhantomTooFewKeys { provided: times.len() });
    }
    if spec.speed == Speed::Constant
        && (spec.channel != Channel::Translation || spec.interpolation == Interpolation::Step)
    {
        return err(path.clone().field("speed"), K::SpeedNotApplicable);
    }
    Ok(())
}

fn check_finite(keys: &Keys, path: &Path) -> Result<(), ClipError> {
    let bad = match keys {
        Keys::Vec3(v) => v.iter().position(|x| !x.is_finite()),
        Keys::Vec4(v) => v.iter().position(|x| !x.is_finite()),
    };
    match bad {
        Some(i) => Err(ClipError::new(path.clone().index(i), K::NonFinite)),
        None => Ok(()),
    }
}

/// Normalises one rotation key, refusing near-zero ones (docs/clip-format.md,
/// “Quaternion Catmull-Rom”).
pub(crate) fn unit_quat(v: Vec4, path: &Path) -> Result<DQuat, ClipError> {
    let d = v.as_dvec4();
    let norm = d.length();
    if norm.is_nan() || norm < 1e-6 {
        return Err(ClipError::new(path.clone(), K::ZeroQuaternion { norm: norm as f32 }));
    }
    Ok(DQuat::from_vec4(d / norm))
}

/// Compiles a translation or scale track; a constant-speed table's work is
/// charged to `meter` (the whole clip's), and refused once it is over.
pub(crate) fn vec3_track(
    spec: &TrackSpec,
    path: &Path,
    meter: &mut Meter<'_>,
) -> Result<Compiled<Vec3Curve>, ClipError> {
    check_common(spec, path)?;
    let Keys::Vec3(values) = &spec.values else { unreachable!("width checked") };
    let times = &spec.times;
    let n = times.len();
    let domain = (times[0], times[n - 1]);
    let a3 = |v: &Vec3| Vec3A::from(*v);
    if n == 1 {
        return Ok(Compiled { times: times.clone(), curve: Vec3Curve::Constant(a3(&values[0])), domain });
    }
    let c: Vec<DVec3> = values.iter().map(|v| v.as_dvec3()).collect();
    let t: Vec<f64> = times.iter().map(|&x| x as f64).collect();
    let segments: Vec<[DVec3; 4]> = match spec.interpolation {
        Interpolation::Step => {
            let keys = values.iter().map(a3).collect();
            return Ok(Compiled { times: times.clone(), curve: Vec3Curve::Step(keys), domain });
        }
        Interpolation::Linear if spec.speed == Speed::Keyed => {
            let keys = values.iter().map(a3).collect();
            return Ok(Compiled { times: times.clone(), curve: Vec3Curve::Linear(keys), domain });
        }
        // A line is the Bezier with control points at thirds
        // (`a + (b − a)·s` is exact when a = b; glam's lerp is not).
        Interpolation::Linear => {
            let at = |a: DVec3, b: DVec3, s: f64| a + (b - a) * s;
            c.windows(2).map(|w| [w[0], at(w[0], w[1], 1.0 / 3.0), at(w[0], w[1], 2.0 / 3.0), w[1]]).collect()
        }
        Interpolation::CubicHermite => {
            let (Some(Keys::Vec3(a)), Some(Keys::Vec3(b))) = (&spec.in_tangents, &spec.out_tangents) else {
                unreachable!("tangents checked")
            };
            (0..n - 1)
                .map(|i| {
                    let h = t[i + 1] - t[i];
                    [c[i], c[i] + b[i].as_dvec3() * (h / 3.0), c[i + 1] - a[i + 1].as_dvec3() * (h / 3.0), c[i + 1]]
                })
                .collect()
        }
        Interpolation::CatmullRom | Interpolation::BSpline => {
            let ends = spec.ends.unwrap_or_default();
            if ends == Ends::Wrap && !same_vec3(c[0], c[n - 1]) {
                return Err(ClipError::new(path.clone().field("values").index(n - 1), K::WrapEndsDiffer));
            }
            spline(spec, &c, &t, ends)
        }
    };
    // Phantom ends interpolate only the inner keys.
    let (t_in, inner) =
        if spec.ends == Some(Ends::Phantom) { (&t[1..n - 1], &times[1..n - 1]) } else { (&t[..], &times[..]) };
    let domain = (inner[0], inner[inner.len() - 1]);
    // Control points are computed in f64 and may overshoot the keys past f32.
    if let Some(k) = segments.iter().position(|s| !s.iter().all(|p| p.as_vec3().is_finite())) {
        return Err(ClipError::new(path.clone().field("values").index(k), K::CurveOverflow));
    }
    let f32_segments = || segments.iter().map(|s| s.map(|p| p.as_vec3().into())).collect::<Box<[[Vec3A; 4]]>>();
    let table = if spec.speed == Speed::Constant {
        let table = arc::build(&segments, t_in[0], t_in[t_in.len() - 1], meter);
        if meter.cancelled() {
            return Err(ClipError::new(path.clone(), K::BuildCancelled));
        }
        if meter.over() {
            let kind = K::BuildBudgetExceeded { limit: meter.limit(), spent: meter.spent() };
            return Err(ClipError::new(path.clone(), kind));
        }
        table
    } else {
        None
    };
    if let Some((arc_times, pieces)) = table {
        let curve = Vec3Curve::ConstantSpeed { segments: f32_segments(), pieces: pieces.into() };
        return Ok(Compiled { times: arc_times, curve, domain });
    }
    Ok(Compiled { times: inner.to_vec(), curve: Vec3Curve::Bezier(f32_segments()), domain })
}

/// Compiles a rotation track.
pub(crate) fn quat_track(spec: &TrackSpec, path: &Path) -> Result<Compiled<QuatCurve>, ClipError> {
    check_common(spec, path)?;
    let Keys::Vec4(values) = &spec.values else { unreachable!("width checked") };
    let times = &spec.times;
    let n = times.len();
    let domain = (times[0], times[n - 1]);
    let vpath = path.clone().field("values");
    if spec.interpolation == Interpolation::CubicHermite {
        // glTF: keys and tangents used as given; normalised after the cubic.
        let (Some(Keys::Vec4(a)), Some(Keys::Vec4(b))) = (&spec.in_tangents, &spec.out_tangents) else {
            unreachable!("tangents checked")
        };
        for (i, v) in values.iter().enumerate() {
            unit_quat(*v, &vpath.clone().index(i))?;
        }
        if n == 1 {
            let q = unit_quat(values[0], &vpath)?;
            return Ok(Compiled { times: times.clone(), curve: QuatCurve::Constant(q.as_quat()), domain });
        }
        let segs: Box<[[Vec4; 4]]> = (0..n - 1)
            .map(|i| {
                let h = times[i + 1] - times[i];
                [values[i], values[i] + b[i] * (h / 3.0), values[i + 1] - a[i + 1] * (h / 3.0), values[i + 1]]
            })
            .collect();
        if let Some(k) = segs.iter().position(|s| !s.iter().all(|p| p.is_finite())) {
            return Err(ClipError::new(vpath.index(k), K::CurveOverflow));
        }
        return Ok(Compiled { times: times.clone(), curve: QuatCurve::Hermite(segs), domain });
    }
    let mut c = values
        .iter()
        .enumerate()
        .map(|(i, v)| unit_quat(*v, &vpath.clone().index(i)))
        .collect::<Result<Vec<_>, _>>()?;
    make_continuous(&mut c);
    let f32_keys = |c: &[DQuat]| c.iter().map(|q| q.as_quat()).collect::<Box<[Quat]>>();
    if n == 1 {
        return Ok(Compiled { times: times.clone(), curve: QuatCurve::Constant(c[0].as_quat()), domain });
    }
    match spec.interpolation {
        Interpolation::Step => Ok(Compiled { times: times.clone(), curve: QuatCurve::Step(f32_keys(&c)), domain }),
        Interpolation::Linear => {
            Ok(Compiled { times: times.clone(), curve: QuatCurve::Slerp(slerp_curve(&c)), domain })
        }
        Interpolation::CatmullRom | Interpolation::BSpline => {
            let ends = spec.ends.unwrap_or_default();
            if ends == Ends::Wrap && c[0].dot(c[n - 1]).abs() < 1.0 - 1e-6 {
                return Err(ClipError::new(vpath.index(n - 1), K::WrapEndsDiffer));
            }
            let t: Vec<f64> = times.iter().map(|&x| x as f64).collect();
            let segments = spline(spec, &c, &t, ends);
            let inner = if ends == Ends::Phantom { &times[1..n - 1] } else { &times[..] };
            let domain = (inner[0], inner[inner.len() - 1]);
            let curve = QuatCurve::SlerpBezier(segments.iter().map(quat_segment).collect());
            Ok(Compiled { times: inner.to_vec(), curve, domain })
        }
        Interpolation::CubicHermite => unreachable!("handled above"),
    }
}

/// Linear rotation keys (already hemisphere-continuous) and the weight
/// series of each pair close enough for four terms.
fn slerp_curve(keys: &[DQuat]) -> SlerpCurve {
    let sine = keys
        .windows(2)
        .map(|w| {
            let theta = w[0].dot(w[1]).clamp(-1.0, 1.0).acos();
            if theta > SERIES_MAX_ANGLE {
                return Vec4::ZERO;
            }
            let c = sine_ratio_series(theta);
            DVec4::new(c[0], c[1], c[2], c[3]).as_vec4()
        })
        .collect();
    SlerpCurve { keys: keys.iter().map(|q| q.as_quat()).collect(), sine }
}

/// Aligns each control point to its predecessor's hemisphere (so every
/// first-level slerp is already the short way), stores the first-level
/// weight series and picks the slerp tier from the polygon's total turn.
pub fn quat_segment(p: &[DQuat; 4]) -> QuatSegment {
    let p0 = p[0];
    let p1 = align(p0, p[1]);
    let p2 = align(p1, p[2]);
    let p3 = align(p2, p[3]);
    let angles = [(p0, p1), (p1, p2), (p2, p3)].map(|(a, b)| a.dot(b).clamp(-1.0, 1.0).acos());
    let series = angles.map(sine_ratio_series);
    let sine = std::array::from_fn(|k| DVec4::new(series[0][k], series[1][k], series[2][k], 0.0).as_vec4());
    let turn: f64 = angles.iter().sum();
    // A margin for the f32 rounding of the intermediate points.
    let fits = |min_cos: f32| turn <= (min_cos as f64).acos() - 1e-3;
    let tier = if fits(TINY_SLERP_MIN_COS) {
        SlerpTier::Tiny
    } else if fits(NARROW_SLERP_MIN_COS) {
        SlerpTier::Narrow
    } else if fits(FAST_SLERP_MIN_COS) {
        SlerpTier::Wide
    } else {
        SlerpTier::Exact
    };
    let v = |q: DQuat| DVec4::from(q).as_vec4();
    QuatSegment { points: [v(p0), v(p1), v(p2), v(p3)], sine, tier }
}

fn same_vec3(a: DVec3, b: DVec3) -> bool {
    (a - b).abs().max_element() <= 1e-6 * a.abs().max_element().max(1.0)
}

/// A key type Catmull-Rom and the B-spline can be built on.
pub trait Key: Copy {
    /// `base + s·(to − from)` for vectors; `pow(short(to·from⁻¹), s)·base`
    /// for quaternions (docs/clip-format.md, “Catmull-Rom” and “Quaternion Catmull-Rom”).
    fn offset(base: Self, to: Self, from: Self, s: f64) -> Self;
}

impl Key for DVec3 {
    fn offset(base: Self, to: Self, from: Self, s: f64) -> Self {
        base + (to - from) * s
    }
}

impl Key for DQuat {
    fn offset(base: Self, to: Self, from: Self, s: f64) -> Self {
        (pow(short(to * from.conjugate()), s) * base).normalize()
    }
}

/// Bezier control points `[c_i, d_i, e_i, c_{i+1}]` of a cardinal spline with
/// tension `k` through `c` at times `t` (at least 2 keys), with the phantom
/// keys of `ends` (docs/clip-format.md, “Catmull-Rom” and “End conditions”).
/// Phantom ends drop the first and last key from the interpolated ones.
pub fn catmull_rom<T: Key>(c: &[T], t: &[f64], ends: Ends, k: f64) -> Vec<[T; 4]> {
    let n = c.len() - 1;
    // Extended keys: x[0] = c_{-1}, x[1..=m] = the interpolated keys, x[m+1] = c_{m}.
    let (mut x, mut tx): (Vec<T>, Vec<f64>) = (Vec::with_capacity(n + 3), Vec::with_capacity(n + 3));
    match ends {
        Ends::Phantom => {
            x.extend_from_slice(c);
            tx.extend_from_slice(t);
        }
        Ends::Wrap => {
            x.push(c[n - 1]);
            tx.push(t[0] - (t[n] - t[n - 1]));
            x.extend_from_slice(c);
            tx.extend_from_slice(t);
            x.push(c[1]);
            tx.push(t[n] + (t[1] - t[0]));
        }
        Ends::Reflect | Ends::ZeroSlope => {
            x.push(T::offset(c[0], c[0], c[1], 1.0));
            tx.push(2.0 * t[0] - t[1]);
            x.extend_from_slice(c);
            tx.extend_from_slice(t);
            x.push(T::offset(c[n], c[n], c[n - 1], 1.0));
            tx.push(2.0 * t[n] - t[n - 1]);
        }
    }
    let segments = x.len() - 3;
    let mut out = Vec::with_capacity(segments);
    for i in 1..=segments {
        // Here x[i] is c_i of the segment, x[i-1] = c_{i-1}, x[i+2] = c_{i+2}.
        let h = tx[i + 1] - tx[i];
        let a = 2.0 * k * h / (3.0 * (tx[i + 1] - tx[i - 1]));
        let b = 2.0 * k * h / (3.0 * (tx[i + 2] - tx[i]));
        let d = T::offset(x[i], x[i + 1], x[i - 1], a);
        let e = T::offset(x[i + 1], x[i + 2], x[i], -b);
        out.push([x[i], d, e, x[i + 1]]);
    }
    if ends == Ends::ZeroSlope {
        out[0][1] = out[0][0];
        let last = out.len() - 1;
        out[last][2] = out[last][3];
    }
    out
}

/// The Bezier segments of a `catmull_rom` or `b_spline` track.
fn spline<T: Key>(spec: &TrackSpec, c: &[T], t: &[f64], ends: Ends) -> Vec<[T; 4]> {
    match spec.interpolation {
        Interpolation::BSpline => b_spline(c, ends),
        _ => catmull_rom(c, t, ends, spec.tension.unwrap_or(DEFAULT_TENSION) as f64),
    }
}

/// Bezier control points of the lecture's uniform cubic B-spline with the keys
/// `c` as its control points (at least 2; at least 4 for phantom ends), by the
/// lecture's conversion (docs/clip-format.md, “Other interpolation modes”):
/// segment `i` from `c_{i-1}..c_{i+2}`, `b_1`, `b_2` at thirds of `c_i →
/// c_{i+1}`, `b_0` and `b_3` halfway to the neighbouring segments' thirds (so
/// adjacent segments share their joint and its tangent line). For quaternions
/// every `lerp` is the short-way slerp.
///
/// Key times play no part: each segment is the uniform basis in its own `u`,
/// which is exactly what docs/clip-format.md asks for on non-uniform keys. Phantom ends
/// use the first and last keys as control points only; reflect ends mirror
/// (`2c_0 − c_1`; rotations `c_0·c_1⁻¹·c_0`), which makes the curve start at
/// `c_0` and end at `c_n`;
/// zero-slope ends repeat the neighbour (`c_{-1} = c_1`), a zero velocity;
/// wrap ends continue the loop (`c_{-1} = c_{n-1}`, `c_{n+1} = c_1`).
pub fn b_spline<T: Key>(c: &[T], ends: Ends) -> Vec<[T; 4]> {
    let n = c.len() - 1;
    let lerp = |a: T, b: T, s: f64| T::offset(a, b, a, s);
    let (first, last) = match ends {
        Ends::Phantom => (None, None),
        Ends::Wrap => (Some(c[n - 1]), Some(c[1])),
        Ends::ZeroSlope => (Some(c[1]), Some(c[n - 1])),
        Ends::Reflect => (Some(T::offset(c[0], c[0], c[1], 1.0)), Some(T::offset(c[n], c[n], c[n - 1], 1.0))),
    };
    let x: Vec<T> = first.into_iter().chain(c.iter().copied()).chain(last).collect();
    x.windows(4)
        .map(|w| {
            let b1 = lerp(w[1], w[2], 1.0 / 3.0);
            let b2 = lerp(w[1], w[2], 2.0 / 3.0);
            let b0 = lerp(lerp(w[0], w[1], 2.0 / 3.0), b1, 0.5);
            let b3 = lerp(b2, lerp(w[2], w[3], 1.0 / 3.0), 0.5);
            [b0, b1, b2, b3]
        })
        .collect()
}

/// Converts spec-level vectors for the skeleton's rest transforms.
pub(crate) fn finite3(v: Vec3, path: Path) -> Result<Vec3A, ClipError> {
    if v.is_finite() { Ok(v.into()) } else { Err(ClipError::new(path, K::NonFinite)) }
}
