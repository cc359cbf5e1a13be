//! The embedded store: SQLite through sqlx, one file in the data directory.
//!
//! Durability is set per connection, on every connection the pool opens
//! (`SqliteConnectOptions` applies its pragmas at connect time), and read
//! back in the pool's `after_connect` hook: a connection that does not
//! report `journal_mode=wal` and `synchronous` FULL or EXTRA (an in-memory
//! database, a filesystem without WAL support) fails to open, so the
//! server refuses to start, unless `--unsafe-fast-writes` was given (which
//! also relaxes `synchronous` to NORMAL):
//! `journal_mode=WAL` so readers never block the writer, `synchronous=FULL`
//! so a commit is on disk (WAL fsync) before the statement returns, which is
//! what lets the service promise that a `201` survives `kill -9` and power
//! loss; `foreign_keys=ON` and a `busy_timeout` so concurrent writers wait
//! for the lock instead of failing.
//!
//! A delete is a single statement (its `clip_tags` and `clip_joints` rows go
//! by cascade). A create or replace writes the clip row and its index rows
//! in one transaction opened with `BEGIN IMMEDIATE`, which takes the write
//! lock before anything is read: no transaction ever upgrades a read lock
//! (which in WAL mode fails with `SQLITE_BUSY` instead of waiting).

use std::path::Path;
use std::str::FromStr;
use std::time::{Duration, Instant};

use anyhow::Context;
use futures_util::FutureExt;
use futures_util::future::BoxFuture;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteSynchronous};
use sqlx::{Connection, Row, migrate::Migrator};

use super::broadcast::{broadcast_from_row, broadcast_methods, control_from_row, lite as bsql};
use super::filter::{SQLITE, list_query};
use super::{
    ClipMeta, ClipStore, Durability, ListQuery, MeshWrite, NewClip, PoolSettings, StoreError, StoredClip, StoredMesh,
    new_clip_id, now_millis,
};
use super::{StoredBroadcast, StoredControl};

static MIGRATOR: Migrator = sqlx::migrate!("./migrations/sqlite");

/// The row columns of [`ClipMeta`], as a literal so queries stay `&'static str`.
macro_rules! meta_columns {
    () => {
        "id, name, version, joints, tracks, events, start_time, end_time, playback, tags, created_at, updated_at"
    };
}

/// A SQLite-backed [`ClipStore`].
#[derive(Debug, Clone)]
pub struct SqliteStore {
    pool: SqlitePool,
}

impl SqliteStore {
    /// Opens (creating if missing) the database file at `path`, applies the
    /// durability pragmas and runs migrations.
    ///
    /// # Errors
    /// The file cannot be opened or created, or a migration fails.
    pub async fn open(path: &Path, settings: &PoolSettings) -> anyhow::Result<Self> {
        let options = SqliteConnectOptions::new().filename(path).create_if_missing(true);
        Self::open_with(options, settings).await
    }

    /// Opens a `sqlite:` URL (e.g. `sqlite://data/inbetween.db`), creating
    /// the file's directory if missing, as `--data-dir` does.
    ///
    /// # Errors
    /// As [`SqliteStore::open`], or the URL does not parse.
    pub async fn open_url(url: &str, settings: &PoolSettings) -> anyhow::Result<Self> {
        let options = SqliteConnectOptions::from_str(url)?.create_if_missing(true);
        if let Some(dir) = options.get_filename().parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
        Self::open_with(options, settings).await
    }

    async fn open_with(options: SqliteConnectOptions, settings: &PoolSettings) -> anyhow::Result<Self> {
        let durability = settings.durability;
        let synchronous = match durability {
            Durability::Required => SqliteSynchronous::Full,
            Durability::UnsafeFast => SqliteSynchronous::Normal,
        };
        let options = options
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(synchronous)
            .foreign_keys(true)
            .busy_timeout(Duration::from_secs(10));
        // One connection checked up front, so a refusal reports its reason
        // (the pool would only time out retrying).
        let mut first = sqlx::SqliteConnection::connect_with(&options).await?;
        check_durability(&mut first, durability).await?;
        first.close().await?;
        let pool = SqlitePoolOptions::new()
            .max_connections(settings.max_connections.max(1))
            .acquire_timeout(settings.acquire_timeout)
            .after_connect(move |conn, _| Box::pin(async move { check_durability(conn, durability).await }))
            .connect_with(options)
            .await?;
        MIGRATOR.run(&pool).await?;
        Ok(SqliteStore { pool })
    }

    /// The pool, for tests that read settings back from its connections.
    pub fn pool(&self) -> &SqlitePool {
        &self.pool
    }
}

