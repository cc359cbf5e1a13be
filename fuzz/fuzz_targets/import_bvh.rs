//! BVH import of arbitrary bytes, with linear and Catmull-Rom keys: errors
//! are fine, panics are not, and whatever imports must build.
#![no_main]

use inbetween::anim::{Clip, Interpolation};
use inbetween::import::{Format, ImportOptions, import};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The last byte picks the interpolation, so both are explored.
    let interpolation = match data.last() {
        Some(b) if b % 2 == 1 => Interpolation::CatmullRom,
        _ => Interpolation::Linear,
    };
    let options = ImportOptions { bvh_interpolation: interpolation, ..ImportOptions::default() };
    if let Ok(imported) = import(data, Format::Bvh, &options) {
        for clip in &imported.clips {
            Clip::build(clip).expect("imported clips build");
        }
    }
});
