//! A bounded cache of built motions (docs/motion.md), so a client that asks for the
//! same composition every frame (`POST /v1/poses` at 60 Hz) looks its clips
//! up but does not rebuild the motion (masks resolved, joints mapped by name,
//! additive reference poses sampled) for each pose.
//!
//! **The key** ([`MotionKey`]) is the motion as the request gave it, every
//! field of it (floats by their bits), together with the id *and version* of
//! each layer's pinned clip and of the stored character it plays on (checked
//! once per version: `server::characters::resolve`). The versions are those the clip lookups just
//! returned, so a cached motion is only ever found for the very clip versions
//! the request would build on: a motion over a replaced version can never be
//! served, even before any invalidation reaches this cache. Mask joints enter
//! the key sorted by name (gRPC's map arrives in no fixed order; a motion
//! naming a joint twice is refused when built, so for every motion that
//! builds, the order is immaterial). The joint subset and the output format
//! stay out of the key: they are checked per request on the cached motion.
//!
//! **Invalidation** keeps replaced or evicted versions from being held alive
//! here (a cached motion holds its clips): a motion goes in only while each
//! of its clips is still the clip cache's entry for its id (checked under
//! this cache's lock, see [`MotionCache::insert_if`]), and whenever the clip
//! cache lets an entry go (a local replace or delete, another node's change
//! heard by `server::notify`, an eviction, a suspension) every motion with a
//! layer of that clip id is dropped ([`MotionCache::invalidate`]). So this
//! cache never keeps a clip in memory that the clip cache's byte bound has
//! let go, and while the clip cache is suspended nothing is cached here
//! either.
//!
//! **Bounds**: at most `motion_cache_entries` motions, and their bytes
//! (`Motion::heap_bytes`: masks, joint maps and, above all, each additive
//! layer's reference pose — 32 such layers over a 4,096-joint clip hold
//! about 9 MB) count on the byte budget every cache shares
//! (`server::cache_budget`): since any new float in a request is a new key,
//! an entry bound alone would let a few hundred small requests hold
//! gigabytes. A motion over the whole budget is built, used and not kept.
//! Eviction is least-recently-used by a scan, as in the clip cache: inserts
//! happen only on misses, and the hit path stays one lock and one hash
//! lookup. Invalidation scans every entry's layers; it happens only on
//! writes and evictions.

use std::sync::{Arc, Mutex};

use crate::cache_budget::{Budgeted, CacheBudget, Entries};
use crate::stream::{PinnedClip, StreamMotion};
use anim::Playback;
use anim::character::Translation;
use anim::motion::{
    LayerMode, LayerSpec, MaskSpec, MotionSpec, RetargetSpec, RootMode, RootMotionSpec, SourcePose, UpAxis,
};

/// What identifies a built motion: the request's motion, field by field,
/// and each layer's pinned clip id and version, in an unambiguous byte
/// encoding (lengths before strings, tags before options).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct MotionKey(Box<[u8]>);

impl MotionKey {
    /// The key of `spec` over the clips its layers were looked up at, and
    /// the stored character it plays on (its id and version: a character
    /// is checked once per version, so that names its skeleton, roles and
    /// reference exactly).
    pub fn of<P: PinnedClip + ?Sized>(spec: &MotionSpec<Arc<P>>, character: Option<(&str, u64)>) -> Self {
        // Destructured without `..`: a field added to the spec cannot be left out of the key.
        let MotionSpec { layers, root_motion, ik, character: _, retarget, springs } = spec;
        let mut key = KeyWriter(Vec::with_capacity(64 * layers.len()));
        key.len(layers.len());
        for layer in layers {
            key.layer(layer);
        }
        key.root_motion(root_motion.as_ref());
        // Every field of every constraint, floats in their shortest exact
        // form: two lists give the same text only if they are the same.
        key.str(&format!("{ik:?}"));
        key.option(character, |key, (id, version)| {
            key.str(id);
            key.u64(version);
        });
        key.retarget(retarget);
        // Every chain, parameter and collider, floats in their shortest exact
        // form; nothing but the option's mark without chains (which run nothing).
        key.option((!springs.chains.is_empty()).then_some(springs), |key, s| key.str(&format!("{s:?}")));
        MotionKey(key.0.into_boxed_slice())
    }
}

