//! [`AppState`]: what every handler shares, and the clip-loading path that
//! puts the cache in front of the store.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use metrics_exporter_prometheus::PrometheusHandle;

use crate::anim::Clip;
use crate::store::{ClipStore, StoredClip};
use crate::wire::json::{DocError, parse_clip};

use super::cache::{CachedClip, ClipCache};
use super::config::Config;
use super::error::ApiError;

/// Documents larger than this are parsed and compiled on the blocking pool,
/// so one big upload cannot stall the async workers.
pub const BLOCKING_THRESHOLD_BYTES: usize = 64 * 1024;

#[derive(Clone)]
pub struct AppState {
    pub store: Arc<dyn ClipStore>,
    pub cache: Arc<ClipCache>,
    pub config: Arc<Config>,
    pub metrics: PrometheusHandle,
    /// False once shutdown has begun (readiness answers 503).
    pub ready: Arc<AtomicBool>,
}

impl AppState {
    pub fn is_ready(&self) -> bool {
        self.ready.load(Ordering::Acquire)
    }

    /// The compiled clip `id`: from the cache, or loaded and compiled once.
    ///
    /// # Errors
    /// `clip_not_found`, or a store failure.
    pub async fn clip(&self, id: &str) -> Result<Arc<CachedClip>, ApiError> {
        if let Some(hit) = self.cache.get(id) {
            metrics::counter!("inbetween_clip_cache_hits_total").increment(1);
            return Ok(hit);
        }
        metrics::counter!("inbetween_clip_cache_misses_total").increment(1);
        let seen = self.cache.epoch();
        let stored = self.store.get(id).await?.ok_or(ApiError::NotFound { what: "clip" })?;
        let cached = Arc::new(if stored.doc_json.len() > BLOCKING_THRESHOLD_BYTES {
            tokio::task::spawn_blocking(move || compile_stored(stored)).await.map_err(ApiError::internal)??
        } else {
            compile_stored(stored)?
        });
        self.cache.insert_loaded(cached.clone(), seen);
        metrics::gauge!("inbetween_clip_cache_entries").set(self.cache.len() as f64);
        Ok(cached)
    }

    /// Write-through after a committed create or replace.
    pub fn cache_written(&self, cached: Arc<CachedClip>) {
        self.cache.insert_written(cached);
        metrics::gauge!("inbetween_clip_cache_entries").set(self.cache.len() as f64);
    }
}

/// Compiles a stored document. It was accepted once, so failure here means
/// the store was corrupted or the rules changed: an internal error.
fn compile_stored(stored: StoredClip) -> Result<CachedClip, ApiError> {
    let (_, spec) = parse_clip(stored.doc_json.as_bytes()).map_err(|e: DocError| {
        ApiError::internal(anyhow::anyhow!("stored clip {} no longer parses: {e}", stored.meta.id))
    })?;
    let clip = Clip::build(&spec)
        .map_err(|e| ApiError::internal(anyhow::anyhow!("stored clip {} no longer builds: {e}", stored.meta.id)))?;
    Ok(CachedClip { meta: stored.meta, clip })
}
