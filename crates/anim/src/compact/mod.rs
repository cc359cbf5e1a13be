//! Compact frames (docs/compact-frames.md): the bit widths that keep a
//! quantised pose within a stated error, and the quantisation itself.
//!
//! The error of a pose is measured where it shows: at every joint's
//! model-space position and at the three points `distance` along its local
//! axes (`M_j · (distance · axis)`), the way ACL measures virtual vertices.
//! A quantisation error at joint `k` moves the whole subtree below it
//! rigidly (translation), turns it about `k` (rotation) or stretches it away
//! from `k` (scale), so its effect is bounded by the subtree's reach from
//! `k`. Errors add up along a chain, so each root-to-leaf chain shares the
//! budget: every quantised channel gets `budget / n`, where `n` is the
//! number of quantised channels on the longest chain through it (for one
//! chain, equal shares minimise the bits). The bound is then computed back
//! from the chosen widths, so what a layout states is derived, not hoped.
//!
//! Decoding is defined in f64 and rounded to f32 once, so every decoder
//! (Rust, JavaScript, Python) produces the same bits.

use glam::{Quat, Vec3, Vec3A};

mod bound;
pub use bound::turned_joints;
mod moved;

use crate::{Clip, Cursor, Pose, Skeleton};

/// The default error bound, metres.
pub const DEFAULT_MAX_ERROR: f32 = 1e-4;
/// The smallest error bound a stream may ask for, metres.
pub const MIN_MAX_ERROR: f32 = 1e-6;
/// The smallest `distance`, metres.
pub const MIN_DISTANCE: f32 = 0.01;
/// The default `distance` as a share of the rest height.
pub const DISTANCE_OF_REST_HEIGHT: f32 = 0.1;
/// The widest channel: more bits than an f32 mantissa carry nothing.
pub const MAX_BITS: u8 = 24;

/// How far a derived range is widened on either side, relative to the
/// largest magnitude that went into it: the f32 rounding of the layering
/// arithmetic (a few steps of 2⁻²⁴ per layer) stays inside.
const ROUNDING_MARGIN: f32 = 1.0 / (1u32 << 16) as f32;

/// Why a stream's poses cannot be bounded at open.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Unbounded(pub &'static str);

/// `1/√2`: the largest magnitude of a unit quaternion's three smallest
/// components.
const SMALLEST_THREE_RANGE: f64 = std::f64::consts::FRAC_1_SQRT_2;
/// The share of `max_error` the widths are chosen for; the rest absorbs
/// the second-order terms the per-channel bounds leave out.
const BUDGET_SHARE: f64 = 0.9;
/// Relative rounding of one f32 result.
const F32_ROUNDING: f64 = 1.0 / (1u64 << 24) as f64;

/// One translation or scale component: its range and width. `bits == 0`
/// means constant: every frame's value is `min` (which equals `max`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    pub min: f32,
    pub max: f32,
    pub bits: u8,
}

/// A joint's rotation: constant (sent once) or quantised "smallest three".
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rotation {
    Constant(Quat),
    Quantised(SmallestThree),
}

/// "Smallest three": the rotation's sign chosen so its largest component
/// is positive, that component's index (sent per frame in 2 bits unless it
/// is always the same, `largest`), and the other three, each quantised in
/// its own range (`[x, y, z, w]`; a component that never changes costs no
/// bits). The largest is rebuilt from the other three.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmallestThree {
    pub largest: Option<u8>,
    pub components: [Axis; 4],
}

impl SmallestThree {
    fn bits(&self) -> u32 {
        let index = if self.largest.is_some() { 0 } else { 2 };
        // The largest component is never sent, but which one it is varies:
        // count the three widest, the frame's worst case.
        let mut widths = self.components.map(|a| u32::from(a.bits));
        widths.sort_unstable();
        index
            + self.largest.map_or(widths[1] + widths[2] + widths[3], |l| {
                self.components
                    .iter()
                    .enumerate()
                    .filter(|&(k, _)| k != usize::from(l))
                    .map(|(_, a)| u32::from(a.bits))
                    .sum()
            })
    }
}

