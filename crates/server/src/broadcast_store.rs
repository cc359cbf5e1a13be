//! Broadcasts kept in the store (docs/broadcasts.md "Many nodes", and the resume after
//! a restart): what is written, how a node builds a broadcast again from it,
//! and how it keeps its copies in step with the store.
//!
//! - A broadcast's **definition** is its creation request as sent plus the
//!   version each of its clips was pinned at; a **control** is its message
//!   as sent (REST's body, or what a socket's control says again) plus, for
//!   a crossfade, its clips' versions. A node builds both again with the
//!   very rules REST applies (`RawBroadcast`, `parse_control`,
//!   `request::crossfade_target`), and refuses to run one whose clips are no
//!   longer at those versions (it could not compute the same frames).
//! - With PostgreSQL every insert and delete is announced on the schema's
//!   channel (`migrations/postgres/0004_broadcasts.sql`); `server::notify`
//!   hands the changes here ([`heard`]), and after each (re)subscription,
//!   and at startup with either store, [`resync`] reconciles every live
//!   copy with the store: adopts what it lacks, adds the controls it has
//!   not heard, ends what was deleted.
//! - [`StoreJournal`] is the stream engine's [`Journal`]: a viewer socket's
//!   controls stored, the viewers' liveness (`active_at`), the idle end
//!   decided in one conditional delete across all nodes, and checkpoints
//!   (`migrations/*/0005_broadcast_checkpoints.sql`): each replaces the one
//!   before and deletes the controls it makes unnecessary. A node adopting
//!   a broadcast starts from its newest checkpoint.

use std::collections::{BTreeMap, HashSet};
use std::sync::Arc;
use std::time::Duration;

use futures_util::FutureExt;
use futures_util::future::BoxFuture;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::error::ApiError;
use super::request::{
    Format, Raw, RawBroadcast, RawGraphStream, RawModes, RawMotion, RawStream, crossfade_target, graph_layer, in_body,
    parse_json,
};
use super::state::AppState;
use crate::auth::CallerKey;
use crate::store::{ClipStore, Covers, StoredBroadcast, StoredCheckpoint, StoredControl};
use crate::stream::{
    Broadcast, BroadcastSpec, Checkpoint, Control, ControlError, Crossfade, Journal, ParsedControl, StampedControl,
    StreamMotion, StreamParams, new_control_id, parse_control, unix_nanos,
};
use formats::wire::json::SpaceDoc;
use formats::wire::motion::MotionDoc;

/// `POST /v1/broadcasts`: what to broadcast.
#[derive(Debug, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateBroadcast {
    /// The motion (`docs/motion.md`; a clip is a one-layer motion), its clips pinned at their current versions.
    pub motion: MotionDoc,
    /// Ticks per second, 1..=240 (default 30).
    #[serde(default)]
    pub fps: Option<f64>,
    #[serde(default)]
    #[schema(value_type = Option<SpaceDoc>)]
    pub space: Option<String>,
    /// `trs` (the default; the only format frames have).
    #[serde(default)]
    #[schema(value_type = Option<Format>)]
    pub format: Option<String>,
    /// Only these joints in every frame, in skeleton order (default: all).
    #[serde(default)]
    pub joints: Option<Vec<String>>,
    /// Only these parameters in every frame (docs/clip-format.md §3; default: all).
    #[serde(default)]
    pub parameters: Option<Vec<String>>,
    /// Seconds with no viewers and no controls before it ends, 1..=86400 (default 300).
    #[serde(default)]
    pub idle_timeout_secs: Option<f64>,
    /// A graph broadcast's frames carry the tick's `graph` report (docs/graphs.md).
    #[serde(default)]
    pub report: bool,
}

/// What the store holds of a broadcast or a control: the message as sent,
/// and the versions of the clips it was resolved against.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Stored {
    message: Value,
    #[serde(default)]
    versions: BTreeMap<String, u64>,
}

