//! An independent `f64` evaluator, written from docs/clip-format.md, “Evaluation math”, alone
//! (the § numbers below are that document's).
//!
//! It shares no code with `src/anim`: it takes the same authoring
//! [`ClipSpec`] but computes everything itself, the straightforward way —
//! de Casteljau with exact slerps `p·(p⁻¹·q)^u`, the `a_i`/`b_i` formulas and
//! phantom keys of §2.2–2.4, the Hermite basis of §2.5, the uniform
//! B-spline of §2.5 by the lecture's basis matrix (vectors) and by its
//! slerp construction (rotations), constant speed by a
//! numeric arc-length table and bisection (§2.6), playback and ease (§2.6–2.7)
//! and model space (§2.8). Speed is not a goal; being obviously right is.
//! glam's `f64` types are used only as plain vector/quaternion arithmetic.

use anim::{Channel, ClipSpec, Ease, Ends, Interpolation, Keys, Playback, Speed, TrackSpec};
use glam::{DMat4, DQuat, DVec3, DVec4};

/// `pow(q, a)` for a unit quaternion `q = (cos θ, sin θ·v)`, `θ ∈ [0, π]`.
pub fn qpow(q: DQuat, a: f64) -> DQuat {
    let v = DVec3::new(q.x, q.y, q.z);
    let s = v.length();
    if s == 0.0 {
        return DQuat::IDENTITY;
    }
    let theta = s.atan2(q.w);
    let axis = v / s;
    let (sn, cs) = (a * theta).sin_cos();
    DQuat::from_xyzw(axis.x * sn, axis.y * sn, axis.z * sn, cs)
}

/// `q` if `q.w >= 0`, else `-q`.
pub fn short(q: DQuat) -> DQuat {
    if q.w >= 0.0 { q } else { -q }
}

fn dot(p: DQuat, q: DQuat) -> f64 {
    p.x * q.x + p.y * q.y + p.z * q.z + p.w * q.w
}

/// Exact short-way slerp `p·(p⁻¹·q)^u`, normalised (docs/clip-format.md, “Quaternion Catmull-Rom”).
pub fn slerp(p: DQuat, q: DQuat, u: f64) -> DQuat {
    let q = if dot(p, q) < 0.0 { -q } else { q };
    (p * qpow(p.conjugate() * q, u)).normalize()
}

fn lerp3(a: DVec3, b: DVec3, u: f64) -> DVec3 {
    a * (1.0 - u) + b * u
}

/// De Casteljau, docs/clip-format.md, “Cubic Bezier by de Casteljau”, equations 1–6.
pub fn casteljau3(p: &[DVec3; 4], u: f64) -> DVec3 {
    let (f, g, h) = (lerp3(p[0], p[1], u), lerp3(p[1], p[2], u), lerp3(p[2], p[3], u));
    let (m, n) = (lerp3(f, g, u), lerp3(g, h, u));
    lerp3(m, n, u)
}

/// De Casteljau with `lerp` replaced by `slerp` (docs/clip-format.md, “Quaternion Catmull-Rom”).
pub fn casteljau_q(p: &[DQuat; 4], u: f64) -> DQuat {
    let (f, g, h) = (slerp(p[0], p[1], u), slerp(p[1], p[2], u), slerp(p[2], p[3], u));
    let (m, n) = (slerp(f, g, u), slerp(g, h, u));
    slerp(m, n, u)
}

/// The segment `i` holding `t` and its parameter `u`, clamped to the keys;
/// at and after the last key, the last segment with `u = 1`.
pub fn locate(times: &[f64], t: f64) -> (usize, f64) {
    let n = times.len();
    assert!(n >= 2);
    if t <= times[0] {
        return (0, 0.0);
    }
    if t >= times[n - 1] {
        return (n - 2, 1.0);
    }
    let mut i = 0;
    while !(times[i] <= t && t < times[i + 1]) {
        i += 1;
    }
    (i, (t - times[i]) / (times[i + 1] - times[i]))
}

fn times_of(spec: &TrackSpec) -> Vec<f64> {
    spec.times.iter().map(|&t| t as f64).collect()
}