/// How one joint travels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLayout {
    pub rotation: Rotation,
    pub translation: [Axis; 3],
    pub scale: [Axis; 3],
}

impl JointLayout {
    /// Whether any of its channels changes from frame to frame.
    pub fn is_animated(&self) -> bool {
        matches!(self.rotation, Rotation::Quantised(_))
            || self.translation.iter().chain(&self.scale).any(|a| a.bits > 0)
    }

    /// Bits of one frame's values for this joint.
    pub fn bits(&self) -> u32 {
        let rotation = match self.rotation {
            Rotation::Constant(_) => 0,
            Rotation::Quantised(r) => r.bits(),
        };
        rotation + self.translation.iter().chain(&self.scale).map(|a| u32::from(a.bits)).sum::<u32>()
    }
}

/// A stream's compact layout: the bound it was asked for, the bound its
/// widths guarantee (for poses within its ranges), and each joint's channels.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    pub max_error: f32,
    pub distance: f32,
    /// The computed worst error of any joint or virtual point, metres.
    pub bound: f32,
    pub joints: Vec<JointLayout>,
}

/// One joint's quantised values (zeros in constant channels). Two frames
/// with equal values decode to the same transform.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct QuantisedJoint {
    /// The index (x, y, z, w = 0..3) of the rotation's largest component.
    pub largest: u8,
    pub rotation: [u32; 3],
    pub translation: [u32; 3],
    pub scale: [u32; 3],
}

/// What a stream's poses span, per joint: translation and scale ranges and
/// whether the rotation ever changes. Fed every pose the stream can produce
/// (a clip sampled at its keys and on a dense grid, say).
#[derive(Debug, Clone, PartialEq)]
pub struct Ranges {
    joints: Vec<JointRange>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct JointRange {
    t_min: Vec3A,
    t_max: Vec3A,
    s_min: Vec3A,
    s_max: Vec3A,
    first_rotation: Option<Quat>,
    rotation_varies: bool,
    /// Components of the rotation (sign: largest positive).
    q_min: [f32; 4],
    q_max: [f32; 4],
    /// Bit `k`: component `k` was the largest in some pose.
    largest_seen: u8,
    /// The largest magnitude of any translation or scale value that went
    /// into the ranges (what a derived range's rounding margin scales with).
    magnitude: f32,
}

impl Ranges {
    /// Nothing seen yet, for `joints` joints.
    pub fn new(joints: usize) -> Self {
        let empty = JointRange {
            t_min: Vec3A::INFINITY,
            t_max: Vec3A::NEG_INFINITY,
            s_min: Vec3A::INFINITY,
            s_max: Vec3A::NEG_INFINITY,
            first_rotation: None,
            rotation_varies: false,
            q_min: [f32::INFINITY; 4],
            q_max: [f32::NEG_INFINITY; 4],
            largest_seen: 0,
            magnitude: 0.0,
        };
        Ranges { joints: vec![empty; joints] }
    }

    /// Widens the ranges to hold `pose` (a local pose of as many joints).
    pub fn observe(&mut self, pose: &Pose) {
        for (j, r) in self.joints.iter_mut().enumerate() {
            let (t, s) = (pose.translations[j], pose.scales[j]);
            r.t_min = r.t_min.min(t);
            r.t_max = r.t_max.max(t);
            r.s_min = r.s_min.min(s);
            r.s_max = r.s_max.max(s);
            r.magnitude = r.magnitude.max(t.abs().max(s.abs()).max_element());
            let q = canonical(pose.rotations[j]);
            r.largest_seen |= 1 << largest_component(q).0;
            for (k, c) in q.to_array().into_iter().enumerate() {
                r.q_min[k] = r.q_min[k].min(c);
                r.q_max[k] = r.q_max[k].max(c);
            }
            match r.first_rotation {
                None => r.first_rotation = Some(q),
                Some(first) => r.rotation_varies |= first != q,
            }
        }
    }

