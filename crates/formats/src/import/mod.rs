//! Importers: the files animators' tools produce (glTF 2.0, GLB, BVH motion
//! capture) turned into [`ClipSpec`]s the core can build.
//!
//! Uploads are untrusted, so every importer reads only the [`Source`] it is
//! given (no filesystem, no network: a glTF buffer that names an external
//! file is refused unless the caller supplies a [`Resolver`], which the CLI
//! does for local files and the server for the parts of a multipart upload),
//! checks every count and offset against the data before it reads or
//! allocates, and bounds everything it produces by [`ImportLimits`]. Any
//! problem is an [`ImportError`], a client error with a stable code; no input
//! panics.
//!
//! Files may be far larger than what is read of them: a GLB's JSON chunk is
//! read whole, then only the byte ranges its animations' accessors and its
//! skins' inverse bind matrices occupy, and those of the skinned mesh a clip
//! keeps for the viewer (`mesh`: bounded by [`ImportLimits::max_mesh_bytes`]
//! before it is read); other images and mesh data are never read. Only a `.gltf` or `.bvh` file (text, parsed whole) is held in
//! memory entire, bounded by [`ImportLimits::max_document_bytes`].
//!
//! What is imported and how (the decisions a user would ask about):
//! - glTF: one clip per animation, named after it (unnamed: after the file,
//!   else `animation<i>`). The skeleton is the joints of every skin the animation
//!   drives, plus every animated node, plus all their ancestors up to the
//!   scene root, parents first, so a joint's model space is its node's
//!   world transform. Rest poses are the nodes' TRS; `matrix` nodes are
//!   decomposed, and a matrix that is not a TRS (shear, non-affine) is
//!   refused rather than silently changed. Joint names are node names or
//!   `node<i>`; a repeated name gets `#<node index>` appended. Inverse bind
//!   matrices come from the skin (identity when it has none). Samplers map
//!   STEP/LINEAR/CUBICSPLINE to `step`/`linear`/`cubic_hermite`; morph
//!   target weight channels are reported as `not_imported` warnings.
//!   VRM 1.0's `VRMC_springBone` becomes each skinned clip's spring chains
//!   (`Imported::springs`, docs/springs.md, “Import”), their nodes part of
//!   its skeleton; a chain that does not fit is left out with a warning.
//! - BVH: one clip. OFFSET is the rest translation; position channels give
//!   translation keys (a missing axis keeps its OFFSET value); rotation
//!   channels multiply in the order listed (`Zrotation Xrotation Yrotation`
//!   is `Rz·Ry·…` left to right, column vectors); End Sites become leaf
//!   joints named `<parent>_end`. Frame `k` is at `k · Frame Time`.
//!
//! Every clip this module returns has passed [`Clip::build`](anim::Clip::build).
//!
//! An import also returns [`Warning`]s, each pointing into the file: parts
//! it left out, and what [`anim::lint`] notices in the clips (glTF:
//! every check; BVH: only the frame-time one, since the importer computes
//! the rotations itself). Warnings never change a clip; the one repair,
//! [`ImportOptions::fix_hemispheres`], is the caller's choice.

use anim::Clip;
use anim::spring::{ChainSpec, Springs, SpringsSpec};

mod accessor;
mod budget;
mod buffers;
mod bvh;
pub mod convention;
mod error;
mod gltf;
mod image;
mod mesh;
mod names;
mod source;
mod spec;
mod vrm;
mod vrm_extension;
mod vrm_humanoid;
pub mod warning;

pub use budget::{Budget, read_document};
pub use error::{ErrorClass, ImportError};
pub use names::{clip_name, is_generic_animation_name, unique_names};
pub use source::Source;
pub use spec::{Format, ImportLimits, ImportOptions, Imported, ImportedCharacter, Resolver, SCALE_RANGE, UpAxis};
pub use warning::Warning;