fn vec3_keys(k: &Keys) -> Vec<DVec3> {
    match k {
        Keys::Vec3(v) => v.iter().map(|x| x.as_dvec3()).collect(),
        Keys::Vec4(_) => panic!("expected 3-vectors"),
    }
}

fn vec4_keys(k: &Keys) -> Vec<DVec4> {
    match k {
        Keys::Vec4(v) => v.iter().map(|x| x.as_dvec4()).collect(),
        Keys::Vec3(_) => panic!("expected 4-vectors"),
    }
}

/// Keys extended with the phantom keys of §2.4: `(times, keys)` where index 0
/// is `c_{-1}` and the last is `c_{n+1}`. For `phantom` the supplied keys are
/// used as they are. `zero_slope` needs no phantom keys (its end control
/// points are overridden), so it gets `reflect`'s, which are never used.
fn extended<T: Copy>(t: &[f64], c: &[T], ends: Ends, reflect: impl Fn(T, T) -> T) -> (Vec<f64>, Vec<T>) {
    let n = c.len() - 1;
    let mut tx = Vec::new();
    let mut cx = Vec::new();
    match ends {
        Ends::Phantom => return (t.to_vec(), c.to_vec()),
        Ends::Wrap => {
            tx.push(t[0] - (t[n] - t[n - 1]));
            cx.push(c[n - 1]);
        }
        Ends::Reflect | Ends::ZeroSlope => {
            tx.push(2.0 * t[0] - t[1]);
            cx.push(reflect(c[0], c[1]));
        }
    }
    tx.extend_from_slice(t);
    cx.extend_from_slice(c);
    match ends {
        Ends::Wrap => {
            tx.push(t[n] + (t[1] - t[0]));
            cx.push(c[1]);
        }
        _ => {
            tx.push(2.0 * t[n] - t[n - 1]);
            cx.push(reflect(c[n], c[n - 1]));
        }
    }
    (tx, cx)
}

/// `(a_i, b_i)` of §2.2 for the segment from extended key `i` to `i + 1`.
fn ab(tx: &[f64], i: usize, k: f64) -> (f64, f64) {
    let h = tx[i + 1] - tx[i];
    (2.0 * k * h / (3.0 * (tx[i + 1] - tx[i - 1])), 2.0 * k * h / (3.0 * (tx[i + 2] - tx[i])))
}

/// Catmull-Rom Bezier segments for vectors, with the times they span.
pub fn cr_vec3(t: &[f64], c: &[DVec3], ends: Ends, k: f64) -> (Vec<f64>, Vec<[DVec3; 4]>) {
    let (tx, cx) = extended(t, c, ends, |a, b| 2.0 * a - b);
    let mut segs = Vec::new();
    for i in 1..cx.len() - 2 {
        let (a, b) = ab(&tx, i, k);
        let d = cx[i] + a * (cx[i + 1] - cx[i - 1]);
        let e = cx[i + 1] - b * (cx[i + 2] - cx[i]);
        segs.push([cx[i], d, e, cx[i + 1]]);
    }
    if ends == Ends::ZeroSlope {
        segs[0][1] = segs[0][0];
        let l = segs.len() - 1;
        segs[l][2] = segs[l][3];
    }
    (tx[1..tx.len() - 1].to_vec(), segs)
}

/// Catmull-Rom slerp-Bezier segments for unit, hemisphere-continuous keys.
pub fn cr_quat(t: &[f64], c: &[DQuat], ends: Ends, k: f64) -> (Vec<f64>, Vec<[DQuat; 4]>) {
    let (tx, cx) = extended(t, c, ends, |a, b| a * b.conjugate() * a);
    let mut segs = Vec::new();
    for i in 1..cx.len() - 2 {
        let (a, b) = ab(&tx, i, k);
        let d = qpow(short(cx[i + 1] * cx[i - 1].conjugate()), a) * cx[i];
        let e = qpow(short(cx[i + 2] * cx[i].conjugate()), -b) * cx[i + 1];
        segs.push([cx[i], d, e, cx[i + 1]]);
    }
    if ends == Ends::ZeroSlope {
        segs[0][1] = segs[0][0];
        let l = segs.len() - 1;
        segs[l][2] = segs[l][3];
    }
    (tx[1..tx.len() - 1].to_vec(), segs)
}

