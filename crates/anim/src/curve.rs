//! Compiled curves: the runtime form of one track, evaluated at a [`Span`].
//!
//! Every cubic mode is stored as per-segment Bezier control points `[c_i, d_i,
//! e_i, c_{i+1}]` (docs/clip-format.md, “Cubic Bezier by de Casteljau”),
//! computed once by `compile`: Catmull-Rom (§2.2, §2.3 there), cubic Hermite
//! (§2.5, `d = v_i + h·b_i/3`, `e = v_{i+1} − h·a_{i+1}/3`, the same cubic) and
//! constant-speed paths (§2.6). Evaluation is then a fixed, branch-light
//! sequence of arithmetic: Bernstein weights for vectors, three levels of slerp
//! de Casteljau for rotations. Nothing here allocates or fails. `tracks` stores
//! these by kind for the sampling loop.

use glam::{Quat, Vec3A, Vec4};

use super::quat::{
    series_weights, slerp_fast, slerp_weights, slerp_weights_exact, slerp_weights_narrow, slerp_weights_tiny,
};
use super::timeline::Span;

/// Bezier control points of one quaternion segment, signs chosen so that
/// each consecutive pair is its own short way, and the slerp weights of its
/// three first-level pairs as polynomials in `u` (their angles are fixed, so
/// `sin(uθ)/sin θ` is a Taylor series computed once: lane k of `sine[i]` is
/// coefficient i of pair k).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(16))]
pub struct QuatSegment {
    pub points: [Vec4; 4],
    pub sine: [Vec4; 5],
    pub tier: SlerpTier,
}

/// How the runtime slerps of a segment are computed. Every slerp of the de
/// Casteljau pyramid spans at most the control polygon's total turn, so the
/// turn, known at build time, picks a method that is accurate for all of them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum SlerpTier {
    /// Turn ≤ acos(TINY_SLERP_MIN_COS): 3-term polynomial weights.
    Tiny,
    /// Turn ≤ acos(NARROW_SLERP_MIN_COS): 4-term polynomial weights.
    Narrow,
    /// Turn ≤ acos(FAST_SLERP_MIN_COS): 6-term polynomial weights.
    Wide,
    /// Wider: exact `acos`/`sin` slerps.
    Exact,
}

/// Maps a span of a constant-speed track's arc-length timeline back to a
/// Bezier segment and parameter: `u = u0 + w·du`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcPiece {
    pub segment: u32,
    pub u0: f32,
    pub du: f32,
}

/// A translation or scale curve.
#[derive(Debug, Clone, PartialEq)]
pub enum Vec3Curve {
    Constant(Vec3A),
    Step(Box<[Vec3A]>),
    Linear(Box<[Vec3A]>),
    Bezier(Box<[[Vec3A; 4]]>),
    /// Bezier segments walked at constant speed; the track's timeline holds
    /// the arc-length breakpoints, one per piece.
    ConstantSpeed {
        segments: Box<[[Vec3A; 4]]>,
        pieces: Box<[ArcPiece]>,
    },
}

impl Vec3Curve {
    /// The largest coordinate magnitude the curve can take: each Bezier
    /// stays inside its control points' hull, so their largest bounds it.
    pub fn max_abs(&self) -> f32 {
        let of = |points: &mut dyn Iterator<Item = &Vec3A>| points.map(|p| p.abs().max_element()).fold(0.0, f32::max);
        match self {
            Vec3Curve::Constant(v) => v.abs().max_element(),
            Vec3Curve::Step(keys) | Vec3Curve::Linear(keys) => of(&mut keys.iter()),
            Vec3Curve::Bezier(segments) | Vec3Curve::ConstantSpeed { segments, .. } => {
                of(&mut segments.iter().flatten())
            }
        }
    }
}

impl Vec3Curve {
    /// The curve's value at `s`, a span of the timeline it was compiled
    /// with (a constant ignores it): one curve evaluated on its own, as a
    /// keyed IK target is, where track lists evaluate theirs in bulk.
    pub fn at(&self, s: Span) -> Vec3A {
        let i = s.index as usize;
        match self {
            Vec3Curve::Constant(v) => *v,
            Vec3Curve::Step(keys) => step(keys, s),
            Vec3Curve::Linear(keys) => lerp_keys(keys[i], keys[i + 1], s.u),
            Vec3Curve::Bezier(segments) => bezier3(&segments[i], s.u),
            Vec3Curve::ConstantSpeed { segments, pieces } => {
                let piece = pieces[i];
                bezier3(&segments[piece.segment as usize], piece.u0 + s.u * piece.du)
            }
        }
    }
}

/// A rotation curve.
#[derive(Debug, Clone, PartialEq)]
pub enum QuatCurve {
    Constant(Quat),
    Step(Box<[Quat]>),
    Slerp(SlerpCurve),
    /// Catmull-Rom by slerp de Casteljau (docs/clip-format.md, “Quaternion Catmull-Rom”).
    SlerpBezier(Box<[QuatSegment]>),
    /// glTF CUBICSPLINE: a cubic on the 4-vectors, then normalised.
    Hermite(Box<[[Vec4; 4]]>),
}

