//! Content codings on the REST port (the gRPC port's are tonic's own,
//! switched on in `grpc`).
//!
//! **Answers** are compressed with zstd, br or gzip when the client's
//! `Accept-Encoding` asks for one (tower-http's `CompressionLayer`): clip
//! documents (the 131_03 take: 1.8 MB of JSON), sample batches, the OpenAPI
//! document and the viewer's files. Not compressed: answers of a known length
//! under `compression_min_bytes` (a pose, an error: a compressor's header and
//! CPU for a few bytes saved), the WebSocket upgrade (a 101 without a body;
//! frames are never compressed: no `permessage-deflate`), gRPC, images and
//! event streams. An answer sent in pieces (`rest::pieces`) is compressed
//! piece by piece as the client takes them: the encoder holds its window,
//! never the answer.
//!
//! [`negotiate`] picks the coding itself and hands the compressor exactly
//! that one: the client's highest `q`, ties broken zstd → br → gzip (zstd is
//! the fastest of the three at a similar size). A header that accepts none of
//! them (`identity;q=0` alone, say) gets an uncompressed answer, which RFC
//! 9110 §12.5.3 allows, rather than tower-http 0.7's 406 — which it sends
//! after the handler ran, so a `POST` would have created a clip behind it.
//!
//! **What compressing costs** (docs/operations.md, “Memory”): each
//! compressed answer holds an encoder — its window and match tables — for
//! as long as it is sent, and burns CPU per byte. So at most
//! `max_compressed_answers` answers are compressed at once; an answer that
//! finds them all busy goes uncompressed (as if the client had not asked),
//! never waits. Answers of a known length under [`SMALL_ANSWER_BYTES`] use
//! zstd's and gzip's usual levels (3 and 6: a few kilobytes, where the ratio
//! matters and the CPU does not); larger ones and answers sent in pieces use
//! level 1 of each, where the CPU per megabyte is what counts. br is always
//! at quality 1: from quality 2 up its encoder allocates its full window
//! tables whatever the answer's size (≈ 40 MB at quality 4, tower-http's
//! default; 64 of them killed a 1 GiB server). [`state_bytes`] gives an
//! answer's encoder memory; its CPU is in its price (`work::price::compression`,
//! which a pose request charges as [`AnswerCoding`] says; figures:
//! BENCHMARKS.md, “Compression”).
//!
//! On the gRPC port, tonic compresses unary answers (gzip or zstd) for
//! clients that ask and decodes compressed requests ([`grpc`]). tonic
//! compresses on the async workers at fixed levels (gzip 6, zstd 3), so
//! [`GrpcAnswers`] lets it do so only for answers that cost a few
//! milliseconds at most: a unary answer under [`SMALL_ANSWER_BYTES`]
//! ([`grpc_answer`]), holding one of the same `max_compressed_answers`
//! permits as REST's, charged in its price as REST's are. Streams of frames
//! and of pose batches, and larger answers, go uncompressed.
//!
//! **Request bodies** may be sent with `Content-Encoding: gzip`, `br` or
//! `zstd` (uploads of large documents). They are decoded *before* the body
//! guard (`body_guard`) reads them, so `max_body_bytes` and the arrival
//! budget count decoded bytes: a small compressed body that inflates past the
//! limit is cut off with 413 as soon as the decoded bytes pass it, and no
//! more of it is inflated (a zip bomb costs the server at most
//! `max_body_bytes` of inflating). A coding we do not decode is 415
//! `unsupported_media_type`, with `Accept-Encoding` naming the ones we do.
//! With `compression = false` neither happens: answers go as they are and
//! a compressed body is 415.

