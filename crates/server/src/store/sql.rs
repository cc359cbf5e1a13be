//! The one [`ClipStore`] implementation, over sqlx, for both backends.
//!
//! The statements are the same for SQLite and PostgreSQL: both take `$n`
//! placeholders (sqlx binds SQLite's `$n` by its number), and the two
//! schemas share table names, column names and types
//! (`migrations/*/0001_clips.sql`). What differs is small and sits in a
//! [`Dialect`]: how a write transaction begins, how a list of strings
//! becomes rows, how the list filters compare names, and which failures are
//! transient (retried with backoff, see `store::retry`). Opening a pool
//! (pragmas, durability checks, migrations) stays with each backend
//! (`sqlite.rs`, `postgres.rs`).
//!
//! Reads and id-keyed inserts are retried after any transient failure (an
//! insert carries its id, so a retry after an attempt that did commit finds
//! its own row); a replace or delete only when the failure proves the
//! statement did not run. Broadcast writes and `ping` are never retried.

use std::fmt::Debug;
use std::future::Future;
use std::time::Instant;

use futures_util::FutureExt;
use futures_util::future::BoxFuture;
use sqlx::migrate::{Migrate, Migrator};
use sqlx::pool::PoolOptions;
use sqlx::{ColumnIndex, Connection, Decode, Encode, Executor, IntoArguments, Pool, Row, Type};

use super::broadcast::Covers;
use super::broadcast::{broadcast_from_row, control_from_row};
use super::dialect::Dialect;
use super::filter::list_query;
use super::retry::{Retry, RetryPolicy, Transience, with_retry};
use super::{
    ClipMeta, ClipStore, DocKind, DocMeta, DocQuery, ImportWritten, ListQuery, MeshWrite, NewCharacter, NewClip,
    NewDoc, OnName, PoolSettings, StoreError, StoredBroadcast, StoredCheckpoint, StoredClip, StoredControl, StoredDoc,
    StoredMesh, meta_from_row, new_clip_id, now_millis,
};

/// The row columns of [`ClipMeta`], as a literal so queries stay `&'static str`.
macro_rules! meta_columns {
    () => {
        "id, name, version, joints, tracks, events, start_time, end_time, playback, tags, created_at, updated_at"
    };
}
#[cfg(test)]
pub(crate) use meta_columns;

/// The row a replace or delete may change, for clips and documents alike:
/// `$1` its id, `$2` the version it must be at, or NULL for any.
macro_rules! at_version {
    () => {
        "WHERE id = $1 AND (CAST($2 AS BIGINT) IS NULL OR version = $2)"
    };
}
pub(super) use at_version;

/// The [`Named`] checks of table `$table`, whose rows are `$what`s.
macro_rules! named {
    ($table:literal, $what:literal) => {
        Named {
            what: $what,
            holders: concat!("SELECT id FROM ", $table, " WHERE name = $1 ORDER BY id LIMIT 8"),
            name_of: concat!("SELECT name FROM ", $table, " WHERE id = $1"),
            version_of: concat!("SELECT version FROM ", $table, " WHERE id = $1"),
        }
    };
}
pub(super) use named;

const INSERT_CLIP: &str = "INSERT INTO clips (id, name, version, doc, joints, tracks, events, start_time, end_time, \
     playback, tags, created_at, updated_at) VALUES ($1, $2, 1, $3, $4, $5, $6, $7, $8, $9, $11, $10, $10)";
const GET_CLIP: &str = concat!("SELECT ", meta_columns!(), ", doc FROM clips WHERE id = $1");
const REPLACE_CLIP: &str = concat!(
    "UPDATE clips SET name = $3, doc = $4, joints = $5, tracks = $6, events = $7, start_time = $8, ",
    "end_time = $9, playback = $10, updated_at = $11, tags = $12, version = version + 1 ",
    at_version!(),
    " RETURNING ",
    meta_columns!()
);
const DELETE_CLIP: &str = concat!("DELETE FROM clips ", at_version!());
/// The name checks of clips.
const CLIPS: Named = named!("clips", "clip");
const CLIP_JOINTS: &str = "SELECT joints FROM clips WHERE id = $1";
/// The clips' meshes.
const CLIP_MESHES: Meshes = Meshes {
    tag: "SELECT m.etag FROM clips c LEFT JOIN clip_meshes m ON m.clip_id = c.id WHERE c.id = $1",
    get: "SELECT etag, bytes FROM clip_meshes WHERE clip_id = $1",
    insert: "INSERT INTO clip_meshes (clip_id, etag, bytes) VALUES ($1, $2, $3)",
    delete: "DELETE FROM clip_meshes WHERE clip_id = $1",
};

const INSERT_BROADCAST: &str = "INSERT INTO broadcasts (id, definition, created_at, active_at) VALUES ($1, $2, $3, $4)";
const INSERT_CONTROL: &str = "INSERT INTO broadcast_controls (id, broadcast_id, seq, control) SELECT $1, $2, $3, $4 \
     WHERE EXISTS (SELECT 1 FROM broadcasts WHERE id = $2)";
