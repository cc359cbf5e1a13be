//! Key times and the search for the segment that holds a time.
//!
//! Tracks whose key times are identical share one [`Timeline`] (glTF
//! samplers often share inputs; every BVH channel shares the frame times),
//! so a pose does one search per distinct timeline rather than per track.
//! The search is O(1) for forward playback (the caller's hint is the last
//! segment; it and the next are tried without a branch, the last segment
//! by one check), O(1) for uniformly spaced
//! keys (the index is computed, then checked), a bucket index for long
//! irregular ones (constant-speed arc tables, hand-timed keys), and a binary
//! search otherwise.

/// Strictly increasing key times, with each segment's reciprocal length.
#[derive(Debug, Clone, PartialEq)]
pub struct Timeline {
    /// `[t_i, 1/(t_{i+1} − t_i)]` per key (0 for the last), so the common
    /// case reads one pair and the next key's time.
    keys: Box<[[f32; 2]]>,
    /// `(t0, 1/h)` when every key sits at `t0 + i·h` to within f32 rounding.
    uniform: Option<(f32, f32)>,
    /// Otherwise, with many keys: `(t0, 1/w, first)` where `first[b]` is the
    /// segment holding `t0 + b·w` (one bucket per key), so a search starts at
    /// most a few keys away instead of bisecting the whole array.
    buckets: Option<(f32, f32, Box<[u32]>)>,
}

/// Below this many keys a binary search is as quick as a bucket lookup.
const BUCKET_MIN_KEYS: usize = 64;
/// Keys walked from a bucket's first segment before bisecting the bucket.
const BUCKET_WALK: usize = 8;

/// `1/h`, saturated at `f32::MAX`: a subnormal gap (keys 1e-45 s apart,
/// which a BVH `Frame Time` can give) has an infinite reciprocal, and
/// `(t − t_i)·∞` is NaN at `t = t_i`. Saturated, `u` stays in `[0, 1]`.
fn reciprocal(h: f32) -> f32 {
    (1.0 / h).min(f32::MAX)
}

/// Where a time falls: segment `index` (keys `index` and `index + 1`) at
/// parameter `u ∈ [0, 1]`. A single-key timeline always gives `(0, 0)`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Span {
    pub index: u32,
    pub u: f32,
}

impl Timeline {
    /// `times` must be non-empty and strictly increasing (checked by the
    /// caller, `Clip::build`).
    pub(crate) fn new(times: &[f32]) -> Self {
        debug_assert!(!times.is_empty());
        debug_assert!(times.windows(2).all(|w| w[0] < w[1]));
        let keys = times
            .iter()
            .enumerate()
            .map(|(i, &t)| [t, times.get(i + 1).map_or(0.0, |&next| reciprocal(next - t))])
            .collect();
        let uniform = Self::detect_uniform(times);
        let buckets = if uniform.is_none() && times.len() >= BUCKET_MIN_KEYS { Self::buckets(times) } else { None };
        Timeline { keys, uniform, buckets }
    }

    fn buckets(times: &[f32]) -> Option<(f32, f32, Box<[u32]>)> {
        let n = times.len();
        let span = times[n - 1] as f64 - times[0] as f64;
        let inv_w = (n as f64 / span) as f32;
        if !inv_w.is_finite() || inv_w <= 0.0 {
            return None;
        }
        // first[b] = the last key at or before the bucket's start, computed
        // with the same f32 arithmetic the lookup uses.
        let first = (0..n)
            .map(|b| {
                let start = times[0] + b as f32 / inv_w;
                (times.partition_point(|&k| k <= start).max(1) - 1).min(n - 2) as u32
            })
            .collect();
        Some((times[0], inv_w, first))
    }

