//! `inbetween serve`: the HTTP service around the core.
//!
//! [`Application::build`] opens the store, binds the listeners (port 0 picks a
//! free one; [`Application::local_addr`] and [`Application::grpc_addr`]
//! report them) and assembles the router;
//! [`Application::run_until_stopped`] serves until the given shutdown future
//! resolves, then drains. `main` and `cli/serve.rs` only wire flags to this,
//! and tests build it directly on `127.0.0.1:0` with a temporary store.
//!
//! Codemap: `config` layered settings; `error` the one `ApiError` (the only
//! place statuses are chosen); `state` what handlers share; `cache` compiled
//! clips; `motion_cache` built motions over them; `cache_budget` the one
//! byte budget those caches share; `builds` where clips are built and what a build costs (on the work pool);
//! `work` the price of work, the node's capacity and the pool where poses,
//! IK and answers are worked out;
//! `tokens` token specs and hashes; `auth` the caller of each request and its scopes; `limits` admission of uploads; `metrics`
//! Prometheus; `listen` the accept loop (hyper, with a header-read timeout);
//! `request` the sampling and stream rules both transports share, with their
//! stable codes; `rest` the routes; `grpc` the gRPC API, served on its own port
//! (`--grpc-listen`) by tonic beside the HTTP server, with the same shutdown.
//!
//! Shutdown: when the signal fires, readiness flips to 503 first; the
//! streaming engine ends every stream with a final status (gRPC
//! `UNAVAILABLE`, WebSocket close 1001: upgraded connections live in their
//! own tasks, which the engine's shutdown reaches) and waits for them to be
//! delivered; then both servers stop accepting and let in-flight requests
//! finish. One drain deadline (the drain timeout from the signal) bounds all
//! of it: whatever is still open then (a client that ignores GOAWAY, a
//! request that never ends) is cut off. Then the metrics upkeep task stops
//! and the store closes.

use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio::time::Instant;

use crate::store::ClipStore;
use crate::store::feed::ChangeFeed;
use crate::store::postgres::PgStore;
use crate::store::sqlite::SqliteStore;
use crate::stream::{Engine, EngineConfig};

pub(crate) mod access_log;
pub mod auth;
pub(crate) mod body_guard;
pub(crate) mod broadcast_store;
pub(crate) mod broadcast_work;
pub(crate) mod builds;
pub mod built;
pub(crate) mod cache;
pub(crate) mod cache_budget;
pub mod characters;
pub(crate) mod compression;
pub mod config;
pub(crate) mod connections;
pub(crate) mod documents;
pub mod error;
pub mod graphs;
pub(crate) mod grpc;
pub(crate) mod grpc_character;
pub(crate) mod grpc_edge;
pub(crate) mod grpc_graph;
pub(crate) mod grpc_motion;
pub(crate) mod limits;
mod listen;
pub(crate) mod metrics;
pub(crate) mod motion_cache;
pub(crate) mod notify;
pub(crate) mod ratelimit;
pub(crate) mod request;
pub(crate) mod rest;
pub mod routes;
pub(crate) mod shed;
pub(crate) mod spool;
pub(crate) mod state;
pub(crate) mod tls;
pub mod tokens;
pub(crate) mod work;

pub mod store;
pub mod stream;

mod panics;
mod sync;

pub use config::Config;
pub use error::ApiError;
pub use state::AppState;

/// A built server: store open, listeners bound, not yet serving.
pub struct Application {
    listener: TcpListener,
    grpc_listener: TcpListener,
    state: AppState,
    /// Certificate and key when serving TLS (`--tls-cert`).
    tls: Option<tls::TlsMaterial>,
    /// The changes other nodes sharing the store commit, which keep the
    /// cache in step (`notify`); `None` for a store of one node (SQLite).
    change_feed: Option<Arc<dyn ChangeFeed>>,
}

/// When the servers must have drained: `None` until shutdown begins.
type StopSignal = watch::Receiver<Option<Instant>>;

