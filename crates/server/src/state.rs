//! [`AppState`]: what every handler shares, the clip-loading path that puts
//! the cache in front of the store, and the upkeep that keeps the motion
//! cache over exactly what the clip cache holds.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use futures_util::FutureExt;
use futures_util::future::{self, BoxFuture};
use metrics_exporter_prometheus::PrometheusHandle;

use crate::store::ClipStore;

use super::auth::Auth;
use super::built::BuiltCharacter;
use super::built::BuiltGraph;
use super::cache::{Cache, CachedClip, ClipCache, Epoch};
use super::cache_budget::{CacheBudget, trim};
use super::config::Config;
use super::error::ApiError;
use super::motion_cache::{MotionCache, MotionKey};
use crate::store::DocKind;
use crate::stream::StreamMotion;

/// What every handler shares. One `Arc` around everything: extractors clone
/// the state per request, and one reference count is cheaper than ten
/// (each is an atomic that both cores bounce between them).
#[derive(Clone)]
pub struct AppState(Arc<Shared>);

impl AppState {
    pub fn new(shared: Shared) -> Self {
        AppState(Arc::new(shared))
    }
}

impl std::ops::Deref for AppState {
    type Target = Shared;
    fn deref(&self) -> &Shared {
        &self.0
    }
}

/// The fields of [`AppState`].
pub struct Shared {
    pub store: Arc<dyn ClipStore>,
    pub cache: Arc<ClipCache>,
    /// Built motions over the clip cache's entries (`server::motion_cache`).
    pub motions: MotionCache,
    /// Built graphs by id at one version, over the clip cache's entries (`server::graphs`).
    pub graphs: Cache<BuiltGraph>,
    /// Checked characters by id at one version (`server::characters`).
    pub characters: Cache<BuiltCharacter>,
    /// The byte budget every cache draws on (`server::cache_budget`).
    pub cache_budget: Arc<CacheBudget>,
    pub config: Arc<Config>,
    /// Identifies callers from the configured tokens (REST and gRPC).
    pub auth: Auth,
    pub metrics: PrometheusHandle,
    pub counters: super::metrics::Counters,
    /// False once shutdown has begun (readiness answers 503).
    pub ready: Arc<AtomicBool>,
    /// Clip loads in flight, shared by concurrent misses.
    pub loads: Loads,
    /// The streaming engine behind WebSocket and gRPC streams.
    pub streams: crate::stream::Engine,
    /// The per-caller write rate limit, shared by REST and gRPC.
    pub writes: Arc<super::ratelimit::WriteLimiter>,
    /// Requests in flight per caller, shared by REST and gRPC (`shed`).
    pub in_flight: Arc<super::shed::Clients>,
    /// Request bodies and first gRPC messages held at once, in bytes (`shed::Arrivals`).
    pub arrivals: super::shed::Arrivals,
    /// Patches of one clip take turns on this node (`rest::patch`).
    pub patches: crate::sync::Turns,
    /// Where poses are evaluated and clips and motions built, and what the
    /// node and each caller may spend on them (`server::work`).
    pub work: Arc<crate::work::Work>,
    /// The answers compressed at once, REST's and gRPC's (`server::compression`).
    pub compressors: crate::compression::Gate,
}

impl AppState {
    pub fn is_ready(&self) -> bool {
        self.ready.load(Ordering::Acquire)
    }

    /// The compiled clip `id`: from the cache, or loaded and compiled once.
    /// Concurrent misses on one id share one load (no thundering herd on a
    /// cold clip).
    ///
    /// # Errors
    /// `clip_not_found`, or a store failure.
    pub async fn clip(&self, id: &str) -> Result<Arc<CachedClip>, ApiError> {
        if let Some(hit) = self.cache.get(id) {
            self.counters.cache_hits.increment(1);
            return Ok(hit);
        }
        let load = {
            let mut loads = crate::sync::lock(&self.loads);
            loads.entry(id.to_owned()).or_insert_with(|| self.load(id.to_owned())).clone()
        };
        let result = load.clone().await;
        {
            let mut loads = crate::sync::lock(&self.loads);
            if loads.get(id).is_some_and(|l| l.ptr_eq(&load)) {
                loads.remove(id);
            }
        }
        result.map_err(|failure| match failure {
            LoadFailure::NotFound => ApiError::NotFound { what: "clip" },
            LoadFailure::Unavailable => ApiError::Unavailable(None),
            LoadFailure::OverBudget => over_budget_stored(id, self.config.limits.max_build_work),
            LoadFailure::Busy => ApiError::WorkOverloaded { retry_after: 1 },
            LoadFailure::TimedOut { secs } => ApiError::Timeout { secs },
            LoadFailure::Internal => ApiError::Internal(anyhow::anyhow!("loading clip {id} failed (logged above)")),
        })
    }

