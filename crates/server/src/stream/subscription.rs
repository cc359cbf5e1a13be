//! A [`Subscription`]: one stream as its transport sees it — the frames of
//! its playback, with its own `dropped` count and frame limit, and the way
//! to send it controls.

use std::sync::Arc;

use tokio::sync::{broadcast, mpsc, oneshot, watch};

use super::control::{Control, ControlCheck, ControlError, Queued};
use super::encode::Encoding;
use super::fanout::Fanout;
use super::hub::{self, EndReason, Hub, Item};
use super::lane::{Delivered, Delivery, DirectWrite, Lane};
use super::limits::StreamPermit;
use super::params::StreamParams;
use super::playhead::Playhead;
use super::schedule::{Grid, Schedule};

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
    broadcast: Option<Option<Arc<dyn ControlSink>>>,
    /// This viewer's broadcast controls whose store writes are under way,
    /// until its transport takes them ([`Subscription::storing`]).
    storing: Vec<StoreOutcome>,
    check: ControlCheck,
    /// The engine's shutdown flag, for a playback this viewer forks.
    shutdown: watch::Receiver<bool>,
    /// What this viewer has been sent, shared with its broadcast's fan-out
    /// once its transport attaches a direct writer (`lane`).
    lane: Arc<Lane>,
    /// A broadcast viewer's fan-out, which its lane joins when attached.
    fanout: Option<Arc<Fanout>>,
    stopped: bool,
    _permit: StreamPermit,
}

impl std::fmt::Debug for Subscription {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Subscription")
            .field("identity", &self.params.identity)
            .field("last_seq", &self.lane.lock().delivery.last_seq())
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
    /// A broadcast's frames of one encoding, where this viewer's controls
    /// go (`None`: it may not control), and the channel's fan-out (`None`:
    /// the broadcast had ended).
    Broadcast { rx: broadcast::Receiver<Item>, controls: Option<Arc<dyn ControlSink>>, fanout: Option<Arc<Fanout>> },
}

impl Subscription {
    pub(crate) fn new(
        params: StreamParams,
        schedule: Schedule,
        source: Source,
        shutdown: watch::Receiver<bool>,
        permit: StreamPermit,
    ) -> Self {
        let (mut broadcast, mut fanout) = (None, None);
        let (rx, driver, handback, controls) = match source {
            Source::Shared { rx, handback } => (rx, None, handback, None),
            Source::Private { hub, rx, controls } => (rx, Some(hub), None, Some(controls)),
            Source::Broadcast { rx, controls, fanout: f } => {
                (broadcast, fanout) = (Some(controls), f);
                (rx, None, None, None)
            }
        };
        let layout = params.compact.as_ref().map(|c| Arc::clone(&c.document));
        let lane = Lane::new(Delivery::new(broadcast.is_some(), layout), params.encoding);
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
            lane,
            fanout,
            stopped: false,
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
        if self.params.max_frames.is_some_and(|max| self.lane.lock().delivery.delivered() >= max) {
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
            let mut lane = self.lane.lock();
            // The names of the joints frames carry, on a protobuf viewer's
            // first frame (made then: kept, they cost every viewer ~1 KiB).
            let first_pb = lane.delivery.last_seq().is_none() && self.params.encoding == Encoding::Protobuf;
            let names = first_pb.then(|| self.params.names());
            if let Some(delivered) = lane.delivery.deliver(&frame, names.as_ref()) {
                return Next::Frame(delivered);
            }
        }
    }

    /// Lets its broadcast's fan-out write this viewer's frames through
    /// `writer` while its lane is parked ([`Subscription::park`]). Returns
    /// whether it does (`false`: not a broadcast's viewer, or it had ended).
    pub(crate) fn attach(&mut self, writer: Arc<dyn DirectWrite>) -> bool {
        let Some(fanout) = &self.fanout else { return false };
        self.lane.attach(writer);
        fanout.join(Arc::clone(&self.lane));
        true
    }

    /// Parks this viewer's lane if it may be (`lane`): its transport then
    /// waits for [`Subscription::unparked`] instead of [`Subscription::next`].
    /// Returns whether it is parked.
    pub(crate) fn park(&mut self) -> bool {
        if self.stopped || self.fanout.is_none() {
            self.lane.unpark();
            return false;
        }
        let rx = &self.rx;
        self.lane.park(|| rx.is_empty())
    }

    /// Resolves once the fan-out has handed the lane back. Cancel-safe.
    pub(crate) async fn unparked(&mut self) {
        std::future::poll_fn(|cx| self.lane.poll_unparked(cx)).await;
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
        let last_seq = self.lane.lock().delivery.last_seq();
        let next = last_seq.map_or(0, |last| last + 1);
        let playhead = Playhead::new(p.start, p.speed, p.fps, p.paused);
        let prev_time = last_seq.map(|last| playhead.time_at(last));
        let schedule = self.schedule.resumed_at(next);
        let (mut hub, rx, tx) = hub::private(p, schedule, self.shutdown.clone());
        hub.resume(prev_time, last_seq.is_none());
        // The shared playback goes on for its other viewers (or, if this
        // viewer drove it alone, ends here).
        self.rx = rx;
        self.handback = None;
        self.driver = Some(hub);
        self.controls = Some(tx);
    }
}

impl Drop for Subscription {
    fn drop(&mut self) {
        // Its connection is let go now, not at the fan-out's next frame.
        self.lane.detach();
    }
}
