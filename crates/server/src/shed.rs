//! Admission of requests that have arrived: a fixed budget of requests in
//! flight per protocol, and a smaller one per caller across both. A request
//! over either is answered at once instead of joining a queue (global: 503 +
//! `Retry-After` / `RESOURCE_EXHAUSTED` [`ApiError::Overloaded`]; per caller:
//! 429 + `Retry-After` / `RESOURCE_EXHAUSTED` [`ApiError::ClientInFlight`]),
//! so under overload the admitted requests keep their latency and memory
//! stays bounded, and one caller cannot take the whole budget.
//!
//! A slot is taken only once the request is here: REST requests pass the
//! body guard (the whole body read, within the body-read timeout) before
//! this middleware; a gRPC call's first message is awaited here, within
//! `request_message_timeout` (else `DEADLINE_EXCEEDED` `body_timeout`), so
//! calls that never send it (or a `Play` that never sends `open`) hold
//! nothing and end. Health, readiness and metrics are never shed: an
//! orchestrator must see an overloaded server as alive.

use std::collections::HashMap;
use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use http_body::{Body, Frame, SizeHint};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tonic::transport::server::TcpConnectInfo;

use super::auth::{Auth, CallerKey, Identity};
use super::error::ApiError;
use crate::sync::lock;

/// Seconds a shed client is told to wait.
const RETRY_AFTER_SECS: u64 = 1;

/// The largest first gRPC message awaited whole (tonic's decoding limit);
/// a longer one is passed on at once and refused by tonic.
const MAX_AWAITED_MESSAGE: usize = 4 * 1024 * 1024;

/// The in-flight budget of one protocol.
#[derive(Debug, Clone)]
pub struct Gate(Arc<Semaphore>);

impl Gate {
    pub fn new(max_in_flight: usize) -> Gate {
        Gate(Arc::new(Semaphore::new(max_in_flight)))
    }
}

/// The bytes of request bodies (and first gRPC messages) held at once, from
/// their arrival until their request ends (`max_arriving_bytes`): arrival
/// comes before admission, so this is what bounds the memory of many
/// requests sending at once.
#[derive(Debug, Clone)]
pub struct Arrivals {
    budget: Arc<Semaphore>,
    max_bytes: usize,
    /// Requests whose body (first gRPC message) is being awaited now.
    awaited: Arc<AtomicUsize>,
}

/// One request counted as awaiting its body until dropped
/// (`inbetween_bodies_awaited`): such requests hold no in-flight slot, and
/// this is where they show.
#[derive(Debug)]
pub struct Awaiting(Arc<AtomicUsize>);

impl Drop for Awaiting {
    fn drop(&mut self) {
        let now = self.0.fetch_sub(1, Ordering::Relaxed) - 1;
        metrics::gauge!("inbetween_bodies_awaited").set(now as f64);
    }
}

impl Arrivals {
    pub fn new(max_bytes: usize) -> Arrivals {
        let max_bytes = max_bytes.min(Semaphore::MAX_PERMITS);
        Arrivals { budget: Arc::new(Semaphore::new(max_bytes)), max_bytes, awaited: Arc::default() }
    }

    /// Counts a request as awaiting its body until the guard is dropped.
    pub fn awaiting(&self) -> Awaiting {
        let now = self.awaited.fetch_add(1, Ordering::Relaxed) + 1;
        metrics::gauge!("inbetween_bodies_awaited").set(now as f64);
        Awaiting(Arc::clone(&self.awaited))
    }

    /// The requests awaiting their body now.
    pub fn awaited(&self) -> usize {
        self.awaited.load(Ordering::Relaxed)
    }

    /// The bytes held now, so a test can wait until a body has arrived.
    pub fn held(&self) -> usize {
        self.max_bytes - self.budget.available_permits()
    }

    /// Counts `bytes` more into `held`, or refuses (503) past the budget.
    ///
    /// # Errors
    /// [`ApiError::Overloaded`] when the budget cannot take them now.
    pub fn take(&self, held: &mut Option<OwnedSemaphorePermit>, bytes: usize) -> Result<(), ApiError> {
        if bytes == 0 {
            return Ok(());
        }
        let permits = u32::try_from(bytes).map_err(|_| shed("arrival"))?;
        let more = Arc::clone(&self.budget).try_acquire_many_owned(permits).map_err(|_| shed("arrival"))?;
        match held {
            Some(permit) => permit.merge(more),
            None => *held = Some(more),
        }
        Ok(())
    }
}

