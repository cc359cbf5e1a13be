//! The clip library in the browser: rows that tell clips apart (short id,
//! version, joints, duration, tags, a thumbnail made once per version and
//! kept in IndexedDB), the filter by name and tag, and rename, replace and
//! delete from the row, which need the write token.

use std::path::Path;

use serde_json::{Value, json};

use super::{TOKEN, set_value, start, text};
use crate::common::{TestApp, WAVE};

/// The clip document of `examples/wave.json` under another name, with tags.
fn wave_named(name: &str, tags: &[&str]) -> String {
    let mut doc: Value = serde_json::from_str(WAVE).unwrap();
    doc["name"] = json!(name);
    doc["tags"] = json!(tags);
    doc.to_string()
}

/// The clip's summary as the REST API gives it now (`null` once deleted).
async fn summary(app: &TestApp, id: &str) -> Value {
    let resp = app.http.get(app.url(&format!("/v1/clips/{id}/skeleton"))).send().await.unwrap();
    if resp.status() == 404 {
        return Value::Null;
    }
    resp.json().await.unwrap()
}

/// The texts of the rows shown, in order: name, facts (id, version, updated), shape (joints, duration), tags.
const ROWS: &str = "[...document.querySelectorAll('#clips li')].map(li => [li.querySelector('.name').textContent, \
                    li.querySelector('.facts').textContent, li.querySelector('.shape').textContent, li.querySelector('.tags').textContent])";

