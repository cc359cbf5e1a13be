//! Graphs at the service's edge (docs/graphs.md): a graph document checked
//! whole before it is stored — its size and shape against the limits, its
//! clips found, then built by the core (every rule of `Graph::build`, with
//! the document's JSON pointers), each step priced and run on the work
//! pool — and a stored graph built once per version for whatever plays it
//! ([`resolve`]): the cache of built graphs keeps it by id at one version,
//! over the clips it was built on, each pinned at its version.
//!
//! A built graph holds its clips' cache entries, so, as a built motion
//! does (`server::motion_cache`), it goes in only while each of them is
//! still the clip cache's entry, and leaves when one of them does (a clip
//! replaced, deleted or evicted, on this node or another): the next use
//! builds it again over the clips' current versions.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use bytes::Bytes;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::auth::CallerKey;
use crate::built::{BuiltGraph, PinnedGraph, PlayedKey};
use crate::cache::CachedClip;
use crate::config::Limits;
use crate::error::{ApiError, At};
use crate::state::AppState;
use crate::store::{DocKind, DocMeta, MeshWrite, NewDoc, OnName, StoreError, StoredDoc, name_reference};
use crate::stream::PinnedClip;
use crate::work::price;
use anim::graph::NodeOptions;
use anim::motion::{RetargetSpec, RootMotionSpec};
use formats::wire::graph::{GraphDoc, ParameterDoc, parse_graph_doc};

/// What a graph's summary shows beyond its identity, derived when it is
/// written (the store keeps it beside the document).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, ToSchema)]
pub struct GraphReport {
    /// Parameter → its type (`float`, `bool` or `trigger`).
    pub parameters: BTreeMap<String, String>,
    /// The machine's states; a graph with an `output` node has none.
    pub states: Vec<String>,
    /// The distinct clip ids the document names, in its order.
    pub clips: Vec<String>,
}

impl GraphReport {
    fn of(doc: &GraphDoc) -> GraphReport {
        let kind = |p: &ParameterDoc| match p {
            ParameterDoc::Float { .. } => "float",
            ParameterDoc::Bool { .. } => "bool",
            ParameterDoc::Trigger => "trigger",
        };
        let mut clips: Vec<String> = Vec::new();
        for (id, _) in doc.clip_references("") {
            if !clips.iter().any(|c| c == id) {
                clips.push(id.to_owned());
            }
        }
        GraphReport {
            parameters: doc.parameters.iter().map(|(name, p)| (name.clone(), kind(p).to_owned())).collect(),
            states: doc.machine.iter().flat_map(|m| m.states.keys().cloned()).collect(),
            clips,
        }
    }
}

/// A checked graph document: the graph it builds, over which clips, and
/// the row to store.
#[derive(Debug)]
pub struct CheckedGraph {
    pub graph: PinnedGraph,
    pub doc: GraphDoc,
    pub clips: Vec<Arc<CachedClip>>,
    pub new_doc: NewDoc,
}

impl CheckedGraph {
    /// The graph as the cache keeps it, once the store has given it `meta`.
    pub fn built(self, meta: DocMeta) -> BuiltGraph {
        let bytes = built_bytes(&self.new_doc.doc_json, &self.clips);
        let (graph, doc, clips) = (Arc::new(self.graph), self.doc, self.clips);
        BuiltGraph { meta, graph, doc, clips, played: Default::default(), bytes }
    }

    /// Stores the graph as a new document (or, as `on_name` allows, the new
    /// version of the one holding its name), then [`Self::written`]: REST's
    /// `POST /v1/graphs` and gRPC's `CreateGraph`.
    ///
    /// # Errors
    /// The store's refusal (`name_taken`, …).
    pub async fn create(self, state: &AppState, on_name: OnName) -> Result<DocMeta, ApiError> {
        let written = state.store.create_docs(DocKind::Graph, vec![self.new_doc.clone()], on_name).await;
        let meta = written.map_err(store_error)?.pop();
        let meta = meta.ok_or_else(|| ApiError::internal(anyhow::anyhow!("a create wrote no graph")))?;
        Ok(self.written(state, meta))
    }

