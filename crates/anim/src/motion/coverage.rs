//! Which joints each layer must sample (docs/motion.md, “How a pose is computed”, read top down).
//!
//! A layer changes nothing where its weight times its mask is 0, and a
//! blend layer at weight 1 copies its own value exactly, so nothing beneath
//! it shows through there. A layer therefore samples and layers only the
//! joints it can still change: a wave masked to the upper body samples the
//! upper body, and the walk and run beneath it the rest. The result is the
//! same, bit for bit, as layering every joint of every layer.
//!
//! Sets are bit sets over the output skeleton's joints, `words(n)` words
//! each; what a layer reaches and hides is fixed at build, what it must
//! sample depends on the live weights and is worked out once per sample.

use super::joint_map::UNMAPPED;
use super::spec::LayerMode;

/// Words of a set of `joints` joints.
pub(super) fn words(joints: usize) -> usize {
    joints.div_ceil(64)
}

/// Whether joint `j` is in `set`.
#[inline]
pub(super) fn has(set: &[u64], j: usize) -> bool {
    set[j / 64] >> (j % 64) & 1 != 0
}

/// Adds joint `j` to `set`.
#[inline]
pub(super) fn insert(set: &mut [u64], j: usize) {
    set[j / 64] |= 1 << (j % 64);
}

/// Calls `f` for every joint in `set`, in increasing order.
#[inline]
pub(super) fn for_each(set: &[u64], mut f: impl FnMut(usize)) {
    for (w, &word) in set.iter().enumerate() {
        let mut rest = word;
        while rest != 0 {
            f(w * 64 + rest.trailing_zeros() as usize);
            rest &= rest - 1;
        }
    }
}

/// The set of the output joints `0..n` for which `f` holds.
fn collect(n: usize, f: impl Fn(usize) -> bool) -> Box<[u64]> {
    let mut set = vec![0u64; words(n)];
    for j in (0..n).filter(|&j| f(j)) {
        insert(&mut set, j);
    }
    set.into_boxed_slice()
}

/// What one layer can touch, from its mask and joint map (fixed at build).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Reach {
    /// Output joints the layer changes at any positive weight: mapped, with
    /// a positive mask.
    pub reaches: Box<[u64]>,
    /// Output joints where the layer, at weight 1, hides every layer
    /// beneath: a blend layer's mapped joints with mask 1.
    pub hides: Box<[u64]>,
    /// Whether `reaches` is every joint of the layer's clip (then, with
    /// nothing hidden, the whole clip is sampled).
    pub whole: bool,
}

impl Reach {
    /// `map` (per output joint, the clip's joint) and `mask` (per output
    /// joint) of a layer whose clip has `clip_joints` joints.
    pub fn new(mode: LayerMode, map: &[u32], mask: &[f32], clip_joints: usize) -> Reach {
        let n = map.len();
        let reaches = collect(n, |j| map[j] != UNMAPPED && mask[j] > 0.0);
        let hides = collect(n, |j| mode == LayerMode::Blend && map[j] != UNMAPPED && mask[j] >= 1.0);
        // Names are unique, so reached joints are distinct joints of the clip.
        let whole = reaches.iter().map(|w| w.count_ones() as usize).sum::<usize>() == clip_joints;
        Reach { reaches, hides, whole }
    }
}

/// Each layer's joints to sample at the live `weights`, `words` words per
/// layer, into `needs`; `hidden` is scratch. Top down: a layer needs what
/// it reaches (at a positive weight) and no layer above hides.
pub(super) fn needs<'a>(
    layers: impl DoubleEndedIterator<Item = (LayerMode, &'a Reach)> + ExactSizeIterator,
    weights: &[f32],
    words: usize,
    needs: &mut Vec<u64>,
    hidden: &mut Vec<u64>,
) {
    needs.clear();
    needs.resize(layers.len() * words, 0);
    hidden.clear();
    hidden.resize(words, 0);
    for (i, (mode, reach)) in layers.enumerate().rev() {
        let need = &mut needs[i * words..(i + 1) * words];
        if weights[i] > 0.0 {
            for ((n, r), h) in need.iter_mut().zip(&*reach.reaches).zip(hidden.iter()) {
                *n = r & !h;
            }
        }
        if mode == LayerMode::Blend && weights[i] >= 1.0 {
            for (h, hides) in hidden.iter_mut().zip(&*reach.hides) {
                *h |= hides;
            }
        }
    }
}

