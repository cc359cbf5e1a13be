//! The gRPC side of a stream: a [`Subscription`] as the response stream of
//! `StreamFrames` and `Play`.
//!
//! The stream is polled by tonic only when the client's HTTP/2 window has
//! room, so a client that stops reading simply stops polling; its playback
//! keeps its schedule and the subscription's bounded buffer drops the
//! oldest frames. No task per stream: the subscription *is* the stream.

use futures_util::Stream;
use tonic::Status;

use super::hub::EndReason;
use super::subscription::{Next, Subscription};
use formats::wire::frame::WireFrame;

/// Why a broadcast's viewers were ended for its work.
pub const TOO_MUCH_WORK: &str = "the broadcast's ticks took far more CPU than its price; it was ended";

/// The status a stream ends with, or `None` for a clean OK.
pub fn end_status(reason: EndReason) -> Option<Status> {
    match reason {
        EndReason::MaxFrames | EndReason::Stopped | EndReason::Ended => None,
        EndReason::Shutdown => Some(Status::unavailable("the server is shutting down; reconnect to resume")),
        EndReason::Failed => Some(Status::internal("the stream failed")),
        EndReason::TooMuchWork => {
            let mut status = Status::resource_exhausted(format!("too_much_work: {TOO_MUCH_WORK}"));
            status.metadata_mut().insert("x-error-code", tonic::metadata::MetadataValue::from_static("too_much_work"));
            Some(status)
        }
    }
}

/// The frames of `sub` until it ends; ends with OK after `max_frames` or a
/// `stop`, with UNAVAILABLE at shutdown.
/// A panic while producing a frame is counted and ends the stream with
/// INTERNAL instead of taking the HTTP/2 connection down.
pub fn frames(sub: Subscription) -> impl Stream<Item = Result<WireFrame, Status>> + Send + 'static {
    futures_util::stream::unfold(Some(sub), |sub| async move {
        let mut sub = sub?;
        match crate::panics::guarded("grpc_stream", sub.next()).await {
            Some(Next::Frame(f)) => Some((Ok(WireFrame(f.bytes)), Some(sub))),
            Some(Next::End(reason)) => end_status(reason).map(|status| (Err(status), None)),
            None => Some((Err(Status::internal("the stream failed")), None)),
        }
    })
}
