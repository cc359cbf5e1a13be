//! Sampling requests: one pose (`GET …/pose`, `Sample`) and many
//! (`POST …/sample`, `SampleBatch`), checked and bound to their clip.

use std::ops::RangeInclusive;
use std::sync::Arc;

use glam::Mat4;

use super::cost::{Cost, Estimate, Wire};
use super::raw::{Field, Format, Locate, Raw, RawModes, finite, malformed, unprocessable};
use crate::cache::CachedClip;
use crate::compression::AnswerCoding;
use crate::error::ApiError;
use crate::state::AppState;
use crate::stream::MAX_FPS;
use crate::work::price;
use anim::{Clip, SampleOptions, Sampler, frame_count, frame_times};
use formats::wire::proto::pb;

/// The frame rates of a `{start, end, fps}` range: a stream's (docs/api.md).
pub const FPS_RANGE: RangeInclusive<f64> = 1.0..=MAX_FPS as f64;

/// # Errors
/// `no_inverse_binds`: skinning matrices of a clip without inverse binds.
fn check_format(format: Format, clip: &Clip, at: Locate) -> Result<(), ApiError> {
    if format == Format::Skinning && !clip.skeleton().has_inverse_binds() {
        let detail = "format=skinning needs a clip whose skeleton has inverse bind matrices".to_owned();
        return Err(unprocessable("no_inverse_binds", Field::Format, at, detail));
    }
    Ok(())
}

/// The clip `id`, checked to render `format`.
async fn clip_for(state: &AppState, id: &str, format: Format, at: Locate) -> Result<Arc<CachedClip>, ApiError> {
    let cached = super::raw::clip(state, id).await?;
    check_format(format, &cached.clip, at)?;
    Ok(cached)
}

/// Samples `clip` at request time `t`: the pose into `sampler` (TRS), or
/// the model (skinning) matrices into `matrices`. Returns the clip time. The
/// one evaluation every renderer reads from.
pub fn evaluate(
    clip: &Clip,
    t: f64,
    options: &SampleOptions,
    format: Format,
    sampler: &mut Sampler,
    matrices: &mut Vec<Mat4>,
) -> f32 {
    match format {
        Format::Trs => clip.sample(t, options, sampler),
        Format::Matrix | Format::Skinning => {
            clip.matrices(t, options, format == Format::Skinning, sampler, matrices);
            clip.clip_time(t, options.playback.unwrap_or(clip.playback()), options.ease)
        }
    }
}

/// Whether a clip route plays the clip `id` as its one-layer motion so
/// that the clip's own spring chains run (docs/springs.md, “Clip routes”):
/// the caller did not turn them off (`springs`, default on) and the clip
/// has some.
///
/// # Errors
/// `clip_not_found`.
pub(super) async fn runs_springs(state: &AppState, id: &str, springs: bool) -> Result<bool, ApiError> {
    Ok(springs && !super::raw::clip(state, id).await?.springs.chains.is_empty())
}

/// `ease` on a clip route that plays a motion (a character, or the clip's
/// spring chains): a motion's layers have no ease (its streams do).
pub(super) fn no_ease_in_motion(at: crate::error::At, why: &str) -> ApiError {
    let detail = format!("`ease` does not apply {why}: the one-layer motion played has no ease");
    ApiError::BadParameter { code: "unknown_parameter", at, detail }
}

/// One pose, as a transport decoded it.
#[derive(Debug, Clone, Copy)]
pub struct RawPose<'a> {
    pub t: Option<Raw<'a>>,
    pub modes: RawModes<'a>,
    pub format: Option<Raw<'a>>,
    pub at: Locate,
}

/// A checked one-pose request.
#[derive(Debug, Clone, Copy)]
pub struct PoseRequest {
    pub t: f64,
    pub options: SampleOptions,
    pub format: Format,
    /// Its price in work units, once bound to a clip (0 before).
    pub work: u64,
}

impl RawPose<'_> {
    /// # Errors
    /// `missing_parameter`, `bad_number`, `bad_parameter`.
    pub fn check(&self) -> Result<PoseRequest, ApiError> {
        let t = self.t.ok_or_else(|| malformed("missing_parameter", Field::Time, self.at, "`t` is required".into()))?;
        let t = finite(t, Field::Time, self.at)?;
        let options = self.modes.check(self.at)?;
        let format = Format::decode(self.format, self.at)?;
        Ok(PoseRequest { t, options, format, work: 0 })
    }

    /// Checks the request, then binds it to the clip `id` at its current
    /// version and checks what its answer, sent as `wire` and compressed as
    /// `coding` says, would cost.
    ///
    /// # Errors
    /// As [`RawPose::check`], then `clip_not_found`, `no_inverse_binds`,
    /// `answer_too_large`.
    pub async fn resolve(
        &self,
        state: &AppState,
        id: &str,
        wire: Wire,
        coding: AnswerCoding,
    ) -> Result<(PoseRequest, Arc<CachedClip>), ApiError> {
        let request = self.check()?;
        let cached = clip_for(state, id, request.format, self.at).await?;
        let estimate = Estimate::pose(&cached.clip, &cached.meta.id, request.format, wire);
        let (joints, per_pose) = (cached.clip.joint_count() as u64, price::clip_pose(&cached.clip));
        let cost = Cost::new(1, joints, per_pose, estimate.total(1)).compressed(coding.at(estimate.total(1)));
        cost.check(&state.config.limits, Field::Time, self.at)?;
        Ok((PoseRequest { work: cost.work(), ..request }, cached))
    }
}