/// The versions `motion`'s clips are pinned at.
fn versions(motion: &StreamMotion) -> BTreeMap<String, u64> {
    motion.layers().map(|c| (c.id().to_owned(), c.version())).collect()
}

/// The versions a broadcast's definition is pinned at: its motion's clips,
/// or its graph's (`graph:ID` at the graph's version, and every clip of
/// every state).
fn definition_versions(params: &StreamParams) -> BTreeMap<String, u64> {
    let Some(g) = &params.graph else { return versions(&params.motion) };
    let mut all: BTreeMap<String, u64> = g.graph.state_motions().flat_map(|m| versions(m)).collect();
    all.insert(format!("graph:{}", g.id), g.version);
    all
}

/// Refuses a motion built again over other versions than the stored ones:
/// its frames could not be the ones other nodes compute. The versions it
/// was made of are gone, so it is the clip that is not found (a 404 with a
/// stable code, not a server error).
fn same_versions(now: BTreeMap<String, u64>, stored: &BTreeMap<String, u64>) -> Result<(), ApiError> {
    if &now == stored {
        return Ok(());
    }
    Err(ApiError::ClipNotFoundAt {
        at: super::error::At::Pointer("/motion".into()),
        detail: format!(
            "this broadcast was made of the clip (and graph) versions {stored:?}, and one was replaced since ({now:?} now): \
             its frames cannot be computed again here; delete the broadcast and create it anew"
        ),
    })
}

/// The broadcast a creation body asks for: the request layer's rules.
///
/// # Errors
/// As `POST /v1/broadcasts` answers them.
pub async fn spec_from_body(state: &AppState, body: &[u8]) -> Result<BroadcastSpec, ApiError> {
    let req: CreateBroadcast = parse_json(body)?;
    let sent: Value = serde_json::from_slice(body).unwrap_or_default();
    let description =
        serde_json::json!({"motion": sent.get("motion"), "space": req.space.as_deref().unwrap_or("local")});
    let stream = RawStream {
        fps: req.fps.map(Raw::Number),
        start: None,
        speed: None,
        modes: RawModes { space: req.space.as_deref().map(Raw::Text), ..RawModes::default() },
        encoding: None,
        max_error: None,
        distance: None,
        max_frames: None,
        paused: false,
        springs: true,
        joints: req.joints.as_deref(),
        parameters: req.parameters.as_deref(),
        at: in_body,
    };
    let raw = RawBroadcast {
        stream,
        format: req.format.as_deref().map(Raw::Text),
        idle_timeout_secs: req.idle_timeout_secs.map(Raw::Number),
        at: in_body,
    };
    match graph_layer(&req.motion)? {
        Some(layer) => {
            let graph = RawGraphStream { reference: layer.reference, stages: &layer.stages, report: req.report };
            raw.graph_spec(state, graph, description).await
        }
        None if req.report => {
            let detail = "`report` is a graph broadcast's: the motion's layer names no `graph`";
            Err(ApiError::invalid("graph_unsupported", "/report", detail))
        }
        None => raw.spec(state, RawMotion::of_doc(&req.motion)?, description).await,
    }
}

/// The control a control message asks for (a crossfade's motion looked up).
///
/// # Errors
/// As `POST /v1/broadcasts/{id}/controls` answers them.
pub async fn control_from_body(state: &AppState, body: &[u8]) -> Result<Control, ApiError> {
    // Not JSON at all is 400 like every body; a JSON that is no control is the socket's `bad_control`.
    let _: Value = parse_json(body)?;
    let text = std::str::from_utf8(body).map_err(|e| ApiError::invalid("bad_control", "", e.to_string()))?;
    match parse_control(text) {
        Ok(ParsedControl::Ready(control)) => Ok(control),
        Ok(ParsedControl::Crossfade { to, duration, ease }) => {
            let motion = crossfade_target(state, &CallerKey::Node, &to).await?;
            Ok(Control::Crossfade(Crossfade { to: motion, duration, ease, source: Some(Arc::new(to)) }))
        }
        Err(e) => Err(ApiError::invalid(e.code, e.pointer.unwrap_or_default(), e.detail)),
    }
}

