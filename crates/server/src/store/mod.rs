//! Durable clip storage behind one trait.
//!
//! The service talks to a [`ClipStore`]. SQLite ([`sqlite::SqliteStore`]) is
//! embedded so that `inbetween serve` needs no setup; PostgreSQL
//! ([`postgres::PgStore`]) is for several nodes sharing one database, whose
//! [`feed::ChangeFeed`] tells each node what the others changed. Both are one
//! implementation ([`sql::SqlStore`]) running the same statements, with the
//! few differences in a [`dialect::Dialect`]; each runs its own migrations
//! (`migrations/sqlite`, `migrations/postgres`, the same tables), and nothing
//! above this module knows which one is underneath.
//!
//! **Architecture invariant:** the store knows nothing of clips beyond what a
//! row holds. It never parses or validates documents: whatever reaches it has
//! already been accepted by `Clip::build`, and it stores the canonical text
//! as given, with what the list filters on (tags, joint names) handed to it
//! beside it (migration 0002 read stored documents once, to index the clips
//! stored before it). Every write is one atomic transaction (the clip row
//! and its `clip_tags` and `clip_joints` rows), durable when it returns
//! (SQLite `synchronous=FULL` in WAL mode; PostgreSQL with `fsync`,
//! `full_page_writes` and `synchronous_commit` on; both checked as read back
//! from every pooled connection, see [`Durability`]), so a caller that answers `201`
//! after `create` returns never promises more than the disk holds.
//!
//! The trait returns boxed futures so that the service can hold an
//! `Arc<dyn ClipStore>` and pick the backend at startup.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use futures_util::future::BoxFuture;

use anim::Playback;

pub mod broadcast;
pub mod character;
pub mod dialect;
pub mod document;
pub mod feed;
mod filter;
pub mod postgres;
mod retry;
pub mod sql;
mod sql_character;
mod sql_document;
pub mod sqlite;

pub use broadcast::{Covers, StoredBroadcast, StoredCheckpoint, StoredControl};
pub use character::{CharacterMeta, CharacterQuery, NewCharacter, StoredCharacter};
pub use document::{DocKind, DocMeta, DocQuery, NewDoc, StoredDoc, name_reference};
pub use retry::{RetryPolicy, Transience};

/// Whether the store insists on durable commits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Durability {
    /// Every pooled connection is checked as it opens (settings read back
    /// from the database); one that would acknowledge a write before it is
    /// on disk fails to open, so the server refuses to start.
    #[default]
    Required,
    /// `--unsafe-fast-writes`: no check (a warning is logged), and SQLite
    /// runs with `synchronous=NORMAL` (a commit may be lost on power loss).
    UnsafeFast,
}

/// How a store pools its connections and retries transient failures.
#[derive(Debug, Clone, PartialEq)]
pub struct PoolSettings {
    pub max_connections: u32,
    /// How long a request waits for a free connection before it fails (503).
    pub acquire_timeout: Duration,
    pub retry: RetryPolicy,
    pub durability: Durability,
}

impl Default for PoolSettings {
    fn default() -> Self {
        PoolSettings {
            max_connections: 8,
            acquire_timeout: Duration::from_secs(10),
            retry: RetryPolicy::default(),
            durability: Durability::Required,
        }
    }
}

/// The figures of a clip that a listing shows, derived from the compiled
/// clip when it is written (so listing never reads documents).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClipStats {
    pub joints: u32,
    pub tracks: u32,
    pub events: u32,
    pub start: f32,
    pub end: f32,
    pub playback: Playback,
}

/// A clip's row without its document.
#[derive(Debug, Clone, PartialEq)]
pub struct ClipMeta {
    /// Opaque, URL-safe, time-ordered (UUIDv7).
    pub id: String,
    pub name: String,
    /// 1 on create, +1 on each replace.
    pub version: u64,
    pub stats: ClipStats,
    /// The document's `tags`, as the list filters them (`clip_tags`).
    pub tags: Vec<String>,
    /// Unix milliseconds.
    pub created_at: i64,
    pub updated_at: i64,
}

/// A stored clip: its row and the canonical document, exactly as accepted.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredClip {
    pub meta: ClipMeta,
    pub doc_json: String,
}

