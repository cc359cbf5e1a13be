//! Where clips are built: every `Clip::build` the server does (uploads,
//! replaces, imports, gRPC `PutClip`, cache misses) runs here, on a blocking
//! thread, and at most `max_concurrent_builds` at once.
//!
//! A build is CPU work bounded by `max_build_work`, up to a fraction of a
//! second; on the async workers it would stall everything they serve
//! (`/healthz`, gRPC `Ping`, pose requests) for that long. On the blocking
//! pool the probes keep answering, and the semaphore keeps many concurrent
//! uploads from taking every core: the rest wait, asynchronously, holding
//! nothing but their body. A waiter whose client goes away is dropped before
//! it starts; a started build runs to its end (bounded by its budget).

use tokio::sync::Semaphore;

use super::error::ApiError;
use super::metrics::join_failed;

/// The build gate (see the module docs).
#[derive(Debug)]
pub struct Builds {
    permits: Semaphore,
}

impl Builds {
    /// # Panics
    /// If `concurrency` is 0 (the configuration refuses it).
    pub fn new(concurrency: usize) -> Self {
        assert!(concurrency > 0, "builds need at least one permit");
        Builds { permits: Semaphore::new(concurrency) }
    }

    /// Runs `build` on a blocking thread once a permit is free.
    ///
    /// # Errors
    /// Whatever `build` returns; `internal` if it panicked (counted).
    pub async fn run<T, F>(&self, build: F) -> Result<T, ApiError>
    where
        F: FnOnce() -> Result<T, ApiError> + Send + 'static,
        T: Send + 'static,
    {
        // Never closed, so acquiring fails only if that changes.
        let _permit = self.permits.acquire().await.map_err(ApiError::internal)?;
        tokio::task::spawn_blocking(build).await.map_err(join_failed)?
    }

    /// Builds that could start now without waiting.
    pub fn available(&self) -> usize {
        self.permits.available_permits()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[tokio::test]
    async fn no_more_than_the_permits_run_at_once_and_never_on_the_caller() {
        let builds = Arc::new(Builds::new(2));
        let (running, peak) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        let caller = std::thread::current().id();
        let tasks: Vec<_> = (0..6)
            .map(|_| {
                let (builds, running, peak) = (builds.clone(), running.clone(), peak.clone());
                tokio::spawn(async move {
                    builds
                        .run(move || {
                            assert_ne!(std::thread::current().id(), caller, "a build on the async worker");
                            let now = running.fetch_add(1, Ordering::SeqCst) + 1;
                            peak.fetch_max(now, Ordering::SeqCst);
                            std::thread::sleep(std::time::Duration::from_millis(20));
                            running.fetch_sub(1, Ordering::SeqCst);
                            Ok(())
                        })
                        .await
                })
            })
            .collect();
        for task in tasks {
            task.await.unwrap().unwrap();
        }
        assert_eq!(peak.load(Ordering::SeqCst), 2, "the two permits were both used, and never more");
        assert_eq!(builds.available(), 2);
    }
}
