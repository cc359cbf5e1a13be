//! Characters in the store, on both backends: read back exactly, versions
//! and `If-Match`, name filters, names held under concurrent writes, the
//! `name:` reference, meshes, and a clip import's clips and characters
//! refused together.

use std::sync::Arc;

use server::store::{
    CharacterQuery, ClipStore, ListQuery, MeshWrite, NameFilters, NewCharacter, OnName, StoreError, StoredMesh,
};

use super::new_clip;

pub fn new_character(name: &str, doc: &str) -> NewCharacter {
    NewCharacter {
        name: name.to_owned(),
        doc_json: doc.to_owned(),
        joints: 3,
        roles_json: r#"{"roles":{"hips":{"joint":"Hips","by":"name"}},"family":null}"#.to_owned(),
        mesh: MeshWrite::None,
    }
}

fn named(prefix: &str) -> CharacterQuery {
    CharacterQuery { names: NameFilters { name_prefix: Some(prefix.into()), ..NameFilters::default() }, limit: 100 }
}

pub async fn a_character_reads_back_and_versions_like_a_clip(store: Arc<dyn ClipStore>) {
    let doc = format!("{{\"name\":\"fox ✓\",\"pad\":\"{}\"}}", "é".repeat(10_000));
    let made = store.create_characters(vec![new_character("rigs/fox", &doc)], OnName::Refuse).await.unwrap();
    let meta = &made[0];
    assert_eq!((meta.version, meta.joints, meta.mesh), (1, 3, false));
    let got = store.character(&meta.id).await.unwrap().unwrap();
    assert_eq!((&got.meta, got.doc_json.as_str()), (meta, doc.as_str()));
    assert_eq!(store.character_by_ref("name:rigs/fox").await.unwrap().unwrap().meta.id, meta.id);
    assert_eq!(store.character_by_ref(&meta.id).await.unwrap().unwrap().meta.id, meta.id);
    assert!(store.character_by_ref("name:rigs/wolf").await.unwrap().is_none());
    // Characters and clips are separate: a clip of the same name is no character.
    store.create(new_clip("rigs/fox", "{}"), OnName::Refuse).await.unwrap();
    assert!(
        store
            .character(&store.list(ListQuery { limit: 100, ..ListQuery::default() }).await.unwrap()[0].id)
            .await
            .unwrap()
            .is_none()
    );

    assert!(matches!(
        store.replace_character(&meta.id, new_character("rigs/fox", "{}"), Some(7)).await,
        Err(StoreError::VersionMismatch { current: 1 })
    ));
    let replaced = store.replace_character(&meta.id, new_character("rigs/fox", "{\"v\":2}"), Some(1)).await.unwrap();
    assert_eq!((replaced.id.as_str(), replaced.version, replaced.created_at), (meta.id.as_str(), 2, meta.created_at));
    assert!(matches!(store.delete_character(&meta.id, Some(1)).await, Err(StoreError::VersionMismatch { current: 2 })));
    store.delete_character(&meta.id, Some(2)).await.unwrap();
    assert!(store.character(&meta.id).await.unwrap().is_none());
    assert!(matches!(store.delete_character(&meta.id, None).await, Err(StoreError::NotFound)));
    assert!(matches!(
        store.replace_character(&meta.id, new_character("x", "{}"), None).await,
        Err(StoreError::NotFound)
    ));
}

pub async fn characters_list_by_name_in_creation_order(store: Arc<dyn ClipStore>) {
    for name in ["fox/a", "fox/b", "foxes", "wolf/a", "fox/c"] {
        store.create_characters(vec![new_character(name, "{}")], OnName::Refuse).await.unwrap();
    }
    let names = |page: Vec<server::store::CharacterMeta>| page.into_iter().map(|m| m.name).collect::<Vec<_>>();
    assert_eq!(names(store.list_characters(named("fox/")).await.unwrap()), ["fox/a", "fox/b", "fox/c"]);
    let first = store.list_characters(CharacterQuery { limit: 2, ..named("fox") }).await.unwrap();
    let after = first.last().unwrap().id.clone();
    assert_eq!(names(first), ["fox/a", "fox/b"]);
    let rest = CharacterQuery { names: NameFilters { after: Some(after), ..named("fox").names }, limit: 10 };
    assert_eq!(names(store.list_characters(rest).await.unwrap()), ["foxes", "fox/c"]);
}