    fn detect_uniform(times: &[f32]) -> Option<(f32, f32)> {
        let n = times.len();
        if n < 3 {
            return None;
        }
        let t0 = times[0] as f64;
        let h = (times[n - 1] as f64 - t0) / (n - 1) as f64;
        let tolerance = 1e-3 * h;
        let uniform = times.iter().enumerate().all(|(i, &t)| (t as f64 - (t0 + i as f64 * h)).abs() <= tolerance);
        uniform.then_some((times[0], reciprocal(h as f32)))
    }

    /// The number of keys.
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    /// Bytes of its key table and bucket index.
    pub fn heap_bytes(&self) -> usize {
        std::mem::size_of_val(&*self.keys) + self.buckets.as_ref().map_or(0, |(_, _, b)| std::mem::size_of_val(&**b))
    }

    /// Whether it has no keys.
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// The time of key `i`.
    ///
    /// # Panics
    /// If there is no key `i`.
    pub fn time(&self, i: usize) -> f32 {
        self.keys[i][0]
    }

    /// The first key's time.
    ///
    /// # Panics
    /// On an empty timeline.
    pub fn first(&self) -> f32 {
        self.keys[0][0]
    }

    /// The last key's time.
    ///
    /// # Panics
    /// On an empty timeline.
    pub fn last(&self) -> f32 {
        self.keys[self.keys.len() - 1][0]
    }

    /// The segment holding `t`, clamped outside the keys (docs/clip-format.md,
    /// “Evaluation math”: a track holds its end values; at `t = t_n` the last
    /// segment with `u = 1`). `hint` is the caller's last answer and is
    /// updated.
    #[inline]
    pub fn locate(&self, t: f32, hint: &mut u32) -> Span {
        let keys = &*self.keys;
        let i = *hint as usize;
        // Forward playback stays in the hinted segment or moves to the next
        // one. Which of the two is data, not a branch (a key passed every
        // few samples on every track would mispredict), then one check that
        // nearly always holds; anything else is a search.
        if i + 2 < keys.len() {
            let j = i + usize::from(t >= keys[i + 1][0]);
            let [a, inv_h] = keys[j];
            if a <= t && t < keys[j + 1][0] {
                *hint = j as u32;
                // t ≥ a makes (t − a) ≥ 0 exactly; rounding can only overshoot 1.
                return Span { index: j as u32, u: ((t - a) * inv_h).min(1.0) };
            }
        }
        self.locate_slow(t, hint)
    }

