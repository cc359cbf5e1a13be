//! The JSON graph (docs/graphs.md): parameters, nodes and a state machine
//! by name, parsed strictly (unknown fields refused), checked with JSON
//! pointers, and compiled into the core's [`Graph`] once its clips are
//! resolved by the caller.
//!
//! The document names things; the core takes indices. [`GraphDoc::compile`]
//! resolves every name (parameters, nodes, states; each distinct clip id
//! once, through the caller's closure) and hands the rest of the rules —
//! ranges, cycles, blend spaces, skeletons — to [`Graph::build`], whose
//! paths are the document's own.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::doc::{DocError, EaseDoc, PlaybackDoc};
use super::json::parse_document;
use super::motion::{LayerModeDoc, MaskDoc};
use anim::Ease;
use anim::graph::{
    Blend1dSpec, Blend2dSpec, ClipNodeSpec, Comparison, Condition, EntrySource, EntrySpec, Graph, GraphSpec,
    MachineSpec, NodeKind, NodeOptions, NodeSpec, ParameterKind, ParameterSpec, StateSpec, TopSpec, TransitionSpec,
    Value,
};
use anim::motion::{ClipSource, LayerMode, MaskSpec};

/// An animation graph as `docs/graphs.md` describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraphDoc {
    pub name: String,
    #[serde(default)]
    pub parameters: BTreeMap<String, ParameterDoc>,
    pub nodes: BTreeMap<String, NodeDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub machine: Option<MachineDoc>,
    /// The node that always plays, for a graph without a machine.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub output: Option<String>,
}

/// A parameter by its `type`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ParameterDoc {
    Float {
        #[serde(default)]
        default: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        min: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        max: Option<f64>,
    },
    Bool {
        #[serde(default)]
        default: bool,
    },
    Trigger,
}

