//! Stream controls, in one place: what a client may ask of a playback
//! (`pause`, `seek`, `crossfade`, …; docs/motion.md, "Controls"; a graph
//! stream's `set`, docs/graphs.md), read
//! from a WebSocket's JSON and a `Play` call's protobuf, checked against
//! the stream, said again for a broadcast's journal, and applied to a
//! playback — a per-viewer stream's and a broadcast's alike.
//!
//! Every `match` on a control here names each variant (no `_`), so a new
//! control is a compile error at each place it must be handled; a new one
//! touches this file, the `.proto` and its doc section.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use futures_util::future::BoxFuture;

use super::compact::{CompactLayout, CompactRefusal, Relayout};
use super::fade_chain::FadeChain;
use super::graph::{GraphDeck, StreamGraph};
use super::params::StreamParams;
use super::pinned::StreamMotion;
use super::pinned::StreamPlayer;
use super::playhead::{MAX_SPEED, Playhead};
use anim::Ease;
use anim::graph::Value;
use anim::ik::{IkConstraint, IkError, IkLimits, IkSpec, build_constraints};
use anim::motion::PlayerError;
use formats::wire::graph_inputs::{SetDoc, parameters};
use formats::wire::ik::IkDoc;
use formats::wire::json::{DocError, EaseDoc};
use formats::wire::proto::{ease_from_pb, ik_from_pb, pb};
use formats::wire::proto_graph::value_from_proto;

/// A change asked of a playback, applied at its next tick.
#[derive(Debug, Clone, PartialEq)]
pub enum Control {
    Play,
    Pause,
    /// Show this motion time of the current motion at the next tick.
    Seek(f64),
    /// Stream seconds per real second (negative plays backwards).
    Speed(f64),
    /// End the stream cleanly.
    Stop,
    /// Fade to another motion (docs/motion.md).
    Crossfade(Crossfade),
    /// Ramp a layer of the current motion to a weight.
    Layer {
        index: usize,
        weight: f32,
        duration: f64,
    },
    /// Replace the stream's IK constraints (docs/ik.md), as a client names
    /// them; the stream's check resolves them into [`Control::SetIk`].
    Ik(Vec<IkSpec>),
    /// Replace the stream's IK constraints, resolved against its skeleton.
    SetIk(Vec<IkConstraint>),
    /// Restart the spring chains at rest (docs/springs.md, “Time”).
    ResetSprings,
    /// Set a graph stream's parameters from the next tick (docs/graphs.md),
    /// as a client names them; the stream's check resolves them into
    /// [`Control::SetGraph`].
    Set(SetDoc),
    /// Set a graph stream's parameters, resolved against its graph.
    SetGraph(Vec<(usize, Value)>),
}

/// A crossfade asked for: its target, already built over pinned clips.
#[derive(Debug, Clone)]
pub struct Crossfade {
    pub to: Arc<StreamMotion>,
    pub duration: f64,
    pub ease: Ease,
    /// `to` as the client wrote it (the JSON motion), so that the control
    /// can be said again: a broadcast stores it for the other nodes.
    pub source: Option<Arc<serde_json::Value>>,
}

impl PartialEq for Crossfade {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.to, &other.to) && self.duration == other.duration && self.ease == other.ease
    }
}

/// The longest crossfade or weight ramp, seconds.
pub const MAX_FADE_SECONDS: f64 = 3600.0;

