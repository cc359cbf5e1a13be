//! A precise tick timer: one thread that wakes playbacks at their due
//! instants, to tens of microseconds instead of tokio's whole milliseconds.
//!
//! tokio's timer wheel rounds every sleep up to the next millisecond and
//! fires only when a worker gets round to polling its driver, so a 60 fps
//! frame left on average half a millisecond late and, under load, several.
//! Here every due instant is a key of one ordered map holding the wakers of
//! the tasks due then; the thread sleeps (`park_timeout`, a futex with the
//! kernel's 50 µs slack) until the earliest key, takes every key that is
//! due and wakes its tasks. Streams of one rate and phase share their due
//! instants exactly (`schedule::Grid`), so thousands of streams cost the
//! thread about `fps × phases` wake-ups a second, not one per stream.
//!
//! The thread starts on first use and lives as long as the process. It
//! never runs task code: waking a tokio task only queues it.

use std::collections::BTreeMap;
use std::future::Future;
use std::pin::Pin;
use std::sync::{Mutex, OnceLock};
use std::task::{Context, Poll, Waker};
use std::thread::Thread;
use std::time::Instant;

struct Shared {
    due: Mutex<BTreeMap<Instant, Vec<Waker>>>,
    thread: Thread,
}

fn shared() -> &'static Shared {
    static SHARED: OnceLock<Shared> = OnceLock::new();
    SHARED.get_or_init(|| {
        let thread = std::thread::Builder::new()
            .name("inbetween-ticks".into())
            .spawn(run)
            .expect("spawning the tick timer thread");
        Shared { due: Mutex::default(), thread: thread.thread().clone() }
    })
}

fn run() {
    let shared = shared();
    let mut woken = Vec::new();
    loop {
        let now = Instant::now();
        let next = {
            let mut due = crate::sync::lock(&shared.due);
            while let Some(entry) = due.first_entry() {
                if *entry.key() > now {
                    break;
                }
                woken.append(&mut entry.remove());
            }
            due.keys().next().copied()
        };
        for waker in woken.drain(..) {
            waker.wake();
        }
        match next {
            Some(at) => std::thread::park_timeout(at.saturating_duration_since(Instant::now())),
            None => std::thread::park(),
        }
    }
}

/// Resolves at `due` (or at once if it has passed).
pub fn sleep_until(due: Instant) -> TickSleep {
    TickSleep { due, registered: None }
}

/// The future of [`sleep_until`]. Dropping it early leaves its waker queued
/// until `due`: one spurious wake-up, which tasks tolerate.
#[derive(Debug)]
pub struct TickSleep {
    due: Instant,
    registered: Option<Waker>,
}

impl Future for TickSleep {
    type Output = ();

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        if Instant::now() >= self.due {
            return Poll::Ready(());
        }
        if self.registered.as_ref().is_some_and(|w| w.will_wake(cx.waker())) {
            return Poll::Pending;
        }
        let shared = shared();
        let earliest = {
            let mut due = crate::sync::lock(&shared.due);
            due.entry(self.due).or_default().push(cx.waker().clone());
            due.keys().next() == Some(&self.due)
        };
        // A new earliest instant: the thread may be parked until a later one.
        if earliest {
            shared.thread.unpark();
        }
        self.registered = Some(cx.waker().clone());
        Poll::Pending
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn sleepers_wake_no_earlier_than_their_instants_and_soon_after() {
        let start = Instant::now();
        // Out of order, some sharing an instant.
        let offsets = [30u64, 10, 20, 10, 40, 5];
        let tasks: Vec<_> = offsets
            .iter()
            .map(|&ms| {
                let due = start + Duration::from_millis(ms);
                tokio::spawn(async move {
                    sleep_until(due).await;
                    Instant::now().checked_duration_since(due)
                })
            })
            .collect();
        for (task, ms) in tasks.into_iter().zip(offsets) {
            // Never early (the future checks the clock); late by the
            // scheduler's wake-up only, a latency checked in the slow runs
            // (INBETWEEN_SLOW=1).
            let late = task.await.unwrap().unwrap_or_else(|| panic!("{ms} ms sleeper woke early"));
            if std::env::var("INBETWEEN_SLOW").is_ok_and(|v| v == "1") {
                assert!(late < Duration::from_millis(20), "{ms} ms sleeper woke {late:?} late");
            }
        }
        // A due instant in the past resolves at once.
        sleep_until(start).await;
    }
}
