//! Sampling requests over a graph (docs/graphs.md, “Using a graph”): a
//! motion one of whose layers names `"graph"` (alone, or among clip layers
//! run on its pose with the motion's IK and springs), played on the tick grid `k/fps`
//! from 0 with the request's timed `inputs`, the poses of the ticks from
//! `start` to `end` answered (or, for one pose, of the last tick at or
//! before `time`). REST and gRPC alike: each says where its fields sit
//! ([`Locate`]). The graph comes built from the cache of built graphs
//! (`server::graphs`); every tick played, answered or not, is priced before
//! any is played.

use std::sync::Arc;

use super::cost::{Cost, Estimate, F32_TEXT, F64_TEXT, Wire, ik_reports, json_str};
use super::raw::{Field, Format, Locate, Raw, RawModes, joint_subset, unprocessable};
use super::sample::FPS_RANGE;
use crate::auth::CallerKey;
use crate::built::{BuiltGraph, PinnedGraph, PinnedPost};
use crate::error::{ApiError, At};
use crate::graphs::MotionOnGraph;
use crate::state::AppState;
use crate::stream::MAX_FPS;
use crate::stream::PinnedClip;
use crate::work::price;
use anim::Pose;
use anim::Space;
use anim::graph::{GraphPlayer, GraphPost, Inputs, PostRun, TickRange};
use anim::motion::MotionSpec;
use anim::motion::{Planar, RootMotion};
use formats::wire::graph_inputs::InputDoc;
use formats::wire::motion::{LayerDoc, LayerModeDoc, MotionDoc};

/// The grid's rate when a request gives none.
const DEFAULT_GRAPH_FPS: f64 = 60.0;

/// Where a graph layer's reference sits in a request.
pub const GRAPH_AT: &str = "/motion/layers/0/graph";

fn unsupported(pointer: &str, detail: &str) -> ApiError {
    ApiError::invalid("graph_unsupported", pointer, detail)
}

/// A motion's graph layer: the graph's reference, and the stages the
/// motion runs on the graph's pose (docs/graphs.md, “What composes with a
/// graph”).
#[derive(Debug, Clone)]
pub struct GraphLayer<'a> {
    pub reference: &'a str,
    pub stages: GraphStages,
}

/// What the motion builds the graph's nodes with (its character, retarget
/// options and root motion), its clip layers beside the graph's, and its IK
/// constraints and spring chains, checked against the output skeleton once
/// the graph is resolved.
#[derive(Debug, Clone, Default)]
pub struct GraphStages {
    motion: MotionOnGraph,
    /// The motion with the graph's layer at `at` (its clip a stand-in),
    /// when it has clip layers beside it.
    mix: Option<(usize, MotionSpec<String>)>,
    ik: Vec<anim::ik::IkSpec>,
    springs: anim::spring::SpringsSpec,
}

