//! The shared store: PostgreSQL through sqlx, for several nodes on one
//! database (`--database-url postgres://…`).
//!
//! The schema (`migrations/postgres`) is the SQLite tables plus a trigger that
//! announces every committed change with `NOTIFY` on [`PgStore::channel`];
//! [`PgChangeFeed`] listens there for `server::notify`, which keeps each
//! node's cache of compiled clips in step. Migrations take sqlx's advisory lock, so nodes starting
//! together apply them once.
//!
//! Durability is checked, not assumed: every pooled connection reads back
//! `fsync`, `full_page_writes` and `synchronous_commit` as it opens and is
//! refused unless all are on (a role or database can turn
//! `synchronous_commit` off behind the server's back), unless the operator
//! chose [`Durability::UnsafeFast`].
//!
//! Transient failures (a reset connection, a terminated backend, a
//! serialization failure) are retried with backoff ([`super::RetryPolicy`];
//! which operations may be repeated is said in `store::sql`, whose
//! statements are shared with SQLite).

use std::str::FromStr;
use std::time::Duration;

use futures_util::FutureExt;
use futures_util::future::BoxFuture;
use sqlx::migrate::Migrator;
use sqlx::postgres::{PgConnectOptions, PgListener, PgPool, PgPoolOptions, PgQueryResult};
use sqlx::{PgConnection, Postgres};

use super::dialect::Dialect;
use super::feed::{ChangeFeed, FeedError, Subscription};
use super::retry::Transience;
use super::sql::SqlStore;
use super::{Durability, PoolSettings};

static MIGRATOR: Migrator = sqlx::migrate!("./migrations/postgres");

/// The `application_name` connections carry unless the URL sets one, so an
/// operator can find them in `pg_stat_activity`.
const DEFAULT_APPLICATION_NAME: &str = "inbetween";

/// A PostgreSQL-backed [`ClipStore`](super::ClipStore).
pub type PgStore = SqlStore<Postgres>;

impl Dialect for Postgres {
    /// The `NOTIFY` channel the schema's trigger announces changes on.
    type Extra = String;
    type StringList = Vec<String>;

    const BEGIN_WRITE: &'static str = "BEGIN";
    const INSERT_TAGS: &'static str = "INSERT INTO clip_tags (clip_id, tag) SELECT DISTINCT $1, unnest($2::text[])";
    const INSERT_JOINTS: &'static str =
        "INSERT INTO clip_joints (clip_id, joint) SELECT DISTINCT $1, unnest($2::text[])";
    /// `clips_by_name_bytewise` is built `COLLATE "C"`, whatever the database's locale.
    const BYTEWISE_NAME: &'static str = "c.name COLLATE \"C\"";
    const POSITION_FN: &'static str = "strpos";
    const FORGET_CONTROLS: &'static str =
        "DELETE FROM broadcast_controls WHERE broadcast_id = $1 AND seq <= $2 AND id <> ALL($3::text[])";
    /// A transaction-scoped advisory lock on the name's 64-bit hash (a
    /// collision only makes two names wait for each other).
    const LOCK_NAME: Option<&'static str> = Some("SELECT pg_advisory_xact_lock(hashtextextended($1, 0))");

    fn string_list(items: &[String]) -> Vec<String> {
        items.to_vec()
    }

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

    fn is_clip_id_conflict(e: &sqlx::Error) -> bool {
        matches!(e, sqlx::Error::Database(db) if matches!(db.constraint(), Some("clips_pkey" | "characters_pkey" | "graphs_pkey")))
    }

    fn rows_affected(done: &PgQueryResult) -> u64 {
        done.rows_affected()
    }

    fn check_durability(conn: &mut PgConnection, durability: Durability) -> BoxFuture<'_, Result<(), sqlx::Error>> {
        check_durability(conn, durability).boxed()
    }
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
        SqlStore::connect(options, settings, &MIGRATOR, async |pool| {
            let schema: String = sqlx::query_scalar("SELECT current_schema()").fetch_one(pool).await?;
            Ok(format!("inbetween_clips_{schema}"))
        })
        .await
    }

    /// The `NOTIFY` channel the schema's trigger announces changes on.
    pub fn channel(&self) -> &str {
        &self.extra
    }

    /// The feed of this store's changes, as every node sharing it announces them.
    pub fn change_feed(&self) -> PgChangeFeed {
        PgChangeFeed { pool: self.pool.clone(), channel: self.extra.clone() }
    }
}

/// Refuses a connection that would acknowledge a commit before it is durable.
async fn check_durability(conn: &mut PgConnection, durability: Durability) -> Result<(), sqlx::Error> {
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

/// `LISTEN`/`NOTIFY` on the schema's channel: the [`ChangeFeed`] of a [`PgStore`].
#[derive(Debug, Clone)]
pub struct PgChangeFeed {
    /// The store's pool: heartbeats are sent on it, and subscriptions
    /// connect with its options.
    pool: PgPool,
    channel: String,
}

impl ChangeFeed for PgChangeFeed {
    fn name(&self) -> &str {
        &self.channel
    }

    fn subscribe(&self) -> BoxFuture<'_, Result<Box<dyn Subscription>, FeedError>> {
        async move {
            let pool = PgPoolOptions::new()
                .max_connections(1)
                .acquire_timeout(Duration::from_secs(5))
                .idle_timeout(None)
                .max_lifetime(None)
                .connect_with((*self.pool.connect_options()).clone())
                .await?;
            let mut listener = PgListener::connect_with(&pool).await?;
            listener.eager_reconnect(false);
            listener.ignore_pool_close_event(true);
            listener.listen(&self.channel).await?;
            Ok(Box::new(listener) as Box<dyn Subscription>)
        }
        .boxed()
    }

    fn ping(&self) -> BoxFuture<'_, Result<(), FeedError>> {
        async move {
            sqlx::query("SELECT pg_notify($1, 'ping 0 -')").bind(&self.channel).execute(&self.pool).await?;
            Ok(())
        }
        .boxed()
    }
}

impl Subscription for PgListener {
    fn next(&mut self) -> BoxFuture<'_, Result<Option<String>, FeedError>> {
        async move { Ok(self.try_recv().await?.map(|n| n.payload().to_owned())) }.boxed()
    }
}
