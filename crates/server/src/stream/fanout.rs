//! A broadcast channel's fan-out: the tasks that write each tick's frame to
//! the sockets of its parked WebSocket viewers (`lane`), so that a tick
//! wakes a few tasks rather than one per viewer.
//!
//! Waking every viewer's task per frame, each to take the frame from the
//! channel, patch it and write it, cost more of the server's CPU per
//! delivered frame than a plain broadcaster writing every socket from one
//! loop (BENCHMARKS.md, "Broadcasts against a Node `ws` peer"). Here the
//! lanes are split among **phases**, one per worker thread of the runtime
//! that first joined one; each phase is a task on that runtime that, per
//! frame, writes every parked lane of its share in turn (a non-blocking
//! write; whatever cannot be written at once goes back to that viewer's own
//! task, `lane`). The broadcast's task hands a frame to the phases through
//! a channel as small as a viewer's: it never waits for them, and a phase
//! that falls further behind loses its oldest frames, its viewers counting
//! them as their own `dropped`, as a slow viewer's task would. The phases
//! end with the broadcast's end (or its channel's), handing every lane back
//! so each task reads the end from its channel.
//!
//! `inbetween_broadcast_fanout_frames_total` counts the frames the phases
//! wrote, `inbetween_broadcast_fanout_handbacks_total` the lanes they
//! handed back.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use tokio::sync::broadcast;

use super::encode::Encoded;
use super::hub::Item;
use super::lane::{Lane, Offered};

/// Phases of one fan-out, at most.
const MAX_PHASES: usize = 16;

/// Lanes a phase writes before it lets its worker's other tasks run.
const YIELD_EVERY: usize = 256;

/// The fan-out of one broadcast channel (an encoding, or a compact layout).
pub(crate) struct Fanout {
    frames: broadcast::Sender<Item>,
    /// Started when the first lane joins.
    phases: OnceLock<Vec<Arc<Phase>>>,
    joined: AtomicUsize,
}

/// One phase's lanes.
struct Phase {
    lanes: Mutex<Vec<Arc<Lane>>>,
}

impl Fanout {
    /// A fan-out whose phases keep up to `buffer` frames each.
    pub(crate) fn new(buffer: usize) -> Self {
        Fanout { frames: broadcast::channel(buffer).0, phases: OnceLock::new(), joined: AtomicUsize::new(0) }
    }

    /// Hands `item` to the phases (none before a lane joined). Never waits.
    pub(crate) fn publish(&self, item: &Item) {
        if self.phases.get().is_some() {
            // An error only means every phase has ended.
            let _ = self.frames.send(item.clone());
        }
    }

    /// Adds `lane` to a phase, starting the phases on the current runtime
    /// if it is the first.
    pub(crate) fn join(&self, lane: Arc<Lane>) {
        let phases = self.phases.get_or_init(|| {
            let runtime = tokio::runtime::Handle::current();
            let count = runtime.metrics().num_workers().clamp(1, MAX_PHASES);
            let phases: Vec<_> = (0..count).map(|_| Arc::new(Phase { lanes: Mutex::new(Vec::new()) })).collect();
            for phase in &phases {
                drop(runtime.spawn(Arc::clone(phase).run(self.frames.subscribe())));
            }
            phases
        });
        let at = self.joined.fetch_add(1, Ordering::Relaxed) % phases.len();
        crate::sync::lock(&phases[at].lanes).push(lane);
    }
}

impl Phase {
    async fn run(self: Arc<Self>, mut frames: broadcast::Receiver<Item>) {
        let written = metrics::counter!("inbetween_broadcast_fanout_frames_total");
        let handed_back = metrics::counter!("inbetween_broadcast_fanout_handbacks_total");
        loop {
            match frames.recv().await {
                Ok(Item::Frame(frame)) => {
                    let (w, h) = self.offer(&frame).await;
                    written.increment(w);
                    handed_back.increment(h);
                }
                // The sender gone (its channel dropped) ends the phase as its end does.
                Ok(Item::End(_)) | Err(broadcast::error::RecvError::Closed) => break,
                // Its lanes count the frames missed as their own `dropped`.
                Err(broadcast::error::RecvError::Lagged(_)) => {}
            }
        }
        for lane in std::mem::take(&mut *crate::sync::lock(&self.lanes)) {
            lane.hand_back();
        }
    }

    /// Offers `frame` to each lane, forgetting those whose viewers left,
    /// and lets the worker's other tasks run every [`YIELD_EVERY`] lanes;
    /// returns the lanes written and handed back. The lanes are taken out
    /// meanwhile, so a viewer joining never waits for the writes.
    async fn offer(&self, frame: &Encoded) -> (u64, u64) {
        let mut lanes = std::mem::take(&mut *crate::sync::lock(&self.lanes));
        let (mut gone, mut written, mut handed_back) = (Vec::new(), 0, 0);
        for (at, lane) in lanes.iter().enumerate() {
            if at % YIELD_EVERY == YIELD_EVERY - 1 {
                tokio::task::yield_now().await;
            }
            match lane.offer(frame) {
                Offered::Written => written += 1,
                Offered::HandedBack => handed_back += 1,
                Offered::Passed => {}
                Offered::Gone => gone.push(at),
            }
        }
        for at in gone.into_iter().rev() {
            lanes.swap_remove(at);
        }
        let mut now = crate::sync::lock(&self.lanes);
        lanes.append(&mut now);
        *now = lanes;
        (written, handed_back)
    }
}