    /// The ranges of `clip`'s poses: sampled at every key and `rate` times
    /// a second in between (the grid catches curves bulging between keys;
    /// poses beyond the ranges are clamped).
    pub fn of_clip(clip: &Clip, rate: f32) -> Ranges {
        let mut ranges = Ranges::new(clip.joint_count());
        let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
        let steps = (clip.duration() * rate).ceil().max(1.0) as u32;
        let grid = (0..=steps).map(|i| clip.start() + clip.duration() * i as f32 / steps as f32);
        for t in grid.chain(clip.key_times()) {
            clip.sample_into(t.clamp(clip.start(), clip.end()), &mut cursor, &mut pose);
            ranges.observe(&pose);
        }
        ranges
    }

    /// How many poses [`Ranges::of_clip`] samples at `rate`: what taking
    /// the ranges costs.
    pub fn clip_samples(clip: &Clip, rate: f32) -> u64 {
        let steps = (clip.duration() * rate).ceil().max(1.0) as u64;
        steps + 1 + clip.key_times().count() as u64
    }
}

/// `q` or `-q`, whichever has its largest component positive (the first
/// largest on ties): the sign compact frames send.
fn canonical(q: Quat) -> Quat {
    let (largest, _) = largest_component(q);
    if q.to_array()[largest] < 0.0 { -q } else { q }
}

fn largest_component(q: Quat) -> (usize, f32) {
    let c = q.to_array();
    (0..4).fold((0, c[0].abs()), |(i, m), k| if c[k].abs() > m { (k, c[k].abs()) } else { (i, m) })
}

/// The largest extent of the rest pose's joint positions along any model
/// axis: a character's height whichever way is up.
pub fn rest_height(skeleton: &Skeleton) -> f32 {
    let mut model = Pose::default();
    skeleton.to_model(skeleton.rest(), &mut model);
    let lo = model.translations.iter().fold(Vec3A::INFINITY, |a, &t| a.min(t));
    let hi = model.translations.iter().fold(Vec3A::NEG_INFINITY, |a, &t| a.max(t));
    if model.translations.is_empty() { 0.0 } else { (hi - lo).max_element() }
}

/// The default `distance`: 10 % of the rest height, at least 1 cm.
pub fn default_distance(skeleton: &Skeleton) -> f32 {
    (DISTANCE_OF_REST_HEIGHT * rest_height(skeleton)).max(MIN_DISTANCE)
}

/// What each joint's channels may contribute, and how far its subtree reaches.
struct Reach {
    /// Upper bound of the model scale's largest component, per joint.
    model_scale: Vec<f64>,
    /// Upper bound of the distance from the joint to any point it moves.
    reach: Vec<f64>,
    /// Quantised channels on the longest chain through each joint.
    chain_channels: Vec<u32>,
}

impl Layout {
    /// Chooses widths so that every joint and virtual point of every pose
    /// within `ranges` stays within `max_error` of the f32 pose.
    /// `max_error` and `distance` are taken as given (the caller checks
    /// them against [`MIN_MAX_ERROR`] and [`MIN_DISTANCE`]). When even
    /// [`MAX_BITS`] cannot meet the bound, the widths stop there and
    /// [`Layout::bound`] says what they achieve.
    pub fn choose(skeleton: &Skeleton, ranges: &Ranges, max_error: f32, distance: f32) -> Layout {
        let mut joints: Vec<JointLayout> = ranges.joints.iter().map(unsized_joint).collect();
        let reach = Reach::of(skeleton, &joints, distance);
        let budget = BUDGET_SHARE * f64::from(max_error);
        for (k, joint) in joints.iter_mut().enumerate() {
            let share = budget / f64::from(reach.chain_channels[k].max(1));
            let parent_scale = skeleton.parent(k).map_or(1.0, |p| reach.model_scale[p]);
            size_joint(joint, share, parent_scale, reach.reach[k]);
        }
        let mut layout = Layout { max_error, distance, bound: 0.0, joints };
        layout.bound = layout.computed_bound(skeleton, &reach) as f32;
        layout
    }

