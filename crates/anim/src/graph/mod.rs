//! Animation graphs (docs/graphs.md): blend spaces and a state machine,
//! driven by a few named parameters.
//!
//! [`Graph::build`] checks a [`GraphSpec`] once — parameter types and
//! ranges, references, cycles, blend spaces (triangulated here, never per
//! tick) — and turns every node a state plays into one motion (docs/motion.md): a clip is
//! one layer, a blend is one layer per point whose weights the parameters
//! set each tick (`w_k / Σ_{j≤k} w_j`, so the stack is exactly the blend),
//! sharing one sync group; a `layers` node is its entries' layers. Playing
//! is the [`GraphPlayer`]'s: parameters, the machine's transitions as
//! crossfades, and the pose, tick by tick, without allocating.
//!
//! Module map: `spec` the authoring types (indices, not names); `error` why
//! a graph is refused; `blend` the blend spaces; `player` the evaluator and
//! its state; `post` the motion's IK and springs on its pose; `ticks` the tick grid and timed inputs of a sampling request.

mod blend;
mod error;
mod player;
mod post;
mod spec;
mod ticks;

use std::sync::Arc;

pub use error::{Degeneracy, GraphError, GraphErrorKind};
pub use player::{FadeProgress, GraphPlayer, GraphReport, GraphState, SetError, SlotState, TransitionReport};
pub use post::{GraphPost, PostRun};
pub use spec::{
    Blend1dSpec, Blend2dSpec, ClipNodeSpec, Comparison, Condition, EntrySource, EntrySpec, GraphSpec, MachineSpec,
    NodeKind, NodeSpec, ParameterKind, ParameterSpec, StateSpec, TopSpec, TransitionSpec, Value,
};
pub use ticks::{Inputs, TickRange, due_tick};

use self::blend::{Line, Plane};
use self::error::GraphErrorKind as K;
use crate::motion::{
    CharacterSpec, ClipSource, LayerMode, LayerSpec, MAX_FADES, Motion, MotionSpec, RetargetSpec, RootMotionSpec,
};
use crate::{Path, Playback, Step};

/// A validated graph, ready to play.
#[derive(Debug, Clone)]
pub struct Graph<C> {
    parameters: Vec<ParameterSpec>,
    node_names: Vec<String>,
    blends: Vec<Blend>,
    /// Per node, its layer stack (every node has one once built).
    stacks: Vec<Option<Stack<C>>>,
    states: Vec<StateSpec>,
    transitions: Vec<TransitionSpec>,
    initial: usize,
}

/// A blend node's space and the parameters that place a value in it.
#[derive(Debug, Clone, PartialEq)]
struct Blend {
    node: usize,
    points: usize,
    space: Space,
}

#[derive(Debug, Clone, PartialEq)]
enum Space {
    Line {
        parameter: usize,
        line: Line,
    },
    /// Each axis: its parameter and `(min, max − min)` to normalise by.
    Plane {
        axes: [(usize, f64, f64); 2],
        plane: Plane,
    },
}

/// A node as one motion: its layers, their weights when no blend sets
/// them, the blends that do (each from its first layer on) and how its
/// exit time is measured.
#[derive(Debug, Clone)]
struct Stack<C> {
    motion: Arc<Motion<C>>,
    weights: Vec<f32>,
    blends: Vec<(usize, usize)>,
    exit: Exit,
}

/// Cycles played since the node started (docs/graphs.md, “exit_time”).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Exit {
    /// The first layer's sync-group phase (group 0).
    Phase,
    /// The first layer's clip: `|speed|·τ / duration`, at most 1 if it plays once.
    Clip { speed: f64, duration: f64, once: bool },
}

/// A node's layers while they are being gathered, each with the document
/// path it came from (so a motion's error points into the graph).
struct Flat<C> {
    layers: Vec<LayerSpec<C>>,
    origins: Vec<Path>,
    blends: Vec<(usize, usize)>,
    exit: Option<Exit>,
}

impl<C: ClipSource + Clone> Graph<C> {
    /// Checks `spec` against `clips` (indexed by the spec's clip indices)
    /// and prepares every state's node.
    ///
    /// # Errors
    /// The first rule of docs/graphs.md it breaks, with the path of the
    /// field in the graph document (`nodes/strafe/blend2d/points`).
    pub fn build(spec: GraphSpec, clips: &[C]) -> Result<Graph<C>, GraphError> {
        Graph::build_with(spec, clips, &NodeOptions::default())
    }

