//! Graph streams (docs/graphs.md, “Streams and broadcasts”): a stored graph
//! played on a stream's tick grid from motion time 0, one graph tick per
//! stream tick, its parameters set by `set` controls from the next tick —
//! so frame `k` of a stream that was never paused is tick `k` of a sampling
//! request with the same settings at the same ticks. A tick the playback
//! woke too late for is stepped without its pose, as a sampling request
//! steps the ticks before its `start`. A pause holds the pose and the
//! graph's time (the first tick is always played: it shows node time 0).
//!
//! The player's state is plain values (`anim::graph::GraphState`), which a
//! broadcast checkpoint keeps exactly (`checkpoint`).

use std::sync::Arc;

use super::pinned::PinnedClip;
use anim::graph::{Graph, GraphPlayer, GraphReport, GraphState, SetError, Value};
use anim::{Pose, Space};

/// A graph over clips pinned at their versions.
pub type StreamGraph = Graph<Arc<dyn PinnedClip>>;

/// What a graph stream plays: the graph at the version it opened on (it
/// keeps it, replaced or not, as a clip stream keeps its clip), and whether
/// each frame carries the tick's report.
#[derive(Debug, Clone)]
pub struct GraphProgram {
    pub graph: Arc<StreamGraph>,
    /// The stored graph's id (frames name it as their clip) and version.
    pub id: Arc<str>,
    pub version: u64,
    pub report: bool,
}

/// A graph playing on a stream or a broadcast.
#[derive(Debug, Clone)]
pub(crate) struct GraphDeck {
    player: GraphPlayer<Arc<dyn PinnedClip>>,
    report: bool,
    space: Space,
    /// The pose in model space, when frames are.
    model: Pose,
}

impl GraphDeck {
    /// Before its tick 0, every parameter at its default.
    pub(super) fn new(program: &GraphProgram, space: Space) -> Self {
        let player = GraphPlayer::new(Arc::clone(&program.graph));
        GraphDeck { player, report: program.report, space, model: Pose::default() }
    }

    /// The deck a checkpoint's `state` describes (its next tick evaluates
    /// the pose).
    ///
    /// # Errors
    /// A state that does not fit the graph.
    pub(super) fn from_state(program: &GraphProgram, space: Space, state: GraphState) -> Result<Self, SetError> {
        let player = GraphPlayer::from_state(Arc::clone(&program.graph), state)?;
        Ok(GraphDeck { player, report: program.report, space, model: Pose::default() })
    }

    /// Stream tick `k` at `fps`, `skipped` ticks after the previous one was
    /// shown (those are stepped without a pose, as are the ticks before a
    /// first tick that came late), so that a stream never paused shows
    /// graph tick `k` at tick `k`; nothing while `paused` but the first.
    /// Returns the motion time shown, as a frame's `clip_time`.
    pub(super) fn tick(&mut self, fps: u32, paused: bool, (k, skipped): (u64, u64)) -> f32 {
        let dt = 1.0 / f64::from(fps);
        let first = self.player.ticks() == 0;
        if !paused || first {
            for _ in 0..if first { k } else { skipped } {
                self.player.step(dt);
            }
            self.player.tick(dt);
            if self.space == Space::Model {
                self.player.graph().skeleton().to_model(self.player.pose(), &mut self.model);
            }
        }
        self.time(fps) as f32
    }

    /// Sets parameters from the next tick on (each checked against the
    /// graph when its control was).
    pub(super) fn set(&mut self, values: &[(usize, Value)]) {
        for &(parameter, value) in values {
            if let Err(e) = self.player.set(parameter, value) {
                tracing::error!(error = %e, "a graph setting its control's check accepted was refused");
            }
        }
    }

    /// The motion time of the last tick played: `(ticks − 1) / fps`.
    pub(super) fn time(&self, fps: u32) -> f64 {
        self.player.ticks().saturating_sub(1) as f64 / f64::from(fps)
    }

    /// The last tick's pose, in the stream's space.
    pub(super) fn pose(&self) -> &Pose {
        if self.space == Space::Model { &self.model } else { self.player.pose() }
    }

    /// The last tick's report, when the stream asked for it.
    pub(super) fn report(&self) -> Option<GraphReport<'_, Arc<dyn PinnedClip>>> {
        self.report.then(|| self.player.report())
    }

    /// What a checkpoint keeps.
    pub(super) fn state(&self) -> GraphState {
        self.player.state()
    }
}