impl Control {
    /// Checks the numbers a client sent.
    ///
    /// # Errors
    /// A non-finite seek time, a speed that is not finite or exceeds
    /// [`MAX_SPEED`] in magnitude, a fade or ramp longer than
    /// [`MAX_FADE_SECONDS`], a layer weight outside [0, 1].
    pub fn validate(self) -> Result<Self, &'static str> {
        match self.problem() {
            Some(problem) => Err(problem),
            None => Ok(self),
        }
    }

    fn problem(&self) -> Option<&'static str> {
        let long = |d: f64| !(0.0..=MAX_FADE_SECONDS).contains(&d);
        match *self {
            Control::Seek(t) => (!t.is_finite()).then_some("seek time must be a finite number of seconds"),
            Control::Speed(v) => (!v.is_finite() || v.abs() > MAX_SPEED)
                .then_some("speed must be a finite number between -1000 and 1000"),
            Control::Crossfade(Crossfade { duration, .. }) => {
                long(duration).then_some("a crossfade's duration must be between 0 and 3600 seconds")
            }
            Control::Layer { weight, duration, .. } => {
                if long(duration) {
                    Some("a weight ramp's duration must be between 0 and 3600 seconds")
                } else {
                    (!(0.0..=1.0).contains(&weight)).then_some("a layer weight must be in [0, 1]")
                }
            }
            Control::Play
            | Control::Pause
            | Control::Stop
            | Control::Ik(_)
            | Control::SetIk(_)
            | Control::ResetSprings
            | Control::Set(_)
            | Control::SetGraph(_) => None,
        }
    }

    /// Why a broadcast refuses this control, if it does (its viewers share
    /// one playback, which only `DELETE` ends).
    pub(crate) fn refused_on_broadcast(&self) -> Option<&'static str> {
        match self {
            Control::Stop => Some("a broadcast has no `stop`: DELETE it to end it for every viewer"),
            Control::Play
            | Control::Pause
            | Control::Seek(_)
            | Control::Speed(_)
            | Control::Crossfade(_)
            | Control::Layer { .. }
            | Control::Ik(_)
            | Control::SetIk(_)
            | Control::ResetSprings
            | Control::Set(_)
            | Control::SetGraph(_) => None,
        }
    }

    /// Why a graph stream refuses this control, if it does: it plays the
    /// graph's own time from 0 at speed 1, with its own crossfades.
    fn refused_on_graph(&self) -> Option<&'static str> {
        match self {
            Control::Seek(_) => Some("a graph stream plays its ticks from 0: it has no `seek`"),
            Control::Speed(_) => Some("a graph stream plays one graph tick per tick: it has no `speed`"),
            Control::Crossfade(_) => Some("a graph's transitions are its own crossfades: send `set` controls"),
            Control::Layer { .. } => Some("a graph's blend weights come from its parameters: send `set` controls"),
            Control::Ik(_) | Control::SetIk(_) => Some("a graph stream's IK is its motion's `ik`, fixed when it opens"),
            Control::Play
            | Control::Pause
            | Control::Stop
            | Control::ResetSprings
            | Control::Set(_)
            | Control::SetGraph(_) => None,
        }
    }

    /// The `(paused, speed)` a broadcast's status reports once this control
    /// is accepted, from the ones before it.
    pub(crate) fn status_after(&self, paused: bool, speed: f64) -> (bool, f64) {
        match *self {
            Control::Play => (false, speed),
            Control::Pause => (true, speed),
            Control::Speed(v) => (paused, v),
            Control::Seek(_)
            | Control::Stop
            | Control::Crossfade(_)
            | Control::Layer { .. }
            | Control::Ik(_)
            | Control::SetIk(_)
            | Control::ResetSprings
            | Control::Set(_)
            | Control::SetGraph(_) => (paused, speed),
        }
    }

    /// Applies the control to a playback so that it takes effect at tick
    /// `k` (`k >= 1`): the one step of per-viewer streams and broadcasts
    /// (`graph`: a graph stream's graph).
    ///
    /// # Errors
    /// A crossfade or ramp the player refuses (nothing changed).
    pub(crate) fn apply(
        self,
        playhead: &mut Playhead,
        player: &mut StreamPlayer,
        graph: Option<&mut GraphDeck>,
        k: u64,
    ) -> Result<Applied, Refused> {
        match self {
            Control::Play => playhead.play(k),
            Control::Pause => playhead.pause(k),
            Control::Speed(v) => playhead.set_speed(v, k),
            Control::Seek(tau) => {
                player.seek(tau);
                return Ok(Applied::Jumped);
            }
            Control::Stop => return Ok(Applied::Stopped),
            Control::Crossfade(Crossfade { to, duration, ease, .. }) => {
                player.crossfade(to, duration, ease).map_err(|error| Refused { what: "crossfade", error })?;
            }
            Control::Layer { index, weight, duration } => {
                player.ramp(index, weight, duration).map_err(|error| Refused { what: "weight ramp", error })?;
            }
            Control::SetIk(constraints) => player.set_ik(constraints),
            Control::ResetSprings => match graph {
                Some(graph) => graph.reset_springs(),
                None => player.reset_springs(),
            },
            Control::SetGraph(values) => match graph {
                Some(graph) => graph.set(&values),
                None => tracing::error!("graph settings reached a playback without a graph"),
            },
            // The stream's check resolves every `ik` and `set` control before it is queued.
            Control::Ik(_) => tracing::error!("IK constraints reached a playback unresolved"),
            Control::Set(_) => tracing::error!("graph settings reached a playback unresolved"),
        }
        Ok(Applied::Continued)
    }

    /// The control message that says this control again (docs/motion.md);
    /// `None` for `stop`, resolved IK lists and a crossfade whose motion
    /// was not written down (`Crossfade::source`).
    pub fn to_json(&self) -> Option<serde_json::Value> {
        let msg = match self {
            Control::Play => ControlMsg::Play,
            Control::Pause => ControlMsg::Pause,
            Control::Seek(time) => ControlMsg::Seek { time: *time },
            Control::Speed(speed) => ControlMsg::Speed { speed: *speed },
            Control::Crossfade(Crossfade { source: Some(to), duration, ease, .. }) => {
                ControlMsg::Crossfade { to: (**to).clone(), duration: *duration, ease: EaseDoc::from(*ease) }
            }
            Control::Layer { index, weight, duration } => {
                ControlMsg::Layer { index: *index, weight: *weight, duration: *duration }
            }
            Control::Ik(specs) => ControlMsg::Ik { constraints: specs.iter().map(IkDoc::from_spec).collect() },
            Control::ResetSprings => ControlMsg::ResetSprings,
            Control::Set(parameters) => ControlMsg::Set { parameters: parameters.clone() },
            Control::Stop
            | Control::Crossfade(Crossfade { source: None, .. })
            | Control::SetIk(_)
            | Control::SetGraph(_) => return None,
        };
        Some(serde_json::to_value(msg).expect("a control message is JSON"))
    }
}

