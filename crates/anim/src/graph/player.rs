//! Playing a graph tick by tick (docs/graphs.md, “Each tick”).
//!
//! A [`GraphPlayer`] holds the parameter values and a chain of *slots*,
//! bottom to top: the state playing before each transition still in
//! progress, then the current state on top. Each slot is one state's node
//! at its own node time with its own sync-group phases; a transition that
//! fires puts a new slot on top at node time 0 and keeps everything beneath
//! advancing, and the pose is the crossfade (docs/motion.md) of each slot over the mix
//! beneath it at that transition's `α` — so a transition that interrupts
//! another fades from the fade in progress and the pose never jumps, as a
//! motion player's crossfades do. At most [`MAX_FADES`] transitions are in
//! progress; one more finishes the oldest at once.
//!
//! Every buffer is sized in [`GraphPlayer::new`] for the largest node, so a
//! tick allocates nothing.

use std::fmt;
use std::sync::Arc;

use super::{Condition, Graph, ParameterKind, Stack, Value};
use crate::motion::{ClipSource, MAX_FADES, MotionOptions, MotionSampler, Planar, RootMotion, mix};
use crate::{Pose, Space};

/// A graph playing; see the module doc.
#[derive(Debug, Clone)]
pub struct GraphPlayer<C> {
    graph: Arc<Graph<C>>,
    /// Per parameter: a float's value, or 1/0 for a bool or a trigger.
    values: Vec<f64>,
    ticks: u64,
    current: usize,
    slots: Vec<Slot>,
    /// Slot indices, bottom to top.
    chain: Vec<usize>,
    /// Each blend's point weights this tick, from `offsets[b]` on.
    weights: Vec<f64>,
    offsets: Vec<usize>,
    /// Which blends a slot played this tick.
    evaluated: Vec<bool>,
    mixed: Pose,
    spare: Pose,
    /// The last evaluated tick's root motion, when the nodes report it.
    root: Option<RootMotion>,
}

/// One state playing: its node time, phases and live layer weights.
#[derive(Debug, Clone)]
struct Slot {
    state: usize,
    tau: f64,
    phases: Vec<f64>,
    layer_weights: Vec<f32>,
    sampler: MotionSampler,
    fade: Option<FadeProgress>,
}

/// The transition that put a slot on top, and how far it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FadeProgress {
    /// Index into the machine's transitions.
    pub transition: usize,
    /// The state that was current when it fired.
    pub from: usize,
    /// Seconds since it fired.
    pub elapsed: f64,
}

/// One slot of a [`GraphState`].
#[derive(Debug, Clone, PartialEq)]
pub struct SlotState {
    pub state: usize,
    pub tau: f64,
    pub phases: Vec<f64>,
    pub fade: Option<FadeProgress>,
}

/// Everything a [`GraphPlayer`] carries from one tick to the next (a
/// broadcast checkpoint): parameter values, ticks played, the current
/// state, the slots bottom to top and the last tick's root motion. Poses
/// and weights are computed afresh.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphState {
    pub values: Vec<f64>,
    pub ticks: u64,
    pub current: usize,
    pub chain: Vec<SlotState>,
    pub root: Option<RootMotion>,
}

/// Why a parameter value or a state was refused.
#[derive(Debug, Clone, PartialEq)]
pub enum SetError {
    UnknownParameter(usize),
    /// A float for a bool or trigger, or a boolean for a float.
    WrongType {
        expected: &'static str,
    },
    NonFinite,
    /// A float outside its parameter's range (refused by
    /// [`Graph::check_value`]; [`GraphPlayer::set`] clamps instead).
    OutOfRange {
        min: f64,
        max: f64,
    },
    /// A [`GraphState`] that does not fit the graph.
    State(&'static str),
}

/// What a tick did (docs/graphs.md, “report”).
#[derive(Debug, Clone, Copy)]
pub struct GraphReport<'a, C> {
    player: &'a GraphPlayer<C>,
}

/// The transition in progress: its states and its `α` this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TransitionReport<'a> {
    pub from: &'a str,
    pub to: &'a str,
    pub alpha: f32,
}

