//! Strict query strings on every API and operations route: an operation
//! accepts exactly the query parameters its `#[utoipa::path]` documents,
//! each at most once, so a typo like `?time=1` or an option the route does
//! not have (`POST /v1/clips?dry_run=1`) is refused, never silently ignored.
//!
//! The [`strict`] layer parses each request's query once against the table
//! built from the OpenAPI document ([`Allowed`]) and hands the result to the
//! handler through the [`Query`] extractor. A route whose operation documents
//! no query parameters accepts none.

use std::collections::HashMap;
use std::sync::Arc;

use axum::extract::{FromRequestParts, MatchedPath, Request, State};
use axum::http::Method;
use axum::http::request::Parts;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use utoipa::openapi::path::{Operation, ParameterIn, PathItem};
use utoipa::openapi::{OpenApi, RefOr};

use crate::error::ApiError;
use crate::request::{Raw, RawModes};
use crate::store::OnName;

/// The query parameters each operation accepts, by route and method.
#[derive(Debug, Clone, Default)]
pub struct Allowed(Arc<HashMap<String, Vec<MethodParams>>>);

/// One method of a route and the query parameters it accepts.
type MethodParams = (Method, Vec<String>);

impl Allowed {
    /// Every operation's documented query parameters (and its path's).
    pub fn from_openapi(doc: &OpenApi) -> Allowed {
        let mut table = HashMap::new();
        for (path, item) in &doc.paths.paths {
            let operations = [
                (Method::GET, &item.get),
                (Method::PUT, &item.put),
                (Method::POST, &item.post),
                (Method::DELETE, &item.delete),
                (Method::PATCH, &item.patch),
            ];
            let methods = operations
                .into_iter()
                .filter_map(|(method, op)| op.as_ref().map(|op| (method, query_names(item, op))))
                .collect();
            table.insert(path.clone(), methods);
        }
        Allowed(Arc::new(table))
    }

    /// The names `method` on the route template `path` accepts (HEAD: GET's).
    fn names(&self, method: &Method, path: &str) -> &[String] {
        let method = if method == Method::HEAD { &Method::GET } else { method };
        let methods = self.0.get(path).map(Vec::as_slice).unwrap_or_default();
        methods.iter().find(|(m, _)| m == method).map_or(&[], |(_, names)| names.as_slice())
    }
}

fn query_names(item: &PathItem, op: &Operation) -> Vec<String> {
    let all = item.parameters.iter().flatten().chain(op.parameters.iter().flatten());
    all.filter_map(|p| match p {
        RefOr::T(p) if p.parameter_in == ParameterIn::Query => Some(p.name.clone()),
        _ => None,
    })
    .collect()
}

/// Middleware (a route layer, so the route template is known): refuses a
/// query the route does not accept, else hands the parsed query on.
pub async fn strict(State(allowed): State<Allowed>, mut request: Request, next: Next) -> Response {
    let path = request.extensions().get::<MatchedPath>().map(|m| m.as_str().to_owned()).unwrap_or_default();
    let names = allowed.names(request.method(), &path);
    match QueryParams::parse(request.uri().query(), names) {
        Ok(params) => {
            request.extensions_mut().insert(params);
            next.run(request).await
        }
        Err(e) => e.into_response(),
    }
}

/// The request's query parameters, as [`strict`] checked them.
#[derive(Debug)]
pub struct Query(pub QueryParams);

impl<S: Send + Sync> FromRequestParts<S> for Query {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, ApiError> {
        match parts.extensions.remove::<QueryParams>() {
            Some(params) => Ok(Query(params)),
            None => Err(ApiError::internal(anyhow::anyhow!("route without the strict query layer"))),
        }
    }
}

/// Query parameters, each name at most once, from a fixed allowed set.
#[derive(Debug, Clone, Default)]
pub struct QueryParams(Vec<(String, String)>);

impl QueryParams {
    /// # Errors
    /// `bad_query` for undecodable text, `unknown_parameter`, `repeated_parameter`.
    pub fn parse(raw: Option<&str>, allowed: &[impl AsRef<str>]) -> Result<QueryParams, ApiError> {
        let pairs = decode_pairs(raw.unwrap_or(""))?;
        for (i, (name, _)) in pairs.iter().enumerate() {
            if !allowed.iter().any(|a| a.as_ref() == name) {
                let expected: Vec<&str> = allowed.iter().map(AsRef::as_ref).collect();
                let detail = match expected.as_slice() {
                    [] => format!("unknown query parameter `{name}`; this route takes none"),
                    _ => format!("unknown query parameter `{name}`; expected one of: {}", expected.join(", ")),
                };
                return Err(ApiError::parameter("unknown_parameter", name, detail));
            }
            if pairs[..i].iter().any(|(n, _)| n == name) {
                return Err(ApiError::parameter("repeated_parameter", name, format!("`{name}` is given twice")));
            }
        }
        Ok(QueryParams(pairs))
    }

    pub fn get(&self, name: &str) -> Option<&str> {
        self.0.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_str())
    }

    /// The value of `name` for the request layer, if present.
    pub fn raw(&self, name: &str) -> Option<Raw<'_>> {
        self.get(name).map(Raw::Text)
    }

    /// `replace=true|false` (default false): whether a write whose name a
    /// clip has makes a new version of it, or is refused (`name_taken`).
    ///
    /// # Errors
    /// `bad_parameter` for any other value.
    pub fn on_name(&self) -> Result<OnName, ApiError> {
        match self.get("replace") {
            None | Some("false") => Ok(OnName::Refuse),
            Some("true") => Ok(OnName::Replace),
            Some(other) => Err(ApiError::parameter(
                "bad_parameter",
                "replace",
                format!("`replace` must be true or false, got `{other}`"),
            )),
        }
    }

    /// `springs=true|false` (default true): whether a clip route runs the
    /// clip's own spring chains (docs/springs.md, “Clip routes”).
    ///
    /// # Errors
    /// `bad_parameter` for any other value.
    pub fn springs(&self) -> Result<bool, ApiError> {
        match self.get("springs") {
            None | Some("true") => Ok(true),
            Some("false") => Ok(false),
            Some(other) => Err(ApiError::parameter(
                "bad_parameter",
                "springs",
                format!("`springs` must be true or false, got `{other}`"),
            )),
        }
    }

    /// `space`, `playback` and `ease`, for the request layer.
    pub fn modes(&self) -> RawModes<'_> {
        RawModes { space: self.raw("space"), playback: self.raw("playback"), ease: self.raw("ease") }
    }
}

/// `application/x-www-form-urlencoded` pairs (`+` is a space, `%XX` a byte;
/// names and values must decode to UTF-8).
fn decode_pairs(raw: &str) -> Result<Vec<(String, String)>, ApiError> {
    let decode = |s: &str| -> Result<String, ApiError> {
        if !s.contains(['+', '%']) {
            return Ok(s.to_owned());
        }
        let s = s.replace('+', " ");
        percent_encoding::percent_decode_str(&s).decode_utf8().map(|c| c.into_owned()).map_err(|_| bad_query())
    };
    raw.split('&')
        .filter(|pair| !pair.is_empty())
        .map(|pair| {
            let (name, value) = pair.split_once('=').unwrap_or((pair, ""));
            Ok((decode(name)?, decode(value)?))
        })
        .collect()
}

fn bad_query() -> ApiError {
    ApiError::parameter("bad_query", "query", "the query string cannot be decoded")
}
