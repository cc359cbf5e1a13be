//! Composed requests (docs/motion.md): a motion's clips looked up at their current
//! versions and pinned, the motion built (its refusals pointed at
//! `/motion/…`) or found built for those versions in the motion cache
//! (`server::motion_cache`), the joint subset checked, and the answer priced
//! before any pose is evaluated. REST's `POST /v1/poses` and `/v1/samples`,
//! gRPC's `SampleMotion*`, streams, broadcasts and crossfades use it.

use std::sync::Arc;

use super::body::parse_json;
use super::cost::{Cost, Estimate, F64_TEXT, Wire};
use super::raw::{Field, Format, Locate, in_body, joint_subset, parameter_subset};
use crate::auth::CallerKey;
use crate::cache::CachedClip;
use crate::error::{ApiError, At};
use crate::motion_cache::MotionKey;
use crate::state::AppState;
use crate::stream::{PinnedClip, StreamMotion};
use anim::Motion;
use anim::ik::IkLimits;
use anim::motion::MotionSpec;
use formats::wire::motion::MotionDoc;

/// A motion and the joints asked for, as a transport decoded them.
#[derive(Debug, Clone)]
pub struct RawMotion<'a> {
    /// Clip ids still to be looked up.
    pub spec: MotionSpec<String>,
    /// Joint names; `None`: every joint.
    pub joints: Option<&'a [String]>,
    /// Parameter names (docs/clip-format.md §3); `None`: every parameter.
    pub parameters: Option<&'a [String]>,
    pub format: Format,
    pub at: Locate,
    /// The character to play on (an id or `name:…`), still to be looked up.
    pub character: Option<String>,
}

/// A built motion over pinned clips, and the output joints to send.
pub struct Composed {
    pub motion: Arc<StreamMotion>,
    /// Output joint indices, in skeleton order; `None`: all.
    pub joints: Option<Vec<usize>>,
    /// Output parameter indices, in the first clip's order; `None`: all.
    pub parameters: Option<Vec<usize>>,
    /// The motion's `,"warnings":[…]` member (empty without warnings).
    pub warnings: Vec<u8>,
}

/// Bytes a pose's `"root_motion"` adds: two planar transforms of four numbers.
pub(super) const ROOT_MOTION_BYTES: u64 = 80 + 8 * F64_TEXT;

/// Bytes a pose's `"feet"` adds at most (0 when no layer plants feet).
pub(super) fn feet_bytes(motion: &StreamMotion) -> u64 {
    use formats::wire::json::{FEET_MEMBER_BYTES, FOOT_REPORT_BYTES};
    match motion.planted_feet() as u64 {
        0 => 0,
        n => FEET_MEMBER_BYTES + n * FOOT_REPORT_BYTES,
    }
}

impl Composed {
    /// The first layer's clip id (what a composed pose names).
    pub fn clip_id(&self) -> &str {
        self.motion.first_clip().id()
    }

    /// What `poses` poses of this motion cost, sent as `format` over `wire`:
    /// work counts every layer's joints and IK and the motion's IK; the size bound is the first clip's
    /// (a subset only shrinks it) plus the root motion.
    /// Spring chains add the substeps of one simulation through `times`
    /// (docs/springs.md, “Time”), spread over the poses.
    pub fn cost(&self, times: &[f64], format: Format, wire: Wire) -> Cost {
        let poses = times.len() as u64;
        let first = self.motion.first_clip().clip();
        let mut estimate = Estimate::batch(first, self.clip_id(), format, wire);
        if self.motion.has_root_motion() {
            estimate.per_pose += ROOT_MOTION_BYTES;
        }
        estimate.per_pose += feet_bytes(&self.motion);
        // The first clip's reports are in its estimate; the other layers'
        // and the motion's own come on top.
        let more_reports = self.motion.ik_report_count() - first.ik_count();
        estimate.per_pose += super::cost::ik_reports(more_reports as u64, wire) + 8;
        let joints = self.motion.layers().map(|c| c.clip().joint_count() as u64).sum();
        let springs = crate::work::price::spring_run(&self.motion, times).div_ceil(poses.max(1));
        let per_pose = crate::work::price::motion_pose(&self.motion).saturating_add(springs);
        Cost::new(poses, joints, per_pose, estimate.total(poses) + self.warnings.len() as u64)
    }
}

