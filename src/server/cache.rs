//! A bounded cache of compiled clips, so a pose request never re-parses or
//! re-compiles a document and, on a hit, never touches the store.
//!
//! Keyed by clip id; each entry is an immutable `Arc<CachedClip>` at one
//! version, so a request that took an entry keeps a whole, consistent clip
//! even while a replace swaps in the next version (no torn poses).
//!
//! Consistency on one node (this process is the only writer):
//! - writes are *write-through*: after a committed create or replace the new
//!   version is put in, and an insert never replaces a newer version with an
//!   older one when two writes race;
//! - a delete removes the entry;
//! - a miss loads from the store and compiles outside the lock; it may insert
//!   its result only if no write happened meanwhile (a write counter, the
//!   `epoch`, is compared under the lock), so a slow miss can never resurrect
//!   a deleted clip or reinstate an old version.
//!
//! Several nodes (`server::notify`): another node's writes arrive as
//! invalidations ([`ClipCache::invalidate`], from PostgreSQL `LISTEN/NOTIFY`);
//! they bump the epoch exactly like local writes do. While a node cannot hear
//! them (before its first subscription, after a lost connection) the cache
//! is *suspended*: emptied, and nothing goes in, so every request reads the
//! store; [`ClipCache::resume`] empties it again once the node listens.
//!
//! Eviction is least-recently-used by a scan at insert time: inserts happen
//! only on writes and misses, capacities are small (default 1024), and the
//! hit path stays one lock, one hash lookup and one counter store.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::Mutex;

use crate::anim::Clip;
use crate::store::ClipMeta;

/// A compiled clip at one version, with its row (for summaries).
#[derive(Debug)]
pub struct CachedClip {
    pub meta: ClipMeta,
    pub clip: Clip,
}

/// Streams hold the cache entry they started on (no copy of the clip).
impl crate::stream::ClipSource for CachedClip {
    fn clip(&self) -> &Clip {
        &self.clip
    }
}

#[derive(Debug)]
struct Entry {
    clip: Arc<CachedClip>,
    last_used: u64,
}

#[derive(Debug, Default)]
struct Inner {
    entries: HashMap<String, Entry>,
    /// Bumped by every write and invalidation.
    epoch: u64,
    /// Logical clock for recency.
    tick: u64,
    /// True while invalidations may be missed: nothing is cached.
    suspended: bool,
}

/// The clip cache; see the module docs for its consistency rules.
#[derive(Debug)]
pub struct ClipCache {
    capacity: usize,
    inner: Mutex<Inner>,
}

/// A token taken before a miss reads the store; see [`ClipCache::insert_loaded`].
#[derive(Debug, Clone, Copy)]
pub struct Epoch(u64);

impl ClipCache {
    /// # Panics
    /// If `capacity` is 0.
    pub fn new(capacity: usize) -> Self {
        assert!(capacity > 0, "a cache needs room for one clip");
        ClipCache { capacity, inner: Mutex::new(Inner::default()) }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        crate::sync::lock(&self.inner)
    }

    pub fn get(&self, id: &str) -> Option<Arc<CachedClip>> {
        let mut inner = self.lock();
        inner.tick += 1;
        let tick = inner.tick;
        let entry = inner.entries.get_mut(id)?;
        entry.last_used = tick;
        Some(entry.clip.clone())
    }

    /// The current epoch, to pass to [`ClipCache::insert_loaded`].
    pub fn epoch(&self) -> Epoch {
        Epoch(self.lock().epoch)
    }

    /// Write-through after a committed create or replace: keeps whichever of
    /// the cached and the new version is newer.
    pub fn insert_written(&self, clip: Arc<CachedClip>) {
        let mut inner = self.lock();
        inner.epoch += 1;
        if inner.suspended {
            return;
        }
        Self::put(&mut inner, self.capacity, clip);
    }

    /// Inserts what a miss loaded, unless a write happened since `seen` was
    /// taken (the loaded version may then be stale). Returns whether it went in.
    pub fn insert_loaded(&self, clip: Arc<CachedClip>, seen: Epoch) -> bool {
        let mut inner = self.lock();
        if inner.epoch != seen.0 || inner.suspended {
            return false;
        }
        Self::put(&mut inner, self.capacity, clip);
        true
    }

    /// After a committed delete, or when another node changed `id`.
    pub fn invalidate(&self, id: &str) {
        let mut inner = self.lock();
        inner.epoch += 1;
        inner.entries.remove(id);
    }