/// Guesses the format of an upload: the magic bytes first (they cannot
/// lie about a GLB), then the `Content-Type`, then the first text token.
pub fn sniff(bytes: &[u8], content_type: Option<&str>) -> Option<Format> {
    if bytes.starts_with(b"glTF") {
        return Some(Format::Glb);
    }
    let media = content_type.map(|c| c.split(';').next().unwrap_or("").trim().to_ascii_lowercase());
    match media.as_deref() {
        Some("model/gltf-binary") => return Some(Format::Glb),
        Some("model/gltf+json") => return Some(Format::Gltf),
        Some("application/x-bvh" | "model/x-bvh" | "text/x-bvh" | "application/bvh") => return Some(Format::Bvh),
        _ => {}
    }
    let text = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let start = text.iter().position(|b| !b.is_ascii_whitespace()).map_or(&[][..], |i| &text[i..]);
    if start.starts_with(b"{") {
        Some(Format::Gltf)
    } else if start.len() >= 9 && start[..9].eq_ignore_ascii_case(b"HIERARCHY") {
        Some(Format::Bvh)
    } else {
        None
    }
}

/// [`sniff`], or why not: an FBX file by name ([`ImportError::Fbx`]),
/// anything else [`ImportError::UnknownFormat`].
///
/// # Errors
/// As said.
pub fn detect(head: &[u8], content_type: Option<&str>) -> Result<Format, ImportError> {
    if is_fbx(head) {
        return Err(ImportError::Fbx);
    }
    sniff(head, content_type).ok_or(ImportError::UnknownFormat)
}

/// Prefixes every clip's name, then makes the names unique within the
/// file (a later clip of a taken name gets `#<i>`): names identify clips.
fn name_clips(clips: &mut [anim::ClipSpec], prefix: Option<&str>) {
    let names = clips.iter().map(|c| clip_name(&format!("{}{}", prefix.unwrap_or(""), c.name))).collect();
    for (clip, name) in clips.iter_mut().zip(unique_names(names)) {
        clip.name = name;
    }
}

/// As [`name_clips`], for the characters (names identify them too).
fn name_characters(characters: &mut [ImportedCharacter], prefix: Option<&str>) {
    let names = characters.iter().map(|c| clip_name(&format!("{}{}", prefix.unwrap_or(""), c.name))).collect();
    for (character, name) in characters.iter_mut().zip(unique_names(names)) {
        character.name = name;
    }
}

/// Whether the bytes begin an FBX file: binary (`Kaydara FBX Binary`) or
/// ASCII (its `; FBX 7.4.0 project file` comment, or `FBXHeaderExtension:`
/// as its first key). FBX is refused by name ([`ImportError::Fbx`]), with the
/// conversion that makes it importable, rather than as an unknown format.
pub fn is_fbx(head: &[u8]) -> bool {
    if head.starts_with(b"Kaydara FBX Binary") {
        return true;
    }
    let text = head.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(head);
    let start = text.iter().position(|b| !b.is_ascii_whitespace()).map_or(&[][..], |i| &text[i..]);
    let upper = |n: usize| start[..start.len().min(n)].to_ascii_uppercase();
    upper(5).starts_with(b"; FBX") || upper(19).starts_with(b"FBXHEADEREXTENSION")
}

/// A file name without its directory and extension (`walk.bvh` → `walk`),
/// `None` if nothing is left: the [`ImportOptions::file_name`] of an upload.
pub fn file_stem(file_name: &str) -> Option<String> {
    let base = file_name.rsplit(['/', '\\']).next().unwrap_or(file_name);
    let stem = match base.rsplit_once('.') {
        Some((stem, _)) if !stem.is_empty() => stem,
        _ => base,
    };
    (!stem.trim().is_empty()).then(|| stem.to_owned())
}

/// How many leading bytes [`sniff`] needs of a source: a GLB's magic, or a
/// text file's first token after a byte-order mark and some whitespace.
pub const SNIFF_BYTES: usize = 4096;