/// The lecture's uniform cubic B-spline basis: a segment with control
/// points `P0..P3` is `[u³ u² u 1] · M · [P0 P1 P2 P3]ᵀ`.
pub const B_SPLINE_BASIS: [[f64; 4]; 4] = [
    [-1.0 / 6.0, 3.0 / 6.0, -3.0 / 6.0, 1.0 / 6.0],
    [3.0 / 6.0, -6.0 / 6.0, 3.0 / 6.0, 0.0],
    [-3.0 / 6.0, 0.0, 3.0 / 6.0, 0.0],
    [1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0, 0.0],
];

/// `row · M · P` for a row of powers of `u` (or their derivatives), taken
/// relative to `P1` (`M`'s weights sum to 1 for values and 0 for
/// derivatives), so that equal control points give exactly that point and
/// exactly zero speed.
fn basis_apply(row: [f64; 4], p: &[DVec3; 4]) -> DVec3 {
    let mut out = if row[3] == 1.0 { p[1] } else { DVec3::ZERO };
    for (k, pk) in p.iter().enumerate() {
        let w: f64 = (0..4).map(|r| row[r] * B_SPLINE_BASIS[r][k]).sum();
        out += (*pk - p[1]) * w;
    }
    out
}

/// The B-spline's control points per segment, with the outer ones of §2.5:
/// `reflect` as §2.4, `zero_slope` mirrored (`c_{-1} = c_1`), `wrap` as
/// §2.4, `phantom` the supplied keys. Returns the times the segments span.
fn b_spline_windows<T: Copy>(t: &[f64], c: &[T], ends: Ends, reflect: impl Fn(T, T) -> T) -> (Vec<f64>, Vec<[T; 4]>) {
    let n = c.len() - 1;
    let mut x = Vec::new();
    match ends {
        Ends::Phantom => {}
        Ends::Reflect => x.push(reflect(c[0], c[1])),
        Ends::ZeroSlope => x.push(c[1]),
        Ends::Wrap => x.push(c[n - 1]),
    }
    x.extend_from_slice(c);
    match ends {
        Ends::Phantom => {}
        Ends::Reflect => x.push(reflect(c[n], c[n - 1])),
        Ends::ZeroSlope => x.push(c[n - 1]),
        Ends::Wrap => x.push(c[1]),
    }
    let windows = x.windows(4).map(|w| [w[0], w[1], w[2], w[3]]).collect();
    let times = if ends == Ends::Phantom { t[1..n].to_vec() } else { t.to_vec() };
    (times, windows)
}

/// §2.5's slerp construction of a rotation B-spline segment's Bezier points.
pub fn b_spline_quat_segment(w: &[DQuat; 4]) -> [DQuat; 4] {
    let b1 = slerp(w[1], w[2], 1.0 / 3.0);
    let b2 = slerp(w[1], w[2], 2.0 / 3.0);
    let b0 = slerp(slerp(w[0], w[1], 2.0 / 3.0), b1, 0.5);
    let b3 = slerp(b2, slerp(w[2], w[3], 1.0 / 3.0), 0.5);
    [b0, b1, b2, b3]
}

/// The Hermite basis of §2.5 on any vector type.
fn hermite<T>(v0: T, b0: T, v1: T, a1: T, h: f64, u: f64) -> T
where
    T: std::ops::Mul<f64, Output = T> + std::ops::Add<Output = T>,
{
    let (u2, u3) = (u * u, u * u * u);
    v0 * (2.0 * u3 - 3.0 * u2 + 1.0)
        + b0 * ((u3 - 2.0 * u2 + u) * h)
        + v1 * (-2.0 * u3 + 3.0 * u2)
        + a1 * ((u3 - u2) * h)
}

/// A translation or scale path: the curve as a function of `(segment, u)`.
#[derive(Debug, Clone)]
pub enum Path3 {
    Linear(Vec<DVec3>),
    Bezier(Vec<[DVec3; 4]>),
    Hermite {
        v: Vec<DVec3>,
        a: Vec<DVec3>,
        b: Vec<DVec3>,
        h: Vec<f64>,
    },
    /// Uniform B-spline: each segment's four control points.
    BSpline(Vec<[DVec3; 4]>),
}