    /// Stores the graph as graph `id`'s next version (at `expected` if
    /// given), then [`Self::written`]: `PUT /v1/graphs/{id}` and `ReplaceGraph`.
    ///
    /// # Errors
    /// The store's refusal (not found, a version race).
    pub async fn replace(self, state: &AppState, id: &str, expected: Option<u64>) -> Result<DocMeta, ApiError> {
        let meta = state.store.replace_doc(DocKind::Graph, id, self.new_doc.clone(), expected).await;
        Ok(self.written(state, meta.map_err(store_error)?))
    }

    /// Tells every node the graph changed and caches what was built, so its
    /// first use does not build it again.
    fn written(self, state: &AppState, meta: DocMeta) -> DocMeta {
        state.document_changed(DocKind::Graph, &meta.id);
        state.cache_graph(Arc::new(self.built(meta.clone())), None);
        meta
    }
}

/// Checks an uploaded graph document (a REST body): its size before it
/// is read, then as [`check_doc`].
///
/// # Errors
/// 413 `body_too_large` over `max_graph_bytes`; 400 for malformed JSON;
/// as [`check_doc`].
pub async fn check_body(state: &AppState, caller: &CallerKey, body: Bytes) -> Result<CheckedGraph, ApiError> {
    let doc = read(state, caller, body).await?;
    check_doc(state, caller, doc).await
}

/// Reads a graph document on the pool, priced by its bytes, and checks its
/// size and shape against the limits before anything is built.
///
/// # Errors
/// As [`check_body`], up to the shape: `too_many_nodes`, `too_many_points`.
pub async fn read(state: &AppState, caller: &CallerKey, body: Bytes) -> Result<GraphDoc, ApiError> {
    let limits = state.config.limits.clone();
    if body.len() > limits.max_graph_bytes {
        return Err(ApiError::PayloadTooLarge { limit: limits.max_graph_bytes, setting: "max_graph_bytes" });
    }
    let units = price::parse(body.len() as u64);
    crate::builds::run(&state.work, caller, &state.config.limits, units, "reading this graph document", move |_| {
        let doc = parse_graph_doc(&body)?;
        check_shape(&doc, &limits)?;
        Ok(doc)
    })
    .await
}

/// Finds the clips `doc` names and builds it over them, priced and on the
/// pool, into the row to store.
///
/// # Errors
/// `clip_not_found` (404) at the first field naming a clip that does not
/// exist; the document's and the core's refusals (422 with the pointer:
/// `unknown_parameter`, `unknown_node`, `unknown_state`, `node_cycle`,
/// `degenerate_blend_space`, `parameter_range`, `incompatible_skeleton`,
/// `skeleton_mismatch`, …); `too_much_work` over `max_request_work`.
pub async fn check_doc(state: &AppState, caller: &CallerKey, doc: GraphDoc) -> Result<CheckedGraph, ApiError> {
    check_shape(&doc, &state.config.limits)?;
    let clips = find_clips(state, &doc).await?;
    let units = build_price(&doc, &clips);
    let built = crate::builds::run(&state.work, caller, &state.config.limits, units, "building this graph", {
        move |_| build(&doc, &clips).map(|graph| (graph, doc, clips))
    });
    let (graph, doc, clips) = built.await?;
    let new_doc = NewDoc {
        name: doc.name.clone(),
        doc_json: serde_json::to_string(&doc).map_err(ApiError::internal)?,
        figure: doc.nodes.len() as u32,
        report_json: serde_json::to_string(&GraphReport::of(&doc)).map_err(ApiError::internal)?,
        mesh: MeshWrite::None,
    };
    Ok(CheckedGraph { graph, doc, clips, new_doc })
}

