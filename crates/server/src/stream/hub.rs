//! A playback: at each tick of its schedule it evaluates the pose once,
//! encodes it once and publishes the bytes to its viewers (or hands them to
//! its one viewer directly; see below).
//!
//! Viewers receive through a `tokio::sync::broadcast` channel of a few
//! frames. Publishing never waits: when a viewer falls behind, the channel
//! overwrites its oldest frames, and the viewer later learns how many it
//! missed (its `dropped`). A stalled viewer therefore costs a fixed amount
//! of memory and never slows the others. A playback sleeps on the tick timer
//! (`ticker`) between ticks (no busy loop), holds no lock across an await, and
//! reuses its sampler, event and encoding buffers, so a tick allocates only
//! the bytes it sends.
//!
//! It ends when it has no viewers left (checked each tick), on a `stop`
//! control, or at shutdown, publishing a final [`EndReason`] that even a
//! lagging viewer receives (the last item of a broadcast is never dropped).
//!
//! Most playbacks have one viewer (every private one, and every shared one
//! that nobody joined before its first tick). Such a playback needs no task
//! of its own: its viewer's [`Subscription`](super::Subscription) drives it
//! with [`Hub::step`] and takes each frame directly, saving a task wake-up
//! and a channel hand-over per frame. A shared playback runs as its own
//! task until its first tick (so a viewer that joins is never at the mercy
//! of how often the first one is polled); if by then it has one viewer, it
//! hands itself to that viewer and the task ends.

use std::future::Future;
use std::pin::Pin;
use std::time::{SystemTime, UNIX_EPOCH};

use tokio::sync::{broadcast, mpsc, oneshot, watch};

use super::control::{Applied, Queued, Refused};
use super::encode::{Encoded, Encoding, FrameData, FrameEncoder};
use super::events::crossed;
use super::params::StreamParams;
use super::playhead::Playhead;
use super::registry::Listing;
use super::schedule::{CatchUp, Schedule};
use std::sync::Arc;

use super::pinned::StreamMotion;
use anim::motion::{MotionOptions, Player};

use super::graph::GraphDeck;
use super::pinned::StreamPlayer;
use formats::wire::json::ParameterValues;

/// Why a stream ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndReason {
    /// `max_frames` frames were delivered.
    MaxFrames,
    /// The client sent `stop`.
    Stopped,
    /// The server is shutting down.
    Shutdown,
    /// The broadcast watched was deleted or ended (docs/broadcasts.md).
    Ended,
    /// The broadcast watched ended because its ticks took far more CPU
    /// than its price (docs/broadcasts.md, "Work").
    TooMuchWork,
    /// The playback ended unexpectedly (a bug; logged).
    Failed,
}

/// What a playback publishes.
#[derive(Debug, Clone)]
pub enum Item {
    Frame(Encoded),
    End(EndReason),
}

pub(crate) struct Hub {
    params: StreamParams,
    schedule: Schedule,
    playhead: Playhead,
    player: StreamPlayer,
    /// A graph stream's graph, played in place of `player`'s motion.
    graph: Option<GraphDeck>,
    /// The current motion's first-layer position at the previous frame
    /// (for the events crossed), and which motion that was.
    prev: Option<(f64, Arc<StreamMotion>)>,
    crossed: Vec<u32>,
    encoder: FrameEncoder,
    with_names: bool,
    tx: broadcast::Sender<Item>,
    controls: Option<mpsc::Receiver<Queued>>,
    /// A shared playback's entry in the registry, dropped (unlisting it)
    /// before its first tick.
    listing: Option<Listing<Item>>,
    /// Where to hand the playback after its first tick if it has one viewer.
    handback: Option<oneshot::Sender<Box<Hub>>>,
    /// Resolves at shutdown; one future for the playback's life, so it
    /// registers with the watch channel once, not on every tick. `None`
    /// once it has fired.
    shutdown: Option<Pin<Box<dyn Future<Output = ()> + Send>>>,
    /// `inbetween_stream_ticks_total`: evaluated and encoded ticks (one per
    /// playback, however many viewers share it).
    ticks: metrics::Counter,
}

impl Hub {
    pub(crate) fn new(
        params: &StreamParams,
        schedule: Schedule,
        tx: broadcast::Sender<Item>,
        controls: Option<mpsc::Receiver<Queued>>,
        listing: Option<Listing<Item>>,
        shutdown: watch::Receiver<bool>,
    ) -> Self {
        metrics::counter!("inbetween_stream_playbacks_total").increment(1);
        Hub {
            playhead: Playhead::new(params.start, params.speed, params.fps, params.paused),
            params: params.clone(),
            schedule,
            player: Player::new(Arc::clone(&params.motion)),
            graph: params.graph.as_ref().map(|g| GraphDeck::new(g, params.space)),
            prev: None,
            crossed: Vec::new(),
            encoder: params.encoder(),
            with_names: params.encoding == Encoding::Protobuf,
            tx,
            controls,
            listing,
            handback: None,
            shutdown: Some(Box::pin(async move {
                let mut shutdown = shutdown;
                let _ = shutdown.wait_for(|down| *down).await;
            })),
            ticks: metrics::counter!("inbetween_stream_ticks_total"),
        }
    }

