//! Where priced work runs: a fixed set of threads, one per core by default
//! (`work_threads`), taking jobs in the order they came. Pose evaluation,
//! IK and answer encoding run here, never on the async workers (which must
//! keep answering `/healthz` and `Ping`) and never on tokio's blocking pool
//! (which grows to hundreds of threads that all compete for the cores).
//!
//! Every job carries a [`Cancel`] flag, raised when the future awaiting it
//! is dropped (the client left, or the request's deadline cut it off) or
//! when its own deadline passes ([`Pool::run`] answers 503 then). A job
//! checks the flag between poses ([`Cancel::proceed`]); chain IK solves
//! check it between iterations (`anim::ik::stoppable`). A job cancelled
//! before it starts is skipped. So abandoned work stops within one
//! iteration instead of running on for seconds after its client left.

use std::collections::VecDeque;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

use crate::error::ApiError;
use crate::sync::lock;

type Job = Box<dyn FnOnce() + Send>;

/// A job's cancel flag, and the pool's count of the steps jobs took.
#[derive(Debug, Clone)]
pub struct Cancel {
    flag: Arc<AtomicBool>,
    steps: Arc<AtomicU64>,
}

impl Cancel {
    /// Whether to go on with the next step (a pose, a batch): false once
    /// the job's caller has given up. Counts the step.
    pub fn proceed(&self) -> bool {
        if self.is_raised() {
            return false;
        }
        self.steps.fetch_add(1, Ordering::Relaxed);
        true
    }

    pub fn is_raised(&self) -> bool {
        self.flag.load(Ordering::Relaxed)
    }

    /// The flag itself, for work that watches one (`Clip::build_limited`).
    pub fn flag(&self) -> &AtomicBool {
        &self.flag
    }

    fn raise(&self) {
        self.flag.store(true, Ordering::Relaxed);
    }
}

/// Raises the flag when dropped: the awaiting side went away.
struct RaiseOnDrop(Cancel);

impl Drop for RaiseOnDrop {
    fn drop(&mut self) {
        self.0.raise();
    }
}

#[derive(Default)]
struct Queue {
    jobs: VecDeque<Job>,
    closed: bool,
}

struct Inner {
    queue: Mutex<Queue>,
    ready: Condvar,
    steps: Arc<AtomicU64>,
    cancelled: AtomicU64,
}

/// The work threads (see the module docs). Dropping the pool lets its
/// threads finish the queued jobs and end.
pub struct Pool {
    inner: Arc<Inner>,
    threads: usize,
}

impl Pool {
    /// # Panics
    /// If `threads` is 0 (the configuration refuses it) or a thread cannot start.
    pub fn new(threads: usize) -> Pool {
        assert!(threads > 0, "a work pool needs a thread");
        let inner = Arc::new(Inner {
            queue: Mutex::default(),
            ready: Condvar::new(),
            steps: Arc::default(),
            cancelled: AtomicU64::new(0),
        });
        for k in 0..threads {
            let inner = Arc::clone(&inner);
            std::thread::Builder::new()
                .name(format!("inbetween-work-{k}"))
                .spawn(move || {
                    lower_priority();
                    work(&inner)
                })
                .expect("a work thread starts");
        }
        Pool { inner, threads }
    }

    pub fn threads(&self) -> usize {
        self.threads
    }

    /// Steps taken by every job so far ([`Cancel::proceed`] calls that went on).
    pub fn steps(&self) -> u64 {
        self.inner.steps.load(Ordering::Relaxed)
    }

    /// Jobs stopped or skipped because their caller gave up.
    pub fn cancelled(&self) -> u64 {
        self.inner.cancelled.load(Ordering::Relaxed)
    }

    /// Jobs waiting for a thread.
    pub fn queued(&self) -> usize {
        lock(&self.inner.queue).jobs.len()
    }

    /// A fresh flag, counting its steps with the pool's.
    pub fn cancel(&self) -> Cancel {
        Cancel { flag: Arc::default(), steps: Arc::clone(&self.inner.steps) }
    }

    /// Runs `job` on a work thread and waits for it, at most `deadline`.
    /// Dropping the returned future, or the deadline passing, raises the
    /// job's flag.
    ///
    /// # Errors
    /// `request_timeout` (503, gRPC `DEADLINE_EXCEEDED`) at the deadline;
    /// `internal` if the job panicked.
    pub async fn run<T, F>(&self, deadline: Duration, job: F) -> Result<T, ApiError>
    where
        F: FnOnce(&Cancel) -> T + Send + 'static,
        T: Send + 'static,
    {
        let cancel = self.cancel();
        let (tx, rx) = tokio::sync::oneshot::channel();
        let (theirs, inner) = (cancel.clone(), Arc::clone(&self.inner));
        self.submit(Box::new(move || {
            if theirs.is_raised() {
                inner.cancelled.fetch_add(1, Ordering::Relaxed);
                return;
            }
            let out = anim::ik::stoppable(&theirs.flag, || job(&theirs));
            if theirs.is_raised() {
                inner.cancelled.fetch_add(1, Ordering::Relaxed);
            }
            let _ = tx.send(out);
        }));
        let guard = RaiseOnDrop(cancel);
        match tokio::time::timeout(deadline, rx).await {
            Ok(Ok(out)) => Ok(out),
            Ok(Err(_)) => Err(ApiError::internal(anyhow::anyhow!("a work job panicked"))),
            Err(_) => {
                drop(guard);
                metrics::counter!("inbetween_work_timeouts_total").increment(1);
                Err(ApiError::Timeout { secs: deadline.as_secs() })
            }
        }
    }

