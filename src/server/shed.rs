//! Load shedding: a fixed budget of requests in flight per protocol. A
//! request over it is answered at once (503 + `Retry-After`; gRPC
//! `RESOURCE_EXHAUSTED`: [`ApiError::Overloaded`]) instead of
//! joining a queue, so under overload the admitted requests keep their
//! latency and memory stays bounded. Health, readiness and metrics are never
//! shed: an orchestrator must see an overloaded server as alive.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use tokio::sync::Semaphore;

use super::error::ApiError;

/// Seconds a shed client is told to wait.
const RETRY_AFTER_SECS: u64 = 1;

/// The in-flight budget of one protocol.
#[derive(Debug, Clone)]
pub struct Gate(Arc<Semaphore>);

impl Gate {
    pub fn new(max_in_flight: usize) -> Gate {
        Gate(Arc::new(Semaphore::new(max_in_flight)))
    }
}

fn exempt(path: &str) -> bool {
    matches!(path, "/healthz" | "/readyz" | "/metrics") || path.starts_with("/grpc.health.")
}

fn shed(protocol: &'static str) -> ApiError {
    metrics::counter!("inbetween_requests_shed_total", "protocol" => protocol).increment(1);
    ApiError::Overloaded { retry_after: RETRY_AFTER_SECS }
}

/// The REST middleware: holds a slot for the whole request.
pub async fn rest(State(gate): State<Gate>, request: Request, next: Next) -> Response {
    if exempt(request.uri().path()) {
        return next.run(request).await;
    }
    match gate.0.clone().try_acquire_owned() {
        Ok(_slot) => next.run(request).await,
        Err(_) => shed("http").into_response(),
    }
}

/// The same budget as a tower layer for tonic's server. A slot is held until
/// the response head is ready (a stream's frames are governed by the stream
/// caps, not by this).
#[derive(Debug, Clone)]
pub struct GrpcLayer(pub Gate);

impl<S> tower::Layer<S> for GrpcLayer {
    type Service = GrpcShed<S>;
    fn layer(&self, inner: S) -> GrpcShed<S> {
        GrpcShed { inner, gate: self.0.clone() }
    }
}

#[derive(Debug, Clone)]
pub struct GrpcShed<S> {
    inner: S,
    gate: Gate,
}

type BoxFuture<T> = Pin<Box<dyn Future<Output = T> + Send>>;

impl<S, B> tower::Service<axum::http::Request<B>> for GrpcShed<S>
where
    S: tower::Service<axum::http::Request<B>, Response = axum::http::Response<tonic::body::Body>> + Send,
    S::Future: Send + 'static,
    S::Error: Send + 'static,
{
    type Response = axum::http::Response<tonic::body::Body>;
    type Error = S::Error;
    type Future = BoxFuture<Result<Self::Response, S::Error>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), S::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, request: axum::http::Request<B>) -> Self::Future {
        if exempt(request.uri().path()) {
            return Box::pin(self.inner.call(request));
        }
        match self.gate.0.clone().try_acquire_owned() {
            Ok(slot) => {
                let response = self.inner.call(request);
                Box::pin(async move {
                    let r = response.await;
                    drop(slot);
                    r
                })
            }
            Err(_) => {
                let status = tonic::Status::from(shed("grpc"));
                Box::pin(std::future::ready(Ok(status.into_http())))
            }
        }
    }
}
