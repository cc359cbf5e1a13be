//! The per-caller write rate limit: a token bucket per [`Caller`] (keyed by
//! [`Caller::key`]: the token's name when a configured token identifies the
//! caller, else its address), refilled at
//! `write_rate` per second up to `write_burst`. A write over it is answered
//! 429 with `Retry-After` before its body is read, or `RESOURCE_EXHAUSTED`
//! on gRPC (`PutClip`, `DeleteClip`). One limiter serves both transports,
//! so a caller cannot double its budget by switching. Reads are not limited
//! here (they are cheap and cached; the in-flight budget bounds them).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::extract::{Request, State};
use axum::http::Method;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::auth::{Caller, CallerKey, Identity};
use super::error::ApiError;

/// Buckets kept before full (idle) ones are forgotten.
const PRUNE_AT: usize = 4096;

#[derive(Debug, Clone, Copy)]
struct Bucket {
    tokens: f64,
    at: Instant,
}

/// Token buckets, one per caller.
#[derive(Debug)]
pub struct WriteLimiter {
    rate: f64,
    burst: f64,
    buckets: Mutex<HashMap<CallerKey, Bucket>>,
}

impl WriteLimiter {
    pub fn new(rate_per_sec: u32, burst: u32) -> WriteLimiter {
        WriteLimiter { rate: f64::from(rate_per_sec), burst: f64::from(burst), buckets: Mutex::default() }
    }

    /// Takes one token of the caller `key` at `now`, or says how long until
    /// one is available.
    pub fn take(&self, key: CallerKey, now: Instant) -> Result<(), Duration> {
        let mut buckets = crate::sync::lock(&self.buckets);
        if buckets.len() >= PRUNE_AT {
            let (rate, burst) = (self.rate, self.burst);
            buckets.retain(|_, b| b.tokens + now.saturating_duration_since(b.at).as_secs_f64() * rate < burst);
        }
        let b = buckets.entry(key).or_insert(Bucket { tokens: self.burst, at: now });
        b.tokens = (b.tokens + now.saturating_duration_since(b.at).as_secs_f64() * self.rate).min(self.burst);
        b.at = now;
        if b.tokens >= 1.0 {
            b.tokens -= 1.0;
            Ok(())
        } else {
            Err(Duration::from_secs_f64((1.0 - b.tokens) / self.rate))
        }
    }

    /// Admits one write of `caller` now, or says when to retry (counted in
    /// `inbetween_writes_rate_limited_total`).
    ///
    /// # Errors
    /// [`ApiError::RateLimited`] with the whole seconds until a token is back.
    pub fn admit(&self, caller: &Caller) -> Result<(), ApiError> {
        self.take(caller.key(), Instant::now()).map_err(|wait| {
            metrics::counter!("inbetween_writes_rate_limited_total").increment(1);
            ApiError::RateLimited { retry_after: wait.as_secs_f64().ceil().max(1.0) as u64 }
        })
    }
}

/// Whether a request changes state: every non-GET route but the reads sent
/// as POST because their question is a body: the batch `POST
/// /v1/clips/{id}/sample` and the motion reads `POST /v1/poses` and
/// `/v1/samples` (SPEC §6).
fn is_write(method: &Method, path: &str) -> bool {
    let read_by_post = path.ends_with("/sample") || matches!(path, "/v1/poses" | "/v1/samples");
    !matches!(*method, Method::GET | Method::HEAD | Method::OPTIONS) && !read_by_post
}

/// The middleware: limits writes, passes everything else. It runs inside
/// `auth::identify_requests` and counts the caller found there; a write
/// whose token auth refused is not counted (its handler answers 401).
pub async fn limit_writes(State(limiter): State<Arc<WriteLimiter>>, request: Request, next: Next) -> Response {
    if !is_write(request.method(), request.uri().path()) {
        return next.run(request).await;
    }
    let Some(identity) = request.extensions().get::<Identity>() else {
        let missing = anyhow::anyhow!("no caller identity: the auth middleware must run before the rate limit");
        return ApiError::internal(missing).into_response();
    };
    let admitted = identity.caller().map_or(Ok(()), |caller| limiter.admit(caller));
    match admitted {
        Ok(()) => next.run(request).await,
        Err(limited) => limited.into_response(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bucket_allows_its_burst_then_refills_at_the_rate() {
        let limiter = WriteLimiter::new(2, 3);
        let a = CallerKey::Token(Arc::from("a"));
        let b = CallerKey::Addr([10, 0, 0, 1].into());
        let t0 = Instant::now();
        for _ in 0..3 {
            limiter.take(a.clone(), t0).unwrap();
        }
        let wait = limiter.take(a.clone(), t0).unwrap_err();
        assert!((wait.as_secs_f64() - 0.5).abs() < 1e-9, "{wait:?}");
        // Another caller has its own bucket.
        limiter.take(b, t0).unwrap();
        // Half a second later one token (2/s) is back, and only one.
        let t1 = t0 + Duration::from_millis(500);
        limiter.take(a.clone(), t1).unwrap();
        assert!(limiter.take(a.clone(), t1).is_err());
        // Never more than the burst, however long the pause.
        let t2 = t1 + Duration::from_secs(60);
        for _ in 0..3 {
            limiter.take(a.clone(), t2).unwrap();
        }
        assert!(limiter.take(a, t2).is_err());
    }

    #[test]
    fn only_state_changing_routes_are_writes() {
        assert!(is_write(&Method::POST, "/v1/clips"));
        assert!(is_write(&Method::POST, "/v1/clips/import"));
        assert!(is_write(&Method::PUT, "/v1/clips/x"));
        assert!(is_write(&Method::DELETE, "/v1/clips/x"));
        assert!(!is_write(&Method::POST, "/v1/clips/x/sample"));
        assert!(!is_write(&Method::POST, "/v1/poses"));
        assert!(!is_write(&Method::POST, "/v1/samples"));
        assert!(is_write(&Method::POST, "/v1/broadcasts/x/controls"));
        assert!(!is_write(&Method::GET, "/v1/clips/x/pose"));
    }
}
