//! What the gRPC server answers before (or instead of) our handlers: a
//! request tonic itself cannot decode, and a handler that panics.
//!
//! tonic answers a body it cannot decode (a bad length prefix or
//! compression flag, bytes that are not the protobuf message) with
//! `INTERNAL`, and a message over the decoding limit with `OUT_OF_RANGE`.
//! Both are the client's fault, so [`layer`] reclassifies them as
//! `INVALID_ARGUMENT` and `RESOURCE_EXHAUSTED` — the codes `ApiError` gives
//! the same mistakes over REST (400, 413). Our own `INTERNAL`s always carry
//! the message prefix `internal:` (see `ApiError` → `Status`) and are left
//! alone. Only trailers-only responses (status in the headers) are
//! rewritten: that is how every failure to decode a unary or
//! server-streaming request is sent.
//!
//! A panicking handler becomes `INTERNAL` and is counted in
//! `inbetween_panics_total{source="grpc"}`.

use axum::http::{HeaderValue, Response};
use tower::layer::util::Stack;
use tower::util::MapResponseLayer;
use tower_http::catch_panic::CatchPanicLayer;

use super::metrics;

/// The gRPC status codes rewritten here (their numbers on the wire).
const INVALID_ARGUMENT: &str = "3";
const RESOURCE_EXHAUSTED: &str = "8";
const OUT_OF_RANGE: &str = "11";
const INTERNAL: &str = "13";

/// The prefix of every `INTERNAL` message `ApiError` produces.
const OWN_INTERNAL_PREFIX: &[u8] = b"internal:";

/// Both layers: the rewrite next to the routes, the panic catcher around
/// it (a panic's `INTERNAL` is never rewritten).
pub fn layer() -> Stack<MapResponseLayer<Reclassify>, CatchPanicLayer<PanicResponse>> {
    Stack::new(MapResponseLayer::new(reclassify), CatchPanicLayer::custom(PanicResponse))
}

type Reclassify = fn(Response<tonic::body::Body>) -> Response<tonic::body::Body>;

/// Turns tonic's decode failures into client-error codes (module docs).
pub fn reclassify(mut response: Response<tonic::body::Body>) -> Response<tonic::body::Body> {
    let headers = response.headers_mut();
    let Some(status) = headers.get("grpc-status").and_then(|v| v.to_str().ok()) else { return response };
    let new = match status {
        INTERNAL => {
            let message = headers.get("grpc-message").map_or(&b""[..], HeaderValue::as_bytes);
            if message.starts_with(OWN_INTERNAL_PREFIX) {
                return response;
            }
            INVALID_ARGUMENT
        }
        OUT_OF_RANGE => RESOURCE_EXHAUSTED,
        _ => return response,
    };
    headers.insert("grpc-status", HeaderValue::from_static(new));
    response
}

/// The response to a panicking gRPC handler: `INTERNAL`, counted.
#[derive(Clone, Copy)]
pub struct PanicResponse;

impl tower_http::catch_panic::ResponseForPanic for PanicResponse {
    type ResponseBody = tonic::body::Body;

    fn response_for_panic(&mut self, _err: Box<dyn std::any::Any + Send + 'static>) -> Response<Self::ResponseBody> {
        metrics::panic_caught("grpc");
        tonic::Status::internal("internal: internal error; see the server log").into_http()
    }
}
