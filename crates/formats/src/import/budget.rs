//! What one import may read into memory and produce, checked before it
//! allocates: a text document's size, and the keys of all its clips.

use super::error::ImportError;
use super::source::Source;
use super::spec::ImportLimits;

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