/// The graph `reference` names (its id, or `name:<name>`) built at its
/// current version over its clips' current versions: the cache's entry,
/// or read, built (priced, charged to `caller`, on the pool) and cached.
/// `at` is the pointer of the field naming it, where a refusal points.
///
/// # Errors
/// `graph_not_found` (404) at `at`; `clip_not_found` (404) at `at` when a
/// clip it names was deleted since it was stored; 422 at `at` when it no
/// longer builds over its clips' current versions (a clip replaced with
/// another skeleton: `incompatible_skeleton`, `skeleton_mismatch`), the
/// detail saying where in the graph; the price's refusals; the store's.
pub async fn resolve(
    state: &AppState,
    caller: &CallerKey,
    reference: &str,
    at: &str,
) -> Result<Arc<BuiltGraph>, ApiError> {
    if name_reference(reference).is_none()
        && let Some(hit) = state.graphs.get(reference)
    {
        return Ok(hit);
    }
    let seen = state.graphs.epoch();
    let stored = state.store.doc_by_ref(DocKind::Graph, reference).await.map_err(store_error)?;
    let stored = stored.ok_or_else(|| ApiError::GraphNotFoundAt {
        at: At::Pointer(at.to_owned()),
        detail: format!("the graph `{reference}` does not exist"),
    })?;
    if let Some(hit) = state.graphs.get(&stored.meta.id).filter(|hit| hit.meta.version == stored.meta.version) {
        return Ok(hit);
    }
    let built = Arc::new(build_stored(state, caller, stored, at).await?);
    state.cache_graph(Arc::clone(&built), Some(seen));
    Ok(built)
}

/// A stored graph built again, its refusals pointed at `at`.
async fn build_stored(
    state: &AppState,
    caller: &CallerKey,
    stored: StoredDoc,
    at: &str,
) -> Result<BuiltGraph, ApiError> {
    let id = stored.meta.id.clone();
    let moved = |e: ApiError| match e {
        ApiError::ClipNotFoundAt { at: At::Pointer(inner), detail } => ApiError::ClipNotFoundAt {
            at: At::Pointer(at.to_owned()),
            detail: format!("graph {id}: {detail} (at {inner} in the graph)"),
        },
        ApiError::Invalid { code, at: At::Pointer(inner), detail } => ApiError::Invalid {
            code,
            at: At::Pointer(at.to_owned()),
            detail: format!("graph {id} no longer builds over its clips' current versions: {detail} (at {inner})"),
        },
        other => other,
    };
    let doc = read(state, caller, Bytes::from(stored.doc_json.into_bytes())).await.map_err(moved)?;
    let checked = check_doc(state, caller, doc).await.map_err(moved)?;
    Ok(checked.built(stored.meta))
}

/// The limits a document's shape must keep before anything is built: its
/// node count, and each blend's points (a 2D blend's triangulation grows
/// as the fourth power of its points).
fn check_shape(doc: &GraphDoc, limits: &Limits) -> Result<(), ApiError> {
    if doc.nodes.len() > limits.max_graph_nodes {
        let detail = format!(
            "the graph has {} nodes; the limit (max_graph_nodes, --max-graph-nodes) is {}",
            doc.nodes.len(),
            limits.max_graph_nodes
        );
        return Err(ApiError::TooMany { code: "too_many_nodes", pointer: "/nodes".into(), detail });
    }
    for (name, node) in &doc.nodes {
        let blends = [
            ("blend1d", node.blend1d.as_ref().map(|b| b.points.len())),
            ("blend2d", node.blend2d.as_ref().map(|b| b.points.len())),
        ];
        for (kind, points) in blends {
            let Some(points) = points.filter(|n| *n > limits.max_blend_points) else { continue };
            let detail = format!(
                "the blend has {points} points; the limit (max_blend_points, --max-blend-points) is {}",
                limits.max_blend_points
            );
            let pointer = format!("/nodes/{}/{kind}/points", name.replace('~', "~0").replace('/', "~1"));
            return Err(ApiError::TooMany { code: "too_many_points", pointer, detail });
        }
    }
    Ok(())
}

