//! The stored form of characters (docs/characters.md,
//! `migrations/*/0006_characters.sql`): documents of the `characters`
//! table (`store::document`), whose figure is the joint count and whose
//! report is the role map, and their skinned meshes. These types are the
//! character view of a [`DocMeta`] row.

use super::MeshWrite;
use super::document::{DocMeta, NewDoc, StoredDoc};

pub use super::document::DocQuery as CharacterQuery;

/// A character's row without its document.
#[derive(Debug, Clone, PartialEq)]
pub struct CharacterMeta {
    /// Opaque, URL-safe, time-ordered (UUIDv7).
    pub id: String,
    pub name: String,
    /// 1 on create, +1 on each replace.
    pub version: u64,
    pub joints: u32,
    /// The role map as the caller wrote it (a JSON object), opaque here.
    pub roles_json: String,
    /// Whether a skinned mesh is kept with it.
    pub mesh: bool,
    /// Unix milliseconds.
    pub created_at: i64,
    pub updated_at: i64,
}

/// A stored character: its row and the canonical document, exactly as accepted.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredCharacter {
    pub meta: CharacterMeta,
    pub doc_json: String,
}

/// What a create or replace of a character writes.
#[derive(Debug, Clone, PartialEq)]
pub struct NewCharacter {
    pub name: String,
    pub doc_json: String,
    pub joints: u32,
    /// The role map, as [`CharacterMeta::roles_json`] will hand it back.
    pub roles_json: String,
    /// [`MeshWrite::Keep`] is taken as [`MeshWrite::None`]: a character is
    /// only ever written whole.
    pub mesh: MeshWrite,
}

impl From<DocMeta> for CharacterMeta {
    fn from(m: DocMeta) -> Self {
        let DocMeta { id, name, version, figure, report_json, mesh, created_at, updated_at } = m;
        CharacterMeta { id, name, version, joints: figure, roles_json: report_json, mesh, created_at, updated_at }
    }
}

impl From<StoredDoc> for StoredCharacter {
    fn from(s: StoredDoc) -> Self {
        StoredCharacter { meta: s.meta.into(), doc_json: s.doc_json }
    }
}

impl From<NewCharacter> for NewDoc {
    fn from(c: NewCharacter) -> Self {
        let NewCharacter { name, doc_json, joints, roles_json, mesh } = c;
        NewDoc { name, doc_json, figure: joints, report_json: roles_json, mesh }
    }
}