/// Requests in flight per caller (REST and gRPC together).
#[derive(Debug)]
pub struct Clients {
    max: usize,
    counts: Mutex<HashMap<CallerKey, usize>>,
}

impl Clients {
    pub fn new(max_per_client: usize) -> Arc<Clients> {
        Arc::new(Clients { max: max_per_client, counts: Mutex::new(HashMap::new()) })
    }

    /// The requests in flight now, every caller's, so a test can wait until one is admitted.
    pub fn in_flight(&self) -> usize {
        lock(&self.counts).values().sum()
    }

    /// A slot for one more request of `key`, unless it has `max` in flight.
    fn enter(self: &Arc<Self>, key: CallerKey) -> Result<ClientSlot, ApiError> {
        let mut counts = lock(&self.counts);
        let count = counts.entry(key.clone()).or_insert(0);
        if *count >= self.max {
            metrics::counter!("inbetween_client_in_flight_refused_total").increment(1);
            return Err(ApiError::ClientInFlight { limit: self.max, retry_after: RETRY_AFTER_SECS });
        }
        *count += 1;
        Ok(ClientSlot { clients: Arc::clone(self), key })
    }
}

/// One request counted against its caller until dropped.
#[derive(Debug)]
struct ClientSlot {
    clients: Arc<Clients>,
    key: CallerKey,
}

impl Drop for ClientSlot {
    fn drop(&mut self) {
        let mut counts = lock(&self.clients.counts);
        if let Some(count) = counts.get_mut(&self.key) {
            *count -= 1;
            if *count == 0 {
                counts.remove(&self.key);
            }
        }
    }
}

/// Both budgets, as the middleware and the layer hold them.
#[derive(Debug, Clone)]
pub struct Admission {
    pub gate: Gate,
    pub clients: Arc<Clients>,
    /// The REST paths never shed (the route table's probes and metrics).
    pub never_shed: fn(&str) -> bool,
}

/// What an admitted request holds until it is done.
#[derive(Debug)]
struct Slots {
    _client: ClientSlot,
    _global: OwnedSemaphorePermit,
}

impl Admission {
    /// Both slots for `key` (the caller's first, so a caller at its own cap
    /// takes nothing from the others).
    fn admit(&self, key: CallerKey, protocol: &'static str) -> Result<Slots, ApiError> {
        let client = self.clients.enter(key)?;
        let global = Arc::clone(&self.gate.0).try_acquire_owned().map_err(|_| shed(protocol))?;
        Ok(Slots { _client: client, _global: global })
    }
}

impl Admission {
    fn exempt(&self, path: &str) -> bool {
        (self.never_shed)(path) || path.starts_with("/grpc.health.")
    }
}

fn shed(protocol: &'static str) -> ApiError {
    metrics::counter!("inbetween_requests_shed_total", "protocol" => protocol).increment(1);
    ApiError::Overloaded { retry_after: RETRY_AFTER_SECS }
}

/// What per-caller budgets count a request under: its caller, or (a token
/// that matches nothing, refused later anyway) the unknown caller.
pub(crate) fn key_of(identity: Option<&Identity>) -> CallerKey {
    identity.and_then(Identity::caller).map_or(CallerKey::Unknown, |c| c.key())
}

/// The REST middleware (inside the body guard and auth): holds both slots
/// for the whole request.
pub async fn rest(State(admission): State<Admission>, request: Request, next: Next) -> Response {
    if admission.exempt(request.uri().path()) {
        return next.run(request).await;
    }
    let key = key_of(request.extensions().get::<Identity>());
    match admission.admit(key, "http") {
        // A chunked answer counts as in flight until its last piece is sent.
        Ok(slots) => next.run(request).await.map(|body| axum::body::Body::new(holding(body, slots))),
        Err(e) => e.into_response(),
    }
}

/// `body`, keeping `held` until it has been sent (or dropped).
fn holding<B, H>(body: B, held: H) -> Holding<B, H> {
    Holding { body, _held: held }
}

