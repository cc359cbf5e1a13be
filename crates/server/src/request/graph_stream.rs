//! Opening a graph stream or broadcast (docs/graphs.md, “Streams and
//! broadcasts”): a stream request one of whose motion's layers names a
//! `graph` (its clip layers, if any, run on the graph's pose). The graph comes built from the cache of built graphs, pinned at
//! its version for as long as the stream plays; it plays on the stream's
//! tick grid from motion time 0 at speed 1, so what a graph stream does not
//! take — a `start` or `speed`, an `ease`, a parameter subset — is refused `graph_unsupported` at its field. Its price per
//! frame is the graph's costliest tick (as a sampling request's ticks are
//! priced) and its frame's encoding, the report included when asked; with
//! springs or root motion, also its share of the skipped ticks a frame
//! woken late evaluates (`price::catch_up`).

use std::sync::Arc;

use super::cost::{
    Estimate, F64_TEXT, check_stream, check_stream_work, compact_frame, compact_graph_report, ik_reports, json_str,
    stream_work,
};
use super::graph::{GRAPH_AT, GraphStages, pose_bound, report_bytes};
use super::raw::{Field, unprocessable};
use super::stream::{Admitted, Opening, RawStream};
use crate::auth::{Caller, CallerKey};
use crate::error::ApiError;
use crate::state::AppState;
use crate::stream::{GraphProgram, StreamParams, StreamRequest};
use crate::work::price;

/// A graph stream's own fields.
#[derive(Debug, Clone, Copy)]
pub struct RawGraphStream<'a> {
    /// The graph's id, or `name:<name>`.
    pub reference: &'a str,
    /// The motion's IK and springs, run on the graph's pose.
    pub stages: &'a GraphStages,
    /// Each frame carries the tick's report.
    pub report: bool,
}

/// A graph stream's parameters, and the bound of its frame in bytes and
/// its work per frame.
struct GraphStream {
    params: StreamParams,
    frame: u64,
    per_frame: u64,
    /// A stream frame's share of the skipped ticks late frames evaluate
    /// (`price::catch_up`; a broadcast steps each tick once).
    catch_up: u64,
}

impl RawStream<'_> {
    /// As [`RawStream::open_motion`] for a graph (docs/graphs.md): the graph
    /// resolved and pinned, priced, charged to `caller` and admitted.
    ///
    /// # Errors
    /// `graph_unsupported` at `/playback`, `/start`, `/speed`, `/ease`,
    /// `/encoding` or `/parameters/0`; the stream rules' codes; the graph's lookup refusals
    /// at `/motion/layers/0/graph`; then as [`RawStream::open_motion`].
    pub async fn open_graph(
        &self,
        state: &AppState,
        graph: RawGraphStream<'_>,
        caller: &Caller,
    ) -> Result<Admitted, ApiError> {
        let GraphStream { params, frame, per_frame, catch_up } = self.graph_stream(state, graph, &caller.key()).await?;
        let permit = match self.admit(per_frame.saturating_add(catch_up), frame, params.fps, state, caller)? {
            Ok(permit) => permit,
            Err(refused) => return Ok(Err(refused)),
        };
        Ok(Ok(Opening { params, permit }))
    }

    /// A graph broadcast's stream parameters and price per second (as
    /// [`RawStream::motion_params`] for a motion).
    ///
    /// # Errors
    /// As [`RawStream::open_graph`], but the caller's share and the caps.
    pub async fn graph_params(
        &self,
        state: &AppState,
        graph: RawGraphStream<'_>,
    ) -> Result<(StreamParams, u64), ApiError> {
        let GraphStream { params, frame, per_frame, .. } = self.graph_stream(state, graph, &CallerKey::Node).await?;
        check_stream(frame, params.fps, &state.config.limits, self.at)?;
        let per_sec = stream_work(per_frame.saturating_add(price::BROADCAST_TICK), frame, params.fps);
        check_stream_work(per_sec, &state.config.limits, self.at)?;
        Ok((params, per_sec))
    }

    async fn graph_stream(
        &self,
        state: &AppState,
        graph: RawGraphStream<'_>,
        caller: &CallerKey,
    ) -> Result<GraphStream, ApiError> {
        let request = self.check()?;
        self.fits_a_graph(&request)?;
        let compact = self.compact(&request)?;
        self.check_fps(request.fps)?;
        let built = crate::graphs::resolve(state, caller, graph.reference, GRAPH_AT).await?;
        let played = graph.stages.graph(state, caller, &built).await?;
        let id: &str = &built.meta.id;
        let wire = request.encoding.into();
        let post = Arc::new(graph.stages.build(&played, state, caller).await?);
        let pose = pose_bound((&built, &played, &post), |clip| Estimate::frame(clip, id, wire));
        // The report's JSON bound also bounds its protobuf (floats of 4 bytes, not text).
        let report = if graph.report { report_bytes(&built) } else { 0 };
        let ik = ik_reports(post.ik().len() as u64, wire);
        let root = if played.initial_motion().has_root_motion() { super::motion::ROOT_MOTION_BYTES } else { 0 };
        let skeleton = post.skeleton(played.skeleton());
        let joints = skeleton.len();
        let (frame, encoding) = match compact {
            Some(_) => {
                let report = if graph.report { compact_graph_report(&played) } else { 0 };
                (compact_frame(joints, 0).saturating_add(report), price::compact_frame(joints))
            }
            None => {
                let frame = pose.saturating_add(report).saturating_add(ik).saturating_add(root);
                (frame.saturating_add(2 * F64_TEXT + json_str(id)), 0)
            }
        };
        let stages = price::graph_post(&post, skeleton, f64::from(request.fps));
        let tick = price::graph_tick(&played).saturating_add(stages);
        let program =
            GraphProgram { graph: played, post, id: id.into(), version: built.meta.version, report: graph.report };
        let catch_up = if program.catches_up() { price::catch_up(tick, request.fps) } else { 0 };
        let per_frame = tick.saturating_add(encoding);
        let motion = Arc::clone(program.post.mix().unwrap_or(program.graph.initial_motion()));
        let params = StreamParams::of_motion(motion, Arc::clone(&program.id), request).map_err(|e| self.refused(e))?;
        let params = self.bind(params.with_graph(program), state)?;
        let params = self.with_layout(params, compact, state, caller).await?;
        Ok(GraphStream { params, frame, per_frame, catch_up })
    }

    /// A graph plays from motion time 0 at speed 1, its own poses in full.
    fn fits_a_graph(&self, request: &StreamRequest) -> Result<(), ApiError> {
        let refuse = |field: Field, detail: &str| {
            Err(unprocessable("graph_unsupported", field, self.at, format!("a graph stream {detail}")))
        };
        if self.modes.playback.is_some() {
            return refuse(Field::Playback, "plays its nodes' own playbacks: it takes no `playback`");
        }
        if request.start.is_some_and(|t| t != 0.0) {
            return refuse(Field::Start, "plays from motion time 0: it takes no `start`");
        }
        if request.speed.is_some_and(|v| v != 1.0) {
            return refuse(Field::Speed, "plays one graph tick per tick: it takes no `speed`");
        }
        if request.ease != anim::Ease::Linear {
            return refuse(Field::Ease, "plays its ticks as they are: it takes no `ease`");
        }
        if self.parameters.is_some() {
            return refuse(Field::ParameterAt(0), "carries no parameter subset yet");
        }
        Ok(())
    }
}