impl Path3 {
    fn at(&self, i: usize, u: f64) -> DVec3 {
        match self {
            Path3::Linear(c) => lerp3(c[i], c[i + 1], u),
            Path3::Bezier(s) => casteljau3(&s[i], u),
            Path3::Hermite { v, a, b, h } => hermite(v[i], b[i], v[i + 1], a[i + 1], h[i], u),
            Path3::BSpline(p) => basis_apply([u * u * u, u * u, u, 1.0], &p[i]),
        }
    }

    fn segments(&self) -> usize {
        match self {
            Path3::Linear(c) => c.len() - 1,
            Path3::Bezier(s) | Path3::BSpline(s) => s.len(),
            Path3::Hermite { h, .. } => h.len(),
        }
    }

    /// `|dc/du|` by the analytic derivative of each form.
    fn speed(&self, i: usize, u: f64) -> f64 {
        match self {
            Path3::Linear(c) => (c[i + 1] - c[i]).length(),
            Path3::Bezier(s) => {
                let p = &s[i];
                let v = 1.0 - u;
                ((p[1] - p[0]) * (3.0 * v * v) + (p[2] - p[1]) * (6.0 * u * v) + (p[3] - p[2]) * (3.0 * u * u)).length()
            }
            Path3::Hermite { v, a, b, h } => {
                let (u2, hh) = (u * u, h[i]);
                (v[i] * (6.0 * u2 - 6.0 * u)
                    + b[i] * ((3.0 * u2 - 4.0 * u + 1.0) * hh)
                    + v[i + 1] * (-6.0 * u2 + 6.0 * u)
                    + a[i + 1] * ((3.0 * u2 - 2.0 * u) * hh))
                    .length()
            }
            Path3::BSpline(p) => basis_apply([3.0 * u * u, 2.0 * u, 1.0, 0.0], &p[i]).length(),
        }
    }
}

/// Arc length by composite three-point Gauss-Legendre quadrature.
const ARC_STEPS: usize = 256;

fn gauss3(path: &Path3, i: usize, a: f64, b: f64) -> f64 {
    let x = (0.6f64).sqrt();
    let (m, r) = ((a + b) / 2.0, (b - a) / 2.0);
    r * (5.0 / 9.0 * path.speed(i, m - r * x) + 8.0 / 9.0 * path.speed(i, m) + 5.0 / 9.0 * path.speed(i, m + r * x))
}

/// A path walked at constant speed: the cumulative arc length at
/// `ARC_STEPS` parameter steps of each segment.
#[derive(Debug, Clone)]
pub struct ArcTable {
    path: Path3,
    /// `cum[i][j]`: arc length from the path's start to `(i, j/ARC_STEPS)`.
    cum: Vec<Vec<f64>>,
    pub length: f64,
}

impl ArcTable {
    fn new(path: Path3) -> Self {
        let mut cum = Vec::new();
        let mut s = 0.0;
        for i in 0..path.segments() {
            let mut row = vec![s];
            for j in 0..ARC_STEPS {
                let (a, b) = (j as f64 / ARC_STEPS as f64, (j + 1) as f64 / ARC_STEPS as f64);
                // Each step is split once more: the speed can have a kink
                // where it touches zero.
                s += gauss3(&path, i, a, (a + b) / 2.0) + gauss3(&path, i, (a + b) / 2.0, b);
                row.push(s);
            }
            cum.push(row);
        }
        ArcTable { path, cum, length: s }
    }

