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

use std::time::Duration;

use axum::body::{Body, Bytes, HttpBody};
use axum::extract::{Request, State};
use axum::http::{HeaderValue, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::error::ApiError;
use super::shed::Arrivals;

/// The limits the middleware applies.
#[derive(Debug, Clone)]
pub struct BodyGuard {
    pub max_bytes: usize,
    pub read_timeout: Duration,
    /// The budget of bodies held at once (`max_arriving_bytes`).
    pub arrivals: Arrivals,
}

/// The middleware (see the module doc).
pub async fn guard(State(g): State<BodyGuard>, request: Request, next: Next) -> Response {
    let declared = request.headers().get(header::CONTENT_LENGTH).and_then(|v| v.to_str().ok()?.parse::<u64>().ok());
    if declared.is_some_and(|n| n > g.max_bytes as u64) {
        return closing(ApiError::PayloadTooLarge { limit: g.max_bytes });
    }
    if request.body().is_end_stream() {
        return next.run(request).await;
    }
    let (parts, body) = request.into_parts();
    let deadline = tokio::time::Instant::now() + g.read_timeout;
    let mut held = None;
    match tokio::time::timeout_at(deadline, read_whole(body, &g, &mut held)).await {
        Ok(Ok(bytes)) => {
            let response = next.run(Request::from_parts(parts, Body::from(bytes))).await;
            drop(held);
            response
        }
        Ok(Err(e)) => closing(e),
        Err(_) => {
            metrics::counter!("inbetween_body_timeouts_total").increment(1);
            closing(ApiError::BodyTimeout { secs: g.read_timeout.as_secs() })
        }
    }
}

/// The whole body, counted into `held` against the arrival budget as it
/// comes; 413 once it passes `max_bytes`, 503 past the budget (400 if the
/// client breaks the stream off).
async fn read_whole(
    mut body: Body,
    g: &BodyGuard,
    held: &mut Option<tokio::sync::OwnedSemaphorePermit>,
) -> Result<Bytes, ApiError> {
    let mut whole = bytes::BytesMut::new();
    while let Some(frame) = std::future::poll_fn(|cx| std::pin::Pin::new(&mut body).poll_frame(cx)).await {
        let frame = frame.map_err(|e| ApiError::parameter("body_incomplete", "body", format!("{e}")))?;
        let Ok(data) = frame.into_data() else { continue };
        if whole.len() + data.len() > g.max_bytes {
            return Err(ApiError::PayloadTooLarge { limit: g.max_bytes });
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
