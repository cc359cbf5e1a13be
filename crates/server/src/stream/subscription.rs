//! A [`Subscription`]: one stream as its transport sees it — the frames of
//! its playback, with its own `dropped` count and frame limit, and the way
//! to send it controls.

use bytes::Bytes;
use tokio::sync::{broadcast, mpsc, oneshot, watch};

use super::control::{Control, ControlCheck, ControlError, Queued};
use super::encode::Encoding;
use super::hub::{self, EndReason, Hub, Item};
use super::limits::StreamPermit;
use super::params::StreamParams;
use super::playhead::Playhead;
use super::schedule::{Grid, Schedule};

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
    pub layout: Option<(u64, std::sync::Arc<str>)>,
}

/// The next thing to send.
#[derive(Debug, Clone, PartialEq)]
pub enum Next {
    Frame(Delivered),
    End(EndReason),
}

/// Where a broadcast viewer's controls go (the broadcast, which stamps
/// each with the tick it applies from, or the server's gate in front of
/// it). Defined here, implemented by the broadcast, so that a subscription
/// never imports it.
pub(crate) trait ControlSink: Send + Sync {
    /// Queues `control` for every viewer. Its store write may still fail
    /// (the control is then withdrawn): the receiver, if any, then yields
    /// the refusal its sender is told; it closes without one once stored.
    fn send(&self, control: Control) -> Result<Option<StoreOutcome>, ControlError>;
}

/// A control's store write still under way: yields the refusal if it fails.
pub type StoreOutcome = oneshot::Receiver<ControlError>;

/// A sender of controls to a private playback, usable from another task
/// (gRPC `Play` reads controls and frames on different tasks).
#[derive(Debug, Clone)]
pub struct Controller {
    tx: mpsc::Sender<Queued>,
    check: ControlCheck,
}

impl Controller {
    /// Queues `control` for the next tick (once a new compact layout it
    /// needs is chosen, see [`ControlCheck::queue`]). Returns `false` if
    /// the playback has ended.
    ///
    /// # Errors
    /// An invalid control, its work refused, or too many pending.
    pub async fn send(&mut self, control: Control) -> Result<bool, ControlError> {
        match self.tx.try_send(self.check.queue(control).await?) {
            Ok(()) => Ok(true),
            Err(mpsc::error::TrySendError::Full(_)) => Err(ControlError::Busy),
            Err(mpsc::error::TrySendError::Closed(_)) => Ok(false),
        }
    }

    /// Resolves when the playback has ended.
    pub async fn closed(&self) {
        self.tx.closed().await;
    }
}

/// One stream. Dropping it leaves the playback (which ends when its last
/// viewer has gone) and frees its admission slot.
pub struct Subscription {
    params: StreamParams,
    /// The schedule the stream started on (its tick 0 and grid).
    schedule: Schedule,
    rx: broadcast::Receiver<Item>,
    /// The playback this viewer drives itself (see `hub`): a private one,
    /// or a shared one nobody joined. `None`: it reads `rx`.
    driver: Option<Box<Hub>>,
    /// Where a shared playback this viewer started comes back to it after
    /// its first tick if nobody else joined.
    handback: Option<oneshot::Receiver<Box<Hub>>>,
    controls: Option<mpsc::Sender<Queued>>,
    /// A broadcast viewer (docs/broadcasts.md): its first frame has `dropped` 0, and
    /// its controls go to the broadcast (`Some(None)`: a read-only viewer,
    /// whose controls are refused), never into a fork.
    broadcast: Option<Option<std::sync::Arc<dyn ControlSink>>>,
    /// This viewer's broadcast controls whose store writes are under way,
    /// until its transport takes them ([`Subscription::storing`]).
    storing: Vec<StoreOutcome>,
    check: ControlCheck,
    /// The engine's shutdown flag, for a playback this viewer forks.
    shutdown: watch::Receiver<bool>,
    last_seq: Option<u64>,
    /// Compact frames: the last key frame this viewer was sent.
    last_key: Option<u64>,
    /// Compact frames: the layout this viewer was last sent (at first, its
    /// `opened` message's).
    layout: Option<std::sync::Arc<str>>,
    delivered: u64,
    stopped: bool,
    /// `inbetween_stream_frames_total` and `…_dropped_total`, all viewers.
    sent: metrics::Counter,
    dropped: metrics::Counter,
    _permit: StreamPermit,
}

impl std::fmt::Debug for Subscription {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Subscription")
            .field("identity", &self.params.identity)
            .field("last_seq", &self.last_seq)
            .field("delivered", &self.delivered)
            .field("private", &self.controls.is_some())
            .finish_non_exhaustive()
    }
}

