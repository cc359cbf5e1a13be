//! Layering (docs/motion.md) against an `f64` evaluation of it written here.
//!
//! Random motions over random skeletons (fixed seeds): 1–4 layers, blend
//! and additive (with and without a reference time), masks (named joints,
//! descendants, defaults), sync groups over clips of different lengths,
//! every playback mode with offsets and negative speeds, every ease, both
//! spaces. The reference computes each layer's clip time itself (the
//! mapping and rounding rules of docs/clip-format.md, 2.7, the sync-group phase, all in `f64`) and
//! the layering (lerp, exact short-way slerp, the additive formulas) in
//! `f64`; only each layer's clip pose at that time comes from
//! `Clip::sample_into`, which `accuracy` holds to the clip reference. Both
//! must agree within the bound of docs/clip-format.md, 2.9. The worst error is printed
//! (`cargo test --test core composition_reference -- --nocapture`).
//!
//! Also: one full-weight layer is its clip bit for bit at any offset,
//! speed and playback, whatever lies beneath it or under weight 0 above.

use anim::motion::{LayerMode, LayerSpec, MaskSpec, MotionOptions, MotionSpec};
use anim::{Clip, ClipSpec, Cursor, Ease, Motion, MotionSampler, Playback, Pose, SampleOptions, Sampler, Space};
use glam::{DVec3, DVec4};

use crate::accuracy::TOLERANCE;
use crate::random::{Rng, skeleton_clip};
use crate::reference::{RefClip, Trs, qpow, short, slerp};

pub const EASES: [Ease; 4] = [Ease::Linear, Ease::EaseIn, Ease::EaseOut, Ease::EaseInOut];
const PLAYBACKS: [Playback; 3] = [Playback::Once, Playback::Loop, Playback::PingPong];

/// Clips to draw layers from, each with its reference form and joint names.
pub struct Pool {
    pub specs: Vec<ClipSpec>,
    pub clips: Vec<Clip>,
    refs: Vec<RefClip>,
    names: Vec<Vec<String>>,
}

impl Pool {
    pub fn new(specs: Vec<ClipSpec>) -> Pool {
        let clips = specs.iter().map(|s| Clip::build(s).unwrap_or_else(|e| panic!("{e}: {s:?}"))).collect();
        let refs = specs.iter().map(RefClip::new).collect();
        let names = specs
            .iter()
            .map(|s| {
                s.skeleton.as_ref().expect("pool clips have skeletons").joints.iter().map(|j| j.name.clone()).collect()
            })
            .collect();
        Pool { specs, clips, refs, names }
    }

    /// `count` random skeleton clips of 2–9 joints, each at least 0.2 s long.
    pub fn random(rng: &mut Rng, count: usize) -> Pool {
        Pool::new(
            (0..count)
                .map(|_| {
                    long_enough(rng, |rng| {
                        let joints = 2 + rng.below(8);
                        skeleton_clip(rng, joints)
                    })
                })
                .collect(),
        )
    }

    /// `count` random clips that all share the first one's skeleton (so
    /// their motions can crossfade).
    pub fn shared_skeleton(rng: &mut Rng, count: usize, joints: usize) -> Pool {
        let first = long_enough(rng, |rng| skeleton_clip(rng, joints));
        let mut specs = vec![first.clone()];
        while specs.len() < count {
            let mut spec = long_enough(rng, |rng| skeleton_clip(rng, joints));
            spec.skeleton.clone_from(&first.skeleton);
            specs.push(spec);
        }
        Pool::new(specs)
    }

    /// The motion of `layers`, whose clips are indices into the pool.
    pub fn motion(&self, layers: &[LayerSpec<usize>]) -> Motion<&Clip> {
        let spec = MotionSpec { layers: layers.to_vec(), root_motion: None, ..Default::default() };
        let spec = spec.try_map(|_, i| Ok::<_, ()>(&self.clips[i])).unwrap();
        Motion::build(spec).unwrap_or_else(|e| panic!("{e} at {:?}", e.path))
    }
}

/// A random clip whose range is at least 0.2 s (sync groups divide by it).
fn long_enough(rng: &mut Rng, mut draw: impl FnMut(&mut Rng) -> ClipSpec) -> ClipSpec {
    loop {
        let spec = draw(rng);
        let r = RefClip::new(&spec);
        if r.end - r.start >= 0.2 {
            return spec;
        }
    }
}