/// Linear rotation keys (docs/clip-format.md, “Other interpolation modes”),
/// each pair the short way, and per segment the series of its slerp weights:
/// the angle between two keys is fixed, so `sin(uθ)/sin θ` is a polynomial in
/// `u` computed once, and a sample needs no dot product, tier choice or
/// normalisation. A pair wider than
/// [`SERIES_MAX_ANGLE`](super::quat::SERIES_MAX_ANGLE) has a zero series and
/// takes [`slerp_fast`].
#[derive(Debug, Clone, PartialEq)]
pub struct SlerpCurve {
    pub keys: Box<[Quat]>,
    /// Per segment, coefficients 0..4 of [`sine_ratio_series`](super::quat::sine_ratio_series).
    pub sine: Box<[Vec4]>,
}

impl SlerpCurve {
    #[inline(always)]
    pub fn at(&self, s: Span) -> Quat {
        let i = s.index as usize;
        let (p, q, c) = (self.keys[i], self.keys[i + 1], self.sine[i]);
        if c.x == 0.0 {
            return slerp_fast(p, q, s.u);
        }
        let (wp, wq) = series_weights(c, s.u);
        Quat::from_vec4(Vec4::from(p) * wp + Vec4::from(q) * wq)
    }

    pub fn heap_bytes(&self) -> usize {
        std::mem::size_of_val(&*self.keys) + std::mem::size_of_val(&*self.sine)
    }
}

/// `a + (b − a)·u`: a linear key pair's value, exactly `a` between equal
/// keys (glam's `lerp`, `a·(1 − u) + b·u`, can round an ulp off them, which
/// would leave a constant channel's compact range, docs/compact-frames.md).
/// Keys so far apart that `b − a` overflows (near ±`f32::MAX`, which clips
/// may hold) take glam's form, which stays finite.
#[inline]
pub(crate) fn lerp_keys(a: Vec3A, b: Vec3A, u: f32) -> Vec3A {
    let d = b - a;
    if d.is_finite() { a + d * u } else { a.lerp(b, u) }
}

#[inline(always)]
pub(crate) fn bernstein(u: f32) -> Vec4 {
    let v = 1.0 - u;
    Vec4::new(v * v * v, 3.0 * u * v * v, 3.0 * u * u * v, u * u * u)
}

#[inline(always)]
pub fn bezier3(p: &[Vec3A; 4], u: f32) -> Vec3A {
    let b = bernstein(u);
    p[0] * b.x + p[1] * b.y + p[2] * b.z + p[3] * b.w
}

#[inline(always)]
pub fn bezier4(p: &[Vec4; 4], u: f32) -> Vec4 {
    let b = bernstein(u);
    p[0] * b.x + p[1] * b.y + p[2] * b.z + p[3] * b.w
}

/// `step` (docs/clip-format.md, “Other interpolation modes”): `c_i` on `[t_i,
/// t_{i+1})`; at and after the last key, `c_n`.
#[inline(always)]
pub fn step<T: Copy>(keys: &[T], s: Span) -> T {
    let i = s.index as usize;
    if s.u >= 1.0 { keys[i + 1] } else { keys[i] }
}

/// The three-level slerp de Casteljau (docs/clip-format.md, “Quaternion
/// Catmull-Rom”; equations 1–6 with `lerp` replaced by short-way `slerp`): six
/// slerps, whose weights come from the segment's stored series (level 1) and
/// two polynomial evaluations of four lanes each (levels 2 and 3). Always
/// inlined: it is the body of the rotation loop, whole-pose and part-pose
/// sampling alike.
#[inline(always)]
pub fn slerp_bezier(seg: &QuatSegment, u: f32) -> Quat {
    match seg.tier {
        SlerpTier::Tiny => pyramid(seg, u, slerp_weights_tiny),
        SlerpTier::Narrow => pyramid(seg, u, slerp_weights_narrow),
        SlerpTier::Wide => pyramid(seg, u, slerp_weights),
        SlerpTier::Exact => slerp_bezier_exact(seg, u),
    }
}