    /// One shared load: store read, compile, cache insert unless a write raced it.
    fn load(&self, id: String) -> Load {
        let state = self.clone();
        async move {
            state.counters.cache_misses.increment(1);
            let seen = state.cache.epoch();
            let result = async {
                let stored = state.store.get(&id).await?.ok_or(ApiError::NotFound { what: "clip" })?;
                let max_work = state.config.limits.max_build_work;
                let cached = super::builds::stored(&state.work, max_work, stored).await?;
                Ok::<_, ApiError>(Arc::new(cached))
            }
            .await;
            match result {
                Ok(cached) => {
                    state.cache.insert_loaded(cached.clone(), seen);
                    state.trim_caches();
                    Ok(cached)
                }
                Err(ApiError::TooMany { code, detail, .. }) => {
                    // Stored under a larger budget than the one configured now.
                    tracing::warn!(%id, code, detail, "clip load: over the build budget");
                    Err(LoadFailure::OverBudget)
                }
                Err(ApiError::NotFound { .. }) => Err(LoadFailure::NotFound),
                Err(ApiError::WorkOverloaded { .. } | ApiError::CallerWorkLimit { .. }) => Err(LoadFailure::Busy),
                Err(ApiError::Timeout { secs }) => Err(LoadFailure::TimedOut { secs }),
                Err(e @ ApiError::Unavailable(_)) => {
                    tracing::warn!(%id, error = %e, "clip load: store unavailable");
                    Err(LoadFailure::Unavailable)
                }
                Err(e) => {
                    tracing::error!(%id, error = ?e, "clip load failed");
                    Err(LoadFailure::Internal)
                }
            }
        }
        .boxed()
        .shared()
    }

    /// Write-through after a committed create or replace. In-flight loads of
    /// the id are forgotten so later requests cannot join a stale one.
    pub fn cache_written(&self, cached: Arc<CachedClip>) {
        self.forget_load(&cached.meta.id);
        self.cache.insert_written(cached);
        self.trim_caches();
    }

    /// After a committed delete (or another node's change): the clip and
    /// every built motion with a layer of it.
    pub fn cache_invalidate(&self, id: &str) {
        self.forget_load(id);
        self.cache.invalidate(id);
        self.motions.invalidate(&[id]);
        self.forget_departed_motions();
        self.cache_gauges();
    }

    /// Stops caching clips, motions, graphs and characters: changes may go
    /// unheard from now on.
    pub fn cache_suspend(&self) {
        self.cache.suspend();
        self.motions.clear();
        self.graphs.suspend();
        self.characters.suspend();
        self.cache_gauges();
    }

    /// Caches again, from empty, once changes are heard again.
    pub fn cache_resume(&self) {
        self.cache.resume();
        self.motions.clear();
        self.graphs.resume();
        self.characters.resume();
        self.cache_gauges();
    }

    /// After a committed write or delete of document `id` of `kind` on this
    /// node: its built form leaves (the next use builds the new version).
    pub fn document_changed(&self, kind: DocKind, id: &str) {
        match kind {
            DocKind::Graph => self.graphs.invalidate(id),
            DocKind::Character => self.characters.invalidate(id),
        }
        self.forget_departed_motions();
        self.cache_gauges();
    }

    /// Another node changed `id` (to `version`; `None`: deleted): if it is
    /// a built graph or character older than that, it leaves. Idempotent,
    /// as the clip cache's handling (`server::notify`).
    pub fn document_heard(&self, id: &str, version: Option<u64>) {
        let stale = |cached: Option<u64>| cached.is_some() && version.is_none_or(|v| cached.is_some_and(|c| c < v));
        if stale(self.graphs.version_of(id)) {
            self.graphs.invalidate(id);
        }
        if stale(self.characters.version_of(id)) {
            self.characters.invalidate(id);
        }
        self.forget_departed_motions();
        self.cache_gauges();
    }