/// A checked control on its way to a playback, with the compact layout
/// its check chose for it (docs/compact-frames.md), which the playback
/// encodes with from the control's tick.
#[derive(Debug)]
pub(crate) struct Queued {
    pub control: Control,
    pub layout: Option<Arc<CompactLayout>>,
}

/// What applying a control did to its playback.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Applied {
    /// Time goes on from the previous tick.
    Continued,
    /// Time jumped (a seek), which ends event continuity.
    Jumped,
    /// The stream ends (`stop`).
    Stopped,
}

/// A control the player refused: a bug on a per-viewer stream (its check
/// accepted it); on a broadcast, a ramp of a layer a crossfade stamped just
/// before took away, skipped the same way on every node.
#[derive(Debug)]
pub(crate) struct Refused {
    /// `crossfade` or `weight ramp`.
    pub what: &'static str,
    pub error: PlayerError,
}

/// A control message as a client writes it (`{"op": "seek", "time": 1.5}`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "op", rename_all = "snake_case", deny_unknown_fields)]
pub(crate) enum ControlMsg {
    Play,
    Pause,
    Seek {
        time: f64,
    },
    Speed {
        speed: f64,
    },
    Stop,
    Crossfade {
        to: serde_json::Value,
        duration: f64,
        #[serde(default = "linear")]
        ease: EaseDoc,
    },
    Layer {
        index: usize,
        weight: f32,
        #[serde(default)]
        duration: f64,
    },
    /// Replaces the stream's IK constraints at the next tick.
    Ik {
        constraints: Vec<IkDoc>,
    },
    /// Restarts the spring chains at rest at the next tick.
    ResetSprings,
    /// Sets a graph stream's parameters from the next tick.
    Set {
        parameters: SetDoc,
    },
}

fn linear() -> EaseDoc {
    EaseDoc::Linear
}

/// The ops a control message may name, as its refusal lists them.
const OPS: [&str; 10] = ["play", "pause", "seek", "speed", "stop", "crossfade", "layer", "ik", "reset_springs", "set"];

/// The refusal of a text that is no control message; `stop` is listed only
/// where it is taken (a stream's socket, not a broadcast's REST control).
pub(crate) fn not_a_control(e: &serde_json::Error, with_stop: bool) -> String {
    let ops: Vec<String> = OPS.iter().filter(|op| with_stop || **op != "stop").map(|op| format!("\"{op}\"")).collect();
    format!("expected {{\"op\": {}, ...}}: {e}", ops.join("|"))
}

impl ControlMsg {
    /// The control, or for a crossfade what to look its motion up from.
    ///
    /// # Errors
    /// An `ik` control's constraint shape, at `/constraints/…`.
    pub(crate) fn parse(self) -> Result<ParsedControl, DocError> {
        Ok(ParsedControl::Ready(match self {
            ControlMsg::Play => Control::Play,
            ControlMsg::Pause => Control::Pause,
            ControlMsg::Seek { time } => Control::Seek(time),
            ControlMsg::Speed { speed } => Control::Speed(speed),
            ControlMsg::Stop => Control::Stop,
            ControlMsg::ResetSprings => Control::ResetSprings,
            ControlMsg::Set { parameters } => Control::Set(parameters),
            ControlMsg::Layer { index, weight, duration } => Control::Layer { index, weight, duration },
            ControlMsg::Crossfade { to, duration, ease } => {
                return Ok(ParsedControl::Crossfade { to, duration, ease: ease.into() });
            }
            ControlMsg::Ik { constraints } => {
                let specs = constraints.iter().enumerate().map(|(i, c)| c.to_spec(&format!("/constraints/{i}")));
                Control::Ik(specs.collect::<Result<_, _>>()?)
            }
        }))
    }
}

/// A control message parsed on its own: the control, or a crossfade whose
/// motion `to` (JSON, or a `Play` call's protobuf) the caller looks up.
#[derive(Debug, Clone, PartialEq)]
pub enum ParsedControl<M = serde_json::Value> {
    Ready(Control),
    Crossfade { to: M, duration: f64, ease: Ease },
}

