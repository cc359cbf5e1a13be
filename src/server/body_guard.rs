//! Request bodies from slow or oversized senders. A declared
//! `Content-Length` over the body limit is answered 413 before a byte of the
//! body is read (chunked bodies are cut off at the limit by axum's
//! `DefaultBodyLimit`); a body that has not fully arrived within the
//! body-read timeout (counted from the end of the head) is answered 408. Both
//! close the connection, whose unread rest is never drained. (Slow heads and
//! idle keep-alive connections are hyper's header-read timeout, in `listen`.)

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::{HeaderValue, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use futures_util::StreamExt;

use super::error::ApiError;

/// The limits the middleware applies.
#[derive(Debug, Clone, Copy)]
pub struct BodyGuard {
    pub max_bytes: usize,
    pub read_timeout: Duration,
}

#[derive(Debug, thiserror::Error)]
#[error("the request body did not arrive in time")]
struct TimedOut;

/// The middleware (see the module doc).
pub async fn guard(State(g): State<BodyGuard>, request: Request, next: Next) -> Response {
    let headers = request.headers();
    let declared = headers.get(header::CONTENT_LENGTH).and_then(|v| v.to_str().ok()?.parse::<u64>().ok());
    if declared.is_some_and(|n| n > g.max_bytes as u64) {
        return closing(ApiError::PayloadTooLarge { limit: g.max_bytes });
    }
    let has_body = declared.is_some_and(|n| n > 0) || headers.contains_key(header::TRANSFER_ENCODING);
    if !has_body {
        return next.run(request).await;
    }
    let deadline = tokio::time::Instant::now() + g.read_timeout;
    let late = Arc::new(AtomicBool::new(false));
    let flag = late.clone();
    let (parts, body) = request.into_parts();
    let chunks = futures_util::stream::unfold(Some(body.into_data_stream()), move |state| {
        let flag = flag.clone();
        async move {
            let mut chunks = state?;
            match tokio::time::timeout_at(deadline, chunks.next()).await {
                Ok(Some(chunk)) => Some((chunk, Some(chunks))),
                Ok(None) => None,
                Err(_) => {
                    flag.store(true, Ordering::Release);
                    Some((Err(axum::Error::new(TimedOut)), None))
                }
            }
        }
    });
    let response = next.run(Request::from_parts(parts, Body::from_stream(chunks))).await;
    if late.load(Ordering::Acquire) {
        metrics::counter!("inbetween_body_timeouts_total").increment(1);
        return closing(ApiError::BodyTimeout { secs: g.read_timeout.as_secs() });
    }
    response
}

/// The error's response, telling the client the connection will close.
fn closing(e: ApiError) -> Response {
    let mut response = e.into_response();
    response.headers_mut().insert(header::CONNECTION, HeaderValue::from_static("close"));
    response
}
