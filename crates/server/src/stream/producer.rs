//! The producers' thread: a current-thread tokio runtime on its own OS
//! thread, where broadcast tasks run when the engine uses the precise
//! timer (the server does; paused-clock tests keep them on their runtime).
//!
//! A broadcast's tick wakes every viewer's task at once. On the server's
//! shared workers the broadcast task's own next wake-up then queued behind
//! those thousands of viewer tasks, so with 5,000 viewers at 30 fps it
//! evaluated only 434 of 600 ticks and skipped the rest for every viewer
//! (BENCHMARKS.md, issue 19). On this thread the task that steps, encodes
//! and publishes a tick never waits behind its viewers: the kernel runs
//! it beside the workers, and waking a viewer from here only queues that
//! viewer on them. A slow fan-out then costs each late viewer its own
//! frames (its `dropped`), never the tick itself. What a broadcast task
//! starts besides (store writes, long catch-ups) goes to the runtime it
//! was created from.
//!
//! The thread starts on first use and lives as long as the process, like
//! the `ticker` thread; each task on it ends as broadcasts do (deleted,
//! idle, or at its engine's shutdown).

use std::future::Future;
use std::sync::OnceLock;

use tokio::runtime::{Builder, Handle};

/// Runs `task` on the producers' thread.
pub(crate) fn spawn(task: impl Future<Output = ()> + Send + 'static) {
    drop(handle().spawn(task));
}

fn handle() -> &'static Handle {
    static HANDLE: OnceLock<Handle> = OnceLock::new();
    HANDLE.get_or_init(|| {
        let runtime = Builder::new_current_thread().enable_all().build().expect("building the producers' runtime");
        let handle = runtime.handle().clone();
        std::thread::Builder::new()
            .name("inbetween-broadcasts".into())
            .spawn(move || runtime.block_on(std::future::pending::<()>()))
            .expect("spawning the producers' thread");
        handle
    })
}