/// Builds a key's bytes.
struct KeyWriter(Vec<u8>);

impl KeyWriter {
    fn layer<P: PinnedClip + ?Sized>(&mut self, layer: &LayerSpec<Arc<P>>) {
        let LayerSpec { clip, weight, mode, mask, offset, speed, playback, sync, reference_time, retarget } = layer;
        self.str(clip.id());
        self.u64(clip.version());
        self.f32(*weight);
        self.tag(match mode {
            LayerMode::Blend => 0,
            LayerMode::Additive => 1,
        });
        self.mask(mask.as_ref());
        self.f64(*offset);
        self.f64(*speed);
        self.tag(match playback {
            None => 0,
            Some(Playback::Once) => 1,
            Some(Playback::Loop) => 2,
            Some(Playback::PingPong) => 3,
        });
        self.option(sync.as_deref(), Self::str);
        self.option(*reference_time, Self::f64);
        self.option(retarget.as_ref(), Self::retarget);
    }

    fn retarget(&mut self, retarget: &RetargetSpec) {
        let RetargetSpec { source_pose, translation, target_pose, feet } = retarget;
        match source_pose {
            SourcePose::Rest => self.tag(0),
            SourcePose::Time(t) => {
                self.tag(1);
                self.f64(*t);
            }
            SourcePose::Rotations(rotations) => {
                self.tag(2);
                self.len(rotations.len());
                for (name, q) in rotations {
                    self.str(name);
                    q.to_array().iter().for_each(|x| self.f32(*x));
                }
            }
        }
        self.tag(match translation {
            Translation::Hips => 0,
            Translation::None => 1,
            Translation::All => 2,
        });
        self.len(target_pose.len());
        for (name, q) in target_pose {
            self.str(name);
            q.to_array().iter().for_each(|x| self.f32(*x));
        }
        self.option(feet.as_ref(), |key, feet| {
            key.f32(feet.contact_height);
            key.f32(feet.contact_speed);
        });
    }

    fn mask(&mut self, mask: Option<&MaskSpec>) {
        self.option(mask, |key, mask| {
            let MaskSpec { joints, descendants, default } = mask;
            let mut sorted: Vec<&(String, f32)> = joints.iter().collect();
            sorted.sort_by(|(a, wa), (b, wb)| a.cmp(b).then(wa.to_bits().cmp(&wb.to_bits())));
            key.len(sorted.len());
            for (name, weight) in sorted {
                key.str(name);
                key.f32(*weight);
            }
            key.tag(u8::from(*descendants));
            key.option(*default, Self::f32);
        });
    }

    fn root_motion(&mut self, root: Option<&RootMotionSpec>) {
        self.option(root, |key, root| {
            let RootMotionSpec { joint, mode, up } = root;
            key.option(joint.as_deref(), Self::str);
            key.tag(match mode {
                RootMode::Report => 0,
                RootMode::Extract => 1,
            });
            key.tag(match up {
                UpAxis::Y => 0,
                UpAxis::Z => 1,
            });
        });
    }

    fn option<T>(&mut self, value: Option<T>, write: impl FnOnce(&mut Self, T)) {
        match value {
            None => self.tag(0),
            Some(v) => {
                self.tag(1);
                write(self, v);
            }
        }
    }

    fn tag(&mut self, tag: u8) {
        self.0.push(tag);
    }

    fn len(&mut self, len: usize) {
        self.u64(len as u64);
    }

    fn str(&mut self, s: &str) {
        self.len(s.len());
        self.0.extend_from_slice(s.as_bytes());
    }

    fn u64(&mut self, n: u64) {
        self.0.extend_from_slice(&n.to_le_bytes());
    }

    fn f32(&mut self, x: f32) {
        self.0.extend_from_slice(&x.to_bits().to_le_bytes());
    }

    fn f64(&mut self, x: f64) {
        self.u64(x.to_bits());
    }
}

