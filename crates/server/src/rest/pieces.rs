//! Large answers, evaluated a piece at a time: the next piece is evaluated
//! (on the work pool, `server::work`) only when the client has taken the last one, so
//! the memory a request holds is a piece, not its answer, and no thread
//! waits on a slow reader. A client that goes away drops the body, and with
//! it the rest of the work (counted as abandoned), and the piece being
//! evaluated stops at its next pose. The answer's price stays charged to
//! its caller until then. Clip samples and composed samples alike: each is
//! a [`PoseWriter`].

use std::ops::Range;
use std::sync::{Arc, Mutex};

use axum::body::Body;
use axum::http::header::CONTENT_TYPE;
use axum::http::{HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use futures_util::StreamExt;

use crate::error::ApiError;
use crate::state::AppState;
use crate::sync::lock;
use crate::work::{Cancel, Ticket};

/// Bytes of JSON per piece of a streamed answer (at least one pose).
const PIECE_BYTES: u64 = 64 * 1024;

/// The poses of one answer, written on demand.
pub trait PoseWriter: Send + 'static {
    /// How many poses the answer has.
    fn count(&self) -> usize;
    /// The answer's size bound.
    fn bound(&self) -> u64;
    /// Appends poses `range`, comma-separated as inside `{"poses":[…]}`
    /// (a comma before each but pose 0). Called in order. Stops early
    /// (leaving the output unfinished) once `cancel` is raised.
    fn write(&mut self, out: &mut Vec<u8>, range: Range<usize>, cancel: &Cancel);
    /// JSON members after `"poses"` (a composed answer's `,"warnings":[…]`).
    fn trailer(&self) -> &[u8] {
        &[]
    }
}

/// A whole `{"poses":[…]}` document from `writer`, on the calling thread.
pub fn whole(writer: &mut dyn PoseWriter, cancel: &Cancel) -> Vec<u8> {
    let mut body = Vec::with_capacity(usize::try_from(writer.bound()).unwrap_or(0).min(1 << 20));
    body.extend_from_slice(b"{\"poses\":[");
    let n = writer.count();
    writer.write(&mut body, 0..n, cancel);
    body.extend_from_slice(b"]");
    body.extend_from_slice(writer.trailer());
    body.extend_from_slice(b"}");
    body
}

/// An answer being sent in pieces.
pub struct Pieces {
    state: AppState,
    /// The answer's price, charged until it is sent or dropped.
    _ticket: Ticket,
    job: Arc<Mutex<Box<dyn PoseWriter>>>,
    count: usize,
    /// Poses per piece.
    per_piece: usize,
    /// The next pose to evaluate.
    next: usize,
    done: bool,
}

impl Pieces {
    pub fn new(state: AppState, writer: Box<dyn PoseWriter>, ticket: Ticket) -> Pieces {
        let count = writer.count();
        let per_pose = writer.bound() / count.max(1) as u64;
        let per_piece = (PIECE_BYTES / per_pose.max(1)).max(1) as usize;
        Pieces { state, _ticket: ticket, job: Arc::new(Mutex::new(writer)), count, per_piece, next: 0, done: false }
    }

    /// The next piece of the document, `None` after its end.
    async fn piece(&mut self) -> Option<Result<Vec<u8>, ApiError>> {
        if self.done {
            return None;
        }
        let (n, range) = (self.count, self.next..(self.next + self.per_piece).min(self.count));
        let job = Arc::clone(&self.job);
        let render = move |cancel: &Cancel| {
            let mut out = Vec::with_capacity(PIECE_BYTES as usize + 64);
            if range.start == 0 {
                out.extend_from_slice(b"{\"poses\":[");
            }
            let mut job = lock(&job);
            job.write(&mut out, range.clone(), cancel);
            if range.end == n {
                out.extend_from_slice(b"]");
                out.extend_from_slice(job.trailer());
                out.extend_from_slice(b"}");
            }
            (out, range.len())
        };
        let deadline = self.state.config.limits.request_timeout;
        let piece = self.state.work.pool().run(deadline, render).await;
        Some(piece.map(|(out, evaluated)| {
            self.state.counters.poses.increment(evaluated as u64);
            self.next += evaluated;
            self.done = self.next == n;
            out
        }))
    }

    /// A 200 whose JSON body is these pieces, sent as the client reads them.
    /// Fused: a body may be polled again after its end (tower-http's
    /// compressor does, through its reader), and a bare `Unfold` panics then.
    pub fn into_response(self) -> Response {
        let stream = futures_util::stream::unfold(self, |mut pieces| async move {
            let piece = pieces.piece().await?;
            Some((piece, pieces))
        })
        .fuse();
        let body = Body::from_stream(stream);
        (StatusCode::OK, [(CONTENT_TYPE, HeaderValue::from_static("application/json"))], body).into_response()
    }
}

impl Drop for Pieces {
    fn drop(&mut self) {
        if !self.done {
            self.state.counters.answers_abandoned.increment(1);
            self.state.counters.poses_abandoned.increment((self.count - self.next) as u64);
        }
    }
}

/// A whole JSON answer, 200.
pub(super) fn json_response(body: Vec<u8>) -> Response {
    (StatusCode::OK, [(CONTENT_TYPE, HeaderValue::from_static("application/json"))], body).into_response()
}