impl<C: ClipSource> GraphPlayer<C> {
    /// A player at the machine's initial state with every parameter at its
    /// default, its buffers sized for the graph's largest node.
    pub fn new(graph: Arc<Graph<C>>) -> Self {
        let values = graph.parameters.iter().map(|p| default_value(p.kind)).collect();
        let mut offsets = Vec::with_capacity(graph.blends.len());
        let mut total = 0;
        for b in &graph.blends {
            offsets.push(total);
            total += b.points;
        }
        let stacks = || graph.stacks.iter().flatten();
        let layers = stacks().map(|s| s.weights.len()).max().unwrap_or(0);
        let groups = stacks().map(|s| s.motion.sync_group_count()).max().unwrap_or(0);
        let slot = |state| Slot {
            state,
            tau: 0.0,
            phases: Vec::with_capacity(groups),
            layer_weights: vec![0.0; layers],
            sampler: MotionSampler::new(),
            fade: None,
        };
        let mut player = GraphPlayer {
            values,
            ticks: 0,
            current: graph.initial,
            slots: (0..=MAX_FADES).map(|_| slot(graph.initial)).collect(),
            chain: Vec::with_capacity(MAX_FADES + 1),
            weights: vec![0.0; total],
            offsets,
            evaluated: vec![false; graph.blends.len()],
            mixed: Pose::default(),
            spare: Pose::default(),
            root: None,
            graph,
        };
        player.warm();
        player.blend_weights();
        player.start(0, player.current, None);
        player.chain.push(0);
        player
    }

    /// Samples every node once into every slot (at partial and full
    /// weights, so every layer samples) and mixes, so each buffer has the
    /// largest size a tick can need.
    fn warm(&mut self) {
        let options = MotionOptions { space: Space::Local, ..MotionOptions::default() };
        for slot in &mut self.slots {
            for stack in self.graph.stacks.iter().flatten() {
                let n = stack.weights.len();
                stack.motion.phases_at(0.0, &stack.weights, &mut slot.phases);
                for w in [0.5, 1.0] {
                    slot.layer_weights[..n].fill(w);
                    stack.motion.sample_with(0.0, &slot.phases, &slot.layer_weights[..n], &options, &mut slot.sampler);
                }
            }
        }
        let (a, b) = (self.slots[0].sampler.local(), self.slots[1].sampler.local());
        mix(a, b, 0.5, &mut self.mixed);
        mix(a, b, 0.5, &mut self.spare);
    }

    /// Sets parameter `parameter` from the next tick's step 1 on: floats
    /// are clamped to `[min, max]`; `true` sets a trigger for one tick.
    ///
    /// # Errors
    /// No such parameter, a value of the other type, a non-finite float.
    pub fn set(&mut self, parameter: usize, value: Value) -> Result<(), SetError> {
        let kind = self.graph.parameters.get(parameter).ok_or(SetError::UnknownParameter(parameter))?.kind;
        self.values[parameter] = match (kind, value) {
            (ParameterKind::Float { min, max, .. }, Value::Float(v)) if v.is_finite() => v.clamp(min, max),
            (ParameterKind::Float { .. }, Value::Float(_)) => return Err(SetError::NonFinite),
            (ParameterKind::Float { .. }, Value::Bool(_)) => return Err(SetError::WrongType { expected: "float" }),
            (ParameterKind::Bool { .. }, Value::Bool(b)) => f64::from(u8::from(b)),
            (ParameterKind::Trigger, Value::Bool(b)) => f64::from(u8::from(b)),
            (_, Value::Float(_)) => return Err(SetError::WrongType { expected: "boolean" }),
        };
        Ok(())
    }

    /// One tick, `dt` seconds after the previous one (the first tick shows
    /// node time 0 whatever `dt`; a `dt` that is not a positive number
    /// advances nothing). Parameters set before it are in effect.
    pub fn tick(&mut self, dt: f64) {
        self.step(dt);
        self.evaluate();
    }

