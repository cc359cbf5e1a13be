//! Clips stored before the list index (migration 0002) are found by it:
//! a database at migration 0001 with rows in it, opened by today's store,
//! gets each clip's joint names from its stored document, both when the
//! document has a skeleton and when its joints come from its tracks.

use std::path::Path;

use server::store::postgres::PgStore;
use server::store::sqlite::SqliteStore;
use server::store::{ClipStore, ListQuery, PoolSettings};
use sqlx::migrate::Migrator;

use crate::common::pg::Schema;

/// A skeleton of three joints, whose tracks name only two of them.
const WITH_SKELETON: &str = r#"{"name":"a","skeleton":{"joints":[{"name":"hips","parent":null},{"name":"leg","parent":"hips"},{"name":"foot","parent":"leg"}]},"tracks":[{"joint":"hips","channel":"translation","times":[0,1],"values":[[0,0,0],[1,0,0]]},{"joint":"leg","channel":"translation","times":[0,1],"values":[[0,0,0],[1,0,0]]}]}"#;
/// No skeleton: the joints are what the tracks name (hips, leg).
const FROM_TRACKS: &str = r#"{"name":"b","tracks":[{"joint":"hips","channel":"translation","times":[0,1],"values":[[0,0,0],[1,0,0]]},{"joint":"leg","channel":"translation","times":[0,2],"values":[[0,0,0],[1,0,0]]},{"joint":"leg","channel":"scale","times":[0,1],"values":[[1,1,1],[2,2,2]]}]}"#;

/// The migrations of `dir` up to 0001 only, as a migrator of their own
/// (the same file, so the same checksum the store's migrator records).
async fn first_migration_only(dir: &str, scratch: &Path) -> Migrator {
    let from = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/server/migrations").join(dir).join("0001_clips.sql");
    std::fs::copy(&from, scratch.join("0001_clips.sql")).unwrap();
    Migrator::new(scratch).await.unwrap()
}

const INSERT_SQLITE: &str = "INSERT INTO clips (id, name, version, doc, joints, tracks, events, start_time, end_time, \
     playback, created_at, updated_at) VALUES (?1, ?2, 1, ?3, ?4, 2, 0, 0, 1, 'once', 0, 0)";
const INSERT_PG: &str = "INSERT INTO clips (id, name, version, doc, joints, tracks, events, start_time, end_time, \
     playback, created_at, updated_at) VALUES ($1, $2, 1, $3, $4, 2, 0, 0, 1, 'once', 0, 0)";

/// (id, name, doc, joint count) of the two old clips, ids in creation order.
fn old_rows() -> [(String, &'static str, &'static str, i64); 2] {
    let a = server::store::new_clip_id();
    let b = server::store::new_clip_id();
    [(a, "a", WITH_SKELETON, 3), (b, "b", FROM_TRACKS, 2)]
}

async fn check(store: &dyn ClipStore, rows: &[(String, &str, &str, i64); 2]) {
    let compatible = |id: &str| ListQuery { compatible_with: Some(id.to_owned()), limit: 10, ..ListQuery::default() };
    let ids = |metas: Vec<server::store::ClipMeta>| metas.into_iter().map(|m| m.id).collect::<Vec<_>>();
    // a's joints (hips, leg, foot) include b's (hips, leg), not the other way round.
    assert_eq!(ids(store.list(compatible(&rows[1].0)).await.unwrap()), [rows[0].0.clone(), rows[1].0.clone()]);
    assert_eq!(ids(store.list(compatible(&rows[0].0)).await.unwrap()), [rows[0].0.clone()]);
    let old = store.get(&rows[0].0).await.unwrap().unwrap();
    assert!(old.meta.tags.is_empty(), "no clip had tags before");
}

#[tokio::test]
async fn sqlite_clips_stored_before_the_index_are_indexed() {
    let dir = tempfile::tempdir().unwrap();
    let scratch = tempfile::tempdir().unwrap();
    let path = dir.path().join("clips.db");
    let url = format!("sqlite://{}?mode=rwc", path.display());
    let pool = sqlx::SqlitePool::connect(&url).await.unwrap();
    first_migration_only("sqlite", scratch.path()).await.run(&pool).await.unwrap();
    let rows = old_rows();
    for (id, name, doc, joints) in &rows {
        sqlx::query(INSERT_SQLITE).bind(id).bind(name).bind(doc).bind(joints).execute(&pool).await.unwrap();
    }
    pool.close().await;
    let store = SqliteStore::open(&path, &PoolSettings::default()).await.unwrap();
    check(&store, &rows).await;
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_clips_stored_before_the_index_are_indexed() {
    let Some(schema) = Schema::create("upgrade").await else { return };
    let scratch = tempfile::tempdir().unwrap();
    let pool = sqlx::PgPool::connect(&schema.url("")).await.unwrap();
    first_migration_only("postgres", scratch.path()).await.run(&pool).await.unwrap();
    let rows = old_rows();
    for (id, name, doc, joints) in &rows {
        sqlx::query(INSERT_PG).bind(id).bind(name).bind(doc).bind(joints).execute(&pool).await.unwrap();
    }
    pool.close().await;
    let store = PgStore::open(&schema.url(""), &PoolSettings::default()).await.unwrap();
    check(&store, &rows).await;
    store.close().await;
    schema.drop_now().await;
}
