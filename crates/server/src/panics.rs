//! Counting panics wherever they are caught: `inbetween_panics_total`,
//! labelled by where. A panic is always a bug (bad input must become a 4xx),
//! so the counter staying 0 under the malformed corpus is part of the
//! hardening proof (tests/service/hardening). Request handlers are guarded by a tower
//! layer; the tasks that outlive a request (playbacks, WebSocket streams,
//! gRPC stream bodies and control readers) are guarded here.

use std::future::Future;
use std::panic::AssertUnwindSafe;

use futures_util::FutureExt;

/// Counts (and logs) one caught panic.
pub(crate) fn caught(source: &'static str) {
    tracing::error!(source, "a panic was caught");
    metrics::counter!("inbetween_panics_total", "source" => source).increment(1);
}

/// Runs `fut`, counting a panic instead of letting it unwind further.
/// Returns `None` if it panicked.
pub(crate) async fn guarded<T>(source: &'static str, fut: impl Future<Output = T>) -> Option<T> {
    match AssertUnwindSafe(fut).catch_unwind().await {
        Ok(value) => Some(value),
        Err(_) => {
            caught(source);
            None
        }
    }
}

/// `tokio::spawn` of a task whose panic is counted.
pub(crate) fn spawn_guarded(source: &'static str, fut: impl Future<Output = ()> + Send + 'static) {
    tokio::spawn(async move {
        guarded(source, fut).await;
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_panic_in_a_guarded_future_is_contained_and_a_value_passes_through() {
        assert_eq!(guarded("test", async { 7 }).await, Some(7));
        let panicked: Option<()> = guarded("test", async { panic!("a bug") }).await;
        assert_eq!(panicked, None);
    }
}
