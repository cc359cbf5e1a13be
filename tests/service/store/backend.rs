//! The two backends the suite runs on, each opened the way the server opens it.

use std::sync::Arc;

use server::store::postgres::PgStore;
use server::store::sqlite::SqliteStore;
use server::store::{ClipStore, PoolSettings};

use crate::common::pg::Schema;

/// A SQLite file in a temporary directory.
pub struct Sqlite {
    pub store: Arc<dyn ClipStore>,
    /// The database file, for tests that write rows as an older server did.
    pub path: std::path::PathBuf,
    _dir: tempfile::TempDir,
}

impl Sqlite {
    pub async fn open() -> Sqlite {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("clips.db");
        let store = SqliteStore::open(&path, &PoolSettings::default()).await.unwrap();
        Sqlite { store: Arc::new(store), path, _dir: dir }
    }
}

/// A PostgreSQL store in a fresh schema.
pub struct Postgres {
    pub store: Arc<dyn ClipStore>,
    pub pg: PgStore,
    pub schema: Schema,
}

impl Postgres {
    /// `None` when PostgreSQL is unreachable and not required (see `pg`).
    pub async fn open(tag: &str) -> Option<Postgres> {
        Self::open_with(tag, "", &PoolSettings::default()).await
    }

    pub async fn open_with(tag: &str, url_extra: &str, settings: &PoolSettings) -> Option<Postgres> {
        let tag: String = tag.chars().filter(char::is_ascii_alphanumeric).take(12).collect();
        let schema = Schema::create(&tag).await?;
        let pg = PgStore::open(&schema.url(url_extra), settings).await.unwrap();
        Some(Postgres { store: Arc::new(pg.clone()), pg, schema })
    }

    pub async fn finish(self) {
        self.pg.close().await;
        self.schema.drop_now().await;
    }
}