/// Imports `bytes` as `format`.
///
/// # Errors
/// Any malformed, hostile, oversized or unsupported input, as an
/// [`ImportError`]; external glTF buffers are refused.
pub fn import(bytes: &[u8], format: Format, options: &ImportOptions) -> Result<Imported, ImportError> {
    import_with(bytes, format, options, None)
}

/// [`import`] with a resolver for external glTF buffer URIs.
///
/// # Errors
/// As [`import`]; errors from `resolver` are passed through.
pub fn import_with(
    bytes: &[u8],
    format: Format,
    options: &ImportOptions,
    resolver: Option<Resolver<'_>>,
) -> Result<Imported, ImportError> {
    import_from(&Source::memory(bytes::Bytes::copy_from_slice(bytes)), format, options, resolver)
}

/// Imports a [`Source`] as `format`, reading only what the format needs of
/// it (see the module doc): how the server imports a spooled upload and the
/// CLI a file, whatever their size.
///
/// # Errors
/// As [`import_with`]; [`ImportError::Read`] when the source cannot be read.
pub fn import_from(
    source: &Source,
    format: Format,
    options: &ImportOptions,
    resolver: Option<Resolver<'_>>,
) -> Result<Imported, ImportError> {
    let limits = &options.limits;
    if is_fbx(&source.head(64)?) {
        return Err(ImportError::Fbx);
    }
    if source.len() > limits.max_bytes {
        return Err(ImportError::TooLarge { what: "the upload (bytes)", max: limits.max_bytes, found: source.len() });
    }
    if !SCALE_RANGE.contains(&options.scale) {
        let detail = format!("scale must be within {SCALE_RANGE:?}, got {}", options.scale);
        return Err(ImportError::Unsupported(detail));
    }
    let (mut imported, skeleton_pointer) = match format {
        Format::Gltf | Format::Glb => (gltf::import(source, format, options, resolver)?, "/nodes"),
        Format::Bvh => (bvh::import(&read_document(source, "the BVH file", limits)?, options)?, "/HIERARCHY"),
    };
    convention::apply(&mut imported, options, skeleton_pointer);
    if options.characters_only {
        (imported.clips, imported.meshes, imported.springs) = (Vec::new(), Vec::new(), Vec::new());
    }
    name_clips(&mut imported.clips, options.name_prefix.as_deref());
    name_characters(&mut imported.characters, options.name_prefix.as_deref());
    for (clip, springs) in imported.clips.iter().zip(&mut imported.springs) {
        let built = Clip::build_within(clip, limits.max_build_work)
            .map_err(|error| ImportError::InvalidClip { clip: clip.name.clone(), error })?;
        keep_fitting_springs(springs, built.skeleton(), &mut imported.warnings);
    }
    imported.warnings = warning::capped(std::mem::take(&mut imported.warnings));
    Ok(imported)
}

/// Keeps the chains that fit the clip's skeleton together with those kept
/// before them (docs/springs.md, “Fields”); each other is left out with a
/// warning (once per chain, whichever clips it failed on).
fn keep_fitting_springs(chains: &mut Vec<ChainSpec>, skeleton: &anim::Skeleton, warnings: &mut Vec<Warning>) {
    let mut spec = SpringsSpec::default();
    for (k, chain) in std::mem::take(chains).into_iter().enumerate() {
        spec.chains.push(chain);
        let Err(error) = Springs::build(&spec, skeleton) else { continue };
        let chain = spec.chains.pop().expect("just pushed");
        let pointer = format!("{}/springs/{k}", vrm::POINTER);
        if !warnings.iter().any(|w| w.pointer == pointer) {
            let detail = format!("spring '{}' was not imported: {error} ({})", chain.name, error.kind.code());
            warnings.push(Warning::new(warning::NOT_IMPORTED, pointer, detail));
        }
    }
    *chains = spec.chains;
}
