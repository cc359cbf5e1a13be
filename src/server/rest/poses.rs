//! Pose routes: one pose (`GET …/pose`) and many (`POST …/sample`).
//!
//! The clip comes from the cache (compiled once per version); sampling uses a
//! per-thread [`Sampler`] and matrix buffer, so a request allocates only its
//! response body, and poses are serialised straight from the core's buffers
//! into it. Large sample requests run on the blocking pool.

use std::cell::RefCell;

use axum::extract::{RawQuery, State};
use axum::http::header::CONTENT_TYPE;
use axum::http::{HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use glam::Mat4;
use serde::Deserialize;
use utoipa::ToSchema;

use crate::anim::{Ease, SampleOptions, Sampler, Space, frame_count, frame_times};
use crate::server::auth::ReadAccess;
use crate::server::cache::CachedClip;
use crate::server::error::ApiError;
use crate::server::state::AppState;
use crate::wire::json::{EaseDoc, MatricesJson, PlaybackDoc, PoseJson, SpaceDoc};

use super::extract::{ClipId, JsonBody, QueryParams};

/// The frame-rate range of `{start, end, fps}` sample requests (the same as streams, SPEC §5).
pub const FPS_RANGE: std::ops::RangeInclusive<f64> = 1.0..=240.0;

/// Response-size estimates, so a pose body is written without reallocating.
const POSE_HEADER_BYTES: usize = 128;
const JOINT_BYTES: usize = 160;

/// Sample requests with more poses than this run on the blocking pool.
const BLOCKING_POSES: usize = 256;

/// How each pose is rendered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Format {
    /// Translation, rotation `[x,y,z,w]`, scale per joint, in the requested space.
    #[default]
    Trs,
    /// Column-major 4×4 model matrices (model space).
    Matrix,
    /// `M_j · invBind_j`, for clips with inverse bind matrices.
    Skinning,
}

impl std::str::FromStr for Format {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "trs" => Ok(Format::Trs),
            "matrix" => Ok(Format::Matrix),
            "skinning" => Ok(Format::Skinning),
            _ => Err("expected one of: trs, matrix, skinning".into()),
        }
    }
}

thread_local! {
    static SCRATCH: RefCell<(Sampler, Vec<Mat4>)> = RefCell::new((Sampler::new(), Vec::new()));
}

/// Appends the pose of `cached` at request time `t` to `out` as JSON.
fn write_pose(out: &mut Vec<u8>, cached: &CachedClip, t: f64, options: &SampleOptions, format: Format) {
    let clip = &cached.clip;
    SCRATCH.with_borrow_mut(|(sampler, matrices)| {
        let written = match format {
            Format::Trs => {
                let clip_time = clip.sample(t, options, sampler);
                let pose = PoseJson {
                    clip: &cached.meta.id,
                    time: t,
                    clip_time,
                    space: options.space,
                    skeleton: clip.skeleton(),
                    pose: sampler.pose(),
                };
                pose.write_to(out);
                Ok(())
            }
            Format::Matrix | Format::Skinning => {
                let skinning = format == Format::Skinning;
                clip.matrices(t, options, skinning, sampler, matrices);
                let clip_time = clip.clip_time(t, options.playback.unwrap_or(clip.playback()), options.ease);
                let doc = MatricesJson {
                    clip: &cached.meta.id,
                    time: t,
                    clip_time,
                    format: if skinning { "skinning" } else { "matrix" },
                    skeleton: clip.skeleton(),
                    matrices: matrices.as_slice(),
                };
                serde_json::to_writer(SmallWrites(&mut *out), &doc)
            }
        };
        // Writing into a Vec cannot fail, and every float is finite.
        debug_assert!(written.is_ok());
    });
}

/// A `Vec<u8>` writer that copies short slices byte by byte. serde_json
/// writes a pose as hundreds of tiny pieces (a float, a comma); through
/// `Vec::extend_from_slice` each becomes a call to libc `memmove`, which
/// showed up at ~6% of a pose request's CPU time in `perf`.
struct SmallWrites<'a>(&'a mut Vec<u8>);

impl std::io::Write for SmallWrites<'_> {
    #[inline]
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.write_all(buf)?;
        Ok(buf.len())
    }

    #[inline]
    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        if buf.len() <= 32 {
            self.0.reserve(buf.len());
            for &b in buf {
                self.0.push(b);
            }
        } else {
            self.0.extend_from_slice(buf);
        }
        Ok(())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

fn check_format(cached: &CachedClip, format: Format, pointer: &str) -> Result<(), ApiError> {
    if format == Format::Skinning && !cached.clip.skeleton().has_inverse_binds() {
        return Err(ApiError::invalid(
            "no_inverse_binds",
            pointer,
            "format=skinning needs a clip whose skeleton has inverse bind matrices",
        ));
    }
    Ok(())
}

