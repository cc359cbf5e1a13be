//! The storage suite: every behaviour of the `ClipStore` trait, run against
//! a real SQLite file and a real PostgreSQL schema (fresh per test). Then
//! what is particular to each backend: durability read back from the
//! database and refused when off, PostgreSQL's change notifications and its
//! recovery from terminated connections.

mod backend;
mod characters;
mod filters;

use std::sync::Arc;

use anim::Playback;
use server::store::{
    ClipStats, ClipStore, Covers, ListQuery, MeshWrite, NewClip, OnName, StoreError, StoredBroadcast, StoredCheckpoint,
    StoredControl, StoredMesh,
};

/// Runs each listed test once per backend: `sqlite::name` and `postgres::name`.
macro_rules! for_both_backends {
    ($($name:ident),* $(,)?) => {
        mod sqlite {
            $(
                #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
                async fn $name() {
                    let backend = super::backend::Sqlite::open().await;
                    super::$name(backend.store.clone()).await;
                }
            )*
        }
        mod postgres {
            $(
                #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
                async fn $name() {
                    let Some(backend) = super::backend::Postgres::open(stringify!($name)).await else { return };
                    super::$name(backend.store.clone()).await;
                    backend.finish().await;
                }
            )*
        }
    };
}

for_both_backends!(
    a_created_clip_reads_back_exactly,
    an_unknown_id_is_none_and_writes_to_it_are_not_found,
    listing_pages_in_creation_order_and_filters_by_name,
    replace_bumps_the_version_and_honours_the_expected_one,
    delete_honours_the_expected_version,
    create_all_stores_every_clip_in_order,
    concurrent_conditional_replaces_let_exactly_one_win,
    concurrent_creates_all_land,
    a_name_is_held_by_one_clip_even_under_concurrent_writes,
    ping_answers_until_closed,
    every_filter_pages_through_exactly_its_clips,
    tags_and_joints_follow_replace_and_delete,
    a_mesh_is_written_kept_dropped_and_deleted_with_its_clip,
    broadcasts_and_their_controls_read_back_in_order,
    an_idle_broadcast_expires_and_a_touched_one_does_not,
    a_stored_checkpoint_holds_exactly_the_stored_controls_of_its_ticks,
    a_character_reads_back_and_versions_like_a_clip,
    characters_list_by_name_in_creation_order,
    a_character_name_is_held_by_one_even_under_concurrent_writes,
    a_character_mesh_is_kept_and_dropped_by_a_replace,
    an_import_writes_its_clips_and_characters_together_or_not_at_all,
);

use characters::{
    a_character_mesh_is_kept_and_dropped_by_a_replace, a_character_name_is_held_by_one_even_under_concurrent_writes,
    a_character_reads_back_and_versions_like_a_clip, an_import_writes_its_clips_and_characters_together_or_not_at_all,
    characters_list_by_name_in_creation_order,
};

use filters::{every_filter_pages_through_exactly_its_clips, tags_and_joints_follow_replace_and_delete};

pub fn stats(joints: u32, playback: Playback) -> ClipStats {
    ClipStats { joints, tracks: joints * 3, events: 2, start: 0.25, end: 1.5, playback }
}

pub fn new_clip(name: &str, doc: &str) -> NewClip {
    NewClip {
        name: name.to_owned(),
        doc_json: doc.to_owned(),
        stats: stats(4, Playback::Loop),
        tags: vec![],
        joint_names: vec![],
        mesh: MeshWrite::None,
    }
}

async fn a_created_clip_reads_back_exactly(store: Arc<dyn ClipStore>) {
    // The store keeps text as given, multi-byte characters and all.
    let doc = format!("{{\"name\":\"wave ✓\",\"pad\":\"{}\"}}", "é".repeat(50_000));
    let clip = NewClip {
        name: "wave ✓".into(),
        doc_json: doc.clone(),
        stats: stats(7, Playback::PingPong),
        tags: vec!["wave".into(), "✓".into()],
        joint_names: vec!["root".into()],
        mesh: MeshWrite::None,
    };
    let meta = store.create(clip, OnName::Refuse).await.unwrap();
    assert_eq!(meta.version, 1);
    assert!(server::store::is_clip_id(&meta.id));
    assert_eq!(meta.created_at, meta.updated_at);
    let got = store.get(&meta.id).await.unwrap().expect("the clip is there");
    assert_eq!(got.doc_json, doc);
    assert_eq!(got.meta, meta);
    assert_eq!(got.meta.stats, stats(7, Playback::PingPong));
}