/// Stores broadcast `b`, created here from `body`.
///
/// # Errors
/// The store failed.
pub async fn store_created(state: &AppState, b: &Broadcast, body: &[u8]) -> Result<(), ApiError> {
    let message: Value = serde_json::from_slice(body).map_err(ApiError::internal)?;
    let definition = Stored { message, versions: definition_versions(b.params()) };
    let stored = StoredBroadcast {
        id: b.id().to_owned(),
        definition: serde_json::to_string(&definition).map_err(ApiError::internal)?,
        created_at: b.created_at_unix_nanos(),
        controls: Vec::new(),
    };
    Ok(state.store.create_broadcast(stored).await?)
}

/// Checks, stamps, applies and stores the control `body` asks of `b`;
/// returns its stamp. Applied at once, so that it is never late on this
/// node whatever the store's latency; answered only once stored, so that
/// every node (and this one after a restart) plays what this one answered.
/// If the store refuses it, it is withdrawn here too.
///
/// # Errors
/// The control's refusal; `broadcast_not_found` if it was deleted
/// meanwhile; the store failed.
pub async fn control(state: &AppState, b: &Broadcast, body: &[u8]) -> Result<u64, ApiError> {
    let control = control_from_body(state, body).await?;
    let fade_versions = match &control {
        Control::Crossfade(fade) => versions(&fade.to),
        _ => BTreeMap::new(),
    };
    let message: Value = serde_json::from_slice(body).map_err(ApiError::internal)?;
    let text = serde_json::to_string(&Stored { message, versions: fade_versions }).map_err(ApiError::internal)?;
    let id = new_control_id();
    let refused = |e: ControlError| ApiError::from_control(&e);
    let _slot = b.store_slot().map_err(refused)?;
    let seq = b.take(control, Arc::clone(&id)).map_err(refused)?;
    match state.store.add_broadcast_control(b.id(), StoredControl { id: id.to_string(), seq, control: text }).await {
        Ok(()) => Ok(seq),
        Err(e) => {
            b.revoke(&id);
            match e {
                crate::store::StoreError::NotFound => {
                    state.streams.broadcasts().delete(b.id());
                    Err(ApiError::NotFound { what: "broadcast" })
                }
                e => Err(e.into()),
            }
        }
    }
}

/// The broadcast `id`: live here, or stored (created on another node an
/// instant ago, not heard of yet) and started here now.
///
/// # Errors
/// `broadcast_not_found`; a store failure.
pub async fn find(state: &AppState, id: &str) -> Result<Arc<Broadcast>, ApiError> {
    if let Some(b) = state.streams.broadcasts().get(id) {
        return Ok(b);
    }
    let not_found = ApiError::NotFound { what: "broadcast" };
    if uuid::Uuid::try_parse(id).is_err() {
        return Err(not_found);
    }
    match state.store.broadcast(id).await? {
        Some(stored) => adopt(state, stored).await,
        None => Err(not_found),
    }
}

/// Starts here (or brings up to date) the stored broadcast `stored`.
///
/// # Errors
/// Its definition or a control no longer builds (its clips changed), too
/// many broadcasts, shutting down.
pub async fn adopt(state: &AppState, stored: StoredBroadcast) -> Result<Arc<Broadcast>, ApiError> {
    let broadcasts = state.streams.broadcasts();
    let live = broadcasts.get(&stored.id);
    let spec = match &live {
        Some(b) => b.spec().clone(),
        None => {
            let definition: Stored = serde_json::from_str(&stored.definition).map_err(ApiError::internal)?;
            let body = serde_json::to_vec(&definition.message).map_err(ApiError::internal)?;
            let spec = spec_from_body(state, &body).await?;
            same_versions(definition_versions(&spec.params), &definition.versions)?;
            spec
        }
    };
    let known: HashSet<String> = live.as_ref().map(|b| b.control_ids()).unwrap_or_default();
    let mut controls = Vec::new();
    for c in stored.controls.into_iter().filter(|c| !known.contains(&c.id)) {
        match stored_control(state, &c).await {
            Ok(control) => controls.push(StampedControl { seq: c.seq, id: c.id.into(), control }),
            Err(e) => tracing::warn!(broadcast = %stored.id, control = %c.id, error = %e, "a stored control skipped"),
        }
    }
    let (charge, checkpoint) = match &live {
        Some(_) => (crate::stream::BroadcastCharge::free(), None),
        None => (super::broadcast_work::hold(state, &spec), newest_checkpoint(state, &stored.id).await),
    };
    broadcasts
        .adopt(&stored.id, spec, stored.created_at, controls, charge, checkpoint)
        .map_err(ApiError::TooManyBroadcasts)
}