impl Application {
    /// Opens the store (running migrations) and binds the listener.
    ///
    /// # Errors
    /// The data directory or database cannot be opened, or the address
    /// cannot be bound.
    pub async fn build(config: Config) -> anyhow::Result<Application> {
        let mut change_feed: Option<Arc<dyn ChangeFeed>> = None;
        let store: Arc<dyn ClipStore> = match &config.store {
            config::StoreConfig::DataDir(dir) => {
                std::fs::create_dir_all(dir).with_context(|| format!("creating data directory {}", dir.display()))?;
                let path = dir.join("inbetween.db");
                let store = SqliteStore::open(&path, &config.db)
                    .await
                    .with_context(|| format!("opening {}", path.display()))?;
                Arc::new(store)
            }
            config::StoreConfig::SqliteUrl(url) => {
                Arc::new(SqliteStore::open_url(url.expose(), &config.db).await.context("opening database_url")?)
            }
            config::StoreConfig::Postgres(url) => {
                let store = PgStore::open(url.expose(), &config.db).await.context("opening the PostgreSQL database")?;
                change_feed = Some(Arc::new(store.change_feed()));
                Arc::new(store)
            }
        };
        let tls = config.tls.as_ref().map(tls::TlsMaterial::load).transpose()?;
        let cache_budget = Arc::new(cache_budget::CacheBudget::new(config.limits.cache_bytes));
        let cache = Arc::new(cache::ClipCache::new(config.limits.cache_entries, cache_budget.clone()));
        if change_feed.is_some() {
            // Nothing is cached until this node hears other nodes' changes.
            cache.suspend();
        }
        let listener = listen::bind(config.listen).with_context(|| format!("binding {}", config.listen))?;
        let grpc_listener =
            listen::bind(config.grpc_listen).with_context(|| format!("binding {}", config.grpc_listen))?;
        let streams = Engine::new(EngineConfig {
            max_streams: config.limits.max_streams,
            max_streams_per_client: config.limits.max_streams_per_client,
            max_streams_per_token: config.limits.max_streams_per_token,
            max_broadcasts: config.limits.max_broadcasts,
            broadcast_lead: config.limits.broadcast_control_lead,
            checkpointing: stream::Checkpointing {
                every: config.limits.broadcast_checkpoint,
                max_journal: config.limits.broadcast_max_journal,
            },
            precise_timer: true,
            ..EngineConfig::default()
        });
        let writes = Arc::new(ratelimit::WriteLimiter::new(config.limits.write_rate, config.limits.write_burst));
        let work = Arc::new(work::Work::new(&config.limits));
        // The recorder first: handles registered before it would count nothing.
        let prometheus = metrics::handle();
        let counters = metrics::Counters::new();
        counters.cache_limit(config.limits.cache_bytes);
        let compressors = compression::Gate::new(config.compression, config.limits.max_compressed_answers);
        let config = Arc::new(config);
        let state = AppState::new(state::Shared {
            store,
            cache,
            motions: motion_cache::MotionCache::new(config.limits.motion_cache_entries, cache_budget.clone()),
            graphs: cache::Cache::new(config.limits.graph_cache_entries, cache_budget.clone()),
            characters: cache::Cache::new(config.limits.graph_cache_entries, cache_budget.clone()),
            cache_budget,
            writes,
            in_flight: shed::Clients::new(config.limits.max_in_flight_per_client),
            arrivals: shed::Arrivals::new(config.limits.max_arriving_bytes),
            auth: auth::Auth::new(Arc::clone(&config)),
            config,
            metrics: prometheus,
            counters,
            ready: Arc::new(AtomicBool::new(true)),
            loads: Arc::default(),
            streams,
            patches: sync::Turns::default(),
            work,
            compressors,
        });
        // Broadcasts are kept in the store: resumed after a restart, shared by every node.
        let journal = broadcast_store::StoreJournal { store: Arc::clone(&state.store) };
        state.streams.broadcasts().set_journal(Arc::new(journal));
        let layouts = broadcast_work::PooledLayouts { work: Arc::clone(&state.work) };
        state.streams.broadcasts().set_layout_work(Arc::new(layouts));
        let app = Application { listener, grpc_listener, state, tls, change_feed };
        // One line with every setting in effect; `Secret` and `StoreConfig` print no token or password.
        tracing::info!(
            http = %app.local_addr(),
            grpc = %app.grpc_addr(),
            config = ?app.state.config,
            "starting with the effective configuration (secrets redacted)"
        );
        Ok(app)
    }

    /// The bound address (the real port when built with port 0).
    ///
    /// # Panics
    /// If the OS cannot report the socket's address (it always can for a bound TCP listener).
    pub fn local_addr(&self) -> SocketAddr {
        self.listener.local_addr().expect("a bound listener has an address")
    }