    #[inline(never)]
    fn locate_slow(&self, t: f32, hint: &mut u32) -> Span {
        let keys = &*self.keys;
        let n = keys.len();
        if n < 2 || t.is_nan() || t <= keys[0][0] {
            *hint = 0;
            return Span { index: 0, u: 0.0 };
        }
        let last = n - 2;
        if t >= keys[n - 1][0] {
            *hint = last as u32;
            return Span { index: last as u32, u: 1.0 };
        }
        // Here keys[0] < t < keys[n-1], so some i in 0..=last holds it.
        // `locate` has tried the hinted segment and the next one unless the
        // hint is the last segment (or past it), which holds t if it starts
        // at or before it.
        let i = if *hint as usize >= last && keys[last][0] <= t {
            last
        } else if let Some((t0, inv_h)) = self.uniform {
            let mut j = (((t - t0) * inv_h) as usize).min(last);
            while j > 0 && t < keys[j][0] {
                j -= 1;
            }
            while j < last && t >= keys[j + 1][0] {
                j += 1;
            }
            j
        } else if let Some((t0, inv_w, first)) = &self.buckets {
            // Start at the bucket's first segment (at or before t); walk a
            // few keys, else bisect up to the next bucket's start.
            let b = (((t - t0) * inv_w) as usize).min(first.len() - 1);
            let mut j = (first[b] as usize).min(last);
            while j > 0 && t < keys[j][0] {
                j -= 1;
            }
            let mut walked = 0;
            while j < last && t >= keys[j + 1][0] && walked < BUCKET_WALK {
                j += 1;
                walked += 1;
            }
            if j < last && t >= keys[j + 1][0] { j + keys[j..].partition_point(|k| k[0] <= t) - 1 } else { j }
        } else {
            keys.partition_point(|k| k[0] <= t) - 1
        };
        *hint = i as u32;
        Span { index: i as u32, u: ((t - keys[i][0]) * keys[i][1]).clamp(0.0, 1.0) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(times: &[f32], t: f32, hint: u32, expect: (u32, f32)) {
        let tl = Timeline::new(times);
        let mut h = hint;
        let span = tl.locate(t, &mut h);
        assert_eq!(span.index, expect.0, "index for t={t}");
        assert!((span.u - expect.1).abs() < 1e-5, "u for t={t}: {} vs {}", span.u, expect.1);
        assert_eq!(h, span.index);
    }

    #[test]
    fn every_search_path_finds_the_same_segment() {
        let irregular = [0.0, 0.5, 2.0, 2.5, 4.0];
        let uniform: Vec<f32> = (0..50).map(|i| i as f32 / 24.0).collect();
        // Long and irregular (bucketed): clustered keys, then sparse ones.
        let mut bucketed: Vec<f32> = (0..60).map(|i| i as f32 * 0.001).collect();
        bucketed.extend((1..90).map(|i| 0.06 + (i as f32).powf(1.7) * 0.01));
        for times in [&irregular[..], &uniform[..], &bucketed[..]] {
            let n = times.len();
            for k in 0..n - 1 {
                let t = 0.25 * times[k] + 0.75 * times[k + 1];
                for hint in [0, k as u32, (k as u32).saturating_sub(1), (n - 2) as u32, 999] {
                    check(times, t, hint, (k as u32, 0.75));
                }
                check(times, times[k], 7, (k as u32, 0.0));
            }
        }
    }

    /// Playback forward at several rates, backward and by jumps, over
    /// irregular keys: every span is the one a plain binary search gives,
    /// bit for bit, whatever the hint left by the previous time.
    #[test]
    fn a_hinted_walk_finds_what_a_plain_search_finds() {
        let mut x = 0x2545_f491_u32;
        let mut rand = move || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as f32 / u32::MAX as f32
        };
        let mut times = vec![0.0f32];
        for _ in 0..40 {
            let last = *times.last().unwrap();
            times.push(last + 0.005 + 0.2 * rand());
        }
        let tl = Timeline::new(&times);
        let (first, last) = (times[0], *times.last().unwrap());
        let plain = |t: f32| -> (u32, f32) {
            if t.is_nan() || t <= first {
                return (0, 0.0);
            }
            if t >= last {
                return ((times.len() - 2) as u32, 1.0);
            }
            let i = times.partition_point(|&k| k <= t) - 1;
            (i as u32, ((t - times[i]) * tl.keys[i][1]).clamp(0.0, 1.0))
        };
        let mut hint = 0;
        for step in [1.0 / 240.0, 1.0 / 60.0, 1.0 / 24.0, 0.3, -1.0 / 60.0] {
            let mut t = if step > 0.0 { first - 0.1 } else { last + 0.1 };
            for _ in 0..2000 {
                let t_jump = match rand() {
                    r if r < 0.02 => first + (last - first) * rand(),
                    r if r < 0.04 => times[(rand() * (times.len() - 1) as f32) as usize],
                    _ => t,
                };
                let span = tl.locate(t_jump, &mut hint);
                let (i, u) = plain(t_jump);
                assert_eq!((span.index, span.u.to_bits()), (i, u.to_bits()), "t={t_jump}");
                assert_eq!(hint, span.index);
                t += step;
            }
        }
    }

    #[test]
    fn clamps_outside_and_at_the_last_key() {
        let times = [1.0, 2.0, 4.0];
        check(&times, -5.0, 1, (0, 0.0));
        check(&times, 4.0, 0, (1, 1.0));
        check(&times, 9.0, 0, (1, 1.0));
        check(&[3.0], 9.0, 0, (0, 0.0));
    }
}