/// Clicks the button labelled `label` in the row of clip `id`.
fn click_in_row(id: &str, label: &str) -> String {
    format!(
        "[...document.querySelector('#clips li[data-id={}]').querySelectorAll('button')].find(b => b.textContent === {}).click()",
        json!(id),
        json!(label)
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_library_tells_clips_apart_and_renames_replaces_and_deletes() {
    let app = start().await;
    let wave = app.create_id(&wave_named("wave", &[]), Some(TOKEN)).await;
    let greeting = app.create_id(&wave_named("arm-wave", &["greeting", "arm"]), Some(TOKEN)).await;
    let Some(mut browser) = super::cdp::Browser::launch().await else { return };
    let page = &mut browser.page;
    page.navigate(&app.url("/viewer")).await;
    page.wait_for("document.querySelectorAll('#clips li').length === 2", 10).await;

    // Each row: the id's last 8 characters, the version, joints, duration (rounded), tags.
    let rows: Vec<(String, String, String, String)> = serde_json::from_value(page.eval(ROWS).await).unwrap();
    assert_eq!(rows[0].0, "wave");
    for ((name, facts, shape, tags), id) in rows.iter().zip([&wave, &greeting]) {
        assert!(facts.starts_with(&format!("…{} · v1 · ", &id[id.len() - 8..])), "{name}: {facts}");
        assert_eq!(shape, "2 joints · 3 s", "{name}");
        let expected = if name == "arm-wave" { "#greeting #arm" } else { "" };
        assert_eq!(tags, expected);
    }

    // The filter: a name or a tag, any case; `tag:` exactly.
    for (filter, shown) in [
        ("GREET", vec!["arm-wave"]),
        ("tag:arm", vec!["arm-wave"]),
        ("tag:ar", vec![]),
        ("wave", vec!["wave", "arm-wave"]),
    ] {
        set_value(page, "filter", filter).await;
        let names = page.eval("[...document.querySelectorAll('#clips li .name')].map(n => n.textContent)").await;
        assert_eq!(names, json!(shown), "filter {filter:?}");
    }

    // A thumbnail per clip: its skeleton drawn (light pixels on the dark square), made once.
    page.wait_for("document.querySelectorAll('#clips canvas[data-thumb]').length === 2", 15).await;
    let thumbs = page
        .eval(
            "[...document.querySelectorAll('#clips canvas.thumb')].map(c => { const d = c.getContext('2d')\
             .getImageData(0, 0, c.width, c.height).data; let lit = 0; for (let i = 0; i < d.length; i += 4) \
             if (d[i] > 120 && d[i + 1] > 120 && d[i + 2] > 120) lit++; return [c.dataset.thumb, lit]; })",
        )
        .await;
    let thumbs: Vec<(String, u32)> = serde_json::from_value(thumbs).unwrap();
    assert_eq!(thumbs.iter().map(|t| t.0.clone()).collect::<Vec<_>>(), [format!("{wave}@1"), format!("{greeting}@1")]);
    for (key, lit) in &thumbs {
        // A 2-joint wave: one bone, some dozens of lit pixels in a 48×48 square.
        assert!((15..1500).contains(lit), "{key}: {lit} lit pixels");
    }
    assert_eq!(page.eval("window.inbetweenViewer.thumbnails.rendered").await, 2);
    // Again after a reload: from IndexedDB, none made.
    page.navigate(&app.url("/viewer")).await;
    page.wait_for("document.querySelectorAll('#clips canvas[data-thumb]').length === 2", 15).await;
    assert_eq!(
        page.eval("[window.inbetweenViewer.thumbnails.rendered, window.inbetweenViewer.thumbnails.fromCache]").await,
        json!([0, 2])
    );

    // Renaming without the write token: refused, and the page points at the token field.
    page.eval(&click_in_row(&wave, "Rename")).await;
    let rename = "(name => { const f = document.querySelector('#clips input.rename'); f.value = name; \
                  f.dispatchEvent(new KeyboardEvent('keydown', { key: 'Enter', bubbles: true })); })";
    page.eval(&format!("{rename}('wave-left')")).await;
    page.wait_for("document.getElementById('status').textContent.includes('enter the write token')", 10).await;
    assert_eq!(page.eval("document.getElementById('token-form').classList.contains('wanted')").await, true);
    assert_eq!(summary(&app, &wave).await["name"], "wave");
    set_value(page, "token", TOKEN).await;
    page.eval("document.getElementById('token-form').requestSubmit()").await;

    // With it (the list loaded again with the token, which takes the field's mark away): a
    // merge patch, the new name and version in the row.
    page.wait_for("!document.getElementById('token-form').classList.contains('wanted')", 10).await;
    page.eval(&click_in_row(&wave, "Rename")).await;
    page.eval(&format!("{rename}('wave-left')")).await;
    page.wait_for("document.getElementById('status').textContent === 'renamed wave to wave-left'", 10).await;
    let renamed = summary(&app, &wave).await;
    assert_eq!((renamed["name"].as_str(), renamed["version"].as_u64()), (Some("wave-left"), Some(2)));
    let row = format!("document.querySelector('#clips li[data-id={}] .facts').textContent", json!(wave));
    assert!(page.eval(&row).await.as_str().unwrap().contains(" · v2 · "));

    // Replace: a file uploaded as the clip's next version (same id), whatever name the file gives.
    page.eval(&click_in_row(&wave, "Replace")).await;
    page.set_files("#replace-file", &[Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/wave.json"))]).await;
    page.wait_for("document.getElementById('status').textContent === 'replaced wave-left: now version 3'", 20).await;
    let replaced = summary(&app, &wave).await;
    assert_eq!((replaced["name"].as_str(), replaced["version"].as_u64()), (Some("wave-left"), Some(3)));
    assert_eq!(page.eval("window.inbetweenViewer.state.clip.id").await, json!(wave), "the replaced clip is shown");
    let list: Value = app.http.get(app.url("/v1/clips")).send().await.unwrap().json().await.unwrap();
    assert_eq!(list["clips"].as_array().unwrap().len(), 2, "no new clip: {list}");
    // Its thumbnail is made anew for the new version.
    page.wait_for(
        &format!("document.querySelector('#clips li[data-id={}] canvas').dataset.thumb === '{wave}@3'", json!(wave)),
        15,
    )
    .await;

    // Delete asks first: Keep leaves it, Delete deletes it, and the page shows the clip left.
    page.eval(&click_in_row(&wave, "Delete")).await;
    let question = page.eval("document.querySelector('#clips .confirm').textContent").await;
    assert!(question.as_str().unwrap().starts_with("Delete wave-left (v3)?"), "{question}");
    page.eval(&click_in_row(&wave, "Keep")).await;
    assert_eq!(page.eval("document.querySelectorAll('#clips .confirm').length").await, 0);
    assert!(!summary(&app, &wave).await.is_null());
    page.eval(&click_in_row(&wave, "Delete")).await;
    page.eval(&click_in_row(&wave, "Delete")).await;
    page.wait_for("document.getElementById('status').textContent === 'deleted wave-left'", 10).await;
    assert!(summary(&app, &wave).await.is_null(), "deleted on the server");
    assert_eq!(
        page.eval("[...document.querySelectorAll('#clips li')].map(li => li.dataset.id)").await,
        json!([greeting])
    );
    assert_eq!(page.eval("window.inbetweenViewer.state.clip.id").await, json!(greeting));
    assert_eq!(text(page, "now-playing").await, "paused: arm-wave");
    assert_eq!(page.eval("window.inbetweenViewer.cspViolations").await, json!([]));
}