impl<'a> RawMotion<'a> {
    /// The motion of a body or message: every joint and parameter, `trs`
    /// poses (a sampling request narrows them with its own fields).
    pub fn of(spec: MotionSpec<String>) -> RawMotion<'a> {
        RawMotion { spec, joints: None, parameters: None, format: Format::Trs, at: in_body, character: None }
    }

    /// The motion of a JSON document (`/motion`), with its character.
    ///
    /// # Errors
    /// The document's own refusals (an `ik` constraint of the wrong shape,
    /// a spring chain breaking a rule that needs no skeleton).
    pub fn of_doc(doc: &MotionDoc) -> Result<RawMotion<'a>, formats::wire::json::DocError> {
        Ok(RawMotion { character: doc.character.clone(), ..RawMotion::of(doc.to_spec("/motion")?) })
    }

    /// Looks up each layer's clip, finds the motion built over those
    /// versions (or builds and caches it) and checks the subset.
    ///
    /// # Errors
    /// `clip_not_found` for a layer's clip; the core's refusals
    /// (`weight_out_of_range`, `unknown_joint`, …) at `/motion/…`;
    /// `unknown_joint` at `/joints/{i}`; `no_inverse_binds` for skinning
    /// matrices of a skeleton without them.
    pub async fn resolve(self, state: &AppState) -> Result<Composed, ApiError> {
        self.resolve_for(state, &CallerKey::Node).await
    }

    /// [`RawMotion::resolve`], a motion build (a miss of the motion cache)
    /// priced and charged to `caller` and run on the work pool.
    ///
    /// # Errors
    /// As [`RawMotion::resolve`]; `too_much_work` (422) for a build over
    /// `max_request_work`, `caller_work_limit` (429), `overloaded` (503).
    pub async fn resolve_for(self, state: &AppState, caller: &CallerKey) -> Result<Composed, ApiError> {
        let spec = self.spec;
        let mut clips = Vec::with_capacity(spec.layers.len());
        for (i, layer) in spec.layers.iter().enumerate() {
            clips.push(super::raw::clip(state, &layer.clip).await.map_err(|e| match e {
                ApiError::NotFound { .. } => ApiError::ClipNotFoundAt {
                    at: At::Pointer(format!("/motion/layers/{i}/clip")),
                    detail: format!("layer {i}'s clip `{}` does not exist", layer.clip),
                },
                other => other,
            })?);
        }
        let mut pinned = pin(spec, &clips)?;
        let mut character = None;
        if let Some(reference) = &self.character {
            let built = crate::characters::resolve(state, caller, reference).await?;
            pinned.character = Some(Arc::clone(&built.spec));
            character = Some(built);
        } else if let Some(first) = clips.first()
            && pinned.springs.chains.is_empty()
        {
            // The first clip's own chains play unless the motion names some.
            pinned.springs.chains.clone_from(&first.springs.chains);
        }
        let key = MotionKey::of(&pinned, character.as_ref().map(|c| (c.meta.id.as_str(), c.meta.version)));
        let motion = match state.cached_motion(&key) {
            Some(hit) => hit,
            None => {
                let (limits, units) = (&state.config.limits, crate::work::price::motion_build(&pinned));
                let ik = limits.ik();
                let building = crate::builds::run(&state.work, caller, limits, units, "building this motion", {
                    move |_| build(pinned, &ik)
                });
                let motion = Arc::new(building.await?);
                state.cache_motion(key, Arc::clone(&motion), &clips);
                motion
            }
        };
        if self.format == Format::Skinning && !motion.skeleton().has_inverse_binds() {
            let detail = "format=skinning needs inverse bind matrices, which the first layer's clip has not";
            return Err(super::raw::unprocessable("no_inverse_binds", Field::Format, self.at, detail.into()));
        }
        let joints = self.joints.map(|names| joint_subset(motion.skeleton(), names, self.at)).transpose()?;
        let parameters =
            self.parameters.map(|names| parameter_subset(motion.parameters(), names, self.at)).transpose()?;
        let warnings = warnings_member(&motion);
        Ok(Composed { motion, joints, parameters, warnings })
    }
}

/// The motion's warnings as an answer shows them (docs/warnings.md):
/// `{code, pointer, detail}`, pointers under `pointer` (`/motion`).
pub fn warnings(motion: &StreamMotion, pointer: &str) -> Vec<serde_json::Value> {
    let warning = |w: &anim::motion::MotionWarning| {
        serde_json::json!({
            "code": anim::motion::MotionWarning::CODE,
            "pointer": format!("{pointer}{}", w.path.to_pointer()),
            "detail": w.to_string(),
        })
    };
    motion.warnings().iter().map(warning).collect()
}

/// `,"warnings":[…]`, the member a composed answer ends with, or nothing
/// when the motion has no warnings (so plain answers stay as they were).
pub fn warnings_member(motion: &StreamMotion) -> Vec<u8> {
    let warnings = warnings(motion, "/motion");
    if warnings.is_empty() {
        return Vec::new();
    }
    format!(",\"warnings\":{}", serde_json::Value::Array(warnings)).into_bytes()
}

/// A crossfade's target sent as JSON (a control's `to`), looked up and
/// built like a request's motion, every refusal pointed under `/to`.
///
/// # Errors
/// As [`RawMotion::resolve`], and the motion document's own refusals.
pub async fn crossfade_target(
    state: &AppState,
    caller: &CallerKey,
    to: &serde_json::Value,
) -> Result<Arc<StreamMotion>, ApiError> {
    let doc: MotionDoc = parse_json(to.to_string().as_bytes()).map_err(|e| e.moved("", "/to"))?;
    let built = async { Ok(RawMotion::of_doc(&doc)?.resolve_for(state, caller).await?.motion) };
    built.await.map_err(|e: ApiError| e.moved("/motion", "/to"))
}

