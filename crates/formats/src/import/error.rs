//! Why an upload could not be imported.
//!
//! Every variant but [`ImportError::Read`] is the client's fault (a
//! malformed, hostile, oversized or unsupported file): the edge maps
//! [`ErrorClass`] to 400, 413, 415 or 422 and sends [`ImportError::code`] with the
//! message. `Read` is the caller's own source failing (its file could not be
//! read), which the server answers as an internal error. The
//! messages name the offending object by its glTF index or BVH line so a
//! user can find it in their file.

use anim::{ClipError, ClipErrorKind};

/// How an edge should treat an [`ImportError`] (HTTP: 400, 413, 415, 422).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorClass {
    /// The bytes are not a well-formed file of the format (400).
    Malformed,
    /// The file exceeds an [`ImportLimits`](super::ImportLimits) bound (413).
    TooLarge,
    /// Well-formed, but its content cannot be imported (422).
    Unprocessable,
    /// A file of a format the importers do not read (415).
    UnsupportedFormat,
}

/// An upload that cannot be imported. `code()` is stable for clients.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ImportError {
    #[error("the format could not be recognised: expected glTF JSON, GLB or BVH")]
    UnknownFormat,
    #[error(
        "this is an FBX file, which is not imported: convert it to glTF (GLB) first, with Blender's glTF exporter \
         (File ▸ Import ▸ FBX, then File ▸ Export ▸ glTF 2.0) or FBX2glTF (`FBX2glTF --binary file.fbx`)"
    )]
    Fbx,
    #[error("too large: {what} is {found}, the limit is {max}")]
    TooLarge { what: &'static str, max: u64, found: u64 },
    #[error(
        "too large: the buffers read hold {found} bytes (each buffer's byteLength, \
         even when several name the same part), the limit is {max}"
    )]
    ResolvedTooLarge { max: u64, found: u64 },
    /// A part held in memory whole (a `.gltf` or `.bvh` file, a GLB's JSON
    /// chunk) over [`ImportLimits::max_document_bytes`](super::ImportLimits).
    #[error("too large: {what} is {found} bytes and is read into memory whole; the limit is {max}")]
    DocumentTooLarge { what: &'static str, max: u64, found: u64 },
    #[error("the file could not be read: {0}")]
    Read(String),
    #[error("not a valid GLB container: {0}")]
    Container(String),
    #[error("the glTF JSON cannot be read: {0}")]
    Json(String),
    #[error("the glTF document is invalid: {0}")]
    InvalidGltf(String),
    #[error(
        "buffer {buffer} refers to the external file '{uri}', which an upload cannot carry: \
         embed it (a .glb, or a data: URI)"
    )]
    ExternalUri { buffer: usize, uri: String },
    #[error("buffer {buffer} refers to '{uri}', which cannot be read: {reason}")]
    UnreadableUri { buffer: usize, uri: String, reason: String },
    #[error("buffer {buffer} has a bad data: URI: {detail}")]
    DataUri { buffer: usize, detail: String },
    #[error("{what} lies outside its data: {detail}")]
    OutOfBounds { what: String, detail: String },
    #[error("{0}")]
    Unsupported(String),
    #[error("{what} is not a finite number")]
    NonFinite { what: String },
    #[error("{what}: key times must be strictly increasing ({current} follows {previous})")]
    TimesNotIncreasing { what: String, previous: f32, current: f32 },
    #[error("the node hierarchy is not a tree: {0}")]
    NotATree(String),
    #[error("the hierarchy is deeper than {max} levels")]
    TooDeep { max: usize },
    #[error("the file has no animation that can be imported")]
    NoAnimations,
    #[error("the file has no skin (a glTF file) or hierarchy (a BVH file) to make a character of")]
    NoSkins,
    #[error("line {line}: {detail}")]
    BvhSyntax { line: usize, detail: String },
    #[error("line {line}: {detail}")]
    CountMismatch { line: usize, detail: String },
    #[error("Frame Time must be a positive finite number of seconds, got {value}")]
    BadFrameTime { value: String },
    #[error("clip '{clip}' is invalid at {}: {}", error.path, error.kind)]
    InvalidClip { clip: String, error: ClipError },
}

impl ImportError {
    /// A stable machine-readable code.
    pub fn code(&self) -> &'static str {
        use ImportError::*;
        match self {
            UnknownFormat => "unknown_format",
            Fbx => "fbx_not_supported",
            TooLarge { .. } => "too_large",
            ResolvedTooLarge { .. } => "resolved_bytes_too_large",
            DocumentTooLarge { .. } => "document_too_large",
            Read(_) => "unreadable",
            Container(_) => "bad_container",
            Json(_) => "bad_json",
            InvalidGltf(_) => "invalid_gltf",
            ExternalUri { .. } | UnreadableUri { .. } => "external_uri",
            DataUri { .. } => "bad_data_uri",
            OutOfBounds { .. } => "out_of_bounds",
            Unsupported(_) => "unsupported",
            NonFinite { .. } => "non_finite",
            TimesNotIncreasing { .. } => "times_not_increasing",
            NotATree(_) => "not_a_tree",
            TooDeep { .. } => "too_deep",
            NoAnimations => "no_animations",
            NoSkins => "no_skins",
            BvhSyntax { .. } => "bvh_syntax",
            CountMismatch { .. } => "count_mismatch",
            BadFrameTime { .. } => "bad_frame_time",
            // A limit, not a defect of the file: the same code as an upload.
            InvalidClip { error, .. } if matches!(error.kind, ClipErrorKind::BuildBudgetExceeded { .. }) => {
                "build_budget_exceeded"
            }
            InvalidClip { .. } => "invalid_clip",
        }
    }

    /// Which kind of client error this is.
    pub fn class(&self) -> ErrorClass {
        use ImportError::*;
        match self {
            TooLarge { .. } | ResolvedTooLarge { .. } | DocumentTooLarge { .. } | TooDeep { .. } => {
                ErrorClass::TooLarge
            }
            Fbx => ErrorClass::UnsupportedFormat,
            UnknownFormat | Container(_) | Json(_) | DataUri { .. } | BvhSyntax { .. } => ErrorClass::Malformed,
            _ => ErrorClass::Unprocessable,
        }
    }

    /// The JSON pointer into the produced clip document, for
    /// [`ImportError::InvalidClip`]; `None` otherwise.
    pub fn pointer(&self) -> Option<String> {
        match self {
            ImportError::InvalidClip { error, .. } => Some(error.path.to_pointer()),
            _ => None,
        }
    }
}

impl From<std::io::Error> for ImportError {
    fn from(e: std::io::Error) -> Self {
        ImportError::Read(e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anim::Path;

    /// Importers produce no constant-speed tracks today, but a clip over the
    /// build budget must read as the limit it is, as on every other route.
    #[test]
    fn an_imported_clip_over_the_build_budget_has_the_upload_code() {
        let invalid = |kind| ImportError::InvalidClip { clip: "c".into(), error: ClipError::new(Path::root(), kind) };
        let over = invalid(ClipErrorKind::BuildBudgetExceeded { limit: 10, spent: 11 });
        assert_eq!((over.code(), over.class()), ("build_budget_exceeded", ErrorClass::Unprocessable));
        assert_eq!(invalid(ClipErrorKind::NoTracks).code(), "invalid_clip");
    }
}