/// Refuses a connection whose commits would not be on disk when they return.
async fn check_durability(conn: &mut sqlx::SqliteConnection, durability: Durability) -> Result<(), sqlx::Error> {
    let journal: String = sqlx::query_scalar("PRAGMA journal_mode").fetch_one(&mut *conn).await?;
    let synchronous: i64 = sqlx::query_scalar("PRAGMA synchronous").fetch_one(&mut *conn).await?;
    // 2 = FULL, 3 = EXTRA.
    if journal.eq_ignore_ascii_case("wal") && synchronous >= 2 {
        return Ok(());
    }
    let found = format!("journal_mode={journal}, synchronous={synchronous}");
    match durability {
        Durability::Required => Err(sqlx::Error::Configuration(
            format!(
                "SQLite is not durable ({found}; want journal_mode=wal, synchronous=2 (FULL)): a committed clip \
                 could be lost in a crash. Use a file on a local disk, or start with --unsafe-fast-writes"
            )
            .into(),
        )),
        Durability::UnsafeFast => {
            if !journal.eq_ignore_ascii_case("wal") {
                tracing::warn!(%found, "unsafe fast writes: SQLite is not in WAL mode");
            }
            Ok(())
        }
    }
}

fn timed<T>(op: &'static str, started: Instant, r: Result<T, sqlx::Error>) -> Result<T, StoreError> {
    metrics::histogram!("inbetween_store_operation_duration_seconds", "op" => op)
        .record(started.elapsed().as_secs_f64());
    r.map_err(|e| match e {
        sqlx::Error::PoolTimedOut | sqlx::Error::PoolClosed | sqlx::Error::Io(_) => StoreError::Unavailable(e.into()),
        other => StoreError::Backend(other.into()),
    })
}

/// Inserts one new clip at version 1 with a fresh id, and its index rows.
async fn insert(db: &mut sqlx::SqliteConnection, clip: NewClip) -> Result<ClipMeta, sqlx::Error> {
    let now = now_millis();
    let meta = ClipMeta {
        id: new_clip_id(),
        name: clip.name.clone(),
        version: 1,
        stats: clip.stats,
        tags: clip.tags.clone(),
        created_at: now,
        updated_at: now,
    };
    let s = &meta.stats;
    sqlx::query(
        "INSERT INTO clips (id, name, version, doc, joints, tracks, events, start_time, end_time, playback, \
         tags, created_at, updated_at) VALUES (?1, ?2, 1, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?11, ?10, ?10)",
    )
    .bind(&meta.id)
    .bind(&meta.name)
    .bind(&clip.doc_json)
    .bind(s.joints as i64)
    .bind(s.tracks as i64)
    .bind(s.events as i64)
    .bind(s.start as f64)
    .bind(s.end as f64)
    .bind(s.playback.as_str())
    .bind(now)
    .bind(json_list(&clip.tags))
    .execute(&mut *db)
    .await?;
    write_index(db, &meta.id, &clip, false).await?;
    Ok(meta)
}

/// A list of strings as the JSON array `json_each` reads.
fn json_list(items: &[String]) -> String {
    serde_json::Value::from(items).to_string()
}

/// The clip's `clip_tags` and `clip_joints` rows (replacing its old ones).
async fn write_index(
    db: &mut sqlx::SqliteConnection,
    id: &str,
    clip: &NewClip,
    replace: bool,
) -> Result<(), sqlx::Error> {
    if replace {
        sqlx::query("DELETE FROM clip_tags WHERE clip_id = ?1").bind(id).execute(&mut *db).await?;
        sqlx::query("DELETE FROM clip_joints WHERE clip_id = ?1").bind(id).execute(&mut *db).await?;
    }
    sqlx::query("INSERT INTO clip_tags (clip_id, tag) SELECT DISTINCT ?1, value FROM json_each(?2)")
        .bind(id)
        .bind(json_list(&clip.tags))
        .execute(&mut *db)
        .await?;
    sqlx::query("INSERT INTO clip_joints (clip_id, joint) SELECT DISTINCT ?1, value FROM json_each(?2)")
        .bind(id)
        .bind(json_list(&clip.joint_names))
        .execute(&mut *db)
        .await?;
    write_mesh(db, id, &clip.mesh, replace).await
}

/// The clip's `clip_meshes` row as [`MeshWrite`] says.
async fn write_mesh(
    db: &mut sqlx::SqliteConnection,
    id: &str,
    mesh: &MeshWrite,
    replace: bool,
) -> Result<(), sqlx::Error> {
    if *mesh == MeshWrite::Keep {
        return Ok(());
    }
    if replace {
        sqlx::query("DELETE FROM clip_meshes WHERE clip_id = ?1").bind(id).execute(&mut *db).await?;
    }
    if let MeshWrite::Set(m) = mesh {
        sqlx::query("INSERT INTO clip_meshes (clip_id, etag, bytes) VALUES (?1, ?2, ?3)")
            .bind(id)
            .bind(&m.etag)
            .bind(m.bytes.as_ref())
            .execute(&mut *db)
            .await?;
    }
    Ok(())
}

