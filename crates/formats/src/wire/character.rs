//! The character document (docs/characters.md): a skeleton as a clip
//! document has it, and the humanoid roles given for it.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::json::{DocError, SkeletonDoc, parse_document};

/// A character: a named skeleton (rest pose, inverse binds) and the roles
/// given for its joints (the rest are inferred).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CharacterDoc {
    pub name: String,
    pub skeleton: SkeletonDoc,
    /// Role (VRM 1.0 humanoid bone name, such as `hips` or `leftUpperArm`)
    /// → joint name; `null` leaves the role unmapped (inference does not fill it).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    #[schema(value_type = Object)]
    pub roles: BTreeMap<String, Option<String>>,
}

/// Parses a character document, reporting the JSON pointer of any type error.
///
/// # Errors
/// Malformed JSON (`malformed_json`) or a field of the wrong type or name
/// (`invalid_field`), with its pointer.
pub fn parse_character_doc(body: &[u8]) -> Result<CharacterDoc, DocError> {
    parse_document(body)
}
