//! Compiled curves: the runtime form of one track, evaluated at a [`Span`].
//!
//! Every cubic mode is stored as per-segment Bezier control points
//! `[c_i, d_i, e_i, c_{i+1}]` (SPEC §2.1), computed once by `compile`:
//! Catmull-Rom (§2.2, §2.3), cubic Hermite (§2.5, `d = v_i + h·b_i/3`,
//! `e = v_{i+1} − h·a_{i+1}/3`, the same cubic) and constant-speed paths
//! (§2.6). Evaluation is then a fixed, branch-light sequence of arithmetic:
//! Bernstein weights for vectors, three levels of slerp de Casteljau for
//! rotations. Nothing here allocates or fails.

use glam::{Quat, Vec3A, Vec4};

use super::quat::{slerp_fast, slerp_weights, slerp_weights_exact};
use super::timeline::Span;

/// Bezier control points of one quaternion segment, signs chosen so that
/// each consecutive pair is its own short way, plus `cos θ − 1` of the three
/// first-level pairs (constant per segment, so computed once).
///
/// `exact` marks a segment whose control polygon turns through more than
/// `acos(FAST_SLERP_MIN_COS)`: every slerp of its de Casteljau pyramid spans
/// at most the polygon's total angle, so for all other segments the
/// polynomial weights are provably in range.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(16))]
pub struct QuatSegment {
    pub points: [Vec4; 4],
    pub xm1: Vec4,
    pub exact: bool,
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

/// A rotation curve.
#[derive(Debug, Clone, PartialEq)]
pub enum QuatCurve {
    Constant(Quat),
    Step(Box<[Quat]>),
    Slerp(Box<[Quat]>),
    /// Catmull-Rom by slerp de Casteljau (SPEC §2.3).
    SlerpBezier(Box<[QuatSegment]>),
    /// glTF CUBICSPLINE: a cubic on the 4-vectors, then normalised.
    Hermite(Box<[[Vec4; 4]]>),
}

#[inline(always)]
fn bernstein(u: f32) -> Vec4 {
    let v = 1.0 - u;
    Vec4::new(v * v * v, 3.0 * u * v * v, 3.0 * u * u * v, u * u * u)
}

#[inline(always)]
pub fn bezier3(p: &[Vec3A; 4], u: f32) -> Vec3A {
    let b = bernstein(u);
    p[0] * b.x + p[1] * b.y + p[2] * b.z + p[3] * b.w
}

#[inline(always)]
fn bezier4(p: &[Vec4; 4], u: f32) -> Vec4 {
    let b = bernstein(u);
    p[0] * b.x + p[1] * b.y + p[2] * b.z + p[3] * b.w
}

#[inline(always)]
fn step<T: Copy>(keys: &[T], s: Span) -> T {
    // SPEC §2.5: c_i on [t_i, t_{i+1}); at and after the last key, c_n.
    let i = s.index as usize;
    if s.u >= 1.0 { keys[i + 1] } else { keys[i] }
}

impl Vec3Curve {
    #[inline]
    pub fn eval(&self, s: Span) -> Vec3A {
        let i = s.index as usize;
        match self {
            Vec3Curve::Constant(v) => *v,
            Vec3Curve::Step(keys) => step(keys, s),
            Vec3Curve::Linear(keys) => keys[i].lerp(keys[i + 1], s.u),
            Vec3Curve::Bezier(segs) => bezier3(&segs[i], s.u),
            Vec3Curve::ConstantSpeed { segments, pieces } => {
                let piece = pieces[i];
                bezier3(&segments[piece.segment as usize], piece.u0 + s.u * piece.du)
            }
        }
    }
}

impl QuatCurve {
    #[inline]
    pub fn eval(&self, s: Span) -> Quat {
        let i = s.index as usize;
        match self {
            QuatCurve::Constant(q) => *q,
            QuatCurve::Step(keys) => step(keys, s),
            QuatCurve::Slerp(keys) => slerp_fast(keys[i], keys[i + 1], s.u),
            QuatCurve::SlerpBezier(segs) => slerp_bezier(&segs[i], s.u),
            QuatCurve::Hermite(segs) => {
                let r = bezier4(&segs[i], s.u);
                Quat::from_vec4(r * r.length_recip())
            }
        }
    }
}

/// The three-level slerp de Casteljau of SPEC §2.3 (equations 1–6 with
/// `lerp` replaced by short-way `slerp`), six slerps in four weight calls.
#[inline]
pub fn slerp_bezier(seg: &QuatSegment, u: f32) -> Quat {
    if seg.exact {
        return slerp_bezier_exact(seg, u);
    }
    let [c, d, e, c1] = seg.points;
    let v = 1.0 - u;
    // Level 1: f = slerp(c, d), g = slerp(d, e), h = slerp(e, c1); the pairs
    // are pre-aligned, so their weights come straight from the stored cosines.
    let wu = slerp_weights(Vec4::splat(u), seg.xm1);
    let wv = slerp_weights(Vec4::splat(v), seg.xm1);
    let f = c * wv.x + d * wu.x;
    let g = d * wv.y + e * wu.y;
    let h = e * wv.z + c1 * wu.z;
    // Level 2: m = slerp(f, g), n = slerp(g, h), short way.
    let (g_m, x_fg) = aligned(f, g);
    let (h_n, x_gh) = aligned(g, h);
    let w2 = slerp_weights(Vec4::new(v, u, v, u), Vec4::new(x_fg, x_fg, x_gh, x_gh) - Vec4::ONE);
    let m = f * w2.x + g_m * w2.y;
    let n = g * w2.z + h_n * w2.w;
    // Level 3: the point on the curve.
    let (n_r, x_mn) = aligned(m, n);
    let w3 = slerp_weights(Vec4::new(v, u, 0.0, 0.0), Vec4::splat(x_mn - 1.0));
    let r = m * w3.x + n_r * w3.y;
    Quat::from_vec4(r * r.length_recip())
}

/// The same pyramid with exact slerps, for segments too wide for the
/// polynomial weights.
#[cold]
fn slerp_bezier_exact(seg: &QuatSegment, u: f32) -> Quat {
    let slerp = |p: Vec4, q: Vec4| {
        let (q, x) = aligned(p, q);
        let (wp, wq) = slerp_weights_exact(x, u);
        let r = p * wp + q * wq;
        r * r.length_recip()
    };
    let [c, d, e, c1] = seg.points;
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