/// A write transaction that holds the write lock from its first statement.
const BEGIN_WRITE: &str = "BEGIN IMMEDIATE";

impl SqliteStore {
    /// The current version of `id`, for telling "not found" from "version
    /// mismatch" after a conditional write matched no row.
    async fn current_version(&self, id: &str) -> Result<Option<u64>, sqlx::Error> {
        let row = sqlx::query("SELECT version FROM clips WHERE id = ?1").bind(id).fetch_optional(&self.pool).await?;
        row.map(|r| r.try_get::<i64, _>(0).map(|v| v as u64)).transpose()
    }

    /// The joint count of `id`, if it exists (the reference of `compatible_with`).
    async fn joint_count(&self, id: &str) -> Result<Option<i64>, sqlx::Error> {
        sqlx::query_scalar("SELECT joints FROM clips WHERE id = ?1").bind(id).fetch_optional(&self.pool).await
    }

    async fn missed(&self, id: &str) -> Result<StoreError, sqlx::Error> {
        Ok(match self.current_version(id).await? {
            None => StoreError::NotFound,
            Some(current) => StoreError::VersionMismatch { current },
        })
    }
}

impl SqliteStore {
    /// Broadcast `id`'s controls in application order.
    async fn controls_of(&self, id: &str) -> Result<Vec<StoredControl>, sqlx::Error> {
        let rows = sqlx::query(bsql::CONTROLS).bind(id).fetch_all(&self.pool).await?;
        rows.iter().map(control_from_row).collect()
    }
}

impl ClipStore for SqliteStore {
    broadcast_methods!(bsql);