/// Where a new subscription's frames come from.
pub(crate) enum Source {
    /// A shared playback's broadcast, and the channel it comes back on if
    /// this viewer started it and nobody joins (see `hub`).
    Shared { rx: broadcast::Receiver<Item>, handback: Option<oneshot::Receiver<Box<Hub>>> },
    /// A private playback for this viewer to drive, and its controls.
    Private { hub: Box<Hub>, rx: broadcast::Receiver<Item>, controls: mpsc::Sender<Queued> },
    /// A broadcast's frames of one encoding, and where this viewer's
    /// controls go (`None`: it may not control).
    Broadcast { rx: broadcast::Receiver<Item>, controls: Option<std::sync::Arc<dyn ControlSink>> },
}

impl Subscription {
    pub(crate) fn new(
        params: StreamParams,
        schedule: Schedule,
        source: Source,
        shutdown: watch::Receiver<bool>,
        permit: StreamPermit,
    ) -> Self {
        let mut broadcast = None;
        let (rx, driver, handback, controls) = match source {
            Source::Shared { rx, handback } => (rx, None, handback, None),
            Source::Private { hub, rx, controls } => (rx, Some(hub), None, Some(controls)),
            Source::Broadcast { rx, controls } => {
                broadcast = Some(controls);
                (rx, None, None, None)
            }
        };
        let layout = params.compact.as_ref().map(|c| std::sync::Arc::clone(&c.document));
        Subscription {
            check: ControlCheck::new(&params).priced_by(permit.repricing()),
            params,
            schedule,
            rx,
            driver,
            handback,
            controls,
            broadcast,
            storing: Vec::new(),
            shutdown,
            last_seq: None,
            last_key: None,
            layout,
            delivered: 0,
            stopped: false,
            sent: metrics::counter!("inbetween_stream_frames_total"),
            dropped: metrics::counter!("inbetween_stream_frames_dropped_total"),
            _permit: permit,
        }
    }

    pub fn params(&self) -> &StreamParams {
        &self.params
    }

    pub fn encoding(&self) -> Encoding {
        self.params.encoding
    }

    /// The grid this stream's ticks sit on.
    pub fn grid(&self) -> Grid {
        self.schedule.grid()
    }

    /// The grid tick of this stream's frame 0 (frame `seq` is due at
    /// `grid().at(first_tick() + seq)`).
    pub fn first_tick(&self) -> u64 {
        self.schedule.first()
    }

    /// Waits for the next frame or the end. Cancel-safe.
    pub async fn next(&mut self) -> Next {
        if self.stopped {
            return Next::End(EndReason::Stopped);
        }
        if self.params.max_frames.is_some_and(|max| self.delivered >= max) {
            return Next::End(EndReason::MaxFrames);
        }
        loop {
            let item = if let Some(hub) = self.driver.as_mut() {
                Ok(hub.step(false).await.expect("a driven playback always has its viewer"))
            } else if let Some(handback) = self.handback.as_mut() {
                tokio::select! {
                    biased;
                    item = self.rx.recv() => item,
                    hub = handback => {
                        // Alone after the first tick: drive it from now on.
                        self.handback = None;
                        self.driver = hub.ok();
                        continue;
                    }
                }
            } else {
                self.rx.recv().await
            };
            let frame = match item {
                Ok(Item::Frame(f)) => f,
                Ok(Item::End(reason)) => return Next::End(reason),
                // The missed frames show up as a gap in seq.
                Err(broadcast::error::RecvError::Lagged(_)) => continue,
                Err(broadcast::error::RecvError::Closed) => {
                    tracing::error!(clip = %self.params.clip_id, "a playback ended without a final status");
                    return Next::End(EndReason::Failed);
                }
            };
            if self.last_seq.is_some_and(|last| frame.seq <= last) {
                continue;
            }
            // A broadcast viewer's first frame is the tick after it joined:
            // the ticks before were not its losses.
            let first_dropped = if self.broadcast.is_some() { 0 } else { frame.seq };
            let mut first_seq = frame.seq;
            let prelude = self.missed_key(&frame).map(|key| {
                let dropped = self.last_seq.map_or(first_dropped.min(key.seq), |last| key.seq - last - 1);
                self.last_seq = Some(key.seq);
                first_seq = key.seq;
                key.for_viewer(dropped, None)
            });
            let layout = self.new_layout(&frame).map(|doc| (first_seq, doc));
            let dropped = self.last_seq.map_or(first_dropped, |last| frame.seq - last - 1);
            if let Some(key) = frame.key_seq {
                self.last_key = Some(key);
            }
            // The names of the joints frames carry, on a protobuf viewer's
            // first frame (made then: kept, they cost every viewer ~1 KiB).
            let first_pb = self.last_seq.is_none() && self.params.encoding == Encoding::Protobuf;
            let names = first_pb.then(|| self.params.names());
            let bytes = frame.for_viewer(dropped, names.as_ref());
            self.last_seq = Some(frame.seq);
            self.delivered += 1;
            self.sent.increment(1);
            if dropped > 0 {
                self.dropped.increment(dropped);
            }
            let clip_time = frame.clip_time;
            return Next::Frame(Delivered { seq: frame.seq, dropped, clip_time, bytes, prelude, layout });
        }
    }

