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
//! for the lock instead of failing. A writer that still does not get it (the
//! busy handler polls, so under load one can lose to the others for the
//! whole timeout) fails with `SQLITE_BUSY`, which is transient: the
//! statement did not run, so it is retried, and at worst answered 503.
//!
//! A delete is a single statement (its `clip_tags` and `clip_joints` rows go
//! by cascade). A create or replace writes the clip row and its index rows
//! in one transaction opened with `BEGIN IMMEDIATE`, which takes the write
//! lock before anything is read: no transaction ever upgrades a read lock
//! (which in WAL mode fails with `SQLITE_BUSY` instead of waiting).
//!
//! The statements themselves are shared with PostgreSQL (`store::sql`).

use std::path::Path;
use std::str::FromStr;
use std::time::Duration;

use anyhow::Context;
use futures_util::FutureExt;
use futures_util::future::BoxFuture;
use sqlx::migrate::Migrator;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqliteQueryResult, SqliteSynchronous};
use sqlx::{Sqlite, SqliteConnection};

use super::dialect::Dialect;
use super::retry::Transience;
use super::sql::SqlStore;
use super::{Durability, PoolSettings};

static MIGRATOR: Migrator = sqlx::migrate!("./migrations/sqlite");

/// SQLite's primary result codes for a lock not had.
const BUSY: i32 = 5;
const LOCKED: i32 = 6;

/// A SQLite-backed [`ClipStore`](super::ClipStore).
pub type SqliteStore = SqlStore<Sqlite>;

impl Dialect for Sqlite {
    type Extra = ();
    /// A JSON array, which `json_each` reads.
    type StringList = String;

    /// Takes the write lock from the first statement.
    const BEGIN_WRITE: &'static str = "BEGIN IMMEDIATE";
    const INSERT_TAGS: &'static str =
        "INSERT INTO clip_tags (clip_id, tag) SELECT DISTINCT $1, value FROM json_each($2)";
    const INSERT_JOINTS: &'static str =
        "INSERT INTO clip_joints (clip_id, joint) SELECT DISTINCT $1, value FROM json_each($2)";
    const BYTEWISE_NAME: &'static str = "c.name";
    const POSITION_FN: &'static str = "instr";
    const FORGET_CONTROLS: &'static str = "DELETE FROM broadcast_controls WHERE broadcast_id = $1 AND seq <= $2 \
         AND id NOT IN (SELECT value FROM json_each($3))";
    /// `BEGIN IMMEDIATE` takes the database's write lock: writers are serial.
    const LOCK_NAME: Option<&'static str> = None;

    fn string_list(items: &[String]) -> String {
        serde_json::Value::from(items).to_string()
    }

    /// `SQLITE_BUSY` and `SQLITE_LOCKED` (with their extended codes): the
    /// lock was not had within the busy timeout, so the statement did not
    /// run (a transaction it was in is rolled back). Several writers on a
    /// loaded machine can wait that long, SQLite's busy handler being a
    /// poll and not a queue: the operation is retried, and answered 503, not
    /// 500, if it never gets the lock.
    fn classify(e: &sqlx::Error) -> Transience {
        let code = match e {
            sqlx::Error::Database(db) => db.code().and_then(|c| c.parse::<i32>().ok()),
            _ => None,
        };
        match code.map(|c| c & 0xff) {
            Some(BUSY | LOCKED) => Transience::NotExecuted,
            _ => Transience::Permanent,
        }
    }

    fn is_clip_id_conflict(_: &sqlx::Error) -> bool {
        false
    }

    fn rows_affected(done: &SqliteQueryResult) -> u64 {
        done.rows_affected()
    }

    fn check_durability(conn: &mut SqliteConnection, durability: Durability) -> BoxFuture<'_, Result<(), sqlx::Error>> {
        check_durability(conn, durability).boxed()
    }
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
        let synchronous = match settings.durability {
            Durability::Required => SqliteSynchronous::Full,
            Durability::UnsafeFast => SqliteSynchronous::Normal,
        };
        let options = options
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(synchronous)
            .foreign_keys(true)
            .busy_timeout(Duration::from_secs(10));
        SqlStore::connect(options, settings, &MIGRATOR, async |_| Ok(())).await
    }
}

/// Refuses a connection whose commits would not be on disk when they return.
async fn check_durability(conn: &mut SqliteConnection, durability: Durability) -> Result<(), sqlx::Error> {
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

#[cfg(test)]
mod tests {
    use super::SqliteStore;
    use crate::store::filter::list_query;
    use crate::store::sql::meta_columns;
    use crate::store::{ListQuery, PoolSettings};

    /// SQLite's plan of the list for `query`, one line per step.
    async fn plan(store: &SqliteStore, query: &ListQuery) -> String {
        let qb = list_query::<sqlx::Sqlite>(meta_columns!(), query, Some(3));
        let sql = sqlx::AssertSqlSafe(format!("EXPLAIN QUERY PLAN {}", qb.sql().as_str()));
        let rows: Vec<(i64, i64, i64, String)> = sqlx::query_as(sql).fetch_all(store.pool()).await.unwrap();
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
        store.pool().close().await;
    }
}