    /// [`Graph::build`], every node's motion built with a motion's
    /// `options`: played on a character as a clip motion is
    /// (docs/characters.md: each layer whose clip is of another skeleton
    /// retargeted before the node's layers are mixed, so the graph's poses
    /// are the character's), reporting root motion (docs/motion.md).
    ///
    /// # Errors
    /// As [`Graph::build`]; a clip the character cannot map
    /// (`unmappable_skeleton`) or without the root joint (`no_root_joint`)
    /// at its place in the graph; the options' own refusals at
    /// `retarget/…` and `root_motion/…`.
    pub fn build_with(spec: GraphSpec, clips: &[C], options: &NodeOptions) -> Result<Graph<C>, GraphError> {
        check_parameters(&spec.parameters)?;
        let blends = build_blends(&spec)?;
        let (states, transitions, initial) = match spec.top {
            TopSpec::Machine(machine) => (machine.states, machine.transitions, machine.initial),
            TopSpec::Output(node) => {
                let name = spec.nodes.get(node).map_or_else(String::new, |n| n.name.clone());
                (vec![StateSpec { name, node }], Vec::new(), 0)
            }
        };
        let mut graph = Graph {
            node_names: spec.nodes.iter().map(|n| n.name.clone()).collect(),
            parameters: spec.parameters,
            blends,
            stacks: vec![None; spec.nodes.len()],
            states,
            transitions,
            initial,
        };
        graph.check_machine()?;
        check_cycles(&spec.nodes)?;
        for (s, state) in graph.states.iter().enumerate() {
            if state.node >= spec.nodes.len() {
                return Err(GraphError::new(state_path(&graph.states, s).field("node"), unknown("node", state.node)));
            }
        }
        let builder = Builder { nodes: &spec.nodes, clips, blends: &graph.blends, options };
        for n in 0..spec.nodes.len() {
            graph.stacks[n] = Some(builder.stack(n)?);
        }
        graph.check_skeletons()?;
        Ok(graph)
    }
}

impl<C: ClipSource> Graph<C> {
    /// Every state's node must crossfade into every other's: the same
    /// joints and parameters as the first state's.
    fn check_skeletons(&self) -> Result<(), GraphError> {
        let first = self.stack(self.states[0].node).motion.as_ref();
        for (s, state) in self.states.iter().enumerate() {
            let motion = self.stack(state.node).motion.as_ref();
            let same = motion.skeleton().same_joints(first.skeleton())
                && motion.parameters().names() == first.parameters().names()
                && motion.parameters().widths() == first.parameters().widths();
            if !same {
                return Err(GraphError::new(state_path(&self.states, s).field("node"), K::SkeletonMismatch));
            }
        }
        Ok(())
    }

    /// The output skeleton (the initial state's node's first clip's).
    pub fn skeleton(&self) -> &crate::Skeleton {
        self.stack(self.states[self.initial].node).motion.skeleton()
    }

    /// The most states one tick plays: the current one, and beneath it the
    /// ones transitions in progress fade from (a transition of no duration
    /// still shows its old pose on the tick it fires).
    pub fn max_slots(&self) -> usize {
        match self.transitions.iter().map(|t| t.duration).reduce(f64::max) {
            None => 1,
            Some(d) if d <= 0.0 => 2,
            Some(_) => MAX_FADES + 1,
        }
    }

    /// Joint samples of the costliest tick, a bound to price a graph by
    /// before it plays: the largest state's layers' joints in every slot,
    /// and a mix of the output skeleton per slot above the first.
    pub fn tick_joint_samples(&self) -> u64 {
        let joints =
            |s: &StateSpec| -> u64 { self.stack(s.node).motion.layers().map(|c| c.clip().joint_count() as u64).sum() };
        let largest = self.states.iter().map(joints).max().unwrap_or(0);
        let slots = self.max_slots() as u64;
        largest * slots + (slots - 1) * self.skeleton().len() as u64
    }

    /// The motion each state's node plays, in the states' order (the
    /// initial state's is what a stream names its skeleton and clips by;
    /// every state's has its skeleton and parameters).
    pub fn state_motions(&self) -> impl Iterator<Item = &Arc<Motion<C>>> {
        self.states.iter().map(|s| &self.stack(s.node).motion)
    }