    /// The point at arc length `s` from the start.
    pub fn point_at(&self, s: f64) -> DVec3 {
        let s = s.clamp(0.0, self.length);
        let i = self.cum.iter().rposition(|row| row[0] <= s).unwrap_or(0);
        let row = &self.cum[i];
        let j = row.iter().rposition(|&x| x <= s).unwrap_or(0).min(ARC_STEPS - 1);
        let (mut lo, mut hi) = (j as f64 / ARC_STEPS as f64, (j + 1) as f64 / ARC_STEPS as f64);
        let (u0, base) = (lo, row[j]);
        for _ in 0..60 {
            let mid = (lo + hi) / 2.0;
            if base + gauss3(&self.path, i, u0, mid) < s {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        self.path.at(i, (lo + hi) / 2.0)
    }
}

/// One track, ready to evaluate in `f64`.
#[derive(Debug, Clone)]
pub enum RefTrack {
    Const3(DVec3),
    Step3(Vec<f64>, Vec<DVec3>),
    Path3(Vec<f64>, Path3),
    Arc { t0: f64, t1: f64, table: ArcTable },
    ConstQ(DQuat),
    StepQ(Vec<f64>, Vec<DQuat>),
    SlerpQ(Vec<f64>, Vec<DQuat>),
    BezierQ(Vec<f64>, Vec<[DQuat; 4]>),
    HermiteQ { t: Vec<f64>, v: Vec<DVec4>, a: Vec<DVec4>, b: Vec<DVec4> },
}

fn normalised_continuous(values: &[DVec4]) -> Vec<DQuat> {
    let mut q: Vec<DQuat> = values.iter().map(|v| DQuat::from_vec4(*v / v.length())).collect();
    for i in 1..q.len() {
        if dot(q[i - 1], q[i]) < 0.0 {
            q[i] = -q[i];
        }
    }
    q
}

impl RefTrack {
    /// The track of `spec`, which must be valid.
    pub fn new(spec: &TrackSpec) -> Self {
        let t = times_of(spec);
        let k = spec.tension.unwrap_or(0.5) as f64;
        let ends = spec.ends.unwrap_or(Ends::Reflect);
        if spec.channel == Channel::Rotation {
            let raw = vec4_keys(&spec.values);
            if spec.interpolation == Interpolation::CubicHermite {
                if raw.len() == 1 {
                    return RefTrack::ConstQ(DQuat::from_vec4(raw[0] / raw[0].length()));
                }
                let a = vec4_keys(spec.in_tangents.as_ref().unwrap());
                let b = vec4_keys(spec.out_tangents.as_ref().unwrap());
                return RefTrack::HermiteQ { t, v: raw, a, b };
            }
            let q = normalised_continuous(&raw);
            if q.len() == 1 {
                return RefTrack::ConstQ(q[0]);
            }
            return match spec.interpolation {
                Interpolation::Step => RefTrack::StepQ(t, q),
                Interpolation::Linear => RefTrack::SlerpQ(t, q),
                Interpolation::CatmullRom => {
                    let (t, segs) = cr_quat(&t, &q, ends, k);
                    RefTrack::BezierQ(t, segs)
                }
                Interpolation::BSpline => {
                    let (t, windows) = b_spline_windows(&t, &q, ends, |a, b| a * b.conjugate() * a);
                    RefTrack::BezierQ(t, windows.iter().map(b_spline_quat_segment).collect())
                }
                Interpolation::CubicHermite => unreachable!(),
            };
        }
        let c = vec3_keys(&spec.values);
        if c.len() == 1 {
            return RefTrack::Const3(c[0]);
        }
        let (t, path) = match spec.interpolation {
            Interpolation::Step => return RefTrack::Step3(t, c),
            Interpolation::Linear => (t, Path3::Linear(c)),
            Interpolation::CatmullRom => {
                let (t, segs) = cr_vec3(&t, &c, ends, k);
                (t, Path3::Bezier(segs))
            }
            Interpolation::CubicHermite => {
                let a = vec3_keys(spec.in_tangents.as_ref().unwrap());
                let b = vec3_keys(spec.out_tangents.as_ref().unwrap());
                let h = t.windows(2).map(|w| w[1] - w[0]).collect();
                (t, Path3::Hermite { v: c, a, b, h })
            }
            Interpolation::BSpline => {
                let (t, windows) = b_spline_windows(&t, &c, ends, |a, b| 2.0 * a - b);
                (t, Path3::BSpline(windows))
            }
        };
        if spec.speed == Speed::Constant {
            let table = ArcTable::new(path.clone());
            if table.length > 0.0 {
                return RefTrack::Arc { t0: t[0], t1: t[t.len() - 1], table };
            }
        }
        RefTrack::Path3(t, path)
    }

    /// The time range the track interpolates (phantom ends drop a key each side).
    pub fn domain(&self) -> Option<(f64, f64)> {
        let ends = |t: &[f64]| Some((t[0], t[t.len() - 1]));
        match self {
            RefTrack::Const3(_) | RefTrack::ConstQ(_) => None,
            RefTrack::Step3(t, _) | RefTrack::Path3(t, _) => ends(t),
            RefTrack::StepQ(t, _) | RefTrack::SlerpQ(t, _) | RefTrack::BezierQ(t, _) => ends(t),
            RefTrack::HermiteQ { t, .. } => ends(t),
            RefTrack::Arc { t0, t1, .. } => Some((*t0, *t1)),
        }
    }

    pub fn vec3(&self, time: f64) -> DVec3 {
        match self {
            RefTrack::Const3(v) => *v,
            RefTrack::Step3(t, c) => {
                let (i, u) = locate(t, time);
                if u >= 1.0 { c[i + 1] } else { c[i] }
            }
            RefTrack::Path3(t, path) => {
                let (i, u) = locate(t, time);
                path.at(i, u)
            }
            RefTrack::Arc { t0, t1, table } => {
                let x = ((time - t0) / (t1 - t0)).clamp(0.0, 1.0);
                table.point_at(table.length * x)
            }
            _ => panic!("not a vector track"),
        }
    }

    pub fn quat(&self, time: f64) -> DQuat {
        match self {
            RefTrack::ConstQ(q) => *q,
            RefTrack::StepQ(t, c) => {
                let (i, u) = locate(t, time);
                if u >= 1.0 { c[i + 1] } else { c[i] }
            }
            RefTrack::SlerpQ(t, c) => {
                let (i, u) = locate(t, time);
                slerp(c[i], c[i + 1], u)
            }
            RefTrack::BezierQ(t, segs) => {
                let (i, u) = locate(t, time);
                casteljau_q(&segs[i], u)
            }
            RefTrack::HermiteQ { t, v, a, b } => {
                let (i, u) = locate(t, time);
                let r = hermite(v[i], b[i], v[i + 1], a[i + 1], t[i + 1] - t[i], u);
                DQuat::from_vec4(r / r.length())
            }
            _ => panic!("not a rotation track"),
        }
    }

    pub fn arc_length(&self) -> Option<f64> {
        match self {
            RefTrack::Arc { table, .. } => Some(table.length),
            _ => None,
        }
    }
}

/// A local or model transform in `f64`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trs {
    pub t: DVec3,
    pub r: DQuat,
    pub s: DVec3,
}

/// A whole clip in `f64`.
#[derive(Debug, Clone)]
pub struct RefClip {
    pub parents: Vec<Option<usize>>,
    pub rest: Vec<Trs>,
    /// `(joint, channel, track)`.
    tracks: Vec<(usize, Channel, RefTrack)>,
    pub start: f64,
    pub end: f64,
}

impl RefClip {
    /// The reference form of a valid spec.
    pub fn new(spec: &ClipSpec) -> Self {
        let (mut names, mut parents, mut rest) = (Vec::new(), Vec::new(), Vec::new());
        match &spec.skeleton {
            Some(s) => {
                for j in &s.joints {
                    names.push(j.name.clone());
                    parents.push(j.parent.as_ref().map(|p| names.iter().position(|n| n == p).unwrap()));
                    let r = j.rest.rotation.as_dquat();
                    rest.push(Trs {
                        t: j.rest.translation.as_dvec3(),
                        r: DQuat::from_vec4(DVec4::from(r) / DVec4::from(r).length()),
                        s: j.rest.scale.as_dvec3(),
                    });
                }
            }
            None => {
                for t in &spec.tracks {
                    if !names.contains(&t.joint) {
                        names.push(t.joint.clone());
                        parents.push(None);
                        rest.push(Trs { t: DVec3::ZERO, r: DQuat::IDENTITY, s: DVec3::ONE });
                    }
                }
            }
        }
        let (mut start, mut end) = (f64::INFINITY, f64::NEG_INFINITY);
        let mut tracks = Vec::new();
        for t in &spec.tracks {
            let track = RefTrack::new(t);
            let (a, b) = track.domain().unwrap_or((t.times[0] as f64, t.times[t.times.len() - 1] as f64));
            start = start.min(a);
            end = end.max(b);
            let j = names.iter().position(|n| n == &t.joint).unwrap();
            tracks.push((j, t.channel, track));
        }
        RefClip { parents, rest, tracks, start, end }
    }