    /// A tick without its pose (steps 1–5): for ticks nobody sees, whose
    /// transitions depend on parameters and node times only. The report's
    /// weights and the pose stay those of the last evaluated tick.
    pub fn step(&mut self, dt: f64) {
        let dt = if self.ticks == 0 || !(dt.is_finite() && dt > 0.0) { 0.0 } else { dt };
        self.blend_weights();
        for i in 0..self.chain.len() {
            self.set_layer_weights(self.chain[i]);
        }
        if dt > 0.0 {
            self.advance(dt);
        }
        self.complete();
        self.test_transitions();
        for (value, p) in self.values.iter_mut().zip(&self.graph.parameters) {
            if p.kind == ParameterKind::Trigger {
                *value = 0.0;
            }
        }
        self.ticks += 1;
    }

    /// Step 2: node times, phases (at the weights now in effect) and
    /// transitions' elapsed time move on by `dt`.
    fn advance(&mut self, dt: f64) {
        for &s in &self.chain {
            let slot = &mut self.slots[s];
            let stack = self.graph.state_stack(slot.state);
            slot.tau += dt;
            let n = stack.weights.len();
            stack.motion.advance_phases(&mut slot.phases, dt, &slot.layer_weights[..n]);
            if let Some(fade) = slot.fade.as_mut() {
                fade.elapsed += dt;
            }
        }
    }

    /// Step 3: the newest transition whose elapsed time reached its duration
    /// completes, and what it faded from leaves the chain.
    fn complete(&mut self) {
        let done = (1..self.chain.len()).rev().find(|&i| {
            let fade = self.slots[self.chain[i]].fade.expect("a slot above the bottom has a fade");
            fade.elapsed >= self.graph.transitions[fade.transition].duration
        });
        if let Some(i) = done {
            self.chain.drain(..i);
            self.slots[self.chain[0]].fade = None;
        }
    }

    /// Step 4: unless a non-interruptible transition is in progress, the
    /// first transition from the current state (or `*`) whose condition
    /// holds fires.
    fn test_transitions(&mut self) {
        let top = &self.slots[*self.chain.last().expect("the chain is never empty")];
        if top.fade.is_some_and(|f| !self.graph.transitions[f.transition].interruptible) {
            return;
        }
        let fired = self
            .graph
            .transitions
            .iter()
            .position(|t| t.from.is_none_or(|f| f == self.current) && t.to != self.current && self.holds(&t.when));
        let Some(t) = fired else { return };
        let graph = Arc::clone(&self.graph);
        consume(&graph.transitions[t].when, &mut self.values);
        if self.chain.len() == self.slots.len() {
            self.chain.remove(0);
            self.slots[self.chain[0]].fade = None;
        }
        let free = (0..self.slots.len()).find(|s| !self.chain.contains(s)).expect("a slot is free");
        let fade = FadeProgress { transition: t, from: self.current, elapsed: 0.0 };
        self.current = graph.transitions[t].to;
        self.start(free, self.current, Some(fade));
        self.chain.push(free);
    }

    /// Puts `state` in slot `s` at node time 0, its root motion from there.
    fn start(&mut self, s: usize, state: usize, fade: Option<FadeProgress>) {
        let slot = &mut self.slots[s];
        (slot.state, slot.tau, slot.fade) = (state, 0.0, fade);
        slot.sampler.restart_root();
        self.set_layer_weights(s);
        let slot = &mut self.slots[s];
        let stack = self.graph.state_stack(state);
        stack.motion.phases_at(0.0, &slot.layer_weights[..stack.weights.len()], &mut slot.phases);
    }

    /// Whether `when` holds now (for the current state's top slot).
    fn holds(&self, when: &Condition) -> bool {
        match when {
            Condition::Compare { parameter, op, value } => {
                let v = match value {
                    Value::Float(v) => *v,
                    Value::Bool(b) => f64::from(u8::from(*b)),
                };
                op.holds(self.values[*parameter], v)
            }
            Condition::Trigger(p) => self.values[*p] != 0.0,
            Condition::ExitTime(x) => {
                let top = &self.slots[*self.chain.last().expect("the chain is never empty")];
                self.graph.state_stack(top.state).exit.cycles(top.tau, &top.phases) >= *x
            }
            Condition::All(list) => list.iter().all(|c| self.holds(c)),
            Condition::Any(list) => list.iter().any(|c| self.holds(c)),
        }
    }