/// A weight: often exactly 0 or 1, else uniform.
fn weight(rng: &mut Rng) -> f32 {
    match rng.below(5) {
        0 => 0.0,
        1 | 2 => 1.0,
        _ => rng.unit() as f32,
    }
}

/// A random mask over the output skeleton's `names`.
fn mask(rng: &mut Rng, names: &[String]) -> MaskSpec {
    let mut joints = Vec::new();
    for name in names {
        if rng.chance(0.35) {
            joints.push((name.clone(), weight(rng)));
        }
    }
    let default = rng.chance(0.4).then(|| weight(rng));
    MaskSpec { joints, descendants: rng.chance(0.5), default }
}

/// 1–4 random layers over `pool`'s clips: any weight, mode, mask, offset,
/// speed (negative too), playback, sync group and reference time.
pub fn random_layers(rng: &mut Rng, pool: &Pool) -> Vec<LayerSpec<usize>> {
    let first = rng.below(pool.clips.len());
    random_layers_over(rng, pool, first)
}

/// [`random_layers`] whose first layer (the output skeleton) plays clip `first`.
pub fn random_layers_over(rng: &mut Rng, pool: &Pool, first: usize) -> Vec<LayerSpec<usize>> {
    let count = 1 + rng.below(4);
    (0..count)
        .map(|l| {
            let clip = if l == 0 { first } else { rng.below(pool.clips.len()) };
            let mode = if rng.chance(if l == 0 { 0.1 } else { 0.35 }) { LayerMode::Additive } else { LayerMode::Blend };
            let r = &pool.refs[clip];
            LayerSpec {
                clip,
                weight: weight(rng),
                mode,
                mask: rng.chance(0.45).then(|| mask(rng, &pool.names[first])),
                offset: if rng.chance(0.3) { 0.0 } else { rng.range(-3.0, 3.0) },
                speed: [1.0, -1.0, 0.0, rng.range(-2.5, 2.5), rng.range(-2.5, 2.5)][rng.below(5)],
                playback: rng.chance(0.7).then(|| PLAYBACKS[rng.below(3)]),
                sync: rng.chance(0.45).then(|| ["a", "b"][rng.below(2)].to_string()),
                reference_time: (mode == LayerMode::Additive && rng.chance(0.6))
                    .then(|| rng.range(r.start - 1.0, r.end + 1.0)),
                retarget: None,
            }
        })
        .collect()
}

/// The ease warps of docs/clip-format.md, “Speed control”.
pub fn ease(e: Ease, x: f64) -> f64 {
    match e {
        Ease::Linear => x,
        Ease::EaseIn => x * x,
        Ease::EaseOut => 1.0 - (1.0 - x) * (1.0 - x),
        Ease::EaseInOut => 3.0 * x * x - 2.0 * x * x * x,
    }
}

/// The `f64` evaluation of a motion (docs/motion.md).
pub struct Reference<'a> {
    pub pool: &'a Pool,
    pub layers: &'a [LayerSpec<usize>],
}