    /// Caches a graph just built (after a write, or by a use that missed),
    /// unless one of its clips is no longer the clip cache's entry, or (a
    /// miss) a change of graphs was heard since `seen` was taken.
    pub fn cache_graph(&self, built: Arc<BuiltGraph>, seen: Option<Epoch>) {
        let held = |g: &BuiltGraph| g.clips.iter().all(|c| self.cache.holds(c));
        match seen {
            Some(seen) => drop(self.graphs.insert_loaded_if(built, seen, held)),
            None => self.graphs.insert_written_if(built, held),
        }
        self.trim_caches();
    }

    /// The built motion cached under `key`, counted as a hit or a miss.
    pub fn cached_motion(&self, key: &MotionKey) -> Option<Arc<StreamMotion>> {
        let hit = self.motions.get(key);
        let counter = if hit.is_some() { &self.counters.motion_cache_hits } else { &self.counters.motion_cache_misses };
        counter.increment(1);
        hit
    }

    /// Caches a motion just built over `clips`, unless one of them is no
    /// longer the clip cache's entry (replaced, deleted, evicted, or never
    /// cached): the motion would keep a clip alive that the cache let go.
    pub fn cache_motion(&self, key: MotionKey, motion: Arc<StreamMotion>, clips: &[Arc<CachedClip>]) {
        if self.motions.insert_if(key, motion, || clips.iter().all(|c| self.cache.holds(c))) {
            self.trim_caches();
        }
    }

    /// Evicts the least recently used entries of every cache until they fit
    /// `cache_bytes` together, then drops the motions over clips that left.
    fn trim_caches(&self) {
        trim(&self.cache_budget, &[&*self.cache, &self.motions, &self.graphs, &self.characters]);
        self.forget_departed_motions();
        self.cache_gauges();
    }

    /// The caches' sizes on `/metrics` (entries of each; bytes of all).
    pub fn cache_gauges(&self) {
        self.counters.cache_gauges(self.cache.len(), self.cache_budget.used());
        self.counters.motion_cache_gauge(self.motions.len());
        self.counters.document_cache_gauges(self.graphs.len(), self.characters.len());
    }

    /// Drops the graphs over clips that left the clip cache, then the
    /// motions over clips or graphs that left (a motion names what it was
    /// built on by id). Characters are held by the motions built on them
    /// (keyed by their version), so their departures need nothing more.
    fn forget_departed_motions(&self) {
        let mut departed = self.cache.take_departed();
        if !departed.is_empty() {
            self.graphs.invalidate_where(|g| departed.iter().any(|id| g.uses_clip(id)));
        }
        departed.extend(self.graphs.take_departed());
        self.motions.invalidate(&departed);
        drop(self.characters.take_departed());
    }

    fn forget_load(&self, id: &str) {
        crate::sync::lock(&self.loads).remove(id);
    }
}

/// Why a shared load failed (clonable, for every waiter; the cause is logged once).
#[derive(Debug, Clone, Copy)]
pub enum LoadFailure {
    NotFound,
    Unavailable,
    /// A stored clip costs more to build than `max_build_work` now allows.
    OverBudget,
    /// The node's work capacity was taken: its build was not started.
    Busy,
    /// Its build outlived `request_timeout_secs`.
    TimedOut {
        secs: u64,
    },
    Internal,
}

/// A load of one clip, awaited by every request that missed on it.
pub type Load = future::Shared<BoxFuture<'static, Result<Arc<CachedClip>, LoadFailure>>>;

/// In-flight loads by clip id.
pub type Loads = Arc<Mutex<HashMap<String, Load>>>;

/// A stored clip whose build is over the configured budget: refused like
/// an upload would be, so the caller learns which limit (never a 500).
fn over_budget_stored(id: &str, max_work: u64) -> ApiError {
    let detail = format!(
        "clip {id} was stored under a larger build budget than the current max_build_work ({max_work}); \
         raise it with --max-build-work to sample it"
    );
    ApiError::TooMany { code: "build_budget_exceeded", pointer: String::new(), detail }
}
