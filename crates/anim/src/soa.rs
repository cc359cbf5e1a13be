//! Tracks that share key times, evaluated four at a time (ozz-animation's
//! layout): one SSE lane per track, so the slerp de Casteljau pyramid of four
//! rotation tracks is one stream of 4-wide arithmetic instead of four
//! dependency chains, and the span, the Bernstein weights and the powers of
//! `u` are computed once per group rather than per track.
//!
//! A group holds 2–4 tracks of one kind on one timeline; missing lanes
//! repeat lane 0 and are never written. Rotation tracks with their own key
//! times are gathered four at a time too ([`QuatSegment4::gather`]): each
//! lane's segment is found by its own search and the four are transposed
//! into the same form, with a `u` per lane. A lone track stays on the
//! scalar kernel of `tracks`. The arithmetic is the scalar kernel's (`curve`), lane by
//! lane: the same control points, the same level-1 series, Eberly's weights
//! with the widest tier any lane of the segment needs (a longer series is
//! accurate on a narrower turn too), and the exact slerps, per lane, where a
//! lane's control polygon turns too far for any of them (`exact` mask).

use glam::{Mat4, Quat, Vec3A, Vec4};

use super::curve::{QuatSegment, SlerpTier, bernstein, exact_pyramid};
use super::quat::{NARROW, TINY, WIDE};
use super::timeline::Span;

/// Up to four joints written by one group, and how many lanes are real.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Lanes {
    pub joints: [u32; 4],
    pub count: u8,
}

impl Lanes {
    pub fn new(joints: &[u32]) -> Self {
        debug_assert!((1..=4).contains(&joints.len()));
        Lanes { joints: std::array::from_fn(|k| joints[k.min(joints.len() - 1)]), count: joints.len() as u8 }
    }

    /// The real lanes as `(lane, joint)`.
    #[inline(always)]
    pub fn iter(&self) -> impl Iterator<Item = (usize, u32)> + '_ {
        self.joints[..self.count as usize].iter().copied().enumerate()
    }
}

/// One segment of four rotation tracks, lane `k` = track `k`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(16))]
pub(crate) struct QuatSegment4 {
    /// `points[p][c]`: component `c` (x, y, z, w) of control point `p`.
    points: [[Vec4; 4]; 4],
    /// `sine[i][k]`: coefficient `i` of the level-1 series of pair `k`.
    sine: [[Vec4; 3]; 5],
    /// The widest polynomial tier of the non-exact lanes.
    tier: SlerpTier,
    /// Lanes (bit `k`) whose pyramid needs exact slerps.
    exact: u8,
}

impl QuatSegment4 {
    fn new(lanes: &[&QuatSegment]) -> Self {
        let lane = |k: usize| lanes[k.min(lanes.len() - 1)];
        let points = std::array::from_fn(|p| {
            std::array::from_fn(|c| Vec4::from_array(std::array::from_fn(|k| lane(k).points[p][c])))
        });
        let sine = std::array::from_fn(|i| {
            std::array::from_fn(|pair| Vec4::from_array(std::array::from_fn(|k| lane(k).sine[i][pair])))
        });
        let exact =
            lanes.iter().enumerate().filter(|(_, s)| s.tier == SlerpTier::Exact).fold(0, |m, (k, _)| m | 1 << k);
        let tier = lanes.iter().map(|s| s.tier).filter(|&t| t != SlerpTier::Exact).max().unwrap_or(SlerpTier::Tiny);
        QuatSegment4 { points, sine, tier, exact }
    }

    /// Lane `k`'s control points.
    fn lane_points(&self, k: usize) -> [Vec4; 4] {
        self.points.map(|p| Vec4::new(p[0][k], p[1][k], p[2][k], p[3][k]))
    }
}

/// Two to four Catmull-Rom (or B-spline) rotation tracks on one timeline.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct QuatGroup {
    pub lanes: Lanes,
    pub timeline: u32,
    segments: Box<[QuatSegment4]>,
}