impl Reference<'_> {
    fn range(&self, l: usize) -> (f64, f64) {
        let r = &self.pool.refs[self.layers[l].clip];
        (r.start, r.end)
    }

    /// docs/clip-format.md, 2.7: a request time `t` as a position `[0, d]` past the start
    /// after `playback`, with the `f32` rule at the start, the end and the
    /// loop seam.
    fn position(start: f64, end: f64, t: f64, playback: Playback) -> f64 {
        let d = end - start;
        let x = if t as f32 == start as f32 {
            0.0
        } else if t as f32 == end as f32 {
            d
        } else {
            t - start
        };
        match playback {
            Playback::Once => x.clamp(0.0, d),
            Playback::Loop => Self::loop_position(start, end, x - d * (x / d).floor()),
            Playback::PingPong => {
                let p = x - 2.0 * d * (x / (2.0 * d)).floor();
                if p > d { 2.0 * d - p } else { p }
            }
        }
    }

    /// A loop position that rounds to the end is the next cycle's start.
    fn loop_position(start: f64, end: f64, p: f64) -> f64 {
        if (start + p) as f32 >= end as f32 { 0.0 } else { p }
    }

    /// Sync group `name`'s phase at `tau`: `φ_0 + speed·τ/D` with `D` the
    /// share-weighted mean of its layers' durations.
    fn phase(&self, name: &str, tau: f64) -> f64 {
        let members: Vec<usize> =
            (0..self.layers.len()).filter(|&l| self.layers[l].sync.as_deref() == Some(name)).collect();
        let duration = |l: usize| self.range(l).1 - self.range(l).0;
        let w = |l: usize| f64::from(self.layers[l].weight);
        let shares: Vec<f64> = members
            .iter()
            .enumerate()
            .map(|(i, &l)| members[i + 1..].iter().fold(w(l), |e, &k| e * (1.0 - w(k))))
            .collect();
        let total: f64 = shares.iter().sum();
        let d = if total > 0.0 {
            members.iter().zip(&shares).map(|(&l, e)| e * duration(l)).sum::<f64>() / total
        } else {
            members.iter().map(|&l| duration(l)).sum::<f64>() / members.len() as f64
        };
        let first = &self.layers[members[0]];
        (first.offset - self.range(members[0]).0) / duration(members[0]) + first.speed * tau / d
    }

    /// Each layer's clip time at motion time `tau`.
    pub fn clip_times(&self, tau: f64, e: Ease) -> Vec<f64> {
        (0..self.layers.len())
            .map(|l| {
                let layer = &self.layers[l];
                let (start, end) = self.range(l);
                let p = match &layer.sync {
                    None => {
                        let playback = layer.playback.unwrap_or(self.pool.specs[layer.clip].playback);
                        Self::position(start, end, layer.offset + layer.speed * tau, playback)
                    }
                    Some(name) => {
                        let phase = self.phase(name, tau);
                        Self::loop_position(start, end, (phase - phase.floor()) * (end - start))
                    }
                };
                start + ease(e, p / (end - start)) * (end - start)
            })
            .collect()
    }

    /// Layer `l`'s mask weight at output joint `j`: its own weight if
    /// named, else (with `descendants`) its nearest named ancestor's, else
    /// the default.
    fn mask(&self, l: usize, j: usize) -> f64 {
        let Some(mask) = &self.layers[l].mask else { return 1.0 };
        let output = self.layers[0].clip;
        let (names, parents) = (&self.pool.names[output], &self.pool.refs[output].parents);
        let named = |j: usize| mask.joints.iter().find(|(n, _)| *n == names[j]).map(|(_, w)| f64::from(*w));
        let mut at = Some(j);
        while let Some(k) = at {
            if let Some(w) = named(k) {
                return w;
            }
            at = if mask.descendants { parents[k] } else { None };
        }
        mask.default.map_or(if mask.joints.is_empty() { 1.0 } else { 0.0 }, f64::from)
    }

    /// The layered local pose, given each layer's clip time.
    pub fn local(&self, clip_times: &[f64]) -> Vec<Trs> {
        let output = self.layers[0].clip;
        let mut pose = self.pool.refs[output].rest.clone();
        for (l, layer) in self.layers.iter().enumerate() {
            let own = clip_pose(&self.pool.clips[layer.clip], clip_times[l]);
            let reference = (layer.mode == LayerMode::Additive).then(|| {
                let (start, end) = self.range(l);
                clip_pose(&self.pool.clips[layer.clip], layer.reference_time.map_or(start, |t| t.clamp(start, end)))
            });
            for (j, name) in self.pool.names[output].iter().enumerate() {
                let Some(source) = self.pool.names[layer.clip].iter().position(|n| n == name) else { continue };
                let w = f64::from(layer.weight) * self.mask(l, j);
                pose[j] = match &reference {
                    None => blend(pose[j], own[source], w),
                    Some(r) => add(pose[j], own[source], r[source], w),
                };
            }
        }
        pose
    }

    /// The model pose of a local pose (docs/clip-format.md, “Skeleton and
    /// spaces”) on the output skeleton.
    pub fn model(&self, local: &[Trs]) -> Vec<Trs> {
        self.pool.refs[self.layers[0].clip].model(local)
    }
}

/// A clip's local pose at clip time `t` (rounded to the clip's `f32`), in `f64`.
fn clip_pose(clip: &Clip, t: f64) -> Vec<Trs> {
    let mut pose = Pose::default();
    clip.sample_into(t as f32, &mut Cursor::default(), &mut pose);
    (0..pose.len()).map(|j| trs(&pose, j)).collect()
}

pub fn trs(pose: &Pose, j: usize) -> Trs {
    Trs { t: pose.translations[j].as_dvec3(), r: pose.rotations[j].as_dquat(), s: pose.scales[j].as_dvec3() }
}

/// A `blend` layer (and a crossfade): lerp, exact short-way slerp.
pub fn blend(a: Trs, b: Trs, w: f64) -> Trs {
    Trs { t: a.t + (b.t - a.t) * w, r: slerp(a.r, b.r, w), s: a.s + (b.s - a.s) * w }
}

