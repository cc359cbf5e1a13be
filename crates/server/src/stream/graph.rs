//! Graph streams (docs/graphs.md, “Streams and broadcasts”): a stored graph
//! played on a stream's tick grid from motion time 0, one graph tick per
//! stream tick, its parameters set by `set` controls from the next tick —
//! so frame `k` of a stream that was never paused is tick `k` of a sampling
//! request with the same settings at the same ticks. A tick the playback
//! woke too late for is stepped without its pose, as a sampling request
//! steps the ticks before its `start`. A pause holds the pose and the
//! graph's time (the first tick is always played: it shows node time 0).
//!
//! The motion's clip layers (at the tick's motion time), IK and springs run
//! on each tick's pose (docs/graphs.md, “What composes with a graph”), the
//! springs in stream time.
//!
//! The player's state is plain values (`anim::graph::GraphState`), and so is
//! the springs' (`anim::spring::SpringState`), which a broadcast checkpoint
//! keeps exactly (`checkpoint`).

use std::sync::Arc;

use super::pinned::PinnedClip;
use super::schedule::CatchUp;
use crate::built::PinnedPost;
use anim::graph::{Graph, GraphPlayer, GraphReport, GraphState, PostRun, SetError, Value};
use anim::ik::IkReport;
use anim::spring::SpringState;
use anim::{Pose, Space};

/// A graph over clips pinned at their versions.
pub type StreamGraph = Graph<Arc<dyn PinnedClip>>;

/// What a graph stream plays: the graph at the version it opened on (it
/// keeps it, replaced or not, as a clip stream keeps its clip), the
/// motion's IK and springs on its pose, and whether each frame carries the
/// tick's report.
#[derive(Debug, Clone)]
pub struct GraphProgram {
    pub graph: Arc<StreamGraph>,
    pub post: Arc<PinnedPost>,
    /// The stored graph's id (frames name it as their clip) and version.
    pub id: Arc<str>,
    pub version: u64,
    pub report: bool,
}

impl GraphProgram {
    /// Whether a frame woken late evaluates the ticks it skipped (up to
    /// [`MAX_CATCH_UP`](super::schedule::MAX_CATCH_UP)) rather than only stepping them: with springs or
    /// root motion, which must see every tick.
    pub fn catches_up(&self) -> bool {
        catches_up(&self.graph, &self.post)
    }
}

/// [`GraphProgram::catches_up`] of `graph` under `post`.
fn catches_up(graph: &StreamGraph, post: &PinnedPost) -> bool {
    post.springs().is_some() || graph.initial_motion().has_root_motion()
}

/// A graph playing on a stream or a broadcast.
#[derive(Debug, Clone)]
pub(crate) struct GraphDeck {
    player: GraphPlayer<Arc<dyn PinnedClip>>,
    post: Arc<PinnedPost>,
    /// The motion's IK and springs on the player's pose, run in stream
    /// time (docs/springs.md, “Time”).
    run: PostRun,
    report: bool,
    space: Space,
    /// The pose in model space, when frames are.
    model: Pose,
    /// The last tick held the graph (paused): its root did not move.
    held: bool,
}

impl GraphDeck {
    /// Before its tick 0, every parameter at its default, the springs at rest.
    pub(super) fn new(program: &GraphProgram, space: Space) -> Self {
        let player = GraphPlayer::new(Arc::clone(&program.graph));
        let (post, run) = (Arc::clone(&program.post), PostRun::new(&program.post));
        GraphDeck { player, post, run, report: program.report, space, model: Pose::default(), held: false }
    }

    /// The deck a checkpoint's `state` and `springs` describe, showing the
    /// tick it was taken after, at stream time `clock`.
    ///
    /// # Errors
    /// A state that does not fit the graph, or springs that do not fit the motion's.
    pub(super) fn from_state(
        program: &GraphProgram,
        space: Space,
        (state, springs): (GraphState, Option<SpringState>),
        (clock, fps): (f64, u32),
    ) -> Result<Self, SetError> {
        let player = GraphPlayer::from_state(Arc::clone(&program.graph), state)?;
        let run = PostRun::from_state(&program.post, springs)
            .map_err(|_| SetError::State("a spring state that does not fit the motion's springs"))?;
        let post = Arc::clone(&program.post);
        let mut deck =
            GraphDeck { player, post, run, report: program.report, space, model: Pose::default(), held: false };
        if deck.player.ticks() > 0 {
            deck.run_post(fps, clock);
            deck.put_in_space();
        }
        Ok(deck)
    }