/// The graph `doc` names, when a layer names one: its reference and the
/// motion's stages, once the graph's layer is checked to take only what a
/// graph layer takes (`weight`, `mask`, `mode`).
///
/// # Errors
/// `graph_unsupported` at the field that a graph layer does not take (a
/// second graph layer at its `graph`; `root_motion` beside clip layers);
/// the `retarget`, `ik`, `springs` and clip layers' documents' own refusals.
pub fn graph_layer(doc: &MotionDoc) -> Result<Option<GraphLayer<'_>>, ApiError> {
    let mut graphs = doc.layers.iter().enumerate().filter(|(_, l)| l.graph.is_some()).map(|(i, _)| i);
    let Some(at) = graphs.next() else { return Ok(None) };
    if let Some(second) = graphs.next() {
        return Err(unsupported(&format!("/motion/layers/{second}/graph"), "a motion plays at most one graph"));
    }
    let layer = &doc.layers[at];
    if let Some(field) = layer_field_set(layer) {
        let detail = format!(
            "a graph layer takes no `{field}` (it plays its own clock: it takes `weight`, `mask` and `mode` only)"
        );
        return Err(unsupported(&format!("/motion/layers/{at}/{field}"), &detail));
    }
    let mixed =
        doc.layers.len() > 1 || layer.weight != 1.0 || layer.mask.is_some() || layer.mode != LayerModeDoc::Blend;
    if mixed && doc.root_motion.is_some() {
        let detail = "root motion plays with a graph that is its motion's only layer, at its defaults";
        return Err(unsupported("/motion/root_motion", detail));
    }
    let mix = mixed.then(|| mix_spec(doc, at)).transpose()?;
    let retarget = doc.retarget.as_ref().map(|r| r.to_spec("/motion/retarget")).transpose()?.unwrap_or_default();
    let root_motion = doc.root_motion.as_ref().map(formats::wire::motion::RootMotionDoc::to_spec);
    let ik = (doc.ik.iter().enumerate())
        .map(|(i, c)| c.to_spec(&format!("/motion/ik/{i}")))
        .collect::<Result<_, _>>()
        .map_err(ApiError::from)?;
    let springs = doc.springs("/motion").map_err(ApiError::from)?;
    let Some(reference) = layer.graph.as_deref() else { return Ok(None) };
    let motion = MotionOnGraph { character: doc.character.clone(), retarget, root_motion };
    Ok(Some(GraphLayer { reference, stages: GraphStages { motion, mix, ik, springs } }))
}

/// The motion `doc` says with its graph's layer `at` as a clip layer of
/// the same weight, mask and mode (its clip a stand-in the core replaces).
fn mix_spec(doc: &MotionDoc, at: usize) -> Result<(usize, MotionSpec<String>), ApiError> {
    let mut doc = doc.clone();
    doc.layers[at] = LayerDoc { clip: GRAPH_STAND_IN.into(), graph: None, ..doc.layers[at].clone() };
    (doc.ik, doc.springs, doc.root_motion) = (Vec::new(), Vec::new(), None);
    Ok((at, doc.to_spec("/motion")?))
}

/// What a mixed motion's graph layer names as its clip until the core puts
/// the graph's own first clip there.
const GRAPH_STAND_IN: &str = "graph";

impl GraphStages {
    /// The graph `built` plays for this motion: its own, or built with the
    /// motion's character and root motion (`server::graphs::played`).
    ///
    /// # Errors
    /// As `server::graphs::played`.
    pub async fn graph(
        &self,
        state: &AppState,
        caller: &CallerKey,
        built: &Arc<BuiltGraph>,
    ) -> Result<Arc<PinnedGraph>, ApiError> {
        crate::graphs::played(state, caller, built, &self.motion).await
    }

    /// The stages built on `graph`: its clip layers (looked up, pinned,
    /// built priced on the pool with the graph's layer among them), then
    /// IK and springs on the output skeleton, refusals pointed into
    /// `/motion`.
    ///
    /// # Errors
    /// `clip_not_found` (404) at `/motion/layers/i/clip`;
    /// `character_not_found`; as a motion's layers, `ik` and `springs`.
    pub async fn build(
        &self,
        graph: &Arc<PinnedGraph>,
        state: &AppState,
        caller: &CallerKey,
    ) -> Result<PinnedPost, ApiError> {
        let moved = |e: anim::MotionError| {
            ApiError::invalid(e.kind.code(), format!("/motion{}", e.path.to_pointer()), e.kind.to_string())
        };
        let limits = state.config.limits.ik();
        let Some((at, spec)) = &self.mix else {
            return GraphPost::build(&self.ik, &self.springs, graph.skeleton(), &limits).map_err(moved);
        };
        let mut pinned = self.pin(state, (*at, spec.clone()), graph).await?;
        if let Some(reference) = &self.motion.character {
            pinned.character = Some(Arc::clone(&crate::characters::resolve(state, caller, reference).await?.spec));
        }
        (pinned.ik, pinned.springs) = (self.ik.clone(), self.springs.clone());
        let units = price::motion_build(&pinned).saturating_add(price::graph_tick(graph));
        let (at, graph) = (*at, Arc::clone(graph));
        crate::builds::run(&state.work, caller, &state.config.limits, units, "building this motion", move |_| {
            GraphPost::mixed(pinned, at, &graph, &limits).map_err(moved)
        })
        .await
    }

