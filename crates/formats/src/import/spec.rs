//! What an import is asked and what it answers: the format, the options
//! and limits, the imported clips, and the resolver for external buffers.
//! Every importer reads these, so they live apart from the entry points.

use anim::{ClipSpec, Interpolation, Playback, SkeletonSpec};

use super::source::Source;
use super::warning::Warning;

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

/// The axis a file calls up. glTF and this server are Y-up; `Z` turns the
/// file's roots by −90° about X (`import::convention`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UpAxis {
    #[default]
    Y,
    Z,
}

impl std::str::FromStr for UpAxis {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "y" | "Y" => Ok(UpAxis::Y),
            "z" | "Z" => Ok(UpAxis::Z),
            _ => Err(format!("`up` must be y or z, got `{s}`")),
        }
    }
}

/// The bounds of [`ImportOptions::scale`]: a factor outside them is a typo
/// (or would take lengths past what f32 keeps).
pub const SCALE_RANGE: std::ops::RangeInclusive<f32> = 1e-6..=1e6;

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
    /// Build work of one produced clip (see [`Clip::build_within`](anim::Clip::build_within)).
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
    /// A texture is kept only if its header (PNG IHDR, JPEG SOF) declares
    /// at most this many pixels (width × height): a small file can declare
    /// an image that decodes to gigabytes in the viewer.
    pub max_texture_pixels: u64,
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
            max_texture_pixels: 4096 * 4096,
        }
    }
}

/// How to import.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// BVH frames become keys with this interpolation: `Linear` (default),
    /// `CatmullRom` (docs/clip-format.md §2.2), `BSpline` (§2.5: approximating, to smooth
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
    /// Prepended to every clip's name (a folder such as `fox/`).
    pub name_prefix: Option<String>,
    /// The file's up axis (`Z`: turned into Y-up at the roots).
    pub up: UpAxis,
    /// Every length times this (translations, mesh positions, inverse
    /// binds), within [`SCALE_RANGE`]: `0.01` for a file in centimetres.
    pub scale: f32,
    /// Every clip's playback mode: `Loop` by default, as three.js plays
    /// actions (glTF and BVH say nothing of looping).
    pub playback: Playback,
    /// Import characters only (`POST /v1/characters/import`): a glTF file's
    /// skins, its animations not read (a file without any is fine); a BVH
    /// file's `HIERARCHY` as one character.
    pub characters_only: bool,
    pub limits: ImportLimits,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            bvh_interpolation: Interpolation::Linear,
            name: None,
            file_name: None,
            fix_hemispheres: false,
            name_prefix: None,
            up: UpAxis::Y,
            scale: 1.0,
            playback: Playback::Loop,
            characters_only: false,
            limits: ImportLimits::default(),
        }
    }
}

/// The result of an import: clips ready for [`Clip::build`](anim::Clip::build) (each already
/// passed it once) and the warnings about the file (what was left out,
/// what looks wrong), at most [`MAX_WARNINGS`](super::warning::MAX_WARNINGS).
#[derive(Debug, Clone, PartialEq)]
pub struct Imported {
    pub clips: Vec<ClipSpec>,
    /// Per clip (in step with `clips`): the skinned mesh the viewer draws,
    /// in the binary form of [`crate::wire::mesh`], when the clip comes from
    /// a glTF skin with triangles bound to it (shared bytes when several
    /// clips drive one skin).
    pub meshes: Vec<Option<bytes::Bytes>>,
    /// Per clip (in step with `clips`): its spring chains (glTF
    /// `VRMC_springBone`, docs/springs.md), each one checked against the
    /// clip's skeleton; a chain that does not fit was left out with a warning.
    pub springs: Vec<Vec<anim::spring::ChainSpec>>,
    /// glTF: one per skin, its joints (and their ancestors) at their bind
    /// pose; with [`ImportOptions::characters_only`], a BVH's hierarchy.
    pub characters: Vec<ImportedCharacter>,
    pub warnings: Vec<Warning>,
}

/// A character a file holds: a named skeleton whose rest is its bind pose
/// (glTF: every joint's model transform the inverse of its inverse bind
/// matrix; BVH: the offsets, unrotated, the root where the first frame has
/// it), and the skinned mesh bound to it.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportedCharacter {
    pub name: String,
    pub skeleton: SkeletonSpec,
    pub mesh: Option<bytes::Bytes>,
    /// The roles the file gives (a VRM humanoid's `humanBones`): role name →
    /// joint name, as a character document's `roles`; empty: none given.
    pub roles: std::collections::BTreeMap<String, Option<String>>,
}

/// Supplies the bytes of an external glTF buffer URI (exactly as written in
/// the file, still percent-encoded), or says why it will not: the CLI for
/// files next to a local `.gltf`, the server for the parts of a multipart
/// upload. It is called once per distinct URI; buffers naming the same URI
/// share the [`Source`] it returns, and read only the ranges they need.
pub type Resolver<'a> = &'a mut dyn FnMut(&str) -> Result<Source, String>;