#[inline(always)]
fn pyramid(seg: &QuatSegment, u: f32, weights: impl Fn(Vec4, Vec4) -> Vec4) -> Quat {
    let [c, d, e, c1] = seg.points;
    let v = 1.0 - u;
    // Level 1: f = slerp(c, d), g = slerp(d, e), h = slerp(e, c1), weights
    // w(s) = s·Σ c_k·s^(2k) per pair (lanes x, y, z).
    let series = |s: f32| {
        let ss = Vec4::splat(s * s);
        let [c0, c1, c2, c3, c4] = seg.sine;
        (((c4 * ss + c3) * ss + c2) * ss + c1) * ss * s + c0 * s
    };
    let (wu, wv) = (series(u), series(v));
    let f = c * wv.x + d * wu.x;
    let g = d * wv.y + e * wu.y;
    let h = e * wv.z + c1 * wu.z;
    // Level 2: m = slerp(f, g), n = slerp(g, h), short way.
    let (g_m, x_fg) = aligned(f, g);
    let (h_n, x_gh) = aligned(g, h);
    let w2 = weights(Vec4::new(v, u, v, u), Vec4::new(x_fg, x_fg, x_gh, x_gh) - Vec4::ONE);
    let m = f * w2.x + g_m * w2.y;
    let n = g * w2.z + h_n * w2.w;
    // Level 3: the point on the curve.
    let (n_r, x_mn) = aligned(m, n);
    let w3 = weights(Vec4::new(v, u, 0.0, 0.0), Vec4::splat(x_mn - 1.0));
    let r = m * w3.x + n_r * w3.y;
    Quat::from_vec4(r * r.length_recip())
}

/// The same pyramid with exact slerps, for segments too wide for the
/// polynomial weights.
#[cold]
fn slerp_bezier_exact(seg: &QuatSegment, u: f32) -> Quat {
    exact_pyramid(seg.points, u)
}

/// The exact pyramid on control points `[c, d, e, c1]` (each consecutive
/// pair on one side).
pub(crate) fn exact_pyramid(points: [Vec4; 4], u: f32) -> Quat {
    let slerp = |p: Vec4, q: Vec4| {
        let (q, x) = aligned(p, q);
        let (wp, wq) = slerp_weights_exact(x, u);
        let r = p * wp + q * wq;
        r * r.length_recip()
    };
    let [c, d, e, c1] = points;
    let (f, g, h) = (slerp(c, d), slerp(d, e), slerp(e, c1));
    let (m, n) = (slerp(f, g), slerp(g, h));
    Quat::from_vec4(slerp(m, n))
}

/// `q` on `p`'s side, and the (clamped) cosine between them.
#[inline(always)]
fn aligned(p: Vec4, q: Vec4) -> (Vec4, f32) {
    let x = p.dot(q);
    if x < 0.0 { (-q, (-x).min(1.0)) } else { (q, x.min(1.0)) }
}

#[cfg(test)]
mod tests {
    use glam::{DQuat, DVec3};

    use super::*;
    use crate::Ends;
    use crate::compile::catmull_rom;

    /// Equal keys give themselves exactly at any `u`, and keys at ±`f32::MAX`
    /// a finite value (their difference overflows).
    #[test]
    fn linear_keys_keep_equal_values_exact_and_extreme_ones_finite() {
        let a = Vec3A::new(0.1, -3.7e-5, 1234.567);
        for u in [0.0, 0.1, 1.0 / 3.0, 0.5, 0.999_999, 1.0] {
            assert_eq!(lerp_keys(a, a, u), a, "u {u}");
            let wide = lerp_keys(Vec3A::splat(-f32::MAX), Vec3A::splat(f32::MAX), u);
            assert!(wide.is_finite(), "u {u}: {wide}");
        }
        assert_eq!(lerp_keys(Vec3A::ZERO, Vec3A::splat(2.0), 0.25), Vec3A::splat(0.5));
    }

    /// The polynomial pyramid agrees with exact slerps on segments of every
    /// tier (keys up to ~100° apart).
    #[test]
    fn fast_pyramid_matches_exact_slerps() {
        let mut seed = 0x1234_5678_u64;
        let mut rnd = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        let mut tiers = [0usize; 4];
        let mut worst = 0.0f32;
        for case in 0..300 {
            let spread = 0.02 + 1.8 * (case as f64 / 300.0); // radians of rotation between keys
            let mut q = DQuat::IDENTITY;
            let keys: Vec<DQuat> = (0..5)
                .map(|_| {
                    let axis = DVec3::new(rnd(), rnd(), rnd()).normalize_or(DVec3::X);
                    q = (DQuat::from_axis_angle(axis, spread * (0.5 + rnd().abs() / 2.0)) * q).normalize();
                    q
                })
                .collect();
            let times: Vec<f64> = (0..5).map(|i| i as f64 + 0.3 * rnd()).collect();
            for seg in catmull_rom(&keys, &times, Ends::Reflect, 0.5) {
                let built = crate::compile::quat_segment(&seg);
                tiers[built.tier as usize] += 1;
                for k in 0..=20 {
                    let u = k as f32 / 20.0;
                    let (a, b) = (slerp_bezier(&built, u), slerp_bezier_exact(&built, u));
                    let d = (Vec4::from(a) - Vec4::from(b)).length().min((Vec4::from(a) + Vec4::from(b)).length());
                    worst = worst.max(d);
                }
            }
        }
        assert!(tiers.iter().all(|&n| n > 0), "every tier exercised: {tiers:?}");
        assert!(worst < 2e-6, "worst difference from exact slerps: {worst}");
    }
}
