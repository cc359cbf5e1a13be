//! Quaternion tools (docs/clip-format.md, “Quaternion Catmull-Rom”): the
//! short-way choice, powers, slerp and hemisphere continuity.
//!
//! Two precisions live here on purpose. `Clip::build` computes control
//! points once, in `f64` ([`DQuat`]), so the stored curve is as exact as
//! `f32` can hold it. The sampler runs [`slerp_weights`], Eberly's polynomial
//! form of slerp ("A Fast and Accurate Algorithm for Computing SLERP", 2011),
//! which needs no `acos`, `sin` or division and evaluates four slerp weights
//! in one SIMD register. On the pairs it is used for (see
//! [`FAST_SLERP_MIN_COS`]) its error is below 2e-8, far inside the 1e-5
//! bound of docs/clip-format.md, “Accuracy”; wider pairs take the exact formula.

use glam::{DQuat, Quat, Vec4};

/// `q` if `q.w >= 0`, else `-q`: the conditional negation that makes a power
/// go the short way (docs/clip-format.md, “Quaternion Catmull-Rom”).
#[inline]
pub fn short(q: DQuat) -> DQuat {
    if q.w >= 0.0 { q } else { -q }
}

/// `pow(q, a)` for a unit quaternion: `(cos aθ, sin aθ·v)` where
/// `q = (cos θ, sin θ·v)`, `θ ∈ [0, π]`; the identity stays the identity.
pub fn pow(q: DQuat, a: f64) -> DQuat {
    let v = q.xyz();
    let sin_theta = v.length();
    if sin_theta < 1e-15 {
        return DQuat::IDENTITY;
    }
    let theta = sin_theta.atan2(q.w);
    let (s, c) = (a * theta).sin_cos();
    let axis = v / sin_theta;
    DQuat::from_xyzw(axis.x * s, axis.y * s, axis.z * s, c)
}

/// Exact short-way slerp `p·(p⁻¹·q)^u`, normalised, in `f64`.
pub fn slerp_f64(p: DQuat, q: DQuat, u: f64) -> DQuat {
    let q = if p.dot(q) < 0.0 { -q } else { q };
    (p * pow(p.conjugate() * q, u)).normalize()
}

/// Makes a key sequence hemisphere-continuous: `c[i+1] := -c[i+1]` when
/// `dot(c[i], c[i+1]) < 0`, so each consecutive pair is its own short way.
pub fn make_continuous(keys: &mut [DQuat]) {
    for i in 1..keys.len() {
        if keys[i - 1].dot(keys[i]) < 0.0 {
            keys[i] = -keys[i];
        }
    }
}

/// Flips `q` to `p`'s hemisphere (so `dot(p, q) >= 0`).
#[inline]
pub fn align(p: DQuat, q: DQuat) -> DQuat {
    if p.dot(q) < 0.0 { -q } else { q }
}

// Eberly's series, truncated. His paper balances an error factor `1 + μ` on
// the last term over the whole short-way range cos θ ∈ [0, 1], where even 8
// terms only reach 2.6e-5. We use it on narrower ranges, fitted there:
// 3 terms on cos θ ∈ [0.98, 1] (1.4e-9 worst error against the exact sine
// ratio), 4 terms with μ = 0.04 on [0.9, 1] (6e-9) and 6 terms with
// μ = 0.154 on [0.7, 1] (1.1e-8), and the exact formula outside.
const fn eberly<const N: usize>(one_plus_mu: f32) -> ([f32; N], [f32; N]) {
    let (mut u, mut v) = ([0.0; N], [0.0; N]);
    let mut i = 0;
    while i < N {
        let k = (i + 1) as f32;
        let scale = if i + 1 == N { one_plus_mu } else { 1.0 };
        u[i] = scale / (k * (2.0 * k + 1.0));
        v[i] = scale * k / (2.0 * k + 1.0);
        i += 1;
    }
    (u, v)
}

pub(crate) const TINY: ([f32; 3], [f32; 3]) = eberly(1.0);
pub(crate) const NARROW: ([f32; 4], [f32; 4]) = eberly(1.04);
pub(crate) const WIDE: ([f32; 6], [f32; 6]) = eberly(1.154);

/// The smallest `cos θ` (11.5°, a 23° rotation) for [`slerp_weights_tiny`]:
/// dense keys (mocap, baked exports) are nearly all in this range.
pub const TINY_SLERP_MIN_COS: f32 = 0.98;
/// The smallest `cos θ` (θ the angle between two quaternions: 25.8°, a
/// 52° rotation) for [`slerp_weights_narrow`].
pub const NARROW_SLERP_MIN_COS: f32 = 0.9;
/// The smallest `cos θ` (45.6°, a 91° rotation) for [`slerp_weights`].
pub const FAST_SLERP_MIN_COS: f32 = 0.7;