impl ParsedControl<Option<pb::Motion>> {
    /// A `Play` message's control (`open` and `broadcast` only start a call).
    ///
    /// # Errors
    /// No op, a starting op (`bad_control`), an undefined ease, or an `ik`
    /// control's constraint shape at `/constraints/…`.
    pub fn from_pb(op: Option<pb::playback_control::Op>) -> Result<Self, DocError> {
        use pb::playback_control::Op;
        let bad = |detail: &str| DocError { code: "bad_control", pointer: String::new(), detail: detail.into() };
        Ok(ParsedControl::Ready(match op {
            Some(Op::Play(_)) => Control::Play,
            Some(Op::Pause(_)) => Control::Pause,
            Some(Op::Seek(s)) => Control::Seek(s.time),
            Some(Op::Speed(s)) => Control::Speed(s.speed),
            Some(Op::Stop(_)) => Control::Stop,
            Some(Op::ResetSprings(_)) => Control::ResetSprings,
            Some(Op::Layer(l)) => Control::Layer { index: l.index as usize, weight: l.weight, duration: l.duration },
            Some(Op::Crossfade(fade)) => {
                let ease = ease_from_pb(fade.ease, "/ease")?.unwrap_or_default();
                return Ok(ParsedControl::Crossfade { to: fade.to, duration: fade.duration, ease });
            }
            Some(Op::Ik(ik)) => Control::Ik(ik_from_pb(&ik.constraints, "/constraints")?),
            Some(Op::Set(set)) => Control::Set(set_doc_from_pb(&set)),
            Some(Op::Open(_) | Op::Broadcast(_)) => {
                return Err(bad("`open` and `broadcast` are only valid as the first message"));
            }
            None => return Err(bad("a PlaybackControl needs an op")),
        }))
    }
}

/// A `Play` `set`'s parameters as the JSON a WebSocket's would be (so both
/// are checked, refused and journaled alike): a number, a flag, or null
/// for a value with neither (refused `parameter_type` by the check).
fn set_doc_from_pb(set: &pb::SetParameters) -> SetDoc {
    let json = |v: &pb::GraphValue| match value_from_proto(v) {
        Some(Value::Float(n)) => serde_json::Number::from_f64(n).map_or(serde_json::Value::Null, Into::into),
        Some(Value::Bool(b)) => b.into(),
        None => serde_json::Value::Null,
    };
    set.parameters.iter().map(|(name, v)| (name.clone(), json(v))).collect()
}

/// Why a control message was refused: its stable code, the JSON pointer at
/// fault if any, and the human detail.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlRefusal {
    pub code: &'static str,
    pub pointer: Option<String>,
    pub detail: String,
}

/// Parses one control message (`{"op": …}`) as a stream's socket does
/// (REST `POST /v1/broadcasts/{id}/controls` takes the same JSON).
///
/// # Errors
/// Not a control (`bad_control`), or an `ik` control's constraint shape (its rule's code).
pub fn parse_control(text: &str) -> Result<ParsedControl, ControlRefusal> {
    let msg = serde_json::from_str::<ControlMsg>(text).map_err(|e| ControlRefusal {
        code: "bad_control",
        pointer: None,
        detail: not_a_control(&e, false),
    })?;
    msg.parse().map_err(|e| ControlRefusal { code: e.code, pointer: Some(e.pointer), detail: e.detail })
}

