//! Pose routes: one pose (`GET …/pose`) and many (`POST …/sample`).
//!
//! The query or body is decoded here and checked by `server::request` (the
//! rules and codes gRPC shares); this module renders the JSON. The clip comes from the cache (compiled once per version); sampling uses a
//! per-thread [`Sampler`] and matrix buffer, so a request allocates only its
//! response body, and poses are serialised straight from the core's buffers
//! into it. Each request is priced before it runs and charged to its caller
//! (`server::work`); all but the smallest are evaluated on the work pool, and
//! stop at the next pose once the client leaves or the request times out.
//! Answers whose size bound is over [`crate::request::STREAM_ABOVE_BYTES`]
//! are sent chunked, a piece at a time as the client reads (see [`Pieces`]).

use std::cell::RefCell;
use std::sync::Arc;

use axum::extract::State;
use axum::http::HeaderMap;
use axum::response::Response;
use glam::Mat4;
use serde::Deserialize;
use utoipa::ToSchema;

use crate::auth::CallerKey;
use crate::auth::ReadAccess;
use crate::cache::CachedClip;
use crate::compression::AnswerCoding;
use crate::error::ApiError;
use crate::request::{
    ClipRoute, Field, Format, Locate, Raw, RawBatch, RawModes, RawPose, Sampling, Wire, at_clip_route_as, evaluate,
    in_body, in_query, joint_subset, parameter_subset, parse_json,
};
use crate::state::AppState;
use crate::work::Cancel;
use anim::{SampleOptions, Sampler};
use formats::wire::json::{EaseDoc, Extras, MatricesJson, ParameterValues, PlaybackDoc, PoseJson, SpaceDoc};
use formats::wire::motion::MotionDoc;

use super::extract::{ClipId, JsonBody};
use super::motions::{PoseOfMotion, SamplesOfMotion};
use super::pieces::{self, Pieces, PoseWriter, json_response};
use super::query::{Query, QueryParams};

/// Response-size estimates, so a pose body is written without reallocating.
const POSE_HEADER_BYTES: usize = 128;
const JOINT_BYTES: usize = 160;

thread_local! {
    static SCRATCH: RefCell<(Sampler, Vec<Mat4>)> = RefCell::new((Sampler::new(), Vec::new()));
}

/// The joint and parameter subsets of a request (`None`: all).
#[derive(Debug, Clone, Default)]
struct Subsets {
    joints: Option<Vec<usize>>,
    parameters: Option<Vec<usize>>,
}

/// Appends the pose of `cached` at request time `t` to `out` as JSON (only
/// the subsets' joints and parameters, when given).
fn write_pose(
    out: &mut Vec<u8>,
    cached: &CachedClip,
    t: f64,
    (options, format): (&SampleOptions, Format),
    subsets: &Subsets,
) {
    let clip = &cached.clip;
    SCRATCH.with_borrow_mut(|(sampler, matrices)| {
        let clip_time = evaluate(clip, t, options, format, sampler, matrices);
        let parameters = ParameterValues::of(clip.parameters(), sampler.pose(), subsets.parameters.as_deref());
        let joints = subsets.joints.as_deref();
        let extras = Extras { joints, root_motion: None, ik: sampler.ik_reports(), parameters, tail: &[], feet: &[] };
        match format {
            Format::Trs => {
                let pose = PoseJson {
                    clip: &cached.meta.id,
                    time: t,
                    clip_time,
                    space: options.space,
                    skeleton: clip.skeleton(),
                    pose: sampler.pose(),
                };
                pose.write_with(out, extras);
            }
            Format::Matrix | Format::Skinning => {
                let doc = MatricesJson {
                    clip: &cached.meta.id,
                    time: t,
                    clip_time,
                    format: if format == Format::Skinning { "skinning" } else { "matrix" },
                    skeleton: clip.skeleton(),
                    matrices: matrices.as_slice(),
                };
                doc.write_with(out, extras);
            }
        }
    });
}