/// The clips the document names, each found once (in the clip cache, or
/// loaded), in the document's order.
async fn find_clips(state: &AppState, doc: &GraphDoc) -> Result<Vec<Arc<CachedClip>>, ApiError> {
    let mut clips: Vec<Arc<CachedClip>> = Vec::new();
    for (id, pointer) in doc.clip_references("") {
        if clips.iter().any(|c| c.meta.id == id) {
            continue;
        }
        let found = crate::request::clip(state, id).await.map_err(|e| match e {
            ApiError::NotFound { .. } => ApiError::ClipNotFoundAt {
                at: At::Pointer(pointer.clone()),
                detail: format!("the clip `{id}` does not exist"),
            },
            other => other,
        })?;
        clips.push(found);
    }
    Ok(clips)
}

/// The core's build over the found clips (each id resolved to its entry).
fn build(doc: &GraphDoc, clips: &[Arc<CachedClip>]) -> Result<PinnedGraph, ApiError> {
    build_with(doc, clips, &NodeOptions::default())
}

/// [`build`], every node's motion built with `options`.
fn build_with(doc: &GraphDoc, clips: &[Arc<CachedClip>], options: &NodeOptions) -> Result<PinnedGraph, ApiError> {
    let by_id: HashMap<&str, &Arc<CachedClip>> = clips.iter().map(|c| (c.meta.id.as_str(), c)).collect();
    let resolve = |id: &str, at: &str| match by_id.get(id) {
        Some(clip) => Ok(Arc::clone(*clip) as Arc<dyn PinnedClip>),
        None => Err(formats::wire::json::DocError {
            code: "clip_not_found",
            pointer: at.to_owned(),
            detail: format!("the clip `{id}` does not exist"),
        }),
    };
    Ok(doc.compile_with("", resolve, options)?)
}

/// What a motion over a graph builds its nodes with besides the graph: the
/// character it plays on (an id or `name:…`), its retarget options and its
/// root motion.
#[derive(Debug, Clone, Default)]
pub struct MotionOnGraph {
    pub character: Option<String>,
    pub retarget: RetargetSpec,
    pub root_motion: Option<RootMotionSpec>,
}

/// The graph `built` plays for `motion`: its own when the motion names no
/// character and no root motion, else `built` built again with them —
/// each node's clips retargeted onto the character as a clip motion's
/// layers are (docs/characters.md), each node reporting root motion
/// (docs/motion.md) — once per character version and options (priced,
/// charged to `caller`, on the pool) and kept with `built`.
///
/// # Errors
/// `character_not_found` (404) at `/motion/character`; a clip of the graph
/// the character cannot map (`unmappable_skeleton`) at `/motion/character`,
/// or without the root joint (`no_root_joint`) at `/motion/root_motion`,
/// the detail saying where in the graph; the options' refusals at
/// `/motion/retarget/…` and `/motion/root_motion/…`; the price's refusals.
pub async fn played(
    state: &AppState,
    caller: &CallerKey,
    built: &Arc<BuiltGraph>,
    motion: &MotionOnGraph,
) -> Result<Arc<PinnedGraph>, ApiError> {
    if motion.character.is_none() && motion.root_motion.is_none() {
        return Ok(Arc::clone(&built.graph));
    }
    let character = match &motion.character {
        Some(reference) => Some(crate::characters::resolve(state, caller, reference).await?),
        None => None,
    };
    let key = PlayedKey {
        character: character.as_ref().map(|c| (c.meta.id.clone(), c.meta.version)),
        retarget: motion.retarget.clone(),
        root_motion: motion.root_motion.clone(),
    };
    if let Some(hit) = built.played_for(&key) {
        return Ok(hit);
    }
    let options = NodeOptions {
        character: character.as_ref().map(|c| Arc::clone(&c.spec)),
        retarget: motion.retarget.clone(),
        root_motion: motion.root_motion.clone(),
    };
    let units = build_price(&built.doc, &built.clips).saturating_add(setup_price(built, &options));
    let building = Arc::clone(built);
    let graph = crate::builds::run(&state.work, caller, &state.config.limits, units, "building this graph's motion", {
        move |_| {
            let on_character = options.character.is_some();
            build_with(&building.doc, &building.clips, &options)
                .map_err(|e| motion_error(e, &building.meta.id, on_character))
        }
    });
    let graph = Arc::new(graph.await?);
    built.keep_played(key, Arc::clone(&graph));
    Ok(graph)
}

