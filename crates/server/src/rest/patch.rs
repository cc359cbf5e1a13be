//! `PATCH /v1/clips/{id}`: a JSON merge patch (RFC 7396) of the fields of a
//! clip that are not its motion: `name`, `tags`, `metadata`, `playback` and
//! `events`.
//!
//! The patch is applied to the stored document and the result goes through
//! the same admission as a `PUT` (parsed, checked, built), then replaces the
//! clip conditionally on the version it was read at: the version goes up by
//! one, the cache is written through, and other nodes hear of it by the
//! store's notification like any replace. A patch that changes nothing (the
//! merged document equals the stored one) writes nothing and keeps the
//! version. With `If-Match`, a stale tag is 412, as for `PUT`. Without it
//! (also as for `PUT`, which needs none) the patch applies to the current
//! version and is never answered 412: patches of one clip take turns on this
//! node, so they never race each other, and a write from elsewhere (a `PUT`,
//! another node) that lands between the read and the replace makes the patch
//! start again on the new version, after a short jittered backoff, so no
//! concurrent change is ever lost. A patch that loses that race
//! [`RETRIES`] times is answered 503 `unavailable` with `Retry-After`.

use std::sync::Arc;
use std::time::Duration;

use axum::extract::State;
use axum::http::header::IF_MATCH;
use axum::http::{HeaderMap, StatusCode};
use axum::response::Response;
use serde_json::{Map, Value};

use crate::auth::{CallerKey, WriteAccess};
use crate::cache::CachedClip;
use crate::error::ApiError;
use crate::limits::Admitted;
use crate::state::AppState;
use crate::store::{MeshWrite, RetryPolicy, StoreError};

use super::clips::{admit_body, with_etag};
use super::extract::{ClipId, JsonBody, Precondition, precondition};

/// The top-level fields a patch may change.
pub const PATCHABLE: [&str; 5] = ["name", "tags", "metadata", "playback", "events"];

/// How many times a patch without `If-Match` starts again after losing a
/// race to a write from elsewhere.
const RETRIES: u32 = 8;

/// The waits before those retries: doubling from 5 ms to 200 ms (about 0.8 s
/// in all), jittered so that writers racing each other spread out.
const BACKOFF: RetryPolicy =
    RetryPolicy { retries: RETRIES, base_backoff: Duration::from_millis(5), max_backoff: Duration::from_millis(200) };

/// Seconds a patch that lost every race is told to wait.
const RETRY_AFTER_SECS: u64 = 1;

