//! The gRPC side of a stream: a [`Subscription`] as the response stream of
//! `StreamFrames` and `Play`. Compact frames travel as `Frame.compact`
//! bytes, the layout document in the first frame's `compact_layout`, and a
//! new layout (docs/compact-frames.md) in the `compact_layout` of the first
//! frame in it, a key frame.
//!
//! The stream is polled by tonic only when the client's HTTP/2 window has
//! room, so a client that stops reading simply stops polling; its playback
//! keeps its schedule and the subscription's bounded buffer drops the
//! oldest frames. No task per stream: the subscription *is* the stream.

use std::sync::Arc;

use bytes::{BufMut, BytesMut};
use futures_util::Stream;
use prost::encoding::{WireType, encode_key, encode_varint, encoded_len_varint};
use tonic::Status;

use super::encode::Encoding;
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
    let layout = sub.params().compact.as_ref().map(|c| Arc::clone(&c.document));
    let state = (Some(sub), layout, None::<WireFrame>);
    futures_util::stream::unfold(state, |(sub, mut layout, pending)| async move {
        let mut sub = sub?;
        if let Some(frame) = pending {
            return Some((Ok(frame), (Some(sub), layout, None)));
        }
        match crate::panics::guarded("grpc_stream", sub.next()).await {
            Some(Next::Frame(f)) if sub.encoding() == Encoding::Compact => {
                // The layout rides on the first frame (a new one on the first
                // in it); a key frame the viewer missed goes first.
                let opened = layout.take();
                let layout = f.layout.map(|(_, doc)| doc).or(opened);
                let (first, then) = match f.prelude {
                    Some(key) => (compact_frame(&key, layout), Some(compact_frame(&f.bytes, None))),
                    None => (compact_frame(&f.bytes, layout), None),
                };
                Some((Ok(first), (Some(sub), None, then)))
            }
            Some(Next::Frame(f)) => Some((Ok(WireFrame(f.bytes)), (Some(sub), layout, None))),
            Some(Next::End(reason)) => end_status(reason).map(|status| (Err(status), (None, None, None))),
            None => Some((Err(Status::internal("the stream failed")), (None, None, None))),
        }
    })
}

/// A compact frame as a `Frame` message: its bytes in `compact` (field 7),
/// and the layout document in `compact_layout` (field 8) on the first in it.
fn compact_frame(bytes: &[u8], layout: Option<Arc<str>>) -> WireFrame {
    let layout_len = layout.as_ref().map_or(0, |l| 1 + encoded_len_varint(l.len() as u64) + l.len());
    let mut out = BytesMut::with_capacity(1 + encoded_len_varint(bytes.len() as u64) + bytes.len() + layout_len);
    encode_key(7, WireType::LengthDelimited, &mut out);
    encode_varint(bytes.len() as u64, &mut out);
    out.put_slice(bytes);
    if let Some(layout) = layout {
        encode_key(8, WireType::LengthDelimited, &mut out);
        encode_varint(layout.len() as u64, &mut out);
        out.put_slice(layout.as_bytes());
    }
    WireFrame(out.freeze())
}
