//! Warnings as uploads and imports answer them: `{code, pointer, detail}`.
//!
//! A warning is about data that is valid but probably wrong (docs/warnings.md
//! lists every code): the upload still succeeds, and the warning says where
//! to look. `pointer` is a JSON pointer into what the user sent — the clip
//! document (`/tracks/3/values/5`), the glTF file
//! (`/animations/0/channels/3`) — or, for a BVH file, the header line
//! concerned (`/MOTION/Frame Time`). The rules themselves are the core's
//! ([`anim::lint`]) or the importer's (parts of a file not imported);
//! this type only carries them to the edge.

use serde::{Deserialize, Serialize};

use anim::lint::Lint;

/// Something in an upload that is valid but probably not what was meant.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Warning {
    /// Stable snake_case code (docs/warnings.md).
    pub code: String,
    /// Where, in the document or file uploaded.
    pub pointer: String,
    /// What was noticed, and what the server did about it.
    pub detail: String,
}

/// A part of a file the importer left out (a channel or animation it does
/// not support, a conflicting inverse bind matrix).
pub const NOT_IMPORTED: &str = "not_imported";
/// An animation named as exporters name every animation (`mixamo.com`,
/// `Take 001`): the clip was named after the file instead.
pub const GENERIC_ANIMATION_NAME: &str = "generic_animation_name";
/// The last warning of a list cut at [`MAX_WARNINGS`].
pub const TOO_MANY_WARNINGS: &str = "too_many_warnings";
/// At most this many warnings per answer: a file with a problem on every
/// track says so a hundred times, then how many more there were.
pub const MAX_WARNINGS: usize = 100;

impl Warning {
    pub fn new(code: &str, pointer: impl Into<String>, detail: impl Into<String>) -> Self {
        Warning { code: code.to_owned(), pointer: pointer.into(), detail: detail.into() }
    }

    /// A core lint at `pointer`.
    pub fn from_lint(lint: &Lint, pointer: impl Into<String>) -> Self {
        Warning::new(lint.code.as_str(), pointer, lint.detail.clone())
    }
}

/// Lints about a clip document, each at its place in that document.
pub fn in_document(lints: &[Lint]) -> Vec<Warning> {
    capped(lints.iter().map(|l| Warning::from_lint(l, l.path().to_pointer())).collect())
}

/// `warnings` cut to [`MAX_WARNINGS`], the last one then saying how many
/// were left out.
pub fn capped(mut warnings: Vec<Warning>) -> Vec<Warning> {
    if warnings.len() > MAX_WARNINGS {
        let more = warnings.len() - (MAX_WARNINGS - 1);
        warnings.truncate(MAX_WARNINGS - 1);
        warnings.push(Warning::new(TOO_MANY_WARNINGS, "", format!("{more} more warnings were left out")));
    }
    warnings
}
