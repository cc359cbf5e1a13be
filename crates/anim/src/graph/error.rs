//! Why a [`GraphSpec`](super::GraphSpec) was refused, and where (a path
//! relative to the graph document, e.g. `nodes/strafe/blend2d/points`).

use std::fmt;

use crate::Path;
use crate::motion::MotionErrorKind;

/// A refused graph: the place and the rule.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphError {
    pub path: Path,
    pub kind: GraphErrorKind,
}

impl GraphError {
    pub(crate) fn new(path: Path, kind: GraphErrorKind) -> Self {
        GraphError { path, kind }
    }
}

/// Why a blend space cannot give weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Degeneracy {
    /// No points at all.
    Empty,
    /// Two points at the same place (indices into the node's points).
    Coincident(usize, usize),
    /// A 2D blend whose points lie on one line (or has fewer than three).
    Collinear,
}

/// The rules of docs/graphs.md a graph can break.
#[derive(Debug, Clone, PartialEq)]
pub enum GraphErrorKind {
    /// An index that names nothing (a parameter, node, state or clip).
    UnknownReference {
        what: &'static str,
        index: usize,
    },
    /// A parameter used where another type is needed.
    ParameterType {
        expected: &'static str,
    },
    /// A float parameter whose `min ≤ default ≤ max` does not hold, or a
    /// non-finite bound or value where a finite one is needed.
    ParameterRange,
    /// A blend axis whose parameter has no finite `min` and `max`.
    UnboundedAxis,
    DegenerateBlendSpace(Degeneracy),
    /// A node that reaches itself through its references.
    NodeCycle,
    /// A `layers` entry naming a blend or layers node other than as the
    /// first entry at weight 1, blend mode, unmasked: it would not be one
    /// layer stack.
    EntryNotStackable,
    /// A negative or non-finite duration, exit time or speed.
    BadNumber,
    /// States whose nodes do not share the first state's skeleton and
    /// parameters (a transition crossfades them).
    SkeletonMismatch,
    NoStates,
    /// A node's layers broke a rule of docs/motion.md.
    Motion(MotionErrorKind),
}

impl GraphErrorKind {
    /// A stable machine-readable code.
    pub fn code(&self) -> &'static str {
        use GraphErrorKind::*;
        match self {
            UnknownReference { .. } => "unknown_reference",
            ParameterType { .. } => "parameter_type",
            ParameterRange => "parameter_range",
            UnboundedAxis => "unbounded_axis",
            DegenerateBlendSpace(_) => "degenerate_blend_space",
            NodeCycle => "node_cycle",
            EntryNotStackable => "entry_not_stackable",
            BadNumber => "bad_number",
            SkeletonMismatch => "skeleton_mismatch",
            NoStates => "no_states",
            Motion(kind) => kind.code(),
        }
    }
}

impl fmt::Display for GraphError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.kind)
    }
}

impl std::error::Error for GraphError {}

impl fmt::Display for GraphErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use GraphErrorKind::*;
        match self {
            UnknownReference { what, index } => write!(f, "{what} {index} does not exist"),
            ParameterType { expected } => write!(f, "the parameter must be a {expected}"),
            ParameterRange => write!(f, "a float parameter needs min ≤ default ≤ max, all numbers"),
            UnboundedAxis => write!(f, "a blend2d axis needs a parameter with a finite min and max"),
            DegenerateBlendSpace(Degeneracy::Empty) => write!(f, "a blend needs at least one point"),
            DegenerateBlendSpace(Degeneracy::Coincident(a, b)) => {
                write!(f, "points {a} and {b} are at the same place")
            }
            DegenerateBlendSpace(Degeneracy::Collinear) => {
                write!(f, "a blend2d needs three points that are not on one line")
            }
            NodeCycle => write!(f, "the node reaches itself through its references"),
            EntryNotStackable => write!(
                f,
                "a layers entry naming a blend or layers node must be the first entry, at weight 1, blend mode, without a mask"
            ),
            BadNumber => write!(f, "the value must be a finite number ≥ 0"),
            SkeletonMismatch => write!(f, "every state's node must have the first state's skeleton and parameters"),
            NoStates => write!(f, "a machine needs at least one state"),
            Motion(kind) => write!(f, "{kind}"),
        }
    }
}