    /// The bound gRPC address.
    ///
    /// # Panics
    /// As [`Application::local_addr`].
    pub fn grpc_addr(&self) -> SocketAddr {
        self.grpc_listener.local_addr().expect("a bound listener has an address")
    }

    /// Whether both listeners speak TLS (`--tls-cert`).
    pub fn serves_tls(&self) -> bool {
        self.tls.is_some()
    }

    /// The shared state (for tests and for protocols served beside REST).
    pub fn state(&self) -> &AppState {
        &self.state
    }

    /// Serves until `shutdown` resolves, then drains in-flight requests for
    /// at most the configured drain timeout.
    ///
    /// # Errors
    /// The gRPC routes cannot be built (the embedded descriptor set does not
    /// parse: a build defect). Accept errors are logged and retried.
    pub async fn run_until_stopped(self, shutdown: impl Future<Output = ()> + Send + 'static) -> anyhow::Result<()> {
        let Application { listener, grpc_listener, state, tls, change_feed } = self;
        let http_tls = tls.as_ref().map(|m| m.http_config().map(tls::Acceptor::from)).transpose()?;
        let grpc_server = grpc_server(tls.as_ref(), state.config.limits.header_read_timeout)?;
        let background = Background::start(&state, change_feed);
        // Streams end first (each with its final status), then both servers
        // stop accepting and drain, all by one deadline (sent on `stop`).
        let (stop_tx, stop) = watch::channel(None);
        let coordinator = tokio::spawn(end_streams_then_stop(shutdown, &state, stop_tx));
        let grpc = tokio::spawn(serve_grpc(grpc_server, grpc_listener, &state, stop.clone()).await?);
        serve_http(listener, &state, http_tls, stop.clone()).await;
        let drain = state.config.drain_timeout;
        let deadline = stop.borrow().unwrap_or_else(|| Instant::now() + drain);
        drain_grpc(grpc, deadline, drain).await;
        coordinator.abort();
        background.stop();
        state.store.close().await;
        tracing::info!("stopped");
        Ok(())
    }
}

/// What runs beside the servers until they stop.
struct Background {
    upkeep: JoinHandle<()>,
    /// The change feed's listener, when nodes share the store.
    notify: Option<JoinHandle<()>>,
}

impl Background {
    fn start(state: &AppState, change_feed: Option<Arc<dyn ChangeFeed>>) -> Background {
        if change_feed.is_none() {
            // One node alone: resume the stored broadcasts at the tick the wall clock says.
            // (With a change feed the listener does it each time it subscribes.)
            tokio::spawn({
                let state = state.clone();
                async move { broadcast_store::resync(&state).await }
            });
        }
        let notify = change_feed.map(|feed| tokio::spawn(notify::run(feed, state.clone())));
        let upkeep = tokio::spawn(upkeep(state.metrics.clone()));
        Background { upkeep, notify }
    }

    fn stop(self) {
        self.upkeep.abort();
        if let Some(notify) = self.notify {
            notify.abort();
        }
    }
}

/// On `shutdown`: readiness flips to 503, every stream ends with its final
/// status (waited for at most the drain timeout), then `stop` tells both
/// servers to drain by the deadline, the drain timeout from the signal.
fn end_streams_then_stop(
    shutdown: impl Future<Output = ()> + Send + 'static,
    state: &AppState,
    stop: watch::Sender<Option<Instant>>,
) -> impl Future<Output = ()> + Send + 'static {
    let drain = state.config.drain_timeout;
    let ready = state.ready.clone();
    let streams = state.streams.clone();
    async move {
        shutdown.await;
        let deadline = Instant::now() + drain;
        ready.store(false, Ordering::Release);
        tracing::info!(active = streams.active_streams(), "shutting down: ending streams");
        streams.shutdown();
        if !streams.drained(drain).await {
            tracing::warn!(timeout = ?drain, "streams still open after the drain timeout");
        }
        tracing::info!("shutting down: draining in-flight requests");
        let _ = stop.send(Some(deadline));
    }
}

/// The gRPC server builder, with TLS when serving it.
fn grpc_server(
    tls: Option<&tls::TlsMaterial>,
    handshake_timeout: Duration,
) -> anyhow::Result<tonic::transport::Server> {
    let server = tonic::transport::Server::builder();
    Ok(match tls {
        Some(m) => server.tls_config(m.grpc_config(handshake_timeout))?,
        None => server,
    })
}

