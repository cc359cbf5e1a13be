//! How a float is written in JSON: as serde_json writes a finite one,
//! shared by every document that writes its own numbers.

use bytes::BufMut;

/// A float as serde_json writes a finite one. Never `null`: the build
/// invariants make every sampled value finite (`anim::Clip::build` refuses
/// what would overflow), and should one slip through it is written as the
/// nearest finite number (NaN as 0), so a client's number is always a number.
pub fn write_float<F: zmij::Float + Into<f64> + Copy>(out: &mut impl BufMut, x: F) {
    if x.into().is_finite() {
        out.put_slice(zmij::Buffer::new().format_finite(x).as_bytes());
    } else {
        write_finite_stand_in(out, x.into());
    }
}

#[cold]
fn write_finite_stand_in(out: &mut impl BufMut, x: f64) {
    out.put_slice(zmij::Buffer::new().format_finite(finite_stand_in(x)).as_bytes());
}

/// The text of the values most of a pose is made of — `0.0` (untouched
/// translation axes and quaternion components) and `1.0` (scales, identity
/// rotations) — exactly as the formatter writes them, without running it:
/// in a typical pose two numbers in three are one of these.
#[inline(always)]
pub(super) fn common_text(x: f32) -> Option<&'static [u8]> {
    match x.to_bits() {
        0x0000_0000 => Some(b"0.0"),
        0x8000_0000 => Some(b"-0.0"),
        0x3f80_0000 => Some(b"1.0"),
        0xbf80_0000 => Some(b"-1.0"),
        _ => None,
    }
}

/// The nearest finite `f32` to a non-finite `x` (±`f32::MAX`; 0 for NaN).
#[cold]
pub(super) fn finite_stand_in(x: f64) -> f32 {
    if x.is_nan() { 0.0 } else { f32::MAX.copysign(x as f32) }
}
