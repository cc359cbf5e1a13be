//! Stored documents built once per version, as the caches keep them
//! (`AppState`'s `graphs` and `characters`): `graphs` and `characters`
//! build them, whatever plays a graph or a character reads them.

use std::sync::Arc;

use crate::cache::{Cacheable, CachedClip};
use crate::store::DocMeta;
use crate::stream::PinnedClip;
use anim::graph::Graph;
use anim::motion::CharacterSpec;

/// The core's graph over clips pinned at their versions.
pub type PinnedGraph = Graph<Arc<dyn PinnedClip>>;

/// A stored graph at one version, built over its clips at theirs.
#[derive(Debug)]
pub struct BuiltGraph {
    pub meta: DocMeta,
    pub graph: PinnedGraph,
    /// The distinct clips the document names, in its order, each the
    /// clip cache's entry at the version the graph was built on.
    pub clips: Vec<Arc<CachedClip>>,
    /// An estimate of the heap it keeps alive besides its clips (their
    /// bytes are the clip cache's).
    pub bytes: usize,
}

impl BuiltGraph {
    /// Each clip it plays, as `(id, version)`: what a motion or stream over
    /// it is pinned to.
    pub fn clip_versions(&self) -> impl Iterator<Item = (&str, u64)> {
        self.clips.iter().map(|c| (c.meta.id.as_str(), c.meta.version))
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