/// Broadcast `id`'s newest stored checkpoint; `None` (with a warning: the
/// broadcast then steps from tick 0) if it cannot be read.
async fn newest_checkpoint(state: &AppState, id: &str) -> Option<Checkpoint> {
    let stored = match state.store.broadcast_checkpoint(id).await {
        Ok(stored) => stored?,
        Err(e) => {
            tracing::warn!(broadcast = %id, error = %e, "cannot read a broadcast checkpoint");
            return None;
        }
    };
    match Checkpoint::from_text(&stored.state) {
        Ok(checkpoint) if checkpoint.tick == stored.seq => Some(checkpoint),
        Ok(_) => {
            tracing::warn!(broadcast = %id, seq = stored.seq, "a broadcast checkpoint of another tick than its row's");
            None
        }
        Err(e) => {
            tracing::warn!(broadcast = %id, error = %e, "a broadcast checkpoint not readable");
            None
        }
    }
}

/// A stored control built again.
async fn stored_control(state: &AppState, c: &StoredControl) -> Result<Control, ApiError> {
    let stored: Stored = serde_json::from_str(&c.control).map_err(ApiError::internal)?;
    let body = serde_json::to_vec(&stored.message).map_err(ApiError::internal)?;
    let control = control_from_body(state, &body).await?;
    if let Control::Crossfade(fade) = &control {
        same_versions(versions(&fade.to), &stored.versions)?;
    }
    Ok(control)
}

/// Deletes broadcast `id` everywhere; returns whether it existed.
///
/// # Errors
/// The store failed.
pub async fn delete(state: &AppState, id: &str) -> Result<bool, ApiError> {
    let stored = state.store.delete_broadcast(id).await?;
    let live = state.streams.broadcasts().delete(id);
    Ok(stored || live)
}

/// Brings every copy here in step with the store: stored broadcasts
/// started (at startup: resumed at the tick the wall clock says) or given
/// the controls not heard, deleted ones ended. A broadcast created here
/// since the resync began is not in the store's answer yet, and is kept.
pub async fn resync(state: &AppState) {
    let began = std::time::SystemTime::now();
    let stored = match state.store.broadcasts().await {
        Ok(all) => all,
        Err(e) => {
            tracing::warn!(error = %e, "cannot read the stored broadcasts");
            return;
        }
    };
    let ids: HashSet<String> = stored.iter().map(|b| b.id.clone()).collect();
    for b in state.streams.broadcasts().list() {
        if !ids.contains(b.id()) && b.created_at() < began {
            state.streams.broadcasts().delete(b.id());
        }
    }
    for b in stored {
        let id = b.id.clone();
        if let Err(e) = adopt(state, b).await {
            tracing::warn!(broadcast = %id, error = %e, "a stored broadcast cannot run here");
        }
    }
}

/// A broadcast change another node announced.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Heard {
    /// Created, or given a control: read it back and adopt it.
    Changed(String),
    Deleted(String),
}