/// Why a control was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ControlError {
    #[error("{0}")]
    Invalid(&'static str),
    #[error("too many controls pending; wait for a frame before sending more")]
    Busy,
    /// A broadcast holds its most controls since its newest checkpoint
    /// (`broadcast_max_journal`, docs/broadcasts.md "Checkpoints").
    #[error(
        "this broadcast holds as many controls as it keeps between two checkpoints (broadcast_max_journal); \
         send more after its next checkpoint"
    )]
    JournalFull,
    /// An `ik` control's constraint breaks a rule of docs/ik.md (its path
    /// is relative to the control's `constraints`).
    #[error("{}", .0.kind)]
    Ik(IkError),
    /// A broadcast viewer without the write scope sent a control.
    #[error("controlling a broadcast needs the `write` scope; this viewer may only watch")]
    ReadOnly,
    /// A control a graph stream does not take, or a `set` on a stream
    /// without a graph (`graph_unsupported`).
    #[error("{0}")]
    Graph(&'static str),
    /// A `set` control's value its graph refuses (`unknown_parameter`,
    /// `parameter_type`, `parameter_out_of_range` at `/parameters/<name>`).
    #[error("{detail}")]
    Setting { code: &'static str, pointer: String, detail: String },
    /// Refused by the server before it was applied, or withdrawn because
    /// it could not be stored (docs/broadcasts.md, "Control"): the write
    /// budget, the broadcast's work, its store queue. `problem` is the
    /// server's problem document, sent to the socket as it is.
    #[error("{}", problem_detail(problem))]
    Refused { code: &'static str, problem: Arc<serde_json::Value> },
}

fn problem_detail(problem: &serde_json::Value) -> &str {
    problem["detail"].as_str().unwrap_or("the control was refused")
}

impl ControlError {
    /// The stable code a client gets (`bad_control`, or the IK rule's).
    pub fn code(&self) -> &'static str {
        match self {
            ControlError::Ik(e) => e.kind.code(),
            ControlError::ReadOnly => "insufficient_scope",
            ControlError::Invalid(_) | ControlError::Busy => "bad_control",
            ControlError::Refused { code, .. } => code,
            ControlError::JournalFull => "broadcast_journal_full",
            ControlError::Graph(_) => "graph_unsupported",
            ControlError::Setting { code, .. } => code,
        }
    }

    /// The JSON pointer of the field at fault, when there is one.
    pub fn pointer(&self) -> Option<String> {
        match self {
            ControlError::Ik(e) => Some(format!("/constraints{}", e.path.to_pointer())),
            ControlError::Setting { pointer, .. } => Some(pointer.clone()),
            ControlError::Invalid(_)
            | ControlError::Graph(_)
            | ControlError::Busy
            | ControlError::ReadOnly
            | ControlError::Refused { .. }
            | ControlError::JournalFull => None,
        }
    }
}

/// What a control may make a stream cost: one write of its caller's
/// write budget, and what it leaves the stream evaluating, which the
/// service prices and charges its caller for in place of what it held
/// (`request::stream`). A crossfade is priced at every motion its fade
/// chain may evaluate (`fade_chain`: the fades begun before it, then its
/// target), an `ik` control at that chain with the new constraints (the
/// IK runs on the mix of them all).
pub trait Repricing: Send + Sync + std::fmt::Debug {
    /// Charges the stream's caller `units` for choosing a new compact
    /// layout (docs/compact-frames.md), before any work: the returned
    /// runner runs the choice off the async workers (the work pool),
    /// holding the charge until it ends.
    ///
    /// # Errors
    /// [`ControlError::Refused`]: `too_much_work` over `max_request_work`,
    /// `caller_work_limit` or `overloaded` as for any work (the runner's
    /// future: `request_timeout`).
    fn charge_layout(&self, units: u64) -> Result<LayoutRunner, ControlError>;

    /// Charges the stream for evaluating `motions` each frame under the
    /// stream's constraints `ik`, from now on.
    ///
    /// # Errors
    /// [`ControlError::Work`]: over the stream's limit, its caller's share
    /// or the node's capacity; the stream holds what it held.
    fn reprice(&self, motions: &[&StreamMotion], ik: &[IkConstraint]) -> Result<(), ControlError>;

    /// Takes one write of the caller's write budget for a control, as a
    /// REST control (or a broadcast socket's) does: a socket's controls
    /// are writes however they are sent.
    ///
    /// # Errors
    /// [`ControlError::Refused`] with `rate_limited` (429) past the budget.
    fn admit(&self) -> Result<(), ControlError>;
}

/// The choice of a compact stream's new layout: `None` when its layout
/// still holds what the stream plays ([`CompactLayout::after`]).
pub type LayoutJob = Box<dyn FnOnce() -> Result<Option<CompactLayout>, CompactRefusal> + Send>;

/// Runs a [`LayoutJob`] off the async workers, answering what it chose.
pub type LayoutRunner = Box<dyn FnOnce(LayoutJob) -> LayoutRun + Send>;

/// A [`LayoutRunner`]'s run under way.
pub type LayoutRun = BoxFuture<'static, Result<Result<Option<CompactLayout>, CompactRefusal>, ControlError>>;

/// Why a compact stream refuses a crossfade: no range bounds its target.
const UNBOUNDED: &str = "a compact stream cannot crossfade to a motion whose poses no range bounds \
                         (a layer retargeted onto a character, root motion `extract`)";

/// Checks controls against the stream's motions: numbers in range, a
/// crossfade target with the stream's skeleton, a ramp of a layer the
/// motion playing has; and, for a priced stream, what a crossfade or an
/// `ik` control would make it cost ([`Repricing`]). On a compact stream, a
/// control that leaves its layout gets a new one.
#[derive(Debug, Clone)]
pub(crate) struct ControlCheck {
    skeleton: Arc<StreamMotion>,
    /// The motions the accepted crossfades may leave the player
    /// evaluating, the one playing last.
    chain: FadeChain,
    /// The stream's constraints, as the latest accepted control left them.
    ik: Arc<[IkConstraint]>,
    ik_limits: IkLimits,
    repricing: Option<Arc<dyn Repricing>>,
    /// A compact stream's layout, as the latest accepted control left it
    /// (`None`: not compact).
    compact: Option<Arc<CompactLayout>>,
    /// A graph stream's graph, which its `set` controls are checked against.
    graph: Option<Arc<StreamGraph>>,
}

impl ControlCheck {
    pub(crate) fn new(params: &StreamParams) -> Self {
        ControlCheck {
            skeleton: Arc::clone(&params.motion),
            chain: FadeChain::new(&params.motion),
            ik: params.motion.ik().into(),
            ik_limits: params.ik_limits,
            repricing: None,
            compact: params.compact.clone(),
            graph: params.graph.as_ref().map(|g| Arc::clone(&g.graph)),
        }
    }

    /// The motion whose skeleton controls are checked against.
    pub(crate) fn motion(&self) -> &StreamMotion {
        &self.skeleton
    }

    /// The same check, pricing controls with `repricing` (`None`: unpriced).
    pub(crate) fn priced_by(self, repricing: Option<Arc<dyn Repricing>>) -> Self {
        ControlCheck { repricing, ..self }
    }

    fn reprice(&self, motions: &[&StreamMotion], ik: &[IkConstraint]) -> Result<(), ControlError> {
        self.repricing.as_ref().map_or(Ok(()), |r| r.reprice(motions, ik))
    }

    /// Checks `control` (see [`ControlCheck`]) for a playback without a
    /// compact layout (a broadcast's: its compact viewers' layouts refuse
    /// the controls that would leave them); a compact stream's go through
    /// [`ControlCheck::queue`].
    ///
    /// # Errors
    /// A control the stream refuses, or its work; on a compact check, one
    /// that would leave its layout.
    pub(crate) fn check(&mut self, control: Control) -> Result<Control, ControlError> {
        if self.layout_change(&control).is_some() {
            return Err(ControlError::Invalid(
                "this control needs a new compact layout, which this check cannot choose",
            ));
        }
        self.check_control(control)
    }

    /// Checks `control` (see [`ControlCheck`]); on a compact stream whose
    /// layout it leaves, prices and charges the new layout before any work,
    /// then chooses it off the async workers ([`Repricing::charge_layout`];
    /// unpriced, here), to go to the playback with the control, which sends
    /// it before its next frame (a key frame). A refused control leaves the
    /// check as it was.
    ///
    /// # Errors
    /// A control the stream refuses, or its work.
    pub(crate) async fn queue(&mut self, control: Control) -> Result<Queued, ControlError> {
        let mut next = self.clone();
        let runner = next.charge_layout(&control)?;
        let control = next.check_control(control)?;
        let Some(job) = next.layout_job(&control) else {
            *self = next;
            return Ok(Queued { control, layout: None });
        };
        let chosen = match runner {
            Some(run) => run(job).await,
            None => Ok(job()),
        };
        let layout = match chosen {
            Ok(Ok(layout)) => layout.map(Arc::new),
            Ok(Err(_)) => return Err(self.refused(ControlError::Invalid(UNBOUNDED), &control)),
            Err(e) => return Err(self.refused(e, &control)),
        };
        next.compact = layout.clone().or(next.compact);
        *self = next;
        Ok(Queued { control, layout })
    }

    /// `e`, once the stream's price is back to what it was before
    /// `control` repriced it (a crossfade, an `ik` control).
    fn refused(&self, e: ControlError, control: &Control) -> ControlError {
        if matches!(control, Control::Crossfade(_) | Control::SetIk(_))
            && let Err(again) = self.reprice(&self.chain.motions(), &self.ik)
        {
            tracing::warn!(error = %again, "a refused control's stream could not be priced back");
        }
        e
    }

    /// The choice of the new layout `control` (checked) makes a compact
    /// stream need, to run off the async workers (`None`: it needs none).
    fn layout_job(&self, control: &Control) -> Option<LayoutJob> {
        let (layout, change) = (Arc::clone(self.compact.as_ref()?), self.layout_change(control)?);
        let skeleton = Arc::clone(&self.skeleton);
        Some(Box::new(move || layout.after(&change, skeleton.skeleton())))
    }

    /// What `control` makes a compact stream's layout hold besides what it
    /// holds (`None`: nothing, or not compact). An `ik` control counts as
    /// sent or as resolved; only the resolved one names its joints.
    fn layout_change(&self, control: &Control) -> Option<Relayout> {
        let layout = self.compact.as_ref()?;
        match control {
            Control::Crossfade(fade) => Some(Relayout::Plays(Arc::clone(&fade.to))),
            Control::Layer { .. } if !layout.any_weights => Some(Relayout::Plays(Arc::clone(self.chain.playing()))),
            Control::SetIk(constraints) => Some(Relayout::Ik(constraints.clone())),
            Control::Ik(_) => Some(Relayout::Ik(Vec::new())),
            _ => None,
        }
    }

    /// Charges the work of the new layout `control` would make the stream
    /// choose (docs/compact-frames.md, "A new layout"): its range samples,
    /// each a pose of the costliest clip they read.
    fn charge_layout(&self, control: &Control) -> Result<Option<LayoutRunner>, ControlError> {
        let (Some(change), Some(repricing)) = (self.layout_change(control), &self.repricing) else { return Ok(None) };
        let motion = match &change {
            Relayout::Plays(motion) => motion,
            Relayout::Ik(_) => self.chain.playing(),
        };
        let pose = super::compact::range_sample_price(motion, None, crate::work::price::clip_pose);
        repricing.charge_layout(crate::work::price::compact_layout(change.samples(), pose)).map(Some)
    }

    fn check_control(&mut self, control: Control) -> Result<Control, ControlError> {
        // Before any work on it; `stop` ends the stream, so it cannot flood.
        if control != Control::Stop
            && let Some(priced) = &self.repricing
        {
            priced.admit()?;
        }
        let control = control.validate().map_err(ControlError::Invalid)?;
        if let Some(graph) = &self.graph {
            if let Some(why) = control.refused_on_graph() {
                return Err(ControlError::Graph(why));
            }
            if let Control::Set(doc) = &control {
                let values = parameters(graph.as_ref(), doc, "/parameters").map_err(|e| ControlError::Setting {
                    code: e.code,
                    pointer: e.pointer,
                    detail: e.detail,
                })?;
                return Ok(Control::SetGraph(values));
            }
        }
        if let (Some(_), Control::Crossfade(fade)) = (&self.compact, &control)
            && anim::compact::Ranges::boundable(&fade.to).is_err()
        {
            return Err(ControlError::Invalid(UNBOUNDED));
        }
        match &control {
            Control::Crossfade(fade) => {
                self.check_fade(fade)?;
                let chain = self.chain.crossfaded(&fade.to);
                self.reprice(&chain.motions(), &self.ik)?;
                self.chain = chain;
            }
            Control::Layer { index, .. } if *index >= self.chain.playing().layer_count() => {
                return Err(ControlError::Invalid("no such layer in the motion playing"));
            }
            Control::Ik(specs) => {
                let skeleton = self.skeleton.skeleton();
                let constraints = build_constraints(specs, skeleton, &self.ik_limits).map_err(ControlError::Ik)?;
                self.reprice(&self.chain.motions(), &constraints)?;
                self.ik = constraints.as_slice().into();
                return Ok(Control::SetIk(constraints));
            }
            Control::SetIk(_) => return Err(ControlError::Invalid("constraints must be checked against the stream")),
            Control::Set(_) | Control::SetGraph(_) => {
                return Err(ControlError::Graph("`set` drives a graph stream: this stream plays no graph"));
            }
            Control::Play
            | Control::Pause
            | Control::Seek(_)
            | Control::Speed(_)
            | Control::Stop
            | Control::ResetSprings
            | Control::Layer { .. } => {}
        }
        Ok(control)
    }

    /// A crossfade's motion must fit the stream: its skeleton and
    /// parameters, and no IK of its own.
    fn check_fade(&self, fade: &Crossfade) -> Result<(), ControlError> {
        if !fade.to.skeleton().same_joints(self.skeleton.skeleton()) {
            return Err(ControlError::Invalid(
                "the crossfade's motion has another skeleton: its first layer's clip must have the stream's joints in the same order",
            ));
        }
        let (to, here) = (fade.to.parameters(), self.skeleton.parameters());
        if to.names() != here.names() || to.widths() != here.widths() {
            return Err(ControlError::Invalid(
                "the crossfade's motion has other parameters: its first layer's clip must have the stream's parameter names and widths in the same order",
            ));
        }
        if !fade.to.ik().is_empty() {
            return Err(ControlError::Invalid(
                "a crossfade's motion carries no `ik`: change the stream's constraints with an `ik` control",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formats::wire::proto::{ease_to_pb, ik_to_pb};
    use pb::playback_control::Op;
    use serde_json::json;

    /// The protobuf op that says `control` (what a `Play` client sends).
    fn to_pb(control: &Control) -> Op {
        match control {
            Control::Play => Op::Play(pb::Resume {}),
            Control::Pause => Op::Pause(pb::Pause {}),
            Control::Seek(time) => Op::Seek(pb::Seek { time: *time }),
            Control::Speed(speed) => Op::Speed(pb::SetSpeed { speed: *speed }),
            Control::Stop => Op::Stop(pb::Stop {}),
            Control::ResetSprings => Op::ResetSprings(pb::ResetSprings {}),
            Control::Crossfade(fade) => {
                Op::Crossfade(pb::Crossfade { to: None, duration: fade.duration, ease: ease_to_pb(fade.ease) as i32 })
            }
            Control::Layer { index, weight, duration } => {
                Op::Layer(pb::LayerWeight { index: *index as u32, weight: *weight, duration: *duration })
            }
            Control::Ik(specs) => {
                let keyed = specs.iter().map(|s| IkDoc::from_spec(s).to_keyed_spec("").expect("a fixed constraint"));
                Op::Ik(pb::IkControl { constraints: keyed.map(|k| ik_to_pb(&k)).collect() })
            }
            Control::Set(parameters) => {
                let value = |v: &serde_json::Value| pb::GraphValue {
                    value: Some(match v.as_bool() {
                        Some(b) => pb::graph_value::Value::Flag(b),
                        None => pb::graph_value::Value::Number(v.as_f64().unwrap()),
                    }),
                };
                let parameters = parameters.iter().map(|(k, v)| (k.clone(), value(v))).collect();
                Op::Set(pb::SetParameters { parameters })
            }
            Control::SetIk(_) | Control::SetGraph(_) => panic!("resolved controls are never sent"),
        }
    }

    /// A motion to fade to (its lookup is the transport's).
    fn test_motion() -> Arc<StreamMotion> {
        use crate::stream::tests::{clip, pinned};
        let req = crate::stream::StreamRequest { fps: 30, ..Default::default() };
        let params = StreamParams::new(pinned("c1", clip()), req).unwrap();
        Arc::clone(&params.motion)
    }

    fn ready(parsed: ParsedControl<impl std::fmt::Debug>) -> Control {
        match parsed {
            ParsedControl::Ready(control) => control,
            other => panic!("a crossfade: {other:?}"),
        }
    }

    /// One message per op, as a client writes it (every field given).
    fn messages() -> Vec<serde_json::Value> {
        vec![
            json!({"op": "play"}),
            json!({"op": "pause"}),
            json!({"op": "seek", "time": 1.5}),
            json!({"op": "speed", "speed": -2.0}),
            json!({"op": "stop"}),
            json!({"op": "crossfade", "to": {"layers": [{"clip": "run"}]}, "duration": 0.4, "ease": "ease_in_out"}),
            json!({"op": "layer", "index": 1, "weight": 0.25, "duration": 0.5}),
            // Numbers an f32 holds exactly, so that they come back as written.
            json!({"op": "ik", "constraints": [
                {"kind": "two_bone", "joints": ["hip", "knee", "foot"], "target": [0.25, -1.5, 0.125]},
                {"kind": "aim", "joint": "head", "target": [1.0, 2.0, 3.0], "weight": 0.5}
            ]}),
            json!({"op": "reset_springs"}),
            json!({"op": "set", "parameters": {"jump": true, "speed": 2.5}}),
        ]
    }

    #[test]
    fn every_control_round_trips_json_control_protobuf() {
        for message in messages() {
            let parsed = parse_control(&message.to_string()).unwrap();
            let control = match parsed {
                ParsedControl::Ready(control) => control,
                ParsedControl::Crossfade { to, duration, ease } => {
                    assert_eq!((&to, duration, ease), (&message["to"], 0.4, Ease::EaseInOut));
                    let fade = Crossfade { to: test_motion(), duration, ease, source: Some(Arc::new(to)) };
                    let control = Control::Crossfade(fade);
                    assert_eq!(control.to_json().as_ref(), Some(&message));
                    let ParsedControl::Crossfade { to: None, duration: d, ease: e } =
                        ParsedControl::from_pb(Some(to_pb(&control))).unwrap()
                    else {
                        panic!("a crossfade");
                    };
                    assert_eq!((d, e), (duration, ease));
                    continue;
                }
            };
            assert_eq!(ready(ParsedControl::from_pb(Some(to_pb(&control))).unwrap()), control, "{message}");
            match control.to_json() {
                Some(again) => assert_eq!(again, message),
                None => assert_eq!(control, Control::Stop, "only `stop` is not said again"),
            }
        }
    }

    #[test]
    fn every_op_has_a_message() {
        let ops: Vec<String> = messages().iter().map(|m| m["op"].as_str().unwrap().to_owned()).collect();
        assert_eq!(ops, OPS);
    }

    #[test]
    fn refusals_list_the_ops() {
        let e = serde_json::from_str::<ControlMsg>("{}").unwrap_err();
        assert!(not_a_control(&e, true).starts_with(
            r#"expected {"op": "play"|"pause"|"seek"|"speed"|"stop"|"crossfade"|"layer"|"ik"|"reset_springs"|"set", ...}: "#
        ));
        assert!(not_a_control(&e, false).starts_with(
            r#"expected {"op": "play"|"pause"|"seek"|"speed"|"crossfade"|"layer"|"ik"|"reset_springs"|"set", ...}: "#
        ));
    }

    #[test]
    fn starting_ops_are_not_controls() {
        let open = ParsedControl::from_pb(Some(Op::Open(pb::Open::default()))).unwrap_err();
        assert_eq!((open.code, open.pointer.as_str()), ("bad_control", ""));
        assert_eq!(ParsedControl::from_pb(None).unwrap_err().detail, "a PlaybackControl needs an op");
    }

    #[test]
    fn controls_are_validated() {
        assert!(Control::Seek(f64::NAN).validate().is_err());
        assert!(Control::Speed(f64::INFINITY).validate().is_err());
        assert!(Control::Speed(-1000.5).validate().is_err());
        assert_eq!(Control::Speed(-1000.0).validate(), Ok(Control::Speed(-1000.0)));
        let ramp = |weight, duration| Control::Layer { index: 0, weight, duration }.validate();
        assert_eq!(ramp(2.0, -1.0), Err("a weight ramp's duration must be between 0 and 3600 seconds"));
        assert_eq!(ramp(2.0, 1.0), Err("a layer weight must be in [0, 1]"));
    }

    #[test]
    fn only_stop_is_refused_on_a_broadcast() {
        assert!(Control::Stop.refused_on_broadcast().is_some());
        assert_eq!(Control::Pause.refused_on_broadcast(), None);
        assert_eq!(Control::Pause.status_after(false, 2.0), (true, 2.0));
        assert_eq!(Control::Speed(-1.0).status_after(true, 2.0), (true, -1.0));
        assert_eq!(Control::Seek(1.0).status_after(true, 2.0), (true, 2.0));
    }
}
