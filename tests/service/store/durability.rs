//! Durability is configured, not assumed: read back from the database on
//! every pooled connection, and a store (hence the server) that would
//! acknowledge writes before they are durable refuses to open unless the
//! operator accepted that with `--unsafe-fast-writes`.

use std::io::{BufRead, BufReader, Read};
use std::process::Stdio;

use server::store::sqlite::SqliteStore;
use server::store::{Durability, PoolSettings};

use super::backend::Postgres;
use crate::common::ServerProcess;

fn settings(max_connections: u32, durability: Durability) -> PoolSettings {
    PoolSettings { max_connections, durability, ..PoolSettings::default() }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_pooled_sqlite_connection_is_wal_with_full_sync() {
    let dir = tempfile::tempdir().unwrap();
    let store = SqliteStore::open(&dir.path().join("c.db"), &settings(4, Durability::Required)).await.unwrap();
    // Hold four connections at once, so the pool must open four distinct ones.
    let mut held = Vec::new();
    for _ in 0..4 {
        held.push(store.pool().acquire().await.unwrap());
    }
    for conn in &mut held {
        let journal: String = sqlx::query_scalar("PRAGMA journal_mode").fetch_one(&mut **conn).await.unwrap();
        let sync: i64 = sqlx::query_scalar("PRAGMA synchronous").fetch_one(&mut **conn).await.unwrap();
        assert_eq!((journal.as_str(), sync), ("wal", 2), "journal_mode=WAL and synchronous=FULL");
    }
}

#[tokio::test]
async fn a_sqlite_url_in_a_missing_directory_creates_it_like_the_data_dir() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("nested/deeper/clips.db");
    let url = format!("sqlite://{}", file.display());
    SqliteStore::open_url(&url, &settings(1, Durability::Required)).await.unwrap();
    assert!(file.is_file(), "{} created", file.display());
}

#[tokio::test]
async fn an_in_memory_sqlite_database_is_refused_unless_fast_writes_are_accepted() {
    let refused = SqliteStore::open_url("sqlite::memory:", &settings(1, Durability::Required)).await;
    let message = format!("{:#}", refused.expect_err("an in-memory database cannot be durable"));
    assert!(message.contains("not durable") && message.contains("journal_mode=memory"), "{message}");
    SqliteStore::open_url("sqlite::memory:", &settings(1, Durability::UnsafeFast)).await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_connections_are_durable_as_read_back() {
    let Some(backend) = Postgres::open("durable").await else { return };
    let row: (String, String, String) = sqlx::query_as(
        "SELECT current_setting('fsync'), current_setting('full_page_writes'), current_setting('synchronous_commit')",
    )
    .fetch_one(backend.pg.pool())
    .await
    .unwrap();
    assert_eq!(row, ("on".to_owned(), "on".to_owned(), "on".to_owned()));
    backend.finish().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_with_synchronous_commit_off_is_refused_unless_fast_writes_are_accepted() {
    let Some(schema) = crate::common::pg::Schema::create("syncoff").await else { return };
    let url = schema.url("options=-csynchronous_commit%3Doff");
    let refused = server::store::postgres::PgStore::open(&url, &settings(2, Durability::Required)).await;
    let message = format!("{:#}", refused.expect_err("synchronous_commit=off is not durable"));
    assert!(message.contains("synchronous_commit=off"), "{message}");
    let store = server::store::postgres::PgStore::open(&url, &settings(2, Durability::UnsafeFast)).await.unwrap();
    let sync: String = sqlx::query_scalar("SHOW synchronous_commit").fetch_one(store.pool()).await.unwrap();
    assert_eq!(sync, "off", "the flag permits, it does not repair");
    store.pool().close().await;
    schema.drop_now().await;
}

/// The real binary: exits with the reason, or starts when the flag (or
/// `INBETWEEN_UNSAFE_FAST_WRITES`) accepts the risk.
#[test]
fn the_server_refuses_to_start_on_a_non_durable_store() {
    let serve = |extra: &[&str], env: Option<(&str, &str)>| {
        let mut c = ServerProcess::command();
        c.args([
            "serve",
            "--listen",
            "127.0.0.1:0",
            "--grpc-listen",
            "127.0.0.1:0",
            "--database-url",
            "sqlite::memory:",
        ])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
        if let Some((k, v)) = env {
            c.env(k, v);
        }
        c.spawn().unwrap()
    };
    let refused = serve(&[], None).wait_with_output().unwrap();
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(stderr.contains("not durable") && stderr.contains("--unsafe-fast-writes"), "{stderr}");

    for (extra, env) in [(&["--unsafe-fast-writes"][..], None), (&[][..], Some(("INBETWEEN_UNSAFE_FAST_WRITES", "1")))]
    {
        let mut child = serve(extra, env);
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let started = line.starts_with("inbetween listening on ");
        child.kill().unwrap();
        let mut stderr = String::new();
        child.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
        child.wait().unwrap();
        assert!(started, "with {extra:?} {env:?} the server starts; got {line:?}, stderr {stderr}");
    }
}