    /// The mix's spec with each clip layer's clip looked up (the graph's
    /// layer given the graph's first clip, which the core puts there too).
    async fn pin(
        &self,
        state: &AppState,
        (at, spec): (usize, MotionSpec<String>),
        graph: &PinnedGraph,
    ) -> Result<MotionSpec<Arc<dyn PinnedClip>>, ApiError> {
        let mut clips = Vec::with_capacity(spec.layers.len());
        for (i, layer) in spec.layers.iter().enumerate() {
            if i == at {
                clips.push(Arc::clone(graph.initial_motion().first_clip()));
                continue;
            }
            let clip = super::raw::clip(state, &layer.clip).await.map_err(|e| match e {
                ApiError::NotFound { .. } => ApiError::ClipNotFoundAt {
                    at: At::Pointer(format!("/motion/layers/{i}/clip")),
                    detail: format!("layer {i}'s clip `{}` does not exist", layer.clip),
                },
                other => other,
            })?;
            clips.push(clip as Arc<dyn PinnedClip>);
        }
        let mut clips = clips.into_iter();
        spec.try_map(|_, _| clips.next().ok_or(()))
            .map_err(|()| ApiError::internal(anyhow::anyhow!("a layer lost its clip")))
    }
}

/// A graph's fields in a request whose motion names no graph: refused
/// (`graph_unsupported`) at the first of `/report`, `/inputs`, `/fps`
/// that is set.
///
/// # Errors
/// As said.
pub fn no_graph_fields(report: bool, inputs: bool, fps: bool) -> Result<(), ApiError> {
    let fields = [(report, "report"), (inputs, "inputs"), (fps, "fps")];
    let Some(field) = fields.into_iter().find_map(|(set, field)| set.then_some(field)) else {
        return Ok(());
    };
    let detail = format!("`{field}` drives a graph: the motion's layer names no `graph`");
    Err(unsupported(&format!("/{field}"), &detail))
}

/// The first field of a graph layer that a graph layer does not take: a
/// graph plays its own clock, so no time of a clip's.
fn layer_field_set(layer: &LayerDoc) -> Option<&'static str> {
    [
        ("clip", !layer.clip.is_empty()),
        ("offset", layer.offset != 0.0),
        ("speed", layer.speed != 1.0),
        ("playback", layer.playback.is_some()),
        ("sync", layer.sync.is_some()),
        ("reference_time", layer.reference_time.is_some()),
        ("retarget", layer.retarget.is_some()),
    ]
    .into_iter()
    .find_map(|(field, set)| set.then_some(field))
}

/// A graph sampling request's own fields, as a JSON body or a protobuf
/// message carried them.
#[derive(Debug, Clone, Copy)]
pub struct RawGraphSampling<'a> {
    pub reference: &'a str,
    pub stages: &'a GraphStages,
    pub inputs: &'a [InputDoc],
    /// One pose's time (`POST /v1/poses`, `SampleMotion`): the last tick at
    /// or before it is answered, and `times`, `start` and `end` are absent.
    pub time: Option<f64>,
    pub times: Option<&'a [f64]>,
    pub start: Option<f64>,
    pub end: Option<f64>,
    pub fps: Option<f64>,
    pub format: Option<Raw<'a>>,
    pub space: Option<Raw<'a>>,
    pub joints: Option<&'a [String]>,
    pub parameters: Option<&'a [String]>,
    pub report: bool,
    /// Where each field sits on the request's wire, and the wire the
    /// answer is priced on.
    pub at: Locate,
    pub wire: Wire,
}

