//! [`ApiError`]: every way a request can fail, and the only place an HTTP
//! status is chosen.
//!
//! Each variant carries a stable machine `code` (clients switch on it), a
//! human `detail`, and where it applies the JSON pointer (body fields) or the
//! name (query parameters, headers) of what was wrong. [`ApiError::status`] and
//! [`ApiError::code`] are plain functions so another protocol can map the same
//! errors (gRPC: `ApiError` → `tonic::Status` by matching on the variant, the
//! way `IntoResponse` below does for problem+json).
//!
//! Internal failures keep their cause for the log and show the client only
//! "internal error": no SQL or file paths ever leave the process. Client
//! errors are logged at debug level; only 5xx are logged as errors.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

use crate::store::StoreError;
use formats::import::{ErrorClass, ImportError};
use formats::wire::json::DocError;

/// The media type of every error body (RFC 9457).
pub const PROBLEM_JSON: &str = "application/problem+json";

#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    /// The body is not JSON at all.
    #[error("{detail}")]
    MalformedJson { pointer: String, detail: String },
    /// A body, clip or request value that parses but breaks a rule (types,
    /// docs/clip-format.md §1–2, limits, the request rules of `server::request`).
    #[error("{detail}")]
    Invalid { code: &'static str, at: At, detail: String },
    /// A query parameter, header or request value that does not parse.
    #[error("{detail}")]
    BadParameter { code: &'static str, at: At, detail: String },
    #[error("missing or wrong bearer token")]
    Unauthorized,
    /// A known token without the scope the route needs.
    #[error("this token lacks the `{needed}` scope")]
    Forbidden { needed: &'static str },
    #[error("{what} not found")]
    NotFound { what: &'static str },
    /// A clip named in a request that does not exist: `clip_not_found` at
    /// the field naming it (a motion layer's `clip`, `compatible_with`).
    #[error("{detail}")]
    ClipNotFoundAt { at: At, detail: String },
    /// A motion's `character` that does not exist: `character_not_found`
    /// at `/motion/character`.
    #[error("{detail}")]
    CharacterNotFoundAt { at: At, detail: String },
    /// A graph named in a request that does not exist: `graph_not_found`
    /// at the field naming it (a motion layer's `graph`).
    #[error("{detail}")]
    GraphNotFoundAt { at: At, detail: String },
    #[error("method not allowed")]
    MethodNotAllowed,
    /// A write whose name another clip has (`name_taken`), or one that
    /// names a clip by a name several share (`ambiguous_name`): 409.
    #[error("{detail}")]
    NameConflict { code: &'static str, pointer: String, detail: String },
    #[error("the clip is at version {current}; If-Match did not match")]
    PreconditionFailed { current: u64 },
    /// A body over a size limit: `setting` names the limit (`max_body_bytes`,
    /// `max_import_bytes`) so the answer can say how to raise it.
    #[error("request body is over the {limit}-byte limit ({})", raise_hint(setting))]
    PayloadTooLarge { limit: usize, setting: &'static str },
    #[error("{detail}")]
    UnsupportedMediaType { detail: String },
    #[error("{detail}")]
    TooMany { code: &'static str, pointer: String, detail: String },
    /// `max_broadcasts` broadcasts are live (docs/broadcasts.md).
    #[error("{} ({})", .0, raise_hint("max_broadcasts"))]
    TooManyBroadcasts(crate::stream::BroadcastError),
    /// The stream caps (global or per client address) are reached.
    #[error("{0}")]
    TooManyStreams(crate::stream::AdmitError),
    /// An uploaded file that cannot be imported: 400 when it is not a
    /// well-formed file, 413 over an import limit, 422 when its content
    /// cannot become a clip.
    #[error("{detail}")]
    Import { class: ErrorClass, code: &'static str, pointer: Option<String>, detail: String },
    #[error("the request took longer than {secs} s")]
    Timeout { secs: u64 },
    /// The body did not arrive within the body-read timeout (slow client).
    #[error("the request body did not arrive within {secs} s ({})", raise_hint("body_read_timeout_secs"))]
    BodyTimeout { secs: u64 },
    /// An import upload slower than `min_upload_bytes_per_sec` over the last
    /// window: cut off so that its slot goes to someone else.
    #[error(
        "the upload sent {received} bytes in the last {window_secs} s, under {min_per_sec} bytes/s ({})",
        raise_hint("min_upload_bytes_per_sec").replace("raise", "lower")
    )]
    UploadTooSlow { received: u64, window_secs: u64, min_per_sec: u64 },
    /// Too many requests in flight: shed at once instead of queued.
    #[error("the server is at capacity; retry after {retry_after} s")]
    Overloaded { retry_after: u64 },
    /// The caller's write rate limit (token bucket) is used up.
    #[error("write rate limit reached; retry after {retry_after} s")]
    RateLimited { retry_after: u64 },
    /// A unary answer (gRPC `SampleBatch`) whose size bound is over the
    /// largest message this server sends: the streaming RPC serves it.
    #[error("the answer may take {bytes} bytes, over the {limit}-byte limit of one message; ask {stream} instead")]
    AnswerTooLargeForUnary { bytes: u64, limit: u64, stream: &'static str },
    /// The caller already has `limit` requests in flight (`max_in_flight_per_client`).
    #[error(
        "this caller already has {limit} requests in flight (max_in_flight_per_client, --max-in-flight-per-client); \
         retry after {retry_after} s"
    )]
    ClientInFlight { limit: usize, retry_after: u64 },
    /// The caller already holds its share of the node's work
    /// (`caller_work_share`; docs/api.md, “Work and its price”).
    #[error(
        "this caller holds {held} work units and asks for {units} more; its share is {share} (caller_work_share, \
         --caller-work-share); retry after {retry_after} s"
    )]
    CallerWorkLimit { held: u64, units: u64, share: u64, retry_after: u64 },
    /// The node's work capacity is taken (`node_work_per_sec`).
    #[error("the server's work capacity is taken; retry after {retry_after} s")]
    WorkOverloaded { retry_after: u64 },
    #[error("service unavailable")]
    Unavailable(#[source] Option<anyhow::Error>),
    /// A write without a precondition that lost the race to other writes of
    /// the same clip every time it started again (`unavailable`, with `Retry-After`).
    #[error("the clip kept changing while this write was applied ({attempts} attempts); retry after {retry_after} s")]
    WriteRace { attempts: u32, retry_after: u64 },
    /// A broadcast's store queue is full (docs/broadcasts.md, "Control"):
    /// the control is refused, never applied (`unavailable`, with `Retry-After`).
    #[error("{limit} controls of this broadcast are waiting to be stored; retry after {retry_after} s")]
    StoreQueueFull { limit: usize, retry_after: u64 },
    /// A refusal of this server's carried as a broadcast control's
    /// (`stream::ControlError::Refused`), answered as it was made.
    #[error("{detail}")]
    Relayed { status: u16, code: &'static str, detail: String },
    #[error("internal error")]
    Internal(#[source] anyhow::Error),
}

/// How an operator raises a limit: the setting and its flag and environment
/// variable, which follow one pattern for every limit (`max_x`, `--max-x`,
/// `INBETWEEN_MAX_X`; docs/configuration.md's table is rendered from the config rows).
pub fn raise_hint(setting: &str) -> String {
    format!("{setting}; raise it with --{} or INBETWEEN_{}", setting.replace('_', "-"), setting.to_ascii_uppercase())
}

/// Where a refused value sits in the request: problem+json says `parameter`
/// or `pointer`, gRPC `(parameter …)` or `(at …)` in the message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum At {
    /// A query parameter or header, by name.
    Parameter(String),
    /// A body or protobuf message field, by JSON pointer (`""`: the whole request).
    Pointer(String),
}

#[derive(Serialize)]
struct Problem<'a> {
    #[serde(rename = "type")]
    type_: String,
    title: &'a str,
    status: u16,
    code: &'a str,
    detail: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pointer: Option<&'a str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    parameter: Option<&'a str>,
}

impl ApiError {
    /// A refused stream or broadcast control: its own code (422), or the
    /// server's refusal it carries, answered as it was made.
    pub fn from_control(e: &crate::stream::ControlError) -> ApiError {
        match e {
            crate::stream::ControlError::Refused { code, problem } => ApiError::Relayed {
                status: problem["status"].as_u64().map_or(500, |s| s as u16),
                code,
                detail: e.to_string(),
            },
            e => ApiError::invalid(e.code(), e.pointer().unwrap_or_default(), e.to_string()),
        }
    }

    /// This refusal as a broadcast control's, its problem carried whole
    /// (to a socket as `{"error": problem}`; back by [`ApiError::from_control`]).
    pub fn to_control(&self) -> crate::stream::ControlError {
        crate::stream::ControlError::Refused { code: self.code(), problem: std::sync::Arc::new(self.problem_json()) }
    }

    pub fn status(&self) -> StatusCode {
        use ApiError::*;
        match self {
            MalformedJson { .. } | BadParameter { .. } => StatusCode::BAD_REQUEST,
            Invalid { .. } | TooMany { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            Unauthorized => StatusCode::UNAUTHORIZED,
            Forbidden { .. } => StatusCode::FORBIDDEN,
            NotFound { .. } | ClipNotFoundAt { .. } | CharacterNotFoundAt { .. } | GraphNotFoundAt { .. } => {
                StatusCode::NOT_FOUND
            }
            MethodNotAllowed => StatusCode::METHOD_NOT_ALLOWED,
            NameConflict { .. } => StatusCode::CONFLICT,
            PreconditionFailed { .. } => StatusCode::PRECONDITION_FAILED,
            PayloadTooLarge { .. } | AnswerTooLargeForUnary { .. } => StatusCode::PAYLOAD_TOO_LARGE,
            UnsupportedMediaType { .. } => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            TooManyStreams(crate::stream::AdmitError::ShuttingDown) => StatusCode::SERVICE_UNAVAILABLE,
            TooManyStreams(_) => StatusCode::TOO_MANY_REQUESTS,
            TooManyBroadcasts(crate::stream::BroadcastError::ShuttingDown) => StatusCode::SERVICE_UNAVAILABLE,
            TooManyBroadcasts(_) => StatusCode::TOO_MANY_REQUESTS,
            Import { class: ErrorClass::Malformed, .. } => StatusCode::BAD_REQUEST,
            Import { class: ErrorClass::TooLarge, .. } => StatusCode::PAYLOAD_TOO_LARGE,
            Import { class: ErrorClass::Unprocessable, .. } => StatusCode::UNPROCESSABLE_ENTITY,
            Import { class: ErrorClass::UnsupportedFormat, .. } => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            Timeout { .. } | Unavailable(_) | WriteRace { .. } | StoreQueueFull { .. } => {
                StatusCode::SERVICE_UNAVAILABLE
            }
            Relayed { status, .. } => StatusCode::from_u16(*status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR),
            BodyTimeout { .. } | UploadTooSlow { .. } => StatusCode::REQUEST_TIMEOUT,
            Overloaded { .. } | WorkOverloaded { .. } => StatusCode::SERVICE_UNAVAILABLE,
            RateLimited { .. } | ClientInFlight { .. } | CallerWorkLimit { .. } => StatusCode::TOO_MANY_REQUESTS,
            Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    /// The stable machine-readable code.
    pub fn code(&self) -> &'static str {
        use ApiError::*;
        match self {
            MalformedJson { .. } => "malformed_json",
            Invalid { code, .. }
            | BadParameter { code, .. }
            | TooMany { code, .. }
            | Import { code, .. }
            | NameConflict { code, .. } => code,
            Unauthorized => "unauthorized",
            Forbidden { .. } => "insufficient_scope",
            NotFound { what: "route" } => "route_not_found",
            NotFound { what: "broadcast" } => "broadcast_not_found",
            NotFound { what: "mesh" } => "no_mesh",
            NotFound { what: "character" } => "character_not_found",
            CharacterNotFoundAt { .. } => "character_not_found",
            NotFound { what: "graph" } | GraphNotFoundAt { .. } => "graph_not_found",
            NotFound { .. } | ClipNotFoundAt { .. } => "clip_not_found",
            MethodNotAllowed => "method_not_allowed",
            PreconditionFailed { .. } => "version_mismatch",
            PayloadTooLarge { .. } => "body_too_large",
            AnswerTooLargeForUnary { .. } => "use_sample_stream",
            UnsupportedMediaType { .. } => "unsupported_media_type",
            TooManyStreams(crate::stream::AdmitError::ShuttingDown) => "shutting_down",
            TooManyStreams(_) => "too_many_streams",
            TooManyBroadcasts(crate::stream::BroadcastError::ShuttingDown) => "shutting_down",
            TooManyBroadcasts(_) => "too_many_broadcasts",
            Timeout { .. } => "request_timeout",
            Unavailable(_) | WriteRace { .. } | StoreQueueFull { .. } => "unavailable",
            Relayed { code, .. } => code,
            BodyTimeout { .. } | UploadTooSlow { .. } => "body_timeout",
            Overloaded { .. } | WorkOverloaded { .. } => "overloaded",
            CallerWorkLimit { .. } => "caller_work_limit",
            RateLimited { .. } => "rate_limited",
            ClientInFlight { .. } => "client_in_flight_limit",
            Internal(_) => "internal",
        }
    }

    fn pointer(&self) -> Option<&str> {
        match self {
            ApiError::MalformedJson { pointer, .. }
            | ApiError::TooMany { pointer, .. }
            | ApiError::NameConflict { pointer, .. } => Some(pointer),
            ApiError::Invalid { at: At::Pointer(pointer), .. }
            | ApiError::ClipNotFoundAt { at: At::Pointer(pointer), .. }
            | ApiError::CharacterNotFoundAt { at: At::Pointer(pointer), .. }
            | ApiError::GraphNotFoundAt { at: At::Pointer(pointer), .. }
            | ApiError::BadParameter { at: At::Pointer(pointer), .. } => Some(pointer),
            ApiError::Import { pointer, .. } => pointer.as_deref(),
            _ => None,
        }
    }

    /// The query parameter or header at fault, if that is where the error is.
    fn parameter_name(&self) -> Option<&str> {
        match self {
            ApiError::Invalid { at: At::Parameter(name), .. }
            | ApiError::BadParameter { at: At::Parameter(name), .. }
            | ApiError::ClipNotFoundAt { at: At::Parameter(name), .. }
            | ApiError::CharacterNotFoundAt { at: At::Parameter(name), .. } => Some(name),
            _ => None,
        }
    }

    /// A query parameter or header that does not parse (400).
    pub fn parameter(code: &'static str, parameter: &str, detail: impl Into<String>) -> Self {
        ApiError::BadParameter { code, at: At::Parameter(parameter.to_owned()), detail: detail.into() }
    }

    /// A body field that breaks a rule, at a JSON pointer (422).
    pub fn invalid(code: &'static str, pointer: impl Into<String>, detail: impl Into<String>) -> Self {
        ApiError::Invalid { code, at: At::Pointer(pointer.into()), detail: detail.into() }
    }

    pub fn internal(e: impl Into<anyhow::Error>) -> Self {
        ApiError::Internal(e.into())
    }
}

impl From<ImportError> for ApiError {
    fn from(e: ImportError) -> Self {
        ApiError::Import { class: e.class(), code: e.code(), pointer: e.pointer(), detail: e.to_string() }
    }
}

impl From<DocError> for ApiError {
    fn from(e: DocError) -> Self {
        if e.code == "malformed_json" {
            ApiError::MalformedJson { pointer: e.pointer, detail: e.detail }
        } else {
            ApiError::Invalid { code: e.code, at: At::Pointer(e.pointer), detail: e.detail }
        }
    }
}

impl From<StoreError> for ApiError {
    fn from(e: StoreError) -> Self {
        match e {
            StoreError::NotFound => ApiError::NotFound { what: "clip" },
            StoreError::VersionMismatch { current } => ApiError::PreconditionFailed { current },
            StoreError::NameTaken { name, id, what } => ApiError::NameConflict {
                code: "name_taken",
                pointer: "/name".into(),
                detail: format!(
                    "a {what} named {name:?} exists ({id}): names identify {what}s; choose another name, or write \
                     with replace=true to make this a new version of that {what}"
                ),
            },
            StoreError::AmbiguousName { name, ids, what } => ApiError::NameConflict {
                code: "ambiguous_name",
                pointer: "/name".into(),
                detail: format!(
                    "several {what}s are named {name:?} ({}), stored before names were unique: address one by id, or \
                     delete or rename the others",
                    ids.join(", ")
                ),
            },
            StoreError::Unavailable(cause) => ApiError::Unavailable(Some(anyhow::Error::from_boxed(cause))),
            StoreError::Backend(cause) => ApiError::Internal(anyhow::Error::from_boxed(cause)),
        }
    }
}

impl ApiError {
    /// The problem document (RFC 9457) this error answers with; logged once.
    fn problem(&self) -> Problem<'_> {
        let status = self.status();
        let code = self.code();
        if status.is_server_error() {
            tracing::error!(code, error = %ErrorChain(self), "request failed");
        } else {
            tracing::debug!(code, detail = %self, "request refused");
        }
        Problem {
            type_: format!("urn:inbetween:problem:{code}"),
            title: status.canonical_reason().unwrap_or("Error"),
            status: status.as_u16(),
            code,
            detail: self.public_detail(),
            pointer: self.pointer(),
            parameter: self.parameter_name(),
        }
    }

    /// The same error with a JSON pointer under `from` moved under `to`
    /// (a motion checked as a request's `/motion`, sent as a control's `/to`).
    pub fn moved(self, from: &str, to: &str) -> ApiError {
        self.relocated(|at| match at {
            At::Pointer(p) => At::Pointer(match p.strip_prefix(from) {
                Some(rest) if rest.is_empty() || rest.starts_with('/') => format!("{to}{rest}"),
                _ => p,
            }),
            other => other,
        })
    }

    /// The same error with its location replaced by `f(location)` (a
    /// request answered on another route's behalf, its fields there).
    pub fn relocated(self, f: impl Fn(At) -> At) -> ApiError {
        match self {
            ApiError::Invalid { code, at, detail } => ApiError::Invalid { code, at: f(at), detail },
            ApiError::BadParameter { code, at, detail } => ApiError::BadParameter { code, at: f(at), detail },
            ApiError::MalformedJson { pointer, detail } => match f(At::Pointer(pointer.clone())) {
                At::Pointer(moved) => ApiError::MalformedJson { pointer: moved, detail },
                At::Parameter(_) => ApiError::MalformedJson { pointer, detail },
            },
            ApiError::ClipNotFoundAt { at, detail } => ApiError::ClipNotFoundAt { at: f(at), detail },
            ApiError::CharacterNotFoundAt { at, detail } => ApiError::CharacterNotFoundAt { at: f(at), detail },
            ApiError::GraphNotFoundAt { at, detail } => ApiError::GraphNotFoundAt { at: f(at), detail },
            other => other,
        }
    }

    /// The problem as JSON text, for transports that carry it in a message
    /// (a WebSocket stream's `{"error": problem}`).
    pub fn problem_json(&self) -> serde_json::Value {
        serde_json::to_value(self.problem()).unwrap_or_default()
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = self.status();
        let body = serde_json::to_vec(&self.problem()).unwrap_or_default();
        let mut response =
            (status, [(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON))], body).into_response();
        if matches!(self, ApiError::Unauthorized) {
            response.headers_mut().insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        if let ApiError::Overloaded { retry_after }
        | ApiError::RateLimited { retry_after }
        | ApiError::ClientInFlight { retry_after, .. }
        | ApiError::WriteRace { retry_after, .. }
        | ApiError::StoreQueueFull { retry_after, .. }
        | ApiError::CallerWorkLimit { retry_after, .. }
        | ApiError::WorkOverloaded { retry_after } = &self
        {
            response.headers_mut().insert(header::RETRY_AFTER, HeaderValue::from(*retry_after));
        }
        if let ApiError::Relayed { status: 429 | 503, .. } = &self {
            response.headers_mut().insert(header::RETRY_AFTER, HeaderValue::from(1));
        }
        response
    }
}

impl From<crate::stream::AdmitError> for ApiError {
    fn from(e: crate::stream::AdmitError) -> Self {
        ApiError::TooManyStreams(e)
    }
}

impl ApiError {
    /// The client-facing message: internals never leave the process.
    fn public_detail(&self) -> String {
        match self {
            ApiError::Internal(_) => "internal error; see the server log".to_owned(),
            ApiError::Unavailable(_) => "the service is unavailable; try again shortly".to_owned(),
            other => other.to_string(),
        }
    }

    /// The gRPC status code of this error (the twin of [`ApiError::status`]).
    pub fn grpc_code(&self) -> tonic::Code {
        use ApiError::*;
        use tonic::Code;
        match self {
            MalformedJson { .. } | Invalid { .. } | BadParameter { .. } | UnsupportedMediaType { .. } => {
                Code::InvalidArgument
            }
            // A request over a size limit is still the caller's to fix.
            TooMany { .. } => Code::InvalidArgument,
            Unauthorized => Code::Unauthenticated,
            Forbidden { .. } => Code::PermissionDenied,
            NotFound { .. } | ClipNotFoundAt { .. } | CharacterNotFoundAt { .. } | GraphNotFoundAt { .. } => {
                Code::NotFound
            }
            MethodNotAllowed => Code::Unimplemented,
            NameConflict { code: "name_taken", .. } => Code::AlreadyExists,
            NameConflict { .. } => Code::FailedPrecondition,
            PreconditionFailed { .. } => Code::FailedPrecondition,
            PayloadTooLarge { .. } | AnswerTooLargeForUnary { .. } => Code::ResourceExhausted,
            Import { class: ErrorClass::TooLarge, .. } => Code::ResourceExhausted,
            Import { .. } => Code::InvalidArgument,
            TooManyStreams(crate::stream::AdmitError::ShuttingDown) => Code::Unavailable,
            TooManyStreams(_) => Code::ResourceExhausted,
            TooManyBroadcasts(crate::stream::BroadcastError::ShuttingDown) => Code::Unavailable,
            TooManyBroadcasts(_) => Code::ResourceExhausted,
            Timeout { .. } => Code::DeadlineExceeded,
            Unavailable(_) | WriteRace { .. } | StoreQueueFull { .. } => Code::Unavailable,
            Relayed { status, .. } => match *status {
                429 => Code::ResourceExhausted,
                503 => Code::Unavailable,
                404 => Code::NotFound,
                400..=499 => Code::InvalidArgument,
                _ => Code::Internal,
            },
            BodyTimeout { .. } | UploadTooSlow { .. } => Code::DeadlineExceeded,
            Overloaded { .. } | RateLimited { .. } | ClientInFlight { .. } | CallerWorkLimit { .. } => {
                Code::ResourceExhausted
            }
            // The node, not the caller, is short: another node may serve it.
            WorkOverloaded { .. } => Code::Unavailable,
            Internal(_) => Code::Internal,
        }
    }
}

/// `ApiError` → gRPC status: the code from [`ApiError::grpc_code`], the
/// message `"<code>: <detail>"` plus `" (at <pointer>)"` for field errors, and
/// the stable code also in the `x-error-code` metadata.
impl From<ApiError> for tonic::Status {
    fn from(e: ApiError) -> Self {
        let code = e.code();
        if e.status().is_server_error() {
            tracing::error!(code, error = %ErrorChain(&e), "gRPC call failed");
        } else {
            tracing::debug!(code, detail = %e, "gRPC call refused");
        }
        let mut message = format!("{code}: {}", e.public_detail());
        if let Some(pointer) = e.pointer().filter(|p| !p.is_empty()) {
            message.push_str(&format!(" (at {pointer})"));
        } else if let Some(parameter) = e.parameter_name() {
            message.push_str(&format!(" (parameter {parameter})"));
        }
        let mut status = tonic::Status::new(e.grpc_code(), message);
        if let Ok(v) = tonic::metadata::MetadataValue::try_from(code) {
            status.metadata_mut().insert("x-error-code", v);
        }
        status
    }
}

/// Renders an error with its whole `source()` chain for the log.
struct ErrorChain<'a>(&'a ApiError);

impl std::fmt::Display for ErrorChain<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.0)?;
        let mut source = std::error::Error::source(self.0);
        while let Some(s) = source {
            write!(f, ": {s}")?;
            source = s.source();
        }
        Ok(())
    }
}