/// The gRPC server on its listener, behind the edge, admission and
/// connection layers, until `stop` says to drain.
///
/// # Errors
/// The routes cannot be built (see [`Application::run_until_stopped`]).
async fn serve_grpc(
    server: tonic::transport::Server,
    listener: TcpListener,
    state: &AppState,
    mut stop: StopSignal,
) -> anyhow::Result<impl Future<Output = Result<(), tonic::transport::Error>> + Send + 'static> {
    let routes = grpc::routes(state.clone(), state.streams.clone()).await?;
    let limits = &state.config.limits;
    let admission = shed::GrpcLayer {
        admission: shed::Admission {
            gate: shed::Gate::new(limits.max_in_flight),
            clients: Arc::clone(&state.in_flight),
            never_shed: crate::routes::never_shed,
        },
        arrivals: state.arrivals.clone(),
        auth: state.auth.clone(),
        message_timeout: limits.request_message_timeout,
        frame_stream: crate::routes::is_frame_rpc,
    };
    let incoming = connections::tracked_incoming(
        listener,
        connections::ConnGate::new(limits.max_connections, "grpc"),
        (limits.idle_timeout, limits.write_stall_timeout),
        limits.stream_buffer_bytes,
    );
    Ok(server
        .http2_keepalive_interval(Some(Duration::from_secs(30)))
        .max_concurrent_streams(limits.http2_max_concurrent_streams)
        .layer(connections::GrpcConnLayer)
        .layer(grpc_edge::layer())
        .layer(admission)
        // Next to the routes: a call that admission sheds takes no compressor.
        .layer(compression::GrpcAnswers::new(state.compressors.clone(), crate::routes::is_unary_rpc))
        .add_routes(routes)
        .serve_with_incoming_shutdown(incoming, async move {
            let _ = stop.wait_for(Option::is_some).await;
        }))
}

/// Serves REST until `stop` says to drain, then lets in-flight requests
/// finish until the deadline it carries, and cuts off the rest.
async fn serve_http(listener: TcpListener, state: &AppState, tls: Option<tls::Acceptor>, mut stop: StopSignal) {
    let (started_tx, started_rx) = tokio::sync::oneshot::channel::<Instant>();
    let signal = async move {
        let deadline = stop.wait_for(Option::is_some).await.ok().and_then(|d| *d);
        if let Some(deadline) = deadline {
            let _ = started_tx.send(deadline);
        }
    };
    let router = rest::router(state.clone());
    let limits = &state.config.limits;
    let listening = listen::Listening {
        header_read_timeout: limits.header_read_timeout,
        idle_timeout: limits.idle_timeout,
        write_stall_timeout: limits.write_stall_timeout,
        max_concurrent_streams: limits.http2_max_concurrent_streams,
        connections: connections::ConnGate::new(limits.max_connections, "http"),
        stream_buffer_bytes: limits.stream_buffer_bytes,
    };
    let mut serve = std::pin::pin!(listen::serve(listener, router, listening, tls, signal));
    tokio::select! {
        () = &mut serve => {}
        Ok(deadline) = started_rx => {
            if tokio::time::timeout_at(deadline, &mut serve).await.is_err() {
                let drain = state.config.drain_timeout;
                tracing::warn!(timeout = ?drain, "drain timeout: cutting off the remaining requests");
            }
        }
    }
}

/// Waits for the gRPC server to finish draining until `deadline`, then cuts
/// off the calls still open.
async fn drain_grpc(mut grpc: JoinHandle<Result<(), tonic::transport::Error>>, deadline: Instant, drain: Duration) {
    match tokio::time::timeout_at(deadline, &mut grpc).await {
        Ok(Ok(Err(e))) => tracing::error!(error = %e, "the gRPC server failed"),
        Ok(Err(e)) => tracing::error!(error = %e, "the gRPC server task failed"),
        Ok(Ok(Ok(()))) => {}
        Err(_) => {
            tracing::warn!(timeout = ?drain, "drain timeout: cutting off the remaining gRPC calls");
            grpc.abort();
        }
    }
}

/// Runs the Prometheus exporter's upkeep (histogram rotation) until aborted.
async fn upkeep(handle: metrics_exporter_prometheus::PrometheusHandle) {
    let mut every = tokio::time::interval(Duration::from_secs(5));
    loop {
        every.tick().await;
        handle.run_upkeep();
    }
}
