//! glTF/GLB import of arbitrary bytes: errors are fine, panics are not, and
//! whatever imports must build.
#![no_main]

use inbetween::anim::Clip;
use inbetween::import::{Format, ImportOptions, import};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let format = if data.starts_with(b"glTF") { Format::Glb } else { Format::Gltf };
    if let Ok(imported) = import(data, format, &ImportOptions::default()) {
        for clip in &imported.clips {
            Clip::build(clip).expect("imported clips build");
        }
    }
});