/// An `additive` layer: `t += w·(t_l − t_r)`, `q = q·slerp(I, short(q_r⁻¹·q_l), w)`,
/// `s = s ⊙ (1 + w·(s_l ⊘ s_r − 1))`.
pub fn add(a: Trs, l: Trs, r: Trs, w: f64) -> Trs {
    let step = qpow(short(r.r.conjugate() * l.r), w);
    Trs { t: a.t + (l.t - r.t) * w, r: (a.r * step).normalize(), s: a.s * (DVec3::ONE + (l.s / r.s - DVec3::ONE) * w) }
}

/// docs/clip-format.md, 2.9: the worst error of `got` against `expected`, each component
/// scaled by `max(1, |reference|)`; quaternions compared after choosing the sign.
pub fn bound_err(got: Trs, expected: Trs) -> f64 {
    let vec = |a: DVec3, b: DVec3| ((a - b).abs() / b.abs().max(DVec3::ONE)).max_element();
    let (a, b) = (DVec4::from(got.r), DVec4::from(expected.r));
    let quat = (a - b).abs().max_element().min((a + b).abs().max_element());
    vec(got.t, expected.t).max(vec(got.s, expected.s)).max(quat)
}

/// The worst [`bound_err`] over a pose (NaN counts as infinitely wrong).
pub fn pose_err(got: &Pose, expected: &[Trs]) -> f64 {
    assert_eq!(got.len(), expected.len(), "joint count");
    expected
        .iter()
        .enumerate()
        .map(|(j, &e)| bound_err(trs(got, j), e))
        .fold(0.0, |w, e| if e.is_nan() { f64::INFINITY } else { w.max(e) })
}

/// How often the random draw exercised each feature, so the sweep cannot
/// pass by never meeting one.
#[derive(Debug, Default)]
struct Coverage {
    additive: usize,
    masked_descendants: usize,
    masked_flat: usize,
    synced_pairs: usize,
    negative_speed: usize,
    playbacks: [usize; 3],
    partial_weight: usize,
}

impl Coverage {
    fn count(&mut self, layers: &[LayerSpec<usize>]) {
        for l in layers {
            self.additive += usize::from(l.mode == LayerMode::Additive);
            self.masked_descendants += usize::from(l.mask.as_ref().is_some_and(|m| m.descendants));
            self.masked_flat += usize::from(l.mask.as_ref().is_some_and(|m| !m.descendants));
            self.negative_speed += usize::from(l.speed < 0.0 && l.sync.is_none());
            self.partial_weight += usize::from(l.weight > 0.0 && l.weight < 1.0);
            if let Some(p) = l.playback.filter(|_| l.sync.is_none()) {
                self.playbacks[PLAYBACKS.iter().position(|&q| q == p).unwrap()] += 1;
            }
        }
        for name in ["a", "b"] {
            self.synced_pairs += usize::from(layers.iter().filter(|l| l.sync.as_deref() == Some(name)).count() >= 2);
        }
    }

    fn assert_enough(&self) {
        let least = [
            self.additive,
            self.masked_descendants,
            self.masked_flat,
            self.synced_pairs,
            self.negative_speed,
            self.partial_weight,
        ]
        .into_iter()
        .chain(self.playbacks)
        .min()
        .unwrap();
        assert!(least >= 20, "the sweep missed a feature: {self:?}");
    }
}

