//! The shared store: PostgreSQL through sqlx, for several nodes on one
//! database (`--database-url postgres://…`).
//!
//! The schema (`migrations/postgres`) is the SQLite tables plus a trigger that
//! announces every committed change with `NOTIFY` on [`PgStore::channel`];
//! `server::notify` listens there and keeps each node's cache of compiled
//! clips in step. Migrations take sqlx's advisory lock, so nodes starting
//! together apply them once.
//!
//! Durability is checked, not assumed: every pooled connection reads back
//! `fsync`, `full_page_writes` and `synchronous_commit` as it opens and is
//! refused unless all are on (a role or database can turn
//! `synchronous_commit` off behind the server's back), unless the operator
//! chose [`Durability::UnsafeFast`].
//!
//! Transient failures (a reset connection, a terminated backend, a
//! serialization failure) are retried with backoff (`store::retry`, [`super::RetryPolicy`]):
//! reads and inserts always (an insert carries its id, so a retry after an
//! attempt that did commit finds its own row), a replace or delete only when
//! the failure proves the statement did not run.

use std::str::FromStr;
use std::time::Instant;

use futures_util::FutureExt;
use futures_util::future::BoxFuture;
use sqlx::postgres::{PgConnectOptions, PgPool, PgPoolOptions};
use sqlx::{Connection, Row, migrate::Migrator};

use super::broadcast::{broadcast_from_row, broadcast_methods, control_from_row, pg as bsql};
use super::filter::{POSTGRES, list_query};
use super::retry::{Retry, Transience, with_retry};
use super::{
    ClipMeta, ClipStore, Durability, ListQuery, MeshWrite, NewClip, PoolSettings, StoreError, StoredClip, StoredMesh,
    new_clip_id, now_millis,
};
use super::{StoredBroadcast, StoredControl};

static MIGRATOR: Migrator = sqlx::migrate!("./migrations/postgres");

/// The `application_name` connections carry unless the URL sets one, so an
/// operator can find them in `pg_stat_activity`.
const DEFAULT_APPLICATION_NAME: &str = "inbetween";

macro_rules! meta_columns {
    () => {
        "id, name, version, joints, tracks, events, start_time, end_time, playback, tags, created_at, updated_at"
    };
}

/// A PostgreSQL-backed [`ClipStore`].
#[derive(Debug, Clone)]
pub struct PgStore {
    pool: PgPool,
    options: PgConnectOptions,
    settings: PoolSettings,
    channel: String,
}

impl PgStore {
    /// Connects to a `postgres://` URL, checks durability on every pooled
    /// connection and runs migrations.
    ///
    /// # Errors
    /// The URL does not parse, the database is unreachable (within the
    /// acquire timeout), a connection fails the durability check, or a
    /// migration fails.
    pub async fn open(url: &str, settings: &PoolSettings) -> anyhow::Result<Self> {
        let mut options = PgConnectOptions::from_str(url)?;
        if options.get_application_name().is_none() {
            options = options.application_name(DEFAULT_APPLICATION_NAME);
        }
        let durability = settings.durability;
        // One connection checked up front, so a refusal reports its reason
        // (the pool would only time out retrying).
        let mut first = sqlx::PgConnection::connect_with(&options).await?;
        check_durability(&mut first, durability).await?;
        first.close().await?;
        let pool = PgPoolOptions::new()
            .max_connections(settings.max_connections.max(1))
            .acquire_timeout(settings.acquire_timeout)
            .after_connect(move |conn, _| Box::pin(async move { check_durability(conn, durability).await }))
            .connect_with(options.clone())
            .await?;
        MIGRATOR.run(&pool).await?;
        let schema: String = sqlx::query_scalar("SELECT current_schema()").fetch_one(&pool).await?;
        Ok(PgStore { pool, options, settings: settings.clone(), channel: format!("inbetween_clips_{schema}") })
    }

    /// The `NOTIFY` channel the schema's trigger announces changes on.
    pub fn channel(&self) -> &str {
        &self.channel
    }

    /// The options this store connects with (the listener opens its own
    /// connection with the same ones).
    pub(crate) fn connect_options(&self) -> &PgConnectOptions {
        &self.options
    }

    /// The pool, for the notification listener's revalidation queries.
    pub fn pool(&self) -> &PgPool {
        &self.pool
    }