pub async fn a_character_name_is_held_by_one_even_under_concurrent_writes(store: Arc<dyn ClipStore>) {
    let tasks: Vec<_> = (0..8)
        .map(|i| {
            let store = store.clone();
            let character = new_character("hero", &format!("{{\"i\":{i}}}"));
            tokio::spawn(async move { store.create_characters(vec![character], OnName::Refuse).await })
        })
        .collect();
    let (mut won, mut taken) = (Vec::new(), 0);
    for t in tasks {
        match t.await.unwrap() {
            Ok(mut metas) => won.push(metas.pop().unwrap()),
            Err(StoreError::NameTaken { name, what, .. }) if name == "hero" && what == "character" => taken += 1,
            Err(e) => panic!("unexpected {e:?}"),
        }
    }
    assert_eq!((won.len(), taken), (1, 7), "one create of a new name lands");
    let holder = won.pop().unwrap();
    let replaces: Vec<_> = (0..5)
        .map(|i| {
            let store = store.clone();
            let character = new_character("hero", &format!("{{\"r\":{i}}}"));
            tokio::spawn(async move { store.create_characters(vec![character], OnName::Replace).await })
        })
        .collect();
    let mut versions = Vec::new();
    for t in replaces {
        let meta = t.await.unwrap().unwrap().pop().unwrap();
        assert_eq!(meta.id, holder.id, "a replace by name keeps the id");
        versions.push(meta.version);
    }
    versions.sort();
    assert_eq!(versions, [2, 3, 4, 5, 6]);
    let other = store.create_characters(vec![new_character("sidekick", "{}")], OnName::Refuse).await.unwrap();
    match store.replace_character(&other[0].id, new_character("hero", "{}"), None).await {
        Err(StoreError::NameTaken { id, .. }) => assert_eq!(id, holder.id),
        other => panic!("a rename to a taken name must be refused, got {other:?}"),
    }
}

pub async fn a_character_mesh_is_kept_and_dropped_by_a_replace(store: Arc<dyn ClipStore>) {
    let mesh = StoredMesh { etag: "\"m1\"".into(), bytes: bytes::Bytes::from_static(b"INBM mesh") };
    let mut skinned = new_character("skinned", "{}");
    skinned.mesh = MeshWrite::Set(mesh.clone());
    let meta = store.create_characters(vec![skinned], OnName::Refuse).await.unwrap().pop().unwrap();
    assert!(meta.mesh);
    assert_eq!(store.character_mesh_tag(&meta.id).await.unwrap(), Some(Some("\"m1\"".into())));
    assert_eq!(store.character_mesh(&meta.id).await.unwrap(), Some(mesh));
    assert!(store.character(&meta.id).await.unwrap().unwrap().meta.mesh);
    // A replace from JSON drops it (the new skeleton may not fit it).
    let replaced = store.replace_character(&meta.id, new_character("skinned", "{}"), None).await.unwrap();
    assert!(!replaced.mesh);
    assert_eq!(store.character_mesh_tag(&meta.id).await.unwrap(), Some(None));
    assert_eq!(store.character_mesh_tag("no-such-id").await.unwrap(), None);
}

/// A clip import whose character's name is taken stores none of its clips.
pub async fn an_import_writes_its_clips_and_characters_together_or_not_at_all(store: Arc<dyn ClipStore>) {
    store.create_characters(vec![new_character("cesium", "{}")], OnName::Refuse).await.unwrap();
    let refused = store
        .create_clips_and_characters(
            vec![new_clip("cesium/walk", "{}")],
            vec![new_character("cesium", "{}")],
            OnName::Refuse,
        )
        .await;
    assert!(matches!(refused, Err(StoreError::NameTaken { what: "character", .. })), "{refused:?}");
    assert!(
        store.list(ListQuery { limit: 100, ..ListQuery::default() }).await.unwrap().is_empty(),
        "no clip of the refused import"
    );
    let (clips, characters) = store
        .create_clips_and_characters(
            vec![new_clip("cesium/walk", "{}")],
            vec![new_character("cesium", "{}")],
            OnName::Replace,
        )
        .await
        .unwrap();
    assert_eq!((clips.len(), clips[0].version, characters[0].version), (1, 1, 2));
}