    /// Each blend's point weights for the current parameter values.
    fn blend_weights(&mut self) {
        for (b, blend) in self.graph.blends.iter().enumerate() {
            let at = self.offsets[b];
            blend.weights(&self.values, &mut self.weights[at..at + blend.points]);
        }
    }

    /// Slot `s`'s layer weights: its stack's own, with each blend's points
    /// as the layer stack `w_k / Σ_{j≤k} w_j`.
    fn set_layer_weights(&mut self, s: usize) {
        let slot = &mut self.slots[s];
        let stack: &Stack<C> = self.graph.state_stack(slot.state);
        slot.layer_weights[..stack.weights.len()].copy_from_slice(&stack.weights);
        for &(b, first) in &stack.blends {
            let at = self.offsets[b];
            let points = &self.weights[at..at + self.graph.blends[b].points];
            let mut sum = 0.0;
            for (k, w) in points.iter().enumerate() {
                sum += w;
                slot.layer_weights[first + k] = if sum > 0.0 { (w / sum) as f32 } else { 0.0 };
            }
        }
    }

    /// Step 6: every slot's pose, then each mixed over the ones beneath.
    fn evaluate(&mut self) {
        let options = MotionOptions { space: Space::Local, ..MotionOptions::default() };
        self.evaluated.fill(false);
        for &s in &self.chain {
            let slot = &mut self.slots[s];
            let stack = self.graph.state_stack(slot.state);
            let n = stack.weights.len();
            stack.motion.sample_with(slot.tau, &slot.phases, &slot.layer_weights[..n], &options, &mut slot.sampler);
            for &(b, _) in &stack.blends {
                self.evaluated[b] = true;
            }
        }
        for i in 1..self.chain.len() {
            let alpha = self.alpha(self.chain[i]);
            let top = self.slots[self.chain[i]].sampler.local();
            if i == 1 {
                mix(self.slots[self.chain[0]].sampler.local(), top, alpha, &mut self.mixed);
            } else {
                std::mem::swap(&mut self.mixed, &mut self.spare);
                mix(&self.spare, top, alpha, &mut self.mixed);
            }
        }
        self.layer_root_motion();
    }

    /// The tick's root motion (docs/graphs.md, “Root motion”): each slot's
    /// delta since its last evaluated tick (its layers' deltas weighted as
    /// its pose, a seam crossed counting whole cycles), crossfaded up the
    /// chain at each transition's `α` as the poses are; and the total.
    fn layer_root_motion(&mut self) {
        let Some(up) = self.graph.initial_motion().root_up() else { return };
        let delta_of = |s: usize| self.slots[s].sampler.root_motion().map_or(Planar::IDENTITY, |r| r.delta);
        let mut delta = delta_of(self.chain[0]);
        for &s in &self.chain[1..] {
            delta = delta.lerp(delta_of(s), f64::from(self.alpha(s)));
        }
        let total = self.root.map_or(Planar::IDENTITY, |r| r.total).then(delta, up);
        self.root = Some(RootMotion { delta, total });
    }
}

impl<C> GraphPlayer<C> {
    /// The graph playing.
    pub fn graph(&self) -> &Arc<Graph<C>> {
        &self.graph
    }

    /// The current state (a transition's target while it is in progress).
    pub fn current(&self) -> usize {
        self.current
    }

    /// Ticks played.
    pub fn ticks(&self) -> u64 {
        self.ticks
    }

    /// The parameter values (a bool or trigger as 1 or 0).
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// The last tick's local pose.
    pub fn pose(&self) -> &Pose {
        if self.chain.len() == 1 { self.slots[self.chain[0]].sampler.local() } else { &self.mixed }
    }

