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

use anim::{Clip, ClipSpec, Interpolation, MAX_NAME_CHARS};

mod accessor;
mod buffers;
mod bvh;
mod error;
mod gltf;
mod mesh;
mod source;
pub mod warning;

pub use error::{ErrorClass, ImportError};
pub use source::Source;
pub use warning::Warning;

/// A file format the importers read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// glTF 2.0 JSON (`.gltf`), buffers embedded as `data:` URIs.
    Gltf,
    /// Binary glTF (`.glb`): a JSON chunk and a BIN chunk.
    Glb,
    /// BioVision Hierarchy motion capture (`.bvh`), text.
    Bvh,
}

impl Format {
    pub fn as_str(self) -> &'static str {
        match self {
            Format::Gltf => "gltf",
            Format::Glb => "glb",
            Format::Bvh => "bvh",
        }
    }
}

impl std::str::FromStr for Format {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "gltf" => Ok(Format::Gltf),
            "glb" => Ok(Format::Glb),
            "bvh" => Ok(Format::Bvh),
            _ => Err(format!("unknown format '{s}': expected gltf, glb or bvh")),
        }
    }
}

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

/// Bounds on what one import may read and produce. Each is checked before
/// the corresponding allocation, so a small hostile file cannot make the
/// importer allocate much more than its own size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImportLimits {
    /// The file itself (a file-backed [`Source`] is read by range, so this
    /// bounds disk, not memory).
    pub max_bytes: u64,
    /// What is read into memory whole: a `.gltf` or `.bvh` file, a GLB's
    /// JSON chunk.
    pub max_document_bytes: u64,
    /// Joints of one clip's skeleton.
    pub max_joints: usize,
    /// Tracks of one clip.
    pub max_tracks: usize,
    /// Keys of one track (glTF accessor counts).
    pub max_keys_per_track: usize,
    /// BVH `Frames:`.
    pub max_frames: usize,
    /// Clips (glTF animations) of one file.
    pub max_clips: usize,
    /// Keys plus joints over every clip of the import: bounds the output
    /// even when many channels share one accessor. The importers also cap
    /// it at one per input byte (+4096), which no real file comes near.
    pub max_total_keys: u64,
    /// Levels of the joint hierarchy.
    pub max_depth: usize,
    /// Bytes of glTF buffers named by URI (`data:`, or a file or part the
    /// [`Resolver`] supplies): every opened buffer's `byteLength`, counted
    /// once per buffer even when several name the same part or file (whose
    /// bytes are then shared, not copied). A GLB's own BIN chunk is bounded
    /// by `max_bytes` instead.
    pub max_resolved_bytes: u64,
    /// Build work of one produced clip (see [`Clip::build_within`]).
    pub max_build_work: u64,
    /// The encoded size the skinned meshes of one import may reach together
    /// (each bounded from its accessors' counts before any is read); a mesh
    /// that would pass it is left out with a warning, its clips imported
    /// without it.
    pub max_mesh_bytes: u64,
    /// A base colour texture is kept with a mesh up to this many bytes
    /// (PNG or JPEG as in the file); a larger one leaves the base colour
    /// factor.
    pub max_mesh_texture_bytes: u64,
}

impl Default for ImportLimits {
    fn default() -> Self {
        ImportLimits {
            max_bytes: 256 << 20,
            max_document_bytes: 64 << 20,
            max_joints: 4096,
            max_tracks: 16_384,
            max_keys_per_track: 1_000_000,
            max_frames: 1_000_000,
            max_clips: 1024,
            max_total_keys: 16_000_000,
            max_depth: 256,
            max_resolved_bytes: 4 * (64 << 20),
            max_build_work: anim::DEFAULT_BUILD_WORK,
            max_mesh_bytes: 16 << 20,
            max_mesh_texture_bytes: 1 << 20,
        }
    }
}

/// How to import.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// BVH frames become keys with this interpolation: `Linear` (default),
    /// `CatmullRom` (SPEC §2.2), `BSpline` (§2.5: approximating, to smooth
    /// the capture's jitter) or `Step`. `CubicHermite` is refused (no
    /// tangents in a BVH).
    pub bvh_interpolation: Interpolation,
    /// The clip name (BVH), or a prefix `NAME/<animation>` for glTF files
    /// with several animations (a single animation is named `NAME`).
    pub name: Option<String>,
    /// The file's name without its extension (the CLI's path, a multipart
    /// part's file name), for clips the file does not name: without `name`,
    /// a BVH clip is named after it, and so is an unnamed glTF animation
    /// (`FILE`, or `FILE/animation<i>` when the file has several).
    pub file_name: Option<String>,
    /// glTF `CUBICSPLINE` rotations: flip each key (value and tangents)
    /// that lies in the opposite hemisphere to the key before, so the curve
    /// turns the short way (Blender 3.x's exporter writes such keys). Off by
    /// default: the glTF spec says to use keys as given.
    pub fix_hemispheres: bool,
    pub limits: ImportLimits,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            bvh_interpolation: Interpolation::Linear,
            name: None,
            file_name: None,
            fix_hemispheres: false,
            limits: ImportLimits::default(),
        }
    }
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

