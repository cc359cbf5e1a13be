//! Named, versioned JSON documents (characters, graphs): one row per
//! document — id, name, version, the canonical text — with the one figure
//! and the one report a listing shows, derived by the caller when it writes
//! (the store parses no document). Names identify documents as they do
//! clips (docs/api.md, "Names"); every kind follows the same statements
//! (`store::sql_document`), each in its own table.

use super::{MeshWrite, NameFilters};

/// Which table of documents.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DocKind {
    /// `characters` (docs/characters.md): the figure is the joint count, the report the role map.
    Character,
    /// `graphs` (docs/graphs.md): the figure is the node count, the report the graph's summary.
    Graph,
}

impl DocKind {
    /// What a row is, in refusals and logs (`character`, `graph`).
    pub fn what(self) -> &'static str {
        match self {
            DocKind::Character => "character",
            DocKind::Graph => "graph",
        }
    }
}

/// A document's row without its document.
#[derive(Debug, Clone, PartialEq)]
pub struct DocMeta {
    /// Opaque, URL-safe, time-ordered (UUIDv7).
    pub id: String,
    pub name: String,
    /// 1 on create, +1 on each replace.
    pub version: u64,
    /// The one count a listing shows (a character's joints, a graph's nodes).
    pub figure: u32,
    /// What a listing shows beyond it, as the caller wrote it (JSON), opaque here.
    pub report_json: String,
    /// Whether a skinned mesh is kept with it (only characters have meshes).
    pub mesh: bool,
    /// Unix milliseconds.
    pub created_at: i64,
    pub updated_at: i64,
}

/// A stored document: its row and the canonical text, exactly as accepted.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredDoc {
    pub meta: DocMeta,
    pub doc_json: String,
}

/// What a create or replace of a document writes.
#[derive(Debug, Clone, PartialEq)]
pub struct NewDoc {
    pub name: String,
    pub doc_json: String,
    pub figure: u32,
    pub report_json: String,
    /// [`MeshWrite::Keep`] is taken as [`MeshWrite::None`]: a document is
    /// only ever written whole; a kind without meshes ignores it.
    pub mesh: MeshWrite,
}

/// A page of documents: ids after `after`, in id (creation) order, that
/// pass every name filter given.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DocQuery {
    pub names: NameFilters,
    pub limit: u32,
}

/// How a document is referred to: `name:<name>`, else an id.
pub fn name_reference(reference: &str) -> Option<&str> {
    reference.strip_prefix("name:")
}