/// Exactly one of: a clip (with `playback`, `speed`), `blend1d`, `blend2d`, `layers`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeDoc {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clip: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub playback: Option<PlaybackDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blend1d: Option<Blend1dDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blend2d: Option<Blend2dDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layers: Option<Vec<EntryDoc>>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Blend1dDoc {
    pub parameter: String,
    pub points: Vec<Point1dDoc>,
    #[serde(default = "yes")]
    pub sync: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Point1dDoc {
    pub clip: String,
    pub at: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Blend2dDoc {
    pub x: String,
    pub y: String,
    pub points: Vec<Point2dDoc>,
    #[serde(default = "yes")]
    pub sync: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Point2dDoc {
    pub clip: String,
    pub at: [f64; 2],
}

/// A `layers` entry: exactly one of `clip` and `node`, with a motion layer's fields.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EntryDoc {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clip: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub playback: Option<PlaybackDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed: Option<f64>,
    #[serde(default = "one")]
    pub weight: f32,
    #[serde(default)]
    pub mode: LayerModeDoc,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<MaskDoc>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MachineDoc {
    pub initial: String,
    pub states: BTreeMap<String, StateDoc>,
    #[serde(default)]
    pub transitions: Vec<TransitionDoc>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StateDoc {
    pub node: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransitionDoc {
    /// A state, or `*` for any.
    pub from: String,
    pub to: String,
    pub when: ConditionDoc,
    #[serde(default)]
    pub duration: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ease: Option<EaseDoc>,
    #[serde(default = "yes")]
    pub interruptible: bool,
}

/// Exactly one form: `parameter` with one comparison, `trigger`,
/// `exit_time`, `all` or `any`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConditionDoc {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parameter: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eq: Option<ValueDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ne: Option<ValueDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gt: Option<ValueDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ge: Option<ValueDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lt: Option<ValueDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub le: Option<ValueDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trigger: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exit_time: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub all: Option<Vec<ConditionDoc>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub any: Option<Vec<ConditionDoc>>,
}

/// A comparison's value: a number for a float parameter, a boolean for a bool.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ValueDoc {
    Bool(bool),
    Number(f64),
}

/// Parses a graph document, reporting the JSON pointer of any type error.
///
/// # Errors
/// Malformed JSON (`malformed_json`) or a field of the wrong type or name
/// (`invalid_field`), with its pointer.
pub fn parse_graph_doc(body: &[u8]) -> Result<GraphDoc, DocError> {
    parse_document(body)
}

impl GraphDoc {
    /// Every clip the document names, each with the pointer of the field
    /// naming it (under `pointer`, the graph's place in its message), in
    /// the document's order: what a caller resolves before
    /// [`GraphDoc::compile`].
    pub fn clip_references(&self, pointer: &str) -> Vec<(&str, String)> {
        let mut out = Vec::new();
        for (name, node) in &self.nodes {
            let at = format!("{pointer}/nodes/{}", escape(name));
            if let Some(id) = &node.clip {
                out.push((id.as_str(), format!("{at}/clip")));
            }
            if let Some(b) = &node.blend1d {
                let points = b.points.iter().enumerate();
                out.extend(points.map(|(i, p)| (p.clip.as_str(), format!("{at}/blend1d/points/{i}/clip"))));
            }
            if let Some(b) = &node.blend2d {
                let points = b.points.iter().enumerate();
                out.extend(points.map(|(i, p)| (p.clip.as_str(), format!("{at}/blend2d/points/{i}/clip"))));
            }
            for (i, entry) in node.layers.iter().flatten().enumerate() {
                if let Some(id) = &entry.clip {
                    out.push((id.as_str(), format!("{at}/layers/{i}/clip")));
                }
            }
        }
        out
    }
}

fn yes() -> bool {
    true
}

fn one() -> f32 {
    1.0
}

fn problem(code: &'static str, pointer: String, detail: impl Into<String>) -> DocError {
    DocError { code, pointer, detail: detail.into() }
}

/// RFC 6901: a map key in a pointer.
fn escape(key: &str) -> String {
    key.replace('~', "~0").replace('/', "~1")
}

/// Names to indices, and the distinct clip ids with the pointer of each one's first use.
struct Names<'a> {
    doc: &'a GraphDoc,
    pointer: &'a str,
    parameters: Vec<&'a str>,
    nodes: Vec<&'a str>,
    clips: Vec<(String, String)>,
}

impl GraphDoc {
    /// Checks the document's names and shapes and builds the graph, with
    /// each distinct clip id resolved once by `resolve(id, pointer)` (which
    /// answers the caller's own problem, e.g. 404 `unknown_clip`, for a
    /// clip that does not exist); `pointer` is the graph's place in its
    /// message (`""` for a whole body).
    ///
    /// # Errors
    /// The first problem, with its JSON pointer: names that refer to
    /// nothing, a node or condition that is not exactly one form, a
    /// `machine` and `output` both or neither, then the core's rules
    /// (`degenerate_blend_space`, `node_cycle`, `parameter_range`, …).
    pub fn compile<C: ClipSource + Clone>(
        &self,
        pointer: &str,
        resolve: impl FnMut(&str, &str) -> Result<C, DocError>,
    ) -> Result<Graph<C>, DocError> {
        self.compile_with(pointer, resolve, &NodeOptions::default())
    }

    /// [`GraphDoc::compile`] with a motion's node options
    /// (`Graph::build_with`): a refusal at `retarget/…` or `root_motion/…`
    /// is pointed there, not into the document.
    ///
    /// # Errors
    /// As [`GraphDoc::compile`].
    pub fn compile_with<C: ClipSource + Clone>(
        &self,
        pointer: &str,
        mut resolve: impl FnMut(&str, &str) -> Result<C, DocError>,
        options: &NodeOptions,
    ) -> Result<Graph<C>, DocError> {
        let mut names = Names {
            doc: self,
            pointer,
            parameters: self.parameters.keys().map(String::as_str).collect(),
            nodes: self.nodes.keys().map(String::as_str).collect(),
            clips: Vec::new(),
        };
        let spec = names.spec()?;
        let clips = (names.clips.iter()).map(|(id, at)| resolve(id, at)).collect::<Result<Vec<C>, DocError>>()?;
        Graph::build_with(spec, &clips, options).map_err(|e| {
            let at = e.path.to_pointer();
            let motion_own = at.starts_with("/retarget") || at.starts_with("/root_motion");
            let at = if motion_own { at } else { format!("{pointer}{at}") };
            problem(e.kind.code(), at, e.kind.to_string())
        })
    }
}

impl Names<'_> {
    fn spec(&mut self) -> Result<GraphSpec, DocError> {
        let parameters = self.parameter_specs()?;
        let mut nodes = Vec::with_capacity(self.nodes.len());
        for (name, node) in &self.doc.nodes {
            let at = format!("{}/nodes/{}", self.pointer, escape(name));
            nodes.push(NodeSpec { name: name.clone(), kind: self.node_kind(node, &at)? });
        }
        let top = match (&self.doc.machine, &self.doc.output) {
            (Some(machine), None) => TopSpec::Machine(self.machine(machine)?),
            (None, Some(output)) => TopSpec::Output(self.node(output, format!("{}/output", self.pointer))?),
            _ => {
                let detail = "a graph has either a `machine` or an `output` node, not both";
                return Err(problem("graph_top", self.pointer.to_owned(), detail));
            }
        };
        Ok(GraphSpec { parameters, nodes, top })
    }

    fn parameter_specs(&self) -> Result<Vec<ParameterSpec>, DocError> {
        let mut out = Vec::with_capacity(self.doc.parameters.len());
        for (name, p) in &self.doc.parameters {
            let kind = match *p {
                ParameterDoc::Float { default, min, max } => {
                    let (min, max) = (min.unwrap_or(f64::NEG_INFINITY), max.unwrap_or(f64::INFINITY));
                    if !(min <= default && default <= max) {
                        let at = format!("{}/parameters/{}/default", self.pointer, escape(name));
                        return Err(problem("parameter_range", at, "a float parameter needs min ≤ default ≤ max"));
                    }
                    ParameterKind::Float { default, min, max }
                }
                ParameterDoc::Bool { default } => ParameterKind::Bool { default },
                ParameterDoc::Trigger => ParameterKind::Trigger,
            };
            out.push(ParameterSpec { name: name.clone(), kind });
        }
        Ok(out)
    }

    fn parameter(&self, name: &str, at: String) -> Result<usize, DocError> {
        let detail = || format!("parameter '{name}' is not in the graph's parameters");
        self.parameters.iter().position(|p| *p == name).ok_or_else(|| problem("unknown_parameter", at, detail()))
    }

    fn node(&self, name: &str, at: String) -> Result<usize, DocError> {
        let detail = || format!("node '{name}' is not in the graph's nodes");
        self.nodes.iter().position(|n| *n == name).ok_or_else(|| problem("unknown_node", at, detail()))
    }

    /// The index of clip `id` among the distinct clips, first use first.
    fn clip(&mut self, id: &str, at: String) -> usize {
        match self.clips.iter().position(|(c, _)| c == id) {
            Some(i) => i,
            None => {
                self.clips.push((id.to_owned(), at));
                self.clips.len() - 1
            }
        }
    }

    fn node_kind(&mut self, node: &NodeDoc, at: &str) -> Result<NodeKind, DocError> {
        let forms = [node.clip.is_some(), node.blend1d.is_some(), node.blend2d.is_some(), node.layers.is_some()];
        let clip_fields = node.playback.is_some() || node.speed.is_some();
        if forms.iter().filter(|f| **f).count() != 1 || (clip_fields && node.clip.is_none()) {
            let detail =
                "a node is exactly one of: a `clip` (with `playback`, `speed`), `blend1d`, `blend2d`, `layers`";
            return Err(problem("node_kind", at.to_owned(), detail));
        }
        if let Some(id) = &node.clip {
            let clip = self.clip(id, format!("{at}/clip"));
            return Ok(NodeKind::Clip(ClipNodeSpec {
                clip,
                playback: node.playback.map(Into::into),
                speed: node.speed.unwrap_or(1.0),
            }));
        }
        if let Some(b) = &node.blend1d {
            let parameter = self.parameter(&b.parameter, format!("{at}/blend1d/parameter"))?;
            let points = (b.points.iter().enumerate())
                .map(|(i, p)| (self.clip(&p.clip, format!("{at}/blend1d/points/{i}/clip")), p.at))
                .collect();
            return Ok(NodeKind::Blend1d(Blend1dSpec { parameter, points, sync: b.sync }));
        }
        if let Some(b) = &node.blend2d {
            let x = self.parameter(&b.x, format!("{at}/blend2d/x"))?;
            let y = self.parameter(&b.y, format!("{at}/blend2d/y"))?;
            let points = (b.points.iter().enumerate())
                .map(|(i, p)| (self.clip(&p.clip, format!("{at}/blend2d/points/{i}/clip")), p.at))
                .collect();
            return Ok(NodeKind::Blend2d(Blend2dSpec { x, y, points, sync: b.sync }));
        }
        let entries = node.layers.as_deref().unwrap_or_default();
        let entries = (entries.iter().enumerate())
            .map(|(i, e)| self.entry(e, &format!("{at}/layers/{i}")))
            .collect::<Result<_, _>>()?;
        Ok(NodeKind::Layers(entries))
    }

    fn entry(&mut self, entry: &EntryDoc, at: &str) -> Result<EntrySpec, DocError> {
        let source = match (&entry.clip, &entry.node) {
            (Some(id), None) => {
                let clip = self.clip(id, format!("{at}/clip"));
                let speed = entry.speed.unwrap_or(1.0);
                EntrySource::Clip(ClipNodeSpec { clip, playback: entry.playback.map(Into::into), speed })
            }
            (None, Some(name)) if entry.playback.is_none() && entry.speed.is_none() => {
                EntrySource::Node(self.node(name, format!("{at}/node"))?)
            }
            _ => {
                let detail =
                    "a layers entry names exactly one of `clip` and `node` (`playback` and `speed` go with a clip)";
                return Err(problem("entry_kind", at.to_owned(), detail));
            }
        };
        Ok(EntrySpec {
            source,
            weight: entry.weight,
            mode: match entry.mode {
                LayerModeDoc::Blend => LayerMode::Blend,
                LayerModeDoc::Additive => LayerMode::Additive,
            },
            mask: entry.mask.as_ref().map(|m| MaskSpec {
                joints: m.joints.iter().map(|(name, w)| (name.clone(), *w)).collect(),
                descendants: m.descendants,
                default: m.default,
            }),
        })
    }

    fn machine(&self, machine: &MachineDoc) -> Result<MachineSpec, DocError> {
        let at = format!("{}/machine", self.pointer);
        let names: Vec<&str> = machine.states.keys().map(String::as_str).collect();
        let state = |name: &str, at: String| {
            let detail = || format!("state '{name}' is not in the machine's states");
            names.iter().position(|s| *s == name).ok_or_else(|| problem("unknown_state", at, detail()))
        };
        let mut states = Vec::with_capacity(names.len());
        for (name, s) in &machine.states {
            let node = self.node(&s.node, format!("{at}/states/{}/node", escape(name)))?;
            states.push(StateSpec { name: name.clone(), node });
        }
        let mut transitions = Vec::with_capacity(machine.transitions.len());
        for (i, t) in machine.transitions.iter().enumerate() {
            let at = format!("{at}/transitions/{i}");
            let from = if t.from == "*" { None } else { Some(state(&t.from, format!("{at}/from"))?) };
            transitions.push(TransitionSpec {
                from,
                to: state(&t.to, format!("{at}/to"))?,
                when: self.condition(&t.when, &format!("{at}/when"))?,
                duration: t.duration,
                ease: t.ease.map_or(Ease::Linear, Into::into),
                interruptible: t.interruptible,
            });
        }
        Ok(MachineSpec { initial: state(&machine.initial, format!("{at}/initial"))?, states, transitions })
    }

    fn condition(&self, c: &ConditionDoc, at: &str) -> Result<Condition, DocError> {
        let comparisons = [
            (Comparison::Eq, c.eq),
            (Comparison::Ne, c.ne),
            (Comparison::Gt, c.gt),
            (Comparison::Ge, c.ge),
            (Comparison::Lt, c.lt),
            (Comparison::Le, c.le),
        ];
        let compared: Vec<(Comparison, ValueDoc)> =
            comparisons.into_iter().filter_map(|(op, v)| v.map(|v| (op, v))).collect();
        let forms =
            [c.parameter.is_some(), c.trigger.is_some(), c.exit_time.is_some(), c.all.is_some(), c.any.is_some()];
        let one_form = forms.iter().filter(|f| **f).count() == 1;
        let kind_error = || {
            let detail = "a condition is exactly one of: `parameter` with one of eq, ne, gt, ge, lt, le; `trigger`; `exit_time`; `all`; `any`";
            problem("condition_kind", at.to_owned(), detail)
        };
        if !one_form || (c.parameter.is_some() != (compared.len() == 1)) || compared.len() > 1 {
            return Err(kind_error());
        }
        if let Some(name) = &c.parameter {
            let (op, value) = compared[0];
            let parameter = self.parameter(name, format!("{at}/parameter"))?;
            let value = match value {
                ValueDoc::Bool(b) => Value::Bool(b),
                ValueDoc::Number(v) => Value::Float(v),
            };
            return Ok(Condition::Compare { parameter, op, value });
        }
        if let Some(name) = &c.trigger {
            return Ok(Condition::Trigger(self.parameter(name, format!("{at}/trigger"))?));
        }
        if let Some(x) = c.exit_time {
            return Ok(Condition::ExitTime(x));
        }
        let (name, list) = match (&c.all, &c.any) {
            (Some(list), _) => ("all", list),
            (_, Some(list)) => ("any", list),
            (None, None) => return Err(kind_error()),
        };
        let list = (list.iter().enumerate())
            .map(|(i, c)| self.condition(c, &format!("{at}/{name}/{i}")))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(if name == "all" { Condition::All(list) } else { Condition::Any(list) })
    }
}
