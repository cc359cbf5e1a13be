//! What only the shared store does: announce every committed change on its
//! schema's channel, and ride out connections the server terminates.

use std::time::Duration;

use server::store::{OnName, PoolSettings};
use sqlx::postgres::PgListener;

use super::backend::Postgres;
use super::new_clip;

async fn next_payload(listener: &mut PgListener) -> String {
    let n = tokio::time::timeout(Duration::from_secs(5), listener.recv()).await.expect("a notification").unwrap();
    n.payload().to_owned()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_committed_change_is_announced_on_the_schema_channel() {
    let Some(backend) = Postgres::open("announce").await else { return };
    let store = &backend.store;
    let mut listener = PgListener::connect(&backend.schema.url("")).await.unwrap();
    listener.listen(backend.pg.channel()).await.unwrap();
    assert!(backend.pg.channel().ends_with(&backend.schema.name), "one channel per schema");

    let meta = store.create(new_clip("a", "{}"), OnName::Refuse).await.unwrap();
    assert_eq!(next_payload(&mut listener).await, format!("create 1 {}", meta.id));
    store.replace(&meta.id, new_clip("a", "{\"v\":2}"), None).await.unwrap();
    assert_eq!(next_payload(&mut listener).await, format!("replace 2 {}", meta.id));
    // A refused conditional write changes nothing, so announces nothing.
    assert!(store.replace(&meta.id, new_clip("a", "{}"), Some(1)).await.is_err());
    store.delete(&meta.id, Some(2)).await.unwrap();
    assert_eq!(next_payload(&mut listener).await, format!("delete 2 {}", meta.id));
    let metas = store.create_all(vec![new_clip("x", "{}"), new_clip("y", "{}")], OnName::Refuse).await.unwrap();
    for m in &metas {
        assert_eq!(next_payload(&mut listener).await, format!("create 1 {}", m.id));
    }
    listener.unlisten_all().await.unwrap();
    backend.finish().await;
}

/// Broadcasts (docs/broadcasts.md) are announced on the same channel: created, each
/// control (naming its broadcast), deleted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn broadcast_changes_are_announced_on_the_schema_channel() {
    let Some(backend) = Postgres::open("bannounce").await else { return };
    let store = &backend.store;
    let mut listener = PgListener::connect(&backend.schema.url("")).await.unwrap();
    listener.listen(backend.pg.channel()).await.unwrap();
    let id = "01a20000-0000-7000-8000-0000000000bb";
    let b = server::store::StoredBroadcast { id: id.into(), definition: "{}".into(), created_at: 1, controls: vec![] };
    store.create_broadcast(b).await.unwrap();
    assert_eq!(next_payload(&mut listener).await, format!("broadcast 0 {id}"));
    let c = server::store::StoredControl { id: "c1".into(), seq: 5, control: "{}".into() };
    store.add_broadcast_control(id, c).await.unwrap();
    assert_eq!(next_payload(&mut listener).await, format!("control 0 {id}"));
    store.touch_broadcast(id, i64::MAX).await.unwrap();
    store.delete_broadcast(id).await.unwrap();
    assert_eq!(next_payload(&mut listener).await, format!("unbroadcast 0 {id}"), "touching announces nothing");
    listener.unlisten_all().await.unwrap();
    backend.finish().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_store_rides_out_terminated_connections() {
    let app = "store-terminated";
    let settings = PoolSettings { max_connections: 3, ..PoolSettings::default() };
    let Some(backend) = Postgres::open_with("terminated", &format!("application_name={app}"), &settings).await else {
        return;
    };
    let store = &backend.store;
    let meta = store.create(new_clip("a", "{}"), OnName::Refuse).await.unwrap();
    // Warm several pooled connections, then have the server kill them all.
    let reads: Vec<_> = (0..3).map(|_| store.get(&meta.id)).collect();
    for r in futures_util::future::join_all(reads).await {
        r.unwrap();
    }
    for round in 0..3 {
        let killed = backend.schema.terminate(app).await;
        assert!(killed >= 1, "round {round}: the store's connections carry application_name={app}");
        // Once they have exited, the read below meets the closed connections and must get through them.
        backend.schema.until_gone(app).await;
        let got = store.get(&meta.id).await.expect("a read after the terminations succeeds").unwrap();
        assert_eq!(got.meta.version, round + 1);
        store.replace(&meta.id, new_clip("a", "{}"), Some(round + 1)).await.expect("so does a write");
    }
    backend.finish().await;
}