async fn an_unknown_id_is_none_and_writes_to_it_are_not_found(store: Arc<dyn ClipStore>) {
    let id = server::store::new_clip_id();
    assert!(store.get(&id).await.unwrap().is_none());
    assert!(matches!(store.replace(&id, new_clip("x", "{}"), None).await, Err(StoreError::NotFound)));
    assert!(matches!(store.replace(&id, new_clip("x", "{}"), Some(1)).await, Err(StoreError::NotFound)));
    assert!(matches!(store.delete(&id, None).await, Err(StoreError::NotFound)));
}

async fn listing_pages_in_creation_order_and_filters_by_name(store: Arc<dyn ClipStore>) {
    let mut ids = Vec::new();
    for i in 0..7 {
        let name = if i % 2 == 0 { format!("even/{i}") } else { format!("odd/{i}") };
        ids.push(store.create(new_clip(&name, &format!("{{\"i\":{i}}}")), OnName::Refuse).await.unwrap().id);
    }
    let mut seen = Vec::new();
    let mut after = None;
    loop {
        let page =
            store.list(ListQuery { after: after.clone(), name: None, limit: 3, ..ListQuery::default() }).await.unwrap();
        assert!(page.len() <= 3);
        if page.is_empty() {
            break;
        }
        after = Some(page.last().unwrap().id.clone());
        seen.extend(page.into_iter().map(|m| m.id));
    }
    assert_eq!(seen, ids, "every clip once, in creation order");
    let odd = store
        .list(ListQuery { after: None, name_prefix: Some("odd/".into()), limit: 100, ..ListQuery::default() })
        .await
        .unwrap();
    assert_eq!(
        odd.iter().map(|m| m.id.clone()).collect::<Vec<_>>(),
        vec![ids[1].clone(), ids[3].clone(), ids[5].clone()]
    );
    let after_first_odd = store
        .list(ListQuery {
            after: Some(ids[1].clone()),
            name_prefix: Some("odd/".into()),
            limit: 1,
            ..ListQuery::default()
        })
        .await
        .unwrap();
    assert_eq!(after_first_odd.len(), 1);
    assert_eq!(after_first_odd[0].id, ids[3]);
    let one = store.list(ListQuery { name: Some("odd/3".into()), limit: 100, ..ListQuery::default() }).await.unwrap();
    assert_eq!(one.iter().map(|m| m.id.as_str()).collect::<Vec<_>>(), [ids[3].as_str()]);
}

async fn replace_bumps_the_version_and_honours_the_expected_one(store: Arc<dyn ClipStore>) {
    let v1 = store.create(new_clip("a", "{\"v\":1}"), OnName::Refuse).await.unwrap();
    let replacement = NewClip { doc_json: "{\"v\":2}".into(), stats: stats(9, Playback::Once), ..new_clip("b", "") };
    let v2 = store.replace(&v1.id, replacement, Some(1)).await.unwrap();
    assert_eq!((v2.id.as_str(), v2.version, v2.name.as_str()), (v1.id.as_str(), 2, "b"));
    assert_eq!(v2.created_at, v1.created_at);
    assert!(v2.updated_at >= v1.updated_at);
    assert_eq!(v2.stats, stats(9, Playback::Once));
    match store.replace(&v1.id, new_clip("c", "{\"v\":3}"), Some(1)).await {
        Err(StoreError::VersionMismatch { current }) => assert_eq!(current, 2),
        other => panic!("a stale expected version must be refused, got {other:?}"),
    }
    let got = store.get(&v1.id).await.unwrap().unwrap();
    assert_eq!((got.doc_json.as_str(), got.meta.version), ("{\"v\":2}", 2), "the refused replace changed nothing");
    let v3 = store.replace(&v1.id, new_clip("c", "{\"v\":3}"), None).await.unwrap();
    assert_eq!(v3.version, 3);
}