const TOUCH_BROADCAST: &str = "UPDATE broadcasts SET active_at = $2 WHERE id = $1 AND active_at < $2";
const DELETE_BROADCAST: &str = "DELETE FROM broadcasts WHERE id = $1";
const EXPIRE_BROADCAST: &str = "DELETE FROM broadcasts WHERE id = $1 AND active_at < $2";
const ALL_BROADCASTS: &str = "SELECT id, definition, created_at FROM broadcasts ORDER BY id";
const ONE_BROADCAST: &str = "SELECT id, definition, created_at FROM broadcasts WHERE id = $1";
const CONTROLS: &str = "SELECT id, seq, control FROM broadcast_controls WHERE broadcast_id = $1 ORDER BY seq, id";
const PUT_CHECKPOINT: &str = "INSERT INTO broadcast_checkpoints (broadcast_id, seq, state) SELECT $1, $2, $3 \
     WHERE EXISTS (SELECT 1 FROM broadcasts WHERE id = $1) \
     ON CONFLICT (broadcast_id, seq) DO UPDATE SET state = excluded.state";
const FORGET_CHECKPOINTS: &str = "DELETE FROM broadcast_checkpoints WHERE broadcast_id = $1 AND seq < $2";
const NEWEST_CHECKPOINT: &str =
    "SELECT seq, state FROM broadcast_checkpoints WHERE broadcast_id = $1 ORDER BY seq DESC LIMIT 1";
const CHECKPOINTS_FROM: &str = "SELECT seq FROM broadcast_checkpoints WHERE broadcast_id = $1 AND seq >= $2 LIMIT 1";
const CHECKPOINTS_BEFORE: &str = "SELECT seq FROM broadcast_checkpoints WHERE broadcast_id = $1 AND seq < $2 \
     ORDER BY seq DESC LIMIT 1";
const CONTROLS_BETWEEN: &str =
    "SELECT id, seq FROM broadcast_controls WHERE broadcast_id = $1 AND seq > $2 AND seq <= $3";

/// What a broadcast's control and checkpoint writes lock (PostgreSQL), so
/// that each sees the other's: a control is never stored for a tick a
/// stored checkpoint has passed, nor a checkpoint without a control stored
/// for its ticks.
fn broadcast_lock(id: &str) -> String {
    format!("broadcast {id}")
}

/// Whether the controls `stored` after the previous checkpoint (`since`)
/// up to a new one's tick `seq` are exactly those it `covers` in that span.
fn same_controls(mut stored: Vec<(String, u64)>, covers: &[(String, u64)], since: i64, seq: i64) -> bool {
    let span = |c: &&(String, u64)| (since + 1..=seq).contains(&(c.1 as i64));
    let mut covered: Vec<(String, u64)> = covers.iter().filter(span).cloned().collect();
    stored.sort();
    covered.sort();
    stored == covered
}

/// The statements that check names in a table of named, versioned rows
/// (clips, characters): names identify rows the same way in each.
pub(super) struct Named {
    /// What a row is, in refusals (`clip`, `character`).
    pub what: &'static str,
    /// `$1` a name: the ids holding it (at most a few: more say nothing more).
    pub holders: &'static str,
    /// `$1` an id: its name.
    pub name_of: &'static str,
    /// `$1` an id: its version.
    pub version_of: &'static str,
}

/// The statements of a table of skinned meshes kept one per row of another
/// (clips, characters), written in that row's transaction.
pub(super) struct Meshes {
    /// `$1` an owner id: the mesh's tag, NULL without a mesh, no row without the owner.
    pub tag: &'static str,
    /// `$1` an owner id: `etag, bytes`.
    pub get: &'static str,
    /// `$1` an owner id, `$2` the tag, `$3` the bytes.
    pub insert: &'static str,
    /// `$1` an owner id.
    pub delete: &'static str,
}

/// What a named write did in its transaction.
pub(super) enum Written<T> {
    Done(T),
    /// An earlier attempt of this very write committed (its own id holds the name).
    Ours,
    Refused(StoreError),
}

impl<T> Written<T> {
    pub(super) fn map<U>(self, f: impl FnOnce(T) -> U) -> Written<U> {
        match self {
            Written::Done(done) => Written::Done(f(done)),
            Written::Ours => Written::Ours,
            Written::Refused(refused) => Written::Refused(refused),
        }
    }
}

/// What a create does with a name, given the ids holding it.
pub(super) enum NameCheck {
    /// No row has it: insert.
    Free,
    /// Our own id has it: an earlier attempt of this write committed.
    Ours,
    /// Make the write a new version of this row.
    Replace(String),
    Refused(StoreError),
}

