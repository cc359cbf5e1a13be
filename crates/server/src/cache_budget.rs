//! One byte budget shared by every cache of the node (docs/operations.md,
//! “Memory”): compiled clips (`server::cache`) and built motions
//! (`server::motion_cache`) draw on the same `cache_bytes`, so no mix of
//! entries — a few huge motions, many small clips — can hold more than it.
//!
//! Each cache counts its entries with a size function that sums their
//! allocations ([`crate::cache::CachedClip::bytes`], `Motion::heap_bytes`),
//! charges the budget on insert and refunds it on removal, and stamps each
//! use with the budget's one clock. [`trim`] then evicts the least recently
//! used entry across all caches until the total fits again. An entry larger
//! than the whole budget is never kept: it is built, used and dropped.
//!
//! Adding a cache is one more [`Budgeted`] in the list `AppState` trims.
//! Between an insert and its trim the total may pass the budget by the
//! entries being inserted at that moment (each at most the budget).

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

/// The shared budget: its bound, what the caches hold now, and the clock
/// their recency stamps come from.
#[derive(Debug)]
pub struct CacheBudget {
    capacity: usize,
    used: AtomicUsize,
    clock: AtomicU64,
}

impl CacheBudget {
    /// A budget of `capacity` bytes.
    pub fn new(capacity: usize) -> Self {
        CacheBudget { capacity, used: AtomicUsize::new(0), clock: AtomicU64::new(0) }
    }

    /// The next recency stamp (later uses get larger stamps, in every cache).
    pub fn tick(&self) -> u64 {
        self.clock.fetch_add(1, Ordering::Relaxed) + 1
    }

    /// Whether an entry of `bytes` may be kept at all.
    pub fn admits(&self, bytes: usize) -> bool {
        bytes <= self.capacity
    }

    pub fn charge(&self, bytes: usize) {
        self.used.fetch_add(bytes, Ordering::Relaxed);
    }

    pub fn refund(&self, bytes: usize) {
        self.used.fetch_sub(bytes, Ordering::Relaxed);
    }

    /// Bytes the caches hold together.
    pub fn used(&self) -> usize {
        self.used.load(Ordering::Relaxed)
    }

    /// The bound (`cache_bytes`).
    pub fn capacity(&self) -> usize {
        self.capacity
    }
}

/// A cache drawing on a [`CacheBudget`].
pub trait Budgeted: Send + Sync {
    /// The stamp of its least recently used entry; `None` when empty.
    fn oldest(&self) -> Option<u64>;
    /// Evicts its least recently used entry (charging back its bytes).
    fn evict_oldest(&self);
}

/// Evicts the least recently used entry of all `caches` until their total
/// fits `budget` (or nothing is left to evict).
pub fn trim(budget: &CacheBudget, caches: &[&dyn Budgeted]) {
    while budget.used() > budget.capacity {
        let oldest = caches.iter().filter_map(|c| c.oldest().map(|stamp| (stamp, c))).min_by_key(|(stamp, _)| *stamp);
        match oldest {
            Some((_, cache)) => cache.evict_oldest(),
            None => break,
        }
    }
}
