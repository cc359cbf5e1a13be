//! [`StreamParams`]: a stream request checked against the rules of docs/api.md
//! and bound to the motion (a clip is a one-layer motion) and the compiled
//! clip versions it plays. The transports build
//! them (REST and gRPC alike); everything else in the engine reads them.

use std::sync::Arc;

use super::compact::CompactLayout;
use super::encode::{Encoding, FrameEncoder, Names};
use super::graph::GraphProgram;
use super::pinned::{PinnedClip, StreamMotion};
use super::playhead::MAX_SPEED;
use anim::ik::IkLimits;
use anim::motion::{LayerSpec, MotionSpec};
use anim::spring::SpringsSpec;
use anim::{Clip, Ease, Motion, Playback, Space};

/// The highest accepted frame rate.
pub const MAX_FPS: u32 = 240;

/// What a client asked for, before validation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StreamRequest {
    pub fps: u32,
    /// `None`: the clip's start.
    pub start: Option<f64>,
    /// `None`: 1.
    pub speed: Option<f64>,
    /// `None`: the clip's default.
    pub playback: Option<Playback>,
    pub ease: Ease,
    pub space: Space,
    pub encoding: Encoding,
    /// 0: no limit.
    pub max_frames: u64,
    /// Start paused (private playbacks only).
    pub paused: bool,
    /// A clip stream's keyed poses: the clip's own spring chains left out
    /// (docs/springs.md, “Clip routes”).
    pub without_springs: bool,
}

/// A request the engine cannot serve: the field at fault and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {detail}")]
pub struct ParamError {
    pub field: &'static str,
    pub detail: String,
}

/// A validated stream request, bound to the motion (and so the clip
/// versions) it plays.
#[derive(Clone)]
pub struct StreamParams {
    /// The clip id frames name at first: the first layer's.
    pub clip_id: Arc<str>,
    /// What makes two playbacks the same program: the clip and version for a
    /// clip stream, the motion's cache key for a motion.
    pub identity: Arc<str>,
    /// The compiled clips the stream started on; it keeps playing these
    /// versions even if a clip is replaced or deleted meanwhile.
    pub motion: Arc<StreamMotion>,
    pub fps: u32,
    pub start: f64,
    pub speed: f64,
    pub ease: Ease,
    pub space: Space,
    pub encoding: Encoding,
    pub max_frames: Option<u64>,
    pub paused: bool,
    /// The output joints frames carry (skeleton order); `None`: all.
    pub joints: Option<Arc<[usize]>>,
    /// The parameters frames carry (the first clip's order); `None`: all.
    pub parameters: Option<Arc<[usize]>>,
    /// Ceilings on the constraints of `ik` controls.
    pub ik_limits: IkLimits,
    /// Compact frames' layout (`encoding` compact).
    pub compact: Option<Arc<CompactLayout>>,
    /// A graph stream's graph (docs/graphs.md), played in place of
    /// `motion` (its initial state's, which names the skeleton).
    pub graph: Option<GraphProgram>,
}

impl std::fmt::Debug for StreamParams {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StreamParams")
            .field("identity", &self.identity)
            .field("fps", &self.fps)
            .field("start", &self.start)
            .field("speed", &self.speed)
            .field("encoding", &self.encoding)
            .field("max_frames", &self.max_frames)
            .finish_non_exhaustive()
    }
}

impl StreamParams {
    /// A stream of one clip: validates `req` against the stream rules
    /// (docs/api.md) and plays the clip as a one-layer motion with the
    /// request's playback, and the clip's spring chains unless it asks
    /// `without_springs` (a program of its own then: other poses).
    ///
    /// # Errors
    /// `fps` outside 1..=240, a non-finite start, a speed that is not finite
    /// or exceeds ±1000.
    pub fn new(pinned: Arc<dyn PinnedClip>, req: StreamRequest) -> Result<Self, ParamError> {
        let playback = req.playback.unwrap_or(pinned.clip().playback());
        let springs = if req.without_springs { SpringsSpec::default() } else { pinned.springs().clone() };
        let keyed = if req.without_springs && !pinned.springs().chains.is_empty() { " keyed" } else { "" };
        let identity = format!("clip {}@{} {}{keyed}", pinned.id(), pinned.version(), playback.as_str());
        let layer = LayerSpec { playback: Some(playback), ..LayerSpec::new(pinned) };
        let motion =
            Motion::build(MotionSpec { layers: vec![layer], root_motion: None, springs, ..Default::default() })
                .map_err(|e| ParamError { field: "motion", detail: e.to_string() })?;
        Self::of_motion(Arc::new(motion), identity.into(), req)
    }

