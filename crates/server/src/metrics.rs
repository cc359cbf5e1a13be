//! Prometheus metrics, all prefixed `inbetween_`.
//!
//! The `metrics` facade has one global recorder per process, so the exporter
//! is installed once ([`handle`]) and shared by every [`super::Application`]
//! in the process (tests run several). `/metrics` renders the handle in our
//! own route; a task owned by the application runs the exporter's upkeep and
//! stops on shutdown.
//!
//! Requests are labelled by the *matched route template* (`/v1/clips/{id}`),
//! never the raw path, so clip ids cannot blow up label cardinality.

use std::sync::OnceLock;
use std::time::Instant;

use axum::extract::{MatchedPath, Request};
use axum::middleware::Next;
use axum::response::Response;
use metrics_exporter_prometheus::{Matcher, PrometheusBuilder, PrometheusHandle};

/// Seconds; covers a cached pose (tens of µs) up to a large sample or upload.
const LATENCY_BUCKETS: &[f64] =
    &[0.0001, 0.00025, 0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0];

/// The process-wide Prometheus handle, installing the recorder on first use.
/// If another recorder was installed first (an embedding program's), our
/// handle still renders, just without the facade's metrics.
pub fn handle() -> PrometheusHandle {
    static HANDLE: OnceLock<PrometheusHandle> = OnceLock::new();
    HANDLE
        .get_or_init(|| {
            let recorder = PrometheusBuilder::new()
                .set_buckets_for_metric(Matcher::Suffix("_seconds".into()), LATENCY_BUCKETS)
                .expect("the bucket list is not empty")
                .build_recorder();
            let handle = recorder.handle();
            if metrics::set_global_recorder(recorder).is_err() {
                tracing::warn!("a metrics recorder was already installed; /metrics will miss inbetween_* metrics");
            }
            describe();
            handle
        })
        .clone()
}

fn describe() {
    use metrics::{Unit, describe_counter, describe_gauge, describe_histogram};
    describe_counter!("inbetween_http_requests_total", "HTTP requests by method, route and status.");
    describe_histogram!(
        "inbetween_http_request_duration_seconds",
        Unit::Seconds,
        "HTTP request latency by method and route."
    );
    describe_counter!("inbetween_poses_evaluated_total", "Poses evaluated for REST requests.");
    describe_counter!("inbetween_clip_cache_hits_total", "Pose and sample requests served from the clip cache.");
    describe_counter!("inbetween_clip_cache_misses_total", "Clip loads that had to read and compile from the store.");
    describe_gauge!("inbetween_clip_cache_entries", "Compiled clips held in memory (as inbetween_cache_entries).");
    describe_gauge!("inbetween_cache_entries", "Compiled clips held in memory.");
    describe_gauge!(
        "inbetween_cache_bytes",
        Unit::Bytes,
        "Heap bytes the caches hold together (compiled clips and built motions), against cache_bytes."
    );
    describe_gauge!("inbetween_cache_limit_bytes", Unit::Bytes, "The caches' one byte bound (cache_bytes).");
    describe_counter!(
        "inbetween_motion_cache_hits_total",
        "Composed requests whose motion was found built in the motion cache."
    );
    describe_counter!(
        "inbetween_motion_cache_misses_total",
        "Composed requests whose motion had to be built (not cached for these clip versions)."
    );
    describe_gauge!("inbetween_motion_cache_entries", "Built motions held in memory.");
    describe_gauge!("inbetween_graph_cache_entries", "Built graphs held in memory, each by id at one version.");
    describe_gauge!(
        "inbetween_character_cache_entries",
        "Checked characters held in memory, each by id at one version."
    );
    describe_gauge!(
        "inbetween_bodies_awaited",
        "Requests whose body (a gRPC call's first message) is still arriving: they hold no in-flight slot yet."
    );
    describe_histogram!(
        "inbetween_store_operation_duration_seconds",
        Unit::Seconds,
        "Store latency by operation (create, get, list, replace, delete, ping)."
    );
    describe_counter!(
        "inbetween_panics_total",
        "Panics caught (source: http handler, grpc handler, blocking task); any is a bug."
    );
}