/// A checked, priced graph sampling request.
pub struct GraphSampling {
    pub built: Arc<BuiltGraph>,
    /// What plays: the built graph's own, or its build on the character.
    pub graph: Arc<PinnedGraph>,
    /// The motion's IK and springs on the graph's pose.
    pub post: Arc<PinnedPost>,
    pub range: TickRange,
    pub inputs: Inputs,
    pub format: Format,
    pub space: Space,
    pub joints: Option<Vec<usize>>,
    pub report: bool,
    pub cost: Cost,
}

impl GraphSampling {
    /// The skeleton its poses are of: the motion's output skeleton.
    pub fn skeleton(&self) -> &anim::Skeleton {
        self.post.skeleton(self.graph.skeleton())
    }
}

impl RawGraphSampling<'_> {
    /// The tick range, then the graph (built, from the cache of built
    /// graphs), the inputs checked against it, the joint subset and the price
    /// of every tick played.
    ///
    /// # Errors
    /// `graph_needs_ticks` (`times`), `graph_unsupported` (`parameters`),
    /// `times_or_range`, `fps_out_of_range`, `bad_range` (also a pose's
    /// `time` below 0), `bad_number` (a pose's `time` not a number),
    /// `too_many_poses`;
    /// the graph's lookup refusals at `/motion/layers/0/graph`; the inputs'
    /// (`bad_time`, `unknown_parameter`, `parameter_type`,
    /// `parameter_out_of_range`) at `/inputs/…`; `no_inverse_binds`,
    /// `unknown_joint`. The caller checks the price, once compressed.
    pub async fn resolve(&self, state: &AppState, caller: &CallerKey) -> Result<GraphSampling, ApiError> {
        let format = Format::decode(self.format, self.at)?;
        let space = RawModes { space: self.space, ..RawModes::default() }.check(self.at)?.space;
        let range = self.range(state.config.limits.max_poses)?;
        let built = crate::graphs::resolve(state, caller, self.reference, GRAPH_AT).await?;
        let graph = self.stages.graph(state, caller, &built).await?;
        let inputs = formats::wire::graph_inputs::inputs(&graph, self.inputs, range.fps, "/inputs")?;
        let post = Arc::new(self.stages.build(&graph, state, caller).await?);
        let skeleton = post.skeleton(graph.skeleton());
        if format == Format::Skinning && !skeleton.has_inverse_binds() {
            let detail = "format=skinning needs inverse bind matrices, which the graph's skeleton has not";
            return Err(unprocessable("no_inverse_binds", Field::Format, self.at, detail.into()));
        }
        let joints = self.joints.map(|names| joint_subset(skeleton, names, self.at)).transpose()?;
        let cost = cost((&built, &graph), &post, &range, (format, self.wire), self.report);
        let report = self.report;
        Ok(GraphSampling { built, graph, post, range, inputs, format, space, joints, report, cost })
    }

    fn range(&self, max_poses: usize) -> Result<TickRange, ApiError> {
        if self.times.is_some() {
            let detail = "a graph is played on ticks: give `start` and `end` (and `fps`, default 60), not `times`";
            return Err(unprocessable("graph_needs_ticks", Field::Times, self.at, detail.into()));
        }
        if self.parameters.is_some() {
            return Err(unsupported("/parameters", "a graph's poses carry no parameter subset yet"));
        }
        if let Some(time) = self.time {
            return self.tick_at(time);
        }
        let (Some(start), Some(end)) = (self.start, self.end) else {
            let detail = "a graph is played on ticks: give `start` and `end` (and `fps`, default 60)";
            return Err(unprocessable("times_or_range", Field::When, self.at, detail.into()));
        };
        let fps = self.fps()?;
        if !(start.is_finite() && start >= 0.0) {
            let detail = format!("start is a finite time ≥ 0, got {start}");
            return Err(unprocessable("bad_range", Field::Start, self.at, detail));
        }
        let range = TickRange::new(start, end, fps).ok_or_else(|| {
            let detail = format!("no tick of the grid at {fps} fps lies in [{start}, {end}]");
            unprocessable("bad_range", Field::End, self.at, detail)
        })?;
        if range.answered() > max_poses as u64 {
            let detail = format!("{} poses requested; the limit is {max_poses} per request", range.answered());
            return Err(unprocessable("too_many_poses", Field::When, self.at, detail));
        }
        Ok(range)
    }

    /// The grid's rate, 1..=240 (default 60).
    fn fps(&self) -> Result<f64, ApiError> {
        let fps = self.fps.unwrap_or(DEFAULT_GRAPH_FPS);
        if !FPS_RANGE.contains(&fps) {
            let detail = format!("fps must be in 1..={MAX_FPS}, got {fps}");
            return Err(unprocessable("fps_out_of_range", Field::Fps, self.at, detail));
        }
        Ok(fps)
    }

    /// One pose's tick: the last at or before `time` (within the grid's
    /// tolerance, so 0.1 s at 60 fps is tick 6), every tick before it
    /// played. A time that is not a number is `bad_number`, as any pose's.
    fn tick_at(&self, time: f64) -> Result<TickRange, ApiError> {
        let time = super::raw::finite(Raw::Number(time), Field::Time, self.at)?;
        let fps = self.fps()?;
        let Some(played) = (time >= 0.0).then(|| TickRange::new(0.0, time, fps)).flatten() else {
            let detail = format!("a graph's pose is at a time ≥ 0 within the grid's reach, got {time}");
            return Err(unprocessable("bad_range", Field::Time, self.at, detail));
        };
        Ok(TickRange { first: played.last, ..played })
    }
}