fn json_response(body: Vec<u8>) -> Response {
    (StatusCode::OK, [(CONTENT_TYPE, HeaderValue::from_static("application/json"))], body).into_response()
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
    ),
    responses(
        (status = 200, description = "The pose", body = super::openapi::PoseSchema),
        (status = 400, description = "A parameter does not parse", body = super::openapi::Problem),
        (status = 404, body = super::openapi::Problem),
        (status = 422, description = "format=skinning without inverse binds", body = super::openapi::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn get_pose(
    State(state): State<AppState>,
    _: ReadAccess,
    ClipId(id): ClipId,
    RawQuery(query): RawQuery,
) -> Result<Response, ApiError> {
    let params = QueryParams::parse(query.as_deref(), &["t", "space", "playback", "ease", "format"])?;
    let t = params.finite("t")?.ok_or_else(|| ApiError::parameter("missing_parameter", "t", "`t` is required"))?;
    let options = SampleOptions {
        playback: params.parsed::<PlaybackDoc>("playback")?.map(Into::into),
        ease: params.parsed::<EaseDoc>("ease")?.map_or(Ease::Linear, Into::into),
        space: params.parsed::<SpaceDoc>("space")?.map_or(Space::Local, Into::into),
    };
    let format = params.parsed::<Format>("format")?.unwrap_or_default();
    let cached = state.clip(&id).await?;
    check_format(&cached, format, "")?;
    let mut body = Vec::with_capacity(POSE_HEADER_BYTES + JOINT_BYTES * cached.clip.joint_count());
    write_pose(&mut body, &cached, t, &options, format);
    state.counters.poses.increment(1);
    Ok(json_response(body))
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
    #[serde(default)]
    pub space: Option<SpaceDoc>,
    #[serde(default)]
    pub playback: Option<PlaybackDoc>,
    #[serde(default)]
    pub ease: Option<EaseDoc>,
    #[serde(default)]
    pub format: Option<Format>,
}

fn parse_sample(body: &[u8]) -> Result<SampleRequest, ApiError> {
    let de = &mut serde_json::Deserializer::from_slice(body);
    let req = serde_path_to_error::deserialize(&mut *de).map_err(|e| {
        use serde_path_to_error::Segment;
        let pointer: String = e
            .path()
            .iter()
            .map(|s| match s {
                Segment::Seq { index } => format!("/{index}"),
                Segment::Map { key } => format!("/{}", key.replace('~', "~0").replace('/', "~1")),
                Segment::Enum { variant } => format!("/{variant}"),
                Segment::Unknown => String::new(),
            })
            .collect();
        let inner = e.into_inner();
        if inner.is_syntax() || inner.is_eof() {
            ApiError::MalformedJson { pointer, detail: inner.to_string() }
        } else {
            ApiError::invalid("invalid_field", pointer, inner.to_string())
        }
    })?;
    de.end().map_err(|e| ApiError::MalformedJson { pointer: String::new(), detail: e.to_string() })?;
    Ok(req)
}

/// The request times, bounded by `max_poses`.
fn times_of(req: &SampleRequest, max_poses: usize) -> Result<Vec<f64>, ApiError> {
    let too_many = |n: u64, pointer: &str| ApiError::TooMany {
        code: "too_many_poses",
        pointer: pointer.to_owned(),
        detail: format!("{n} poses requested; the limit is {max_poses} per request"),
    };
    match (&req.times, req.start, req.end, req.fps) {
        (Some(times), None, None, None) => {
            if times.len() > max_poses {
                return Err(too_many(times.len() as u64, "/times"));
            }
            Ok(times.clone())
        }
        (None, Some(start), Some(end), Some(fps)) => {
            if !FPS_RANGE.contains(&fps) {
                return Err(ApiError::invalid(
                    "fps_out_of_range",
                    "/fps",
                    format!("fps must be in 1..=240, got {fps}"),
                ));
            }
            if end < start {
                return Err(ApiError::invalid("bad_range", "/end", format!("end {end} is before start {start}")));
            }
            let n = frame_count(start, end, fps);
            if n > max_poses as u64 {
                return Err(too_many(n, ""));
            }
            Ok(frame_times(start, end, fps).collect())
        }
        _ => Err(ApiError::invalid(
            "times_or_range",
            "",
            "give either `times` or all of `start`, `end` and `fps`, not both",
        )),
    }
}

/// Many poses in one request.
#[utoipa::path(
    post, path = "/v1/clips/{id}/sample", tag = "poses",
    params(("id" = String, Path, description = "Clip id")),
    request_body(content = SampleRequest, content_type = "application/json"),
    responses(
        (status = 200, description = "`{\"poses\": [pose, ...]}`", body = super::openapi::PosesSchema),
        (status = 400, body = super::openapi::Problem),
        (status = 404, body = super::openapi::Problem),
        (status = 422, description = "Bad times, range or fps; too many poses", body = super::openapi::Problem),
    ),
    security((), ("bearer" = []))
)]
pub async fn sample(
    State(state): State<AppState>,
    _: ReadAccess,
    ClipId(id): ClipId,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let req = parse_sample(&body)?;
    let times = times_of(&req, state.config.limits.max_poses)?;
    let options = SampleOptions {
        playback: req.playback.map(Into::into),
        ease: req.ease.map_or(Ease::Linear, Into::into),
        space: req.space.map_or(Space::Local, Into::into),
    };
    let format = req.format.unwrap_or_default();
    let cached = state.clip(&id).await?;
    check_format(&cached, format, "/format")?;
    let n = times.len();
    let render = move || {
        let mut body = Vec::with_capacity(16 + n * (POSE_HEADER_BYTES + JOINT_BYTES * cached.clip.joint_count()));
        body.extend_from_slice(b"{\"poses\":[");
        for (k, &t) in times.iter().enumerate() {
            if k > 0 {
                body.push(b',');
            }
            write_pose(&mut body, &cached, t, &options, format);
        }
        body.extend_from_slice(b"]}");
        body
    };
    let body = if n > BLOCKING_POSES {
        tokio::task::spawn_blocking(render).await.map_err(crate::server::metrics::join_failed)?
    } else {
        render()
    };
    state.counters.poses.increment(n as u64);
    Ok(json_response(body))
}