    /// The last evaluated tick's root motion: its delta since the tick
    /// evaluated before it, and the total since the first; `None` unless
    /// the nodes report root motion.
    pub fn root_motion(&self) -> Option<RootMotion> {
        self.root
    }

    /// The last tick's state, transition and blend weights.
    pub fn report(&self) -> GraphReport<'_, C> {
        GraphReport { player: self }
    }

    /// Slot `s`'s transition `α` (0 on the tick it fired).
    fn alpha(&self, s: usize) -> f32 {
        let Some(fade) = self.slots[s].fade else { return 1.0 };
        let t = &self.graph.transitions[fade.transition];
        if t.duration <= 0.0 {
            return if fade.elapsed > 0.0 { 1.0 } else { 0.0 };
        }
        t.ease.apply((fade.elapsed / t.duration).min(1.0)) as f32
    }

    /// What the player carries to the next tick (see [`GraphState`]).
    pub fn state(&self) -> GraphState {
        let slot = |&s: &usize| {
            let slot = &self.slots[s];
            SlotState { state: slot.state, tau: slot.tau, phases: slot.phases.clone(), fade: slot.fade }
        };
        GraphState {
            values: self.values.clone(),
            ticks: self.ticks,
            current: self.current,
            chain: self.chain.iter().map(slot).collect(),
            root: self.root,
        }
    }
}

impl<C: ClipSource> GraphPlayer<C> {
    /// A player of `graph` that steps on from `state` exactly as the one it
    /// was taken from would, showing (pose and report) the tick it was taken after.
    ///
    /// # Errors
    /// A state that does not fit the graph (lengths, indices).
    pub fn from_state(graph: Arc<Graph<C>>, state: GraphState) -> Result<Self, SetError> {
        let mut player = GraphPlayer::new(graph);
        let graph = Arc::clone(&player.graph);
        if state.values.len() != graph.parameters.len() {
            return Err(SetError::State("one value per parameter"));
        }
        if state.chain.is_empty() || state.chain.len() > player.slots.len() {
            return Err(SetError::State("between one slot and one more than the most transitions in progress"));
        }
        if state.current >= graph.states.len() {
            return Err(SetError::State("no such current state"));
        }
        player.chain.clear();
        for (i, s) in state.chain.into_iter().enumerate() {
            if s.state >= graph.states.len() {
                return Err(SetError::State("no such state in a slot"));
            }
            if s.phases.len() != graph.state_stack(s.state).motion.sync_group_count() {
                return Err(SetError::State("one phase per sync group of the slot's node"));
            }
            let fits = |f: FadeProgress| f.transition < graph.transitions.len() && f.from < graph.states.len();
            if (i == 0) != s.fade.is_none() || s.fade.is_some_and(|f| !fits(f)) {
                return Err(SetError::State("a fade on every slot but the bottom one"));
            }
            let slot = &mut player.slots[i];
            (slot.state, slot.tau, slot.fade) = (s.state, s.tau, s.fade);
            slot.phases.clear();
            slot.phases.extend_from_slice(&s.phases);
            player.chain.push(i);
        }
        (player.values, player.ticks, player.current) = (state.values, state.ticks, state.current);
        player.show_again();
        // The slots' roots are where that tick put them, so the next delta starts there.
        player.root = state.root;
        Ok(player)
    }

    /// The last tick's blend weights, layer weights and pose computed again
    /// from the state (nothing advances), so that a restored player shows
    /// the tick it was taken after — a paused stream shows it again.
    fn show_again(&mut self) {
        self.blend_weights();
        for i in 0..self.chain.len() {
            self.set_layer_weights(self.chain[i]);
        }
        self.evaluate();
    }
}