/// Plays a graph sampling's ticks in order, for any transport: the player
/// is made at the first answered tick (on the work pool) and goes on from
/// tick to tick, so an answer, however it is cut into pieces, holds the
/// poses [`GraphPlayer::play`] gives. The motion's IK and springs run on
/// every tick evaluated: the answered ones, and with springs the ticks of
/// their warm-up before the first (docs/springs.md, “Time”).
#[derive(Default)]
pub struct GraphTicks {
    player: Option<GraphPlayer<Arc<dyn PinnedClip>>>,
    post: Option<PostRun>,
    next_input: usize,
    /// The root motion's total at the first answered tick, which the
    /// answer's totals start from.
    root_base: Planar,
}

impl GraphTicks {
    /// Answered tick `i` (tick `range.first + i`); `i` only grows from
    /// call to call.
    pub fn play(&mut self, s: &GraphSampling, i: usize) -> GraphTick<'_> {
        let k = s.range.first + i as u64;
        let player = self.player.get_or_insert_with(|| GraphPlayer::new(Arc::clone(&s.graph)));
        let run = self.post.get_or_insert_with(|| PostRun::new(&s.post));
        let skeleton = s.graph.skeleton();
        let evaluated = (&s.range, s.post.first_run(&s.range));
        let each = |tick, p: &GraphPlayer<_>| {
            if !s.post.is_empty() {
                let time = s.range.time(tick);
                run.run(&s.post, skeleton, p.pose(), (time, time));
            }
        };
        // The inputs were checked against this graph, so no setting fails.
        let _ = player.play_through(k, evaluated, &s.inputs, &mut self.next_input, each);
        let pose = if s.post.is_empty() { player.pose() } else { run.pose() };
        let root_motion = answered_root(player, i, &mut self.root_base);
        GraphTick { player, pose, ik: run.ik_reports(), root_motion, time: s.range.time(k) }
    }
}

