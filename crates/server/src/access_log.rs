//! The access log: one line at `info` (target `inbetween::access`) for
//! every REST request answered 4xx or 5xx, and for a sampled share
//! (`access_log_sample`, default 1%) of the rest, with the method, the
//! matched route template (never the raw path, which carries clip ids;
//! `unmatched` for a path no route has), the status, the latency until the
//! answer's head (an answer sent in pieces goes on after it), the request id
//! (`x-request-id`, as the client sees it) and the caller: the token's name
//! when a token identified it, else its address (`unauthenticated` for a
//! token that matches nothing), with the client's address beside it.
//!
//! Sampling is counted, not random: of the first `n` such requests,
//! `⌊n·rate⌋` are logged, so a rate of 0.01 logs the 100th, 200th, … and 1
//! logs all. Filter the lines out with `INBETWEEN_LOG=info,inbetween::access=off`.

use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use axum::extract::{ConnectInfo, MatchedPath, Request, State};
use axum::http::HeaderValue;
use axum::middleware::Next;
use axum::response::Response;

use super::auth::Identity;

/// The log's target, for filters.
pub const TARGET: &str = "inbetween::access";

/// What the middleware shares: the sampling counter.
#[derive(Debug, Clone)]
pub struct AccessLog {
    sampler: Arc<Sampler>,
}

impl AccessLog {
    /// Logs `rate` (0..=1) of the 1xx–3xx answers.
    pub fn new(rate: f64) -> AccessLog {
        // Parts per million: exact for every rate a person would configure.
        let per_million = (rate.clamp(0.0, 1.0) * 1e6).round() as u64;
        AccessLog { sampler: Arc::new(Sampler { per_million, seen: AtomicU64::new(0) }) }
    }
}

#[derive(Debug)]
struct Sampler {
    per_million: u64,
    seen: AtomicU64,
}

impl Sampler {
    /// Whether the next request is one of the sampled: the `n`-th is when
    /// `⌊n·rate⌋` steps up at `n`.
    fn take(&self) -> bool {
        let n = u128::from(self.seen.fetch_add(1, Ordering::Relaxed));
        let p = u128::from(self.per_million);
        (n + 1) * p / 1_000_000 > n * p / 1_000_000
    }
}

/// What the request told us, kept until its answer is known (cheap clones:
/// nothing is formatted unless the line is written).
struct Seen {
    method: axum::http::Method,
    route: Option<MatchedPath>,
    request_id: Option<HeaderValue>,
    peer: Option<IpAddr>,
}

/// The middleware: the auth layer (inside it) leaves the request's
/// [`Identity`] on the answer's extensions; a request answered before auth
/// ran (a timeout, a panic) is named by its peer address.
pub async fn log(State(log): State<AccessLog>, request: Request, next: Next) -> Response {
    let started = Instant::now();
    let seen = Seen {
        method: request.method().clone(),
        route: request.extensions().get::<MatchedPath>().cloned(),
        request_id: request.headers().get("x-request-id").cloned(),
        peer: request.extensions().get::<ConnectInfo<SocketAddr>>().map(|ConnectInfo(a)| a.ip()),
    };
    let response = next.run(request).await;
    let status = response.status();
    if status.is_client_error() || status.is_server_error() || log.sampler.take() {
        write(&seen, &response, started);
    }
    response
}

fn write(seen: &Seen, response: &Response, started: Instant) {
    let identity = response.extensions().get::<Identity>();
    let (caller, client) = match identity {
        Some(identity) => match identity.caller() {
            Some(caller) => {
                let client = caller.addr.or(seen.peer);
                let name = caller.token.as_deref().map(str::to_owned).or_else(|| client.map(|a| a.to_string()));
                (name.unwrap_or_else(|| "-".into()), client)
            }
            None => ("unauthenticated".to_owned(), seen.peer),
        },
        None => (seen.peer.map_or_else(|| "-".into(), |a| a.to_string()), seen.peer),
    };
    tracing::info!(
        target: TARGET,
        method = %seen.method,
        route = seen.route.as_ref().map_or("unmatched", MatchedPath::as_str),
        status = response.status().as_u16(),
        // Whole microseconds, so the number prints short.
        latency_ms = started.elapsed().as_micros() as f64 / 1e3,
        request_id = seen.request_id.as_ref().and_then(|v| v.to_str().ok()).unwrap_or("-"),
        caller = %caller,
        client = %client.map_or_else(|| "-".into(), |a| a.to_string()),
        "request"
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn logged(rate: f64, requests: usize) -> Vec<usize> {
        let log = AccessLog::new(rate);
        (1..=requests).filter(|_| log.sampler.take()).collect()
    }

    #[test]
    fn sampling_logs_floor_n_times_rate_of_the_first_n() {
        assert_eq!(logged(0.01, 1000), vec![100, 200, 300, 400, 500, 600, 700, 800, 900, 1000]);
        assert_eq!(logged(1.0, 5), vec![1, 2, 3, 4, 5]);
        assert!(logged(0.0, 10_000).is_empty());
        assert_eq!(logged(0.25, 12), vec![4, 8, 12]);
        assert_eq!(logged(0.5, 9), vec![2, 4, 6, 8]);
    }
}