/// Many poses, as a transport decoded them: `times`, or a range of
/// `start`, `end` and `fps` (a JSON body may carry any mix; a protobuf
/// message one or the other, or neither).
#[derive(Debug, Clone, Copy)]
pub struct RawBatch<'a> {
    pub times: Option<&'a [f64]>,
    pub start: Option<f64>,
    pub end: Option<f64>,
    pub fps: Option<f64>,
    pub modes: RawModes<'a>,
    pub format: Option<Raw<'a>>,
    pub at: Locate,
}

/// A checked many-pose request.
#[derive(Debug, Clone)]
pub struct Sampling {
    pub times: Vec<f64>,
    pub options: SampleOptions,
    pub format: Format,
    /// The answer's size bound, once bound to a clip (0 before).
    pub answer_bytes: u64,
    /// Its price in work units, once bound to a clip (0 before).
    pub work: u64,
}

impl Sampling {
    /// Whether its answer is big enough to be streamed in pieces (chunked
    /// REST, `SampleStream`) rather than built whole.
    pub fn is_large(&self) -> bool {
        self.answer_bytes > STREAM_ABOVE_BYTES
    }
}

/// Answers whose size bound is over this are sent in pieces as they are
/// evaluated, so a request's memory is a piece, not its answer.
pub const STREAM_ABOVE_BYTES: u64 = 1024 * 1024;

impl<'a> RawBatch<'a> {
    /// A protobuf batch message's `times` or `range` (whichever its `when`
    /// holds), its modes and its format number; the range's fields are
    /// located in `/range`.
    pub fn of_message(
        times: Option<&'a pb::Times>,
        range: Option<&pb::FrameRange>,
        modes: RawModes<'a>,
        format: i32,
    ) -> RawBatch<'a> {
        RawBatch {
            times: times.map(|t| t.values.as_slice()),
            start: range.map(|r| r.start),
            end: range.map(|r| r.end),
            fps: range.map(|r| r.fps),
            modes,
            format: Some(Raw::Enum(format)),
            at: super::raw::in_batch_message,
        }
    }
}

impl RawBatch<'_> {
    /// # Errors
    /// `bad_parameter`, `bad_number`; `times_or_range`, `fps_out_of_range`,
    /// `bad_range`, `too_many_poses` (over `max_poses`).
    pub fn check(&self, max_poses: usize) -> Result<Sampling, ApiError> {
        let options = self.modes.check(self.at)?;
        let format = Format::decode(self.format, self.at)?;
        let times = self.times(max_poses)?;
        Ok(Sampling { times, options, format, answer_bytes: 0, work: 0 })
    }

    /// Checks the request against the configured pose limit, then binds it to
    /// the clip `id` at its current version and checks what its answer, sent
    /// as `wire` and compressed as `coding` says, would cost (before
    /// anything is evaluated).
    ///
    /// # Errors
    /// As [`RawBatch::check`], then `clip_not_found`, `no_inverse_binds`,
    /// then `too_many_poses` (over `max_joint_poses`), `answer_too_large`.
    pub async fn resolve(
        &self,
        state: &AppState,
        id: &str,
        wire: Wire,
        coding: AnswerCoding,
    ) -> Result<(Sampling, Arc<CachedClip>), ApiError> {
        let mut sampling = self.check(state.config.limits.max_poses)?;
        let cached = clip_for(state, id, sampling.format, self.at).await?;
        let estimate = Estimate::batch(&cached.clip, &cached.meta.id, sampling.format, wire);
        let poses = sampling.times.len() as u64;
        let (joints, per_pose) = (cached.clip.joint_count() as u64, price::clip_pose(&cached.clip));
        let cost =
            Cost::new(poses, joints, per_pose, estimate.total(poses)).compressed(coding.at(estimate.total(poses)));
        let field = if self.times.is_some() { Field::Times } else { Field::When };
        cost.check(&state.config.limits, field, self.at)?;
        sampling.answer_bytes = cost.bytes;
        sampling.work = cost.work();
        Ok((sampling, cached))
    }

    fn times(&self, max_poses: usize) -> Result<Vec<f64>, ApiError> {
        let at = self.at;
        let too_many = |n: u64, field: Field| {
            let detail = format!("{n} poses requested; the limit is {max_poses} per request");
            unprocessable("too_many_poses", field, at, detail)
        };
        match (self.times, self.start, self.end, self.fps) {
            (Some(times), None, None, None) => {
                for (i, &t) in times.iter().enumerate() {
                    finite(Raw::Number(t), Field::TimeAt(i), at)?;
                }
                if times.len() > max_poses {
                    return Err(too_many(times.len() as u64, Field::Times));
                }
                Ok(times.to_vec())
            }
            (None, Some(start), Some(end), Some(fps)) => {
                let start = finite(Raw::Number(start), Field::Start, at)?;
                let end = finite(Raw::Number(end), Field::End, at)?;
                let fps = finite(Raw::Number(fps), Field::Fps, at)?;
                if !FPS_RANGE.contains(&fps) {
                    let detail = format!("fps must be in 1..={MAX_FPS}, got {fps}");
                    return Err(unprocessable("fps_out_of_range", Field::Fps, at, detail));
                }
                if end < start {
                    let detail = format!("end {end} is before start {start}");
                    return Err(unprocessable("bad_range", Field::End, at, detail));
                }
                let n = frame_count(start, end, fps);
                if n > max_poses as u64 {
                    return Err(too_many(n, Field::When));
                }
                Ok(frame_times(start, end, fps).collect())
            }
            _ => {
                let detail = "give either `times` or a range (`start`, `end` and `fps`), not both".to_owned();
                Err(unprocessable("times_or_range", Field::When, at, detail))
            }
        }
    }
}