/// The motion cache; see the module docs for its key and invalidation rules.
#[derive(Debug)]
pub struct MotionCache {
    entries: Mutex<Entries<MotionKey, Arc<StreamMotion>>>,
}

/// The bytes a cached motion keeps alive: its key, the motion itself and
/// its own heap (not its layers' clips: the clip cache counts those, and a
/// motion never outlives their entries there).
pub fn motion_bytes(key: &MotionKey, motion: &StreamMotion) -> usize {
    ENTRY_BYTES + key.0.len() + std::mem::size_of::<StreamMotion>() + motion.heap_bytes()
}

/// An entry's own record: its handle on the motion, weight and stamp.
const ENTRY_BYTES: usize = std::mem::size_of::<(Arc<StreamMotion>, usize, u64)>();

impl MotionCache {
    /// A cache of at most `capacity` motions, whose bytes count on `budget`.
    ///
    /// # Panics
    /// If `capacity` is 0.
    pub fn new(capacity: usize, budget: Arc<CacheBudget>) -> Self {
        assert!(capacity > 0, "a motion cache needs room for one motion");
        MotionCache { entries: Mutex::new(Entries::new(capacity, budget)) }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Entries<MotionKey, Arc<StreamMotion>>> {
        crate::sync::lock(&self.entries)
    }

    pub fn get(&self, key: &MotionKey) -> Option<Arc<StreamMotion>> {
        self.lock().get(key).cloned()
    }

    /// Puts `motion` in under `key` if `still_current()` holds, asked under
    /// this cache's lock: an invalidation cannot slip between the question
    /// and the insert (it waits for the lock, then drops the motion). Evicts
    /// the least recently used motion when full; a motion over the whole
    /// byte budget is not kept (the caller trims the budget after).
    /// Returns whether it went in.
    pub fn insert_if(&self, key: MotionKey, motion: Arc<StreamMotion>, still_current: impl FnOnce() -> bool) -> bool {
        let bytes = motion_bytes(&key, &motion);
        let mut entries = self.lock();
        still_current() && entries.insert(key, motion, bytes).is_ok()
    }

    /// Drops every motion with a layer of one of `clip_ids`; returns how many.
    pub fn invalidate<S: AsRef<str>>(&self, clip_ids: &[S]) -> usize {
        if clip_ids.is_empty() {
            return 0;
        }
        let uses =
            |motion: &Arc<StreamMotion>| motion.layers().any(|c| clip_ids.iter().any(|id| id.as_ref() == c.id()));
        self.lock().remove_where(uses).len()
    }

    /// Drops everything (the clip cache was suspended or resumed).
    pub fn clear(&self) {
        self.lock().clear();
    }

    pub fn len(&self) -> usize {
        self.lock().len()
    }

    /// Bytes of the cached motions (see [`motion_bytes`]).
    pub fn bytes(&self) -> usize {
        self.lock().bytes()
    }

    pub fn is_empty(&self) -> bool {
        self.lock().is_empty()
    }
}

impl Budgeted for MotionCache {
    fn oldest(&self) -> Option<u64> {
        self.lock().oldest()
    }