impl NameCheck {
    /// The one rule of names (docs/api.md, "Names"), for every table.
    pub(super) fn of(table: &Named, holders: &[String], own_id: &str, name: &str, on_name: OnName) -> NameCheck {
        let (name, what) = (name.to_owned(), table.what);
        match (holders, on_name) {
            ([], _) => NameCheck::Free,
            (ids, _) if ids.iter().any(|id| id == own_id) => NameCheck::Ours,
            ([id], OnName::Replace) => NameCheck::Replace(id.clone()),
            ([id, ..], OnName::Refuse) => NameCheck::Refused(StoreError::NameTaken { name, id: id.clone(), what }),
            (ids, _) => NameCheck::Refused(StoreError::AmbiguousName { name, ids: ids.to_vec(), what }),
        }
    }
}

/// A [`ClipStore`] on a sqlx pool of either backend
/// ([`super::sqlite::SqliteStore`], [`super::postgres::PgStore`]).
pub struct SqlStore<DB: Dialect> {
    pub(super) pool: Pool<DB>,
    pub(super) retry: RetryPolicy,
    pub(super) extra: DB::Extra,
}

impl<DB: Dialect> Clone for SqlStore<DB> {
    fn clone(&self) -> Self {
        SqlStore { pool: self.pool.clone(), retry: self.retry, extra: self.extra.clone() }
    }
}

impl<DB: Dialect> Debug for SqlStore<DB> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SqlStore").field("pool", &self.pool).field("extra", &self.extra).finish()
    }
}

impl<DB: Dialect> SqlStore<DB>
where
    DB::Connection: Migrate,
{
    /// Opens a pool whose every connection passes the durability check, and
    /// runs `migrator`. One connection is checked up front, so a refusal
    /// reports its reason (the pool would only time out retrying).
    pub(super) async fn connect(
        options: <DB::Connection as Connection>::Options,
        settings: &PoolSettings,
        migrator: &Migrator,
        extra: impl AsyncFnOnce(&Pool<DB>) -> Result<DB::Extra, sqlx::Error>,
    ) -> anyhow::Result<Self> {
        let durability = settings.durability;
        let mut first = DB::Connection::connect_with(&options).await?;
        DB::check_durability(&mut first, durability).await?;
        first.close().await?;
        let pool = PoolOptions::<DB>::new()
            .max_connections(settings.max_connections.max(1))
            .acquire_timeout(settings.acquire_timeout)
            // The pool drops a connection whose after_connect hook failed.
            .after_connect(move |conn, _| DB::check_durability(conn, durability))
            .connect_with(options)
            .await?;
        migrator.run(&pool).await?;
        let extra = extra(&pool).await?;
        Ok(SqlStore { pool, retry: settings.retry, extra })
    }
}

impl<DB: Dialect> SqlStore<DB> {
    /// The pool, for tests that read settings back from its connections.
    pub fn pool(&self) -> &Pool<DB> {
        &self.pool
    }
}

/// Records an operation's duration and maps its error.
pub(super) fn timed<DB: Dialect, T>(
    op: &'static str,
    started: Instant,
    r: Result<T, sqlx::Error>,
) -> Result<T, StoreError> {
    metrics::histogram!("inbetween_store_operation_duration_seconds", "op" => op)
        .record(started.elapsed().as_secs_f64());
    r.map_err(to_store_error::<DB>)
}

fn to_store_error<DB: Dialect>(e: sqlx::Error) -> StoreError {
    match e {
        sqlx::Error::PoolTimedOut | sqlx::Error::PoolClosed | sqlx::Error::Io(_) => StoreError::Unavailable(e.into()),
        e if DB::classify(&e) != Transience::Permanent => StoreError::Unavailable(e.into()),
        other => StoreError::Backend(other.into()),
    }
}

/// Whether `e` is the primary-key conflict of an insert whose earlier
/// attempt committed (then the row is ours).
pub(super) fn is_own_duplicate<DB: Dialect>(e: &sqlx::Error, attempt: u32) -> bool {
    attempt > 0 && DB::is_clip_id_conflict(e)
}

pub(super) fn new_meta(clip: &NewClip, now: i64) -> ClipMeta {
    ClipMeta {
        id: new_clip_id(),
        name: clip.name.clone(),
        version: 1,
        stats: clip.stats,
        tags: clip.tags.clone(),
        created_at: now,
        updated_at: now,
    }
}

/// A list of strings as the JSON array the `tags` column holds.
fn json_list(items: &[String]) -> String {
    serde_json::Value::from(items).to_string()
}