    /// The initial state's node's motion.
    pub fn initial_motion(&self) -> &Arc<Motion<C>> {
        &self.stack(self.states[self.initial].node).motion
    }

    fn stack(&self, node: usize) -> &Stack<C> {
        self.stacks[node].as_ref().expect("every state's node has a stack")
    }
}

impl<C> Graph<C> {
    /// The parameters, in the spec's order.
    pub fn parameters(&self) -> &[ParameterSpec] {
        &self.parameters
    }

    /// Each blend node's name and its number of points, in the document's
    /// order: what a report's `weights` can hold.
    pub fn blend_nodes(&self) -> impl Iterator<Item = (&str, usize)> {
        self.blends.iter().map(|b| (self.node_names[b.node].as_str(), b.points))
    }

    /// The index of parameter `name`.
    pub fn parameter_index(&self, name: &str) -> Option<usize> {
        self.parameters.iter().position(|p| p.name == name)
    }

    /// Node `i`'s name.
    pub fn node_name(&self, i: usize) -> &str {
        &self.node_names[i]
    }

    /// The states' names, in the spec's order (one, the node's name, for an output graph).
    pub fn state_names(&self) -> impl Iterator<Item = &str> {
        self.states.iter().map(|s| s.name.as_str())
    }

    /// The machine's initial state.
    pub fn initial(&self) -> usize {
        self.initial
    }

    /// The triangles of blend2d node `node` (point indices), if it is one.
    pub fn triangles(&self, node: usize) -> Option<Vec<[usize; 3]>> {
        self.blends.iter().find(|b| b.node == node).and_then(|b| match &b.space {
            Space::Plane { plane, .. } => Some(plane.triangles().collect()),
            Space::Line { .. } => None,
        })
    }

    /// Checks the machine's states and transitions.
    fn check_machine(&self) -> Result<(), GraphError> {
        let machine = Path::root().field("machine");
        if self.states.is_empty() {
            return Err(GraphError::new(machine.field("states"), K::NoStates));
        }
        if self.initial >= self.states.len() {
            return Err(GraphError::new(machine.field("initial"), unknown("state", self.initial)));
        }
        for (i, t) in self.transitions.iter().enumerate() {
            let path = machine.clone().field("transitions").index(i);
            if let Some(from) = t.from.filter(|&f| f >= self.states.len()) {
                return Err(GraphError::new(path.field("from"), unknown("state", from)));
            }
            if t.to >= self.states.len() {
                return Err(GraphError::new(path.field("to"), unknown("state", t.to)));
            }
            if !(t.duration.is_finite() && t.duration >= 0.0) {
                return Err(GraphError::new(path.field("duration"), K::BadNumber));
            }
            check_condition(&self.parameters, &t.when, path.field("when"))?;
        }
        Ok(())
    }
}

fn unknown(what: &'static str, index: usize) -> GraphErrorKind {
    K::UnknownReference { what, index }
}

fn state_path(states: &[StateSpec], s: usize) -> Path {
    Path::root().field("machine").field("states").key(&states[s].name)
}

fn node_path(nodes: &[NodeSpec], n: usize) -> Path {
    Path::root().field("nodes").key(&nodes[n].name)
}

fn check_parameters(parameters: &[ParameterSpec]) -> Result<(), GraphError> {
    for p in parameters {
        if let ParameterKind::Float { default, min, max } = p.kind {
            let ordered = !min.is_nan() && !max.is_nan() && min <= default && default <= max;
            if !(default.is_finite() && ordered) {
                let path = Path::root().field("parameters").key(&p.name);
                return Err(GraphError::new(path, K::ParameterRange));
            }
        }
    }
    Ok(())
}

