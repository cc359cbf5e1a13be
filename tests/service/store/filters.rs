//! The list filters as store queries, on both backends: each filter alone
//! and combined, walked a page at a time, against the answer worked out
//! here in plain Rust from the fixture (sets, string tests).

use std::collections::HashSet;
use std::sync::Arc;

use anim::Playback;
use server::store::{ClipStats, ClipStore, ListQuery, MeshWrite, NewClip, OnName, StoreError};

/// One fixture clip: name, tags, joint names, duration.
struct Fixture {
    name: &'static str,
    tags: &'static [&'static str],
    joints: &'static [&'static str],
    duration: f32,
}

const LEGS: &[&str] = &["hips", "spine", "head", "l_leg", "r_leg"];

const FIXTURE: &[Fixture] = &[
    Fixture { name: "walk-fast", tags: &["locomotion", "fast"], joints: LEGS, duration: 2.0 },
    Fixture { name: "walk-slow", tags: &["locomotion"], joints: LEGS, duration: 4.0 },
    Fixture {
        name: "run",
        tags: &["locomotion", "fast"],
        joints: &["hips", "spine", "head", "l_leg", "r_leg", "tail"],
        duration: 1.0,
    },
    Fixture { name: "wave", tags: &["gesture"], joints: &["spine", "head", "l_arm"], duration: 3.0 },
    Fixture {
        name: "upper-walk",
        tags: &[],
        joints: &["hips", "spine", "head", "l_leg", "r_leg", "l_arm", "r_arm"],
        duration: 0.5,
    },
    Fixture { name: "Walk-caps", tags: &["Locomotion"], joints: &["hips"], duration: 2.0 },
    Fixture { name: "wälk ✓", tags: &["fast"], joints: &["hips", "spine"], duration: 2.5 },
    Fixture { name: "walk", tags: &["locomotion"], joints: &["hips", "spine", "head", "l_leg"], duration: 2.0 },
];

fn new_clip(f: &Fixture) -> NewClip {
    let owned = |v: &[&str]| v.iter().map(|s| (*s).to_owned()).collect::<Vec<_>>();
    NewClip {
        name: f.name.to_owned(),
        doc_json: format!("{{\"name\":{:?}}}", f.name),
        stats: ClipStats {
            joints: f.joints.len() as u32,
            tracks: 1,
            events: 0,
            start: 0.5,
            end: 0.5 + f.duration,
            playback: Playback::Once,
        },
        tags: owned(f.tags),
        joint_names: owned(f.joints),
        mesh: MeshWrite::None,
    }
}

/// Stores the fixture; its ids in fixture order.
async fn store_fixture(store: &Arc<dyn ClipStore>) -> Vec<String> {
    let mut ids = Vec::new();
    for f in FIXTURE {
        ids.push(store.create(new_clip(f), OnName::Refuse).await.unwrap().id);
    }
    ids
}

/// Every page of `query` at `page` clips a page, concatenated (ids).
async fn walk(store: &Arc<dyn ClipStore>, query: &ListQuery, page: u32) -> Vec<String> {
    let mut all = Vec::new();
    let mut after = None;
    loop {
        let q = ListQuery { after: after.clone(), limit: page + 1, ..query.clone() };
        let mut got = store.list(q).await.unwrap();
        let more = got.len() > page as usize;
        got.truncate(page as usize);
        all.extend(got.iter().map(|m| m.id.clone()));
        if !more {
            return all;
        }
        after = got.last().map(|m| m.id.clone());
    }
}

fn expected(ids: &[String], keep: impl Fn(&Fixture) -> bool) -> Vec<String> {
    FIXTURE.iter().zip(ids).filter(|(f, _)| keep(f)).map(|(_, id)| id.clone()).collect()
}

fn includes(candidate: &Fixture, reference: &Fixture) -> bool {
    let have: HashSet<&str> = candidate.joints.iter().copied().collect();
    reference.joints.iter().all(|j| have.contains(j))
}

