//! Request bodies from slow or oversized senders, read whole before the
//! request is admitted. A declared `Content-Length` over the body limit is
//! answered 413 before a byte of the body is read; a body that grows past it
//! is cut off with 413 too; a body that has not fully arrived within the
//! body-read timeout (counted from the end of the head) is answered 408. All
//! three close the connection, whose unread rest is never drained.
//!
//! The body is buffered here, before the load-shedding and per-client
//! in-flight budgets (`shed`), which sit inside this middleware: a request
//! whose body is slow or never comes holds no in-flight slot, so such
//! requests cannot shed the ones that did arrive. A request without a body
//! (its head ends the stream: no `Content-Length`/`Transfer-Encoding` in
//! HTTP/1.1, `END_STREAM` on the HTTP/2 headers) passes straight on. (Slow
//! heads and idle connections are the accept loop's, in `listen`.)
//!
//! The import route's body is spooled to a temporary file instead of held
//! (`spool`), under its own limit (`max_import_bytes`), the same timeout and
//! a floor on its arrival rate; it takes one of its caller's upload slots
//! rather than the arrival budget, which is memory, and only a caller allowed
//! to write gets one. Others are refused without
//! spooling; their body, when no bigger than `max_body_bytes`, is read and
//! dropped first, so that a client still sending gets the answer rather
//! than a reset connection.
//! Every 413 names its limit and how to raise it.

use std::time::Duration;

