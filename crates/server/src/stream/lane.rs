//! A viewer's lane: what makes a shared frame this viewer's (its own
//! `dropped`, a compact key frame or layout it has not had yet), and, for a
//! broadcast's WebSocket viewer, the way its broadcast's fan-out writes
//! frames to its socket itself (`fanout`).
//!
//! A viewer's task takes its frames from its playback's channel and sends
//! them. A broadcast WebSocket viewer whose socket has nothing unsent and
//! whose channel holds no frame it has not seen **parks** its lane: from
//! then on its broadcast's fan-out writes each frame to its socket (one
//! non-blocking write of the whole frame, `dropped` patched as its task
//! would) and the task sleeps until a control, a ping or the fan-out wakes
//! it. The fan-out hands the lane back — unparks it and wakes the task —
//! whenever a frame needs more than that: the socket did not take it
//! whole (the task drains the rest, and is a slow viewer as before), a
//! compact key frame or layout this viewer has not had, the end. The task
//! then reads its channel again, skipping the frames the fan-out wrote
//! (their `seq` is not newer than its last), so a viewer's frames, losses
//! and closes are the same whichever of the two sent them.

use std::sync::{Arc, Mutex, MutexGuard};
use std::task::{Context, Poll};

use bytes::Bytes;
use futures_util::task::AtomicWaker;

use super::encode::{Encoded, Encoding, Names};

/// A frame as this stream's client must receive it.
#[derive(Debug, Clone, PartialEq)]
pub struct Delivered {
    pub seq: u64,
    /// Ticks skipped since this client's previous frame.
    pub dropped: u64,
    pub clip_time: f32,
    pub bytes: Bytes,
    /// Compact frames: the key frame this delta frame is relative to, sent
    /// before it because this viewer missed it (docs/compact-frames.md).
    pub prelude: Option<Bytes>,
    /// Compact frames: a new layout (docs/compact-frames.md, "A new
    /// layout") to send before them, with the `seq` of the first frame in
    /// it (the prelude's, else this frame's).
    pub layout: Option<(u64, Arc<str>)>,
}

/// What one viewer has been sent: the state its own `dropped`, key frames
/// and layouts are reckoned from.
pub(crate) struct Delivery {
    /// A broadcast viewer: its first frame has `dropped` 0.
    broadcast: bool,
    last_seq: Option<u64>,
    /// Compact frames: the last key frame this viewer was sent.
    last_key: Option<u64>,
    /// Compact frames: the layout this viewer was last sent (at first, its
    /// `opened` message's).
    layout: Option<Arc<str>>,
    delivered: u64,
    /// `inbetween_stream_frames_total` and `…_dropped_total`, all viewers.
    sent: metrics::Counter,
    dropped: metrics::Counter,
}

impl Delivery {
    pub(crate) fn new(broadcast: bool, layout: Option<Arc<str>>) -> Self {
        Delivery {
            broadcast,
            last_seq: None,
            last_key: None,
            layout,
            delivered: 0,
            sent: metrics::counter!("inbetween_stream_frames_total"),
            dropped: metrics::counter!("inbetween_stream_frames_dropped_total"),
        }
    }

    pub(crate) fn last_seq(&self) -> Option<u64> {
        self.last_seq
    }

    pub(crate) fn delivered(&self) -> u64 {
        self.delivered
    }

    /// `frame` as this viewer gets it (`names`: a protobuf viewer's first
    /// frame carries the joint names), or `None` if it had it already.
    pub(crate) fn deliver(&mut self, frame: &Encoded, names: Option<&Names>) -> Option<Delivered> {
        if self.last_seq.is_some_and(|last| frame.seq <= last) {
            return None;
        }
        // A broadcast viewer's first frame is the tick after it joined:
        // the ticks before were not its losses.
        let first_dropped = if self.broadcast { 0 } else { frame.seq };
        let mut first_seq = frame.seq;
        let prelude = self.missed_key(frame).map(|key| {
            let dropped = self.last_seq.map_or(first_dropped.min(key.seq), |last| key.seq - last - 1);
            self.last_seq = Some(key.seq);
            first_seq = key.seq;
            key.for_viewer(dropped, None)
        });
        let layout = self.new_layout(frame).map(|doc| (first_seq, doc));
        let dropped = self.last_seq.map_or(first_dropped, |last| frame.seq - last - 1);
        if let Some(key) = frame.key_seq {
            self.last_key = Some(key);
        }
        let bytes = frame.for_viewer(dropped, names);
        self.last_seq = Some(frame.seq);
        self.delivered += 1;
        self.sent.increment(1);
        if dropped > 0 {
            self.dropped.increment(dropped);
        }
        Some(Delivered { seq: frame.seq, dropped, clip_time: frame.clip_time, bytes, prelude, layout })
    }

    /// Whether `frame` reaches this viewer as its own bytes alone: not its
    /// first frame, nor one that needs a key frame or layout sent first.
    fn plain(&self, frame: &Encoded) -> bool {
        let layout_had = |doc: &Arc<str>| self.layout.as_ref().is_some_and(|had| Arc::ptr_eq(had, doc) || had == doc);
        self.last_seq.is_some() && self.missed_key(frame).is_none() && frame.layout.as_ref().is_none_or(layout_had)
    }

