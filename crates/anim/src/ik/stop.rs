//! Stopping long solves early. A chain solve may iterate for a long time
//! (its budget is up to `max_iterations` steps over every joint of the
//! chain); a service that has given up on the answer — its client left, or
//! its time ran out — raises a flag, and every chain solve on that thread
//! stops at its next iteration, reporting where it got to (not converged).
//!
//! The flag is scoped to the thread for the duration of a closure rather
//! than passed down through every sampling call: sampling keeps its
//! signatures, and a thread that never set a flag pays one thread-local read
//! per iteration. Nothing here does I/O; a solve that is not stopped gives
//! the same answer as ever.

use std::cell::RefCell;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

thread_local! {
    static STOP: RefCell<Option<Arc<AtomicBool>>> = const { RefCell::new(None) };
}

/// Runs `f` with `flag` as this thread's stop flag: chain solves inside it
/// end at their next iteration once `flag` is raised. The previous flag (if
/// any) is restored afterwards, even if `f` panics.
pub fn stoppable<R>(flag: &Arc<AtomicBool>, f: impl FnOnce() -> R) -> R {
    struct Restore(Option<Arc<AtomicBool>>);
    impl Drop for Restore {
        fn drop(&mut self) {
            STOP.set(self.0.take());
        }
    }
    let _restore = Restore(STOP.replace(Some(Arc::clone(flag))));
    f()
}

/// Whether this thread's stop flag is raised.
pub(crate) fn stopped() -> bool {
    STOP.with_borrow(|flag| flag.as_ref().is_some_and(|f| f.load(Ordering::Relaxed)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flag_is_seen_inside_and_restored_after() {
        let flag = Arc::new(AtomicBool::new(false));
        assert!(!stopped());
        stoppable(&flag, || {
            assert!(!stopped());
            flag.store(true, Ordering::Relaxed);
            assert!(stopped());
        });
        assert!(!stopped(), "outside the closure no flag applies");
    }
}
