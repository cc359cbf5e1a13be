//! What a stream plays: a motion over clips pinned at their versions
//! (docs/motion.md). The transports pin their clips (the server's cache entries
//! implement [`PinnedClip`]); the engine reads them.

use std::sync::Arc;

use anim::motion::Player;
use anim::spring::SpringsSpec;
use anim::{Clip, Motion};

/// The player of a stream's motion: the one type per-viewer streams and
/// broadcasts advance tick by tick.
pub(super) type StreamPlayer = Player<Arc<dyn PinnedClip>>;

/// A clip pinned at the version a stream plays: its id and version name
/// the frames and the shared playbacks.
pub trait PinnedClip: Send + Sync + 'static {
    fn id(&self) -> &str;
    fn version(&self) -> u64;
    fn clip(&self) -> &Clip;
    /// The clip's own spring chains (docs/springs.md); none by default.
    fn springs(&self) -> &SpringsSpec {
        &NO_SPRINGS
    }
}

/// The chains of a clip without any.
static NO_SPRINGS: SpringsSpec = SpringsSpec { chains: Vec::new(), substep_hz: anim::spring::DEFAULT_SUBSTEP_HZ };

impl std::fmt::Debug for dyn PinnedClip {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}@{}", self.id(), self.version())
    }
}

impl anim::ClipSource for dyn PinnedClip {
    fn clip(&self) -> &Clip {
        PinnedClip::clip(self)
    }
}

/// What a stream plays: a motion over pinned clips (docs/motion.md). A clip
/// stream plays a motion of one full-weight layer, which is the clip's own
/// pose bit for bit.
pub type StreamMotion = Motion<Arc<dyn PinnedClip>>;

/// A bare compiled clip with the id and version it stands for (tests and
/// tools; the server pins its cache entries, which are [`PinnedClip`]s).
pub struct Pinned {
    id: Arc<str>,
    version: u64,
    clip: Arc<Clip>,
}

impl Pinned {
    pub fn new(id: &str, version: u64, clip: Arc<Clip>) -> Self {
        Pinned { id: id.into(), version, clip }
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
        &self.clip
    }
}
