//! One byte budget shared by every cache of the node (docs/operations.md,
//! “Memory”): compiled clips (`server::cache`) and built motions
//! (`server::motion_cache`) draw on the same `cache_bytes`, so no mix of
//! entries — a few huge motions, many small clips — can hold more than it.
//!
//! Each cache keeps its entries in an [`Entries`] and says only what an
//! entry weighs, from a size function that sums its allocations
//! ([`crate::cache::CachedClip::bytes`], `Motion::heap_bytes`); [`Entries`]
//! charges the budget on insert and refunds it on removal, bounds the
//! entries, and stamps each use with the budget's one clock. [`trim`] then
//! evicts the least recently used entry across all caches until the total
//! fits again. An entry larger than the whole budget is never kept: it is
//! built, used and dropped.
//!
//! Adding a cache is one more [`Budgeted`] in the list `AppState` trims.
//! Between an insert and its trim the total may pass the budget by the
//! entries being inserted at that moment (each at most the budget).

use std::borrow::Borrow;
use std::collections::HashMap;
use std::hash::Hash;
use std::sync::Arc;
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

/// One cache's entries on the shared budget. The cache says what an entry
/// weighs when it puts it in ([`Entries::insert`]); this keeps the rest —
/// the weights charged to the budget until each entry leaves (replaced,
/// removed, evicted, cleared), the entry bound (least recently used out
/// first), and each use stamped with the budget's clock — so every cache
/// counts the same way and [`trim`] can compare them.
#[derive(Debug)]
pub struct Entries<K, V> {
    map: HashMap<K, Entry<V>>,
    /// The sum of the entries' weights.
    bytes: usize,
    /// At most this many entries.
    capacity: usize,
    budget: Arc<CacheBudget>,
}

#[derive(Debug)]
struct Entry<V> {
    value: V,
    /// Its weight, charged to the budget while it is here.
    bytes: usize,
    last_used: u64,
}

impl<K: Eq + Hash + Clone, V> Entries<K, V> {
    /// At most `capacity` entries, weighed on `budget`.
    ///
    /// # Panics
    /// If `capacity` is 0.
    pub fn new(capacity: usize, budget: Arc<CacheBudget>) -> Self {
        assert!(capacity > 0, "a cache needs room for one entry");
        Entries { map: HashMap::new(), bytes: 0, capacity, budget }
    }

    /// The entry under `key`, stamped as just used.
    pub fn get<Q: Hash + Eq + ?Sized>(&mut self, key: &Q) -> Option<&V>
    where
        K: Borrow<Q>,
    {
        let entry = self.map.get_mut(key)?;
        entry.last_used = self.budget.tick();
        Some(&entry.value)
    }

    /// The entry under `key`, its recency untouched.
    pub fn peek<Q: Hash + Eq + ?Sized>(&self, key: &Q) -> Option<&V>
    where
        K: Borrow<Q>,
    {
        self.map.get(key).map(|e| &e.value)
    }

    /// Puts `value`, weighing `bytes`, under `key`: what was under it
    /// leaves, then the least recently used others while the entry bound
    /// is reached. Returns what left. A value over the whole budget is
    /// handed back and nothing changes.
    ///
    /// # Errors
    /// `value`, when it alone weighs more than the budget.
    pub fn insert(&mut self, key: K, value: V, bytes: usize) -> Result<Vec<V>, V> {
        if !self.budget.admits(bytes) {
            return Err(value);
        }
        let mut left: Vec<V> = self.remove(&key).into_iter().collect();
        while self.map.len() >= self.capacity {
            match self.evict_oldest() {
                Some(value) => left.push(value),
                None => break,
            }
        }
        self.budget.charge(bytes);
        self.bytes += bytes;
        self.map.insert(key, Entry { value, bytes, last_used: self.budget.tick() });
        Ok(left)
    }

    /// Takes the entry under `key` out, refunding its weight.
    pub fn remove<Q: Hash + Eq + ?Sized>(&mut self, key: &Q) -> Option<V>
    where
        K: Borrow<Q>,
    {
        let entry = self.map.remove(key)?;
        self.bytes -= entry.bytes;
        self.budget.refund(entry.bytes);
        Some(entry.value)
    }

    /// Takes out every entry `leaves` says should go; returns them.
    pub fn remove_where(&mut self, mut leaves: impl FnMut(&V) -> bool) -> Vec<V> {
        let keys: Vec<K> = self.map.iter().filter(|(_, e)| leaves(&e.value)).map(|(k, _)| k.clone()).collect();
        keys.iter().filter_map(|k| self.remove(k)).collect()
    }

    /// Takes out the least recently used entry.
    pub fn evict_oldest(&mut self) -> Option<V> {
        let oldest = self.map.iter().min_by_key(|(_, e)| e.last_used).map(|(k, _)| k.clone())?;
        self.remove(&oldest)
    }

    /// The stamp of the least recently used entry; `None` when empty.
    pub fn oldest(&self) -> Option<u64> {
        self.map.values().map(|e| e.last_used).min()
    }

    /// Takes every entry out.
    pub fn clear(&mut self) {
        self.map.clear();
        self.budget.refund(self.bytes);
        self.bytes = 0;
    }

    pub fn len(&self) -> usize {
        self.map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }

    /// The sum of the entries' weights.
    pub fn bytes(&self) -> usize {
        self.bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_charge_their_weights_and_give_them_back_however_they_leave() {
        let budget = Arc::new(CacheBudget::new(1000));
        let mut entries: Entries<&str, u32> = Entries::new(3, budget.clone());
        for (key, weight) in [("a", 100), ("b", 200), ("c", 300)] {
            assert!(entries.insert(key, weight as u32, weight).unwrap().is_empty());
        }
        assert_eq!((budget.used(), entries.bytes()), (600, 600));
        entries.get("a");
        // The bound of 3: b, the least recently used, leaves for d.
        assert_eq!(entries.insert("d", 50, 50).unwrap(), vec![200]);
        assert_eq!((budget.used(), entries.len()), (450, 3));
        // Replacing an entry refunds the old weight.
        assert_eq!(entries.insert("a", 7, 10).unwrap(), vec![100]);
        assert_eq!(budget.used(), 360);
        assert_eq!(entries.insert("huge", 0, 1001).unwrap_err(), 0, "over the whole budget: not kept");
        assert_eq!(budget.used(), 360);
        // c (300) was used longest ago.
        assert_eq!(entries.evict_oldest(), Some(300));
        assert_eq!(entries.remove_where(|v| *v == 50), vec![50]);
        assert_eq!((entries.remove("a"), budget.used()), (Some(7), 0));
        entries.insert("e", 1, 10).unwrap();
        entries.clear();
        assert_eq!((budget.used(), entries.bytes(), entries.oldest()), (0, 0, None));
    }
}
