//! The REST API (docs/api.md): routes, their extractors and the middleware stack.
//!
//! `router(state)` is the whole HTTP surface; [`crate::Application`]
//! only binds and serves it, so tests may also drive it with `oneshot`.
//! Other protocols' routes (the WebSocket stream, import) merge in here.
//! Every API and operations route sits behind `query::strict`: it takes
//! exactly the query parameters its OpenAPI operation lists.

use std::time::Duration;

use axum::Router;
use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::{HeaderName, HeaderValue, Method, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::trace::TraceLayer;

use super::access_log::{self, AccessLog};
use super::config::Cors;
use super::error::ApiError;
use super::metrics;
use super::state::AppState;
use super::{auth, body_guard, compression, ratelimit, routes, shed, spool};

pub mod broadcasts;
pub mod characters;
pub mod clips;
pub mod documents;
pub mod extract;
pub mod graphs;
pub mod health;
pub mod import;
pub mod mesh;
pub mod motions;
pub mod openapi;
pub mod patch;
pub mod pieces;
pub mod poses;
pub mod query;
pub mod schemas;
pub mod skeleton;
pub mod socket;
pub mod stream;
pub mod summary;
pub mod viewer;

/// Every route, with the middleware stack, bound to `state`.
pub fn router(state: AppState) -> Router {
    let limits = &state.config.limits;
    let cors = cors_layer(&state.config.cors);
    let request_id = HeaderName::from_static("x-request-id");
    // The API and operations routes take exactly the query parameters they document.
    let allowed = query::Allowed::from_openapi(&<openapi::ApiDoc as utoipa::OpenApi>::openapi());
    let strict = routes::mount(Router::new()).route_layer(middleware::from_fn_with_state(allowed, query::strict));
    Router::new()
        .merge(strict)
        .merge(openapi::router())
        .merge(viewer::router())
        .fallback(|| async { ApiError::NotFound { what: "route" } })
        .method_not_allowed_fallback(|| async { ApiError::MethodNotAllowed })
        .layer(DefaultBodyLimit::max(limits.max_body_bytes))
        // Admission after arrival: the in-flight slots are taken once the body guard has read the body.
        .layer(middleware::from_fn_with_state(
            shed::Admission {
                gate: shed::Gate::new(limits.max_in_flight),
                clients: std::sync::Arc::clone(&state.in_flight),
                never_shed: routes::never_shed,
            },
            shed::rest,
        ))
        .layer(middleware::from_fn_with_state(
            body_guard::BodyGuard {
                max_bytes: limits.max_body_bytes,
                read_timeout: limits.body_read_timeout,
                arrivals: state.arrivals.clone(),
                spool: Some(spool::SpoolRoute::new(
                    routes::import_paths(),
                    (limits.max_import_bytes, "max_import_bytes"),
                    spool::UploadLimits {
                        node: limits.max_import_uploads,
                        per_caller: limits.max_import_uploads_per_caller,
                        wait: limits.import_slot_wait,
                    },
                    spool::PaceLimit {
                        min_per_sec: limits.min_upload_bytes_per_sec,
                        window: limits.upload_rate_window,
                    },
                )),
            },
            body_guard::guard,
        ))
        // Compressed bodies are decoded before the body guard reads them: its limits count decoded bytes.
        .layer(compression::requests(state.config.compression))
        .layer(middleware::from_fn_with_state(
            ratelimit::WriteGate { limiter: std::sync::Arc::clone(&state.writes), is_write: routes::is_write },
            ratelimit::limit_writes,
        ))
        .layer(middleware::from_fn_with_state(state.auth.clone(), auth::identify_requests))
        .layer(middleware::from_fn_with_state(limits.request_timeout, request_timeout))
        .layer(middleware::from_fn(metrics::track))
        .layer(CatchPanicLayer::custom(|_| {
            metrics::panic_caught("http");
            ApiError::internal(anyhow::anyhow!("handler panicked")).into_response()
        }))
        .layer(middleware::from_fn_with_state(AccessLog::new(state.config.access_log_sample), access_log::log))
        .layer(compression::responses(state.config.compression))
        .layer(middleware::from_fn_with_state(state.compressors.clone(), compression::negotiate))
        .layer(TraceLayer::new_for_http())
        .layer(PropagateRequestIdLayer::new(request_id.clone()))
        .layer(SetRequestIdLayer::new(request_id, MakeRequestUuid))
        .layer(cors)
        .with_state(state)
}

/// Answers 503 `request_timeout` when a request takes longer than the limit.
async fn request_timeout(State(limit): State<Duration>, request: Request, next: Next) -> Response {
    match tokio::time::timeout(limit, next.run(request)).await {
        Ok(response) => response,
        Err(_) => ApiError::Timeout { secs: limit.as_secs() }.into_response(),
    }
}

fn cors_layer(cors: &Cors) -> CorsLayer {
    let origins = match cors {
        Cors::Off => return CorsLayer::new(),
        Cors::Any => AllowOrigin::any(),
        Cors::Origins(list) => AllowOrigin::list(list.iter().filter_map(|o| HeaderValue::from_str(o).ok())),
    };
    CorsLayer::new()
        .allow_origin(origins)
        .allow_methods([Method::GET, Method::POST, Method::PUT, Method::PATCH, Method::DELETE])
        .allow_headers([header::AUTHORIZATION, header::CONTENT_TYPE, header::IF_MATCH, header::IF_NONE_MATCH])
        .expose_headers([header::ETAG, header::LOCATION])
        .max_age(Duration::from_secs(3600))
}
