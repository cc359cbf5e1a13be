//! Liveness, readiness and the Prometheus scrape.
//!
//! `/healthz` answers as long as the process serves HTTP (it touches nothing);
//! `/readyz` answers 200 only while the store answers a trivial query and
//! shutdown has not begun, so a load balancer stops sending traffic before
//! the drain starts.

use std::time::Duration;

use axum::Json;
use axum::extract::State;
use axum::http::HeaderValue;
use axum::http::header::CONTENT_TYPE;
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use utoipa::ToSchema;

use crate::auth::AdminAccess;
use crate::error::ApiError;
use crate::state::AppState;

/// How long readiness waits for the store.
const PING_TIMEOUT: Duration = Duration::from_secs(2);

#[derive(Debug, Serialize, ToSchema)]
pub struct Status {
    /// `ok` (healthz) or `ready` (readyz).
    pub status: &'static str,
}

/// Liveness: the process serves HTTP.
#[utoipa::path(get, path = "/healthz", tag = "operations", responses((status = 200, body = Status)))]
pub async fn healthz() -> Json<Status> {
    Json(Status { status: "ok" })
}

/// Readiness: the store answers and the server is not shutting down.
#[utoipa::path(
    get, path = "/readyz", tag = "operations",
    responses((status = 200, body = Status), (status = 503, body = super::schemas::Problem))
)]
pub async fn readyz(State(state): State<AppState>) -> Result<Json<Status>, ApiError> {
    if !state.is_ready() {
        return Err(ApiError::Unavailable(Some(anyhow::anyhow!("shutting down"))));
    }
    match tokio::time::timeout(PING_TIMEOUT, state.store.ping()).await {
        Ok(Ok(())) => Ok(Json(Status { status: "ready" })),
        Ok(Err(e)) => Err(ApiError::Unavailable(Some(e.into()))),
        Err(_) => Err(ApiError::Unavailable(Some(anyhow::anyhow!("store ping timed out")))),
    }
}

/// Prometheus text exposition of every `inbetween_*` metric. Needs the admin
/// scope once an admin token is configured (the figures describe every
/// client's traffic).
#[utoipa::path(
    get, path = "/metrics", tag = "operations",
    responses(
        (status = 200, description = "Prometheus text format", content_type = "text/plain"),
    ),
    security((), ("bearer" = []))
)]
pub async fn metrics(_: AdminAccess, State(state): State<AppState>) -> Response {
    let content_type = HeaderValue::from_static("text/plain; version=0.0.4; charset=utf-8");
    ([(CONTENT_TYPE, content_type)], state.metrics.render()).into_response()
}