/// Answered tick `i`'s root motion (docs/motion.md, “Root motion”): the
/// first's delta and total 0 (its total is the `base` the others' start
/// from), the others' delta the player's and their total since the first.
fn answered_root(player: &GraphPlayer<Arc<dyn PinnedClip>>, i: usize, base: &mut Planar) -> Option<RootMotion> {
    let (root, up) = (player.root_motion()?, player.graph().initial_motion().root_up()?);
    if i == 0 {
        *base = root.total;
        return Some(RootMotion::default());
    }
    Some(RootMotion { delta: root.delta, total: base.inverse(up).then(root.total, up) })
}

/// One answered tick of a graph sampling.
pub struct GraphTick<'a> {
    /// The player after the tick (its report).
    pub player: &'a GraphPlayer<Arc<dyn PinnedClip>>,
    /// The tick's local pose after the motion's IK and springs.
    pub pose: &'a Pose,
    /// The motion's IK reports, one per constraint.
    pub ik: &'a [anim::ik::IkReport],
    /// Its root motion since the answer's first tick, when the motion asks for it.
    pub root_motion: Option<RootMotion>,
    /// Its motion time `k/fps`.
    pub time: f64,
}

/// Every tick played (from 0, answered or not) at the graph's costliest
/// tick, and an answer as long as the largest of its clips' poses (or of
/// the character's, which every pose then is), with the reports when asked
/// for.
fn cost(
    (built, graph): (&BuiltGraph, &PinnedGraph),
    post: &PinnedPost,
    range: &TickRange,
    (format, wire): (Format, Wire),
    report: bool,
) -> Cost {
    let per_pose =
        pose_bound((built, graph, post), |clip| Estimate::batch(clip, &built.meta.id, format, wire).per_pose)
            + json_str(&built.meta.id)
            + ik_reports(post.ik().len() as u64, wire)
            + if graph.initial_motion().has_root_motion() { super::motion::ROOT_MOTION_BYTES } else { 0 }
            + if report { report_bytes(built) } else { 0 };
    let bytes = 12 + per_pose.saturating_mul(range.answered());
    let ticks = range.last.saturating_add(1);
    let skeleton = post.skeleton(graph.skeleton());
    let stages = (range.last - post.first_run(range) + 1).saturating_mul(price::graph_post(post, skeleton, range.fps));
    let per_tick = price::graph_tick(graph).saturating_add(stages.div_ceil(ticks));
    Cost::new(ticks, skeleton.len() as u64, per_tick, bytes)
}

/// The largest pose `graph` plays, by `bytes` of a clip: its clips'
/// largest; on a character, whose joints every pose then has, each clip's
/// scaled by how many more joints the character has, and its names' text.
pub(super) fn pose_bound(
    (built, graph, post): (&BuiltGraph, &PinnedGraph, &PinnedPost),
    bytes: impl Fn(&anim::Clip) -> u64,
) -> u64 {
    let skeleton = post.skeleton(graph.skeleton());
    let clips = || {
        let layers = post.mix().into_iter().flat_map(|m| m.layers()).map(|c| c.clip());
        built.clips.iter().map(|c| &c.clip).chain(layers)
    };
    if std::ptr::eq(skeleton, built.graph.skeleton()) && post.mix().is_none() {
        return clips().map(&bytes).max().unwrap_or(0);
    }
    let joints = skeleton.len() as u64;
    let scale = |clip: &anim::Clip| joints.div_ceil(clip.joint_count().max(1) as u64).max(1);
    let largest = clips().map(|c| bytes(c).saturating_mul(scale(c))).max().unwrap_or(0);
    largest.saturating_add(skeleton.names().iter().map(|n| json_str(n)).sum())
}

/// The longest `,"graph":{…}` a tick's report can write.
pub(super) fn report_bytes(built: &BuiltGraph) -> u64 {
    let graph = &built.graph;
    let state = graph.state_names().map(json_str).max().unwrap_or(2);
    let weights: u64 =
        graph.blend_nodes().map(|(name, points)| json_str(name) + 4 + points as u64 * (F64_TEXT + 1)).sum();
    64 + 3 * state + F32_TEXT + weights
}