use axum::body::{Body, Bytes, HttpBody};
use axum::extract::{Request, State};
use axum::http::{HeaderValue, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::auth::{Identity, Scope};
use super::compression::BodyCoding;
use super::error::ApiError;
use super::shed::{Arrivals, key_of};
use super::spool::SpoolRoute;

/// The limits the middleware applies.
#[derive(Debug, Clone)]
pub struct BodyGuard {
    pub max_bytes: usize,
    pub read_timeout: Duration,
    /// The budget of bodies held at once (`max_arriving_bytes`).
    pub arrivals: Arrivals,
    /// The route whose bodies go to a temporary file instead (import).
    pub spool: Option<SpoolRoute>,
}

/// The setting `max_bytes` comes from.
const MAX_BODY_BYTES: &str = "max_body_bytes";

/// The middleware (see the module doc).
pub async fn guard(State(g): State<BodyGuard>, request: Request, next: Next) -> Response {
    let spool = g.spool.as_ref().filter(|route| route.matches(&request));
    let (max_bytes, setting) = spool.map_or((g.max_bytes, MAX_BODY_BYTES), |r| (r.max_bytes, r.setting));
    let declared = request.headers().get(header::CONTENT_LENGTH).and_then(|v| v.to_str().ok()?.parse::<u64>().ok());
    if declared.is_some_and(|n| n > max_bytes as u64) {
        return closing(ApiError::PayloadTooLarge { limit: max_bytes, setting });
    }
    if request.body().is_end_stream() {
        return next.run(request).await;
    }
    match spool {
        Some(route) => spooled(route, &g, request, next).await,
        None => held(&g, request, next).await,
    }
}

/// A body read whole into memory, then the request.
async fn held(g: &BodyGuard, request: Request, next: Next) -> Response {
    let (parts, body) = request.into_parts();
    let coding = parts.extensions.get::<BodyCoding>().copied();
    let deadline = tokio::time::Instant::now() + g.read_timeout;
    let mut held = None;
    let awaiting = g.arrivals.awaiting();
    let read = tokio::time::timeout_at(deadline, read_whole(body, g, coding, &mut held)).await;
    drop(awaiting);
    match read {
        Ok(Ok(bytes)) => {
            let response = next.run(Request::from_parts(parts, Body::from(bytes))).await;
            drop(held);
            response
        }
        Ok(Err(e)) => closing(e),
        Err(_) => timed_out(g.read_timeout),
    }
}

/// A body spooled to a temporary file, then the request with an empty body
/// and the file in its extensions (`spool::SpooledBody`).
///
/// A caller who may not write is refused before the file is spooled: a file
/// this size is not taken from someone the handler would answer 401 or 403.
async fn spooled(route: &SpoolRoute, g: &BodyGuard, request: Request, next: Next) -> Response {
    let read_timeout = g.read_timeout;
    if let Some(Err(refused)) = request.extensions().get::<Identity>().map(|id| id.authorize(Scope::Write)) {
        return refuse_unread(refused, request.into_body(), g).await;
    }
    let caller = key_of(request.extensions().get::<Identity>());
    let slot = match route.slot(caller).await {
        Ok(slot) => slot,
        Err(e) => return refuse_unread(e, request.into_body(), g).await,
    };
    let (parts, body) = request.into_parts();
    let deadline = tokio::time::Instant::now() + read_timeout;
    let awaiting = g.arrivals.awaiting();
    let received = tokio::time::timeout_at(deadline, route.receive(body)).await;
    drop(awaiting);
    match received {
        Ok(Ok(spooled)) => {
            let mut request = Request::from_parts(parts, Body::empty());
            request.extensions_mut().insert(spooled);
            let response = next.run(request).await;
            drop(slot);
            response
        }
        Ok(Err(e)) => closing(e),
        Err(_) => timed_out(read_timeout),
    }
}

/// Refuses a request whose body the route will not take. A body no bigger
/// than `max_body_bytes` (what any route reads from anyone) is read and
/// dropped first, within the body-read timeout: closing on a client that is
/// still sending resets the connection, and a client whose write fails
/// (hyper's, the CLI's) reports a broken pipe instead of this answer. A
/// bigger body is refused at once, unread.
async fn refuse_unread(e: ApiError, mut body: Body, g: &BodyGuard) -> Response {
    let declared = body.size_hint().exact();
    if declared.is_none_or(|n| n <= g.max_bytes as u64) {
        let mut read = 0;
        let drain = async {
            while let Some(Ok(frame)) = std::future::poll_fn(|cx| std::pin::Pin::new(&mut body).poll_frame(cx)).await {
                read += frame.data_ref().map_or(0, Bytes::len);
                if read > g.max_bytes {
                    break;
                }
            }
        };
        let _ = tokio::time::timeout(g.read_timeout, drain).await;
    }
    closing(e)
}

fn timed_out(read_timeout: Duration) -> Response {
    metrics::counter!("inbetween_body_timeouts_total").increment(1);
    closing(ApiError::BodyTimeout { secs: read_timeout.as_secs() })
}

/// The whole body, counted into `held` against the arrival budget as it
/// comes; 413 once it passes `max_bytes`, 503 past the budget (400 if the
/// client breaks the stream off, or a compressed body does not decode).
/// A body sent with a `Content-Encoding` (`coding`) arrives here decoded
/// (`compression`), so both limits count decoded bytes.
async fn read_whole(
    mut body: Body,
    g: &BodyGuard,
    coding: Option<BodyCoding>,
    held: &mut Option<tokio::sync::OwnedSemaphorePermit>,
) -> Result<Bytes, ApiError> {
    let mut whole = bytes::BytesMut::new();
    while let Some(frame) = std::future::poll_fn(|cx| std::pin::Pin::new(&mut body).poll_frame(cx)).await {
        let frame = frame.map_err(|e| match coding {
            Some(BodyCoding(coding)) => ApiError::parameter(
                "body_not_decodable",
                "body",
                format!("the body is not valid {coding} (its Content-Encoding), or it was cut off: {e}"),
            ),
            None => ApiError::parameter("body_incomplete", "body", format!("{e}")),
        })?;
        let Ok(data) = frame.into_data() else { continue };
        if whole.len() + data.len() > g.max_bytes {
            return Err(ApiError::PayloadTooLarge { limit: g.max_bytes, setting: MAX_BODY_BYTES });
        }
        g.arrivals.take(held, data.len())?;
        whole.extend_from_slice(&data);
    }
    Ok(whole.freeze())
}

/// The error's response, telling the client the connection will close.
fn closing(e: ApiError) -> Response {
    let mut response = e.into_response();
    response.headers_mut().insert(header::CONNECTION, HeaderValue::from_static("close"));
    response
}