/// The result of an import: clips ready for [`Clip::build`] (each already
/// passed it once) and the warnings about the file (what was left out,
/// what looks wrong), at most [`warning::MAX_WARNINGS`].
#[derive(Debug, Clone, PartialEq)]
pub struct Imported {
    pub clips: Vec<ClipSpec>,
    /// Per clip (in step with `clips`): the skinned mesh the viewer draws,
    /// in the binary form of [`crate::wire::mesh`], when the clip comes from
    /// a glTF skin with triangles bound to it (shared bytes when several
    /// clips drive one skin).
    pub meshes: Vec<Option<bytes::Bytes>>,
    pub warnings: Vec<Warning>,
}

/// Supplies the bytes of an external glTF buffer URI (exactly as written in
/// the file, still percent-encoded), or says why it will not: the CLI for
/// files next to a local `.gltf`, the server for the parts of a multipart
/// upload. It is called once per distinct URI; buffers naming the same URI
/// share the [`Source`] it returns, and read only the ranges they need.
pub type Resolver<'a> = &'a mut dyn FnMut(&str) -> Result<Source, String>;

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
    if source.len() > limits.max_bytes {
        return Err(ImportError::TooLarge { what: "the upload (bytes)", max: limits.max_bytes, found: source.len() });
    }
    let mut imported = match format {
        Format::Gltf | Format::Glb => gltf::import(source, format, options, resolver)?,
        Format::Bvh => bvh::import(&read_document(source, "the BVH file", limits)?, options)?,
    };
    imported.warnings = warning::capped(std::mem::take(&mut imported.warnings));
    for clip in &imported.clips {
        Clip::build_within(clip, limits.max_build_work)
            .map_err(|error| ImportError::InvalidClip { clip: clip.name.clone(), error })?;
    }
    Ok(imported)
}

/// A text file, read into memory whole once it is known to fit
/// [`ImportLimits::max_document_bytes`].
pub fn read_document(source: &Source, what: &'static str, limits: &ImportLimits) -> Result<bytes::Bytes, ImportError> {
    if source.len() > limits.max_document_bytes {
        return Err(ImportError::DocumentTooLarge { what, max: limits.max_document_bytes, found: source.len() });
    }
    Ok(source.read_all()?)
}

/// Counts what an import produces (keys and joints, over all clips)
/// against [`ImportLimits::max_total_keys`] and against the input's size.
///
/// Real files spend several bytes per key (a BVH value is at least two
/// characters, a glTF key at least 16 bytes of buffer plus its time), so
/// one key per input byte, plus a little, never binds them. Only hostile
/// files reach it: many channels sharing one accessor, or sparse accessors
/// with no buffer view (zeros plus a few stored values), which would
/// otherwise turn a few hundred bytes of JSON into gigabytes of keys.
pub struct Budget {
    max: u64,
    used: u64,
}

/// Keys allowed beyond one per input byte, for tiny files.
const BUDGET_SLACK: u64 = 4096;

impl Budget {
    pub fn new(limits: &ImportLimits, input_bytes: u64) -> Self {
        Budget { max: limits.max_total_keys.min(input_bytes.saturating_add(BUDGET_SLACK)), used: 0 }
    }

    /// Reserves `n` more keys (or joints), before they are allocated.
    pub fn take(&mut self, n: usize) -> Result<(), ImportError> {
        self.used = self.used.saturating_add(n as u64);
        if self.used > self.max {
            return Err(ImportError::TooLarge { what: "the keys of all clips", max: self.max, found: self.used });
        }
        Ok(())
    }
}

/// A clip name within the core's limit (longer names are cut, by character).
pub fn clip_name(name: &str) -> String {
    let name = if name.trim().is_empty() { "clip" } else { name };
    name.chars().take(MAX_NAME_CHARS).collect()
}

/// Makes joint names unique within one file, in order: the first holder of
/// a name keeps it; a later one becomes `name#<i>` (`i` its index: the glTF
/// node or BVH joint, which tells the user which one it was), or if that is
/// taken too, `name#<n>` for the smallest free `n` from 2. Every name in the
/// file is reserved up front, so a suffix never takes a name a later node
/// has in the file. A per-name counter keeps crafted collisions linear.
pub fn unique_names(names: Vec<String>) -> Vec<String> {
    use std::collections::{HashMap, HashSet};
    let mut taken: HashSet<String> = names.iter().cloned().collect();
    let mut kept: HashSet<String> = HashSet::with_capacity(names.len());
    let mut next: HashMap<String, usize> = HashMap::new();
    names
        .into_iter()
        .enumerate()
        .map(|(i, name)| {
            if kept.insert(name.clone()) {
                return name;
            }
            let candidate = format!("{name}#{i}");
            if taken.insert(candidate.clone()) {
                return candidate;
            }
            let n = next.entry(name.clone()).or_insert(2);
            loop {
                let candidate = format!("{name}#{n}");
                *n += 1;
                if taken.insert(candidate.clone()) {
                    return candidate;
                }
            }
        })
        .collect()
}