use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use axum::body::{Body, Bytes, HttpBody};
use axum::extract::{Request, State};
use axum::http::header::{ACCEPT_ENCODING, CONTENT_ENCODING, CONTENT_LENGTH};
use axum::http::{HeaderMap, HeaderValue, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tower::layer::util::Stack;
use tower_http::compression::predicate::{NotForContentType, Predicate};
use tower_http::compression::{CompressionLayer, CompressionLevel};
use tower_http::decompression::RequestDecompressionLayer;

use tonic::codec::CompressionEncoding;

use super::config::Compression;
use super::error::ApiError;
use crate::work::price::{self, Coding};
use formats::wire::proto::server::animation_server::{Animation, AnimationServer};

/// The codings we produce and decode, in our order of preference.
const CODINGS: [&str; 3] = ["zstd", "br", "gzip"];

/// The content coding a request body was sent in, left in the request's
/// extensions for the body guard's error message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BodyCoding(pub &'static str);

/// Answers worth compressing by status and size: never one that has no
/// body by definition (1xx — the WebSocket upgrade —, 204, 304) or an empty
/// one, nor one whose known length is under the minimum. A length not known
/// in advance (an answer sent in pieces) is compressed.
#[derive(Debug, Clone, Copy)]
struct WorthIt {
    min_bytes: u64,
}

impl Predicate for WorthIt {
    fn should_compress<B: HttpBody>(&self, response: &axum::http::Response<B>) -> bool {
        let status = response.status();
        if status.is_informational() || status == StatusCode::NO_CONTENT || status == StatusCode::NOT_MODIFIED {
            return false;
        }
        let known = response.body().size_hint().exact().or_else(|| {
            response.headers().get(CONTENT_LENGTH).and_then(|v| v.to_str().ok()).and_then(|v| v.parse().ok())
        });
        known.is_none_or(|n| n > 0 && n >= self.min_bytes)
    }
}

/// Answers of a known length under this are small: compressed at zstd's and
/// gzip's usual levels; the others, and br always, at [`LARGE_LEVEL`].
pub const SMALL_ANSWER_BYTES: u64 = 64 * 1024;

/// The level of large and streamed answers, the same number for the three
/// codings: zstd 1, br 1, gzip 1.
pub const LARGE_LEVEL: i32 = 1;

/// [`WorthIt`], not gRPC, images or event streams; with `small_only`, only
/// answers of a known length under [`SMALL_ANSWER_BYTES`].
#[derive(Debug, Clone, Copy)]
pub struct Answers {
    worth_it: WorthIt,
    small_only: bool,
}

impl Predicate for Answers {
    fn should_compress<B: HttpBody>(&self, response: &axum::http::Response<B>) -> bool {
        let small = || response.body().size_hint().exact().is_some_and(|n| n < SMALL_ANSWER_BYTES);
        self.worth_it.should_compress(response)
            && NotForContentType::GRPC.should_compress(response)
            && NotForContentType::IMAGES.should_compress(response)
            && NotForContentType::SSE.should_compress(response)
            && (!self.small_only || small())
    }
}

/// The compressors of answers (see the module doc for what they leave
/// alone): the inner one takes the small answers at the usual levels, the
/// outer one what is left (it never compresses an answer twice: tower-http
/// leaves one that has a `Content-Encoding`) at [`LARGE_LEVEL`].
pub fn responses(config: Compression) -> Stack<CompressionLayer<Answers>, CompressionLayer<Answers>> {
    let worth_it = WorthIt { min_bytes: config.min_bytes as u64 };
    let on = config.enabled;
    let small =
        CompressionLayer::new().zstd(on).br(false).gzip(on).compress_when(Answers { worth_it, small_only: true });
    let large = CompressionLayer::new()
        .zstd(on)
        .br(on)
        .gzip(on)
        .quality(CompressionLevel::Precise(LARGE_LEVEL))
        .compress_when(Answers { worth_it, small_only: false });
    Stack::new(small, large)
}

/// Bytes one encoder holds while it compresses, by coding and level
/// (window plus match tables; BENCHMARKS.md, “Compression”): what [`Gate`]
/// lets at most `max_compressed_answers` answers hold at once.
#[allow(dead_code, reason = "the figures of docs/operations.md, “Memory”; tested here")]
pub fn state_bytes(coding: &str, level: i32) -> u64 {
    const KIB: u64 = 1024;
    match (coding, level) {
        // zstd allocates in C, out of the Rust counter's sight: its own
        // estimate for these levels (window 512 KiB at 1, 1 MiB at 3).
        ("zstd", ..=1) => 1280 * KIB,
        ("zstd", _) => 2560 * KIB,
        // Measured: quality 1 keeps no window tables; 2 and up do (lgwin 22).
        ("br", ..=1) => 96 * KIB,
        ("br", 2..=9) => 40 * 1024 * KIB,
        ("br", _) => 72 * 1024 * KIB,
        // Measured: deflate's window, hash chains and pending buffer.
        ("gzip", _) => 404 * KIB,
        _ => 0,
    }
}

/// The coding [`negotiate`] chose for a request's answer (it rewrote
/// `Accept-Encoding` to that one, or to none), whose level [`responses`]
/// picks by the answer's size: what a pose request's price charges for
/// compressing (`work::price::compression`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AnswerCoding {
    coding: Option<Coding>,
    min_bytes: u64,
    /// Answers this large and larger go as they are (gRPC's; REST: none).
    max_bytes: Option<u64>,
}