/// The price of the nodes' retargeters beyond [`build_price`]: as a
/// motion's on a character, over every node's layers.
fn setup_price(built: &BuiltGraph, options: &NodeOptions) -> u64 {
    let Some(character) = &options.character else { return 0 };
    let joints = built.clips.iter().map(|c| c.clip.joint_count() as u64).max().unwrap_or(0);
    let (output, feet, root) =
        (character.skeleton.len() as u64, options.retarget.feet.is_some(), options.root_motion.is_some());
    price::graph_retarget_setup(node_layers(&built.doc), joints, output, (feet, root))
}

/// A refusal of a graph's build with a motion's options, pointed into the
/// request's motion: the options' own at `/motion/retarget/…` and
/// `/motion/root_motion/…`, anything else (a clip the character cannot
/// map, or without the root joint) at `/motion/character` on a character,
/// else at `/motion/root_motion`.
fn motion_error(e: ApiError, id: &str, on_character: bool) -> ApiError {
    match e {
        ApiError::Invalid { code, at: At::Pointer(inner), detail }
            if inner.starts_with("/retarget") || inner.starts_with("/root_motion") =>
        {
            ApiError::Invalid { code, at: At::Pointer(format!("/motion{inner}")), detail }
        }
        ApiError::Invalid { code, at: At::Pointer(inner), detail } => ApiError::Invalid {
            code,
            at: At::Pointer(if on_character { "/motion/character" } else { "/motion/root_motion" }.into()),
            detail: format!("graph {id} does not play with this motion: {detail} (at {inner} in the graph)"),
        },
        other => other,
    }
}

/// The price of [`build`]: each node's layers over the largest clip's
/// joints, each 2D blend's triangulation (`server::work::price`).
fn build_price(doc: &GraphDoc, clips: &[Arc<CachedClip>]) -> u64 {
    let joints = clips.iter().map(|c| c.clip.joint_count() as u64).max().unwrap_or(0);
    let blend2d = doc.nodes.values().filter_map(|node| node.blend2d.as_ref().map(|b| b.points.len() as u64));
    price::graph_build(node_layers(doc), blend2d, joints)
}

/// Each node's layers, as its motion is built: its clip, its points, its
/// entries (an entry naming a node at most a motion's bound of layers).
fn node_layers(doc: &GraphDoc) -> impl Iterator<Item = u64> + '_ {
    doc.nodes.values().map(|node| {
        let points =
            node.blend1d.as_ref().map_or(0, |b| b.points.len()) + node.blend2d.as_ref().map_or(0, |b| b.points.len());
        let entries = node.layers.as_ref().map_or(0, |entries| {
            // An entry naming a node repeats that node's layers: at most a motion's bound.
            entries.iter().map(|e| if e.node.is_some() { anim::motion::MAX_LAYERS } else { 1 }).sum()
        });
        (usize::from(node.clip.is_some()) + points + entries) as u64
    })
}

/// An estimate of a built graph's own heap: per node, a motion whose
/// layers map the clips' joints; the document's size stands for its names
/// (twice: the graph's and the document's own); and room for its builds
/// for motions, each as large again with a retargeter per clip (about
/// 256 bytes a joint: offsets, references and two model-space poses).
fn built_bytes(doc_json: &str, clips: &[Arc<CachedClip>]) -> usize {
    let joints: usize = clips.iter().map(|c| c.clip.joint_count()).max().unwrap_or(0);
    let own = doc_json.len() * 6 + clips.len() * joints * 16;
    let played = doc_json.len() * 4 + clips.len() * joints * (16 + 256);
    std::mem::size_of::<BuiltGraph>() + own + crate::built::MAX_PLAYED * played
}

/// A store refusal of a graph write or read: a missing row is a missing graph.
pub fn store_error(e: StoreError) -> ApiError {
    crate::documents::store_error(DocKind::Graph, e)
}