/// What a create or replace writes: the document, and what the list
/// filters on, derived from it by the caller (the store parses no document).
#[derive(Debug, Clone, PartialEq)]
pub struct NewClip {
    pub name: String,
    pub doc_json: String,
    pub stats: ClipStats,
    /// Distinct tags (`clip_tags`, indexed by tag).
    pub tags: Vec<String>,
    /// Every joint name of the skeleton (`clip_joints`, indexed by name), for
    /// [`ListQuery::compatible_with`].
    pub joint_names: Vec<String>,
    /// What happens to the clip's mesh (`clip_meshes`), in the same transaction.
    pub mesh: MeshWrite,
}

/// What a create or replace does to the clip's skinned mesh.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum MeshWrite {
    /// No mesh: a create stores none, a replace drops the stored one (a
    /// `PUT`'s document may rename or move the joints it is bound to).
    #[default]
    None,
    /// A replace keeps the stored mesh (a `PATCH`, which cannot change the
    /// skeleton); a create stores none.
    Keep,
    /// Store this one (an import).
    Set(StoredMesh),
}

/// A clip's mesh as stored: the bytes an import wrote (docs/mesh-format.md)
/// and the entity tag they are served with.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredMesh {
    pub etag: String,
    pub bytes: bytes::Bytes,
}

/// A page request: clips with ids after `after`, in id (creation) order,
/// that pass every filter given (`None`: no filter).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ListQuery {
    pub after: Option<String>,
    /// Exactly this name.
    pub name: Option<String>,
    /// Names starting with this (case-sensitive; an index range).
    pub name_prefix: Option<String>,
    /// Names containing this (case-sensitive).
    pub name_contains: Option<String>,
    /// Clips carrying this tag.
    pub tag: Option<String>,
    /// `end - start` at least / at most this many seconds.
    pub min_duration: Option<f64>,
    pub max_duration: Option<f64>,
    /// Clips whose joint names include every joint name of this clip (the
    /// ones a layer of it can be put on); [`StoreError::NotFound`] when the
    /// clip does not exist.
    pub compatible_with: Option<String>,
    pub limit: u32,
}

impl ListQuery {
    /// The cursor and name filters, which every list of named rows has.
    pub fn names(&self) -> NameFilters {
        NameFilters {
            after: self.after.clone(),
            name: self.name.clone(),
            name_prefix: self.name_prefix.clone(),
            name_contains: self.name_contains.clone(),
        }
    }
}

/// The cursor and name filters of a list (clips, characters).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NameFilters {
    pub after: Option<String>,
    /// Exactly this name.
    pub name: Option<String>,
    /// Names starting with this (case-sensitive; an index range).
    pub name_prefix: Option<String>,
    /// Names containing this (case-sensitive).
    pub name_contains: Option<String>,
}

/// What a glTF import wrote: its clips and the characters of its skins.
pub type ImportWritten = (Vec<ClipMeta>, Vec<CharacterMeta>);

/// What a create does when a clip already has the new clip's name (names
/// identify clips: docs/api.md, "Names").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OnName {
    /// Refuse the write ([`StoreError::NameTaken`]).
    #[default]
    Refuse,
    /// Make the write a new version of that clip (same id).
    Replace,
}