impl QuatGroup {
    /// `tracks[k]` = (joint, segments) of lane `k`; all on `timeline`, so
    /// with as many segments each.
    pub fn new(timeline: u32, tracks: &[(u32, &[QuatSegment])]) -> Self {
        let joints: Vec<u32> = tracks.iter().map(|t| t.0).collect();
        let n = tracks[0].1.len();
        debug_assert!(tracks.iter().all(|t| t.1.len() == n));
        let segments = (0..n).map(|i| QuatSegment4::new(&tracks.iter().map(|t| &t.1[i]).collect::<Vec<_>>())).collect();
        QuatGroup { lanes: Lanes::new(&joints), timeline, segments }
    }

    pub fn heap_bytes(&self) -> usize {
        std::mem::size_of_val(&*self.segments)
    }

    /// The four lanes' rotations at `s`.
    #[inline(always)]
    pub fn at(&self, s: Span) -> [Quat; 4] {
        self.segments[s.index as usize].at(Vec4::splat(s.u))
    }
}

impl QuatSegment4 {
    /// Four rotation tracks' current segments, whatever their timelines,
    /// side by side: the stored per-track records transposed (tracks with
    /// their own key times, gathered at sampling time).
    #[inline(always)]
    pub fn gather(segs: [&QuatSegment; 4]) -> Self {
        let points = std::array::from_fn(|p| {
            let m = Mat4::from_cols(segs[0].points[p], segs[1].points[p], segs[2].points[p], segs[3].points[p]);
            let t = m.transpose();
            [t.x_axis, t.y_axis, t.z_axis, t.w_axis]
        });
        let sine = std::array::from_fn(|i| {
            let m = Mat4::from_cols(segs[0].sine[i], segs[1].sine[i], segs[2].sine[i], segs[3].sine[i]);
            let t = m.transpose();
            [t.x_axis, t.y_axis, t.z_axis]
        });
        let (mut tier, mut exact) = (SlerpTier::Tiny, 0);
        for (k, seg) in segs.iter().enumerate() {
            if seg.tier == SlerpTier::Exact {
                exact |= 1 << k;
            } else {
                tier = tier.max(seg.tier);
            }
        }
        QuatSegment4 { points, sine, tier, exact }
    }

    /// The four lanes' rotations, lane `k` at `u[k]`.
    #[inline(always)]
    pub fn at(&self, u: Vec4) -> [Quat; 4] {
        let mut out = match self.tier {
            SlerpTier::Tiny => pyramid4(self, u, &TINY),
            SlerpTier::Narrow => pyramid4(self, u, &NARROW),
            SlerpTier::Wide | SlerpTier::Exact => pyramid4(self, u, &WIDE),
        };
        if self.exact != 0 {
            exact_lanes(self, u, &mut out);
        }
        out
    }
}

#[cold]
fn exact_lanes(seg: &QuatSegment4, u: Vec4, out: &mut [Quat; 4]) {
    for (k, q) in out.iter_mut().enumerate() {
        if seg.exact & (1 << k) != 0 {
            *q = exact_pyramid(seg.lane_points(k), u[k]);
        }
    }
}

/// Four quaternions by component.
type Quat4 = [Vec4; 4];

#[inline(always)]
fn blend(p: &Quat4, q: &Quat4, wp: Vec4, wq: Vec4) -> Quat4 {
    [p[0] * wp + q[0] * wq, p[1] * wp + q[1] * wq, p[2] * wp + q[2] * wq, p[3] * wp + q[3] * wq]
}

#[inline(always)]
fn dot(p: &Quat4, q: &Quat4) -> Vec4 {
    p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3]
}

/// Per lane, `q` on `p`'s side and the clamped cosine between them, minus 1.
#[inline(always)]
fn aligned(p: &Quat4, q: &Quat4) -> (Quat4, Vec4) {
    let x = dot(p, q);
    let sign = Vec4::select(x.cmplt(Vec4::ZERO), Vec4::NEG_ONE, Vec4::ONE);
    ([q[0] * sign, q[1] * sign, q[2] * sign, q[3] * sign], (x * sign).min(Vec4::ONE) - Vec4::ONE)
}

