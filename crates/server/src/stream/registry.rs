//! The registry of shared playbacks that can still be joined.
//!
//! A shared playback is listed under its [`PlaybackKey`] from the moment it
//! is opened until just before its first tick; a viewer asking for the same
//! thing in that window subscribes to it instead of starting its own. The
//! playback holds its [`Listing`], and dropping the listing (at the first
//! tick, or when the playback ends without one) removes the entry, so an
//! entry never outlives its playback.
//!
//! The map sits behind a std mutex held for one lookup, insert or removal,
//! never across an await and never while a playback is started.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard};

use tokio::sync::broadcast;

use super::encode::Encoding;
use super::params::StreamParams;
use super::schedule::Schedule;

/// What makes two streams the same playback (if they start together).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(crate) struct PlaybackKey {
    identity: Arc<str>,
    joints: Option<Arc<[usize]>>,
    parameters: Option<Arc<[usize]>>,
    fps: u32,
    start: u64,
    speed: u64,
    modes: [&'static str; 2],
    encoding: Encoding,
    paused: bool,
}

impl PlaybackKey {
    pub(crate) fn of(params: &StreamParams) -> Self {
        PlaybackKey {
            identity: Arc::clone(&params.identity),
            joints: params.joints.clone(),
            parameters: params.parameters.clone(),
            fps: params.fps,
            start: params.start.to_bits(),
            speed: params.speed.to_bits(),
            modes: [params.ease.as_str(), params.space.as_str()],
            encoding: params.encoding,
            paused: params.paused,
        }
    }
}

/// What a viewer needs to join a listed playback of items `T`: its
/// broadcast and its schedule.
pub(crate) struct Joinable<T> {
    pub(crate) tx: broadcast::Sender<T>,
    pub(crate) schedule: Schedule,
}

impl<T> Clone for Joinable<T> {
    fn clone(&self) -> Self {
        Joinable { tx: self.tx.clone(), schedule: self.schedule.clone() }
    }
}

/// What [`Registry::join`] found.
pub(crate) enum Joined<T> {
    /// A listed playback: its schedule and a receiver of its items.
    Existing { schedule: Schedule, rx: broadcast::Receiver<T> },
    /// Nothing was listed; the new playback now is. The caller starts it,
    /// handing it `listing`.
    Opened { joinable: Joinable<T>, rx: broadcast::Receiver<T>, listing: Listing<T> },
}

/// Shared playbacks (publishing items `T`) that have not ticked yet.
pub(crate) struct Registry<T> {
    open: Mutex<HashMap<PlaybackKey, Joinable<T>>>,
}

impl<T> Default for Registry<T> {
    fn default() -> Self {
        Registry { open: Mutex::default() }
    }
}

impl<T> Registry<T> {
    /// Joins the playback listed under `key`, or lists a new one made by
    /// `make` (which must not block: it runs under the lock).
    pub(crate) fn join(self: &Arc<Self>, key: PlaybackKey, make: impl FnOnce() -> Joinable<T>) -> Joined<T> {
        let mut open = self.lock();
        if let Some(listed) = open.get(&key) {
            return Joined::Existing { schedule: listed.schedule.clone(), rx: listed.tx.subscribe() };
        }
        let joinable = make();
        let rx = joinable.tx.subscribe();
        open.insert(key.clone(), joinable.clone());
        Joined::Opened { joinable, rx, listing: Listing { registry: Arc::clone(self), key } }
    }

    /// Playbacks listed now.
    pub(crate) fn len(&self) -> usize {
        self.lock().len()
    }

    /// Every critical section is one map operation (`crate::sync`'s policy).
    fn lock(&self) -> MutexGuard<'_, HashMap<PlaybackKey, Joinable<T>>> {
        crate::sync::lock(&self.open)
    }
}

/// A playback's entry in the registry; dropping it unlists the playback.
pub(crate) struct Listing<T> {
    registry: Arc<Registry<T>>,
    key: PlaybackKey,
}

impl<T> Drop for Listing<T> {
    fn drop(&mut self) {
        self.registry.lock().remove(&self.key);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stream::{StreamRequest, schedule::Grid};
    use anim::{Channel, Clip, ClipSpec, Interpolation, Keys, Playback, TrackSpec};

    fn key(fps: u32) -> PlaybackKey {
        let track = TrackSpec::new(
            "j",
            Channel::Translation,
            Interpolation::Linear,
            vec![0.0, 1.0],
            Keys::Vec3(vec![glam::Vec3::ZERO, glam::Vec3::X]),
        );
        let spec = ClipSpec {
            name: "r".into(),
            skeleton: None,
            tracks: vec![track],
            events: vec![],
            playback: Playback::Once,
            ..Default::default()
        };
        let clip: Arc<Clip> = Arc::new(Clip::build(&spec).unwrap());
        let params = StreamParams::new(
            std::sync::Arc::new(crate::stream::Pinned::new("c", 1, clip)),
            StreamRequest { fps, ..Default::default() },
        )
        .unwrap();
        PlaybackKey::of(&params)
    }

    fn joinable() -> Joinable<u32> {
        let grid = Grid { epoch: tokio::time::Instant::now(), fps: 30, phase_ms: 0 };
        Joinable { tx: broadcast::channel(4).0, schedule: Schedule::new(grid, 0, 0) }
    }

    #[test]
    fn the_same_key_joins_until_the_listing_is_dropped() {
        let registry: Arc<Registry<u32>> = Arc::default();
        let Joined::Opened { joinable: opened, listing, .. } = registry.join(key(30), joinable) else {
            panic!("the first viewer opens");
        };
        let Joined::Existing { mut rx, .. } = registry.join(key(30), || unreachable!("listed")) else {
            panic!("the second viewer joins");
        };
        opened.tx.send(7).unwrap();
        assert_eq!(rx.try_recv().unwrap(), 7, "the joiner receives the opener's playback");
        assert!(matches!(registry.join(key(60), joinable), Joined::Opened { .. }), "another key opens its own");
        assert_eq!(registry.len(), 1, "the dropped listing for fps 60 unlisted it at once");
        drop(listing);
        assert_eq!(registry.len(), 0);
        assert!(matches!(registry.join(key(30), joinable), Joined::Opened { .. }), "unlisted: opens anew");
    }
}