impl<C> Graph<C> {
    /// `value` if parameter `parameter` takes it as it is: what a client
    /// sends is checked, not corrected (a float outside `[min, max]` is
    /// refused here, where [`GraphPlayer::set`] would clamp it).
    ///
    /// # Errors
    /// As [`GraphPlayer::set`], and [`SetError::OutOfRange`].
    pub fn check_value(&self, parameter: usize, value: Value) -> Result<Value, SetError> {
        let kind = self.parameters.get(parameter).ok_or(SetError::UnknownParameter(parameter))?.kind;
        match (kind, value) {
            (ParameterKind::Float { min, max, .. }, Value::Float(v)) if v.is_finite() && !(min <= v && v <= max) => {
                Err(SetError::OutOfRange { min, max })
            }
            (ParameterKind::Float { .. }, Value::Float(v)) if !v.is_finite() => Err(SetError::NonFinite),
            (ParameterKind::Float { .. }, Value::Float(_)) => Ok(value),
            (ParameterKind::Float { .. }, Value::Bool(_)) => Err(SetError::WrongType { expected: "float" }),
            (_, Value::Bool(_)) => Ok(value),
            (_, Value::Float(_)) => Err(SetError::WrongType { expected: "boolean" }),
        }
    }

    fn state_stack(&self, state: usize) -> &Stack<C> {
        self.stacks[self.states[state].node].as_ref().expect("every node has a stack")
    }
}

impl<'a, C> GraphReport<'a, C> {
    /// The current state's name.
    pub fn state(&self) -> &'a str {
        &self.player.graph.states[self.player.current].name
    }

    /// The transition in progress, if any.
    pub fn transition(&self) -> Option<TransitionReport<'a>> {
        let states = &self.player.graph.states[..];
        let (from, to, alpha) = self.indices().1?;
        Some(TransitionReport { from: &states[from].name, to: &states[to].name, alpha })
    }

    /// The report by index, as compact frames send it (docs/compact-frames.md,
    /// “The graph report section”): the current state's index in
    /// [`Graph::state_names`](super::Graph::state_names), and the
    /// transition's `(from, to, α)` likewise.
    pub fn indices(&self) -> (usize, Option<(usize, usize, f32)>) {
        let player = self.player;
        let transition = player.chain.last().and_then(|&top| {
            let fade = player.slots[top].fade?;
            Some((fade.from, player.slots[top].state, player.alpha(top)))
        });
        (player.current, transition)
    }

    /// Each blend node a slot played this tick, by its index in
    /// [`Graph::blend_nodes`](super::Graph::blend_nodes), with one weight per point.
    pub fn indexed_weights(&self) -> impl Iterator<Item = (usize, &'a [f64])> + 'a {
        let player = self.player;
        player.graph.blends.iter().enumerate().filter(move |(b, _)| player.evaluated[*b]).map(move |(b, blend)| {
            let at = player.offsets[b];
            (b, &player.weights[at..at + blend.points])
        })
    }

    /// Each blend node a slot played this tick: its name and one weight per point.
    pub fn weights(&self) -> impl Iterator<Item = (&'a str, &'a [f64])> + 'a {
        let graph = &*self.player.graph;
        self.indexed_weights().map(move |(b, w)| (graph.node_names[graph.blends[b].node].as_str(), w))
    }
}

fn default_value(kind: ParameterKind) -> f64 {
    match kind {
        ParameterKind::Float { default, .. } => default,
        ParameterKind::Bool { default } => f64::from(u8::from(default)),
        ParameterKind::Trigger => 0.0,
    }
}

/// Clears the triggers `when` tests (its transition fired).
fn consume(when: &Condition, values: &mut [f64]) {
    match when {
        Condition::Trigger(p) => values[*p] = 0.0,
        Condition::All(list) | Condition::Any(list) => list.iter().for_each(|c| consume(c, values)),
        _ => {}
    }
}

impl fmt::Display for SetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SetError::UnknownParameter(p) => write!(f, "parameter {p} does not exist"),
            SetError::WrongType { expected } => write!(f, "the parameter takes a {expected}"),
            SetError::NonFinite => write!(f, "value is not a finite number"),
            SetError::OutOfRange { min, max } => write!(f, "the value is outside the parameter's range [{min}, {max}]"),
            SetError::State(what) => write!(f, "a graph state that does not fit its graph: {what}"),
        }
    }
}

impl std::error::Error for SetError {}