    /// Continues a playback a viewer was watching elsewhere (a fork): the
    /// stream time of its last frame, and whether it still needs the names.
    /// A fork is of a playback nobody controlled, so its player is the
    /// motion at that time, and its root-motion total the travel from frame
    /// 0's time to it (sampled in one step: deltas count whole loop cycles).
    pub(crate) fn resume(&mut self, prev_time: Option<f64>, with_names: bool) {
        if let Some(t) = prev_time {
            let options = MotionOptions { ease: self.params.ease, space: self.params.space };
            self.player.sample(self.params.start, &options);
            self.player.sample(t, &options);
            let position = self.player.first_layer_position().x;
            self.prev = Some((position, Arc::clone(&self.params.motion)));
        }
        self.with_names = with_names && self.params.encoding == Encoding::Protobuf;
    }

    /// After its first tick, a playback with a single viewer goes to it
    /// through `to` (see the module doc).
    pub(crate) fn hand_back_to(&mut self, to: oneshot::Sender<Box<Hub>>) {
        self.handback = Some(to);
    }

    /// Publishes `item` to the broadcast's viewers.
    pub(crate) fn publish(&self, item: Item) {
        // An error only means no viewer is left; the next tick ends it.
        let _ = self.tx.send(item);
    }

    /// Waits for the next tick and produces it: a frame, the end, or
    /// `None` when `require_viewers` and nobody watches any more.
    /// Cancel-safe: nothing changes until the tick is due.
    pub(crate) async fn step(&mut self, require_viewers: bool) -> Option<Item> {
        let Some(shutdown) = self.shutdown.as_mut() else {
            return Some(Item::End(EndReason::Shutdown));
        };
        let tick = tokio::select! {
            biased;
            () = shutdown => {
                self.shutdown = None;
                return Some(Item::End(EndReason::Shutdown));
            }
            tick = self.schedule.next() => tick,
        };
        // Nobody joins after the first tick, so frame 0 reaches every viewer.
        drop(self.listing.take());
        if require_viewers && self.tx.receiver_count() == 0 {
            return None;
        }
        let mut jumped = false;
        if let Some(controls) = &mut self.controls {
            let mut stop = false;
            while let Ok(Queued { control, layout }) = controls.try_recv() {
                if let Some(layout) = layout {
                    self.encoder.relayout(&layout);
                }
                match control.apply(&mut self.playhead, &mut self.player, self.graph.as_mut(), tick.k) {
                    Ok(Applied::Continued) => {}
                    Ok(Applied::Jumped) => jumped = true,
                    Ok(Applied::Stopped) => stop = true,
                    // Checked by the subscription; a refusal here is a bug.
                    Err(Refused { what, error }) => {
                        tracing::error!(%error, "a {what} the subscription accepted was refused");
                    }
                }
            }
            if stop {
                return Some(Item::End(EndReason::Stopped));
            }
        }
        let frame = self.frame(tick.k, tick.skipped, jumped);
        self.ticks.increment(1);
        Some(Item::Frame(frame))
    }

    /// The playback as its own task: publishes every tick to its viewers
    /// until it ends or none is left.
    pub(crate) async fn run(mut self) {
        loop {
            match self.step(true).await {
                Some(item @ Item::Frame(_)) => {
                    self.publish(item);
                    if self.tx.receiver_count() == 1
                        && let Some(to) = self.handback.take()
                    {
                        // Nobody can join any more (the first tick took it
                        // out of the registry): the one viewer drives it.
                        let _ = to.send(Box::new(self));
                        return;
                    }
                    self.handback = None;
                }
                Some(end @ Item::End(_)) => return self.publish(end),
                None => return,
            }
        }
    }

    /// Evaluates and encodes tick `k`.
    fn frame(&mut self, k: u64, skipped: u64, jumped: bool) -> Encoded {
        let clip_time = match &mut self.graph {
            Some(graph) => graph.tick(self.params.fps, self.playhead.paused(), (k, skipped)),
            None => {
                // The chains catch up the latest skipped ticks only.
                if let Some(last) = CatchUp::of(k, skipped, true).skip_to {
                    self.player.skip_springs_to(stream_clock(&self.params, last));
                }
                let time = (self.playhead.time_at(k), stream_clock(&self.params, k));
                sample_tick(&mut self.player, &self.params, time, jumped, &mut self.prev, &mut self.crossed)
            }
        };
        let tick = TickStamp { seq: k, dropped: skipped, sent_at: unix_nanos(), clip_time };
        let with_names = std::mem::take(&mut self.with_names);
        let playing = Playing { player: &self.player, graph: self.graph.as_ref() };
        self.encoder.encode(&frame_data(playing, &self.params, &self.crossed, tick, with_names))
    }
}

