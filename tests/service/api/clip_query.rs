//! `GET /v1/clips` filters over HTTP, on a server on SQLite and one on
//! PostgreSQL: each filter walked a page at a time equals the answer worked
//! out here from the uploaded documents; bad filters are refused with their
//! parameter; gRPC `ListClips` filters the same way.

use std::collections::HashSet;

use formats::wire::proto::pb;
use serde_json::{Value, json};
use server::config::{Secret, StoreConfig};

use super::TestApp;
use crate::common::pg::Schema;

/// (name, tags, joints, duration): each becomes a clip with one
/// translation track per joint from 0 to `duration` seconds.
type Row = (&'static str, &'static [&'static str], &'static [&'static str], f32);

const LEGS: &[&str] = &["hips", "l_leg", "r_leg"];

const ROWS: &[Row] = &[
    ("walk", &["locomotion"], LEGS, 2.0),
    ("walk-slow", &["locomotion", "slow"], LEGS, 4.0),
    ("run", &["locomotion", "fast"], &["hips", "l_leg", "r_leg", "tail"], 1.0),
    ("wave", &["gesture"], &["hips", "l_arm"], 3.0),
    ("Walk-upper", &[], &["hips", "l_leg", "r_leg", "l_arm"], 0.5),
    ("sidewalk", &["locomotion"], &["hips"], 2.5),
];

fn doc(&(name, tags, joints, duration): &Row) -> String {
    let tracks: Vec<Value> = joints
        .iter()
        .map(|j| json!({"joint": j, "channel": "translation", "times": [0.0, duration], "values": [[0, 0, 0], [1, 0, 0]]}))
        .collect();
    json!({"name": name, "tags": tags, "tracks": tracks}).to_string()
}

/// Every page of `/v1/clips?{query}` at `limit` a page: the ids.
async fn walk(app: &TestApp, query: &str, limit: u32) -> Vec<String> {
    let (mut ids, mut cursor) = (Vec::new(), None::<String>);
    loop {
        let mut url = format!("/v1/clips?{query}&limit={limit}");
        if let Some(c) = &cursor {
            url.push_str(&format!("&cursor={c}"));
        }
        let page = app.get_json(&url).await;
        let clips = page["clips"].as_array().unwrap_or_else(|| panic!("{url}: {page}"));
        assert!(clips.len() <= limit as usize);
        ids.extend(clips.iter().map(|c| c["id"].as_str().unwrap().to_owned()));
        match page["next_cursor"].as_str() {
            Some(c) => cursor = Some(c.to_owned()),
            None => return ids,
        }
    }
}

async fn filters_answer_exactly_their_clips(app: &TestApp) {
    let mut ids = Vec::new();
    for row in ROWS {
        ids.push(app.create_id(&doc(row), None).await);
    }
    let select = |keep: &dyn Fn(&Row) -> bool| -> Vec<String> {
        ROWS.iter().zip(&ids).filter(|(r, _)| keep(r)).map(|(_, id)| id.clone()).collect()
    };
    let superset_of = |reference: usize| {
        let want: HashSet<&str> = ROWS[reference].2.iter().copied().collect();
        move |r: &Row| want.iter().all(|j| r.2.contains(j))
    };
    let cases: Vec<(String, Vec<String>)> = vec![
        ("name=walk".into(), select(&|r| r.0 == "walk")),
        ("name_prefix=walk".into(), select(&|r| r.0.starts_with("walk"))),
        ("name_prefix=W".into(), select(&|r| r.0.starts_with('W'))),
        ("name_contains=walk".into(), select(&|r| r.0.contains("walk"))),
        ("tag=locomotion".into(), select(&|r| r.1.contains(&"locomotion"))),
        ("min_duration=2&max_duration=3".into(), select(&|r| (2.0..=3.0).contains(&r.3))),
        ("max_duration=1".into(), select(&|r| r.3 <= 1.0)),
        (format!("compatible_with={}", ids[0]), select(&superset_of(0))),
        (format!("compatible_with={}", ids[3]), select(&superset_of(3))),
        (format!("tag=locomotion&min_duration=1.5&compatible_with={}", ids[0]), {
            let compatible = superset_of(0);
            select(&|r| r.1.contains(&"locomotion") && r.3 >= 1.5 && compatible(r))
        }),
    ];
    for (query, want) in cases {
        assert!(!want.is_empty(), "{query} should match something");
        for limit in [1, 2, 100] {
            assert_eq!(walk(app, &query, limit).await, want, "{query}, limit {limit}");
        }
    }
    // By hand, for the skeleton rule: walk's joints (hips, l_leg, r_leg) are
    // in walk, walk-slow, run and Walk-upper, not in wave or sidewalk.
    let compatible = walk(app, &format!("compatible_with={}", ids[0]), 10).await;
    assert_eq!(compatible, [&ids[0], &ids[1], &ids[2], &ids[4]].map(String::clone));
}

async fn bad_filters_are_refused_with_their_parameter(app: &TestApp) {
    let unknown = server::store::new_clip_id();
    let cases = [
        ("min_duration=-1".to_owned(), 422, "bad_duration_range", "min_duration"),
        ("min_duration=3&max_duration=2".to_owned(), 422, "bad_duration_range", "min_duration"),
        ("max_duration=soon".to_owned(), 400, "bad_number", "max_duration"),
        ("max_duration=inf".to_owned(), 400, "bad_number", "max_duration"),
        ("name_prefix=".to_owned(), 400, "bad_filter", "name_prefix"),
        ("tag=".to_owned(), 400, "bad_filter", "tag"),
        (format!("name_contains={}", "x".repeat(257)), 400, "bad_filter", "name_contains"),
        (format!("compatible_with={unknown}"), 404, "clip_not_found", "compatible_with"),
        ("compatible_with=nope".to_owned(), 404, "clip_not_found", "compatible_with"),
        ("joint=hips".to_owned(), 400, "unknown_parameter", "joint"),
    ];
    for (query, status, code, parameter) in cases {
        let resp = app.http.get(app.url(&format!("/v1/clips?{query}"))).send().await.unwrap();
        let got = resp.status().as_u16();
        let problem: Value = resp.json().await.unwrap();
        assert_eq!(
            (got, problem["code"].as_str(), problem["parameter"].as_str()),
            (status, Some(code), Some(parameter)),
            "{query}: {problem}"
        );
    }
}

#[tokio::test]
async fn filters_on_sqlite() {
    let app = TestApp::start().await;
    filters_answer_exactly_their_clips(&app).await;
    bad_filters_are_refused_with_their_parameter(&app).await;
    app.stop().await;
}

#[tokio::test]
async fn filters_on_postgres() {
    let Some(schema) = Schema::create("apifilters").await else { return };
    let url = schema.url("");
    let app = TestApp::builder().configure(|c| c.store = StoreConfig::Postgres(Secret::new(url))).start().await;
    filters_answer_exactly_their_clips(&app).await;
    bad_filters_are_refused_with_their_parameter(&app).await;
    app.stop().await;
    schema.drop_now().await;
}

#[tokio::test]
async fn grpc_list_clips_filters_like_rest() {
    let app = TestApp::start().await;
    let mut ids = Vec::new();
    for row in ROWS {
        ids.push(app.create_id(&doc(row), None).await);
    }
    let mut grpc = app.grpc().await;
    let list = |req: pb::ListClipsRequest| {
        let mut grpc = grpc.clone();
        async move { grpc.list_clips(req).await }
    };
    let ids_of = |r: pb::ListClipsResponse| r.clips.into_iter().map(|c| c.id).collect::<Vec<_>>();
    let cases = [
        ("name_prefix=walk", pb::ListClipsRequest { name_prefix: "walk".into(), ..Default::default() }),
        ("name_contains=walk", pb::ListClipsRequest { name_contains: "walk".into(), ..Default::default() }),
        ("tag=locomotion", pb::ListClipsRequest { tag: "locomotion".into(), ..Default::default() }),
        (
            "min_duration=2&max_duration=3",
            pb::ListClipsRequest { min_duration: Some(2.0), max_duration: Some(3.0), ..Default::default() },
        ),
    ];
    for (query, req) in cases {
        let rest = walk(&app, query, 100).await;
        assert_eq!(ids_of(list(req).await.unwrap().into_inner()), rest, "{query}");
    }
    let compatible = pb::ListClipsRequest { compatible_with: ids[0].clone(), limit: 2, ..Default::default() };
    let first = list(compatible.clone()).await.unwrap().into_inner();
    let next = pb::ListClipsRequest { cursor: first.next_cursor.clone(), ..compatible };
    let mut got = ids_of(first);
    got.extend(ids_of(list(next).await.unwrap().into_inner()));
    assert_eq!(got, walk(&app, &format!("compatible_with={}", ids[0]), 100).await);
    let tagged = list(pb::ListClipsRequest { tag: "fast".into(), ..Default::default() }).await.unwrap().into_inner();
    assert_eq!(tagged.clips[0].tags, ["locomotion", "fast"]);

    let unknown = pb::ListClipsRequest { compatible_with: server::store::new_clip_id(), ..Default::default() };
    let status = list(unknown).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::NotFound, "{status:?}");
    let reversed = pb::ListClipsRequest { min_duration: Some(3.0), max_duration: Some(1.0), ..Default::default() };
    let status = list(reversed).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    assert!(status.message().contains("bad_duration_range"), "{status:?}");

    // PutClip carries tags and metadata; GetClip gives them back.
    let clip = crate::security::wave_pb();
    let put = pb::PutClipRequest {
        clip: Some(clip),
        replace: true,
        tags: vec!["grpc".into()],
        metadata_json: r#"{"from":"grpc"}"#.into(),
        ..Default::default()
    };
    let created = grpc.put_clip(put).await.unwrap().into_inner();
    assert_eq!(created.tags, ["grpc"]);
    let record = grpc.get_clip(pb::GetClipRequest { clip_id: created.id.clone() }).await.unwrap().into_inner();
    assert_eq!(serde_json::from_str::<Value>(&record.metadata_json).unwrap(), json!({"from": "grpc"}));
    let bad = pb::PutClipRequest { clip: record.clip, metadata_json: "[1]".into(), ..Default::default() };
    assert_eq!(grpc.put_clip(bad).await.unwrap_err().code(), tonic::Code::InvalidArgument);
    app.stop().await;
}

/// Two nodes on one PostgreSQL: a PATCH on one reaches the other's cache
/// through the store's notification, like any replace (the skeleton route
/// answers from the cache, so it shows the version the node holds).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_patch_on_one_node_reaches_the_others_cache() {
    let Some(schema) = Schema::create("patchnodes").await else { return };
    let node =
        |url: String| TestApp::builder().configure(|c| c.store = StoreConfig::Postgres(Secret::new(url))).start();
    let (a, b) = (node(schema.url("")).await, node(schema.url("")).await);
    let id = a.create_id(super::WAVE, None).await;
    let path = format!("/v1/clips/{id}/skeleton");
    assert_eq!(b.get_json(&path).await["version"], 1, "b has cached version 1");
    let resp = a.http.patch(a.url(&format!("/v1/clips/{id}"))).header("content-type", "application/json");
    let resp = resp.header("if-match", "\"1\"").body(r#"{"name":"patched on a"}"#).send().await.unwrap();
    assert_eq!(resp.status(), 200);
    let five = std::time::Duration::from_secs(5);
    let seen = crate::common::eventually_some(five, "b serves version 2", || async {
        let seen = b.get_json(&path).await;
        (seen["version"] == 2).then_some(seen)
    })
    .await;
    assert_eq!(seen["name"], "patched on a");
    a.stop().await;
    b.stop().await;
    schema.drop_now().await;
}