impl AnswerCoding {
    /// The coding of a request with `headers` (after [`negotiate`]) on a
    /// server compressing answers of `min_bytes` and more.
    pub fn of(headers: &HeaderMap, min_bytes: usize) -> AnswerCoding {
        let coding = match headers.get(ACCEPT_ENCODING).and_then(|v| v.to_str().ok()) {
            Some("zstd") => Some(Coding::Zstd),
            Some("br") => Some(Coding::Br),
            Some("gzip") => Some(Coding::Gzip),
            _ => None,
        };
        AnswerCoding { coding, min_bytes: min_bytes as u64, max_bytes: None }
    }

    /// The coding of a gRPC request after [`GrpcAnswers`] (tonic's levels,
    /// which are REST's small-answer levels; only small answers).
    pub fn of_grpc<T>(request: &tonic::Request<T>) -> AnswerCoding {
        request.extensions().get::<AnswerCoding>().copied().unwrap_or_default()
    }

    /// How an answer of at most `bound` bytes is compressed; `None` when
    /// it goes as it is (no coding, or under `compression_min_bytes`).
    pub fn at(self, bound: u64) -> Option<price::Compression> {
        let compressed = bound >= self.min_bytes && self.max_bytes.is_none_or(|max| bound < max);
        let coding = self.coding.filter(|_| compressed)?;
        let level = match coding {
            Coding::Br => LARGE_LEVEL,
            _ if bound >= SMALL_ANSWER_BYTES => LARGE_LEVEL,
            Coding::Zstd => SMALL_ZSTD_LEVEL,
            Coding::Gzip => SMALL_GZIP_LEVEL,
        };
        Some(price::Compression { coding, level })
    }
}

/// The usual levels small answers get (tower-http's defaults).
const SMALL_ZSTD_LEVEL: i32 = 3;
const SMALL_GZIP_LEVEL: i32 = 6;

/// The cap on answers compressed at once; handed to [`negotiate`].
#[derive(Debug, Clone)]
pub struct Gate {
    config: Compression,
    permits: Arc<Semaphore>,
}

impl Gate {
    /// At most `max_answers` compressed at once.
    pub fn new(config: Compression, max_answers: usize) -> Self {
        Gate { config, permits: Arc::new(Semaphore::new(max_answers)) }
    }
}

/// An answer's body holding its compressor's permit until it is sent (or dropped).
struct Held<B> {
    body: B,
    _permit: OwnedSemaphorePermit,
}

impl<B: HttpBody<Data = Bytes> + Unpin> HttpBody for Held<B> {
    type Data = Bytes;
    type Error = B::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<http_body::Frame<Bytes>, B::Error>>> {
        Pin::new(&mut self.body).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.body.is_end_stream()
    }

    fn size_hint(&self) -> http_body::SizeHint {
        self.body.size_hint()
    }
}

/// The decoder of request bodies; [`negotiate`] has already refused codings
/// it does not decode.
pub fn requests(config: Compression) -> RequestDecompressionLayer {
    RequestDecompressionLayer::new().zstd(config.enabled).br(config.enabled).gzip(config.enabled)
}

/// The `Animation` service with gzip and zstd both ways: requests sent with
/// `grpc-encoding` are decoded (tonic counts the decoding limit in decoded
/// bytes and stops inflating there: `RESOURCE_EXHAUSTED`), and answers are
/// compressed when the client's `grpc-accept-encoding` lists one of them.
pub fn grpc<S: Animation>(server: AnimationServer<S>, config: Compression) -> AnimationServer<S> {
    if !config.enabled {
        return server;
    }
    server
        .accept_compressed(CompressionEncoding::Gzip)
        .accept_compressed(CompressionEncoding::Zstd)
        .send_compressed(CompressionEncoding::Zstd)
        .send_compressed(CompressionEncoding::Gzip)
}