    /// Request time → clip time (docs/clip-format.md, 2.6–2.7).
    pub fn clip_time(&self, t: f64, playback: Playback, ease: Ease) -> f64 {
        let d = self.end - self.start;
        if d <= 0.0 {
            return self.start;
        }
        let x = t - self.start;
        let x = match playback {
            Playback::Once => x.clamp(0.0, d),
            Playback::Loop => x - d * (x / d).floor(),
            Playback::PingPong => {
                let p = x - 2.0 * d * (x / (2.0 * d)).floor();
                if p <= d { p } else { 2.0 * d - p }
            }
        };
        let y = x / d;
        let y = match ease {
            Ease::Linear => y,
            Ease::EaseIn => y * y,
            Ease::EaseOut => 1.0 - (1.0 - y) * (1.0 - y),
            Ease::EaseInOut => 3.0 * y * y - 2.0 * y * y * y,
        };
        self.start + y * d
    }

    /// The local pose at clip time `t`.
    pub fn local(&self, t: f64) -> Vec<Trs> {
        let mut pose = self.rest.clone();
        for (j, channel, track) in &self.tracks {
            match channel {
                Channel::Translation => pose[*j].t = track.vec3(t),
                Channel::Scale => pose[*j].s = track.vec3(t),
                Channel::Rotation => pose[*j].r = track.quat(t),
            }
        }
        pose
    }