/// One pose at request time `t`.
#[utoipa::path(
    get, path = "/v1/clips/{id}/pose", tag = "poses",
    params(
        ("id" = String, Path, description = "Clip id"),
        ("t" = f64, Query, description = "Request time in seconds (finite)"),
        ("space" = Option<String>, Query, pattern = "^(local|model)$", description = "local (default) | model"),
        ("playback" = Option<String>, Query, pattern = "^(once|loop|ping_pong)$", description = "once | loop | ping_pong (default: the clip's)"),
        ("ease" = Option<String>, Query, pattern = "^(linear|ease_in|ease_out|ease_in_out)$", description = "linear (default) | ease_in | ease_out | ease_in_out"),
        ("format" = Option<String>, Query, pattern = "^(trs|matrix|skinning)$", description = "trs (default) | matrix | skinning"),
        ("joints" = Option<String>, Query, description = "Comma-separated joint names: only those joints, in skeleton order (model space still goes through the whole hierarchy)"),
        ("parameters" = Option<String>, Query, description = "Comma-separated parameter names (docs/clip-format.md §3): only those parameters, in the clip's order"),
        ("character" = Option<String>, Query, description = "A character id or `name:<name>`: the clip played on it, answered as `POST /v1/poses` answers the one-layer motion `{\"layers\":[{\"clip\":id}],\"character\":…}` (docs/characters.md); refusals `character_not_found` (404), `unmappable_skeleton` (422) at `character`; `ease` is refused with it"),
        ("springs" = Option<bool>, Query, description = "true (default) | false. A clip with spring chains is answered as `POST /v1/poses` answers the one-layer motion `{\"layers\":[{\"clip\":id}]}`, its chains running (docs/springs.md, “Clip routes”; `ease` is refused then); false: the keyed pose"),
    ),
    responses(
        (status = 200, description = "The pose", body = super::schemas::PoseSchema),
        (status = 400, description = "A parameter does not parse (`missing_parameter`, `bad_number`, `bad_parameter`)", body = super::schemas::Problem),
        (status = 404, body = super::schemas::Problem),
        (status = 422, description = "format=skinning without inverse binds (`no_inverse_binds`); a price over `max_request_work` (`too_much_work`); an answer over `max_answer_bytes` (`answer_too_large`)", body = super::schemas::Problem),
        (status = 429, description = "The caller holds its share of the node's work (`caller_work_limit`, with `Retry-After`)", body = super::schemas::Problem),
        (status = 503, description = "The node's work capacity is taken (`overloaded`, with `Retry-After`); the request outlived `request_timeout_secs` (`request_timeout`)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn get_pose(
    State(state): State<AppState>,
    ReadAccess(caller): ReadAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
    Query(q): Query,
) -> Result<Response, ApiError> {
    let raw = RawPose { t: q.raw("t"), modes: q.modes(), format: q.raw("format"), at: in_query };
    let checked = raw.check()?;
    let route = ClipRoute {
        id: &id,
        character: q.get("character"),
        springs: q.springs()?,
        playback: checked.options.playback,
        ease: q.get("ease").map(|_| in_query as Locate),
    };
    if let Some(motion) = route.motion(&state).await? {
        return pose_as_motion(state, caller.key(), &headers, (motion, checked.t), &q).await;
    }
    let coding = AnswerCoding::of(&headers, state.config.compression.min_bytes);
    let (req, cached) = raw.resolve(&state, &id, Wire::Json, coding).await?;
    let list = |name: &str| -> Option<Vec<&str>> {
        q.raw(name).map(|raw| match raw {
            Raw::Text(text) => text.split(',').collect(),
            _ => Vec::new(),
        })
    };
    let joints = list("joints").map(|names| joint_subset(cached.clip.skeleton(), &names, in_query)).transpose()?;
    let parameters =
        list("parameters").map(|names| parameter_subset(cached.clip.parameters(), &names, in_query)).transpose()?;
    let subsets = Subsets { joints, parameters };
    let body = state
        .work
        .spend(&caller.key(), req.work, move |_| {
            let mut body = Vec::with_capacity(POSE_HEADER_BYTES + JOINT_BYTES * cached.clip.joint_count());
            write_pose(&mut body, &cached, req.t, (&req.options, req.format), &subsets);
            body
        })
        .await?;
    state.counters.poses.increment(1);
    Ok(json_response(body))
}

/// `GET …/pose` as `POST /v1/poses` of the one-layer motion of the clip
/// (on a character, or running its spring chains), refusals at the
/// query's names.
async fn pose_as_motion(
    state: AppState,
    caller: CallerKey,
    headers: &HeaderMap,
    ((motion, field), time): ((MotionDoc, Field), f64),
    q: &QueryParams,
) -> Result<Response, ApiError> {
    let list = |name: &str| q.get(name).map(|text| text.split(',').map(str::to_owned).collect());
    let req = PoseOfMotion {
        motion,
        time,
        space: q.get("space").map(str::to_owned),
        format: q.get("format").map(str::to_owned),
        joints: list("joints"),
        parameters: list("parameters"),
        inputs: None,
        fps: None,
        report: false,
    };
    super::motions::answer_pose(state, caller, headers, req).await.map_err(|e| at_clip_route_as(e, in_query, field))
}

/// `POST …/sample` as `POST /v1/samples` of the one-layer motion of the
/// clip (on a character, or running its spring chains).
async fn samples_as_motion(
    state: AppState,
    caller: CallerKey,
    headers: &HeaderMap,
    (motion, field): (MotionDoc, Field),
    req: SampleRequest,
) -> Result<Response, ApiError> {
    let samples = SamplesOfMotion {
        motion,
        times: req.times,
        start: req.start,
        end: req.end,
        fps: req.fps,
        space: req.space,
        format: req.format,
        joints: req.joints,
        parameters: req.parameters,
        inputs: None,
        report: false,
    };
    super::motions::answer_samples(state, caller, headers, samples)
        .await
        .map_err(|e| at_clip_route_as(e, in_body, field))
}

/// `POST …/sample`: either `times` or `start`, `end` and `fps`.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SampleRequest {
    /// Request times in seconds.
    #[serde(default)]
    pub times: Option<Vec<f64>>,
    /// First frame time (with `end` and `fps`).
    #[serde(default)]
    pub start: Option<f64>,
    /// Last frame time, inclusive when on the frame grid.
    #[serde(default)]
    pub end: Option<f64>,
    /// Frames per second, 1..=240.
    #[serde(default)]
    pub fps: Option<f64>,
    // The enums stay text here so that the request layer decodes them, with
    // the same code (`bad_parameter`) as a query parameter or a gRPC field.
    #[serde(default)]
    #[schema(value_type = Option<SpaceDoc>)]
    pub space: Option<String>,
    #[serde(default)]
    #[schema(value_type = Option<PlaybackDoc>)]
    pub playback: Option<String>,
    #[serde(default)]
    #[schema(value_type = Option<EaseDoc>)]
    pub ease: Option<String>,
    #[serde(default)]
    #[schema(value_type = Option<Format>)]
    pub format: Option<String>,
    /// Only these joints, in skeleton order (model space still goes through the whole hierarchy).
    #[serde(default)]
    pub joints: Option<Vec<String>>,
    /// Only these parameters (docs/clip-format.md §3), in the clip's order.
    #[serde(default)]
    pub parameters: Option<Vec<String>>,
    /// A character id or `name:<name>`: the clip played on it, as the
    /// one-layer motion `{"layers":[{"clip":id}],"character":…}` (docs/characters.md).
    #[serde(default)]
    pub character: Option<String>,
    /// Whether the clip's own spring chains run (default true): the clip
    /// answered as `POST /v1/samples` answers its one-layer motion
    /// (docs/springs.md, “Clip routes”); false: the keyed poses.
    #[serde(default)]
    pub springs: Option<bool>,
}