/// The gRPC answers' gate (module doc): for a call whose answers may be
/// compressed (the route table's unary calls) and a client whose
/// `grpc-accept-encoding` names gzip or zstd, one compressor permit, held
/// by the answer's body; without a free permit, or for a stream, the
/// header is dropped and the answer goes as it is. Frames go uncompressed
/// as on the WebSocket: a playback encodes each frame once for all its
/// viewers, and compressing would cost every viewer a compressor per tick
/// (grpcio clients ask for gzip by default). What the client sends
/// compressed is still decoded.
#[derive(Clone)]
pub struct GrpcAnswers {
    gate: Gate,
    compresses: fn(&str) -> bool,
}

impl GrpcAnswers {
    /// `compresses`: whether the call at a path answers one message.
    pub fn new(gate: Gate, compresses: fn(&str) -> bool) -> Self {
        GrpcAnswers { gate, compresses }
    }

    /// Narrows the request's `grpc-accept-encoding` to the coding its
    /// answer will use, or removes it; the permit that coding holds.
    fn admit<B>(&self, request: &mut axum::http::Request<B>) -> Option<OwnedSemaphorePermit> {
        let wanted = (self.gate.config.enabled && (self.compresses)(request.uri().path()))
            .then(|| grpc_answer_coding(request.headers()))
            .flatten();
        let permit = wanted.and_then(|_| Arc::clone(&self.gate.permits).try_acquire_owned().ok());
        match wanted.filter(|_| permit.is_some()) {
            Some((name, coding)) => {
                request.headers_mut().insert(GRPC_ACCEPT_ENCODING, HeaderValue::from_static(name));
                let max_bytes = Some(SMALL_ANSWER_BYTES);
                request.extensions_mut().insert(AnswerCoding { coding: Some(coding), min_bytes: 0, max_bytes });
            }
            None => {
                request.headers_mut().remove(GRPC_ACCEPT_ENCODING);
            }
        }
        permit
    }
}

const GRPC_ACCEPT_ENCODING: &str = "grpc-accept-encoding";

/// The first of the client's `grpc-accept-encoding` codings that tonic
/// sends ([`grpc`]), as tonic picks it: the client's order.
fn grpc_answer_coding(headers: &HeaderMap) -> Option<(&'static str, Coding)> {
    let value = headers.get(GRPC_ACCEPT_ENCODING)?.to_str().ok()?;
    value.split(',').find_map(|name| match name.trim() {
        "zstd" => Some(("zstd", Coding::Zstd)),
        "gzip" => Some(("gzip", Coding::Gzip)),
        _ => None,
    })
}

impl<S> tower::Layer<S> for GrpcAnswers {
    type Service = GrpcAnswersService<S>;

    fn layer(&self, inner: S) -> Self::Service {
        GrpcAnswersService { inner, layer: self.clone() }
    }
}

/// [`GrpcAnswers`] around the gRPC routes.
#[derive(Clone)]
pub struct GrpcAnswersService<S> {
    inner: S,
    layer: GrpcAnswers,
}

type GrpcResponse = axum::http::Response<tonic::body::Body>;

impl<S, B> tower::Service<axum::http::Request<B>> for GrpcAnswersService<S>
where
    S: tower::Service<axum::http::Request<B>, Response = GrpcResponse>,
    S::Future: Send + 'static,
{
    type Response = GrpcResponse;
    type Error = S::Error;
    type Future = futures_util::future::BoxFuture<'static, Result<GrpcResponse, S::Error>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, mut request: axum::http::Request<B>) -> Self::Future {
        let permit = self.layer.admit(&mut request);
        let answer = self.inner.call(request);
        Box::pin(async move {
            let response = answer.await?;
            Ok(match permit {
                Some(permit) if response.headers().contains_key("grpc-encoding") => {
                    response.map(|body| tonic::body::Body::new(Held { body, _permit: permit }))
                }
                _ => response,
            })
        })
    }
}

/// A unary gRPC answer: compressed (if its client asked and
/// [`GrpcAnswers`] let it) only under [`SMALL_ANSWER_BYTES`], which costs
/// the async worker that tonic compresses on at most a few milliseconds.
pub fn grpc_answer<T: prost::Message>(message: T) -> tonic::Response<T> {
    let large = message.encoded_len() as u64 >= SMALL_ANSWER_BYTES;
    let mut response = tonic::Response::new(message);
    if large {
        response.extensions_mut().insert(tonic::codec::SingleMessageCompressionOverride::Disable);
    }
    response
}

