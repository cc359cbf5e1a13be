//! Stored documents built once per version, as the caches keep them
//! (`AppState`'s `graphs` and `characters`): `graphs` and `characters`
//! build them, whatever plays a graph or a character reads them.

use std::sync::{Arc, Mutex};

use crate::cache::{Cacheable, CachedClip};
use crate::store::DocMeta;
use crate::stream::PinnedClip;
use anim::graph::Graph;
use anim::motion::{CharacterSpec, RetargetSpec, RootMotionSpec};
use formats::wire::graph::GraphDoc;

/// The core's graph over clips pinned at their versions.
pub type PinnedGraph = Graph<Arc<dyn PinnedClip>>;

/// What a motion over a pinned graph runs on its pose: its clip layers, IK and springs.
pub type PinnedPost = anim::graph::GraphPost<Arc<dyn PinnedClip>>;

/// A stored graph at one version, built over its clips at theirs.
#[derive(Debug)]
pub struct BuiltGraph {
    pub meta: DocMeta,
    pub graph: Arc<PinnedGraph>,
    /// The document it was built from, to build it again with a motion's
    /// character and root motion.
    pub doc: GraphDoc,
    /// The distinct clips the document names, in its order, each the
    /// clip cache's entry at the version the graph was built on.
    pub clips: Vec<Arc<CachedClip>>,
    /// The graph built again for motions over it (`server::graphs::played`),
    /// by [`PlayedKey`]: at most [`MAX_PLAYED`], the oldest replaced. They
    /// leave with it.
    pub played: Mutex<Vec<(PlayedKey, Arc<PinnedGraph>)>>,
    /// An estimate of the heap it keeps alive besides its clips (their
    /// bytes are the clip cache's), room for its builds for motions
    /// included.
    pub bytes: usize,
}

/// What a graph's build for a motion depends on besides the graph: the
/// character's id and version, the retarget options, the root motion.
#[derive(Debug, Clone, PartialEq)]
pub struct PlayedKey {
    pub character: Option<(String, u64)>,
    pub retarget: RetargetSpec,
    pub root_motion: Option<RootMotionSpec>,
}

/// How many builds for motions (on characters, with root motion) a built graph keeps.
pub const MAX_PLAYED: usize = 4;

impl BuiltGraph {
    /// Each clip it plays, as `(id, version)`: what a motion or stream over
    /// it is pinned to.
    pub fn clip_versions(&self) -> impl Iterator<Item = (&str, u64)> {
        self.clips.iter().map(|c| (c.meta.id.as_str(), c.meta.version))
    }

    /// Its build for a motion with `key`.
    pub fn played_for(&self, key: &PlayedKey) -> Option<Arc<PinnedGraph>> {
        let kept = self.played.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        kept.iter().find(|(k, _)| k == key).map(|(_, graph)| Arc::clone(graph))
    }

    /// Keeps its build for a motion under `key`, the oldest let go when
    /// [`MAX_PLAYED`] are kept.
    pub fn keep_played(&self, key: PlayedKey, graph: Arc<PinnedGraph>) {
        let mut kept = self.played.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if kept.iter().any(|(k, _)| *k == key) {
            return;
        }
        if kept.len() >= MAX_PLAYED {
            kept.remove(0);
        }
        kept.push((key, graph));
    }

    /// Whether it was built on a version of clip `id`.
    pub fn uses_clip(&self, id: &str) -> bool {
        self.clips.iter().any(|c| c.meta.id == id)
    }
}

impl Cacheable for BuiltGraph {
    fn cache_id(&self) -> &str {
        &self.meta.id
    }

    fn cache_version(&self) -> u64 {
        self.meta.version
    }

    fn cache_bytes(&self) -> usize {
        self.bytes
    }
}

/// A stored character at one version as motions play on it: its skeleton,
/// role map and rest pose as reference, checked once per version.
#[derive(Debug)]
pub struct BuiltCharacter {
    pub meta: DocMeta,
    pub spec: Arc<CharacterSpec>,
    pub bytes: usize,
}

impl Cacheable for BuiltCharacter {
    fn cache_id(&self) -> &str {
        &self.meta.id
    }

    fn cache_version(&self) -> u64 {
        self.meta.version
    }

    fn cache_bytes(&self) -> usize {
        self.bytes
    }
}
