//! Where clips are built: every `Clip::build` the server does (uploads,
//! replaces, imports, gRPC `PutClip`, cache misses) runs here, on a blocking
//! thread, and at most `max_concurrent_builds` at once.
//!
//! A build is CPU work bounded by `max_build_work`, up to a fraction of a
//! second; on the async workers it would stall everything they serve
//! (`/healthz`, gRPC `Ping`, pose requests) for that long. On the blocking
//! pool the probes keep answering, and the semaphore keeps many concurrent
//! uploads from taking every core: the rest wait, asynchronously, holding
//! nothing but their body. A waiter whose client goes away (or whose request
//! times out) is dropped before it starts; a started build is handed a
//! cancel flag that is raised when its caller stops waiting, so it stops
//! within a few units of work instead of finishing in the background.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use tokio::sync::Semaphore;

use super::error::ApiError;
use super::metrics::join_failed;

/// The build gate (see the module docs).
#[derive(Debug)]
pub struct Builds {
    permits: Arc<Semaphore>,
}

/// Raises its flag when dropped: the awaiting side of a build went away.
struct CancelOnDrop(Arc<AtomicBool>);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

impl Builds {
    /// # Panics
    /// If `concurrency` is 0 (the configuration refuses it).
    pub fn new(concurrency: usize) -> Self {
        assert!(concurrency > 0, "builds need at least one permit");
        Builds { permits: Arc::new(Semaphore::new(concurrency)) }
    }

    /// Runs `build` on a blocking thread once a permit is free, with a flag
    /// raised if this future is dropped first (for `Clip::build_cancellable`).
    /// The thread holds the permit until it is done, so a cancelled build
    /// keeps its place until it has noticed.
    ///
    /// # Errors
    /// Whatever `build` returns; `internal` if it panicked (counted).
    pub async fn run<T, F>(&self, build: F) -> Result<T, ApiError>
    where
        F: FnOnce(&AtomicBool) -> Result<T, ApiError> + Send + 'static,
        T: Send + 'static,
    {
        // Never closed, so acquiring fails only if that changes.
        let permit = self.permits.clone().acquire_owned().await.map_err(ApiError::internal)?;
        let cancel = CancelOnDrop(Arc::new(AtomicBool::new(false)));
        let flag = cancel.0.clone();
        let result = tokio::task::spawn_blocking(move || {
            let _permit = permit;
            build(&flag)
        })
        .await;
        drop(cancel);
        result.map_err(join_failed)?
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
                        .run(move |_| {
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

    #[tokio::test]
    async fn a_build_whose_caller_stops_waiting_sees_its_flag_raised() {
        let builds = Arc::new(Builds::new(1));
        let (seen_tx, seen_rx) = std::sync::mpsc::channel();
        let (started_tx, started_rx) = tokio::sync::oneshot::channel();
        let waiting = builds.run(move |cancel| {
            started_tx.send(()).unwrap();
            let since = std::time::Instant::now();
            while !cancel.load(Ordering::Relaxed) && since.elapsed().as_secs() < 10 {
                std::thread::yield_now();
            }
            seen_tx.send(cancel.load(Ordering::Relaxed)).unwrap();
            Ok(())
        });
        tokio::select! {
            _ = waiting => panic!("the build ended on its own"),
            _ = started_rx => {}
        }
        // The future was dropped by select!: the build sees the flag.
        let seen = tokio::task::spawn_blocking(move || seen_rx.recv().unwrap()).await.unwrap();
        assert!(seen, "the flag was raised");
        let ok = builds.run(|_| Ok(7)).await.unwrap();
        assert_eq!((ok, builds.available()), (7, 1), "the permit came back once the thread was done");
    }
}