#[inline(always)]
fn eberly_weights<const N: usize>(s: Vec4, xm1: Vec4, (cu, cv): &([f32; N], [f32; N])) -> Vec4 {
    let ss = s * s;
    let mut acc = Vec4::ONE;
    // Horner from the innermost term outwards: acc = 1 + (U_i·s² − V_i)·(x − 1)·acc.
    // Plain multiply-add: `Vec4::mul_add` without the `fma` target feature
    // falls back to a software fmaf per lane (10x slower).
    let mut i = N;
    while i > 0 {
        i -= 1;
        acc = (ss * cu[i] - Vec4::splat(cv[i])) * xm1 * acc + Vec4::ONE;
    }
    s * acc
}

/// Four slerp weights at once: lane `k` is `sin(s_k·θ_k)/sin θ_k` where
/// `s` holds the parameters and `xm1` holds `cos θ_k − 1`.
///
/// For a slerp from `p` to `q` at `u`, the weight of `q` is this at
/// `s = u` and the weight of `p` at `s = 1 − u`; callers pack both (or
/// several slerps' worth) into the lanes. Accurate to 2e-8 for
/// `cos θ_k ∈ [FAST_SLERP_MIN_COS, 1]`; callers guarantee that range.
#[inline(always)]
pub fn slerp_weights(s: Vec4, xm1: Vec4) -> Vec4 {
    eberly_weights(s, xm1, &WIDE)
}

/// [`slerp_weights`] with fewer terms, for `cos θ_k ∈ [NARROW_SLERP_MIN_COS, 1]`.
#[inline(always)]
pub fn slerp_weights_narrow(s: Vec4, xm1: Vec4) -> Vec4 {
    eberly_weights(s, xm1, &NARROW)
}

/// [`slerp_weights`] with fewer terms, for `cos θ_k ∈ [TINY_SLERP_MIN_COS, 1]`.
#[inline(always)]
pub fn slerp_weights_tiny(s: Vec4, xm1: Vec4) -> Vec4 {
    eberly_weights(s, xm1, &TINY)
}

/// Taylor coefficients `c_k` of `sin(uθ)/sin θ = Σ c_k·u^(2k+1)` for a
/// fixed θ (so the weights of a segment's fixed pairs are a polynomial in
/// `u`). Five terms leave under 3e-9 for θ ≤ 45.6°.
pub fn sine_ratio_series(theta: f64) -> [f64; 5] {
    if theta < 1e-9 {
        return [1.0, 0.0, 0.0, 0.0, 0.0];
    }
    let sin = theta.sin();
    let mut c = [0.0; 5];
    let mut term = theta / sin; // θ^(2k+1) / (2k+1)! / sin θ, with sign
    for (k, ck) in c.iter_mut().enumerate() {
        *ck = term;
        let (a, b) = ((2 * k + 2) as f64, (2 * k + 3) as f64);
        term *= -theta * theta / (a * b);
    }
    c
}

/// The widest angle θ between two keys whose slerp weights are taken from
/// four terms of [`sine_ratio_series`] (a 57° rotation): the first term
/// left out is below 1.2e-8 there.
pub const SERIES_MAX_ANGLE: f64 = 0.5;

/// The slerp weights `(w_p, w_q)` at `u` of a pair whose four series
/// coefficients are `c` (lane k: coefficient k): `w(s) = s·Σ c_k·s^(2k)`
/// at `s = 1 − u` and `s = u`, two lanes of one Horner chain.
#[inline(always)]
pub fn series_weights(c: Vec4, u: f32) -> (f32, f32) {
    let s = Vec4::new(1.0 - u, u, 0.0, 0.0);
    let ss = s * s;
    let acc = ((Vec4::splat(c.w) * ss + Vec4::splat(c.z)) * ss + Vec4::splat(c.y)) * ss + Vec4::splat(c.x);
    let w = acc * s;
    (w.x, w.y)
}