    fn evict_oldest(&self) {
        self.lock().evict_oldest();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anim::{Channel, Clip, ClipSpec, Interpolation, Keys, Motion, TrackSpec};

    fn unbounded() -> Arc<CacheBudget> {
        Arc::new(CacheBudget::new(usize::MAX))
    }

    /// A clip pinned at a version: joints `j` and `k`.
    fn pinned(id: &str, version: u64) -> Arc<dyn PinnedClip> {
        let track = |joint: &str| {
            TrackSpec::new(
                joint,
                Channel::Translation,
                Interpolation::Linear,
                vec![0.0, 1.0],
                Keys::Vec3(vec![glam::Vec3::ZERO, glam::Vec3::X]),
            )
        };
        let spec = ClipSpec {
            name: id.into(),
            skeleton: None,
            tracks: vec![track("j"), track("k")],
            events: vec![],
            playback: Playback::Loop,
            ..Default::default()
        };
        Arc::new(crate::stream::Pinned::new(id, version, Arc::new(Clip::build(&spec).unwrap())))
    }

    /// A motion of one full layer per clip.
    fn spec(clips: &[Arc<dyn PinnedClip>]) -> MotionSpec<Arc<dyn PinnedClip>> {
        MotionSpec {
            layers: clips.iter().cloned().map(LayerSpec::new).collect(),
            root_motion: None,
            ..Default::default()
        }
    }

    fn built(spec: MotionSpec<Arc<dyn PinnedClip>>) -> (MotionKey, Arc<StreamMotion>) {
        (MotionKey::of(&spec, None), Arc::new(Motion::build(spec).unwrap()))
    }

    fn mask(joints: &[(&str, f32)]) -> Option<MaskSpec> {
        let joints = joints.iter().map(|&(n, w)| (n.to_owned(), w)).collect();
        Some(MaskSpec { joints, descendants: true, default: None })
    }

    #[test]
    fn equal_motions_over_equal_versions_have_equal_keys() {
        let (a, b) = (pinned("a", 1), pinned("b", 1));
        let mut masked = spec(&[a.clone(), b.clone()]);
        masked.layers[1].mask = mask(&[("j", 0.5), ("k", 1.0)]);
        let mut again = spec(&[pinned("a", 1), pinned("b", 1)]);
        again.layers[1].mask = mask(&[("k", 1.0), ("j", 0.5)]);
        assert_eq!(
            MotionKey::of(&masked, None),
            MotionKey::of(&again, None),
            "other copies of the same versions, mask reordered"
        );
    }

    #[test]
    fn any_difference_in_the_motion_or_its_versions_is_another_key() {
        let (a, b) = (pinned("a", 1), pinned("b", 1));
        let base = spec(&[a.clone(), b.clone()]);
        let key = MotionKey::of(&base, None);
        let changed: Vec<(&str, MotionSpec<Arc<dyn PinnedClip>>)> = vec![
            ("a weight", {
                let mut s = base.clone();
                s.layers[1].weight = 0.3;
                s
            }),
            ("a weight by one ulp", {
                let mut s = base.clone();
                s.layers[1].weight = f32::from_bits(1.0f32.to_bits() - 1);
                s
            }),
            ("a mask", {
                let mut s = base.clone();
                s.layers[1].mask = mask(&[("j", 1.0)]);
                s
            }),
            ("a mask weight", {
                let mut s = base.clone();
                s.layers[1].mask = mask(&[("j", 0.5)]);
                s
            }),
            ("a version", spec(&[a.clone(), pinned("b", 2)])),
            ("a clip", spec(&[a.clone(), pinned("c", 1)])),
            ("the layer order", spec(&[b.clone(), a.clone()])),
            ("a layer less", spec(std::slice::from_ref(&a))),
            ("the mode", {
                let mut s = base.clone();
                s.layers[1].mode = LayerMode::Additive;
                s
            }),
            ("an offset", {
                let mut s = base.clone();
                s.layers[0].offset = 0.25;
                s
            }),
            ("a sync group", {
                let mut s = base.clone();
                s.layers[0].sync = Some("walk".into());
                s
            }),
            ("root motion", MotionSpec { root_motion: Some(RootMotionSpec::default()), ..base.clone() }),
        ];
        for (what, spec) in &changed {
            assert_ne!(MotionKey::of(spec, None), key, "{what}");
        }
        // And the changed ones differ from one another (no two collapse).
        for (i, (what, s)) in changed.iter().enumerate() {
            for (other, t) in &changed[i + 1..] {
                assert_ne!(MotionKey::of(s, None), MotionKey::of(t, None), "{what} vs {other}");
            }
        }
    }

    #[test]
    fn a_character_is_keyed_by_its_id_and_version() {
        let base = spec(&[pinned("a", 1)]);
        let keys = [None, Some(("c", 1)), Some(("c", 2)), Some(("d", 1))].map(|c| MotionKey::of(&base, c));
        for (i, k) in keys.iter().enumerate() {
            assert!(keys[i + 1..].iter().all(|other| other != k), "character {i} collides");
        }
        assert_eq!(MotionKey::of(&base, Some(("c", 2))), keys[2]);
    }

    #[test]
    fn strings_are_delimited_so_ids_cannot_run_into_each_other() {
        let mut one = spec(&[pinned("ab", 1)]);
        one.layers[0].sync = Some("c".into());
        let mut other = spec(&[pinned("a", 1)]);
        other.layers[0].sync = Some("bc".into());
        assert_ne!(MotionKey::of(&one, None), MotionKey::of(&other, None));
    }

    #[test]
    fn the_least_recently_used_motion_is_evicted() {
        let cache = MotionCache::new(2, unbounded());
        let (a, b, c) = (pinned("a", 1), pinned("b", 1), pinned("c", 1));
        let (ka, ma) = built(spec(std::slice::from_ref(&a)));
        let (kb, mb) = built(spec(std::slice::from_ref(&b)));
        let (kc, mc) = built(spec(std::slice::from_ref(&c)));
        assert!(cache.insert_if(ka.clone(), ma.clone(), || true));
        assert!(cache.insert_if(kb.clone(), mb, || true));
        assert!(Arc::ptr_eq(&cache.get(&ka).unwrap(), &ma));
        assert!(cache.insert_if(kc.clone(), mc, || true));
        assert_eq!(cache.len(), 2);
        assert!(cache.get(&kb).is_none(), "b was the least recently used");
        assert!(cache.get(&ka).is_some() && cache.get(&kc).is_some());
        // Re-inserting a present key evicts nothing.
        let (_, again) = built(spec(std::slice::from_ref(&a)));
        assert!(cache.insert_if(ka.clone(), again.clone(), || true));
        assert_eq!(cache.len(), 2);
        assert!(Arc::ptr_eq(&cache.get(&ka).unwrap(), &again) && cache.get(&kc).is_some());
    }

    #[test]
    fn invalidating_a_clip_drops_every_motion_with_a_layer_of_it() {
        let cache = MotionCache::new(8, unbounded());
        let (a, b, c) = (pinned("a", 1), pinned("b", 1), pinned("c", 1));
        let motions = [
            spec(std::slice::from_ref(&a)),
            spec(&[b.clone(), a.clone()]),
            spec(std::slice::from_ref(&b)),
            spec(std::slice::from_ref(&c)),
        ];
        let keys: Vec<MotionKey> = motions
            .into_iter()
            .map(|s| {
                let (key, motion) = built(s);
                assert!(cache.insert_if(key.clone(), motion, || true));
                key
            })
            .collect();
        assert_eq!(cache.invalidate(&["a"]), 2, "a alone and a under b");
        assert!(cache.get(&keys[0]).is_none() && cache.get(&keys[1]).is_none());
        assert!(cache.get(&keys[2]).is_some() && cache.get(&keys[3]).is_some());
        assert_eq!(cache.invalidate(&["zz", "c"]), 1);
        assert_eq!(cache.invalidate(&[] as &[&str]), 0);
        assert_eq!(cache.len(), 1);
        cache.clear();
        assert!(cache.is_empty());
    }

    #[test]
    fn a_motion_whose_clips_went_meanwhile_is_not_cached() {
        let cache = MotionCache::new(8, unbounded());
        let (key, motion) = built(spec(&[pinned("a", 1)]));
        assert!(!cache.insert_if(key.clone(), motion, || false));
        assert!(cache.get(&key).is_none() && cache.is_empty());
    }

    /// A clip of `joints` joints, each with a two-key translation track.
    fn wide(id: &str, joints: usize) -> Arc<dyn PinnedClip> {
        let track = |j: usize| {
            TrackSpec::new(
                &format!("j{j}"),
                Channel::Translation,
                Interpolation::Linear,
                vec![0.0, 1.0],
                Keys::Vec3(vec![glam::Vec3::ZERO, glam::Vec3::X]),
            )
        };
        let spec = ClipSpec { name: id.into(), tracks: (0..joints).map(track).collect(), ..Default::default() };
        Arc::new(crate::stream::Pinned::new(id, 1, Arc::new(Clip::build(&spec).unwrap())))
    }

    #[test]
    fn a_motions_bytes_are_its_reference_poses_masks_and_maps_counted_by_hand() {
        let (joints, layers) = (256, 4);
        let clip = wide("w", joints);
        let mut additive = spec(&vec![clip.clone(); layers]);
        for layer in &mut additive.layers {
            layer.mode = LayerMode::Additive;
        }
        let (key, motion) = built(additive);
        // Per layer: a reference pose (translation, rotation and scale of
        // 16 bytes each per joint), a mask (f32) and a map (u32) per joint,
        // and two bit sets of the joints.
        let per_layer = joints * (3 * 16 + 4 + 4) + 2 * joints.div_ceil(64) * 8;
        let counted = motion_bytes(&key, &motion);
        let by_hand = layers * per_layer;
        assert!(counted >= by_hand, "{counted} < {by_hand}");
        // A layer's record (about 500 bytes: its clip, times, pointers to a
        // retargeter and a foot planter, …) and the key.
        assert!(counted - by_hand < layers * 576, "{counted} is far over {by_hand}: the layers' records and the key");
        // The reference poses alone: the same motion in blend mode has none.
        let (blend_key, blend) = built(spec(&vec![clip; layers]));
        assert_eq!(
            counted - motion_bytes(&blend_key, &blend),
            layers * joints * 3 * 16 + (key.0.len() - blend_key.0.len())
        );
    }

    #[test]
    fn the_byte_budget_evicts_the_least_recently_used_across_clips_and_motions_and_skips_one_over_it() {
        use crate::cache::ClipCache;
        use crate::cache::tests::cached_keys;
        use crate::cache_budget::trim;
        let (a, b, c) = (cached_keys("a", 1, 1000), cached_keys("b", 1, 1000), cached_keys("c", 1, 1000));
        let unit = a.bytes();
        let over_a: Arc<dyn PinnedClip> = a.clone();
        let (key, motion) = built(spec(&[over_a]));
        let m = motion_bytes(&key, &motion);
        assert!(m < unit / 2, "the test wants a motion under half a clip: {m} vs {unit}");
        let budget = Arc::new(CacheBudget::new(2 * unit + m + unit / 2));
        let (clips, motions) = (ClipCache::new(100, budget.clone()), MotionCache::new(100, budget.clone()));
        let caches: [&dyn Budgeted; 2] = [&clips, &motions];
        clips.insert_written(a.clone());
        clips.insert_written(b);
        assert!(motions.insert_if(key.clone(), motion, || true));
        clips.get("a");
        assert_eq!(budget.used(), 2 * unit + m);
        clips.insert_written(c);
        trim(&budget, &caches);
        assert!(clips.get("b").is_none(), "b was the least recently used of all");
        assert!(motions.get(&key).is_some() && clips.version_of("a").is_some());
        assert_eq!(budget.used(), 2 * unit + m);
        // Now a (last used before the motion was, just above) goes first.
        clips.insert_written(cached_keys("d", 1, 1000));
        trim(&budget, &caches);
        assert!(clips.version_of("a").is_none() && motions.get(&key).is_some(), "a, then enough room");
        assert_eq!(budget.used(), 2 * unit + m);
        // The motion (last used before c and d), then c.
        clips.get("c");
        clips.get("d");
        clips.insert_written(cached_keys("e", 1, 1000));
        trim(&budget, &caches);
        assert!(motions.is_empty() && clips.version_of("c").is_none() && clips.version_of("d").is_some());
        assert_eq!((budget.used(), clips.bytes() + motions.bytes()), (2 * unit, 2 * unit));
        // A motion over the whole budget is not kept.
        let small = Arc::new(CacheBudget::new(m - 1));
        let tiny = MotionCache::new(100, small.clone());
        let (key, motion) = built(spec(&[pinned("a", 1)]));
        assert!(!tiny.insert_if(key, motion, || true));
        assert_eq!((tiny.len(), small.used()), (0, 0));
    }
}