    async fn run<T, F, Fut>(&self, op: &'static str, mode: Retry, attempt: F) -> Result<T, StoreError>
    where
        F: FnMut(u32) -> Fut,
        Fut: Future<Output = Result<T, sqlx::Error>>,
    {
        let started = Instant::now();
        let r = with_retry(self.settings.retry, mode, classify, attempt).await;
        metrics::histogram!("inbetween_store_operation_duration_seconds", "op" => op)
            .record(started.elapsed().as_secs_f64());
        r.map_err(to_store_error)
    }
}

/// Refuses a connection that would acknowledge a commit before it is durable.
async fn check_durability(conn: &mut sqlx::PgConnection, durability: Durability) -> Result<(), sqlx::Error> {
    let (fsync, fpw, sync_commit): (String, String, String) = sqlx::query_as(
        "SELECT current_setting('fsync'), current_setting('full_page_writes'), current_setting('synchronous_commit')",
    )
    .fetch_one(&mut *conn)
    .await?;
    let unsafe_settings: Vec<String> =
        [("fsync", &fsync), ("full_page_writes", &fpw), ("synchronous_commit", &sync_commit)]
            .into_iter()
            .filter(|(_, v)| v.as_str() == "off")
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
    if unsafe_settings.is_empty() {
        return Ok(());
    }
    match durability {
        // The pool drops a connection whose after_connect hook failed.
        Durability::Required => Err(sqlx::Error::Configuration(
            format!(
                "PostgreSQL is not durable ({}): a committed clip could be lost in a crash. Turn these on, \
                     or start with --unsafe-fast-writes to accept that",
                unsafe_settings.join(", ")
            )
            .into(),
        )),
        Durability::UnsafeFast => {
            tracing::warn!(settings = %unsafe_settings.join(", "), "unsafe fast writes: PostgreSQL is not durable");
            Ok(())
        }
    }
}

/// Which failures are worth a retry, and whether the statement may have run.
fn classify(e: &sqlx::Error) -> Transience {
    match e {
        // The server rolled the statement back (serialization failure,
        // deadlock victim), refused the connection, or terminated the
        // backend before answering (a commit is acknowledged before the
        // termination message could be read).
        sqlx::Error::Database(db) => match db.code().as_deref() {
            Some("40001" | "40P01" | "57P01" | "57P02" | "57P03" | "53300") => Transience::NotExecuted,
            Some(code) if code.starts_with("08") => Transience::Ambiguous,
            _ => Transience::Permanent,
        },
        // The connection broke: the statement may or may not have committed.
        sqlx::Error::Io(_) => Transience::Ambiguous,
        // Already waited the whole acquire timeout; the pool is shut.
        _ => Transience::Permanent,
    }
}

fn is_transient(e: &sqlx::Error) -> bool {
    classify(e) != Transience::Permanent
}

fn to_store_error(e: sqlx::Error) -> StoreError {
    match e {
        sqlx::Error::PoolTimedOut | sqlx::Error::PoolClosed | sqlx::Error::Io(_) => StoreError::Unavailable(e.into()),
        e if is_transient(&e) => StoreError::Unavailable(e.into()),
        other => StoreError::Backend(other.into()),
    }
}

/// Whether `e` is the primary-key conflict of an insert whose earlier
/// attempt committed (then the row is ours).
fn is_own_duplicate(e: &sqlx::Error, attempt: u32) -> bool {
    attempt > 0 && matches!(e, sqlx::Error::Database(db) if db.constraint() == Some("clips_pkey"))
}

fn new_meta(clip: &NewClip, now: i64) -> ClipMeta {
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

/// Inserts the clip row and its index rows (in the caller's transaction).
async fn insert(db: &mut sqlx::PgConnection, meta: &ClipMeta, clip: &NewClip) -> Result<(), sqlx::Error> {
    let s = &meta.stats;
    sqlx::query(
        "INSERT INTO clips (id, name, version, doc, joints, tracks, events, start_time, end_time, playback, \
         tags, created_at, updated_at) VALUES ($1, $2, 1, $3, $4, $5, $6, $7, $8, $9, $11, $10, $10)",
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
    .bind(meta.created_at)
    .bind(serde_json::Value::from(clip.tags.as_slice()).to_string())
    .execute(&mut *db)
    .await?;
    write_index(db, &meta.id, clip, false).await
}

/// The clip's `clip_tags` and `clip_joints` rows (replacing its old ones).
async fn write_index(db: &mut sqlx::PgConnection, id: &str, clip: &NewClip, replace: bool) -> Result<(), sqlx::Error> {
    if replace {
        sqlx::query("DELETE FROM clip_tags WHERE clip_id = $1").bind(id).execute(&mut *db).await?;
        sqlx::query("DELETE FROM clip_joints WHERE clip_id = $1").bind(id).execute(&mut *db).await?;
    }
    sqlx::query("INSERT INTO clip_tags (clip_id, tag) SELECT DISTINCT $1, unnest($2::text[])")
        .bind(id)
        .bind(&clip.tags)
        .execute(&mut *db)
        .await?;
    sqlx::query("INSERT INTO clip_joints (clip_id, joint) SELECT DISTINCT $1, unnest($2::text[])")
        .bind(id)
        .bind(&clip.joint_names)
        .execute(&mut *db)
        .await?;
    write_mesh(db, id, &clip.mesh, replace).await
}

/// The clip's `clip_meshes` row as [`MeshWrite`] says.
async fn write_mesh(db: &mut sqlx::PgConnection, id: &str, mesh: &MeshWrite, replace: bool) -> Result<(), sqlx::Error> {
    if *mesh == MeshWrite::Keep {
        return Ok(());
    }
    if replace {
        sqlx::query("DELETE FROM clip_meshes WHERE clip_id = $1").bind(id).execute(&mut *db).await?;
    }
    if let MeshWrite::Set(m) = mesh {
        sqlx::query("INSERT INTO clip_meshes (clip_id, etag, bytes) VALUES ($1, $2, $3)")
            .bind(id)
            .bind(&m.etag)
            .bind(m.bytes.as_ref())
            .execute(&mut *db)
            .await?;
    }
    Ok(())
}

impl PgStore {
    /// Tells "not found" from "version mismatch" after a conditional write matched no row.
    async fn missed(&self, id: &str) -> Result<StoreError, sqlx::Error> {
        let row = sqlx::query("SELECT version FROM clips WHERE id = $1").bind(id).fetch_optional(&self.pool).await?;
        Ok(match row.map(|r| r.try_get::<i64, _>(0)).transpose()? {
            None => StoreError::NotFound,
            Some(current) => StoreError::VersionMismatch { current: current as u64 },
        })
    }
}

impl PgStore {
    /// Broadcast `id`'s controls in application order.
    async fn controls_of(&self, id: &str) -> Result<Vec<StoredControl>, sqlx::Error> {
        let rows = sqlx::query(bsql::CONTROLS).bind(id).fetch_all(&self.pool).await?;
        rows.iter().map(control_from_row).collect()
    }
}

impl ClipStore for PgStore {
    broadcast_methods!(bsql);

    fn create(&self, clip: NewClip) -> BoxFuture<'_, Result<ClipMeta, StoreError>> {
        async move {
            let meta = new_meta(&clip, now_millis());
            self.run("create", Retry::Always, |n| {
                let (meta, clip) = (&meta, &clip);
                async move {
                    let r = async {
                        let mut tx = self.pool.begin().await?;
                        insert(&mut tx, meta, clip).await?;
                        tx.commit().await
                    }
                    .await;
                    match r {
                        Err(e) if !is_own_duplicate(&e, n) => Err(e),
                        _ => Ok(()),
                    }
                }
            })
            .await?;
            Ok(meta)
        }
        .boxed()
    }

    fn create_all(&self, clips: Vec<NewClip>) -> BoxFuture<'_, Result<Vec<ClipMeta>, StoreError>> {
        async move {
            let now = now_millis();
            let metas: Vec<ClipMeta> = clips.iter().map(|c| new_meta(c, now)).collect();
            self.run("create_all", Retry::Always, |n| {
                let (metas, clips) = (&metas, &clips);
                async move {
                    let r = async {
                        let mut tx = self.pool.begin().await?;
                        for (meta, clip) in metas.iter().zip(clips) {
                            insert(&mut tx, meta, clip).await?;
                        }
                        tx.commit().await
                    }
                    .await;
                    // All or nothing: a duplicate on a retry means the earlier attempt committed them all.
                    match r {
                        Err(e) if !is_own_duplicate(&e, n) => Err(e),
                        _ => Ok(()),
                    }
                }
            })
            .await?;
            Ok(metas)
        }
        .boxed()
    }

    fn get<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredClip>, StoreError>> {
        async move {
            self.run("get", Retry::Always, |_| async move {
                let sql = concat!("SELECT ", meta_columns!(), ", doc FROM clips WHERE id = $1");
                let row = sqlx::query(sql).bind(id).fetch_optional(&self.pool).await?;
                row.map(|row| Ok(StoredClip { meta: super::meta_from_row(&row)?, doc_json: row.try_get("doc")? }))
                    .transpose()
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
                    Some(id) => {
                        let joints = sqlx::query_scalar("SELECT joints FROM clips WHERE id = $1")
                            .bind(id)
                            .fetch_optional(&self.pool)
                            .await?;
                        match joints {
                            Some(n) => Some(n),
                            None => return Ok(Err(StoreError::NotFound)),
                        }
                    }
                };
                let mut qb = list_query(meta_columns!(), query, reference, POSTGRES);
                let rows = qb.build().fetch_all(&self.pool).await?;
                rows.iter().map(super::meta_from_row).collect::<Result<Vec<_>, _>>().map(Ok)
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
            let sql = concat!(
                "UPDATE clips SET name = $3, doc = $4, joints = $5, tracks = $6, events = $7, start_time = $8, ",
                "end_time = $9, playback = $10, updated_at = $11, tags = $12, version = version + 1 ",
                "WHERE id = $1 AND ($2::bigint IS NULL OR version = $2) RETURNING ",
                meta_columns!()
            );
            let clip = &clip;
            let now = now_millis();
            let tags = serde_json::Value::from(clip.tags.as_slice()).to_string();
            let tags = &tags;
            self.run("replace", Retry::IfNotExecuted, |_| async move {
                let s = clip.stats;
                let mut tx = self.pool.begin().await?;
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
                    .bind(now)
                    .bind(tags)
                    .fetch_optional(&mut *tx)
                    .await?;
                let Some(row) = row else {
                    tx.rollback().await?;
                    return self.missed(id).await.map(Err);
                };
                let meta = super::meta_from_row(&row)?;
                write_index(&mut tx, id, clip, true).await?;
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
                let done = sqlx::query("DELETE FROM clips WHERE id = $1 AND ($2::bigint IS NULL OR version = $2)")
                    .bind(id)
                    .bind(expected_version.map(|v| v as i64))
                    .execute(&self.pool)
                    .await?;
                if done.rows_affected() == 1 { Ok(Ok(())) } else { self.missed(id).await.map(Err) }
            })
            .await?
        }
        .boxed()
    }

    fn mesh_tag<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<Option<String>>, StoreError>> {
        async move {
            self.run("mesh_tag", Retry::Always, |_| async move {
                let sql = "SELECT m.etag FROM clips c LEFT JOIN clip_meshes m ON m.clip_id = c.id WHERE c.id = $1";
                sqlx::query_scalar::<_, Option<String>>(sql).bind(id).fetch_optional(&self.pool).await
            })
            .await
        }
        .boxed()
    }

    fn mesh<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredMesh>, StoreError>> {
        async move {
            self.run("mesh", Retry::Always, |_| async move {
                let row = sqlx::query("SELECT etag, bytes FROM clip_meshes WHERE clip_id = $1")
                    .bind(id)
                    .fetch_optional(&self.pool)
                    .await?;
                row.map(|row| {
                    let bytes: Vec<u8> = row.try_get("bytes")?;
                    Ok(StoredMesh { etag: row.try_get("etag")?, bytes: bytes.into() })
                })
                .transpose()
            })
            .await
        }
        .boxed()
    }

    fn ping(&self) -> BoxFuture<'_, Result<(), StoreError>> {
        async move {
            // No retry: readiness must report the database as it is now.
            let started = Instant::now();
            let r = sqlx::query("SELECT 1").execute(&self.pool).await.map(|_| ());
            metrics::histogram!("inbetween_store_operation_duration_seconds", "op" => "ping")
                .record(started.elapsed().as_secs_f64());
            r.map_err(to_store_error)
        }
        .boxed()
    }

    fn close(&self) -> BoxFuture<'_, ()> {
        self.pool.close().boxed()
    }
}

/// Records a broadcast operation's duration and maps its error (broadcast
/// writes are not retried: a caller sees the failure and may send again).
fn timed<T>(op: &'static str, started: Instant, r: Result<T, sqlx::Error>) -> Result<T, StoreError> {
    metrics::histogram!("inbetween_store_operation_duration_seconds", "op" => op)
        .record(started.elapsed().as_secs_f64());
    r.map_err(to_store_error)
}