fn check_condition(parameters: &[ParameterSpec], when: &Condition, path: Path) -> Result<(), GraphError> {
    let kind = |p: usize, path: &Path| {
        parameters.get(p).map(|p| p.kind).ok_or_else(|| GraphError::new(path.clone(), unknown("parameter", p)))
    };
    match when {
        Condition::Compare { parameter, op, value } => {
            let at = path.clone().field("parameter");
            match (kind(*parameter, &at)?, value) {
                (ParameterKind::Float { .. }, Value::Float(v)) if v.is_finite() => Ok(()),
                (ParameterKind::Bool { .. }, Value::Bool(_)) if matches!(op, Comparison::Eq | Comparison::Ne) => Ok(()),
                (ParameterKind::Float { .. }, _) => {
                    Err(GraphError::new(path.field(op.as_str()), K::ParameterType { expected: "float" }))
                }
                (ParameterKind::Bool { .. }, _) => Err(GraphError::new(
                    path.field(op.as_str()),
                    K::ParameterType { expected: "float (only eq and ne compare booleans)" },
                )),
                (ParameterKind::Trigger, _) => Err(GraphError::new(
                    at,
                    K::ParameterType { expected: "float or bool (a trigger is tested with `trigger`)" },
                )),
            }
        }
        Condition::Trigger(p) => {
            let at = path.field("trigger");
            match kind(*p, &at)? {
                ParameterKind::Trigger => Ok(()),
                _ => Err(GraphError::new(at, K::ParameterType { expected: "trigger" })),
            }
        }
        Condition::ExitTime(x) if x.is_finite() && *x >= 0.0 => Ok(()),
        Condition::ExitTime(_) => Err(GraphError::new(path.field("exit_time"), K::BadNumber)),
        Condition::All(list) | Condition::Any(list) => {
            let name = if matches!(when, Condition::All(_)) { "all" } else { "any" };
            for (i, c) in list.iter().enumerate() {
                check_condition(parameters, c, path.clone().field(name).index(i))?;
            }
            Ok(())
        }
    }
}

/// Node references (`layers` entries naming nodes) form no cycle: a
/// depth-first walk that meets a node on its own path refuses it.
fn check_cycles(nodes: &[NodeSpec]) -> Result<(), GraphError> {
    fn visit(nodes: &[NodeSpec], n: usize, marks: &mut [u8]) -> Result<(), GraphError> {
        match marks[n] {
            1 => return Err(GraphError::new(node_path(nodes, n), K::NodeCycle)),
            2 => return Ok(()),
            _ => {}
        }
        marks[n] = 1;
        if let NodeKind::Layers(entries) = &nodes[n].kind {
            for (i, entry) in entries.iter().enumerate() {
                let EntrySource::Node(m) = entry.source else { continue };
                if m >= nodes.len() {
                    let path = node_path(nodes, n).field("layers").index(i).field("node");
                    return Err(GraphError::new(path, unknown("node", m)));
                }
                visit(nodes, m, marks)?;
            }
        }
        marks[n] = 2;
        Ok(())
    }
    let mut marks = vec![0u8; nodes.len()];
    (0..nodes.len()).try_for_each(|n| visit(nodes, n, &mut marks))
}

/// One [`Blend`] per blend node, in node order, triangulated once.
fn build_blends(spec: &GraphSpec) -> Result<Vec<Blend>, GraphError> {
    let mut blends = Vec::new();
    for (n, node) in spec.nodes.iter().enumerate() {
        let (space, points) = match &node.kind {
            NodeKind::Blend1d(b) => {
                let path = node_path(&spec.nodes, n).field("blend1d");
                float_axis(&spec.parameters, b.parameter, path.clone().field("parameter"))?;
                let at: Vec<f64> = b.points.iter().map(|p| p.1).collect();
                let line =
                    Line::new(&at).map_err(|d| GraphError::new(path.field("points"), K::DegenerateBlendSpace(d)))?;
                (Space::Line { parameter: b.parameter, line }, b.points.len())
            }
            NodeKind::Blend2d(b) => {
                let path = node_path(&spec.nodes, n).field("blend2d");
                let axes = [
                    plane_axis(&spec.parameters, b.x, path.clone().field("x"))?,
                    plane_axis(&spec.parameters, b.y, path.clone().field("y"))?,
                ];
                let normalise = |at: [f64; 2]| [(at[0] - axes[0].1) / axes[0].2, (at[1] - axes[1].1) / axes[1].2];
                let at: Vec<[f64; 2]> = b.points.iter().map(|p| normalise(p.1)).collect();
                let plane =
                    Plane::new(&at).map_err(|d| GraphError::new(path.field("points"), K::DegenerateBlendSpace(d)))?;
                (Space::Plane { axes, plane }, b.points.len())
            }
            _ => continue,
        };
        blends.push(Blend { node: n, points, space });
    }
    Ok(blends)
}

/// The float parameter's `(min, max)`.
fn float_axis(parameters: &[ParameterSpec], p: usize, path: Path) -> Result<(f64, f64), GraphError> {
    match parameters.get(p).map(|p| p.kind) {
        Some(ParameterKind::Float { min, max, .. }) => Ok((min, max)),
        Some(_) => Err(GraphError::new(path, K::ParameterType { expected: "float" })),
        None => Err(GraphError::new(path, unknown("parameter", p))),
    }
}