/// `spec` with each layer's clip id swapped for the clip looked up for it.
fn pin(spec: MotionSpec<String>, clips: &[Arc<CachedClip>]) -> Result<MotionSpec<Arc<dyn PinnedClip>>, ApiError> {
    let mut clips = clips.iter();
    let spec = spec.try_map(|_, _| clips.next().map(|c| Arc::clone(c) as Arc<dyn PinnedClip>).ok_or(()));
    spec.map_err(|()| ApiError::internal(anyhow::anyhow!("a layer lost its clip")))
}

/// Builds the motion, its refusals pointed into the request's `/motion`.
fn build(spec: MotionSpec<Arc<dyn PinnedClip>>, ik: &IkLimits) -> Result<StreamMotion, ApiError> {
    Motion::build_limited(spec, ik)
        .map_err(|e| ApiError::invalid(e.kind.code(), format!("/motion{}", e.path.to_pointer()), e.kind.to_string()))
}

/// What a clip route plays as a motion: the one-layer motion
/// `{"layers":[{"clip":id}]}`, the route's `playback` as the layer's. Its
/// clip's own spring chains run in it (docs/springs.md, “Clip routes”).
pub fn of_clip(clip: &str, playback: Option<anim::Playback>) -> MotionDoc {
    let mut layer = formats::wire::motion::LayerDoc::new(clip);
    layer.playback = playback.map(Into::into);
    MotionDoc {
        layers: vec![layer],
        root_motion: None,
        ik: Vec::new(),
        springs: Vec::new(),
        spring_substep_hz: None,
        character: None,
        retarget: None,
    }
}

/// What a clip route with `character=` plays (docs/characters.md, “Clip routes on a
/// character”): [`of_clip`]'s motion with `"character":…`.
pub fn on_character(clip: &str, playback: Option<anim::Playback>, character: &str) -> MotionDoc {
    MotionDoc { character: Some(character.to_owned()), ..of_clip(clip, playback) }
}

/// What a clip route (`GET …/pose`, `POST …/sample`, gRPC `Sample`,
/// `SampleBatch`, `SampleStream`) asks to play.
#[derive(Debug, Clone, Copy)]
pub struct ClipRoute<'a> {
    pub id: &'a str,
    /// A character id or `name:…` to play the clip on.
    pub character: Option<&'a str>,
    /// The clip's own spring chains run (`false`: its keyed poses).
    pub springs: bool,
    pub playback: Option<anim::Playback>,
    /// Where the request's `ease` sits, if it gave one.
    pub ease: Option<Locate>,
}

impl ClipRoute<'_> {
    /// The one-layer motion the route plays instead of its clip, with the
    /// route's field its motion's refusals point at: on its `character`
    /// (docs/characters.md), else with the clip's own spring chains when it
    /// has some and the route did not turn them off (docs/springs.md, “Clip
    /// routes”). `None`: the clip itself.
    ///
    /// # Errors
    /// `clip_not_found` (a clip looked up for its chains); `unknown_parameter`
    /// for an `ease` (a motion's layers have none).
    pub async fn motion(&self, state: &AppState) -> Result<Option<(MotionDoc, Field)>, ApiError> {
        let (motion, why, field) = match self.character {
            Some(character) => (on_character(self.id, self.playback, character), "with `character`", Field::Character),
            None if super::sample::runs_springs(state, self.id, self.springs).await? => {
                let why = "to a clip's spring chains (turning them off eases its keyed pose)";
                (of_clip(self.id, self.playback), why, Field::Springs)
            }
            None => return Ok(None),
        };
        if let Some(at) = self.ease {
            return Err(super::sample::no_ease_in_motion(at(Field::Ease), why));
        }
        Ok(Some((motion, field)))
    }
}

/// A refusal of [`on_character`]'s motion, located on the clip route that
/// asked for it (`at`): whatever the motion path points into `/motion`
/// (the character not found, a clip it cannot map) is the route's
/// `character`; the request's own fields keep their names.
pub fn at_clip_route(e: ApiError, at: Locate) -> ApiError {
    at_clip_route_as(e, at, Field::Character)
}

/// [`at_clip_route`], a motion path pointed at `motion` (the route's
/// `character`, or its `springs` when the clip's chains made the motion).
pub fn at_clip_route_as(e: ApiError, at: impl Fn(Field) -> At, motion: Field) -> ApiError {
    let to_route = |pointer: &str| {
        if pointer.starts_with("/motion") {
            return at(motion);
        }
        let mut parts = pointer.trim_start_matches('/').split('/');
        let (name, index) = (parts.next().unwrap_or(""), parts.next().and_then(|i| i.parse().ok()));
        match (name, index) {
            ("joints", Some(i)) => at(Field::JointAt(i)),
            ("parameters", Some(i)) => at(Field::ParameterAt(i)),
            ("time", _) => at(Field::Time),
            ("times", Some(i)) => at(Field::TimeAt(i)),
            ("times", None) => at(Field::Times),
            _ if pointer.is_empty() => at(Field::When),
            _ => At::Pointer(pointer.to_owned()),
        }
    };
    e.relocated(|location| match location {
        At::Pointer(pointer) => to_route(&pointer),
        other => other,
    })
}