    /// A compact frame's layout, when this viewer was last sent another.
    fn new_layout(&mut self, frame: &super::encode::Encoded) -> Option<std::sync::Arc<str>> {
        let doc = frame.layout.as_ref()?;
        if self.layout.as_ref().is_some_and(|had| std::sync::Arc::ptr_eq(had, doc)) {
            return None;
        }
        // A broadcast viewer's layout may be an equal copy of the one encoded.
        let same = self.layout.as_ref().is_some_and(|had| had == doc);
        self.layout = Some(std::sync::Arc::clone(doc));
        (!same).then(|| std::sync::Arc::clone(doc))
    }

    /// A compact delta frame's key frame, when this viewer has not had it.
    fn missed_key(&self, frame: &super::encode::Encoded) -> Option<std::sync::Arc<super::encode::Encoded>> {
        frame
            .key
            .as_ref()
            .filter(|key| self.last_key != Some(key.seq) && self.last_seq.is_none_or(|l| l < key.seq))
            .cloned()
    }

    /// Applies `control` at the next tick. A viewer of a shared playback
    /// first forks a private one that continues from its last frame (same
    /// schedule, same playhead), so other viewers are unaffected. `stop` on
    /// a shared viewer just ends this stream.
    ///
    /// A compact stream's control that leaves its layout waits here for
    /// the new one to be chosen ([`ControlCheck::queue`]): no frame is
    /// taken meanwhile, so the layout goes with the control, before the
    /// frame after it.
    ///
    /// # Errors
    /// An invalid control (non-finite numbers, speed beyond ±1000, a
    /// crossfade to another skeleton, a layer the motion lacks), its work
    /// refused, or too many pending.
    pub async fn control(&mut self, control: Control) -> Result<(), ControlError> {
        if let Some(sink) = &self.broadcast {
            if control == Control::Stop {
                self.stopped = true;
                return Ok(());
            }
            let storing = sink.as_ref().ok_or(ControlError::ReadOnly)?.send(control)?;
            self.storing.extend(storing);
            return Ok(());
        }
        let queued = self.check.queue(control).await?;
        if self.controls.is_none() {
            if queued.control == Control::Stop {
                self.stopped = true;
                return Ok(());
            }
            self.fork();
        }
        let tx = self.controls.as_ref().expect("forked above");
        match tx.try_send(queued) {
            Ok(()) | Err(mpsc::error::TrySendError::Closed(_)) => Ok(()),
            Err(mpsc::error::TrySendError::Full(_)) => Err(ControlError::Busy),
        }
    }

    /// The store writes of this viewer's broadcast controls sent since
    /// the last call: each yields the refusal to tell its sender if the
    /// control could not be stored (and was withdrawn).
    pub(crate) fn storing(&mut self) -> std::vec::Drain<'_, StoreOutcome> {
        self.storing.drain(..)
    }

    /// A controller for another task (private playbacks only).
    pub fn controller(&self) -> Option<Controller> {
        self.controls.as_ref().map(|tx| Controller { tx: tx.clone(), check: self.check.clone() })
    }

    fn fork(&mut self) {
        let p = &self.params;
        let next = self.last_seq.map_or(0, |last| last + 1);
        let playhead = Playhead::new(p.start, p.speed, p.fps, p.paused);
        let prev_time = self.last_seq.map(|last| playhead.time_at(last));
        let schedule = self.schedule.resumed_at(next);
        let (mut hub, rx, tx) = hub::private(p, schedule, self.shutdown.clone());
        hub.resume(prev_time, self.last_seq.is_none());
        // The shared playback goes on for its other viewers (or, if this
        // viewer drove it alone, ends here).
        self.rx = rx;
        self.handback = None;
        self.driver = Some(hub);
        self.controls = Some(tx);
    }
}
