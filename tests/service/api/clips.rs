//! Clip CRUD: round trip, pagination, filters, conditional writes.

use serde_json::Value;

use super::{TestApp, WAVE, canonical, uniform_clip};

#[tokio::test]
async fn an_uploaded_clip_comes_back_as_accepted() {
    let app = TestApp::start().await;
    let resp =
        app.http.post(app.url("/v1/clips")).header("content-type", "application/json").body(WAVE).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let location = resp.headers()["location"].to_str().unwrap().to_owned();
    assert_eq!(resp.headers()["etag"], "\"1\"");
    let summary: Value = resp.json().await.unwrap();
    let id = summary["id"].as_str().unwrap();
    assert_eq!(location, format!("/v1/clips/{id}"));
    // Figures of the docs/clip-format.md §1 example, counted by hand: 2 joints, 2 tracks,
    // keys from 0 to 3, one event, loop playback.
    assert_eq!(summary["name"], "wave");
    assert_eq!(summary["version"], 1);
    assert_eq!((summary["joints"].as_u64(), summary["tracks"].as_u64()), (Some(2), Some(2)));
    assert_eq!((summary["start"].as_f64(), summary["end"].as_f64()), (Some(0.0), Some(3.0)));
    assert_eq!(summary["duration"].as_f64(), Some(3.0));
    assert_eq!(summary["playback"], "loop");
    assert_eq!(summary["events"], 1);
    assert_eq!(summary["etag"], "\"1\"");
    assert!(summary["created_at"].as_str().unwrap().ends_with('Z'));

    let resp = app.http.get(app.url(&location)).send().await.unwrap();
    assert_eq!(resp.status(), 200);
    assert_eq!(resp.headers()["etag"], "\"1\"");
    assert_eq!(resp.headers()["content-type"], "application/json");
    let body = resp.text().await.unwrap();
    assert_eq!(body, canonical(WAVE), "GET returns the canonical document");
    let original = formats::wire::json::parse_clip_doc(WAVE.as_bytes()).unwrap();
    let back = formats::wire::json::parse_clip_doc(body.as_bytes()).unwrap();
    assert_eq!(back, original, "the document means what was uploaded");

    let resp = app.http.get(app.url(&location)).header("if-none-match", "\"1\"").send().await.unwrap();
    assert_eq!(resp.status(), 304);
    app.stop().await;
}

#[tokio::test]
async fn pagination_walks_every_clip_exactly_once_in_creation_order() {
    let app = TestApp::start().await;
    let mut ids = Vec::new();
    for i in 0..23 {
        let name = if i % 3 == 0 { format!("even-third/{i}") } else { format!("other/{i}") };
        let s = app.create(&uniform_clip(&name, 1, 2, i as f32), None).await;
        ids.push(s["id"].as_str().unwrap().to_owned());
    }
    for page in [1, 5, 23, 100] {
        let listed: Vec<String> =
            app.list_all(page, None).await.iter().map(|s| s["id"].as_str().unwrap().to_owned()).collect();
        assert_eq!(listed, ids, "page size {page}");
    }
    let body: Value = app.get_json("/v1/clips?name_prefix=even-third/&limit=3").await;
    let first: Vec<&str> = body["clips"].as_array().unwrap().iter().map(|c| c["id"].as_str().unwrap()).collect();
    assert_eq!(first, [&ids[0], &ids[3], &ids[6]]);
    let next = body["next_cursor"].as_str().unwrap();
    let body: Value = app.get_json(&format!("/v1/clips?name_prefix=even-third/&limit=10&cursor={next}")).await;
    let rest: Vec<&str> = body["clips"].as_array().unwrap().iter().map(|c| c["id"].as_str().unwrap()).collect();
    let expected: Vec<&str> = ids.iter().skip(9).step_by(3).map(String::as_str).collect();
    assert_eq!(rest, expected);
    assert!(body["next_cursor"].is_null());
    app.stop().await;
}

#[tokio::test]
async fn replace_honours_if_match_and_delete_removes() {
    let app = TestApp::start().await;
    let s = app.create(&uniform_clip("a", 2, 2, 1.0), None).await;
    let url = app.url(&format!("/v1/clips/{}", s["id"].as_str().unwrap()));
    let v2 = uniform_clip("a2", 2, 2, 2.0);

    let put = |if_match: &'static str, body: String| {
        app.http.put(&url).header("content-type", "application/json").header("if-match", if_match).body(body).send()
    };
    // Stale tag: 412 and nothing changes.
    let resp = put("\"7\"", v2.clone()).await.unwrap();
    assert_eq!(resp.status(), 412);
    assert_eq!(resp.json::<Value>().await.unwrap()["code"], "version_mismatch");
    assert_eq!(
        app.http.get(&url).send().await.unwrap().text().await.unwrap(),
        canonical(&uniform_clip("a", 2, 2, 1.0))
    );

    let resp = put("\"1\"", v2.clone()).await.unwrap();
    assert_eq!(resp.status(), 200);
    assert_eq!(resp.headers()["etag"], "\"2\"");
    let summary: Value = resp.json().await.unwrap();
    assert_eq!((summary["version"].as_u64(), summary["name"].as_str()), (Some(2), Some("a2")));
    // A list containing the current tag matches; `*` matches any version.
    assert_eq!(put("\"1\", \"2\"", v2.clone()).await.unwrap().status(), 200);
    assert_eq!(put("*", v2.clone()).await.unwrap().status(), 200);
    let resp = app.http.get(&url).send().await.unwrap();
    assert_eq!(resp.headers()["etag"], "\"4\"");
    assert_eq!(resp.text().await.unwrap(), canonical(&v2));
    // Pose requests see the replaced version at once (write-through cache).
    let pose: Value = app.http.get(format!("{url}/pose?t=0.5")).send().await.unwrap().json().await.unwrap();
    assert_eq!(pose["joints"][0]["translation"], serde_json::json!([2.0, 2.0, 2.0]));

    assert_eq!(app.http.delete(&url).header("if-match", "\"3\"").send().await.unwrap().status(), 412);
    assert_eq!(app.http.delete(&url).header("if-match", "\"4\"").send().await.unwrap().status(), 204);
    assert_eq!(app.http.get(&url).send().await.unwrap().status(), 404);
    assert_eq!(app.http.get(format!("{url}/pose?t=0")).send().await.unwrap().status(), 404);
    assert_eq!(app.http.delete(&url).send().await.unwrap().status(), 404);
    assert!(app.list_all(10, None).await.is_empty());
    app.stop().await;
}

#[tokio::test]
async fn the_name_filter_decodes_query_escapes() {
    let app = TestApp::start().await;
    let name = "walk cycle/ä&b+c=1";
    let id = app.create(&uniform_clip(name, 1, 2, 0.0), None).await["id"].as_str().unwrap().to_owned();
    app.create(&uniform_clip("walk cycle", 1, 2, 0.0), None).await;
    // Percent-encoded (as reqwest's query builder sends it) and with `+` for spaces.
    let encoded = app.http.get(app.url("/v1/clips")).query(&[("name", name)]).send().await.unwrap();
    let plus = app.http.get(app.url("/v1/clips?name=walk+cycle%2F%C3%A4%26b%2Bc%3D1")).send().await.unwrap();
    for resp in [encoded, plus] {
        let body: Value = resp.json().await.unwrap();
        let ids: Vec<&str> = body["clips"].as_array().unwrap().iter().map(|c| c["id"].as_str().unwrap()).collect();
        assert_eq!(ids, [id.as_str()]);
    }
    app.stop().await;
}
