//! Arc-length reparameterisation for `speed: "constant"` (docs/clip-format.md, “Speed control”).
//!
//! Built once per track, in `f64`: the path is cut into pieces inside which
//! the Bezier parameter is linear in arc length to within a tolerance of
//! `min(1e-6·L, 1e-6)` in position (checked at three points per piece, pieces split
//! adaptively, which also handles zero-speed cusps such as `zero_slope`
//! ends). The piece boundaries become the track's timeline, so sampling is
//! the ordinary span search plus one Bezier evaluation.
//!
//! The whole clip's tables share one [`Meter`]: every quadrature evaluation
//! and every piece is charged to it, and once it is over its limit the
//! tables stop refining at once, so the clip is refused (by `Clip::build`)
//! after at most the limit's worth of work, however its curves are split
//! into tracks.

use std::sync::atomic::{AtomicBool, Ordering};

use glam::DVec3;

use super::curve::ArcPiece;

/// Position tolerance: relative to the path length, capped absolutely so long
/// paths also stay inside the 1e-5 of docs/clip-format.md, “Accuracy” (at about
/// f32 resolution).
const REL_TOLERANCE: f64 = 1e-6;
const ABS_TOLERANCE: f64 = 1e-6;
/// A sixth of an `f32` ulp, relative: finer positions cannot be output.
const F32_RESOLUTION: f64 = 1e-8;
/// Bounds on refinement, so that no input can make a build slow: at depth
/// 16 a piece is 1/65536 of its segment, already within ~3e-6 of its length
/// even at a zero-speed cusp; past the budget, pieces stop splitting.
const MAX_DEPTH: u32 = 16;
const MAX_PIECES: usize = 1 << 20;

/// The build work of one clip: quadrature evaluations (one five-point
/// Gauss-Legendre rule each) plus arc-length pieces, counted against a limit,
/// and a flag the caller may raise to abandon the build.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Meter<'a> {
    spent: u64,
    limit: u64,
    cancel: &'a AtomicBool,
}

impl<'a> Meter<'a> {
    pub fn new(limit: u64, cancel: &'a AtomicBool) -> Self {
        Meter { spent: 0, limit, cancel }
    }

    fn charge(&mut self, units: u64) {
        self.spent = self.spent.saturating_add(units);
    }

    /// Past the limit, or cancelled: everything still to do is skipped.
    pub fn over(&self) -> bool {
        self.spent > self.limit || self.cancelled()
    }

    pub fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }

    pub fn spent(&self) -> u64 {
        self.spent
    }

    pub fn limit(&self) -> u64 {
        self.limit
    }
}

pub(crate) fn point(p: &[DVec3; 4], u: f64) -> DVec3 {
    let v = 1.0 - u;
    p[0] * (v * v * v) + p[1] * (3.0 * u * v * v) + p[2] * (3.0 * u * u * v) + p[3] * (u * u * u)
}

fn velocity(p: &[DVec3; 4], u: f64) -> DVec3 {
    let v = 1.0 - u;
    (p[1] - p[0]) * (3.0 * v * v) + (p[2] - p[1]) * (6.0 * u * v) + (p[3] - p[2]) * (3.0 * u * u)
}

/// Five-point Gauss-Legendre quadrature of the speed over `[a, b]`.
fn gauss5(p: &[DVec3; 4], a: f64, b: f64) -> f64 {
    const X: [f64; 5] =
        [0.0, -0.538_469_310_105_683_1, 0.538_469_310_105_683_1, -0.906_179_845_938_664, 0.906_179_845_938_664];
    const W: [f64; 5] = [
        0.568_888_888_888_888_9,
        0.478_628_670_499_366_5,
        0.478_628_670_499_366_5,
        0.236_926_885_056_189_1,
        0.236_926_885_056_189_1,
    ];
    let (mid, half) = ((a + b) / 2.0, (b - a) / 2.0);
    half * X.iter().zip(W).map(|(x, w)| w * velocity(p, mid + half * x).length()).sum::<f64>()
}

/// Quadrature evaluations one [`length`] may spend: far more than any
/// curve representable in `f32` needs at the tolerances asked for here, and
/// a bound on the work a hostile curve can cause.
const LENGTH_BUDGET: u32 = 1 << 12;

