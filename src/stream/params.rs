//! [`StreamParams`]: a stream request checked against the rules of SPEC §5
//! and bound to the compiled clip version it plays. The transports build
//! them (REST and gRPC alike); everything else in the engine reads them.

use std::sync::Arc;

use super::encode::Encoding;
use super::playhead::MAX_SPEED;
use crate::anim::{Clip, Ease, Playback, Space};

/// The highest accepted frame rate.
pub const MAX_FPS: u32 = 240;

/// Whatever holds a compiled clip (the server's cache entry, or a bare
/// [`Clip`]), so a stream can keep it alive without copying it.
pub trait ClipSource: Send + Sync + 'static {
    fn clip(&self) -> &Clip;
}

impl ClipSource for Clip {
    fn clip(&self) -> &Clip {
        self
    }
}

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
}

/// A request the engine cannot serve: the field at fault and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {detail}")]
pub struct ParamError {
    pub field: &'static str,
    pub detail: String,
}

/// A validated stream request, bound to the clip version it plays.
#[derive(Clone)]
pub struct StreamParams {
    pub clip_id: Arc<str>,
    pub version: u64,
    /// The compiled clip the stream started on; it keeps playing this
    /// version even if the clip is replaced or deleted meanwhile.
    pub source: Arc<dyn ClipSource>,
    pub fps: u32,
    pub start: f64,
    pub speed: f64,
    pub playback: Playback,
    pub ease: Ease,
    pub space: Space,
    pub encoding: Encoding,
    pub max_frames: Option<u64>,
    pub paused: bool,
}

impl std::fmt::Debug for StreamParams {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StreamParams")
            .field("clip_id", &self.clip_id)
            .field("version", &self.version)
            .field("fps", &self.fps)
            .field("start", &self.start)
            .field("speed", &self.speed)
            .field("playback", &self.playback)
            .field("encoding", &self.encoding)
            .field("max_frames", &self.max_frames)
            .finish_non_exhaustive()
    }
}

impl StreamParams {
    /// Validates `req` against the stream rules (SPEC §5).
    ///
    /// # Errors
    /// `fps` outside 1..=240, a non-finite start, a speed that is not finite
    /// or exceeds ±1000.
    pub fn new(
        clip_id: &str,
        version: u64,
        source: Arc<dyn ClipSource>,
        req: StreamRequest,
    ) -> Result<Self, ParamError> {
        let clip = source.clip();
        if !(1..=MAX_FPS).contains(&req.fps) {
            return Err(ParamError { field: "fps", detail: format!("must be 1..={MAX_FPS}, got {}", req.fps) });
        }
        let start = req.start.unwrap_or(f64::from(clip.start()));
        if !start.is_finite() {
            return Err(ParamError { field: "start", detail: "must be a finite number of seconds".into() });
        }
        let speed = req.speed.unwrap_or(1.0);
        if !speed.is_finite() || speed.abs() > MAX_SPEED {
            return Err(ParamError { field: "speed", detail: format!("must be finite and within ±{MAX_SPEED}") });
        }
        Ok(StreamParams {
            clip_id: clip_id.into(),
            version,
            playback: req.playback.unwrap_or(clip.playback()),
            source,
            fps: req.fps,
            start,
            speed,
            ease: req.ease,
            space: req.space,
            encoding: req.encoding,
            max_frames: (req.max_frames > 0).then_some(req.max_frames),
            paused: req.paused,
        })
    }

    /// The compiled clip.
    pub fn clip(&self) -> &Clip {
        self.source.clip()
    }
}