    /// The worst error over every chain: each joint's rotation, translation
    /// and scale contributions summed from the root down.
    fn computed_bound(&self, skeleton: &Skeleton, reach: &Reach) -> f64 {
        let mut down_to = vec![0.0f64; self.joints.len()];
        for (k, joint) in self.joints.iter().enumerate() {
            let parent_scale = skeleton.parent(k).map_or(1.0, |p| reach.model_scale[p]);
            let own = rotation_error(&joint.rotation) * reach.reach[k]
                + translation_error(&joint.translation) * parent_scale
                + scale_error(&joint.scale) * reach.reach[k];
            down_to[k] = own + skeleton.parent(k).map_or(0.0, |p| down_to[p]);
        }
        down_to.into_iter().fold(0.0, f64::max)
    }

    /// Total bits of a key frame's values.
    pub fn key_bits(&self) -> u32 {
        self.joints.iter().map(JointLayout::bits).sum()
    }

    /// The quantised values of `pose` (clamped into the ranges) into `out`.
    pub fn quantise(&self, pose: &Pose, out: &mut Vec<QuantisedJoint>) {
        out.clear();
        out.extend(self.joints.iter().enumerate().map(|(j, layout)| {
            let (largest, rotation) = match layout.rotation {
                Rotation::Constant(_) => (0, [0; 3]),
                Rotation::Quantised(r) => quantise_rotation(pose.rotations[j], &r),
            };
            QuantisedJoint {
                largest,
                rotation,
                translation: quantise_axes(&layout.translation, pose.translations[j].into()),
                scale: quantise_axes(&layout.scale, pose.scales[j].into()),
            }
        }));
    }