// The sqlx bounds below say what the generic code needs of `DB`: an
// executor per connection and the column types the schema uses.
impl<DB: Dialect> SqlStore<DB>
where
    for<'c> &'c mut DB::Connection: Executor<'c, Database = DB>,
    DB::Arguments: IntoArguments<DB>,
    for<'q> String: Encode<'q, DB> + Decode<'q, DB> + Type<DB>,
    for<'q> &'q str: Encode<'q, DB> + Type<DB>,
    for<'q> i64: Encode<'q, DB> + Decode<'q, DB> + Type<DB>,
    for<'q> Option<i64>: Encode<'q, DB>,
    for<'q> f64: Encode<'q, DB> + Decode<'q, DB> + Type<DB>,
    for<'q> &'q [u8]: Encode<'q, DB> + Type<DB>,
    for<'q> Vec<u8>: Decode<'q, DB> + Type<DB>,
    &'static str: ColumnIndex<DB::Row>,
    usize: ColumnIndex<DB::Row>,
{
    pub(super) async fn run<T, F, Fut>(&self, op: &'static str, mode: Retry, attempt: F) -> Result<T, StoreError>
    where
        F: FnMut(u32) -> Fut,
        Fut: Future<Output = Result<T, sqlx::Error>>,
    {
        let started = Instant::now();
        let r = with_retry(self.retry, mode, DB::classify, attempt).await;
        timed::<DB, T>(op, started, r)
    }

    /// Inserts the clip row and its index rows (in the caller's transaction).
    async fn insert(db: &mut DB::Connection, meta: &ClipMeta, clip: &NewClip) -> Result<(), sqlx::Error> {
        let s = &meta.stats;
        sqlx::query(INSERT_CLIP)
            .bind(&meta.id)
            .bind(&meta.name)
            .bind(&clip.doc_json)
            .bind(s.joints as i64)
            .bind(s.tracks as i64)
            .bind(s.events as i64)
            .bind(s.start as f64)
            .bind(s.end as f64)
            .bind(s.playback.as_str())
            .bind(meta.created_at)
            .bind(json_list(&clip.tags))
            .execute(&mut *db)
            .await?;
        Self::write_index(db, &meta.id, clip, false).await
    }

    /// The clip's `clip_tags` and `clip_joints` rows (replacing its old ones).
    async fn write_index(db: &mut DB::Connection, id: &str, clip: &NewClip, replace: bool) -> Result<(), sqlx::Error> {
        if replace {
            sqlx::query("DELETE FROM clip_tags WHERE clip_id = $1").bind(id).execute(&mut *db).await?;
            sqlx::query("DELETE FROM clip_joints WHERE clip_id = $1").bind(id).execute(&mut *db).await?;
        }
        sqlx::query(DB::INSERT_TAGS).bind(id).bind(DB::string_list(&clip.tags)).execute(&mut *db).await?;
        sqlx::query(DB::INSERT_JOINTS).bind(id).bind(DB::string_list(&clip.joint_names)).execute(&mut *db).await?;
        Self::write_mesh(db, &CLIP_MESHES, id, &clip.mesh, replace).await
    }

    /// The clip's `clip_meshes` row as [`MeshWrite`] says.
    pub(super) async fn write_mesh(
        db: &mut DB::Connection,
        table: &Meshes,
        id: &str,
        mesh: &MeshWrite,
        replace: bool,
    ) -> Result<(), sqlx::Error> {
        if *mesh == MeshWrite::Keep {
            return Ok(());
        }
        if replace {
            sqlx::query(table.delete).bind(id).execute(&mut *db).await?;
        }
        if let MeshWrite::Set(m) = mesh {
            sqlx::query(table.insert).bind(id).bind(&m.etag).bind(m.bytes.as_ref()).execute(&mut *db).await?;
        }
        Ok(())
    }

    /// The tag of row `id`'s mesh: `None` without the row, `Some(None)` without a mesh.
    pub(super) async fn read_mesh_tag(&self, table: &Meshes, id: &str) -> Result<Option<Option<String>>, StoreError> {
        self.run("mesh_tag", Retry::Always, |_| async move {
            sqlx::query_scalar::<_, Option<String>>(table.tag).bind(id).fetch_optional(&self.pool).await
        })
        .await
    }

    /// Row `id`'s mesh, or `None`.
    pub(super) async fn read_mesh(&self, table: &Meshes, id: &str) -> Result<Option<StoredMesh>, StoreError> {
        self.run("mesh", Retry::Always, |_| async move {
            let row = sqlx::query(table.get).bind(id).fetch_optional(&self.pool).await?;
            row.map(|row| {
                let bytes: Vec<u8> = row.try_get("bytes")?;
                Ok(StoredMesh { etag: row.try_get("etag")?, bytes: bytes.into() })
            })
            .transpose()
        })
        .await
    }

    /// The ids of the rows of `table` named `name` (in the caller's
    /// transaction, after taking the name's lock, so no other write of it
    /// can slip in between).
    pub(super) async fn holders(
        db: &mut DB::Connection,
        table: &Named,
        name: &str,
    ) -> Result<Vec<String>, sqlx::Error> {
        if let Some(lock) = DB::LOCK_NAME {
            sqlx::query(lock).bind(name).execute(&mut *db).await?;
        }
        sqlx::query_scalar(table.holders).bind(name).fetch_all(&mut *db).await
    }

    /// Writes `clips` in the caller's transaction, each a new clip, or the
    /// new version of the one holding its name as `on_name` allows.
    pub(super) async fn write_clips(
        db: &mut DB::Connection,
        metas: &[ClipMeta],
        clips: &[NewClip],
        on_name: OnName,
    ) -> Result<Written<Vec<ClipMeta>>, sqlx::Error> {
        let mut written = Vec::with_capacity(clips.len());
        for (meta, clip) in metas.iter().zip(clips) {
            let ids = Self::holders(db, &CLIPS, &clip.name).await?;
            match NameCheck::of(&CLIPS, &ids, &meta.id, &clip.name, on_name) {
                NameCheck::Free => {
                    Self::insert(db, meta, clip).await?;
                    written.push(meta.clone());
                }
                NameCheck::Ours => return Ok(Written::Ours),
                NameCheck::Replace(id) => {
                    let row = Self::update(db, &id, clip, None, meta.updated_at).await?;
                    written.push(row.ok_or(sqlx::Error::RowNotFound)?);
                }
                NameCheck::Refused(refused) => return Ok(Written::Refused(refused)),
            }
        }
        Ok(Written::Done(written))
    }

    /// Runs `write` in one write transaction, committed when it is done.
    /// An earlier attempt that committed (`attempt` > 0) is recognised by
    /// its own ids, and answered with what it wrote (`earlier`).
    pub(super) async fn in_write<T>(
        &self,
        attempt: u32,
        earlier: impl Fn() -> T,
        write: impl AsyncFnOnce(&mut DB::Connection) -> Result<Written<T>, sqlx::Error>,
    ) -> Result<Result<T, StoreError>, sqlx::Error> {
        let r = async {
            let mut tx = self.pool.begin_with(DB::BEGIN_WRITE).await?;
            match write(&mut tx).await? {
                Written::Done(done) => {
                    tx.commit().await?;
                    Ok(Ok(done))
                }
                Written::Ours => Ok(Ok(earlier())),
                Written::Refused(refused) => {
                    tx.rollback().await?;
                    Ok(Err(refused))
                }
            }
        }
        .await;
        match r {
            Err(e) if is_own_duplicate::<DB>(&e, attempt) => Ok(Ok(earlier())),
            other => other,
        }
    }

    /// The replace statement and the index rows, in the caller's
    /// transaction; `None` when no row matched (no such id, or another version).
    async fn update(
        db: &mut DB::Connection,
        id: &str,
        clip: &NewClip,
        expected_version: Option<u64>,
        now: i64,
    ) -> Result<Option<ClipMeta>, sqlx::Error> {
        let s = clip.stats;
        let row = sqlx::query(REPLACE_CLIP)
            .bind(id)
            .bind(expected_version.map(|v| v as i64))
            .bind(&clip.name)
            .bind(&clip.doc_json)
            .bind(s.joints as i64)
            .bind(s.tracks as i64)
            .bind(s.events as i64)
            .bind(s.start as f64)
            .bind(s.end as f64)
            .bind(s.playback.as_str())
            .bind(now)
            .bind(json_list(&clip.tags))
            .fetch_optional(&mut *db)
            .await?;
        let Some(row) = row else { return Ok(None) };
        let meta = meta_from_row(&row)?;
        Self::write_index(db, id, clip, true).await?;
        Ok(Some(meta))
    }

    /// Whether row `id` of `table` may take `name`: it has it already (clips
    /// stored before names were unique keep their shared names), or no other row has it.
    pub(super) async fn rename_refused(
        db: &mut DB::Connection,
        table: &Named,
        id: &str,
        name: &str,
    ) -> Result<Option<StoreError>, sqlx::Error> {
        let current: Option<String> = sqlx::query_scalar(table.name_of).bind(id).fetch_optional(&mut *db).await?;
        if current.is_none_or(|c| c == name) {
            return Ok(None);
        }
        let others = Self::holders(db, table, name).await?;
        Ok(others.into_iter().find(|other| other != id).map(|other| StoreError::NameTaken {
            name: name.to_owned(),
            id: other,
            what: table.what,
        }))
    }

    /// Tells "not found" from "version mismatch" after a conditional write matched no row.
    pub(super) async fn missed(&self, table: &Named, id: &str) -> Result<StoreError, sqlx::Error> {
        let version: Option<i64> = sqlx::query_scalar(table.version_of).bind(id).fetch_optional(&self.pool).await?;
        Ok(match version {
            None => StoreError::NotFound,
            Some(current) => StoreError::VersionMismatch { current: current as u64 },
        })
    }

    /// Broadcast `id`'s controls in application order.
    async fn controls_of(&self, id: &str) -> Result<Vec<StoredControl>, sqlx::Error> {
        let rows = sqlx::query(CONTROLS).bind(id).fetch_all(&self.pool).await?;
        rows.iter().map(control_from_row).collect()
    }
}

impl<DB: Dialect> ClipStore for SqlStore<DB>
where
    for<'c> &'c mut DB::Connection: Executor<'c, Database = DB>,
    DB::Arguments: IntoArguments<DB>,
    for<'q> String: Encode<'q, DB> + Decode<'q, DB> + Type<DB>,
    for<'q> &'q str: Encode<'q, DB> + Type<DB>,
    for<'q> i64: Encode<'q, DB> + Decode<'q, DB> + Type<DB>,
    for<'q> Option<i64>: Encode<'q, DB>,
    for<'q> f64: Encode<'q, DB> + Decode<'q, DB> + Type<DB>,
    for<'q> &'q [u8]: Encode<'q, DB> + Type<DB>,
    for<'q> Vec<u8>: Decode<'q, DB> + Type<DB>,
    &'static str: ColumnIndex<DB::Row>,
    usize: ColumnIndex<DB::Row>,
{
    fn create(&self, clip: NewClip, on_name: OnName) -> BoxFuture<'_, Result<ClipMeta, StoreError>> {
        async move {
            let mut metas = self.create_all(vec![clip], on_name).await?;
            metas.pop().ok_or_else(|| StoreError::Backend("a create wrote no row".into()))
        }
        .boxed()
    }

    fn create_all(&self, clips: Vec<NewClip>, on_name: OnName) -> BoxFuture<'_, Result<Vec<ClipMeta>, StoreError>> {
        async move {
            let now = now_millis();
            let metas: Vec<ClipMeta> = clips.iter().map(|c| new_meta(c, now)).collect();
            // A replace must not run twice: retried only when it surely did not run.
            let mode = if on_name == OnName::Replace { Retry::IfNotExecuted } else { Retry::Always };
            self.run("create_all", mode, |n| {
                self.in_write(n, || metas.clone(), async |db| Self::write_clips(db, &metas, &clips, on_name).await)
            })
            .await?
        }
        .boxed()
    }

    fn get<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredClip>, StoreError>> {
        async move {
            self.run("get", Retry::Always, |_| async move {
                let row = sqlx::query(GET_CLIP).bind(id).fetch_optional(&self.pool).await?;
                row.map(|row| Ok(StoredClip { meta: meta_from_row(&row)?, doc_json: row.try_get("doc")? })).transpose()
            })
            .await
        }
        .boxed()
    }

    fn list(&self, query: ListQuery) -> BoxFuture<'_, Result<Vec<ClipMeta>, StoreError>> {
        async move {
            let query = &query;
            self.run("list", Retry::Always, |_| async move {
                let reference = match &query.compatible_with {
                    None => None,
                    Some(id) => match sqlx::query_scalar(CLIP_JOINTS).bind(id).fetch_optional(&self.pool).await? {
                        Some(n) => Some(n),
                        None => return Ok(Err(StoreError::NotFound)),
                    },
                };
                let mut qb = list_query::<DB>(meta_columns!(), query, reference);
                let rows = qb.build().fetch_all(&self.pool).await?;
                rows.iter().map(meta_from_row).collect::<Result<Vec<_>, _>>().map(Ok)
            })
            .await?
        }
        .boxed()
    }

    fn replace<'a>(
        &'a self,
        id: &'a str,
        clip: NewClip,
        expected_version: Option<u64>,
    ) -> BoxFuture<'a, Result<ClipMeta, StoreError>> {
        async move {
            let clip = &clip;
            let now = now_millis();
            self.run("replace", Retry::IfNotExecuted, |_| async move {
                let mut tx = self.pool.begin_with(DB::BEGIN_WRITE).await?;
                if let Some(refused) = Self::rename_refused(&mut tx, &CLIPS, id, &clip.name).await? {
                    tx.rollback().await?;
                    return Ok(Err(refused));
                }
                let Some(meta) = Self::update(&mut tx, id, clip, expected_version, now).await? else {
                    tx.rollback().await?;
                    return self.missed(&CLIPS, id).await.map(Err);
                };
                tx.commit().await?;
                Ok(Ok(meta))
            })
            .await?
        }
        .boxed()
    }

    fn delete<'a>(&'a self, id: &'a str, expected_version: Option<u64>) -> BoxFuture<'a, Result<(), StoreError>> {
        async move {
            self.run("delete", Retry::IfNotExecuted, |_| async move {
                let done = sqlx::query(DELETE_CLIP)
                    .bind(id)
                    .bind(expected_version.map(|v| v as i64))
                    .execute(&self.pool)
                    .await?;
                if DB::rows_affected(&done) == 1 { Ok(Ok(())) } else { self.missed(&CLIPS, id).await.map(Err) }
            })
            .await?
        }
        .boxed()
    }

    fn mesh_tag<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<Option<String>>, StoreError>> {
        self.read_mesh_tag(&CLIP_MESHES, id).boxed()
    }

    fn mesh<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredMesh>, StoreError>> {
        self.read_mesh(&CLIP_MESHES, id).boxed()
    }

    fn create_docs(
        &self,
        kind: DocKind,
        docs: Vec<NewDoc>,
        on_name: OnName,
    ) -> BoxFuture<'_, Result<Vec<DocMeta>, StoreError>> {
        self.create_docs_now(kind, docs, on_name).boxed()
    }

    fn doc<'a>(&'a self, kind: DocKind, id: &'a str) -> BoxFuture<'a, Result<Option<StoredDoc>, StoreError>> {
        self.doc_now(kind, id).boxed()
    }

    fn doc_by_ref<'a>(
        &'a self,
        kind: DocKind,
        reference: &'a str,
    ) -> BoxFuture<'a, Result<Option<StoredDoc>, StoreError>> {
        self.doc_by_ref_now(kind, reference).boxed()
    }

    fn list_docs(&self, kind: DocKind, query: DocQuery) -> BoxFuture<'_, Result<Vec<DocMeta>, StoreError>> {
        self.list_docs_now(kind, query).boxed()
    }

    fn replace_doc<'a>(
        &'a self,
        kind: DocKind,
        id: &'a str,
        doc: NewDoc,
        expected_version: Option<u64>,
    ) -> BoxFuture<'a, Result<DocMeta, StoreError>> {
        self.replace_doc_now(kind, id, doc, expected_version).boxed()
    }

    fn delete_doc<'a>(
        &'a self,
        kind: DocKind,
        id: &'a str,
        expected_version: Option<u64>,
    ) -> BoxFuture<'a, Result<(), StoreError>> {
        self.delete_doc_now(kind, id, expected_version).boxed()
    }

    fn create_clips_and_characters(
        &self,
        clips: Vec<NewClip>,
        characters: Vec<NewCharacter>,
        on_name: OnName,
    ) -> BoxFuture<'_, Result<ImportWritten, StoreError>> {
        self.create_import_now(clips, characters, on_name).boxed()
    }

    fn character_mesh_tag<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<Option<String>>, StoreError>> {
        self.character_mesh_tag_now(id).boxed()
    }

    fn character_mesh<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredMesh>, StoreError>> {
        self.character_mesh_now(id).boxed()
    }

    fn create_broadcast(&self, broadcast: StoredBroadcast) -> BoxFuture<'_, Result<(), StoreError>> {
        async move {
            let started = Instant::now();
            let r = sqlx::query(INSERT_BROADCAST)
                .bind(&broadcast.id)
                .bind(&broadcast.definition)
                .bind(broadcast.created_at)
                .bind(now_millis())
                .execute(&self.pool)
                .await
                .map(|_| ());
            timed::<DB, _>("create_broadcast", started, r)
        }
        .boxed()
    }

    fn add_broadcast_control<'a>(
        &'a self,
        id: &'a str,
        control: StoredControl,
    ) -> BoxFuture<'a, Result<(), StoreError>> {
        async move {
            let started = Instant::now();
            let r = async {
                let mut tx = self.pool.begin_with(DB::BEGIN_WRITE).await?;
                if let Some(lock) = DB::LOCK_NAME {
                    sqlx::query(lock).bind(broadcast_lock(id)).execute(&mut *tx).await?;
                }
                // A checkpoint of its tick or later is stored without it: too late to play everywhere.
                let later = sqlx::query(CHECKPOINTS_FROM).bind(id).bind(control.seq as i64);
                if later.fetch_optional(&mut *tx).await?.is_some() {
                    return Ok(None);
                }
                let done = sqlx::query(INSERT_CONTROL)
                    .bind(&control.id)
                    .bind(id)
                    .bind(control.seq as i64)
                    .bind(&control.control)
                    .execute(&mut *tx)
                    .await?;
                sqlx::query(TOUCH_BROADCAST).bind(id).bind(now_millis()).execute(&mut *tx).await?;
                tx.commit().await?;
                Ok(Some(DB::rows_affected(&done) == 1))
            }
            .await;
            match timed::<DB, _>("add_broadcast_control", started, r)? {
                Some(true) => Ok(()),
                Some(false) => Err(StoreError::NotFound),
                None => Err(StoreError::Unavailable(
                    "a checkpoint of the control's tick was stored first: it came too late to be played on every node"
                        .into(),
                )),
            }
        }
        .boxed()
    }

    fn broadcast<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredBroadcast>, StoreError>> {
        async move {
            let started = Instant::now();
            let r = async {
                let Some(row) = sqlx::query(ONE_BROADCAST).bind(id).fetch_optional(&self.pool).await? else {
                    return Ok(None);
                };
                let mut b = broadcast_from_row(&row)?;
                b.controls = self.controls_of(&b.id).await?;
                Ok(Some(b))
            }
            .await;
            timed::<DB, _>("broadcast", started, r)
        }
        .boxed()
    }

    fn broadcasts(&self) -> BoxFuture<'_, Result<Vec<StoredBroadcast>, StoreError>> {
        async move {
            let started = Instant::now();
            let r = async {
                let rows = sqlx::query(ALL_BROADCASTS).fetch_all(&self.pool).await?;
                let mut all = Vec::with_capacity(rows.len());
                for row in &rows {
                    let mut b = broadcast_from_row(row)?;
                    b.controls = self.controls_of(&b.id).await?;
                    all.push(b);
                }
                Ok(all)
            }
            .await;
            timed::<DB, _>("broadcasts", started, r)
        }
        .boxed()
    }

    fn delete_broadcast<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<bool, StoreError>> {
        async move {
            let started = Instant::now();
            let r = sqlx::query(DELETE_BROADCAST).bind(id).execute(&self.pool).await;
            timed::<DB, _>("delete_broadcast", started, r.map(|d| DB::rows_affected(&d) == 1))
        }
        .boxed()
    }

    fn touch_broadcast<'a>(&'a self, id: &'a str, now_ms: i64) -> BoxFuture<'a, Result<(), StoreError>> {
        async move {
            let started = Instant::now();
            let r = sqlx::query(TOUCH_BROADCAST).bind(id).bind(now_ms).execute(&self.pool).await.map(|_| ());
            timed::<DB, _>("touch_broadcast", started, r)
        }
        .boxed()
    }

    fn expire_broadcast<'a>(&'a self, id: &'a str, before_ms: i64) -> BoxFuture<'a, Result<bool, StoreError>> {
        async move {
            let started = Instant::now();
            let r = sqlx::query(EXPIRE_BROADCAST).bind(id).bind(before_ms).execute(&self.pool).await;
            timed::<DB, _>("expire_broadcast", started, r.map(|d| DB::rows_affected(&d) == 1))
        }
        .boxed()
    }

    fn put_broadcast_checkpoint<'a>(
        &'a self,
        id: &'a str,
        checkpoint: StoredCheckpoint,
        named: &'a [String],
        covers: &'a Covers,
    ) -> BoxFuture<'a, Result<bool, StoreError>> {
        async move {
            let started = Instant::now();
            let seq = checkpoint.seq as i64;
            let r = async {
                let mut tx = self.pool.begin_with(DB::BEGIN_WRITE).await?;
                if let Some(lock) = DB::LOCK_NAME {
                    sqlx::query(lock).bind(broadcast_lock(id)).execute(&mut *tx).await?;
                }
                // The first checkpoint of a tick stored stays: it was checked as this one is.
                if sqlx::query(CHECKPOINTS_FROM).bind(id).bind(seq).fetch_optional(&mut *tx).await?.is_some() {
                    return Ok(false);
                }
                let before = sqlx::query(CHECKPOINTS_BEFORE).bind(id).bind(seq).fetch_optional(&mut *tx).await?;
                let previous = match before {
                    Some(row) => row.try_get::<i64, _>("seq")?,
                    None => -1,
                };
                // Before `from` the node has let its controls go: it vouches from there on.
                let since = previous.max(covers.from as i64 - 1);
                let rows = sqlx::query(CONTROLS_BETWEEN).bind(id).bind(since).bind(seq).fetch_all(&mut *tx).await?;
                let mut stored = Vec::with_capacity(rows.len());
                for row in &rows {
                    stored.push((row.try_get::<String, _>("id")?, row.try_get::<i64, _>("seq")?.max(0) as u64));
                }
                if !same_controls(stored, &covers.controls, since, seq) {
                    return Ok(false);
                }
                let put = sqlx::query(PUT_CHECKPOINT).bind(id).bind(seq).bind(&checkpoint.state);
                if DB::rows_affected(&put.execute(&mut *tx).await?) == 0 {
                    return Ok(false);
                }
                sqlx::query(FORGET_CHECKPOINTS).bind(id).bind(seq).execute(&mut *tx).await?;
                let forget = sqlx::query(DB::FORGET_CONTROLS).bind(id).bind(seq).bind(DB::string_list(named));
                forget.execute(&mut *tx).await?;
                tx.commit().await?;
                Ok(true)
            }
            .await;
            timed::<DB, _>("put_broadcast_checkpoint", started, r)
        }
        .boxed()
    }

    fn broadcast_checkpoint<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredCheckpoint>, StoreError>> {
        async move {
            self.run("broadcast_checkpoint", Retry::Always, |_| async move {
                let row = sqlx::query(NEWEST_CHECKPOINT).bind(id).fetch_optional(&self.pool).await?;
                row.map(|row| {
                    let seq: i64 = row.try_get("seq")?;
                    Ok(StoredCheckpoint { seq: seq.max(0) as u64, state: row.try_get("state")? })
                })
                .transpose()
            })
            .await
        }
        .boxed()
    }

    fn ping(&self) -> BoxFuture<'_, Result<(), StoreError>> {
        async move {
            let started = Instant::now();
            // No retry: readiness must report the database as it is now.
            let r = sqlx::query("SELECT 1").execute(&self.pool).await.map(|_| ());
            timed::<DB, _>("ping", started, r)
        }
        .boxed()
    }

    fn close(&self) -> BoxFuture<'_, ()> {
        self.pool.close().boxed()
    }
}