/// A blend2d axis: its parameter, `min` and `max − min` (finite, positive).
fn plane_axis(parameters: &[ParameterSpec], p: usize, path: Path) -> Result<(usize, f64, f64), GraphError> {
    let (min, max) = float_axis(parameters, p, path.clone())?;
    let span = max - min;
    if !(min.is_finite() && max.is_finite() && span > 0.0 && span.is_finite()) {
        return Err(GraphError::new(path, K::UnboundedAxis));
    }
    Ok((p, min, span))
}

/// What a motion over a graph builds every node's motion with: the
/// character it plays on and how its clips are retargeted onto it, and its
/// root motion (a motion's `character`, `retarget` and `root_motion`).
#[derive(Debug, Clone, Default)]
pub struct NodeOptions {
    pub character: Option<Arc<CharacterSpec>>,
    pub retarget: RetargetSpec,
    pub root_motion: Option<RootMotionSpec>,
}

/// What turning nodes into layer stacks needs.
struct Builder<'a, C> {
    nodes: &'a [NodeSpec],
    clips: &'a [C],
    blends: &'a [Blend],
    options: &'a NodeOptions,
}

impl<C: ClipSource + Clone> Builder<'_, C> {
    /// Node `n` as one motion.
    fn stack(&self, n: usize) -> Result<Stack<C>, GraphError> {
        let mut flat = Flat { layers: Vec::new(), origins: Vec::new(), blends: Vec::new(), exit: None };
        let mut visiting = vec![false; self.nodes.len()];
        self.flatten(n, &mut visiting, &mut flat)?;
        let weights = flat.layers.iter().map(|l| l.weight).collect();
        let exit = flat.exit.unwrap_or(Exit::Phase);
        let NodeOptions { character, retarget, root_motion } = self.options.clone();
        let spec = MotionSpec { layers: flat.layers, character, retarget, root_motion, ..MotionSpec::default() };
        let motion = Motion::build(spec).map_err(|e| motion_error(e, &flat.origins, node_path(self.nodes, n)))?;
        Ok(Stack { motion: Arc::new(motion), weights, blends: flat.blends, exit })
    }

    /// Appends node `n`'s layers to `flat`.
    fn flatten(&self, n: usize, visiting: &mut [bool], flat: &mut Flat<C>) -> Result<(), GraphError> {
        if visiting[n] {
            return Err(GraphError::new(node_path(self.nodes, n), K::NodeCycle));
        }
        visiting[n] = true;
        let path = node_path(self.nodes, n);
        match &self.nodes[n].kind {
            NodeKind::Clip(c) => {
                let layer = self.clip_layer(c, path.clone())?;
                flat.push(layer, path, self.clip_exit(c));
            }
            NodeKind::Blend1d(b) => {
                let points: Vec<usize> = b.points.iter().map(|p| p.0).collect();
                self.blend_layers(n, &points, b.sync, path.field("blend1d"), flat)?;
            }
            NodeKind::Blend2d(b) => {
                let points: Vec<usize> = b.points.iter().map(|p| p.0).collect();
                self.blend_layers(n, &points, b.sync, path.field("blend2d"), flat)?;
            }
            NodeKind::Layers(entries) => {
                for (i, entry) in entries.iter().enumerate() {
                    self.entry_layers(i, entry, path.clone().field("layers").index(i), visiting, flat)?;
                }
            }
        }
        visiting[n] = false;
        Ok(())
    }

    /// A blend's points as layers (weights set per tick), in one sync
    /// group named after the blend's place in the stack unless unsynced.
    fn blend_layers(
        &self,
        n: usize,
        points: &[usize],
        sync: bool,
        path: Path,
        flat: &mut Flat<C>,
    ) -> Result<(), GraphError> {
        let blend = self.blends.iter().position(|b| b.node == n).expect("every blend node has a blend");
        let first = flat.layers.len();
        flat.blends.push((blend, first));
        let group = sync.then(|| format!("{}#{first}", self.nodes[n].name));
        for (i, &clip) in points.iter().enumerate() {
            let at = path.clone().field("points").index(i);
            let spec = ClipNodeSpec::new(clip);
            let layer = LayerSpec { sync: group.clone(), ..self.clip_layer(&spec, at.clone().field("clip"))? };
            let exit = if sync { Exit::Phase } else { self.clip_exit(&spec) };
            flat.push(layer, at, exit);
        }
        Ok(())
    }

    /// Entry `i` of a `layers` node: a clip (or clip node) as one layer, or
    /// a first, full, unmasked blend entry naming a blend or layers node,
    /// whose layers then start the stack (beneath it is the rest pose, which
    /// such a stack covers, so this is exactly that node's pose).
    fn entry_layers(
        &self,
        i: usize,
        entry: &EntrySpec,
        path: Path,
        visiting: &mut [bool],
        flat: &mut Flat<C>,
    ) -> Result<(), GraphError> {
        let clip = match entry.source {
            EntrySource::Clip(c) => c,
            EntrySource::Node(m) => match &self.nodes[m].kind {
                NodeKind::Clip(c) => *c,
                _ => {
                    let stackable =
                        i == 0 && entry.weight == 1.0 && entry.mode == LayerMode::Blend && entry.mask.is_none();
                    if !stackable {
                        return Err(GraphError::new(path.field("node"), K::EntryNotStackable));
                    }
                    return self.flatten(m, visiting, flat);
                }
            },
        };
        let layer = LayerSpec {
            weight: entry.weight,
            mode: entry.mode,
            mask: entry.mask.clone(),
            ..self.clip_layer(&clip, path.clone().field("clip"))?
        };
        flat.push(layer, path, self.clip_exit(&clip));
        Ok(())
    }

    /// A clip played from its start at the node's speed.
    fn clip_layer(&self, c: &ClipNodeSpec, path: Path) -> Result<LayerSpec<C>, GraphError> {
        let clip = self.clips.get(c.clip).ok_or_else(|| GraphError::new(path, unknown("clip", c.clip)))?;
        let start = f64::from(clip.clip().range().start());
        Ok(LayerSpec { offset: start, speed: c.speed, playback: c.playback, ..LayerSpec::new(clip.clone()) })
    }

    fn clip_exit(&self, c: &ClipNodeSpec) -> Exit {
        let clip = self.clips[c.clip].clip();
        let playback = c.playback.unwrap_or_else(|| clip.playback());
        Exit::Clip { speed: c.speed.abs(), duration: clip.range().duration(), once: playback == Playback::Once }
    }
}

