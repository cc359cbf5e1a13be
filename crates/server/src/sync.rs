//! The crate's one policy for poisoned mutexes: take the guard anyway.
//!
//! A `std::sync::Mutex` is poisoned when a thread panics while holding it.
//! Every mutex here guards a cache, a registry, a set of counters or
//! histograms whose invariants hold between statements: each critical
//! section is a few map or counter updates, none of which leaves the data
//! half-changed if the next one panics. So a poisoned guard holds
//! consistent data, and refusing it would turn one caught panic into a
//! panic on every later request, tick or dropped permit (a panic in `Drop`
//! during unwinding aborts the process). Every lock in the crate is taken
//! through [`lock`]. The panic that poisoned a mutex is not counted again
//! here: it is counted (`inbetween_panics_total`) where it was caught.

use std::sync::{Mutex, MutexGuard, PoisonError};

/// Locks `mutex`, recovering the guard if a panicking holder poisoned it.
pub(crate) fn lock<T: ?Sized>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}
