//! A bounded cache of compiled clips, so a pose request never re-parses or
//! re-compiles a document and, on a hit, never touches the store. The same
//! [`Cache`] keeps the built graphs and the checked characters
//! (`server::graphs`, `server::characters`): anything [`Cacheable`], one
//! version per id, under the rules below.
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
//! The cache is bounded twice: by entries (`cache_entries`) and by the heap
//! bytes of the compiled clips ([`CachedClip::bytes`]), which it draws from
//! the byte budget every cache shares (`server::cache_budget`,
//! `cache_bytes`), since one clip's tables can weigh anything from a
//! kilobyte to tens of megabytes. A clip larger than the whole budget is not
//! cached at all. Eviction is least-recently-used by a scan: at insert time
//! for the entry bound, and when the shared budget is trimmed; inserts happen
//! only on writes and misses, entry capacities are small (default 1024), and
//! the hit path stays one lock, one hash lookup and one counter store.
//!
//! Built motions (`server::motion_cache`) hold the entries of their layers.
//! So that they never keep alive what this cache let go, every id whose
//! entry leaves (replaced by a newer version, deleted, invalidated, evicted)
//! is noted; the caller takes the notes after each insert or invalidation
//! ([`ClipCache::take_departed`]) and drops the motions over those ids.

use anim::spring::SpringsSpec;
use std::sync::Arc;
use std::sync::Mutex;

use crate::cache_budget::{Budgeted, CacheBudget, Entries};
use crate::store::ClipMeta;
use anim::Clip;

/// A compiled clip at one version, with its row (for summaries).
#[derive(Debug)]
pub struct CachedClip {
    pub meta: ClipMeta,
    pub clip: Clip,
    /// The clip's spring chains (docs/springs.md), checked against its
    /// skeleton when it was admitted; played where the clip is the first
    /// layer of a motion without chains of its own.
    pub springs: SpringsSpec,
}

impl CachedClip {
    /// The bytes this entry keeps alive: itself, its row's strings and the
    /// compiled clip's heap.
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<Self>() + self.meta.id.capacity() + self.meta.name.capacity() + self.clip.heap_bytes()
    }
}

/// Motions (requests and streams alike; a clip stream is a one-layer
/// motion) hold their layers' cache entries, pinned at the version they
/// were built on: no copy of the clip.
impl crate::stream::PinnedClip for CachedClip {
    fn id(&self) -> &str {
        &self.meta.id
    }

    fn version(&self) -> u64 {
        self.meta.version
    }

    fn clip(&self) -> &Clip {
        &self.clip
    }

    fn springs(&self) -> &SpringsSpec {
        &self.springs
    }
}

/// What a [`Cache`] keeps: one version of one id, immutable, weighed in bytes.
pub trait Cacheable: Send + Sync + 'static {
    fn cache_id(&self) -> &str;
    fn cache_version(&self) -> u64;
    /// The heap bytes the entry keeps alive (counted on the shared budget).
    fn cache_bytes(&self) -> usize;
}

impl Cacheable for CachedClip {
    fn cache_id(&self) -> &str {
        &self.meta.id
    }

    fn cache_version(&self) -> u64 {
        self.meta.version
    }

    fn cache_bytes(&self) -> usize {
        self.bytes()
    }
}

#[derive(Debug)]
struct Inner<T> {
    entries: Entries<String, Arc<T>>,
    /// Bumped by every write and invalidation.
    epoch: u64,
    /// True while invalidations may be missed: nothing is cached.
    suspended: bool,
    /// Ids whose entry left since [`ClipCache::take_departed`] last ran.
    departed: Vec<String>,
}

/// A cache of immutable entries by id, one version each; see the module
/// docs for its consistency rules. Clips, and the built graphs and
/// characters of `server::documents`, are each kept in one.
#[derive(Debug)]
pub struct Cache<T> {
    inner: Mutex<Inner<T>>,
}

/// The cache of compiled clips.
pub type ClipCache = Cache<CachedClip>;