/// Middleware (outside [`requests`] and [`responses`]): checks the body's
/// `Content-Encoding` and rewrites `Accept-Encoding` to the one coding the
/// answer will use (module doc), or to none when every compressor is busy;
/// a compressed answer keeps its permit until it is sent.
pub async fn negotiate(State(gate): State<Gate>, mut request: Request, next: Next) -> Response {
    let config = gate.config;
    match body_coding(request.headers(), config.enabled) {
        Ok(None) => {
            request.headers_mut().remove(CONTENT_ENCODING);
        }
        Ok(Some(_)) if request.body().is_end_stream() => {
            // No body to decode (a GET that names a coding): nothing to do.
            request.headers_mut().remove(CONTENT_ENCODING);
        }
        Ok(Some(coding)) => {
            request.headers_mut().insert(CONTENT_ENCODING, HeaderValue::from_static(coding));
            request.extensions_mut().insert(BodyCoding(coding));
        }
        Err(e) => return unsupported(e, config.enabled),
    }
    let chosen = if config.enabled { answer_coding(request.headers()) } else { None };
    let permit = chosen.and_then(|_| Arc::clone(&gate.permits).try_acquire_owned().ok());
    match chosen.filter(|_| permit.is_some()) {
        Some(coding) => request.headers_mut().insert(ACCEPT_ENCODING, HeaderValue::from_static(coding)),
        None => request.headers_mut().remove(ACCEPT_ENCODING),
    };
    let response = next.run(request).await;
    match permit {
        Some(permit) if response.headers().contains_key(CONTENT_ENCODING) => {
            response.map(|body| Body::new(Held { body, _permit: permit }))
        }
        _ => response,
    }
}

/// The body's coding: `None` for none or `identity`, one of [`CODINGS`]
/// (lower-cased) when enabled, else the refusal.
fn body_coding(headers: &HeaderMap, enabled: bool) -> Result<Option<&'static str>, ApiError> {
    let mut values = headers.get_all(CONTENT_ENCODING).iter();
    let Some(value) = values.next() else { return Ok(None) };
    let refuse = |what: &str| ApiError::UnsupportedMediaType {
        detail: if enabled {
            format!("Content-Encoding {what} is not decoded here: send the body as it is, or in gzip, br or zstd")
        } else {
            format!("Content-Encoding {what} is not decoded here (compression is off): send the body as it is")
        },
    };
    let text = value.to_str().unwrap_or("").trim().to_ascii_lowercase();
    if values.next().is_some() || text.contains(',') {
        return Err(refuse("with several codings"));
    }
    if text == "identity" {
        return Ok(None);
    }
    match CODINGS.iter().find(|c| **c == text) {
        Some(coding) if enabled => Ok(Some(coding)),
        _ => Err(refuse(&format!("`{text}`"))),
    }
}

/// 415, naming the codings we decode (RFC 7694).
fn unsupported(e: ApiError, enabled: bool) -> Response {
    let mut response = e.into_response();
    let accepted = if enabled { "zstd, br, gzip" } else { "identity" };
    response.headers_mut().insert(ACCEPT_ENCODING, HeaderValue::from_static(accepted));
    response
}