/// Patch a clip's name, tags, metadata, playback or events (JSON merge patch).
#[utoipa::path(
    patch, path = "/v1/clips/{id}", tag = "clips",
    params(
        ("id" = String, Path, description = "Clip id"),
        ("If-Match" = Option<String>, Header, pattern = r#"^(\*|"[0-9]{1,19}")$"#, description = "Patch only at this version (`\"3\"`) or `*`; without it the patch applies to the current version"),
    ),
    request_body(content = super::schemas::ClipPatch, content_type = "application/merge-patch+json",
        description = "RFC 7396: a field set replaces it (objects merge), `null` removes it (`name` cannot be removed); `application/json` is accepted too"),
    responses(
        (status = 200, description = "Patched; the version went up by one (kept when the patch changes nothing)", body = super::summary::ClipSummary),
        (status = 400, description = "Not JSON", body = super::schemas::Problem),
        (status = 404, body = super::schemas::Problem),
        (status = 412, description = "`If-Match` did not match the current version", body = super::schemas::Problem),
        (status = 422, description = "Not an object, a field a patch cannot change (`unpatchable_field`), or the patched clip breaks a rule (pointer into the document)", body = super::schemas::Problem),
        (status = 503, description = "Without `If-Match`: the clip kept changing under the patch (`unavailable`, with `Retry-After`); nothing was written", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn patch_clip(
    State(state): State<AppState>,
    WriteAccess(caller): WriteAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let condition = match precondition(&headers, IF_MATCH, false)? {
        Some(Precondition::Any) | None => None,
        Some(tags) => Some(tags),
    };
    let patch = parse_patch(&body)?;
    let _turn = state.patches.take(&id).await;
    for retry in 0..=RETRIES {
        if retry > 0 {
            tokio::time::sleep(BACKOFF.backoff(retry - 1)).await;
        }
        if let Some(response) = patch_once(&state, &caller.key(), &id, condition.as_ref(), &patch).await? {
            return Ok(response);
        }
    }
    metrics::counter!("inbetween_patch_races_lost_total").increment(1);
    Err(ApiError::WriteRace { attempts: RETRIES + 1, retry_after: RETRY_AFTER_SECS })
}

/// One read, merge and conditional replace; `None` when a patch without
/// `If-Match` lost the race to another write (it may start again).
async fn patch_once(
    state: &AppState,
    caller: &CallerKey,
    id: &str,
    condition: Option<&Precondition>,
    patch: &Map<String, Value>,
) -> Result<Option<Response>, ApiError> {
    let stored = state.store.get(id).await?.ok_or(ApiError::NotFound { what: "clip" })?;
    let version = stored.meta.version;
    if condition.is_some_and(|c| !c.matches(version)) {
        return Err(ApiError::PreconditionFailed { current: version });
    }
    let mut doc: Value = serde_json::from_str(&stored.doc_json).map_err(ApiError::internal)?;
    let before = doc.clone();
    merge(&mut doc, patch);
    if doc == before {
        // Nothing changes: no write, no new version (a patch is idempotent).
        return Ok(Some(with_etag(&stored.meta, StatusCode::OK, None)));
    }
    let merged = serde_json::to_vec(&doc).map_err(ApiError::internal)?;
    let Admitted { mut new_clip, clip, springs, .. } = admit_body(state, caller, merged.into()).await?;
    // A patch cannot touch the skeleton: the mesh bound to it stays.
    new_clip.mesh = MeshWrite::Keep;
    if new_clip.doc_json == stored.doc_json {
        // The same canonical document (e.g. `"tags": []` on a clip without tags).
        return Ok(Some(with_etag(&stored.meta, StatusCode::OK, None)));
    }
    match state.store.replace(id, new_clip, Some(version)).await {
        Ok(meta) => {
            tracing::info!(id = %meta.id, version = meta.version, "clip patched");
            let response = with_etag(&meta, StatusCode::OK, None);
            state.cache_written(Arc::new(CachedClip { meta, clip, springs }));
            Ok(Some(response))
        }
        // Another write landed since the read: patch that version instead.
        Err(StoreError::VersionMismatch { .. }) if condition.is_none() => Ok(None),
        Err(e) => Err(e.into()),
    }
}

/// The patch document: an object whose keys are all [`PATCHABLE`].
///
/// # Errors
/// `malformed_json` (400); `bad_patch` (not an object, or `name: null`) and
/// `unpatchable_field` (422, at the field).
fn parse_patch(body: &[u8]) -> Result<Map<String, Value>, ApiError> {
    let value: Value = serde_json::from_slice(body).map_err(|e| ApiError::MalformedJson {
        pointer: String::new(),
        detail: format!("the patch is not JSON: {e}"),
    })?;
    let Value::Object(patch) = value else {
        return Err(ApiError::invalid("bad_patch", "", "a merge patch of a clip is a JSON object"));
    };
    for (key, value) in &patch {
        if !PATCHABLE.contains(&key.as_str()) {
            let detail = format!(
                "a PATCH changes {}; `{key}` is part of the motion: replace the clip (PUT) to change it",
                PATCHABLE.join(", ")
            );
            return Err(ApiError::invalid("unpatchable_field", pointer(key), detail));
        }
        if key == "name" && value.is_null() {
            return Err(ApiError::invalid("bad_patch", "/name", "a clip's name can be changed, not removed"));
        }
    }
    Ok(patch)
}

/// The JSON pointer of a top-level key (RFC 6901 escapes).
fn pointer(key: &str) -> String {
    format!("/{}", key.replace('~', "~0").replace('/', "~1"))
}

/// RFC 7396 §2 `MergePatch(target, patch)` for an object patch.
pub fn merge(target: &mut Value, patch: &Map<String, Value>) {
    if !target.is_object() {
        *target = Value::Object(Map::new());
    }
    let Value::Object(object) = target else { return };
    for (key, value) in patch {
        match value {
            Value::Null => {
                object.remove(key);
            }
            Value::Object(inner) => merge(object.entry(key.clone()).or_insert(Value::Null), inner),
            other => {
                object.insert(key.clone(), other.clone());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use serde_json::{Value, json};

    /// RFC 7396 Appendix A, every example whose patch is an object.
    #[test]
    fn merge_follows_the_rfc_examples() {
        let cases = [
            (json!({"a":"b"}), json!({"a":"c"}), json!({"a":"c"})),
            (json!({"a":"b"}), json!({"b":"c"}), json!({"a":"b","b":"c"})),
            (json!({"a":"b"}), json!({"a":null}), json!({})),
            (json!({"a":"b","b":"c"}), json!({"a":null}), json!({"b":"c"})),
            (json!({"a":["b"]}), json!({"a":"c"}), json!({"a":"c"})),
            (json!({"a":"c"}), json!({"a":["b"]}), json!({"a":["b"]})),
            (json!({"a":{"b":"c"}}), json!({"a":{"b":"d","c":null}}), json!({"a":{"b":"d"}})),
            (json!({"a":[{"b":"c"}]}), json!({"a":[1]}), json!({"a":[1]})),
            (json!(["a", "b"]), json!({"a":"b"}), json!({"a":"b"})),
            (json!({"e":null}), json!({"a":1}), json!({"e":null,"a":1})),
            (json!([1, 2]), json!({"a":"b","c":null}), json!({"a":"b"})),
            (json!({}), json!({"a":{"bb":{"ccc":null}}}), json!({"a":{"bb":{}}})),
        ];
        for (mut target, patch, expected) in cases {
            let Value::Object(patch) = patch else { unreachable!() };
            super::merge(&mut target, &patch);
            assert_eq!(target, expected, "patch {patch:?}");
        }
    }

    #[test]
    fn only_the_fields_beside_the_motion_can_be_patched() {
        let refused = |body: &str| super::parse_patch(body.as_bytes()).unwrap_err();
        assert_eq!(refused(r#"{"tracks":[]}"#).code(), "unpatchable_field");
        assert_eq!(refused(r#"{"name":null}"#).code(), "bad_patch");
        assert_eq!(refused("[1]").code(), "bad_patch");
        assert_eq!(refused("{").code(), "malformed_json");
        assert!(
            super::parse_patch(br#"{"name":"x","tags":null,"metadata":{"a":1},"playback":"once","events":[]}"#).is_ok()
        );
        assert_eq!(super::pointer("a/b~c"), "/a~1b~0c");
    }
}
