//! The part of a glTF document the VRM importers (`vrm`, `vrm_humanoid`)
//! read: its `extensions`, as the one extension type each of them
//! declares, so each reads, and refuses, only its own extension.

use serde::Deserialize;
use serde::de::DeserializeOwned;

use super::error::ImportError;

/// A glTF document seen only through its `extensions` (absent: `None`).
#[derive(Deserialize)]
struct Document<E> {
    extensions: Option<E>,
}

/// The document's `extensions` read as `E`; nothing when the bytes never
/// mention `name`, the extension's name (most files: no parse at all).
///
/// # Errors
/// The document does not read as `E`: `InvalidGltf` at `pointer`.
pub fn extensions<E: DeserializeOwned>(json: &[u8], name: &str, pointer: &str) -> Result<Option<E>, ImportError> {
    if !json.windows(name.len()).any(|w| w == name.as_bytes()) {
        return Ok(None);
    }
    let doc: Document<E> = serde_json::from_slice(json).map_err(|e| invalid(format!("{pointer}: {e}")))?;
    Ok(doc.extensions)
}

/// A VRM extension's refusal: the file is not valid glTF.
pub fn invalid(detail: String) -> ImportError {
    ImportError::InvalidGltf(detail)
}