/// The coding of the answer: the one of [`CODINGS`] the client's
/// `Accept-Encoding` (every line of it) gives the highest `q`, ties in our
/// order; `None` when it accepts none of them. Entries whose `q` does not
/// parse are ignored; `*` stands for any coding not named.
fn answer_coding(headers: &HeaderMap) -> Option<&'static str> {
    let mut named: Vec<(String, f32)> = Vec::new();
    let mut any: Option<f32> = None;
    for item in headers.get_all(ACCEPT_ENCODING).iter().filter_map(|v| v.to_str().ok()).flat_map(|v| v.split(',')) {
        let mut parts = item.split(';');
        let coding = parts.next().unwrap_or("").trim().to_ascii_lowercase();
        let q = match parts.find_map(|p| p.trim().strip_prefix("q=").or_else(|| p.trim().strip_prefix("Q="))) {
            Some(q) => match q.trim().parse::<f32>() {
                Ok(q) if (0.0..=1.0).contains(&q) => q,
                _ => continue,
            },
            None => 1.0,
        };
        match coding.as_str() {
            "" => {}
            "*" => any = Some(q),
            _ => named.push((coding, q)),
        }
    }
    let q_of = |coding: &str| named.iter().find(|(c, _)| c == coding).map(|(_, q)| *q).or(any).unwrap_or(0.0);
    let mut best: Option<(&'static str, f32)> = None;
    for coding in CODINGS {
        let q = q_of(coding);
        if q > 0.0 && best.is_none_or(|(_, b)| q > b) {
            best = Some((coding, q));
        }
    }
    best.map(|(c, _)| c)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn choose(lines: &[&str]) -> Option<&'static str> {
        let mut headers = HeaderMap::new();
        for line in lines {
            headers.append(ACCEPT_ENCODING, HeaderValue::from_str(line).unwrap());
        }
        answer_coding(&headers)
    }

    #[test]
    fn the_clients_preference_wins_and_ties_go_zstd_br_gzip() {
        assert_eq!(choose(&[]), None);
        assert_eq!(choose(&["gzip, deflate, br, zstd"]), Some("zstd"), "Chrome's header");
        assert_eq!(choose(&["gzip, deflate, br"]), Some("br"));
        assert_eq!(choose(&["gzip"]), Some("gzip"));
        assert_eq!(choose(&["GZIP;Q=0.5, br;q=0.4"]), Some("gzip"));
        assert_eq!(choose(&["zstd;q=0.1", "gzip;q=0.9"]), Some("gzip"), "every header line counts");
        assert_eq!(choose(&["*"]), Some("zstd"));
        assert_eq!(choose(&["*;q=0.5, zstd;q=0"]), Some("br"), "a named q=0 beats the wildcard");
        assert_eq!(choose(&["deflate, compress"]), None, "nothing we produce");
        assert_eq!(choose(&["identity;q=0"]), None, "refusing identity alone gets identity anyway");
        assert_eq!(choose(&["gzip;q=2, br;q=abc, zstd;q=0.3"]), Some("zstd"), "bad q values are ignored");
    }

    #[test]
    fn bodiless_statuses_empty_and_small_answers_are_not_worth_compressing() {
        let worth = WorthIt { min_bytes: 1024 };
        let answer =
            |status: u16, body: axum::body::Body| axum::http::Response::builder().status(status).body(body).unwrap();
        let big = || axum::body::Body::from(vec![b'x'; 4096]);
        assert!(worth.should_compress(&answer(200, big())));
        for status in [101, 204, 304] {
            assert!(!worth.should_compress(&answer(status, big())), "{status}");
        }
        assert!(!worth.should_compress(&answer(200, axum::body::Body::empty())));
        assert!(!worth.should_compress(&answer(200, axum::body::Body::from(vec![b'x'; 1023]))));
        assert!(worth.should_compress(&answer(200, axum::body::Body::from(vec![b'x'; 1024]))));
        let pieces = axum::body::Body::from_stream(futures_util::stream::iter([Ok::<_, std::io::Error>("x")]));
        assert!(worth.should_compress(&answer(200, pieces)), "a length not known in advance");
        let zero = WorthIt { min_bytes: 0 };
        assert!(!zero.should_compress(&answer(200, axum::body::Body::empty())), "never an empty body");
    }

    fn content_encoding(values: &[&str], enabled: bool) -> Result<Option<&'static str>, u16> {
        let mut headers = HeaderMap::new();
        for v in values {
            headers.append(CONTENT_ENCODING, HeaderValue::from_str(v).unwrap());
        }
        body_coding(&headers, enabled).map_err(|e| e.status().as_u16())
    }

    #[test]
    fn request_codings_are_ours_or_refused() {
        assert_eq!(content_encoding(&[], true), Ok(None));
        assert_eq!(content_encoding(&["identity"], true), Ok(None));
        assert_eq!(content_encoding(&[" GZip "], true), Ok(Some("gzip")));
        assert_eq!(content_encoding(&["zstd"], true), Ok(Some("zstd")));
        assert_eq!(content_encoding(&["br"], true), Ok(Some("br")));
        assert_eq!(content_encoding(&["deflate"], true), Err(415));
        assert_eq!(content_encoding(&["gzip, gzip"], true), Err(415));
        assert_eq!(content_encoding(&["gzip", "br"], true), Err(415));
        assert_eq!(content_encoding(&["gzip"], false), Err(415));
        assert_eq!(content_encoding(&["identity"], false), Ok(None));
    }

    fn router(max_answers: usize) -> axum::Router {
        let config = Compression { enabled: true, min_bytes: 1024 };
        axum::Router::new()
            .route("/big", axum::routing::get(|| async { vec![b'x'; 100_000] }))
            .route("/small", axum::routing::get(|| async { vec![b'x'; 2000] }))
            .layer(responses(config))
            .layer(axum::middleware::from_fn_with_state(Gate::new(config, max_answers), negotiate))
    }

    fn get(path: &str, coding: &str) -> Request {
        Request::builder().uri(path).header(ACCEPT_ENCODING, coding).body(Body::empty()).unwrap()
    }

    fn coding_of(response: &Response) -> Option<&str> {
        response.headers().get(CONTENT_ENCODING).map(|v| v.to_str().unwrap())
    }

    #[tokio::test]
    async fn past_the_cap_answers_go_uncompressed_until_a_compressed_one_is_sent() {
        use tower::ServiceExt;
        let app = router(1);
        let first = app.clone().oneshot(get("/big", "gzip")).await.unwrap();
        assert_eq!(coding_of(&first), Some("gzip"));
        let second = app.clone().oneshot(get("/big", "gzip")).await.unwrap();
        assert_eq!(coding_of(&second), None, "the one compressor is busy: sent as it is");
        assert_eq!(axum::body::to_bytes(second.into_body(), usize::MAX).await.unwrap().len(), 100_000);
        axum::body::to_bytes(first.into_body(), usize::MAX).await.unwrap();
        let third = app.clone().oneshot(get("/big", "zstd")).await.unwrap();
        assert_eq!(coding_of(&third), Some("zstd"), "the first was sent: its compressor is free again");
        drop(third);
        let small = app.clone().oneshot(get("/small", "br")).await.unwrap();
        assert_eq!(coding_of(&small), Some("br"), "small answers asking for br get it (at quality 1)");
    }

    fn negotiated(coding: &str) -> HeaderMap {
        let mut headers = HeaderMap::new();
        headers.insert(ACCEPT_ENCODING, HeaderValue::from_str(coding).unwrap());
        headers
    }

    #[test]
    fn an_answer_is_priced_at_the_level_its_size_gets() {
        let at = |coding, level| Some(price::Compression { coding, level });
        let of = |coding: &str, bound| AnswerCoding::of(&negotiated(coding), 1024).at(bound);
        assert_eq!(of("zstd", 10_000), at(Coding::Zstd, 3), "small answers at the usual level");
        assert_eq!(of("gzip", 10_000), at(Coding::Gzip, 6));
        assert_eq!(of("br", 10_000), at(Coding::Br, 1), "br always at quality 1");
        assert_eq!(of("zstd", SMALL_ANSWER_BYTES), at(Coding::Zstd, 1), "large ones at level 1");
        assert_eq!(of("gzip", 1 << 20), at(Coding::Gzip, 1));
        assert_eq!(of("br", 1023), None, "under compression_min_bytes: sent as it is");
        assert_eq!(AnswerCoding::of(&HeaderMap::new(), 1024).at(1 << 20), None, "nothing negotiated");
        assert_eq!(AnswerCoding::default().at(1 << 20), None);
        assert_eq!(of("identity", 1 << 20), None);
    }

    #[test]
    fn compressing_is_priced_by_coding_level_and_bytes() {
        use crate::work::price::compression;
        const MB: u64 = 1_000_000;
        assert_eq!(compression(None, MB), 0);
        let price = |coding, level| compression(Some(price::Compression { coding, level }), MB);
        // The measured order (BENCHMARKS.md, “Compression”).
        assert!(price(Coding::Zstd, 1) < price(Coding::Gzip, 1) && price(Coding::Gzip, 1) < price(Coding::Br, 1));
        assert!(price(Coding::Br, 1) < price(Coding::Gzip, 6) && price(Coding::Gzip, 6) < price(Coding::Br, 4));
        assert!(price(Coding::Br, 4) < price(Coding::Br, 11));
        // 14 ns a byte at br 1: 14 ms a megabyte, 1,400,000 units of 10 ns.
        assert_eq!(price(Coding::Br, 1), 1_400_000);
        let gzip = Some(price::Compression { coding: Coding::Gzip, level: 1 });
        assert_eq!(compression(gzip, 3 * MB), 3 * price(Coding::Gzip, 1));
        assert_eq!(compression(gzip, 1), 1, "any compressed byte costs something");
        assert!(state_bytes("br", 1) < state_bytes("gzip", 6) && state_bytes("br", 4) > 32 << 20);
    }
}