    /// Stream tick `k` at `fps`, `skipped` ticks after the previous one was
    /// shown (those are stepped without a pose, as are the ticks before a
    /// first tick that came late — but with springs or root motion the
    /// latest [`MAX_CATCH_UP`](super::schedule::MAX_CATCH_UP) of them are evaluated, so that the chains
    /// and the root's travel see them; the chains skip the older ones'
    /// substeps), so that a stream never paused shows
    /// graph tick `k` at tick `k`; while `paused` only the springs go on
    /// settling on the held pose (the first tick is always played).
    /// Returns the motion time shown, as a frame's `clip_time`.
    pub(super) fn tick(&mut self, fps: u32, paused: bool, (k, skipped): (u64, u64)) -> f32 {
        let dt = 1.0 / f64::from(fps);
        let clock = |tick: u64| tick as f64 / f64::from(fps);
        let first = self.player.ticks() == 0;
        self.held = paused && !first;
        if !paused || first {
            let n = if first { k } else { skipped };
            let CatchUp { evaluated, skip_to } = CatchUp::of(k, n, catches_up(self.player.graph(), &self.post));
            for _ in evaluated..n {
                self.player.step(dt);
            }
            if let Some(last) = skip_to {
                self.run.skip_springs_to(&self.post, clock(last));
            }
            for j in (0..evaluated).rev() {
                self.player.tick(dt);
                self.run_post(fps, clock(k - 1 - j));
            }
            self.player.tick(dt);
            self.run_post(fps, clock(k));
            self.put_in_space();
        } else if self.post.springs().is_some() {
            self.run.settle(&self.post, clock(k));
            self.put_in_space();
        }
        self.time(fps) as f32
    }

    /// The motion's stages on the player's pose of its last tick (whose
    /// motion time the clip layers play at), the springs at `clock`.
    fn run_post(&mut self, fps: u32, clock: f64) {
        if !self.post.is_empty() {
            let tau = self.time(fps);
            self.run.run(&self.post, self.player.graph().skeleton(), self.player.pose(), (tau, clock));
        }
    }

    /// The local pose in the stream's space.
    fn put_in_space(&mut self) {
        if self.space == Space::Model {
            let local = if self.post.is_empty() { self.player.pose() } else { self.run.pose() };
            self.post.skeleton(self.player.graph().skeleton()).to_model(local, &mut self.model);
        }
    }

    /// The springs start again at rest at the next tick, whose frame shows
    /// their joints' rest rotations (`reset_springs`).
    pub(super) fn reset_springs(&mut self) {
        self.run.restart_springs();
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
        match (self.space, self.post.is_empty()) {
            (Space::Model, _) => &self.model,
            (Space::Local, true) => self.player.pose(),
            (Space::Local, false) => self.run.pose(),
        }
    }

    /// The last tick's root motion since tick 0, when the motion asks for
    /// it: a held tick's delta is 0, its total the last played tick's.
    pub(super) fn root_motion(&self) -> Option<anim::motion::RootMotion> {
        let root = self.player.root_motion()?;
        Some(if self.held { anim::motion::RootMotion { delta: anim::motion::Planar::IDENTITY, ..root } } else { root })
    }

    /// The last tick's IK reports (the motion's constraints).
    pub(super) fn ik_reports(&self) -> &[IkReport] {
        self.run.ik_reports()
    }

    /// The last tick's report, when the stream asked for it.
    pub(super) fn report(&self) -> Option<GraphReport<'_, Arc<dyn PinnedClip>>> {
        self.report.then(|| self.player.report())
    }

    /// What a checkpoint keeps: the graph player's state and the springs'.
    pub(super) fn state(&self) -> (GraphState, Option<SpringState>) {
        (self.player.state(), self.run.spring_state())
    }
}