    /// A compact frame's layout, when this viewer was last sent another.
    fn new_layout(&mut self, frame: &Encoded) -> Option<Arc<str>> {
        let doc = frame.layout.as_ref()?;
        if self.layout.as_ref().is_some_and(|had| Arc::ptr_eq(had, doc)) {
            return None;
        }
        // A broadcast viewer's layout may be an equal copy of the one encoded.
        let same = self.layout.as_ref().is_some_and(|had| had == doc);
        self.layout = Some(Arc::clone(doc));
        (!same).then(|| Arc::clone(doc))
    }

    /// A compact delta frame's key frame, when this viewer has not had it.
    fn missed_key(&self, frame: &Encoded) -> Option<Arc<Encoded>> {
        frame
            .key
            .as_ref()
            .filter(|key| self.last_key != Some(key.seq) && self.last_seq.is_none_or(|l| l < key.seq))
            .cloned()
    }
}

/// How a socket took a frame offered for a direct write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direct {
    /// Written whole.
    Written,
    /// Taken, but only partly written: the rest waits in the socket's own
    /// queue for its task to write.
    Partly,
    /// Not taken: the socket still has bytes waiting before it.
    Busy,
    /// Not taken: the connection failed.
    Failed,
}

/// A socket's write side that another task may write whole frames to,
/// without waiting: the server's WebSocket (`server::rest::socket`).
pub trait DirectWrite: Send + Sync {
    /// Writes a frame of `encoding` whose payload `frame` makes, now, if
    /// nothing waits to be written before it (else `frame` is not called).
    fn try_frame(&self, encoding: Encoding, frame: &mut dyn FnMut() -> Bytes) -> Direct;

    /// Whether nothing waits to be written.
    fn idle(&self) -> bool;
}

/// A viewer's delivery, and for a broadcast WebSocket viewer its direct
/// writer and whether its lane is parked (see the module doc).
pub(crate) struct Lane {
    state: Mutex<LaneState>,
    /// The viewer's task, woken when the lane is handed back.
    task: AtomicWaker,
}

pub(crate) struct LaneState {
    pub delivery: Delivery,
    encoding: Encoding,
    writer: Option<Arc<dyn DirectWrite>>,
    parked: bool,
}

/// What became of a frame offered to a lane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Offered {
    /// Written to its socket whole.
    Written,
    /// Not for the fan-out: the lane is not parked, or had the frame.
    Passed,
    /// The lane went back to its task (see the module doc).
    HandedBack,
    /// Its viewer has gone: forget the lane.
    Gone,
}

impl Lane {
    pub(crate) fn new(delivery: Delivery, encoding: Encoding) -> Arc<Self> {
        let state = LaneState { delivery, encoding, writer: None, parked: false };
        Arc::new(Lane { state: Mutex::new(state), task: AtomicWaker::new() })
    }

    pub(crate) fn lock(&self) -> MutexGuard<'_, LaneState> {
        crate::sync::lock(&self.state)
    }

    /// Gives the lane its socket's direct writer.
    pub(crate) fn attach(&self, writer: Arc<dyn DirectWrite>) {
        self.lock().writer = Some(writer);
    }

    /// Its viewer has gone: the writer (its connection) is let go now, and
    /// the fan-out forgets the lane at its next frame.
    pub(crate) fn detach(&self) {
        let mut state = self.lock();
        state.writer = None;
        state.parked = false;
    }

    /// Parks the lane if it may be (see the module doc): it has a writer
    /// with nothing unsent, it was sent a frame, and `caught_up` (its
    /// channel holds nothing it has not seen). Returns whether it is parked.
    pub(crate) fn park(&self, caught_up: impl FnOnce() -> bool) -> bool {
        let mut state = self.lock();
        if !state.parked {
            let idle = state.writer.as_ref().is_some_and(|w| w.idle());
            state.parked = idle && state.delivery.last_seq.is_some() && caught_up();
        }
        state.parked
    }

    /// Takes the lane back from the fan-out (its task sends from now on).
    pub(crate) fn unpark(&self) {
        self.lock().parked = false;
    }

    /// Ready once the fan-out has handed the lane back.
    pub(crate) fn poll_unparked(&self, cx: &mut Context<'_>) -> Poll<()> {
        self.task.register(cx.waker());
        if self.lock().parked { Poll::Pending } else { Poll::Ready(()) }
    }

    /// Hands the lane back to its task and wakes it.
    pub(crate) fn hand_back(&self) {
        self.unpark();
        self.task.wake();
    }

    /// The fan-out's offer of `frame`: written to the socket if the lane is
    /// parked and the frame is plain for it; handed back to the task if it
    /// needs the task (see the module doc).
    pub(crate) fn offer(&self, frame: &Encoded) -> Offered {
        let mut state = self.lock();
        let LaneState { delivery, encoding, writer, parked } = &mut *state;
        let Some(writer) = writer else { return Offered::Gone };
        if !*parked || delivery.last_seq.is_some_and(|last| frame.seq <= last) {
            return Offered::Passed;
        }
        let taken = delivery.plain(frame).then(|| {
            let mut bytes = || delivery.deliver(frame, None).expect("a newer frame is delivered").bytes;
            writer.try_frame(*encoding, &mut bytes)
        });
        if taken == Some(Direct::Written) {
            return Offered::Written;
        }
        *parked = false;
        drop(state);
        self.task.wake();
        Offered::HandedBack
    }
}