    fn submit(&self, job: Job) {
        lock(&self.inner.queue).jobs.push_back(job);
        self.inner.ready.notify_one();
    }
}

impl Drop for Pool {
    fn drop(&mut self) {
        lock(&self.inner.queue).closed = true;
        self.inner.ready.notify_all();
    }
}

/// How much less CPU priority work threads take than the async workers
/// (a `nice` increment): when the cores are busy, `/healthz`, `Ping` and
/// the accept loop are scheduled before more evaluation.
const NICENESS: libc::c_int = 10;

/// Lowers this thread's CPU priority by [`NICENESS`] (Linux: per thread;
/// elsewhere, and if refused, the thread keeps the process's).
fn lower_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: `gettid` has no preconditions; `setpriority` on our own thread
    // id only changes this thread's nice value, and its failure is harmless.
    unsafe {
        let tid = libc::gettid();
        let current = libc::getpriority(libc::PRIO_PROCESS, tid as libc::id_t);
        libc::setpriority(libc::PRIO_PROCESS, tid as libc::id_t, current + NICENESS);
    }
}

/// A work thread: takes jobs until the pool is dropped and the queue empty.
/// A job that panics is counted (`inbetween_panics_total{source="task"}`)
/// and its caller answered 500; the thread goes on.
fn work(inner: &Inner) {
    loop {
        let job = {
            let mut queue = lock(&inner.queue);
            loop {
                if let Some(job) = queue.jobs.pop_front() {
                    break job;
                }
                if queue.closed {
                    return;
                }
                queue = inner.ready.wait(queue).unwrap_or_else(std::sync::PoisonError::into_inner);
            }
        };
        if std::panic::catch_unwind(AssertUnwindSafe(job)).is_err() {
            crate::panics::caught("task");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;
    use std::time::Instant;

    #[tokio::test]
    async fn no_more_jobs_run_at_once_than_threads_and_never_on_the_caller() {
        let pool = Arc::new(Pool::new(2));
        let (running, peak) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        let caller = std::thread::current().id();
        let tasks: Vec<_> = (0..6)
            .map(|_| {
                let (pool, running, peak) = (pool.clone(), running.clone(), peak.clone());
                tokio::spawn(async move {
                    pool.run(Duration::from_secs(10), move |_| {
                        assert_ne!(std::thread::current().id(), caller);
                        let now = running.fetch_add(1, Ordering::SeqCst) + 1;
                        peak.fetch_max(now, Ordering::SeqCst);
                        std::thread::sleep(Duration::from_millis(20));
                        running.fetch_sub(1, Ordering::SeqCst);
                    })
                    .await
                })
            })
            .collect();
        for task in tasks {
            task.await.unwrap().unwrap();
        }
        assert_eq!(peak.load(Ordering::SeqCst), 2);
    }

    /// The deadline answers 503 and the job sees its flag at its next step.
    #[tokio::test]
    async fn a_job_past_its_deadline_is_answered_and_stops() {
        let pool = Pool::new(1);
        let (stopped_tx, stopped_rx) = std::sync::mpsc::channel();
        let answer = pool
            .run(Duration::from_millis(50), move |cancel| {
                let since = Instant::now();
                while cancel.proceed() && since.elapsed() < Duration::from_secs(10) {
                    std::thread::sleep(Duration::from_millis(1));
                }
                stopped_tx.send(Instant::now()).unwrap();
            })
            .await;
        let answered = Instant::now();
        assert_eq!(answer.unwrap_err().code(), "request_timeout");
        let stopped = stopped_rx.recv_timeout(Duration::from_secs(5)).expect("the job stopped");
        // 10 ms is the promise; a loaded test machine only gets a generous bound
        // (timing claims are checked with INBETWEEN_SLOW=1).
        let bound = if std::env::var_os("INBETWEEN_SLOW").is_some() { 10 } else { 1000 };
        let ran_on = stopped.saturating_duration_since(answered);
        assert!(ran_on < Duration::from_millis(bound), "the job ran on for {ran_on:?}");
        // Counted by the work thread just after the job returns.
        let counted = Instant::now();
        while pool.cancelled() == 0 && counted.elapsed() < Duration::from_secs(5) {
            std::thread::yield_now();
        }
        assert_eq!(pool.cancelled(), 1);
    }

    /// A job whose caller left before it started never runs.
    #[tokio::test]
    async fn a_job_dropped_before_it_starts_is_skipped() {
        let pool = Arc::new(Pool::new(1));
        let (release_tx, release_rx) = std::sync::mpsc::channel::<()>();
        let (started_tx, started_rx) = std::sync::mpsc::channel::<()>();
        let blocker = tokio::spawn({
            let pool = pool.clone();
            let job = move |_: &Cancel| {
                started_tx.send(()).unwrap();
                release_rx.recv().unwrap()
            };
            async move { pool.run(Duration::from_secs(10), job).await }
        });
        // The one thread busy with the blocker, so the next job can only queue.
        while started_rx.try_recv().is_err() {
            tokio::task::yield_now().await;
        }
        let ran = Arc::new(AtomicBool::new(false));
        let seen = ran.clone();
        let waiting = pool.run(Duration::from_secs(10), move |_| seen.store(true, Ordering::SeqCst));
        // Polled once (queued), then dropped.
        assert!(futures_util::poll!(Box::pin(waiting)).is_pending());
        release_tx.send(()).unwrap();
        blocker.await.unwrap().unwrap();
        let done = pool.run(Duration::from_secs(10), |_| ()).await;
        assert!(done.is_ok());
        assert!(!ran.load(Ordering::SeqCst), "the abandoned job ran");
        assert_eq!(pool.cancelled(), 1);
    }
}