/// A body that holds something (in-flight slots) for as long as it lives;
/// size and end are the inner body's, so `Content-Length` is kept.
struct Holding<B, H> {
    body: B,
    _held: H,
}

impl<B: Body + Unpin, H: Unpin> Body for Holding<B, H> {
    type Data = B::Data;
    type Error = B::Error;

    fn poll_frame(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Result<Frame<B::Data>, B::Error>>> {
        Pin::new(&mut self.body).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.body.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.body.size_hint()
    }
}

/// The same budgets as a tower layer for tonic's server, which also
/// identifies each call's caller once (left in its extensions for the
/// handlers). Slots are held until the response has been sent, but for
/// streams of frames, which the stream caps govern once they start.
#[derive(Debug, Clone)]
pub struct GrpcLayer {
    pub admission: Admission,
    pub arrivals: Arrivals,
    pub auth: Auth,
    pub message_timeout: Duration,
    /// Streams of frames (`StreamFrames`, `Play`: the route table's) give
    /// their slots back once they start: the stream caps govern them. Every
    /// other call, `SampleStream` included, is in flight until its last
    /// message is sent.
    pub frame_stream: fn(&str) -> bool,
}

impl<S> tower::Layer<S> for GrpcLayer {
    type Service = GrpcShed<S>;
    fn layer(&self, inner: S) -> GrpcShed<S> {
        GrpcShed { inner, layer: self.clone() }
    }
}

#[derive(Debug, Clone)]
pub struct GrpcShed<S> {
    inner: S,
    layer: GrpcLayer,
}

type BoxFuture<T> = Pin<Box<dyn Future<Output = T> + Send>>;
type GrpcRequest = axum::http::Request<tonic::body::Body>;
type GrpcResponse = axum::http::Response<tonic::body::Body>;

impl<S> tower::Service<GrpcRequest> for GrpcShed<S>
where
    S: tower::Service<GrpcRequest, Response = GrpcResponse> + Clone + Send + 'static,
    S::Future: Send + 'static,
    S::Error: Send + 'static,
{
    type Response = GrpcResponse;
    type Error = S::Error;
    type Future = BoxFuture<Result<GrpcResponse, S::Error>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), S::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, mut request: GrpcRequest) -> Self::Future {
        let identity = identify(&self.layer.auth, &request);
        request.extensions_mut().insert(identity.clone());
        if self.layer.admission.exempt(request.uri().path()) {
            return Box::pin(self.inner.call(request));
        }
        // The service that was made ready goes with this call; a fresh clone stays.
        let mut inner = self.inner.clone();
        std::mem::swap(&mut inner, &mut self.inner);
        let layer = self.layer.clone();
        let frames = (self.layer.frame_stream)(request.uri().path());
        Box::pin(async move {
            let (request, held) = match first_message(request, layer.message_timeout, &layer.arrivals).await {
                Ok(arrived) => arrived,
                Err(e) => return Ok(tonic::Status::from(e).into_http()),
            };
            match layer.admission.admit(key_of(Some(&identity)), "grpc") {
                Ok(slots) if frames => {
                    let response = inner.call(request).await;
                    drop((slots, held));
                    response
                }
                Ok(slots) => {
                    let response = inner.call(request).await?;
                    Ok(response.map(|body| tonic::body::Body::new(holding(body, (slots, held)))))
                }
                Err(e) => Ok(tonic::Status::from(e).into_http()),
            }
        })
    }
}

/// The call's caller, from its `authorization` metadata and its address
/// (forwarded by a trusted proxy, see `auth`).
fn identify(auth: &Auth, request: &GrpcRequest) -> Identity {
    let peer = request.extensions().get::<TcpConnectInfo>().and_then(TcpConnectInfo::remote_addr).map(|a| a.ip());
    let headers = request.headers();
    let addr = auth.client_addr(peer, headers);
    auth.identify(headers.get(axum::http::header::AUTHORIZATION).map(|v| v.as_bytes()), addr)
}