/// Eberly's `N`-term slerp weight `sin(sθ)/sin θ` per lane.
#[inline(always)]
fn weight<const N: usize>(s: Vec4, xm1: Vec4, (cu, cv): &([f32; N], [f32; N])) -> Vec4 {
    let ss = s * s;
    let mut acc = Vec4::ONE;
    let mut i = N;
    while i > 0 {
        i -= 1;
        acc = xm1 * acc * (ss * cu[i] - Vec4::splat(cv[i])) + Vec4::ONE;
    }
    acc * s
}

/// The three-level pyramid of `curve::slerp_bezier`, four lanes at once.
#[inline(always)]
fn pyramid4<const N: usize>(seg: &QuatSegment4, u: Vec4, terms: &([f32; N], [f32; N])) -> [Quat; 4] {
    let v = Vec4::ONE - u;
    let (uu, vv) = (u * u, v * v);
    let c = &seg.sine;
    let series =
        |k: usize, s: Vec4, ss: Vec4| ((((c[4][k] * ss + c[3][k]) * ss + c[2][k]) * ss + c[1][k]) * ss + c[0][k]) * s;
    let [p0, p1, p2, p3] = &seg.points;
    // Level 1: pairs with fixed angles, weights from the stored series.
    let f = blend(p0, p1, series(0, v, vv), series(0, u, uu));
    let g = blend(p1, p2, series(1, v, vv), series(1, u, uu));
    let h = blend(p2, p3, series(2, v, vv), series(2, u, uu));
    // Level 2.
    let (g_m, fg) = aligned(&f, &g);
    let (h_n, gh) = aligned(&g, &h);
    let m = blend(&f, &g_m, weight(v, fg, terms), weight(u, fg, terms));
    let n = blend(&g, &h_n, weight(v, gh, terms), weight(u, gh, terms));
    // Level 3, then normalise.
    let (n_r, mn) = aligned(&m, &n);
    let r = blend(&m, &n_r, weight(v, mn, terms), weight(u, mn, terms));
    let inv = Vec4::ONE / dot(&r, &r).sqrt();
    let t = Mat4::from_cols(r[0] * inv, r[1] * inv, r[2] * inv, r[3] * inv).transpose();
    [t.x_axis, t.y_axis, t.z_axis, t.w_axis].map(Quat::from_vec4)
}

/// Two to four Bezier vector tracks on one timeline, each segment's four
/// lanes side by side (one record per segment index).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Vec3Group {
    pub lanes: Lanes,
    pub timeline: u32,
    /// `segments[i][k]`: segment `i` of lane `k`.
    segments: Box<[[[Vec3A; 4]; 4]]>,
}

impl Vec3Group {
    pub fn new(timeline: u32, tracks: &[(u32, &[[Vec3A; 4]])]) -> Self {
        let joints: Vec<u32> = tracks.iter().map(|t| t.0).collect();
        let n = tracks[0].1.len();
        debug_assert!(tracks.iter().all(|t| t.1.len() == n));
        let segments = (0..n).map(|i| std::array::from_fn(|k| tracks[k.min(tracks.len() - 1)].1[i])).collect();
        Vec3Group { lanes: Lanes::new(&joints), timeline, segments }
    }

    pub fn heap_bytes(&self) -> usize {
        std::mem::size_of_val(&*self.segments)
    }

    /// The four lanes' values at `s`: the Bernstein weights once for all.
    #[inline(always)]
    pub fn at(&self, s: Span) -> [Vec3A; 4] {
        let seg = &self.segments[s.index as usize];
        let b = bernstein(s.u);
        seg.map(|p| p[0] * b.x + p[1] * b.y + p[2] * b.z + p[3] * b.w)
    }
}