    /// Model space (§2.8): `t_m = t_p + q_p·(s_p ⊙ t_l)`, `q_m = q_p·q_l`, `s_m = s_p ⊙ s_l`.
    pub fn model(&self, local: &[Trs]) -> Vec<Trs> {
        let mut out: Vec<Trs> = Vec::with_capacity(local.len());
        for (j, l) in local.iter().enumerate() {
            let m = match self.parents[j] {
                None => *l,
                Some(p) => {
                    let p = out[p];
                    Trs { t: p.t + p.r * (p.s * l.t), r: p.r * l.r, s: p.s * l.s }
                }
            };
            out.push(m);
        }
        out
    }

    /// `M_j = M_parent · T·R·S`, composed by hand from the rotation matrix.
    pub fn matrices(&self, local: &[Trs]) -> Vec<DMat4> {
        let mut out: Vec<DMat4> = Vec::with_capacity(local.len());
        for (j, l) in local.iter().enumerate() {
            let q = l.r;
            let (x, y, z, w) = (q.x, q.y, q.z, q.w);
            let r = [
                [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)],
                [2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)],
                [2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)],
            ];
            let s = l.s.to_array();
            let mut cols = [0.0f64; 16];
            for c in 0..3 {
                for row in 0..3 {
                    cols[c * 4 + row] = r[c][row] * s[c];
                }
            }
            cols[12] = l.t.x;
            cols[13] = l.t.y;
            cols[14] = l.t.z;
            cols[15] = 1.0;
            let m = DMat4::from_cols_array(&cols);
            out.push(match self.parents[j] {
                None => m,
                Some(p) => out[p] * m,
            });
        }
        out
    }
}

/// The distance between two rotations as quaternion components, after
/// choosing the sign (the smaller of `|a − b|∞` and `|a + b|∞`, which is
/// "both with `w ≥ 0`" made robust where `w ≈ 0`).
pub fn quat_err(a: DQuat, b: DQuat) -> f64 {
    let (a, b) = (DVec4::from(a), DVec4::from(b));
    (a - b).abs().max_element().min((a + b).abs().max_element())
}

pub fn vec_err(a: DVec3, b: DVec3) -> f64 {
    (a - b).abs().max_element()
}