/// Applies an announced change (on its own task: it reads the store).
pub fn heard(state: &AppState, change: Heard) {
    match change {
        Heard::Deleted(id) => {
            state.streams.broadcasts().delete(&id);
        }
        Heard::Changed(id) => {
            let state = state.clone();
            tokio::spawn(async move {
                match state.store.broadcast(&id).await {
                    Ok(Some(stored)) => {
                        if let Err(e) = adopt(&state, stored).await {
                            tracing::warn!(broadcast = %id, error = %e, "a stored broadcast cannot run here");
                        }
                    }
                    Ok(None) => {
                        state.streams.broadcasts().delete(&id);
                    }
                    Err(e) => tracing::warn!(broadcast = %id, error = %e, "cannot read a stored broadcast"),
                }
            });
        }
    }
}

/// The engine's [`Journal`] over the server's store.
pub struct StoreJournal {
    pub store: Arc<dyn ClipStore>,
}

impl Journal for StoreJournal {
    fn record(
        &self,
        broadcast: &str,
        seq: u64,
        id: &str,
        json: Value,
        fade_to: Option<&StreamMotion>,
    ) -> BoxFuture<'static, Result<(), ControlError>> {
        let store = Arc::clone(&self.store);
        let (broadcast, id) = (broadcast.to_owned(), id.to_owned());
        let versions = fade_to.map(versions).unwrap_or_default();
        async move {
            let stored = Stored { message: json, versions };
            let text = serde_json::to_string(&stored).map_err(|e| ApiError::internal(e).to_control())?;
            let written = store.add_broadcast_control(&broadcast, StoredControl { id, seq, control: text }).await;
            written.map_err(|e| {
                tracing::warn!(%broadcast, error = %e, "a viewer's broadcast control was not stored; withdrawn");
                ApiError::from(e).to_control()
            })
        }
        .boxed()
    }

    fn ended(&self, broadcast: &str) -> BoxFuture<'static, ()> {
        let (store, broadcast) = (Arc::clone(&self.store), broadcast.to_owned());
        async move {
            if let Err(e) = store.delete_broadcast(&broadcast).await {
                tracing::warn!(%broadcast, error = %e, "cannot delete a broadcast that overran its price");
            }
        }
        .boxed()
    }

    fn touch(&self, broadcast: &str) -> BoxFuture<'static, ()> {
        let (store, broadcast) = (Arc::clone(&self.store), broadcast.to_owned());
        async move {
            if let Err(e) = store.touch_broadcast(&broadcast, unix_nanos() / 1_000_000).await {
                tracing::debug!(%broadcast, error = %e, "broadcast liveness not stored");
            }
        }
        .boxed()
    }

    fn checkpoint(
        &self,
        broadcast: &str,
        checkpoint: &Checkpoint,
        from: u64,
        controls: Vec<(String, u64)>,
    ) -> BoxFuture<'static, ()> {
        let (store, broadcast) = (Arc::clone(&self.store), broadcast.to_owned());
        let covers = Covers { from, controls };
        let named = checkpoint.controls();
        let stored = StoredCheckpoint { seq: checkpoint.tick, state: checkpoint.to_text() };
        async move {
            match store.put_broadcast_checkpoint(&broadcast, stored, &named, &covers).await {
                Ok(true) => {}
                // Another node's came first, or this node's controls differ from the stored ones (it has not
                // heard one yet, or one it applied is not stored): the next checkpoint, or another node's.
                Ok(false) => tracing::debug!(%broadcast, "a broadcast checkpoint not stored: another's, or unsettled"),
                Err(e) => tracing::warn!(%broadcast, error = %e, "a broadcast checkpoint was not stored"),
            }
        }
        .boxed()
    }

    fn expire(&self, broadcast: &str, idle: Duration) -> BoxFuture<'static, bool> {
        let (store, broadcast) = (Arc::clone(&self.store), broadcast.to_owned());
        async move {
            let before = unix_nanos() / 1_000_000 - idle.as_millis() as i64;
            match store.expire_broadcast(&broadcast, before).await {
                Ok(ended) => ended,
                Err(e) => {
                    tracing::warn!(%broadcast, error = %e, "cannot end an idle broadcast");
                    false
                }
            }
        }
        .boxed()
    }
}