    /// The pose `values` decode to, into `out` (resized to fit).
    pub fn dequantise(&self, values: &[QuantisedJoint], out: &mut Pose) {
        let n = self.joints.len();
        out.translations.resize(n, Vec3A::ZERO);
        out.rotations.resize(n, Quat::IDENTITY);
        out.scales.resize(n, Vec3A::ONE);
        for (j, (layout, v)) in self.joints.iter().zip(values).enumerate() {
            out.rotations[j] = match layout.rotation {
                Rotation::Constant(q) => q,
                Rotation::Quantised(r) => dequantise_rotation(v.largest, v.rotation, &r),
            };
            out.translations[j] = dequantise_axes(&layout.translation, v.translation);
            out.scales[j] = dequantise_axes(&layout.scale, v.scale);
        }
    }
}

impl Reach {
    fn of(skeleton: &Skeleton, joints: &[JointLayout], distance: f32) -> Reach {
        let n = joints.len();
        let mut model_scale = vec![1.0f64; n];
        let mut channels_to = vec![0u32; n];
        for (k, joint) in joints.iter().enumerate() {
            let local = joint.scale.iter().map(|a| f64::from(a.min.abs().max(a.max.abs()))).fold(0.0, f64::max);
            let parent = skeleton.parent(k);
            model_scale[k] = local * parent.map_or(1.0, |p| model_scale[p]);
            channels_to[k] = quantised_channels(joint) + parent.map_or(0, |p| channels_to[p]);
        }
        let mut reach: Vec<f64> = model_scale.iter().map(|s| f64::from(distance) * s).collect();
        let mut channels_below = vec![0u32; n];
        for k in (0..n).rev() {
            if let Some(p) = skeleton.parent(k) {
                let offset = model_scale[p] * longest_translation(&joints[k].translation);
                reach[p] = reach[p].max(offset + reach[k]);
                channels_below[p] = channels_below[p].max(channels_below[k] + quantised_channels(&joints[k]));
            }
        }
        let chain_channels = (0..n).map(|k| channels_to[k] + channels_below[k]).collect();
        Reach { model_scale, reach, chain_channels }
    }
}

fn quantised_channels(joint: &JointLayout) -> u32 {
    u32::from(matches!(joint.rotation, Rotation::Quantised(_)))
        + u32::from(joint.translation.iter().any(|a| a.min < a.max))
        + u32::from(joint.scale.iter().any(|a| a.min < a.max))
}

fn longest_translation(axes: &[Axis; 3]) -> f64 {
    axes.iter().map(|a| f64::from(a.min.abs().max(a.max.abs())).powi(2)).sum::<f64>().sqrt()
}

/// A joint's ranges with no widths yet (constant channels final).
fn unsized_joint(r: &JointRange) -> JointLayout {
    let axes = |lo: Vec3A, hi: Vec3A, none: f32| {
        std::array::from_fn(|a| {
            let (min, max) = if lo[a] <= hi[a] { (lo[a], hi[a]) } else { (none, none) };
            Axis { min, max, bits: 0 }
        })
    };
    let rotation = match r.first_rotation {
        Some(_) if r.rotation_varies => Rotation::Quantised(smallest_three(r)),
        first => Rotation::Constant(first.unwrap_or(Quat::IDENTITY)),
    };
    JointLayout { rotation, translation: axes(r.t_min, r.t_max, 0.0), scale: axes(r.s_min, r.s_max, 1.0) }
}

/// A rotation whose largest component is always the same one sends the
/// other three within their observed ranges. One whose largest changes
/// sends any three: between two poses on either side of the change, a
/// component can take any value a non-largest component can, `±1/√2`.
fn smallest_three(r: &JointRange) -> SmallestThree {
    if r.largest_seen.count_ones() == 1 {
        let components = std::array::from_fn(|k| Axis { min: r.q_min[k], max: r.q_max[k], bits: 0 });
        SmallestThree { largest: Some(r.largest_seen.trailing_zeros() as u8), components }
    } else {
        let bound = SMALLEST_THREE_RANGE as f32;
        SmallestThree { largest: None, components: [Axis { min: -bound, max: bound, bits: 0 }; 4] }
    }
}

/// Gives each quantised channel of `joint` the fewest bits that keep its
/// contribution within `share`.
fn size_joint(joint: &mut JointLayout, share: f64, parent_scale: f64, reach: f64) {
    if let Rotation::Quantised(r) = &mut joint.rotation {
        size_rotation(r, share / reach);
    }
    let moving = |axes: &[Axis; 3]| axes.iter().filter(|a| a.min < a.max).count().max(1) as f64;
    let per_axis = share / (parent_scale * moving(&joint.translation).sqrt());
    for axis in joint.translation.iter_mut().filter(|a| a.min < a.max) {
        axis.bits = fewest_bits(|b| axis_error(Axis { bits: b, ..*axis }) <= per_axis);
    }
    let smallest = smallest_scale(&joint.scale);
    for axis in joint.scale.iter_mut().filter(|a| a.min < a.max) {
        axis.bits = fewest_bits(|b| axis_error(Axis { bits: b, ..*axis }) / smallest * reach <= share);
    }
}

fn fewest_bits(enough: impl Fn(u8) -> bool) -> u8 {
    (1..=MAX_BITS).find(|&b| enough(b)).unwrap_or(MAX_BITS)
}

fn levels(bits: u8) -> f64 {
    ((1u64 << bits) - 1) as f64
}

/// Gives each changing component the fewest bits that keep the rotation
/// within `angle`: every component's half step at most `e`, the coarsest
/// `e` of the form `(1/√2) / (2^t - 1)` that is enough.
fn size_rotation(r: &mut SmallestThree, angle: f64) {
    for t in 1..=MAX_BITS {
        let e = SMALLEST_THREE_RANGE / levels(t);
        let largest = r.largest.map(usize::from);
        for (_, axis) in r.components.iter_mut().enumerate().filter(|&(k, ref a)| a.min < a.max && Some(k) != largest) {
            let half_step = |b: u8| f64::from(axis.max - axis.min) / (2.0 * levels(b));
            axis.bits = fewest_bits(|b| half_step(b) <= e);
        }
        if rotation_error(&Rotation::Quantised(*r)) <= angle {
            break;
        }
    }
    // The largest component is rebuilt, never sent.
    if let Some(l) = r.largest {
        r.components[usize::from(l)].bits = 0;
    }
    // The common step may leave a component a bit more than it needs.
    for k in 0..4 {
        while r.components[k].bits > 1 {
            let mut fewer = *r;
            fewer.components[k].bits -= 1;
            if rotation_error(&Rotation::Quantised(fewer)) > angle {
                break;
            }
            *r = fewer;
        }
    }
}

/// The largest angle (radians) between a rotation and its decoded form.
///
/// Each sent component `k` is off by at most `eₖ` (half a step plus f32
/// rounding). The largest, `w >= w_min` (at least 1/2, more when it is
/// always the same component), is rebuilt from `s`, the sum of the other
/// three's squares: `|s - s'| <= S = Σ eₖ(2|aₖ| + eₖ)` with `|aₖ|` bounded
/// by its range, and `|w - w'| = |s - s'| / (w + w') <= x` where
/// `x(2 w_min - x) = S`. The chord `|q - q'| <= √(Σ eₖ² + x²)` is
/// `2 sin(φ/2)` for the 4D angle `φ`, and the rotation angle is `2φ`.
fn rotation_error(rotation: &Rotation) -> f64 {
    let Rotation::Quantised(r) = rotation else { return 0.0 };
    let candidates: &[u8] = match &r.largest {
        Some(l) => std::slice::from_ref(l),
        None => &[0, 1, 2, 3],
    };
    let mut worst = 0.0f64;
    for &l in candidates {
        let others = (0..4).filter(|&k| k != usize::from(l)).map(|k| r.components[k]);
        let (mut sum, mut squares) = (0.0, 0.0);
        for axis in others {
            let e = axis_error(axis) + F32_ROUNDING;
            let magnitude = f64::from(axis.min.abs().max(axis.max.abs())).min(SMALLEST_THREE_RANGE);
            sum += e * (2.0 * magnitude + e);
            squares += e * e;
        }
        let w_min = if r.largest.is_some() { f64::from(r.components[usize::from(l)].min).max(0.5) } else { 0.5 };
        if sum >= w_min * w_min {
            return std::f64::consts::PI;
        }
        let x = w_min - (w_min * w_min - sum).sqrt() + F32_ROUNDING;
        let chord = (squares + x * x).sqrt();
        worst = worst.max(4.0 * (chord / 2.0).min(1.0).asin());
    }
    worst
}

/// The largest difference between an axis value and its decoded form:
/// half a step plus the f32 rounding of the result.
fn axis_error(axis: Axis) -> f64 {
    if axis.bits == 0 {
        return 0.0;
    }
    let (lo, hi) = (f64::from(axis.min), f64::from(axis.max));
    (hi - lo) / (2.0 * levels(axis.bits)) + lo.abs().max(hi.abs()) * F32_ROUNDING
}

fn translation_error(axes: &[Axis; 3]) -> f64 {
    axes.iter().map(|&a| axis_error(a).powi(2)).sum::<f64>().sqrt()
}

/// The largest relative error of a scale component: a subtree stretched by
/// it moves each point by at most that share of its distance from the joint.
fn scale_error(axes: &[Axis; 3]) -> f64 {
    let worst = axes.iter().map(|&a| axis_error(a)).fold(0.0, f64::max);
    if worst == 0.0 { 0.0 } else { worst / smallest_scale(axes) }
}

/// The smallest magnitude any scale component can take.
fn smallest_scale(axes: &[Axis; 3]) -> f64 {
    axes.iter()
        .map(|a| if a.min <= 0.0 && a.max >= 0.0 { 0.0 } else { f64::from(a.min.abs().min(a.max.abs())) })
        .fold(f64::INFINITY, f64::min)
}

/// `value`'s step within `[min, max]` at `bits` (clamped; 0 when constant).
pub fn quantise_value(value: f32, axis: Axis) -> u32 {
    if axis.bits == 0 {
        return 0;
    }
    let (lo, hi) = (f64::from(axis.min), f64::from(axis.max));
    let unit = ((f64::from(value) - lo) / (hi - lo)).clamp(0.0, 1.0);
    (unit * levels(axis.bits)).round() as u32
}

/// The value step `u` decodes to: `f32(min + u · (max - min) / (2^bits - 1))`
/// evaluated in f64 in that order (docs/compact-frames.md).
pub fn dequantise_value(u: u32, axis: Axis) -> f32 {
    value_f64(u, axis) as f32
}

/// [`dequantise_value`] before its rounding to f32.
fn value_f64(u: u32, axis: Axis) -> f64 {
    let lo = f64::from(axis.min);
    if axis.bits == 0 {
        return lo;
    }
    lo + f64::from(u) * (f64::from(axis.max) - lo) / levels(axis.bits)
}

fn quantise_axes(axes: &[Axis; 3], v: Vec3) -> [u32; 3] {
    std::array::from_fn(|a| quantise_value(v[a], axes[a]))
}

fn dequantise_axes(axes: &[Axis; 3], u: [u32; 3]) -> Vec3A {
    Vec3A::from_array(std::array::from_fn(|a| dequantise_value(u[a], axes[a])))
}

/// "Smallest three" (see [`SmallestThree`]): the largest component's
/// index, and the other three (in x, y, z, w order) of the sign that makes
/// the largest positive, each quantised in its component's range.
pub fn quantise_rotation(q: Quat, r: &SmallestThree) -> (u8, [u32; 3]) {
    let q = q.normalize();
    let largest = r.largest.map_or_else(|| largest_component(q).0, usize::from);
    // The rebuilt component is positive: choose the sign that makes it so.
    let c = if q.to_array()[largest] < 0.0 { -q } else { q }.to_array();
    let mut out = [0u32; 3];
    for (slot, k) in (0..4).filter(|&k| k != largest).enumerate() {
        out[slot] = quantise_value(c[k], r.components[k]);
    }
    (largest as u8, out)
}

/// The rotation a smallest-three value decodes to (docs/compact-frames.md):
/// each sent component as a value within its range (in f64, not yet
/// rounded), the largest `√(1 - (a² + b² + c²))`, or, when that sum
/// reaches 1, the three divided by its square root and the largest 0;
/// rounded to f32 last.
pub fn dequantise_rotation(largest: u8, values: [u32; 3], r: &SmallestThree) -> Quat {
    let largest = usize::from(largest);
    let mut small = [0.0f64; 3];
    for (slot, k) in (0..4).filter(|&k| k != largest).enumerate() {
        small[slot] = value_f64(values[slot], r.components[k]);
    }
    let sum = small[0] * small[0] + small[1] * small[1] + small[2] * small[2];
    let (small, big) = if sum < 1.0 { (small, (1.0 - sum).sqrt()) } else { (small.map(|c| c / sum.sqrt()), 0.0) };
    let mut c = [0.0f32; 4];
    let mut rest = small.iter();
    for (k, slot) in c.iter_mut().enumerate() {
        *slot = if k == largest { big } else { *rest.next().expect("three components") } as f32;
    }
    Quat::from_array(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rotation angle between two rotations, in f64 from the chord
    /// (acos of a dot product near 1 loses everything).
    fn angle(a: Quat, b: Quat) -> f64 {
        let (a, b) = (a.as_dquat(), b.as_dquat());
        let b = if a.dot(b) < 0.0 { -b } else { b };
        let chord = (a - b).length();
        4.0 * (chord / 2.0).asin()
    }

    /// Full-range components: the worst case for the rebuilt component.
    fn full(bits: u8, largest: Option<u8>) -> SmallestThree {
        let a = Axis { min: -1.0, max: 1.0, bits };
        SmallestThree { largest, components: [a; 4] }
    }

    #[test]
    fn a_rotation_decodes_within_its_stated_angle() {
        for bits in [6u8, 10, 16] {
            let r = full(bits, None);
            let bound = rotation_error(&Rotation::Quantised(r));
            for i in 0..500 {
                let f = i as f32;
                let q = Quat::from_xyzw((f * 0.37).sin(), (f * 1.3).cos(), (f * 0.11).sin(), 0.3 + (f * 0.7).cos())
                    .normalize();
                let (largest, v) = quantise_rotation(q, &r);
                let back = dequantise_rotation(largest, v, &r);
                assert!(angle(q, back) <= bound, "{bits} bits: {} > {bound}", angle(q, back));
            }
        }
    }

    #[test]
    fn the_worst_case_quaternion_stays_within_the_bound() {
        // All four components 1/2: the largest is as small as it gets and
        // the rebuilt one amplifies errors most.
        let r = full(8, None);
        let q = Quat::from_xyzw(0.5, 0.5, 0.5, 0.5);
        let (largest, v) = quantise_rotation(q, &r);
        assert!(angle(q, dequantise_rotation(largest, v, &r)) <= rotation_error(&Rotation::Quantised(r)));
    }

    #[test]
    fn narrow_ranges_need_fewer_bits_for_the_same_angle() {
        // Turns about z by at most 0.3 rad: x and y never change, z stays
        // within ±sin(0.15) and w is always the largest.
        let s = (0.15f32).sin();
        let (zero, w) = (Axis { min: 0.0, max: 0.0, bits: 0 }, Axis { min: 0.98, max: 1.0, bits: 0 });
        let mut narrow =
            SmallestThree { largest: Some(3), components: [zero, zero, Axis { min: -s, max: s, bits: 0 }, w] };
        let mut wide = full(0, None);
        size_rotation(&mut narrow, 1e-4);
        size_rotation(&mut wide, 1e-4);
        assert_eq!(narrow.components.map(|a| a.bits)[..2], [0, 0]);
        assert!(narrow.bits() + 20 < wide.bits(), "{} vs {}", narrow.bits(), wide.bits());
        let q = Quat::from_rotation_z(0.21);
        let (largest, v) = quantise_rotation(q, &narrow);
        assert_eq!(largest, 3);
        assert!(angle(q, dequantise_rotation(largest, v, &narrow)) <= 1e-4);
    }

    #[test]
    fn values_decode_to_the_nearest_grid_step() {
        let axis = Axis { min: -1.0, max: 3.0, bits: 2 };
        // Steps at -1, 1/3, 5/3, 3.
        assert_eq!(quantise_value(0.2, axis), 1);
        assert_eq!(dequantise_value(1, axis), (-1.0f64 + 4.0 / 3.0) as f32);
        assert_eq!(quantise_value(9.0, axis), 3, "clamped");
        assert_eq!(dequantise_value(3, axis), 3.0);
        assert_eq!(dequantise_value(0, Axis { min: 2.5, max: 2.5, bits: 0 }), 2.5);
    }

    #[test]
    fn the_sign_sent_makes_the_largest_component_positive() {
        let r = full(12, None);
        let (largest, v) = quantise_rotation(Quat::from_xyzw(0.1, -0.9, 0.2, 0.1).normalize(), &r);
        assert_eq!(largest, 1);
        let back = dequantise_rotation(largest, v, &r);
        assert!(back.y > 0.0 && back.x < 0.0);
    }
}