pub async fn every_filter_pages_through_exactly_its_clips(store: Arc<dyn ClipStore>) {
    let ids = store_fixture(&store).await;
    let q = ListQuery::default;
    let cases: Vec<(&str, ListQuery, Vec<String>)> = vec![
        ("no filter", q(), expected(&ids, |_| true)),
        ("name", ListQuery { name: Some("walk".into()), ..q() }, expected(&ids, |f| f.name == "walk")),
        (
            "prefix",
            ListQuery { name_prefix: Some("walk".into()), ..q() },
            expected(&ids, |f| f.name.starts_with("walk")),
        ),
        (
            "prefix, multi-byte",
            ListQuery { name_prefix: Some("wä".into()), ..q() },
            expected(&ids, |f| f.name.starts_with("wä")),
        ),
        (
            "substring",
            ListQuery { name_contains: Some("alk".into()), ..q() },
            expected(&ids, |f| f.name.contains("alk")),
        ),
        (
            "substring is case-sensitive",
            ListQuery { name_contains: Some("Walk".into()), ..q() },
            expected(&ids, |f| f.name.contains("Walk")),
        ),
        ("tag", ListQuery { tag: Some("fast".into()), ..q() }, expected(&ids, |f| f.tags.contains(&"fast"))),
        (
            "tag, exact",
            ListQuery { tag: Some("locomotion".into()), ..q() },
            expected(&ids, |f| f.tags.contains(&"locomotion")),
        ),
        (
            "duration range, inclusive",
            ListQuery { min_duration: Some(2.0), max_duration: Some(3.0), ..q() },
            expected(&ids, |f| (2.0..=3.0).contains(&f.duration)),
        ),
        ("min duration", ListQuery { min_duration: Some(2.5), ..q() }, expected(&ids, |f| f.duration >= 2.5)),
        ("max duration", ListQuery { max_duration: Some(1.0), ..q() }, expected(&ids, |f| f.duration <= 1.0)),
        (
            "compatible with walk-fast",
            ListQuery { compatible_with: Some(ids[0].clone()), ..q() },
            expected(&ids, |f| includes(f, &FIXTURE[0])),
        ),
        (
            "compatible with wave",
            ListQuery { compatible_with: Some(ids[3].clone()), ..q() },
            expected(&ids, |f| includes(f, &FIXTURE[3])),
        ),
        (
            "combined: prefix, tag, duration, compatible with walk",
            ListQuery {
                name_prefix: Some("walk".into()),
                tag: Some("locomotion".into()),
                max_duration: Some(3.0),
                compatible_with: Some(ids[7].clone()),
                ..q()
            },
            expected(&ids, |f| {
                f.name.starts_with("walk")
                    && f.tags.contains(&"locomotion")
                    && f.duration <= 3.0
                    && includes(f, &FIXTURE[7])
            }),
        ),
    ];
    for (what, query, want) in cases {
        assert!(!want.is_empty() || what.contains("none"), "{what}: the fixture should match something");
        for page in [1, 2, 100] {
            assert_eq!(walk(&store, &query, page).await, want, "{what}, pages of {page}");
        }
    }
    // The reference set itself: walk-fast's superset list holds walk-fast,
    // walk-slow, run and upper-walk (worked out by hand, too).
    let compatible = walk(&store, &ListQuery { compatible_with: Some(ids[0].clone()), ..q() }, 10).await;
    assert_eq!(compatible, vec![ids[0].clone(), ids[1].clone(), ids[2].clone(), ids[4].clone()]);

    let unknown = ListQuery { compatible_with: Some(server::store::new_clip_id()), limit: 10, ..q() };
    assert!(matches!(store.list(unknown).await, Err(StoreError::NotFound)));
}

pub async fn tags_and_joints_follow_replace_and_delete(store: Arc<dyn ClipStore>) {
    let ids = store_fixture(&store).await;
    let tagged = |tag: &str| ListQuery { tag: Some(tag.into()), limit: 100, ..ListQuery::default() };
    let listed = |q: ListQuery| {
        let store = store.clone();
        async move { store.list(q).await.unwrap().into_iter().map(|m| m.id).collect::<Vec<_>>() }
    };
    // Replace: wave becomes a "fast" clip on the legs skeleton; its old tag and joints are gone.
    let replaced = Fixture { name: "wave", tags: &["fast", "new"], joints: LEGS, duration: 3.0 };
    let meta = store.replace(&ids[3], new_clip(&replaced), None).await.unwrap();
    assert_eq!(meta.tags, vec!["fast".to_owned(), "new".to_owned()]);
    assert_eq!(store.get(&ids[3]).await.unwrap().unwrap().meta.tags, meta.tags);
    assert!(listed(tagged("gesture")).await.is_empty());
    assert_eq!(listed(tagged("new")).await, vec![ids[3].clone()]);
    let compatible = ListQuery { compatible_with: Some(ids[0].clone()), limit: 100, ..ListQuery::default() };
    assert!(listed(compatible.clone()).await.contains(&ids[3]), "wave now has every joint of walk-fast");
    // A failed conditional replace changes nothing.
    let stale = Fixture { name: "wave", tags: &["stale"], joints: &["x"], duration: 1.0 };
    assert!(matches!(store.replace(&ids[3], new_clip(&stale), Some(1)).await, Err(StoreError::VersionMismatch { .. })));
    assert!(listed(tagged("stale")).await.is_empty());
    // Delete: the tag rows and joint rows go with the clip.
    store.delete(&ids[3], None).await.unwrap();
    assert!(listed(tagged("new")).await.is_empty());
    assert!(!listed(compatible).await.contains(&ids[3]));
    store.delete(&ids[0], None).await.unwrap();
    let gone = ListQuery { compatible_with: Some(ids[0].clone()), limit: 10, ..ListQuery::default() };
    assert!(matches!(store.list(gone).await, Err(StoreError::NotFound)));
}
