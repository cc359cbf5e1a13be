//! Importer tests against the real third-party files in `../shared/testdata`
//! (see its SOURCES.md; those the repository ships are read from `examples/`,
//! see `reference::testdata`), with every expected value computed independently in
//! `reference` (raw JSON and buffers, glTF Appendix C formulas, matrix
//! forward kinematics), plus a table of hostile inputs.

mod bvh;
mod compact;
mod conventions;
mod derived_ranges;
mod feet;
mod files;
mod fuzz_regressions;
mod gltf_interpolation;
mod gltf_skinned;
mod graph;
mod hostile;
pub mod reference;

mod springs;
mod validation;
mod vrm;

extern crate inbetween_formats as formats;

use anim::{Clip, ClipSpec, Playback, SampleOptions, Sampler, Space};
use formats::import::{Format, ImportOptions, Imported, Source, import, import_with};

/// Imports a testdata file through the library, resolving a sibling buffer
/// file the way the CLI does (the test reads it itself).
pub fn import_file(rel: &str, options: &ImportOptions) -> Imported {
    import_path(&reference::testdata(rel), options)
}

/// [`import_file`] for any file.
pub fn import_path(path: &std::path::Path, options: &ImportOptions) -> Imported {
    let rel = path.display();
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{rel}: {e} (README, \"The two commands\")"));
    let format = match path.extension().and_then(|e| e.to_str()) {
        Some("glb") => Format::Glb,
        Some("bvh") => Format::Bvh,
        _ => Format::Gltf,
    };
    let dir = path.parent().unwrap().to_path_buf();
    let mut resolve = |uri: &str| std::fs::read(dir.join(uri)).map(Source::from).map_err(|e| e.to_string());
    let imported = if format == Format::Gltf && bytes.windows(5).any(|w| w == b".bin\"") {
        import_with(&bytes, format, options, Some(&mut resolve))
    } else {
        import(&bytes, format, options)
    };
    imported.unwrap_or_else(|e| panic!("{rel}: {e} ({})", e.code()))
}

pub fn build(spec: &ClipSpec) -> Clip {
    Clip::build(spec).unwrap_or_else(|e| panic!("{}: {e}", spec.name))
}

/// Options for sampling at a raw clip time: clamp, no ease.
pub fn opts(space: Space) -> SampleOptions {
    SampleOptions { playback: Some(Playback::Once), space, ..SampleOptions::default() }
}

pub fn sample(clip: &Clip, t: f64, space: Space) -> Sampler {
    let mut sampler = Sampler::new();
    clip.sample(t, &opts(space), &mut sampler);
    sampler
}
