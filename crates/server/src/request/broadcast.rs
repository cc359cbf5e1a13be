//! Creating a broadcast (docs/broadcasts.md): a motion stream's rules (`RawStream`
//! for fps, space and joints, `RawMotion` for the motion) plus the two a
//! broadcast adds — frames are `trs` poses, and how long it lives unwatched.

use std::time::Duration;

use super::graph_stream::RawGraphStream;
use super::motion::RawMotion;
use super::raw::{Field, Locate, Raw, unprocessable, whole};
use super::stream::RawStream;
use crate::error::ApiError;
use crate::state::AppState;
use crate::stream::{BroadcastSpec, Encoding};

/// Seconds a broadcast lives with no viewers and no controls, unless asked.
pub const DEFAULT_IDLE_TIMEOUT_SECS: u64 = 300;

/// The longest idle timeout a broadcast may ask for (one day).
pub const MAX_IDLE_TIMEOUT_SECS: u64 = 86_400;

/// A broadcast request, as a transport decoded it.
#[derive(Debug, Clone, Copy)]
pub struct RawBroadcast<'a> {
    /// fps, space and joints (its encoding, start and speed are unused).
    pub stream: RawStream<'a>,
    /// `trs` only; `None`: `trs`.
    pub format: Option<Raw<'a>>,
    /// Whole seconds in 1..=[`MAX_IDLE_TIMEOUT_SECS`]; `None`: the default.
    pub idle_timeout_secs: Option<Raw<'a>>,
    pub at: Locate,
}

impl RawBroadcast<'_> {
    /// The broadcast `motion` makes, its clips pinned at their current
    /// versions; `description` is what `GET` will show of it.
    ///
    /// # Errors
    /// `bad_number`, `bad_parameter`; `format_not_streamable`,
    /// `idle_timeout_out_of_range`; then a motion stream's refusals
    /// ([`RawStream::motion_params`]).
    pub async fn spec(
        &self,
        state: &AppState,
        motion: RawMotion<'_>,
        description: serde_json::Value,
    ) -> Result<BroadcastSpec, ApiError> {
        let (stream, idle) = self.checked()?;
        let (params, work_per_sec) = stream.motion_params(state, motion).await?;
        Ok(BroadcastSpec {
            params: crate::stream::StreamParams { encoding: Encoding::Json, ..params },
            idle_timeout: idle,
            description,
            work_per_sec,
        })
    }

    /// As [`RawBroadcast::spec`] for a graph (docs/graphs.md).
    ///
    /// # Errors
    /// As [`RawBroadcast::spec`], with a graph stream's refusals
    /// ([`RawStream::graph_params`]).
    pub async fn graph_spec(
        &self,
        state: &AppState,
        graph: RawGraphStream<'_>,
        description: serde_json::Value,
    ) -> Result<BroadcastSpec, ApiError> {
        let (stream, idle) = self.checked()?;
        let (params, work_per_sec) = stream.graph_params(state, graph).await?;
        Ok(BroadcastSpec {
            params: crate::stream::StreamParams { encoding: Encoding::Json, ..params },
            idle_timeout: idle,
            description,
            work_per_sec,
        })
    }

    /// The format and idle timeout checked, and the stream request to price
    /// as JSON, the larger encoding: viewers may ask for either.
    fn checked(&self) -> Result<(RawStream<'_>, Duration), ApiError> {
        let format = super::raw::Format::decode(self.format, self.at)?;
        if format != super::raw::Format::Trs {
            let detail = "broadcast frames are `trs` poses (as every stream's); `matrix` and `skinning` are for \
                          POST /v1/poses and /v1/samples"
                .to_owned();
            return Err(unprocessable("format_not_streamable", Field::Format, self.at, detail));
        }
        Ok((RawStream { encoding: None, ..self.stream }, self.idle_timeout()?))
    }

    fn idle_timeout(&self) -> Result<Duration, ApiError> {
        let Some(raw) = self.idle_timeout_secs else {
            return Ok(Duration::from_secs(DEFAULT_IDLE_TIMEOUT_SECS));
        };
        let secs = whole(raw, Field::IdleTimeout, self.at)?;
        if !(1.0..=MAX_IDLE_TIMEOUT_SECS as f64).contains(&secs) {
            let detail = format!("`idle_timeout_secs` must be in 1..={MAX_IDLE_TIMEOUT_SECS}, got {secs}");
            return Err(unprocessable("idle_timeout_out_of_range", Field::IdleTimeout, self.at, detail));
        }
        Ok(Duration::from_secs(secs as u64))
    }
}