impl<C> Flat<C> {
    fn push(&mut self, layer: LayerSpec<C>, origin: Path, exit: Exit) {
        self.exit.get_or_insert(exit);
        self.layers.push(layer);
        self.origins.push(origin);
    }
}

/// A motion's error with its `layers/i/…` path put at layer `i`'s place in
/// the graph document, its `retarget/…` and `root_motion/…` paths kept
/// (the options are the caller's, not the graph's), the node's own for
/// anything else.
fn motion_error(e: crate::MotionError, origins: &[Path], node: Path) -> GraphError {
    if matches!(e.path.0.first(), Some(Step::Field("retarget" | "root_motion"))) {
        return GraphError::new(e.path, K::Motion(e.kind));
    }
    let mut steps = e.path.0.into_iter();
    let path = match (steps.next(), steps.next()) {
        (Some(Step::Field("layers")), Some(Step::Index(i))) if i < origins.len() => {
            let mut path = origins[i].clone();
            path.0.extend(steps);
            path
        }
        _ => node,
    };
    GraphError::new(path, K::Motion(e.kind))
}

impl Exit {
    /// Cycles played at node time `tau` with sync-group `phases`.
    fn cycles(self, tau: f64, phases: &[f64]) -> f64 {
        match self {
            Exit::Phase => phases.first().copied().unwrap_or(0.0),
            Exit::Clip { duration, once, .. } if duration <= 0.0 => {
                if once {
                    1.0
                } else {
                    f64::INFINITY
                }
            }
            Exit::Clip { speed, duration, once } => {
                let cycles = speed * tau / duration;
                if once { cycles.min(1.0) } else { cycles }
            }
        }
    }
}

impl Blend {
    /// One weight per point for the current parameter `values`.
    fn weights(&self, values: &[f64], out: &mut [f64]) {
        match &self.space {
            Space::Line { parameter, line } => line.weights(values[*parameter], out),
            Space::Plane { axes, plane } => {
                let at = |(p, min, span): (usize, f64, f64)| (values[p] - min) / span;
                plane.weights([at(axes[0]), at(axes[1])], out);
            }
        }
    }
}
