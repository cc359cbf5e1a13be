//! Request parsing at the edge: JSON bodies (media type, size), path ids and
//! `If-Match` / `If-None-Match` (query strings: `rest::query`). Every failure
//! is an [`ApiError`] naming the parameter or header at fault.

use axum::body::Bytes;
use axum::extract::{FromRequest, FromRequestParts, Path, Request};
use axum::http::header::{CONTENT_TYPE, ETAG};
use axum::http::request::Parts;
use axum::http::{HeaderMap, HeaderName, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};

use crate::error::ApiError;
use crate::state::AppState;

/// A request body declared as JSON (`application/json` or `application/*+json`),
/// within the configured size limit. Parsing is the handler's business.
#[derive(Debug)]
pub struct JsonBody(pub Bytes);

fn is_json(headers: &HeaderMap) -> bool {
    let Some(ct) = headers.get(CONTENT_TYPE).and_then(|v| v.to_str().ok()) else { return false };
    let essence = ct.split(';').next().unwrap_or("").trim().to_ascii_lowercase();
    essence == "application/json" || (essence.starts_with("application/") && essence.ends_with("+json"))
}

impl FromRequest<AppState> for JsonBody {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, ApiError> {
        if !is_json(req.headers()) {
            return Err(ApiError::UnsupportedMediaType {
                detail: "the body must be JSON: send Content-Type: application/json".into(),
            });
        }
        match Bytes::from_request(req, state).await {
            Ok(bytes) => Ok(JsonBody(bytes)),
            Err(e) if e.status() == StatusCode::PAYLOAD_TOO_LARGE => {
                Err(ApiError::PayloadTooLarge { limit: state.config.limits.max_body_bytes, setting: "max_body_bytes" })
            }
            Err(e) => Err(ApiError::parameter("unreadable_body", "body", e.body_text())),
        }
    }
}

/// The `{id}` path segment of a clip route.
#[derive(Debug)]
pub struct ClipId(pub String);

impl<S: Send + Sync> FromRequestParts<S> for ClipId {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ApiError> {
        match Path::<String>::from_request_parts(parts, state).await {
            Ok(Path(id)) => Ok(ClipId(id)),
            Err(e) => Err(ApiError::parameter("bad_path", "id", e.body_text())),
        }
    }
}

/// An `If-Match` / `If-None-Match` condition.
#[derive(Debug, Clone, PartialEq)]
pub enum Precondition {
    /// `*`: any current version.
    Any,
    /// Strong entity tags naming versions; tags that cannot be ours (weak,
    /// non-numeric) never match and are kept as `None`.
    Tags(Vec<Option<u64>>),
}

impl Precondition {
    pub fn matches(&self, version: u64) -> bool {
        match self {
            Precondition::Any => true,
            Precondition::Tags(tags) => tags.contains(&Some(version)),
        }
    }

    /// The single version this condition names, if it names exactly one.
    pub fn single(&self) -> Option<Option<u64>> {
        match self {
            Precondition::Tags(tags) if tags.len() == 1 => Some(tags[0]),
            _ => None,
        }
    }
}

/// The version a conditional write must find (`None`: any), resolving a
/// multi-tag `If-Match` against the current version, read by `current`
/// only when that is needed.
///
/// # Errors
/// `version_mismatch` (412) when the condition cannot match; what `current` returns.
pub async fn expected(
    condition: Option<Precondition>,
    current: impl AsyncFnOnce() -> Result<u64, ApiError>,
) -> Result<Option<u64>, ApiError> {
    match condition {
        None | Some(Precondition::Any) => Ok(None),
        Some(p) => match p.single() {
            // One tag that cannot be ours (weak or not a version) never matches.
            Some(None) => Err(ApiError::PreconditionFailed { current: current().await? }),
            Some(Some(v)) => Ok(Some(v)),
            None => {
                let current = current().await?;
                if p.matches(current) { Ok(Some(current)) } else { Err(ApiError::PreconditionFailed { current }) }
            }
        },
    }
}

/// The strong ETag of a clip (or character) version.
pub fn etag(version: u64) -> String {
    format!("\"{version}\"")
}

/// A conditional GET of stored `version`: `304` with its `ETag` when
/// `if_none_match` (parsed before the lookup, so a malformed header is a
/// 400 whether or not the clip exists) names it, else `ok()` with the `ETag`.
///
/// # Errors
/// None in practice: an `ETag` is always a valid header value.
pub fn unless_modified(
    if_none_match: Option<Precondition>,
    version: u64,
    ok: impl FnOnce() -> Response,
) -> Result<Response, ApiError> {
    let tag = HeaderValue::from_str(&etag(version)).map_err(ApiError::internal)?;
    if if_none_match.is_some_and(|p| p.matches(version)) {
        return Ok((StatusCode::NOT_MODIFIED, [(ETAG, tag)]).into_response());
    }
    let mut response = ok();
    response.headers_mut().insert(ETAG, tag);
    Ok(response)
}

/// Parses a conditional header (RFC 9110 §13.1).
///
/// # Errors
/// `bad_precondition` for a header that is not `*` or a list of quoted tags.
/// `If-Match` compares strongly (a weak tag never matches); `If-None-Match`
/// weakly (`weak_matches`).
pub fn precondition(
    headers: &HeaderMap,
    name: HeaderName,
    weak_matches: bool,
) -> Result<Option<Precondition>, ApiError> {
    let mut values = headers.get_all(&name).iter().peekable();
    if values.peek().is_none() {
        return Ok(None);
    }
    let bad = || {
        ApiError::parameter(
            "bad_precondition",
            name.as_str(),
            format!("{name} must be `*` or a list of entity tags like \"3\""),
        )
    };
    let mut tags = Vec::new();
    for value in values {
        let text = value.to_str().map_err(|_| bad())?;
        for item in text.split(',').map(str::trim) {
            if item == "*" {
                return Ok(Some(Precondition::Any));
            }
            let (weak, quoted) = match item.strip_prefix("W/") {
                Some(rest) => (true, rest),
                None => (false, item),
            };
            let inner = quoted.strip_prefix('"').and_then(|s| s.strip_suffix('"')).ok_or_else(bad)?;
            if inner.contains('"') {
                return Err(bad());
            }
            let version = if weak && !weak_matches { None } else { inner.parse::<u64>().ok() };
            tags.push(version);
        }
    }
    if tags.is_empty() { Err(bad()) } else { Ok(Some(Precondition::Tags(tags))) }
}