/// Why a store operation did not happen. Backend errors carry their cause
/// for the logs; the service never shows it to clients.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("no clip with that id")]
    NotFound,
    #[error("the clip is at version {current}")]
    VersionMismatch { current: u64 },
    /// A create or rename to a name another clip has.
    #[error("a {what} named {name:?} exists ({id})")]
    NameTaken { name: String, id: String, what: &'static str },
    /// A replace by name when several clips (stored before names were
    /// unique) share it: which one is meant cannot be told.
    #[error("several {what}s are named {name:?}")]
    AmbiguousName { name: String, ids: Vec<String>, what: &'static str },
    #[error("the store is unavailable")]
    Unavailable(#[source] Box<dyn std::error::Error + Send + Sync>),
    #[error("the store failed")]
    Backend(#[source] Box<dyn std::error::Error + Send + Sync>),
}

/// Durable clip storage. Implementations are cheap to share (`Arc<dyn _>`).
pub trait ClipStore: Send + Sync + 'static {
    /// Inserts a new clip at version 1 with a fresh id, or (`on_name`:
    /// [`OnName::Replace`]) replaces the clip of that name. Durable on `Ok`.
    ///
    /// # Errors
    /// [`StoreError::NameTaken`], [`StoreError::AmbiguousName`], or a backend failure.
    fn create(&self, clip: NewClip, on_name: OnName) -> BoxFuture<'_, Result<ClipMeta, StoreError>>;

    /// [`ClipStore::create`] for several clips in one transaction (an
    /// imported file's animations): all are stored, or none. Durable on `Ok`.
    ///
    /// # Errors
    /// As [`ClipStore::create`].
    fn create_all(&self, clips: Vec<NewClip>, on_name: OnName) -> BoxFuture<'_, Result<Vec<ClipMeta>, StoreError>>;

    /// The clip and its document, or `None`.
    fn get<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredClip>, StoreError>>;

    /// One page of clips (without documents), at most `query.limit`.
    fn list(&self, query: ListQuery) -> BoxFuture<'_, Result<Vec<ClipMeta>, StoreError>>;

    /// Replaces the document and bumps the version, atomically; with
    /// `expected_version`, only if the clip is at exactly that version.
    ///
    /// # Errors
    /// [`StoreError::NotFound`], [`StoreError::VersionMismatch`] with the
    /// current version, [`StoreError::NameTaken`] for a rename to another
    /// clip's name, or a backend failure.
    fn replace<'a>(
        &'a self,
        id: &'a str,
        clip: NewClip,
        expected_version: Option<u64>,
    ) -> BoxFuture<'a, Result<ClipMeta, StoreError>>;

    /// Deletes a clip; with `expected_version`, only at that version.
    ///
    /// # Errors
    /// As [`ClipStore::replace`].
    fn delete<'a>(&'a self, id: &'a str, expected_version: Option<u64>) -> BoxFuture<'a, Result<(), StoreError>>;

    /// The entity tag of the clip's mesh: `None` when there is no such clip,
    /// `Some(None)` when it has no mesh. One small read, for `304`s.
    fn mesh_tag<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<Option<String>>, StoreError>>;

    /// The clip's mesh, or `None` (no such clip, or no mesh).
    fn mesh<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredMesh>, StoreError>>;

    /// Inserts new documents of `kind` at version 1, or (`on_name`:
    /// [`OnName::Replace`]) replaces those holding their names, all in one
    /// transaction. Durable on `Ok`.
    ///
    /// # Errors
    /// As [`ClipStore::create`].
    fn create_docs(
        &self,
        kind: DocKind,
        docs: Vec<NewDoc>,
        on_name: OnName,
    ) -> BoxFuture<'_, Result<Vec<DocMeta>, StoreError>>;

    /// The document of `kind` and its text, or `None`.
    fn doc<'a>(&'a self, kind: DocKind, id: &'a str) -> BoxFuture<'a, Result<Option<StoredDoc>, StoreError>>;

    /// The document of `kind` that `reference` names: `name:<name>` by its
    /// name, else by id; `None` when none does.
    ///
    /// # Errors
    /// [`StoreError::AmbiguousName`] when several share the name (which the
    /// name rule prevents, but a store is trusted no further than its
    /// schema), or a backend failure.
    fn doc_by_ref<'a>(
        &'a self,
        kind: DocKind,
        reference: &'a str,
    ) -> BoxFuture<'a, Result<Option<StoredDoc>, StoreError>>;

    /// One page of documents of `kind` (without their text), at most `query.limit`.
    fn list_docs(&self, kind: DocKind, query: DocQuery) -> BoxFuture<'_, Result<Vec<DocMeta>, StoreError>>;

    /// Replaces a document (and a character's mesh, as `doc.mesh` says)
    /// and bumps its version; with `expected_version`, only at that version.
    ///
    /// # Errors
    /// As [`ClipStore::replace`].
    fn replace_doc<'a>(
        &'a self,
        kind: DocKind,
        id: &'a str,
        doc: NewDoc,
        expected_version: Option<u64>,
    ) -> BoxFuture<'a, Result<DocMeta, StoreError>>;

    /// Deletes a document (with its mesh); with `expected_version`, only at that version.
    ///
    /// # Errors
    /// As [`ClipStore::delete`].
    fn delete_doc<'a>(
        &'a self,
        kind: DocKind,
        id: &'a str,
        expected_version: Option<u64>,
    ) -> BoxFuture<'a, Result<(), StoreError>>;

    /// [`ClipStore::create_docs`] of characters.
    fn create_characters(
        &self,
        characters: Vec<NewCharacter>,
        on_name: OnName,
    ) -> BoxFuture<'_, Result<Vec<CharacterMeta>, StoreError>> {
        let docs = characters.into_iter().map(NewDoc::from).collect();
        let created = self.create_docs(DocKind::Character, docs, on_name);
        Box::pin(async move { Ok(created.await?.into_iter().map(Into::into).collect()) })
    }

    /// [`ClipStore::create_all`] for a file's clips with the characters of
    /// its skins, in one transaction under one name rule (a glTF import).
    ///
    /// # Errors
    /// As [`ClipStore::create`].
    fn create_clips_and_characters(
        &self,
        clips: Vec<NewClip>,
        characters: Vec<NewCharacter>,
        on_name: OnName,
    ) -> BoxFuture<'_, Result<ImportWritten, StoreError>>;

    /// [`ClipStore::doc`] of a character.
    fn character<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredCharacter>, StoreError>> {
        let read = self.doc(DocKind::Character, id);
        Box::pin(async move { Ok(read.await?.map(Into::into)) })
    }

    /// [`ClipStore::doc_by_ref`] of a character.
    fn character_by_ref<'a>(
        &'a self,
        reference: &'a str,
    ) -> BoxFuture<'a, Result<Option<StoredCharacter>, StoreError>> {
        let read = self.doc_by_ref(DocKind::Character, reference);
        Box::pin(async move { Ok(read.await?.map(Into::into)) })
    }

    /// [`ClipStore::list_docs`] of characters.
    fn list_characters(&self, query: CharacterQuery) -> BoxFuture<'_, Result<Vec<CharacterMeta>, StoreError>> {
        let listed = self.list_docs(DocKind::Character, query);
        Box::pin(async move { Ok(listed.await?.into_iter().map(Into::into).collect()) })
    }

    /// [`ClipStore::replace_doc`] of a character.
    fn replace_character<'a>(
        &'a self,
        id: &'a str,
        character: NewCharacter,
        expected_version: Option<u64>,
    ) -> BoxFuture<'a, Result<CharacterMeta, StoreError>> {
        let replaced = self.replace_doc(DocKind::Character, id, character.into(), expected_version);
        Box::pin(async move { Ok(replaced.await?.into()) })
    }

    /// [`ClipStore::delete_doc`] of a character.
    fn delete_character<'a>(
        &'a self,
        id: &'a str,
        expected_version: Option<u64>,
    ) -> BoxFuture<'a, Result<(), StoreError>> {
        self.delete_doc(DocKind::Character, id, expected_version)
    }

    /// As [`ClipStore::mesh_tag`], for a character.
    fn character_mesh_tag<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<Option<String>>, StoreError>>;

    /// As [`ClipStore::mesh`], for a character.
    fn character_mesh<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredMesh>, StoreError>>;

    /// Stores a new broadcast (`broadcast.controls` empty). Durable on `Ok`.
    fn create_broadcast(&self, broadcast: StoredBroadcast) -> BoxFuture<'_, Result<(), StoreError>>;

    /// Stores a control of broadcast `id`; [`StoreError::NotFound`] if the
    /// broadcast is gone, [`StoreError::Unavailable`] if a checkpoint of
    /// its tick or later is stored (it came too late: the checkpoint does
    /// not hold it). Marks the broadcast active. Durable on `Ok`.
    fn add_broadcast_control<'a>(
        &'a self,
        id: &'a str,
        control: StoredControl,
    ) -> BoxFuture<'a, Result<(), StoreError>>;

    /// Broadcast `id` with its controls, or `None`.
    fn broadcast<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredBroadcast>, StoreError>>;

    /// Every stored broadcast with its controls.
    fn broadcasts(&self) -> BoxFuture<'_, Result<Vec<StoredBroadcast>, StoreError>>;

    /// Deletes broadcast `id` and its controls; returns whether it existed.
    fn delete_broadcast<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<bool, StoreError>>;

    /// Marks broadcast `id` active at `now_ms` (a node has viewers).
    fn touch_broadcast<'a>(&'a self, id: &'a str, now_ms: i64) -> BoxFuture<'a, Result<(), StoreError>>;

    /// Deletes broadcast `id` if it has not been active since `before_ms`;
    /// returns whether it did.
    fn expire_broadcast<'a>(&'a self, id: &'a str, before_ms: i64) -> BoxFuture<'a, Result<bool, StoreError>>;

    /// Stores broadcast `id`'s checkpoint of tick `checkpoint.seq`, deletes
    /// its older checkpoints and its controls stamped at or before it
    /// except `named` (those the checkpoint refers to). `covers` are the
    /// controls the checkpoint's state has applied: it is stored only if
    /// the controls stored since the previous checkpoint (and from
    /// `covers.from`) up to its tick are exactly those, and no checkpoint of that tick or later is
    /// stored (so a node restoring it plays what every node plays).
    /// Returns whether it was stored (not: a mismatch, or the broadcast is
    /// gone).
    fn put_broadcast_checkpoint<'a>(
        &'a self,
        id: &'a str,
        checkpoint: StoredCheckpoint,
        named: &'a [String],
        covers: &'a Covers,
    ) -> BoxFuture<'a, Result<bool, StoreError>>;

    /// Broadcast `id`'s newest checkpoint, or `None`.
    fn broadcast_checkpoint<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredCheckpoint>, StoreError>>;

    /// Succeeds when the store answers a trivial query.
    fn ping(&self) -> BoxFuture<'_, Result<(), StoreError>>;

    /// Closes connections; later calls fail.
    fn close(&self) -> BoxFuture<'_, ()>;
}