/// A token taken before a miss reads the store; see [`ClipCache::insert_loaded`].
#[derive(Debug, Clone, Copy)]
pub struct Epoch(u64);

impl<T: Cacheable> Cache<T> {
    /// A cache of at most `capacity` clips, whose bytes count on `budget`.
    ///
    /// # Panics
    /// If `capacity` is 0.
    pub fn new(capacity: usize, budget: Arc<CacheBudget>) -> Self {
        assert!(capacity > 0, "a cache needs room for one clip");
        let entries = Entries::new(capacity, budget);
        Cache { inner: Mutex::new(Inner { entries, epoch: 0, suspended: false, departed: Vec::new() }) }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner<T>> {
        crate::sync::lock(&self.inner)
    }

    pub fn get(&self, id: &str) -> Option<Arc<T>> {
        self.lock().entries.get(id).cloned()
    }

    /// The current epoch, to pass to [`ClipCache::insert_loaded`].
    pub fn epoch(&self) -> Epoch {
        Epoch(self.lock().epoch)
    }

    /// Write-through after a committed create or replace: keeps whichever of
    /// the cached and the new version is newer.
    pub fn insert_written(&self, clip: Arc<T>) {
        self.insert_written_if(clip, |_| true);
    }

    /// [`Cache::insert_written`] if `keep` holds for the entry, asked under
    /// this cache's lock (a built graph goes in only while its clips are
    /// still the clip cache's entries).
    pub fn insert_written_if(&self, entry: Arc<T>, keep: impl FnOnce(&T) -> bool) {
        let mut inner = self.lock();
        inner.epoch += 1;
        if inner.suspended || !keep(&entry) {
            return;
        }
        self.put(&mut inner, entry);
    }

    /// Inserts what a miss loaded, unless a write happened since `seen` was
    /// taken (the loaded version may then be stale). Returns whether it went in.
    pub fn insert_loaded(&self, clip: Arc<T>, seen: Epoch) -> bool {
        self.insert_loaded_if(clip, seen, |_| true)
    }

    /// [`Cache::insert_loaded`] if `keep` holds for the entry, asked under
    /// this cache's lock.
    pub fn insert_loaded_if(&self, entry: Arc<T>, seen: Epoch, keep: impl FnOnce(&T) -> bool) -> bool {
        let mut inner = self.lock();
        if inner.epoch != seen.0 || inner.suspended || !keep(&entry) {
            return false;
        }
        self.put(&mut inner, entry);
        true
    }

    /// Drops every entry `leaves` says (a graph over a clip that left the
    /// clip cache), noting each as departed.
    pub fn invalidate_where(&self, leaves: impl FnMut(&Arc<T>) -> bool) {
        let mut inner = self.lock();
        inner.epoch += 1;
        let gone = inner.entries.remove_where(leaves);
        inner.departed.extend(gone.iter().map(|g| g.cache_id().to_owned()));
    }

    /// After a committed delete, or when another node changed `id`.
    pub fn invalidate(&self, id: &str) {
        let mut inner = self.lock();
        inner.epoch += 1;
        self.remove(&mut inner, id);
    }

    /// Stops caching and drops every entry: invalidations may be missed
    /// from now on (the node lost, or does not yet have, its subscription).
    pub fn suspend(&self) {
        let mut inner = self.lock();
        inner.epoch += 1;
        inner.suspended = true;
        self.clear(&mut inner);
    }

    /// Caches again, from empty: called once invalidations are heard again,
    /// so nothing loaded before that moment is kept.
    pub fn resume(&self) {
        let mut inner = self.lock();
        inner.epoch += 1;
        inner.suspended = false;
        self.clear(&mut inner);
    }

    /// Whether `clip` is the very entry cached for its id (not merely the
    /// same version of it), without touching its recency.
    pub fn holds(&self, clip: &Arc<T>) -> bool {
        self.lock().entries.peek(clip.cache_id()).is_some_and(|cached| Arc::ptr_eq(cached, clip))
    }

    /// The ids whose entry left the cache since the last call (each once;
    /// a suspension or resumption notes nothing: it empties the whole cache).
    pub fn take_departed(&self) -> Vec<String> {
        std::mem::take(&mut self.lock().departed)
    }

    /// The cached version of `id`, without touching its recency.
    pub fn version_of(&self, id: &str) -> Option<u64> {
        self.lock().entries.peek(id).map(|cached| cached.cache_version())
    }

    pub fn len(&self) -> usize {
        self.lock().entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Heap bytes of the cached entries (see [`Cacheable::cache_bytes`]).
    pub fn bytes(&self) -> usize {
        self.lock().entries.bytes()
    }

    /// Puts `clip` in, unless a newer version of it is cached; the least
    /// recently used others leave while the entry bound is reached (the
    /// shared byte budget is trimmed by the caller, `cache_budget::trim`).
    /// A clip over the whole budget is not cached, and takes its older
    /// version out.
    fn put(&self, inner: &mut Inner<T>, clip: Arc<T>) {
        let id = clip.cache_id().to_owned();
        if inner.entries.get(id.as_str()).is_some_and(|cached| cached.cache_version() >= clip.cache_version()) {
            return;
        }
        self.remove(inner, &id);
        let bytes = clip.cache_bytes();
        if let Ok(left) = inner.entries.insert(id, clip, bytes) {
            inner.departed.extend(left.into_iter().map(|gone| gone.cache_id().to_owned()));
        }
    }

    fn remove(&self, inner: &mut Inner<T>, id: &str) {
        if let Some(gone) = inner.entries.remove(id) {
            inner.departed.push(gone.cache_id().to_owned());
        }
    }

    fn clear(&self, inner: &mut Inner<T>) {
        inner.entries.clear();
        inner.departed.clear();
    }
}

impl<T: Cacheable> Budgeted for Cache<T> {
    fn oldest(&self) -> Option<u64> {
        self.lock().entries.oldest()
    }

    fn evict_oldest(&self) {
        let mut inner = self.lock();
        if let Some(gone) = inner.entries.evict_oldest() {
            inner.departed.push(gone.cache_id().to_owned());
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::store::ClipStats;
    use anim::{Channel, ClipSpec, Interpolation, Keys, Playback, TrackSpec};

    fn unbounded() -> Arc<CacheBudget> {
        Arc::new(CacheBudget::new(usize::MAX))
    }

    fn cached(id: &str, version: u64) -> Arc<CachedClip> {
        cached_keys(id, version, 1)
    }

    /// A clip of one linear track with `keys` keys (12 bytes of curve each).
    pub(crate) fn cached_keys(id: &str, version: u64, keys: usize) -> Arc<CachedClip> {
        let spec = ClipSpec {
            name: "c".into(),
            skeleton: None,
            tracks: vec![TrackSpec::new(
                "j",
                Channel::Translation,
                Interpolation::Linear,
                (0..keys).map(|k| k as f32).collect(),
                Keys::Vec3((0..keys).map(|k| glam::Vec3::splat(k as f32)).collect()),
            )],
            events: vec![],
            playback: Playback::Once,
            ..Default::default()
        };
        let stats = ClipStats { joints: 1, tracks: 1, events: 0, start: 0.0, end: 0.0, playback: Playback::Once };
        let meta =
            ClipMeta { id: id.into(), name: "c".into(), version, stats, tags: vec![], created_at: 0, updated_at: 0 };
        Arc::new(CachedClip { meta, clip: Clip::build(&spec).unwrap(), springs: SpringsSpec::default() })
    }

    #[test]
    fn an_older_version_never_replaces_a_newer_one() {
        let cache = ClipCache::new(4, unbounded());
        cache.insert_written(cached("a", 3));
        cache.insert_written(cached("a", 2));
        assert_eq!(cache.get("a").unwrap().meta.version, 3);
        cache.insert_written(cached("a", 4));
        assert_eq!(cache.get("a").unwrap().meta.version, 4);
    }

    #[test]
    fn a_conditional_insert_keeps_out_what_fails_its_check_and_a_sweep_notes_what_it_drops() {
        let cache = ClipCache::new(4, unbounded());
        cache.insert_written_if(cached("a", 1), |_| false);
        assert!(cache.get("a").is_none(), "refused by its check");
        let seen = cache.epoch();
        assert!(!cache.insert_loaded_if(cached("a", 1), seen, |c| c.meta.version > 1));
        assert!(cache.insert_loaded_if(cached("a", 1), seen, |c| c.meta.version == 1));
        cache.insert_written(cached("b", 2));
        cache.insert_written(cached("c", 5));
        cache.take_departed();
        cache.invalidate_where(|c| c.meta.version < 5);
        let mut gone = cache.take_departed();
        gone.sort();
        assert_eq!((gone, cache.len(), cache.version_of("c")), (vec!["a".to_owned(), "b".to_owned()], 1, Some(5)));
    }

    #[test]
    fn a_miss_that_raced_a_write_is_not_cached() {
        let cache = ClipCache::new(4, unbounded());
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
        let cache = ClipCache::new(4, unbounded());
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
    fn every_entry_that_leaves_is_noted_once_and_holds_knows_the_very_entry() {
        let cache = ClipCache::new(2, unbounded());
        let a1 = cached("a", 1);
        cache.insert_written(a1.clone());
        assert!(cache.holds(&a1) && !cache.holds(&cached("a", 1)), "the same version, another copy");
        cache.insert_written(cached("b", 1));
        assert!(cache.take_departed().is_empty(), "nothing left yet");
        cache.insert_written(cached("a", 2)); // replaces a@1
        cache.insert_written(cached("c", 1)); // evicts b, the least recently used
        cache.invalidate("c");
        cache.invalidate("zz"); // not cached: nothing leaves
        assert_eq!(cache.take_departed(), ["a", "b", "c"]);
        assert!(cache.take_departed().is_empty() && !cache.holds(&a1));
        cache.suspend();
        assert!(cache.take_departed().is_empty(), "a suspension empties everything, noting nothing");
    }

    #[test]
    fn the_least_recently_used_entry_is_evicted() {
        let cache = ClipCache::new(2, unbounded());
        cache.insert_written(cached("a", 1));
        cache.insert_written(cached("b", 1));
        cache.get("a");
        cache.insert_written(cached("c", 1));
        assert_eq!(cache.len(), 2);
        assert!(cache.get("a").is_some() && cache.get("c").is_some() && cache.get("b").is_none());
    }

    #[test]
    fn the_byte_bound_evicts_the_least_recently_used_and_skips_a_clip_over_it() {
        let (a, b, c) = (cached_keys("a", 1, 1000), cached_keys("b", 1, 1000), cached_keys("c", 1, 1000));
        let one = a.bytes();
        assert!(one > 1000 * 12, "the curve's keys are counted: {one}");
        let budget = Arc::new(CacheBudget::new(2 * one + one / 2));
        let cache = ClipCache::new(100, budget.clone());
        let put = |clip| {
            cache.insert_written(clip);
            crate::cache_budget::trim(&budget, &[&cache]);
        };
        put(a);
        put(b);
        assert_eq!((cache.len(), cache.bytes(), budget.used()), (2, 2 * one, 2 * one));
        cache.get("a");
        put(c);
        assert_eq!((cache.len(), cache.bytes()), (2, 2 * one), "b left to make room");
        assert!(cache.get("b").is_none() && cache.get("a").is_some() && cache.get("c").is_some());
        // Too big for the whole budget: not cached, and its old version goes.
        put(cached_keys("a", 2, 4000));
        assert!(cache.get("a").is_none());
        assert_eq!((cache.len(), cache.bytes(), budget.used()), (1, one, one));
        cache.invalidate("c");
        assert_eq!((cache.len(), cache.bytes(), budget.used()), (0, 0, 0));
    }
}