impl SampleRequest {
    fn raw(&self) -> RawBatch<'_> {
        fn text(v: &Option<String>) -> Option<Raw<'_>> {
            v.as_deref().map(Raw::Text)
        }
        RawBatch {
            times: self.times.as_deref(),
            start: self.start,
            end: self.end,
            fps: self.fps,
            modes: RawModes { space: text(&self.space), playback: text(&self.playback), ease: text(&self.ease) },
            format: text(&self.format),
            at: in_body,
        }
    }
}

/// Many poses in one request.
#[utoipa::path(
    post, path = "/v1/clips/{id}/sample", tag = "poses",
    params(("id" = String, Path, description = "Clip id")),
    request_body(content = SampleRequest, content_type = "application/json"),
    responses(
        (status = 200, description = "`{\"poses\": [pose, ...]}`; sent chunked, as it is evaluated, when the answer may exceed 1 MiB", body = super::schemas::PosesSchema),
        (status = 400, description = "Not JSON, or a value that does not parse (`bad_parameter` for an unknown space, playback, ease or format)", body = super::schemas::Problem),
        (status = 404, body = super::schemas::Problem),
        (status = 422, description = "A field of the wrong type (`invalid_field`), `times_or_range`, `fps_out_of_range`, `bad_range`, `too_many_poses` (over `max_poses`, or poses × joints over `max_joint_poses`), `too_much_work` (the price over `max_request_work`), `answer_too_large` (the answer's size bound over `max_answer_bytes`), `no_inverse_binds`", body = super::schemas::Problem),
        (status = 429, description = "The caller holds its share of the node's work (`caller_work_limit`, with `Retry-After`)", body = super::schemas::Problem),
        (status = 503, description = "The node's work capacity is taken (`overloaded`, with `Retry-After`); the request outlived `request_timeout_secs` (`request_timeout`)", body = super::schemas::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn sample(
    State(state): State<AppState>,
    ReadAccess(caller): ReadAccess,
    ClipId(id): ClipId,
    headers: HeaderMap,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let req: SampleRequest = parse_json(&body)?;
    let route = ClipRoute {
        id: &id,
        character: req.character.as_deref(),
        springs: req.springs != Some(false),
        playback: req.raw().check(state.config.limits.max_poses)?.options.playback,
        ease: req.ease.as_ref().map(|_| in_body as Locate),
    };
    if let Some(motion) = route.motion(&state).await? {
        return samples_as_motion(state, caller.key(), &headers, motion, req).await;
    }
    let coding = AnswerCoding::of(&headers, state.config.compression.min_bytes);
    let (sampling, cached) = req.raw().resolve(&state, &id, Wire::Json, coding).await?;
    let joints = req.joints.as_deref().map(|names| joint_subset(cached.clip.skeleton(), names, in_body)).transpose()?;
    let parameters = (req.parameters.as_deref())
        .map(|names| parameter_subset(cached.clip.parameters(), names, in_body))
        .transpose()?;
    let (large, work, n) = (sampling.is_large(), sampling.work, sampling.times.len());
    let mut writer = ClipPoses { sampling, cached, subsets: Subsets { joints, parameters } };
    if large {
        let ticket = state.work.charge(&caller.key(), work)?;
        return Ok(Pieces::new(state, Box::new(writer), ticket).into_response());
    }
    let body = state.work.spend(&caller.key(), work, move |cancel| pieces::whole(&mut writer, cancel)).await?;
    state.counters.poses.increment(n as u64);
    Ok(json_response(body))
}

/// A clip's poses at a request's times, for [`pieces`](super::pieces).
struct ClipPoses {
    sampling: Sampling,
    cached: Arc<CachedClip>,
    subsets: Subsets,
}

impl PoseWriter for ClipPoses {
    fn count(&self) -> usize {
        self.sampling.times.len()
    }

    fn bound(&self) -> u64 {
        self.sampling.answer_bytes
    }

    fn write(&mut self, out: &mut Vec<u8>, range: std::ops::Range<usize>, cancel: &Cancel) {
        for k in range {
            if !cancel.proceed() {
                return;
            }
            if k > 0 {
                out.push(b',');
            }
            let sampling = &self.sampling;
            let how = (&sampling.options, sampling.format);
            write_pose(out, &self.cached, sampling.times[k], how, &self.subsets);
        }
    }
}