async fn delete_honours_the_expected_version(store: Arc<dyn ClipStore>) {
    let meta = store.create(new_clip("a", "{}"), OnName::Refuse).await.unwrap();
    store.replace(&meta.id, new_clip("a", "{\"v\":2}"), None).await.unwrap();
    match store.delete(&meta.id, Some(1)).await {
        Err(StoreError::VersionMismatch { current }) => assert_eq!(current, 2),
        other => panic!("a stale expected version must be refused, got {other:?}"),
    }
    assert!(store.get(&meta.id).await.unwrap().is_some());
    store.delete(&meta.id, Some(2)).await.unwrap();
    assert!(store.get(&meta.id).await.unwrap().is_none());
    assert!(matches!(store.delete(&meta.id, None).await, Err(StoreError::NotFound)));
}

async fn create_all_stores_every_clip_in_order(store: Arc<dyn ClipStore>) {
    let clips: Vec<NewClip> = (0..5).map(|i| new_clip(&format!("anim{i}"), &format!("{{\"i\":{i}}}"))).collect();
    let metas = store.create_all(clips, OnName::Refuse).await.unwrap();
    assert_eq!(metas.len(), 5);
    let listed = store.list(ListQuery { after: None, name: None, limit: 10, ..ListQuery::default() }).await.unwrap();
    assert_eq!(listed, metas, "listed in creation order, exactly as returned");
    for (i, m) in metas.iter().enumerate() {
        assert_eq!(store.get(&m.id).await.unwrap().unwrap().doc_json, format!("{{\"i\":{i}}}"));
    }
}

async fn concurrent_conditional_replaces_let_exactly_one_win(store: Arc<dyn ClipStore>) {
    let meta = store.create(new_clip("a", "{}"), OnName::Refuse).await.unwrap();
    let tasks: Vec<_> = (0..8)
        .map(|i| {
            let (store, id) = (store.clone(), meta.id.clone());
            tokio::spawn(async move { store.replace(&id, new_clip("a", &format!("{{\"w\":{i}}}")), Some(1)).await })
        })
        .collect();
    let mut wins = 0;
    for t in tasks {
        match t.await.unwrap() {
            Ok(m) => {
                assert_eq!(m.version, 2);
                wins += 1;
            }
            Err(StoreError::VersionMismatch { current }) => assert_eq!(current, 2),
            Err(e) => panic!("unexpected {e:?}"),
        }
    }
    assert_eq!(wins, 1);
    assert_eq!(store.get(&meta.id).await.unwrap().unwrap().meta.version, 2);
}

async fn concurrent_creates_all_land(store: Arc<dyn ClipStore>) {
    let tasks: Vec<_> = (0..16)
        .map(|i| {
            let store = store.clone();
            tokio::spawn(async move {
                store.create(new_clip(&format!("c/{i}"), &format!("{{\"i\":{i}}}")), OnName::Refuse).await.unwrap().id
            })
        })
        .collect();
    let mut ids = Vec::new();
    for t in tasks {
        ids.push(t.await.unwrap());
    }
    let listed = store
        .list(ListQuery { after: None, name_prefix: Some("c/".into()), limit: 100, ..ListQuery::default() })
        .await
        .unwrap();
    let mut listed: Vec<String> = listed.into_iter().map(|m| m.id).collect();
    listed.sort();
    ids.sort();
    assert_eq!(listed, ids);
}

/// Names identify clips: of concurrent creates of one new name exactly one
/// lands, every other is refused naming it; `Replace` makes a new version
/// of the clip holding the name (same id, one row), also under contention;
/// a rename to a taken name is refused, a replace keeping its name is not.
async fn a_name_is_held_by_one_clip_even_under_concurrent_writes(store: Arc<dyn ClipStore>) {
    let tasks: Vec<_> = (0..8)
        .map(|i| {
            let store = store.clone();
            tokio::spawn(async move { store.create(new_clip("walk", &format!("{{\"i\":{i}}}")), OnName::Refuse).await })
        })
        .collect();
    let (mut won, mut taken) = (Vec::new(), 0);
    for t in tasks {
        match t.await.unwrap() {
            Ok(meta) => won.push(meta),
            Err(StoreError::NameTaken { name, .. }) if name == "walk" => taken += 1,
            Err(e) => panic!("unexpected {e:?}"),
        }
    }
    assert_eq!((won.len(), taken), (1, 7), "one create of a new name lands");
    let holder = won.pop().unwrap();
    match store.create(new_clip("walk", "{}"), OnName::Refuse).await {
        Err(StoreError::NameTaken { id, .. }) => assert_eq!(id, holder.id),
        other => panic!("a taken name must be refused, got {other:?}"),
    }
    let replaces: Vec<_> = (0..6)
        .map(|i| {
            let store = store.clone();
            tokio::spawn(
                async move { store.create(new_clip("walk", &format!("{{\"r\":{i}}}")), OnName::Replace).await },
            )
        })
        .collect();
    let mut versions = Vec::new();
    for t in replaces {
        let meta = t.await.unwrap().unwrap();
        assert_eq!(meta.id, holder.id, "a replace by name keeps the id");
        versions.push(meta.version);
    }
    versions.sort();
    assert_eq!(versions, [2, 3, 4, 5, 6, 7], "each replace one new version");
    let named = store.list(ListQuery { name: Some("walk".into()), limit: 10, ..ListQuery::default() }).await.unwrap();
    assert_eq!(named.len(), 1);
    let fresh = store.create(new_clip("run", "{}"), OnName::Replace).await.unwrap();
    assert_eq!(fresh.version, 1, "replace=true of a new name creates");
    match store.replace(&fresh.id, new_clip("walk", "{}"), None).await {
        Err(StoreError::NameTaken { id, .. }) => assert_eq!(id, holder.id),
        other => panic!("a rename to a taken name must be refused, got {other:?}"),
    }
    assert_eq!(store.replace(&fresh.id, new_clip("run", "{\"v\":2}"), None).await.unwrap().version, 2);
}