/// Where a caught panic happened (the `source` label of `inbetween_panics_total`).
pub const PANIC_SOURCES: [&str; 3] = ["http", "grpc", "task"];

/// Counts a caught panic (see `crate::panics`).
pub fn panic_caught(source: &'static str) {
    crate::panics::caught(source);
}

/// Handles to the unlabelled metrics the hot paths touch, registered once so
/// a pose request does no registry lookup for them.
#[derive(Clone)]
pub struct Counters {
    pub cache_hits: metrics::Counter,
    pub cache_misses: metrics::Counter,
    pub cache_entries: metrics::Gauge,
    pub cache_entries_total: metrics::Gauge,
    pub cache_bytes: metrics::Gauge,
    pub motion_cache_hits: metrics::Counter,
    pub motion_cache_misses: metrics::Counter,
    pub motion_cache_entries: metrics::Gauge,
    pub poses: metrics::Counter,
    /// Streamed answers whose client went away before the end (their
    /// evaluation stopped with them), and the poses left unevaluated.
    pub answers_abandoned: metrics::Counter,
    pub poses_abandoned: metrics::Counter,
}

impl Counters {
    /// Registers the handles (call after [`handle`] installed the recorder).
    pub fn new() -> Self {
        Counters {
            cache_hits: metrics::counter!("inbetween_clip_cache_hits_total"),
            cache_misses: metrics::counter!("inbetween_clip_cache_misses_total"),
            cache_entries: metrics::gauge!("inbetween_clip_cache_entries"),
            cache_entries_total: metrics::gauge!("inbetween_cache_entries"),
            cache_bytes: metrics::gauge!("inbetween_cache_bytes"),
            motion_cache_hits: metrics::counter!("inbetween_motion_cache_hits_total"),
            motion_cache_misses: metrics::counter!("inbetween_motion_cache_misses_total"),
            motion_cache_entries: metrics::gauge!("inbetween_motion_cache_entries"),
            poses: metrics::counter!("inbetween_poses_evaluated_total"),
            answers_abandoned: metrics::counter!("inbetween_answers_abandoned_total"),
            poses_abandoned: metrics::counter!("inbetween_poses_abandoned_total"),
        }
        .with_panic_counters()
    }

    /// The clip cache's size.
    pub fn cache_gauges(&self, entries: usize, bytes: usize) {
        self.cache_entries.set(entries as f64);
        self.cache_entries_total.set(entries as f64);
        self.cache_bytes.set(bytes as f64);
    }

    /// The motion cache's size.
    pub fn motion_cache_gauge(&self, entries: usize) {
        self.motion_cache_entries.set(entries as f64);
    }

    /// The sizes of the caches of built graphs and characters.
    pub fn document_cache_gauges(&self, graphs: usize, characters: usize) {
        metrics::gauge!("inbetween_graph_cache_entries").set(graphs as f64);
        metrics::gauge!("inbetween_character_cache_entries").set(characters as f64);
    }

    /// The cache's byte bound, set once at startup.
    pub fn cache_limit(&self, bytes: usize) {
        metrics::gauge!("inbetween_cache_limit_bytes").set(bytes as f64);
    }

    /// Registers `inbetween_panics_total` at 0 for every source, so it is
    /// on `/metrics` (and can be watched) before the first panic.
    fn with_panic_counters(self) -> Self {
        for source in PANIC_SOURCES {
            metrics::counter!("inbetween_panics_total", "source" => source).increment(0);
        }
        self
    }
}

impl Default for Counters {
    fn default() -> Self {
        Self::new()
    }
}

/// Middleware: counts and times every request by route template and status.
pub async fn track(request: Request, next: Next) -> Response {
    let started = Instant::now();
    let route = request.extensions().get::<MatchedPath>().map_or("unmatched", |p| p.as_str()).to_owned();
    let method = request.method().as_str().to_owned();
    let response = next.run(request).await;
    let status = response.status().as_u16().to_string();
    metrics::counter!("inbetween_http_requests_total", "method" => method.clone(), "route" => route.clone(), "status" => status)
        .increment(1);
    metrics::histogram!("inbetween_http_request_duration_seconds", "method" => method, "route" => route)
        .record(started.elapsed().as_secs_f64());
    response
}
