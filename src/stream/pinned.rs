//! What a stream plays: a motion over clips pinned at their versions
//! (SPEC §6). The transports pin their clips (the server's cache entries
//! implement [`PinnedClip`]); the engine reads them.

use std::sync::Arc;

use crate::anim::{Clip, Motion};

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

/// A clip pinned at the version a stream plays: its id and version name
/// the frames and the shared playbacks.
pub trait PinnedClip: Send + Sync + 'static {
    fn id(&self) -> &str;
    fn version(&self) -> u64;
    fn clip(&self) -> &Clip;
}

impl std::fmt::Debug for dyn PinnedClip {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}@{}", self.id(), self.version())
    }
}

impl crate::anim::ClipSource for dyn PinnedClip {
    fn clip(&self) -> &Clip {
        PinnedClip::clip(self)
    }
}

/// What a stream plays: a motion over pinned clips (SPEC §6). A clip
/// stream plays a motion of one full-weight layer, which is the clip's own
/// pose bit for bit.
pub type StreamMotion = Motion<Arc<dyn PinnedClip>>;

/// A [`ClipSource`] with the id and version it was loaded at (the clip
/// streams' and the tests' pinned clip; the server pins its cache entries).
pub struct Pinned {
    id: Arc<str>,
    version: u64,
    source: Arc<dyn ClipSource>,
}

impl Pinned {
    pub fn new(id: &str, version: u64, source: Arc<dyn ClipSource>) -> Self {
        Pinned { id: id.into(), version, source }
    }
}

impl PinnedClip for Pinned {
    fn id(&self) -> &str {
        &self.id
    }

    fn version(&self) -> u64 {
        self.version
    }

    fn clip(&self) -> &Clip {
        self.source.clip()
    }
}