/// Cuts each layer's needs (`words` words per layer) to the joints in
/// `only`: a caller that reads only those joints of the pose.
pub(super) fn restrict(needs: &mut [u64], words: usize, only: &[u64]) {
    for need in needs.chunks_exact_mut(words) {
        for (n, o) in need.iter_mut().zip(only) {
            *n &= o;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(n: usize, joints: &[usize]) -> Box<[u64]> {
        collect(n, |j| joints.contains(&j))
    }

    fn members(set: &[u64]) -> Vec<usize> {
        let mut out = Vec::new();
        for_each(set, |j| out.push(j));
        out
    }

    #[test]
    fn sets_hold_their_joints_across_words() {
        let s = set(130, &[0, 63, 64, 129]);
        assert_eq!(s.len(), 3);
        assert_eq!(members(&s), vec![0, 63, 64, 129]);
        assert!(has(&s, 63) && !has(&s, 62) && has(&s, 129));
    }

    #[test]
    fn a_reach_follows_the_mask_the_map_and_the_mode() {
        // Output joints 0..4; the clip has 5 joints, its 4 and 0 are output 0 and 1, output 2 unmapped.
        // It is not whole: its joints 1, 2 and 3 are out of reach.
        let map = [4, 0, UNMAPPED, 1];
        let mask = [1.0, 0.5, 1.0, 0.0];
        let blend = Reach::new(LayerMode::Blend, &map, &mask, 5);
        assert_eq!(members(&blend.reaches), vec![0, 1]);
        assert_eq!(members(&blend.hides), vec![0]);
        assert!(!blend.whole);
        let additive = Reach::new(LayerMode::Additive, &map, &mask, 5);
        assert_eq!(members(&additive.hides), Vec::<usize>::new());
        let all = Reach::new(LayerMode::Blend, &[0, 1], &[1.0, 0.3], 2);
        assert!(all.whole);
    }

    #[test]
    fn a_full_weight_blend_hides_the_layers_beneath_only_where_its_mask_is_one() {
        let n = 4;
        let full = Reach::new(LayerMode::Blend, &[0, 1, 2, 3], &[1.0; 4], 4);
        let upper = Reach::new(LayerMode::Blend, &[0, 1, 2, 3], &[0.0, 0.0, 1.0, 0.5], 4);
        let additive = Reach::new(LayerMode::Additive, &[0, 1, 2, 3], &[1.0; 4], 4);
        let layers = [(LayerMode::Blend, &full), (LayerMode::Blend, &full), (LayerMode::Blend, &upper)];
        let (mut needs_out, mut hidden) = (Vec::new(), Vec::new());
        let mut run = |layers: &[(LayerMode, &Reach)], weights: &[f32]| {
            needs(layers.iter().copied(), weights, words(n), &mut needs_out, &mut hidden);
            needs_out.iter().map(|&w| members(&[w])).collect::<Vec<_>>()
        };
        // The upper layer at weight 1 hides joint 2 (mask 1), not 3 (mask 0.5);
        // the middle one at weight 0.3 hides nothing, so the bottom one needs 0, 1, 3.
        assert_eq!(run(&layers, &[1.0, 0.3, 1.0]), vec![vec![0, 1, 3], vec![0, 1, 3], vec![2, 3]]);
        // At full weight the middle one hides everything beneath it.
        assert_eq!(run(&layers, &[1.0, 1.0, 1.0]), vec![vec![], vec![0, 1, 3], vec![2, 3]]);
        // Weight 0 needs nothing and hides nothing; weight 0.9 hides nothing.
        assert_eq!(run(&layers, &[1.0, 0.0, 0.9]), vec![vec![0, 1, 2, 3], vec![], vec![2, 3]]);
        // An additive layer on top hides nothing.
        let layers = [(LayerMode::Blend, &full), (LayerMode::Additive, &additive)];
        assert_eq!(run(&layers, &[1.0, 1.0]), vec![vec![0, 1, 2, 3], vec![0, 1, 2, 3]]);
    }
}