    /// Stops caching and drops every entry: invalidations may be missed
    /// from now on (the node lost, or does not yet have, its subscription).
    pub fn suspend(&self) {
        let mut inner = self.lock();
        inner.epoch += 1;
        inner.suspended = true;
        inner.entries.clear();
    }

    /// Caches again, from empty: called once invalidations are heard again,
    /// so nothing loaded before that moment is kept.
    pub fn resume(&self) {
        let mut inner = self.lock();
        inner.epoch += 1;
        inner.suspended = false;
        inner.entries.clear();
    }

    /// The cached version of `id`, without touching its recency.
    pub fn version_of(&self, id: &str) -> Option<u64> {
        self.lock().entries.get(id).map(|e| e.clip.meta.version)
    }

    pub fn len(&self) -> usize {
        self.lock().entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn put(inner: &mut Inner, capacity: usize, clip: Arc<CachedClip>) {
        inner.tick += 1;
        let tick = inner.tick;
        if let Some(e) = inner.entries.get_mut(&clip.meta.id) {
            if e.clip.meta.version <= clip.meta.version {
                e.clip = clip;
            }
            e.last_used = tick;
            return;
        }
        if inner.entries.len() >= capacity {
            let oldest = inner.entries.iter().min_by_key(|(_, e)| e.last_used).map(|(id, _)| id.clone());
            if let Some(id) = oldest {
                inner.entries.remove(&id);
            }
        }
        inner.entries.insert(clip.meta.id.clone(), Entry { clip, last_used: tick });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::anim::{Channel, ClipSpec, Interpolation, Keys, Playback, TrackSpec};
    use crate::store::ClipStats;

    fn cached(id: &str, version: u64) -> Arc<CachedClip> {
        let spec = ClipSpec {
            name: "c".into(),
            skeleton: None,
            tracks: vec![TrackSpec::new(
                "j",
                Channel::Translation,
                Interpolation::Linear,
                vec![0.0],
                Keys::Vec3(vec![glam::Vec3::ZERO]),
            )],
            events: vec![],
            playback: Playback::Once,
        };
        let stats = ClipStats { joints: 1, tracks: 1, events: 0, start: 0.0, end: 0.0, playback: Playback::Once };
        let meta = ClipMeta { id: id.into(), name: "c".into(), version, stats, created_at: 0, updated_at: 0 };
        Arc::new(CachedClip { meta, clip: Clip::build(&spec).unwrap() })
    }

    #[test]
    fn an_older_version_never_replaces_a_newer_one() {
        let cache = ClipCache::new(4);
        cache.insert_written(cached("a", 3));
        cache.insert_written(cached("a", 2));
        assert_eq!(cache.get("a").unwrap().meta.version, 3);
        cache.insert_written(cached("a", 4));
        assert_eq!(cache.get("a").unwrap().meta.version, 4);
    }

    #[test]
    fn a_miss_that_raced_a_write_is_not_cached() {
        let cache = ClipCache::new(4);
        cache.insert_written(cached("a", 1));
        let seen = cache.epoch();
        cache.invalidate("a"); // a delete committed while the miss was loading
        assert!(!cache.insert_loaded(cached("a", 1), seen));
        assert!(cache.get("a").is_none());
        let seen = cache.epoch();
        assert!(cache.insert_loaded(cached("a", 1), seen));
    }

    #[test]
    fn a_suspended_cache_holds_nothing_until_resumed() {
        let cache = ClipCache::new(4);
        cache.insert_written(cached("a", 1));
        let seen = cache.epoch();
        cache.suspend();
        assert!(cache.get("a").is_none());
        cache.insert_written(cached("b", 1));
        assert!(!cache.insert_loaded(cached("c", 1), cache.epoch()));
        assert!(cache.is_empty());
        cache.resume();
        assert!(!cache.insert_loaded(cached("a", 1), seen), "a load from before the resume is stale");
        assert!(cache.insert_loaded(cached("a", 2), cache.epoch()));
        assert_eq!(cache.version_of("a"), Some(2));
    }

    #[test]
    fn the_least_recently_used_entry_is_evicted() {
        let cache = ClipCache::new(2);
        cache.insert_written(cached("a", 1));
        cache.insert_written(cached("b", 1));
        cache.get("a");
        cache.insert_written(cached("c", 1));
        assert_eq!(cache.len(), 2);
        assert!(cache.get("a").is_some() && cache.get("c").is_some() && cache.get("b").is_none());
    }
}