async fn ping_answers_until_closed(store: Arc<dyn ClipStore>) {
    store.ping().await.unwrap();
    store.close().await;
    assert!(store.ping().await.is_err());
}

mod durability;
mod postgres_only;
mod upgrade;

const SHARE_A_NAME: &str = "UPDATE clips SET name = 'dup' WHERE id = $1 OR id = $2";

/// Two clips made to share a name behind the store's back, as a server
/// from before names were unique could store them: their ids.
async fn two_named_dup(store: &Arc<dyn ClipStore>) -> (String, String) {
    let a = store.create(new_clip("a", "{}"), OnName::Refuse).await.unwrap().id;
    let b = store.create(new_clip("b", "{}"), OnName::Refuse).await.unwrap().id;
    (a, b)
}

/// Clips that already share a name keep it (and may be replaced keeping
/// it); a new clip of that name is refused, and a replace by the name
/// cannot tell which is meant: `AmbiguousName` with both ids.
async fn shared_names_from_before_stay_and_a_replace_by_one_is_ambiguous(
    store: Arc<dyn ClipStore>,
    a: String,
    b: String,
) {
    let named = store.list(ListQuery { name: Some("dup".into()), limit: 10, ..ListQuery::default() }).await.unwrap();
    assert_eq!(named.len(), 2);
    assert!(matches!(store.create(new_clip("dup", "{}"), OnName::Refuse).await, Err(StoreError::NameTaken { .. })));
    match store.create(new_clip("dup", "{}"), OnName::Replace).await {
        Err(StoreError::AmbiguousName { name, mut ids, .. }) => {
            ids.sort();
            let mut expected = vec![a.clone(), b.clone()];
            expected.sort();
            assert_eq!((name.as_str(), ids), ("dup", expected));
        }
        other => panic!("a replace by a shared name must be ambiguous, got {other:?}"),
    }
    assert_eq!(store.replace(&a, new_clip("dup", "{\"v\":2}"), None).await.unwrap().version, 2, "kept name");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sqlite_shared_names_from_before_stay_and_a_replace_by_one_is_ambiguous() {
    let backend = backend::Sqlite::open().await;
    let (a, b) = two_named_dup(&backend.store).await;
    let raw = sqlx::SqlitePool::connect(&format!("sqlite://{}", backend.path.display())).await.unwrap();
    sqlx::query(SHARE_A_NAME).bind(&a).bind(&b).execute(&raw).await.unwrap();
    raw.close().await;
    shared_names_from_before_stay_and_a_replace_by_one_is_ambiguous(backend.store.clone(), a, b).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_shared_names_from_before_stay_and_a_replace_by_one_is_ambiguous() {
    let Some(backend) = backend::Postgres::open("sharednames").await else { return };
    let (a, b) = two_named_dup(&backend.store).await;
    sqlx::query(SHARE_A_NAME).bind(&a).bind(&b).execute(backend.pg.pool()).await.unwrap();
    shared_names_from_before_stay_and_a_replace_by_one_is_ambiguous(backend.store.clone(), a, b).await;
    backend.finish().await;
}

/// A mesh is written in its clip's transaction, read back byte for byte,
/// kept by a replace that says `Keep` (a PATCH), dropped by one that does
/// not (a PUT), and gone with its clip.
async fn a_mesh_is_written_kept_dropped_and_deleted_with_its_clip(store: Arc<dyn ClipStore>) {
    let bytes: Vec<u8> = (0..200_000u32).map(|i| (i * 7 % 251) as u8).collect();
    let mesh = StoredMesh { etag: "\"m-1\"".into(), bytes: bytes.clone().into() };
    let with_mesh = NewClip { mesh: MeshWrite::Set(mesh.clone()), ..new_clip("fox", "{}") };
    let plain = store.create(new_clip("plain", "{}"), OnName::Refuse).await.unwrap();
    let metas = store
        .create_all(vec![with_mesh.clone(), NewClip { name: "fox 2".into(), ..with_mesh }], OnName::Refuse)
        .await
        .unwrap();
    let id = &metas[0].id;
    assert_eq!(store.mesh(id).await.unwrap(), Some(mesh.clone()));
    assert_eq!(store.mesh_tag(id).await.unwrap(), Some(Some(mesh.etag.clone())));
    assert_eq!(store.mesh_tag(&plain.id).await.unwrap(), Some(None), "a clip without a mesh");
    assert_eq!(store.mesh(&plain.id).await.unwrap(), None);
    assert_eq!(store.mesh_tag("no-such-clip").await.unwrap(), None, "no clip at all");

    let patched = NewClip { mesh: MeshWrite::Keep, ..new_clip("renamed", "{}") };
    store.replace(id, patched, Some(1)).await.unwrap();
    assert_eq!(store.mesh(id).await.unwrap(), Some(mesh.clone()), "kept by a patch");
    store.replace(id, new_clip("replaced", "{}"), Some(2)).await.unwrap();
    assert_eq!(store.mesh_tag(id).await.unwrap(), Some(None), "dropped by a put");

    let other = &metas[1].id;
    store.delete(other, None).await.unwrap();
    assert_eq!(store.mesh(other).await.unwrap(), None, "gone with its clip");
    // The deleted clip's mesh row went too: a new row for the same id could be written.
    assert_eq!(store.mesh_tag(other).await.unwrap(), None);
}

fn broadcast(id: &str, created_at: i64) -> StoredBroadcast {
    StoredBroadcast { id: id.to_owned(), definition: format!("{{\"def\":\"{id}\"}}"), created_at, controls: vec![] }
}

fn stored_control(id: &str, seq: u64) -> StoredControl {
    StoredControl { id: id.to_owned(), seq, control: format!("{{\"op\":\"{id}\"}}") }
}

/// The stored form of broadcasts (docs/broadcasts.md): the definition as given, the
/// controls in application order (by `seq`, then id) whatever order they
/// were stored in, gone with their broadcast.
async fn broadcasts_and_their_controls_read_back_in_order(store: Arc<dyn ClipStore>) {
    let (b1, b2) = ("01a20000-0000-7000-8000-000000000001", "01a20000-0000-7000-8000-000000000002");
    store.create_broadcast(broadcast(b1, 1_790_000_000_123_456_789)).await.unwrap();
    store.create_broadcast(broadcast(b2, 7)).await.unwrap();
    assert!(store.create_broadcast(broadcast(b1, 1)).await.is_err(), "one row per id");
    for (id, seq) in [("c", 9), ("b", 4), ("a", 9), ("d", 2)] {
        store.add_broadcast_control(b1, stored_control(id, seq)).await.unwrap();
    }
    let got = store.broadcast(b1).await.unwrap().unwrap();
    assert_eq!(
        (got.definition.as_str(), got.created_at),
        (broadcast(b1, 0).definition.as_str(), 1_790_000_000_123_456_789)
    );
    let order: Vec<(&str, u64)> = got.controls.iter().map(|c| (c.id.as_str(), c.seq)).collect();
    assert_eq!(order, [("d", 2), ("b", 4), ("a", 9), ("c", 9)]);
    assert_eq!(got.controls[0], stored_control("d", 2));
    assert!(store.add_broadcast_control(b1, stored_control("a", 11)).await.is_err(), "control ids are unique");

    let all = store.broadcasts().await.unwrap();
    assert_eq!(all.iter().map(|b| (b.id.as_str(), b.controls.len())).collect::<Vec<_>>(), [(b1, 4), (b2, 0)]);
    assert!(store.delete_broadcast(b1).await.unwrap());
    assert!(!store.delete_broadcast(b1).await.unwrap());
    assert!(store.broadcast(b1).await.unwrap().is_none());
    assert!(matches!(store.add_broadcast_control(b1, stored_control("e", 1)).await, Err(StoreError::NotFound)));
    assert_eq!(store.broadcasts().await.unwrap().len(), 1);
}

/// The idle end across nodes is one conditional delete on `active_at`.
async fn an_idle_broadcast_expires_and_a_touched_one_does_not(store: Arc<dyn ClipStore>) {
    let b = "01a20000-0000-7000-8000-0000000000aa";
    store.create_broadcast(broadcast(b, 0)).await.unwrap();
    let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_millis() as i64;
    // Created (active) just now: not idle since a minute ago.
    assert!(!store.expire_broadcast(b, now - 60_000).await.unwrap());
    store.touch_broadcast(b, now + 60_000).await.unwrap();
    assert!(!store.expire_broadcast(b, now + 30_000).await.unwrap(), "touched later than that");
    assert!(store.expire_broadcast(b, now + 90_000).await.unwrap(), "idle since before then");
    assert!(store.broadcast(b).await.unwrap().is_none());
}

/// A node restoring the newest checkpoint plays what every node plays: a
/// checkpoint is stored only if the controls stored for its ticks (since
/// the previous one) are exactly those its state applied, and a control
/// for a tick a stored checkpoint has passed is refused (its sender's node
/// withdraws it), never kept beside a state that lacks it.
async fn a_stored_checkpoint_holds_exactly_the_stored_controls_of_its_ticks(store: Arc<dyn ClipStore>) {
    let b = "01a20000-0000-7000-8000-0000000000cc";
    store.create_broadcast(broadcast(b, 0)).await.unwrap();
    store.add_broadcast_control(b, stored_control("a", 5)).await.unwrap();
    let at = |seq: u64| StoredCheckpoint { seq, state: format!("state {seq}") };
    let covers = |list: &[(&str, u64)]| Covers {
        from: 0,
        controls: list.iter().map(|(id, seq)| ((*id).to_owned(), *seq)).collect(),
    };
    let newest = || async { store.broadcast_checkpoint(b).await.unwrap().map(|c| c.seq) };

    // A node that has not heard `a`, or that applied `x`, which is not stored: nothing stored.
    assert!(!store.put_broadcast_checkpoint(b, at(10), &[], &covers(&[])).await.unwrap());
    assert!(!store.put_broadcast_checkpoint(b, at(10), &[], &covers(&[("a", 5), ("x", 7)])).await.unwrap());
    assert_eq!(newest().await, None);
    // Exactly the stored ones (a control after the tick is not its business).
    assert!(store.put_broadcast_checkpoint(b, at(10), &[], &covers(&[("a", 5), ("y", 12)])).await.unwrap());
    assert_eq!(newest().await, Some(10));
    assert!(store.broadcast(b).await.unwrap().unwrap().controls.is_empty(), "`a` is in the state now");

    // Heard after the checkpoint was stored: too late for its tick (or the checkpoint's own).
    for (id, seq) in [("late", 8), ("at", 10)] {
        let refused = store.add_broadcast_control(b, stored_control(id, seq)).await;
        assert!(matches!(refused, Err(StoreError::Unavailable(_))), "{id}: {refused:?}");
    }
    store.add_broadcast_control(b, stored_control("next", 11)).await.unwrap();
    let ids: Vec<String> = store.broadcast(b).await.unwrap().unwrap().controls.into_iter().map(|c| c.id).collect();
    assert_eq!(ids, ["next"]);

    // The first of a tick stays; an older one never replaces a newer.
    assert!(!store.put_broadcast_checkpoint(b, at(10), &[], &covers(&[])).await.unwrap());
    assert!(store.put_broadcast_checkpoint(b, at(20), &[], &covers(&[("a", 5), ("next", 11)])).await.unwrap());
    assert!(!store.put_broadcast_checkpoint(b, at(15), &[], &covers(&[("next", 11)])).await.unwrap());
    let stored = store.broadcast_checkpoint(b).await.unwrap().unwrap();
    assert_eq!((stored.seq, stored.state.as_str()), (20, "state 20"));
}
