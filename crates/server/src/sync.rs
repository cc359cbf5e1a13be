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
//!
//! [`Turns`] is the one way async writers of one key take turns on a node.

use std::hash::{Hash, Hasher};
use std::sync::{Mutex, MutexGuard, PoisonError};

/// Locks `mutex`, recovering the guard if a panicking holder poisoned it.
pub(crate) fn lock<T: ?Sized>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Stripes of [`Turns`].
const TURN_STRIPES: usize = 64;

/// Async writers of one key taking turns on this node: a fixed set of
/// mutexes, a key's turn being the stripe its hash falls in (two keys may
/// share one, which only makes them wait for each other).
#[derive(Debug)]
pub struct Turns([tokio::sync::Mutex<()>; TURN_STRIPES]);

impl Default for Turns {
    fn default() -> Self {
        Turns(std::array::from_fn(|_| tokio::sync::Mutex::new(())))
    }
}

impl Turns {
    /// Waits for `key`'s turn, which lasts as long as the guard.
    pub async fn take(&self, key: &str) -> tokio::sync::MutexGuard<'_, ()> {
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        key.hash(&mut hasher);
        self.0[(hasher.finish() % TURN_STRIPES as u64) as usize].lock().await
    }
}