/// What a frame says of its tick besides the pose.
pub(super) struct TickStamp {
    pub seq: u64,
    pub dropped: u64,
    pub sent_at: i64,
    pub clip_time: f32,
}

/// The stream time of tick `k`, the clock springs run on (docs/springs.md,
/// “Time”): pause, speed and seeks do not change it.
pub(super) fn stream_clock(params: &StreamParams, k: u64) -> f64 {
    k as f64 / f64::from(params.fps)
}

/// Samples `player` at request time `time.0` (springs at stream time
/// `time.1`) and lists in `crossed` the first layer's events since `prev`
/// (none across a jump or a change of motion); returns the clip time. One
/// step for playbacks and broadcasts alike.
pub(super) fn sample_tick(
    player: &mut StreamPlayer,
    params: &StreamParams,
    (time, clock): (f64, f64),
    jumped: bool,
    prev: &mut Option<(f64, Arc<StreamMotion>)>,
    crossed_out: &mut Vec<u32>,
) -> f32 {
    let options = MotionOptions { ease: params.ease, space: params.space };
    let clip_time = player.sample_clocked(time, clock, &options);
    let motion = player.motion();
    let position = player.first_layer_position();
    let from = prev.as_ref().filter(|(_, m)| !jumped && Arc::ptr_eq(m, motion)).map(|(x, _)| *x);
    crossed(motion.first_clip().clip(), position.playback, params.ease, from, position.x, crossed_out);
    *prev = Some((position.x, Arc::clone(motion)));
    clip_time
}

/// What a tick played: the motion player, or a graph stream's graph.
#[derive(Clone, Copy)]
pub(super) struct Playing<'a> {
    pub player: &'a StreamPlayer,
    pub graph: Option<&'a GraphDeck>,
}

/// The frame of the current pose, as `params` asks for it. A graph's
/// frame names the graph as its clip, shows the graph's motion time, and
/// carries its report when asked, and the motion's IK reports (no events
/// or root motion: a graph stream has none).
pub(super) fn frame_data<'a>(
    playing: Playing<'a>,
    params: &'a StreamParams,
    crossed: &'a [u32],
    tick: TickStamp,
    with_names: bool,
) -> FrameData<'a> {
    let player = playing.player;
    let motion = player.motion();
    let first = motion.first_clip();
    if let Some(graph) = playing.graph {
        return FrameData {
            seq: tick.seq,
            dropped: tick.dropped,
            sent_at_unix_nanos: tick.sent_at,
            clip_id: &params.clip_id,
            time: graph.time(params.fps),
            clip_time: tick.clip_time,
            space: params.space,
            skeleton: motion.skeleton(),
            pose: graph.pose(),
            joints: params.joints.as_deref(),
            parameters: None,
            root_motion: graph.root_motion(),
            ik: graph.ik_reports(),
            feet: &[],
            events: &[],
            crossed: &[],
            with_names,
            graph: graph.report(),
        };
    }
    FrameData {
        seq: tick.seq,
        dropped: tick.dropped,
        sent_at_unix_nanos: tick.sent_at,
        clip_id: first.id(),
        time: player.motion_time(),
        clip_time: tick.clip_time,
        space: params.space,
        skeleton: motion.skeleton(),
        pose: player.pose(),
        joints: params.joints.as_deref(),
        parameters: ParameterValues::of(motion.parameters(), player.pose(), params.parameters.as_deref()),
        root_motion: player.root_motion(),
        ik: player.ik_reports(),
        feet: player.feet(),
        events: first.clip().events(),
        crossed,
        with_names,
        graph: None,
    }
}

/// Controls queued for a playback before the client is told to slow down.
const CONTROL_QUEUE: usize = 32;

/// A private playback of `params` on `schedule`, for its one viewer to
/// drive: the playback, its (one-frame) broadcast and its control sender.
pub(crate) fn private(
    params: &StreamParams,
    schedule: Schedule,
    shutdown: watch::Receiver<bool>,
) -> (Box<Hub>, broadcast::Receiver<Item>, mpsc::Sender<Queued>) {
    let (tx, rx) = broadcast::channel(1);
    let (ctl_tx, ctl_rx) = mpsc::channel(CONTROL_QUEUE);
    (Box::new(Hub::new(params, schedule, tx, Some(ctl_rx), None, shutdown)), rx, ctl_tx)
}

/// Wall-clock nanoseconds since the Unix epoch (0 if the clock is before it).
pub fn unix_nanos() -> i64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as i64)
}