/// Arc length of `p` over `[a, b]`, adaptively to `abs_tol`, or to the
/// length's own rounding noise (a few ulps) when that is coarser: asking a
/// 1e22-long path for 1e-12 cannot converge, it only recurses (the fuzzer
/// found such a clip: 2⁴⁰ evaluations).
/// Each evaluation is charged to `meter`; once it is over, no more are made.
pub(crate) fn length(p: &[DVec3; 4], a: f64, b: f64, abs_tol: f64, meter: &mut Meter<'_>) -> f64 {
    fn go(
        p: &[DVec3; 4],
        (a, b): (f64, f64),
        whole: f64,
        (tol, floor): (f64, f64),
        depth: u32,
        (budget, meter): (&mut u32, &mut Meter<'_>),
    ) -> f64 {
        if meter.over() {
            return whole;
        }
        let m = (a + b) / 2.0;
        let (l, r) = (gauss5(p, a, m), gauss5(p, m, b));
        *budget = budget.saturating_sub(2);
        meter.charge(2);
        if depth >= 40 || *budget == 0 || (l + r - whole).abs() <= tol.max(floor) {
            l + r
        } else {
            go(p, (a, m), l, (tol / 2.0, floor), depth + 1, (&mut *budget, &mut *meter))
                + go(p, (m, b), r, (tol / 2.0, floor), depth + 1, (budget, meter))
        }
    }
    if meter.over() {
        return 0.0;
    }
    let whole = gauss5(p, a, b);
    meter.charge(1);
    let floor = (whole.abs() * 64.0 * f64::EPSILON).max(1e-300);
    let mut budget = LENGTH_BUDGET;
    go(p, (a, b), whole, (abs_tol, floor), 0, (&mut budget, meter))
}

/// The parameter in `[a, b]` whose arc length from `a` is `target`.
fn invert(p: &[DVec3; 4], (a, b): (f64, f64), target: f64, abs_tol: f64, meter: &mut Meter<'_>) -> f64 {
    let (mut lo, mut hi) = (a, b);
    let mut u = a + (b - a) * 0.5;
    for _ in 0..60 {
        if meter.over() {
            break;
        }
        let s = length(p, a, u, abs_tol, meter);
        let err = s - target;
        // Not finer than the lengths' own rounding (a few ulps).
        if err.abs() <= (abs_tol * 0.01).max(s.abs().max(target.abs()) * 64.0 * f64::EPSILON) {
            break;
        }
        if err > 0.0 {
            hi = u
        } else {
            lo = u
        }
        let speed = velocity(p, u).length();
        let newton = if speed > 0.0 { u - err / speed } else { f64::NAN };
        u = if newton > lo && newton < hi { newton } else { (lo + hi) / 2.0 };
        if hi - lo < 1e-15 {
            break;
        }
    }
    u
}

/// The arc-length breakpoints of a path of Bezier segments spanning
/// `[t0, t1]`: piece start times (plus the end time) and the pieces.
/// Returns `None` for a path of zero length (nothing moves). The work is
/// charged to `meter`; when it goes over, the result is meaningless and the
/// caller refuses the clip.
pub(crate) fn build(
    segments: &[[DVec3; 4]],
    t0: f64,
    t1: f64,
    meter: &mut Meter<'_>,
) -> Option<(Vec<f32>, Vec<ArcPiece>)> {
    let lengths: Vec<f64> = segments.iter().map(|p| length(p, 0.0, 1.0, 1e-12, meter)).collect();
    let total: f64 = lengths.iter().sum();
    // A path shorter than the rounding noise of its coordinates does not move.
    let scale = segments.iter().flatten().map(|p| p.abs().max_element()).fold(1.0, f64::max);
    if !total.is_finite() || total <= 1e-9 * scale {
        return None;
    }
    // Not finer than the output can resolve: poses are f32, whose ulp is
    // 6e-8 of a coordinate (this changes nothing for coordinates ≤ 100).
    let tol = (REL_TOLERANCE * total).min(ABS_TOLERANCE).max(scale * F32_RESOLUTION);
    let quad_tol = tol * 1e-3;
    // (start arc length, piece)
    let mut raw: Vec<(f64, ArcPiece)> = Vec::new();
    let mut s0 = 0.0;
    for (k, (p, &len)) in segments.iter().zip(&lengths).enumerate() {
        if len > 0.0 {
            split(p, k as u32, (0.0, 1.0), (s0, s0 + len), (tol, quad_tol), 0, (&mut raw, &mut *meter));
        }
        s0 += len;
    }
    let scale = (t1 - t0) / total;
    let mut times: Vec<f32> = Vec::with_capacity(raw.len() + 1);
    let mut pieces = Vec::with_capacity(raw.len());
    for (s, piece) in raw {
        let t = (t0 + s * scale) as f32;
        // Pieces shorter than f32 time resolution (or so short that the
        // timeline's reciprocal gap overflows) merge into their neighbour.
        if times.last().is_some_and(|&last| too_close(last, t)) {
            continue;
        }
        times.push(t);
        pieces.push(piece);
    }
    let end = t1 as f32;
    if times.last().is_some_and(|&last| too_close(last, end)) {
        times.pop();
        pieces.pop();
    }
    if pieces.is_empty() {
        return None;
    }
    times.push(end);
    Some((times, pieces))
}

/// Whether `t` cannot follow `last` on a timeline: not after it, or after
/// it by a gap whose reciprocal is not a finite f32 (subnormal spacing).
fn too_close(last: f32, t: f32) -> bool {
    t <= last || !(1.0 / (t - last)).is_finite()
}

fn split(
    p: &[DVec3; 4],
    segment: u32,
    (ua, ub): (f64, f64),
    (sa, sb): (f64, f64),
    (tol, quad_tol): (f64, f64),
    depth: u32,
    (out, meter): (&mut Vec<(f64, ArcPiece)>, &mut Meter<'_>),
) {
    if meter.over() {
        return;
    }
    let mut worst = 0.0f64;
    let mut u_mid = (ua + ub) / 2.0;
    for w in [0.25, 0.5, 0.75] {
        let target = w * (sb - sa);
        let u_true = invert(p, (ua, ub), target, quad_tol, meter);
        let u_lin = ua + w * (ub - ua);
        worst = worst.max((point(p, u_true) - point(p, u_lin)).length());
        if w == 0.5 {
            u_mid = u_true;
        }
    }
    if worst <= tol || depth >= MAX_DEPTH || out.len() >= MAX_PIECES || meter.over() {
        meter.charge(1);
        out.push((sa, ArcPiece { segment, u0: ua as f32, du: (ub - ua) as f32 }));
    } else {
        let sm = (sa + sb) / 2.0;
        split(p, segment, (ua, u_mid), (sa, sm), (tol, quad_tol), depth + 1, (&mut *out, &mut *meter));
        split(p, segment, (u_mid, ub), (sm, sb), (tol, quad_tol), depth + 1, (out, meter));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_are_exact_on_ordinary_curves() {
        // A straight segment with evenly spaced control points: length 5.
        let line =
            [DVec3::ZERO, DVec3::new(1.0, 4.0 / 3.0, 0.0), DVec3::new(2.0, 8.0 / 3.0, 0.0), DVec3::new(3.0, 4.0, 0.0)];
        let never = AtomicBool::new(false);
        let meter = &mut Meter::new(u64::MAX, &never);
        assert!((length(&line, 0.0, 1.0, 1e-12, meter) - 5.0).abs() < 1e-12);
        // A quarter-circle-like arc of radius 1 (the classic 0.5523 handles): π/2 within 3e-4.
        let k = 0.552_284_749_8;
        let arc = [DVec3::X, DVec3::new(1.0, k, 0.0), DVec3::new(k, 1.0, 0.0), DVec3::Y];
        assert!((length(&arc, 0.0, 1.0, 1e-12, meter) - std::f64::consts::FRAC_PI_2).abs() < 3e-4);
    }

    #[test]
    fn a_path_near_the_float_range_builds_a_bounded_table() {
        // From a fuzzer timeout (fuzz/regressions/clip_json): one control point
        // at 2.2e22. An absolute tolerance of 1e-12 on such a length is below
        // its ulp, and the quadrature recursed 2^40 times.
        let far = [DVec3::X, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::new(0.0, 2.222_220_017_222_415e22, 2.0)];
        let (times, pieces) =
            build(&[far], 0.0, 3.0, &mut Meter::new(u64::MAX, &AtomicBool::new(false))).expect("the path moves");
        assert_eq!(times.len(), pieces.len() + 1);
        assert!(pieces.len() <= MAX_PIECES);
        assert!(times.windows(2).all(|w| w[0] < w[1]), "piece times increase");
        assert_eq!((times[0], *times.last().unwrap()), (0.0, 3.0));
    }
}
