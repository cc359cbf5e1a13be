//! The authoring form of a graph (docs/graphs.md), with every reference an
//! index: parameters, nodes and states by position, clips by position in
//! the slice the caller hands to [`Graph::build`](super::Graph::build). The
//! wire layer resolves names to indices; names stay here for reports and
//! error paths.

use crate::motion::{LayerMode, MaskSpec};
use crate::{Ease, Playback};

/// Parameters, nodes, and what plays: a state machine or one node.
#[derive(Debug, Clone)]
pub struct GraphSpec {
    pub parameters: Vec<ParameterSpec>,
    pub nodes: Vec<NodeSpec>,
    pub top: TopSpec,
}

#[derive(Debug, Clone)]
pub struct ParameterSpec {
    pub name: String,
    pub kind: ParameterKind,
}

/// A parameter's type and range; a trigger is true for one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParameterKind {
    /// `min`/`max` may be infinite, except for a blend2d axis.
    Float {
        default: f64,
        min: f64,
        max: f64,
    },
    Bool {
        default: bool,
    },
    Trigger,
}

/// A node and its name (the key of `nodes` in the document).
#[derive(Debug, Clone)]
pub struct NodeSpec {
    pub name: String,
    pub kind: NodeKind,
}

#[derive(Debug, Clone)]
pub enum NodeKind {
    Clip(ClipNodeSpec),
    Blend1d(Blend1dSpec),
    Blend2d(Blend2dSpec),
    Layers(Vec<EntrySpec>),
}

/// A clip played from its start: clip time `playback(start + speed·τ)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClipNodeSpec {
    pub clip: usize,
    /// `None`: the clip's own.
    pub playback: Option<Playback>,
    pub speed: f64,
}

impl ClipNodeSpec {
    /// Clip `clip` at speed 1 with its own playback.
    pub fn new(clip: usize) -> Self {
        ClipNodeSpec { clip, playback: None, speed: 1.0 }
    }
}

/// Clips along one float parameter.
#[derive(Debug, Clone)]
pub struct Blend1dSpec {
    pub parameter: usize,
    /// `(clip, at)`, in any order.
    pub points: Vec<(usize, f64)>,
    /// Whether the children share one sync group (default true).
    pub sync: bool,
}

/// Clips on the plane of two float parameters.
#[derive(Debug, Clone)]
pub struct Blend2dSpec {
    pub x: usize,
    pub y: usize,
    /// `(clip, [x, y])` in parameter units.
    pub points: Vec<(usize, [f64; 2])>,
    pub sync: bool,
}

/// One entry of a `layers` node: a clip, or another node, with a motion
/// layer's fields (docs/motion.md).
#[derive(Debug, Clone)]
pub struct EntrySpec {
    pub source: EntrySource,
    pub weight: f32,
    pub mode: LayerMode,
    pub mask: Option<MaskSpec>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EntrySource {
    Clip(ClipNodeSpec),
    Node(usize),
}

#[derive(Debug, Clone)]
pub enum TopSpec {
    Machine(MachineSpec),
    /// One node, always playing (`"output": node`).
    Output(usize),
}

#[derive(Debug, Clone)]
pub struct MachineSpec {
    pub initial: usize,
    pub states: Vec<StateSpec>,
    /// Tested in this order.
    pub transitions: Vec<TransitionSpec>,
}

#[derive(Debug, Clone)]
pub struct StateSpec {
    pub name: String,
    pub node: usize,
}

#[derive(Debug, Clone)]
pub struct TransitionSpec {
    /// `None`: `*`, any state.
    pub from: Option<usize>,
    pub to: usize,
    pub when: Condition,
    pub duration: f64,
    pub ease: Ease,
    pub interruptible: bool,
}

/// When a transition fires (docs/graphs.md, “Conditions”).
#[derive(Debug, Clone, PartialEq)]
pub enum Condition {
    Compare {
        parameter: usize,
        op: Comparison,
        value: Value,
    },
    /// The trigger was set this tick (and is consumed when the transition fires).
    Trigger(usize),
    /// The current state's node has played at least this many cycles.
    ExitTime(f64),
    All(Vec<Condition>),
    Any(Vec<Condition>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Comparison {
    Eq,
    Ne,
    Gt,
    Ge,
    Lt,
    Le,
}

impl Comparison {
    /// The name documents use (`eq`, `ge`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            Comparison::Eq => "eq",
            Comparison::Ne => "ne",
            Comparison::Gt => "gt",
            Comparison::Ge => "ge",
            Comparison::Lt => "lt",
            Comparison::Le => "le",
        }
    }

    /// Whether `a op b` holds.
    pub fn holds(self, a: f64, b: f64) -> bool {
        match self {
            Comparison::Eq => a == b,
            Comparison::Ne => a != b,
            Comparison::Gt => a > b,
            Comparison::Ge => a >= b,
            Comparison::Lt => a < b,
            Comparison::Le => a <= b,
        }
    }
}

/// A parameter value: floats for float parameters, booleans for bool
/// parameters and triggers (`true` sets a trigger).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    Float(f64),
    Bool(bool),
}