    fn create(&self, clip: NewClip) -> BoxFuture<'_, Result<ClipMeta, StoreError>> {
        async move {
            let started = Instant::now();
            let r = async {
                let mut tx = self.pool.begin_with(BEGIN_WRITE).await?;
                let meta = insert(&mut tx, clip).await?;
                tx.commit().await?;
                Ok(meta)
            }
            .await;
            timed("create", started, r)
        }
        .boxed()
    }

    fn create_all(&self, clips: Vec<NewClip>) -> BoxFuture<'_, Result<Vec<ClipMeta>, StoreError>> {
        async move {
            let started = Instant::now();
            let r = async {
                let mut tx = self.pool.begin_with(BEGIN_WRITE).await?;
                let mut metas = Vec::with_capacity(clips.len());
                for clip in clips {
                    metas.push(insert(&mut tx, clip).await?);
                }
                tx.commit().await?;
                Ok(metas)
            }
            .await;
            timed("create_all", started, r)
        }
        .boxed()
    }

    fn get<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredClip>, StoreError>> {
        async move {
            let started = Instant::now();
            let r = async {
                let sql = concat!("SELECT ", meta_columns!(), ", doc FROM clips WHERE id = ?1");
                let row = sqlx::query(sql).bind(id).fetch_optional(&self.pool).await?;
                row.map(|row| Ok(StoredClip { meta: super::meta_from_row(&row)?, doc_json: row.try_get("doc")? }))
                    .transpose()
            }
            .await;
            timed("get", started, r)
        }
        .boxed()
    }

    fn list(&self, query: ListQuery) -> BoxFuture<'_, Result<Vec<ClipMeta>, StoreError>> {
        async move {
            let started = Instant::now();
            let r = async {
                let reference = match &query.compatible_with {
                    None => None,
                    Some(id) => match self.joint_count(id).await? {
                        Some(n) => Some(n),
                        None => return Ok(Err(StoreError::NotFound)),
                    },
                };
                let mut qb = list_query(meta_columns!(), &query, reference, SQLITE);
                let rows = qb.build().fetch_all(&self.pool).await?;
                rows.iter().map(super::meta_from_row).collect::<Result<_, _>>().map(Ok)
            }
            .await;
            timed("list", started, r)?
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
            let started = Instant::now();
            let s = clip.stats;
            let sql = concat!(
                "UPDATE clips SET name = ?3, doc = ?4, joints = ?5, tracks = ?6, events = ?7, start_time = ?8, ",
                "end_time = ?9, playback = ?10, updated_at = ?11, tags = ?12, version = version + 1 ",
                "WHERE id = ?1 AND (?2 IS NULL OR version = ?2) RETURNING ",
                meta_columns!()
            );
            let r = async {
                let mut tx = self.pool.begin_with(BEGIN_WRITE).await?;
                let row = sqlx::query(sql)
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
                    .bind(now_millis())
                    .bind(json_list(&clip.tags))
                    .fetch_optional(&mut *tx)
                    .await?;
                let Some(row) = row else {
                    tx.rollback().await?;
                    return self.missed(id).await.map(Err);
                };
                let meta = super::meta_from_row(&row)?;
                write_index(&mut tx, id, &clip, true).await?;
                tx.commit().await?;
                Ok(Ok(meta))
            }
            .await;
            timed("replace", started, r)?
        }
        .boxed()
    }

    fn delete<'a>(&'a self, id: &'a str, expected_version: Option<u64>) -> BoxFuture<'a, Result<(), StoreError>> {
        async move {
            let started = Instant::now();
            let r = sqlx::query("DELETE FROM clips WHERE id = ?1 AND (?2 IS NULL OR version = ?2)")
                .bind(id)
                .bind(expected_version.map(|v| v as i64))
                .execute(&self.pool)
                .await;
            let r = match r {
                Ok(done) if done.rows_affected() == 1 => Ok(Ok(())),
                Ok(_) => self.missed(id).await.map(Err),
                Err(e) => Err(e),
            };
            timed("delete", started, r)?
        }
        .boxed()
    }

    fn mesh_tag<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<Option<String>>, StoreError>> {
        async move {
            let started = Instant::now();
            let sql = "SELECT m.etag FROM clips c LEFT JOIN clip_meshes m ON m.clip_id = c.id WHERE c.id = ?1";
            let r = sqlx::query_scalar::<_, Option<String>>(sql).bind(id).fetch_optional(&self.pool).await;
            timed("mesh_tag", started, r)
        }
        .boxed()
    }

    fn mesh<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredMesh>, StoreError>> {
        async move {
            let started = Instant::now();
            let r = async {
                let row = sqlx::query("SELECT etag, bytes FROM clip_meshes WHERE clip_id = ?1")
                    .bind(id)
                    .fetch_optional(&self.pool)
                    .await?;
                row.map(|row| {
                    let bytes: Vec<u8> = row.try_get("bytes")?;
                    Ok(StoredMesh { etag: row.try_get("etag")?, bytes: bytes.into() })
                })
                .transpose()
            }
            .await;
            timed("mesh", started, r)
        }
        .boxed()
    }

    fn ping(&self) -> BoxFuture<'_, Result<(), StoreError>> {
        async move {
            let started = Instant::now();
            let r = sqlx::query("SELECT 1").execute(&self.pool).await.map(|_| ());
            timed("ping", started, r)
        }
        .boxed()
    }

    fn close(&self) -> BoxFuture<'_, ()> {
        self.pool.close().boxed()
    }
}

#[cfg(test)]
mod tests {
    use super::{SQLITE, SqliteStore, list_query};
    use crate::store::{ListQuery, PoolSettings};

    /// SQLite's plan of the list for `query`, one line per step.
    async fn plan(store: &SqliteStore, query: &ListQuery) -> String {
        let qb = list_query::<sqlx::Sqlite>(meta_columns!(), query, Some(3), SQLITE);
        let sql = sqlx::AssertSqlSafe(format!("EXPLAIN QUERY PLAN {}", qb.sql().as_str()));
        let rows: Vec<(i64, i64, i64, String)> = sqlx::query_as(sql).fetch_all(&store.pool).await.unwrap();
        rows.into_iter().map(|r| r.3).collect::<Vec<_>>().join("\n")
    }

    /// Each filter is served by its index, never a scan of every clip.
    #[tokio::test]
    async fn every_indexed_filter_uses_its_index() {
        let dir = tempfile::tempdir().unwrap();
        let store = SqliteStore::open(&dir.path().join("c.db"), &PoolSettings::default()).await.unwrap();
        let q = ListQuery::default;
        let cases = [
            (ListQuery { name_prefix: Some("walk".into()), ..q() }, "clips_by_name"),
            (ListQuery { tag: Some("fast".into()), ..q() }, "clip_tags_by_tag"),
            (ListQuery { min_duration: Some(1.0), max_duration: Some(2.0), ..q() }, "clips_by_duration"),
            // Candidates in id order, each probed joint by joint on the primary key.
            (
                ListQuery { compatible_with: Some("x".into()), ..q() },
                "SEARCH j USING PRIMARY KEY (clip_id=? AND joint=?)",
            ),
        ];
        for (query, index) in cases {
            let plan = plan(&store, &query).await;
            assert!(plan.contains(index), "{query:?} should use {index}:\n{plan}");
        }
        store.pool.close().await;
    }
}