/// A fresh clip id: UUIDv7, ordered by creation within this process.
pub fn new_clip_id() -> String {
    uuid::Uuid::now_v7().hyphenated().to_string()
}

/// Whether `s` has the shape of an id this store hands out (used to tell a
/// malformed cursor from an unknown one).
pub fn is_clip_id(s: &str) -> bool {
    uuid::Uuid::try_parse(s).is_ok_and(|u| u.hyphenated().to_string() == s)
}

pub(crate) fn now_millis() -> i64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_millis() as i64)
}

/// A clip row as [`ClipMeta`]: one mapping for both backends, whose schemas
/// share column names and types (`migrations/*/0001_clips.sql`, `0002_clip_index.sql`).
pub(crate) fn meta_from_row<'r, R>(row: &'r R) -> Result<ClipMeta, sqlx::Error>
where
    R: sqlx::Row,
    &'static str: sqlx::ColumnIndex<R>,
    String: sqlx::Decode<'r, R::Database> + sqlx::Type<R::Database>,
    i64: sqlx::Decode<'r, R::Database> + sqlx::Type<R::Database>,
    f64: sqlx::Decode<'r, R::Database> + sqlx::Type<R::Database>,
{
    use std::str::FromStr;
    let playback: String = row.try_get("playback")?;
    let playback: Playback = formats::wire::json::PlaybackDoc::from_str(&playback)
        .map_err(|e| sqlx::Error::Decode(format!("playback column: {e}").into()))?
        .into();
    let tags: String = row.try_get("tags")?;
    let tags = serde_json::from_str(&tags).map_err(|e| sqlx::Error::Decode(format!("tags column: {e}").into()))?;
    let count = |c: &'static str| -> Result<u32, sqlx::Error> { Ok(row.try_get::<i64, _>(c)? as u32) };
    Ok(ClipMeta {
        id: row.try_get("id")?,
        name: row.try_get("name")?,
        version: row.try_get::<i64, _>("version")? as u64,
        stats: ClipStats {
            joints: count("joints")?,
            tracks: count("tracks")?,
            events: count("events")?,
            start: row.try_get::<f64, _>("start_time")? as f32,
            end: row.try_get::<f64, _>("end_time")? as f32,
            playback,
        },
        tags,
        created_at: row.try_get("created_at")?,
        updated_at: row.try_get("updated_at")?,
    })
}