#[test]
fn layered_motions_match_the_f64_reference() {
    let (mut worst, mut worst_time, mut where_) = (0.0f64, 0.0f64, String::new());
    let mut coverage = Coverage::default();
    for seed in 0..8u64 {
        let mut rng = Rng::new(1600 + seed);
        let pool = Pool::random(&mut rng, 5);
        for case in 0..30 {
            let layers = random_layers(&mut rng, &pool);
            coverage.count(&layers);
            let motion = pool.motion(&layers);
            let reference = Reference { pool: &pool, layers: &layers };
            let mut sampler = MotionSampler::new();
            for _ in 0..16 {
                let tau = if rng.chance(0.1) { 0.0 } else { rng.range(-6.0, 9.0) };
                let (e, space) = (EASES[rng.below(4)], [Space::Local, Space::Model][rng.below(2)]);
                motion.sample(tau, &MotionOptions { ease: e, space }, &mut sampler);
                let times = reference.clip_times(tau, e);
                for (l, (&got, &expected)) in sampler.clip_times().iter().zip(&times).enumerate() {
                    let err = (f64::from(got) - expected).abs() / expected.abs().max(1.0);
                    worst_time = worst_time.max(err);
                    assert!(
                        err <= TOLERANCE,
                        "seed {seed} case {case} layer {l} at τ={tau} ({e:?}): {got} vs {expected}\n{layers:?}"
                    );
                }
                let local = reference.local(&times);
                let mut err = pose_err(sampler.local(), &local);
                if space == Space::Model {
                    err = err.max(pose_err(sampler.pose(), &reference.model(&local)));
                }
                if err > worst {
                    (worst, where_) = (err, format!("seed {seed} case {case} τ={tau} {e:?} {space:?}\n{layers:?}"));
                }
            }
        }
    }
    println!(
        "composition vs f64 reference: worst pose error {worst:.3e}, worst clip-time error {worst_time:.3e}; {coverage:?}"
    );
    assert!(worst <= TOLERANCE, "worst error {worst:e} at {where_}");
    coverage.assert_enough();
}

#[test]
fn the_reference_sees_a_wrong_layering() {
    // The sweep's check can fail: a motion whose second layer is at half
    // weight is not the reference of the same motion at weight 0.6.
    let mut rng = Rng::new(1650);
    let pool = Pool::random(&mut rng, 2);
    let base = LayerSpec::new(0);
    let layers = vec![base.clone(), LayerSpec { weight: 0.5, ..LayerSpec::new(1) }];
    let wrong = vec![base, LayerSpec { weight: 0.6, ..LayerSpec::new(1) }];
    let mut sampler = MotionSampler::new();
    pool.motion(&layers).sample(0.3, &MotionOptions::default(), &mut sampler);
    let reference = Reference { pool: &pool, layers: &wrong };
    let err = pose_err(sampler.local(), &reference.local(&reference.clip_times(0.3, Ease::Linear)));
    assert!(err > 100.0 * TOLERANCE, "{err}");
}

#[test]
fn a_full_weight_layer_is_its_clip_bit_for_bit() {
    let mut rng = Rng::new(1660);
    for _ in 0..40 {
        let pool = Pool::random(&mut rng, 3);
        let (offset, speed) = (rng.range(-3.0, 3.0), [1.0, -1.0, rng.range(-2.5, 2.5)][rng.below(3)]);
        let playback = PLAYBACKS[rng.below(3)];
        let names = &pool.names[0];
        // Every joint named at 1, or nothing named with default 1, or no mask: all full weight.
        let mask = match rng.below(3) {
            0 => Some(MaskSpec { joints: names.iter().map(|n| (n.clone(), 1.0)).collect(), ..MaskSpec::default() }),
            1 => Some(MaskSpec { default: Some(1.0), ..MaskSpec::default() }),
            _ => None,
        };
        let top = LayerSpec { offset, speed, playback: Some(playback), mask, ..LayerSpec::new(0) };
        // Beneath it anything on the same output skeleton (it covers every
        // joint) or nothing; above it a layer at weight 0 and one masked out.
        let mut layers = random_layers_over(&mut rng, &pool, 0);
        if rng.chance(0.3) {
            layers.clear();
        }
        layers.push(top);
        layers.push(LayerSpec { weight: 0.0, ..LayerSpec::new(1 + rng.below(2)) });
        layers.push(LayerSpec {
            mask: Some(MaskSpec { joints: vec![(names[0].clone(), 0.0)], ..MaskSpec::default() }),
            ..LayerSpec::new(2)
        });
        let motion = pool.motion(&layers);
        let clip = &pool.clips[0];
        let (mut plain, mut composed) = (Sampler::new(), MotionSampler::new());
        for _ in 0..25 {
            let tau = rng.range(-6.0, 9.0);
            let (e, space) = (EASES[rng.below(4)], [Space::Local, Space::Model][rng.below(2)]);
            let expected = clip.sample(
                offset + speed * tau,
                &SampleOptions { playback: Some(playback), ease: e, space },
                &mut plain,
            );
            motion.sample(tau, &MotionOptions { ease: e, space }, &mut composed);
            let at = layers.len() - 3;
            assert_eq!(composed.clip_times()[at].to_bits(), expected.to_bits(), "clip time at τ={tau}");
            assert_eq!(composed.pose(), plain.pose(), "τ={tau} {space:?} {e:?} {layers:?}");
        }
    }
}
