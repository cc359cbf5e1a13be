//! Bounded retries with exponential backoff for transient database failures.
//!
//! A connection reset, a server restart (`admin_shutdown`), a serialization
//! failure or a deadlock victim says nothing about the request: the same
//! statement may succeed a moment later, and a client should not see a 503
//! for a blip. A retry is only safe when the first attempt cannot have
//! committed, or when repeating it is harmless; the caller says which
//! failures qualify ([`Retry::Always`] for reads and id-keyed inserts,
//! [`Retry::IfNotExecuted`] for a replace or delete, whose repetition would
//! bump a version twice or turn a success into "not found").

use std::future::Future;
use std::time::Duration;

/// How often and how patiently to retry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RetryPolicy {
    /// Retries after the first attempt (0 disables retrying).
    pub retries: u32,
    /// The first backoff; each later one doubles, up to `max_backoff`.
    pub base_backoff: Duration,
    pub max_backoff: Duration,
}

impl Default for RetryPolicy {
    fn default() -> Self {
        RetryPolicy { retries: 3, base_backoff: Duration::from_millis(50), max_backoff: Duration::from_secs(1) }
    }
}

impl RetryPolicy {
    /// The wait before retry number `n` (0-based): doubling, capped, with up
    /// to a quarter of jitter so that nodes retrying together spread out.
    pub fn backoff(&self, n: u32) -> Duration {
        let exp = self.base_backoff.saturating_mul(1u32 << n.min(16)).min(self.max_backoff);
        let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.subsec_nanos());
        let quarter = exp.as_nanos() as u64 / 4;
        let jitter = if quarter == 0 { 0 } else { u64::from(nanos) % quarter };
        exp.saturating_sub(Duration::from_nanos(jitter))
    }
}

/// Which failures an operation may be repeated after.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Retry {
    /// Any transient failure: the operation is a read, or repeating it is harmless.
    Always,
    /// Only failures that prove the statement did not run (the connection
    /// could not be made, or the server refused or rolled back the statement).
    IfNotExecuted,
}

/// How a failure should be treated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transience {
    /// Permanent: retrying cannot help.
    Permanent,
    /// Transient, and the statement certainly did not run.
    NotExecuted,
    /// Transient, but the statement may have run (e.g. a connection reset
    /// after the statement was sent).
    Ambiguous,
}

/// Runs `attempt` until it succeeds, fails permanently, fails in a way
/// `mode` does not allow to repeat, or `policy.retries` are spent. `attempt`
/// gets the attempt number (0 first) so an insert can tell a duplicate of
/// its own earlier, committed attempt from a real conflict.
pub async fn with_retry<T, E, F, Fut>(
    policy: RetryPolicy,
    mode: Retry,
    classify: impl Fn(&E) -> Transience,
    mut attempt: F,
) -> Result<T, E>
where
    F: FnMut(u32) -> Fut,
    Fut: Future<Output = Result<T, E>>,
    E: std::fmt::Display,
{
    let mut n = 0;
    loop {
        match attempt(n).await {
            Ok(v) => return Ok(v),
            Err(e) => {
                let repeatable = match (classify(&e), mode) {
                    (Transience::Permanent, _) => false,
                    (Transience::NotExecuted, _) => true,
                    (Transience::Ambiguous, Retry::Always) => true,
                    (Transience::Ambiguous, Retry::IfNotExecuted) => false,
                };
                if !repeatable || n >= policy.retries {
                    return Err(e);
                }
                let wait = policy.backoff(n);
                tracing::warn!(error = %e, attempt = n + 1, ?wait, "transient store failure: retrying");
                metrics::counter!("inbetween_store_retries_total").increment(1);
                tokio::time::sleep(wait).await;
                n += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU32, Ordering};

    fn policy(retries: u32) -> RetryPolicy {
        RetryPolicy { retries, base_backoff: Duration::from_millis(1), max_backoff: Duration::from_millis(4) }
    }

    #[test]
    fn backoff_doubles_up_to_the_cap() {
        let p =
            RetryPolicy { retries: 9, base_backoff: Duration::from_millis(100), max_backoff: Duration::from_secs(1) };
        for (n, full) in [(0, 100), (1, 200), (2, 400), (3, 800), (4, 1000), (9, 1000)] {
            let b = p.backoff(n).as_millis() as u64;
            assert!(b <= full && b >= full * 3 / 4, "backoff({n}) = {b} ms, want ¾·{full}..={full}");
        }
    }

    async fn run(mode: Retry, failure: Transience, fail_times: u32, retries: u32) -> (Result<u32, String>, u32) {
        let calls = AtomicU32::new(0);
        let r = with_retry(
            policy(retries),
            mode,
            |_: &String| failure,
            |n| {
                calls.fetch_add(1, Ordering::SeqCst);
                async move { if n < fail_times { Err(format!("fail {n}")) } else { Ok(n) } }
            },
        )
        .await;
        (r, calls.load(Ordering::SeqCst))
    }

    #[tokio::test]
    async fn transient_failures_are_retried_within_the_bound() {
        assert_eq!(run(Retry::Always, Transience::Ambiguous, 2, 3).await, (Ok(2), 3));
        assert_eq!(run(Retry::IfNotExecuted, Transience::NotExecuted, 3, 3).await, (Ok(3), 4));
        assert_eq!(run(Retry::Always, Transience::NotExecuted, 5, 3).await, (Err("fail 3".into()), 4));
    }

    #[tokio::test]
    async fn permanent_or_ambiguous_write_failures_are_not_repeated() {
        assert_eq!(run(Retry::Always, Transience::Permanent, 1, 3).await, (Err("fail 0".into()), 1));
        assert_eq!(run(Retry::IfNotExecuted, Transience::Ambiguous, 1, 3).await, (Err("fail 0".into()), 1));
    }
}