/// Short-way slerp of two unit quaternions, normalised: polynomial weights
/// when the pair is close enough, the exact ones otherwise.
#[inline]
pub fn slerp_fast(p: Quat, q: Quat, u: f32) -> Quat {
    let (p4, q4) = (Vec4::from(p), Vec4::from(q));
    let x = p4.dot(q4);
    let (q4, x) = if x < 0.0 { (-q4, -x) } else { (q4, x) };
    let s = Vec4::new(1.0 - u, u, 0.0, 0.0);
    let xm1 = Vec4::splat(x.min(1.0) - 1.0);
    let (wp, wq) = if x >= TINY_SLERP_MIN_COS {
        let w = slerp_weights_tiny(s, xm1);
        (w.x, w.y)
    } else if x >= NARROW_SLERP_MIN_COS {
        let w = slerp_weights_narrow(s, xm1);
        (w.x, w.y)
    } else if x >= FAST_SLERP_MIN_COS {
        let w = slerp_weights(s, xm1);
        (w.x, w.y)
    } else {
        slerp_weights_exact(x, u)
    };
    let r = p4 * wp + q4 * wq;
    Quat::from_vec4(r * r.length_recip())
}

/// Exact short-way slerp weights `(w_p, w_q)` for `cos θ = x ∈ [0, 1]`.
#[inline]
pub fn slerp_weights_exact(x: f32, u: f32) -> (f32, f32) {
    let theta = x.min(1.0).acos();
    let sin = theta.sin();
    if sin < 1e-6 {
        return (1.0 - u, u);
    }
    (((1.0 - u) * theta).sin() / sin, (u * theta).sin() / sin)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eberly_weights_match_sine_ratio() {
        // Exhaustive grid over the short-way domain.
        let mut worst = 0.0f64;
        let lo = FAST_SLERP_MIN_COS as f64;
        for xi in 0..=200 {
            let x = lo + (1.0 - lo) * xi as f64 / 200.0;
            let theta = x.acos();
            for si in 0..=100 {
                let s = si as f64 / 100.0;
                let exact = if theta < 1e-12 { s } else { (s * theta).sin() / theta.sin() };
                let w = slerp_weights(Vec4::splat(s as f32), Vec4::splat((x - 1.0) as f32));
                worst = worst.max((w.x as f64 - exact).abs());
            }
        }
        assert!(worst < 2e-7, "worst slerp-weight error {worst}");
    }

    #[test]
    fn narrow_weights_and_series_match_sine_ratio() {
        let mut worst = (0.0f64, 0.0f64);
        for xi in 0..=200 {
            let x = FAST_SLERP_MIN_COS as f64 + (1.0 - FAST_SLERP_MIN_COS as f64) * xi as f64 / 200.0;
            let theta = x.acos();
            let c = sine_ratio_series(theta);
            for si in 0..=100 {
                let s = si as f64 / 100.0;
                let exact = if theta < 1e-12 { s } else { (s * theta).sin() / theta.sin() };
                let series: f64 = c.iter().enumerate().map(|(k, ck)| ck * s.powi(2 * k as i32 + 1)).sum();
                worst.1 = worst.1.max((series - exact).abs());
                let (sv, xv) = (Vec4::splat(s as f32), Vec4::splat((x - 1.0) as f32));
                if x >= NARROW_SLERP_MIN_COS as f64 {
                    worst.0 = worst.0.max((slerp_weights_narrow(sv, xv).x as f64 - exact).abs());
                }
                if x >= TINY_SLERP_MIN_COS as f64 {
                    worst.0 = worst.0.max((slerp_weights_tiny(sv, xv).x as f64 - exact).abs());
                }
            }
        }
        assert!(worst.0 < 2e-7 && worst.1 < 1e-8, "worst errors (narrow, series): {worst:?}");
    }

    /// Four terms up to `SERIES_MAX_ANGLE`, evaluated in f32 as the linear
    /// rotation curves do: within 2e-7 of the exact weights (the truncation
    /// is 1.2e-8, the rest is f32 rounding: an ulp of 1 is 1.2e-7).
    #[test]
    fn four_term_series_weights_match_sine_ratio() {
        let mut worst = 0.0f64;
        for ti in 0..=200 {
            let theta = SERIES_MAX_ANGLE * ti as f64 / 200.0;
            let c = sine_ratio_series(theta);
            let c4 = Vec4::new(c[0] as f32, c[1] as f32, c[2] as f32, c[3] as f32);
            for ui in 0..=100 {
                let u = ui as f64 / 100.0;
                let exact = |s: f64| if theta < 1e-12 { s } else { (s * theta).sin() / theta.sin() };
                let (wp, wq) = series_weights(c4, u as f32);
                worst = worst.max((wp as f64 - exact(1.0 - u)).abs()).max((wq as f64 - exact(u)).abs());
            }
        }
        assert!(worst < 2e-7, "worst series weight error {worst}");
    }
}