/// `request` once its first gRPC message has fully arrived (or its body
/// ended, or the message is too long to wait for: tonic then answers),
/// with the bytes read so far put back in front of the body.
async fn first_message(
    request: GrpcRequest,
    timeout: Duration,
    arrivals: &Arrivals,
) -> Result<(GrpcRequest, Option<OwnedSemaphorePermit>), ApiError> {
    let (parts, mut body) = request.into_parts();
    let mut head = bytes::BytesMut::new();
    let mut held = None;
    let _awaiting = arrivals.awaiting();
    let read = async {
        while !message_complete(&head) {
            let Some(frame) = std::future::poll_fn(|cx| Pin::new(&mut body).poll_frame(cx)).await else { break };
            match frame.map(Frame::into_data) {
                Ok(Ok(data)) => {
                    arrivals.take(&mut held, data.len())?;
                    head.extend_from_slice(&data);
                }
                // Trailers, or a broken stream: tonic reports it.
                _ => break,
            }
        }
        Ok::<(), ApiError>(())
    };
    match tokio::time::timeout(timeout, read).await {
        Ok(read) => read?,
        Err(_) => {
            metrics::counter!("inbetween_message_timeouts_total").increment(1);
            return Err(ApiError::BodyTimeout { secs: timeout.as_secs() });
        }
    }
    let body = tonic::body::Body::new(Prefixed { head: Some(head.freeze()).filter(|h| !h.is_empty()), body });
    Ok((GrpcRequest::from_parts(parts, body), held))
}

/// Whether `head` holds a whole gRPC message (5-byte prefix, then the
/// length it declares), or enough to know it is too long to await.
fn message_complete(head: &[u8]) -> bool {
    let Some(prefix) = head.get(..5) else { return false };
    let length = u32::from_be_bytes([prefix[1], prefix[2], prefix[3], prefix[4]]) as usize;
    length > MAX_AWAITED_MESSAGE || head.len() >= 5 + length
}

/// A request body with the bytes already read put back in front.
struct Prefixed {
    head: Option<Bytes>,
    body: tonic::body::Body,
}

impl Body for Prefixed {
    type Data = Bytes;
    type Error = tonic::Status;

    fn poll_frame(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Result<Frame<Bytes>, tonic::Status>>> {
        let this = self.get_mut();
        if let Some(head) = this.head.take() {
            return Poll::Ready(Some(Ok(Frame::data(head))));
        }
        Pin::new(&mut this.body).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.head.is_none() && self.body.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        let mut hint = self.body.size_hint();
        let extra = self.head.as_ref().map_or(0, |h| h.len() as u64);
        hint.set_lower(hint.lower() + extra);
        if let Some(upper) = hint.upper() {
            hint.set_upper(upper + extra);
        }
        hint
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_message_is_complete_once_its_declared_length_is_here() {
        assert!(!message_complete(&[0, 0, 0]));
        assert!(message_complete(&[0, 0, 0, 0, 0]), "an empty message");
        assert!(!message_complete(&[0, 0, 0, 0, 3, 1, 2]));
        assert!(message_complete(&[0, 0, 0, 0, 3, 1, 2, 3]));
        assert!(message_complete(&[0, 0x01, 0, 0, 0]), "16 MiB: passed on for tonic to refuse");
    }

    #[test]
    fn arriving_bytes_are_bounded_together_and_come_back() {
        let arrivals = Arrivals::new(100);
        let (mut a, mut b) = (None, None);
        arrivals.take(&mut a, 60).unwrap();
        arrivals.take(&mut a, 30).unwrap();
        assert!(matches!(arrivals.take(&mut b, 20), Err(ApiError::Overloaded { .. })));
        arrivals.take(&mut b, 10).unwrap();
        drop(a);
        arrivals.take(&mut b, 80).unwrap();
        assert_eq!(b.map(|p| p.num_permits()), Some(90));
    }

    #[test]
    fn a_caller_at_its_cap_is_refused_until_one_of_its_requests_ends() {
        let clients = Clients::new(2);
        let a = CallerKey::Addr([10, 0, 0, 1].into());
        let (first, _second) = (clients.enter(a.clone()).unwrap(), clients.enter(a.clone()).unwrap());
        assert!(matches!(clients.enter(a.clone()), Err(ApiError::ClientInFlight { limit: 2, .. })));
        assert!(clients.enter(CallerKey::Addr([10, 0, 0, 2].into())).is_ok(), "others are not affected");
        drop(first);
        assert!(clients.enter(a).is_ok());
    }
}