    /// A stream of a built motion whose program is called `identity`
    /// (equal identities play equal poses).
    ///
    /// # Errors
    /// As [`StreamParams::new`].
    pub fn of_motion(motion: Arc<StreamMotion>, identity: Arc<str>, req: StreamRequest) -> Result<Self, ParamError> {
        if !(1..=MAX_FPS).contains(&req.fps) {
            return Err(ParamError { field: "fps", detail: format!("must be 1..={MAX_FPS}, got {}", req.fps) });
        }
        let first = motion.first_clip();
        let start = req.start.unwrap_or(f64::from(first.clip().start()));
        if !start.is_finite() {
            return Err(ParamError { field: "start", detail: "must be a finite number of seconds".into() });
        }
        let speed = req.speed.unwrap_or(1.0);
        if !speed.is_finite() || speed.abs() > MAX_SPEED {
            return Err(ParamError { field: "speed", detail: format!("must be finite and within ±{MAX_SPEED}") });
        }
        Ok(StreamParams {
            clip_id: first.id().into(),
            identity,
            fps: req.fps,
            start,
            speed,
            ease: req.ease,
            space: req.space,
            encoding: req.encoding,
            max_frames: (req.max_frames > 0).then_some(req.max_frames),
            paused: req.paused,
            joints: None,
            parameters: None,
            ik_limits: IkLimits::default(),
            compact: None,
            graph: None,
            motion,
        })
    }

    /// The same stream carrying only `joints` (output joint indices, in
    /// skeleton order).
    /// The same stream with `ik` controls held to `limits`.
    pub fn with_ik_limits(self, limits: IkLimits) -> Self {
        StreamParams { ik_limits: limits, ..self }
    }

    /// The same stream in compact frames of `layout` (a program of its own:
    /// only viewers of the same bound and distance share a playback).
    pub fn with_compact(self, layout: Arc<CompactLayout>) -> Self {
        let (max_error, distance) = layout.key();
        let identity = format!("{} compact {max_error:08x} {distance:08x}", self.identity).into();
        StreamParams { encoding: Encoding::Compact, compact: Some(layout), identity, ..self }
    }

    /// The same stream playing `graph` from motion time 0: frames name the
    /// graph as their clip, and the stream is a program of its own (a graph
    /// stream is never shared: its `set` controls are its viewer's).
    pub fn with_graph(self, graph: GraphProgram) -> Self {
        static STREAMS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let unique = STREAMS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let identity = format!("graph {}@{} {unique}", graph.id, graph.version).into();
        StreamParams { clip_id: Arc::clone(&graph.id), identity, graph: Some(graph), start: 0.0, ..self }
    }

    /// An encoder of this stream's frames.
    pub fn encoder(&self) -> FrameEncoder {
        match (&self.compact, self.encoding) {
            (Some(c), Encoding::Compact) => FrameEncoder::compact(c),
            _ => FrameEncoder::new(self.encoding),
        }
    }

    pub fn with_joints(self, joints: Option<Vec<usize>>) -> Self {
        StreamParams { joints: joints.map(Into::into), ..self }
    }

    /// The same stream carrying only `parameters` (indices in the first
    /// clip's order).
    pub fn with_parameters(self, parameters: Option<Vec<usize>>) -> Self {
        StreamParams { parameters: parameters.map(Into::into), ..self }
    }

    /// What a protobuf viewer's first frame names: the joints, and the
    /// parameters with their widths.
    pub fn names(&self) -> Names {
        let layout = self.motion.parameters();
        let parameters: Vec<usize> = match &self.parameters {
            _ if self.graph.is_some() => Vec::new(),
            Some(subset) => subset.to_vec(),
            None => (0..layout.len()).collect(),
        };
        Names {
            joints: self.joint_names(),
            parameters: parameters.iter().map(|&p| layout.names()[p].clone()).collect(),
            widths: parameters.iter().map(|&p| layout.widths()[p]).collect(),
        }
    }

    /// The first layer's compiled clip.
    pub fn clip(&self) -> &Clip {
        self.motion.first_clip().clip()
    }

    /// The names of the joints frames carry.
    pub fn joint_names(&self) -> Vec<String> {
        let names = self.motion.skeleton().names();
        match &self.joints {
            Some(joints) => joints.iter().map(|&j| names[j].clone()).collect(),
            None => names.to_vec(),
        }
    }
}
