//! Request time → clip time (docs/clip-format.md, 2.6–2.7): the playback modes, the ease
//! warp, and the rule at the seams.
//!
//! A clip keeps its times in `f32`; requests arrive in `f64`. A request
//! time that rounds (as `f32`) to the clip's start or end *is* that start or
//! end, so a time read back from the clip's summary (`"start": 0.1`, which
//! is not the `f32` 0.1 exactly) never lands a hair before the start, where
//! `loop` would wrap it to the end. In `loop`, a position that rounds to
//! the end is the next cycle's start. Everything else stays in `f64`, so a
//! loop an hour (or 10⁶ s) in is still exact to the microsecond. Key times
//! need no rule of their own: the clip time is rounded to `f32` last, so a
//! request time that rounds to a key is at the key.
//!
//! Every mapping of a request time goes through [`TimeRange`]: sampling
//! ([`Clip::clip_time`](super::Clip::clip_time)) and the stream's event
//! crossing alike, so a frame's pose and its events never disagree at a
//! seam. The work is per request time, never per joint.

use super::spec::{Ease, Playback};

/// A clip's time range as the clip keeps it, and the map from request
/// times into it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeRange {
    start: f32,
    end: f32,
}

impl TimeRange {
    /// The range `[start, end]` (`start <= end`, both finite).
    pub(crate) fn new(start: f32, end: f32) -> Self {
        TimeRange { start, end }
    }

    /// The first key's time.
    pub fn start(self) -> f32 {
        self.start
    }

    /// The last key's time.
    pub fn end(self) -> f32 {
        self.end
    }

    /// `end − start` in `f64`: the loop period every mapping uses.
    pub fn duration(self) -> f64 {
        f64::from(self.end) - f64::from(self.start)
    }

    /// Request time `t` as an offset from the start: exactly 0 or exactly
    /// the duration when `t` rounds to the start or the end, otherwise
    /// `t − start` in full precision.
    #[inline]
    pub fn offset(self, t: f64) -> f64 {
        let rounded = t as f32;
        if rounded == self.start {
            0.0
        } else if rounded == self.end {
            self.duration()
        } else {
            t - f64::from(self.start)
        }
    }

    /// A `loop` offset as `(cycle, position)`: `cycle` whole durations
    /// from the start, then `position ∈ [0, duration)`. A position that
    /// rounds to the end is the next cycle's start.
    #[inline]
    pub fn cycle(self, x: f64) -> (f64, f64) {
        let duration = self.duration();
        let position = x.rem_euclid(duration);
        let cycle = ((x - position) / duration).round();
        if (f64::from(self.start) + position) as f32 >= self.end { (cycle + 1.0, 0.0) } else { (cycle, position) }
    }

    /// The clip time at `position` (0 to the duration) after the ease warp,
    /// rounded to the clip's precision.
    #[inline]
    pub fn at(self, position: f64, ease: Ease) -> f32 {
        let position = match ease {
            Ease::Linear => position,
            _ => {
                let duration = self.duration();
                ease.apply((position / duration).clamp(0.0, 1.0)) * duration
            }
        };
        ((f64::from(self.start) + position) as f32).clamp(self.start, self.end)
    }

    /// Maps request time `t` to clip time (docs/clip-format.md, 2.6–2.7): playback first
    /// (`once` clamps, `loop` wraps, `ping_pong` reflects), then the ease.
    /// A non-finite `t`, or an empty range, maps to the start.
    #[inline]
    pub fn clip_time(self, t: f64, playback: Playback, ease: Ease) -> f32 {
        let duration = self.duration();
        if duration.is_nan() || duration <= 0.0 || !t.is_finite() {
            return self.start;
        }
        let x = self.offset(t);
        let position = match playback {
            Playback::Once => x.clamp(0.0, duration),
            Playback::Loop => self.cycle(x).1,
            Playback::PingPong => {
                let p = x.rem_euclid(2.0 * duration);
                if p > duration { 2.0 * duration - p } else { p }
            }
        };
        self.at(position, ease)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MODES: [Playback; 3] = [Playback::Once, Playback::Loop, Playback::PingPong];
    const EASES: [Ease; 4] = [Ease::Linear, Ease::EaseIn, Ease::EaseOut, Ease::EaseInOut];

    /// Ranges whose ends `f32` cannot hold exactly, with the decimal text
    /// a summary prints for each end (the shortest text that reads back as
    /// the same `f32`), parsed as a request would parse it.
    fn inexact() -> Vec<(TimeRange, f64, f64)> {
        let third = 1.0f32 / 3.0;
        let text = |x: f32| x.to_string().parse::<f64>().unwrap();
        [(0.1f32, 1.3f32), (third, 1.3), (third, 2.0 + third), (-0.7, 0.1)]
            .into_iter()
            .map(|(s, e)| (TimeRange::new(s, e), text(s), text(e)))
            .collect()
    }

    /// The request times that must count as `x` (an `f32` clip time): its
    /// decimal text, its exact value, and values just inside its rounding.
    fn around(x: f32, text: f64) -> [f64; 4] {
        let (bits, m) = (x.abs().to_bits(), x.abs());
        let gap = (f32::from_bits(bits + 1) - m).min(m - f32::from_bits(bits - 1));
        let inside = 0.45 * f64::from(gap);
        [text, f64::from(x), f64::from(x) - inside, f64::from(x) + inside]
    }

    #[test]
    fn a_time_that_rounds_to_the_start_is_the_start_in_every_mode_and_ease() {
        for (range, start, _) in inexact() {
            assert_ne!(start, f64::from(range.start()), "the test needs an inexact start");
            for t in around(range.start(), start) {
                for (playback, ease) in MODES.into_iter().flat_map(|p| EASES.map(|e| (p, e))) {
                    assert_eq!(
                        range.clip_time(t, playback, ease),
                        range.start(),
                        "{range:?} t={t} {playback:?} {ease:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_time_that_rounds_to_the_end_is_the_end_and_loop_wraps_it_to_the_start() {
        for (range, _, end) in inexact() {
            for t in around(range.end(), end) {
                for ease in EASES {
                    let what = format!("{range:?} t={t} {ease:?}");
                    assert_eq!(range.clip_time(t, Playback::Once, ease), range.end(), "{what}");
                    assert_eq!(range.clip_time(t, Playback::PingPong, ease), range.end(), "{what}");
                    assert_eq!(range.clip_time(t, Playback::Loop, ease), range.start(), "{what}");
                }
            }
        }
    }

    #[test]
    fn every_loop_cycle_starts_at_the_start() {
        for (range, _, _) in inexact() {
            let duration = range.duration();
            for cycle in [-3.0, -1.0, 1.0, 2.0, 7.0, 1000.0] {
                // The seam where cycle `cycle` begins, and a hair on either
                // side of it: just before, the position rounds to the end.
                let seam = f64::from(range.start()) + cycle * duration;
                for t in [seam, seam - 1e-12, seam + 1e-12] {
                    assert_eq!(range.clip_time(t, Playback::Loop, Ease::Linear), range.start(), "{range:?} t={t}");
                }
                let (c, p) = range.cycle(range.offset(seam - 1e-12));
                assert_eq!((c, p), (cycle, 0.0), "{range:?}: the seam opens the next cycle");
            }
        }
    }

    #[test]
    fn ping_pong_turns_at_both_ends_in_later_cycles() {
        let range = TimeRange::new(0.1, 1.3);
        let d = range.duration();
        for k in 1..5 {
            let expected = if k % 2 == 1 { range.end() } else { range.start() };
            let t = 0.1 + f64::from(k) * d;
            assert_eq!(range.clip_time(t, Playback::PingPong, Ease::Linear), expected, "turn {k}");
        }
    }

    #[test]
    fn away_from_the_seams_time_keeps_f64_precision() {
        // Exact ends, so the expected clip time is worked out by hand:
        // t = 10⁶ + 0.25 + δ is offset 999 999.75 + δ = 666 666·1.5 + 0.75 + δ
        // from the start 0.5, so clip time 1.25 + δ.
        let range = TimeRange::new(0.5, 2.0);
        for micros in [0.0, 1e-6, 7e-6, 0.25] {
            let t = 1.0e6 + 0.25 + micros;
            let expected = 1.25 + micros;
            let got = f64::from(range.clip_time(t, Playback::Loop, Ease::Linear));
            assert!((got - expected).abs() < 0.5e-6, "t={t}: {got} vs {expected}");
        }
        // Ping-pong: t = 10⁶ + 1 + δ is offset 333 333·3 + 1.5 + δ, δ into a
        // backward half, so clip time 2 − δ.
        let got = f64::from(range.clip_time(1.0e6 + 1.0 + 3e-6, Playback::PingPong, Ease::Linear));
        assert!((got - (2.0 - 3e-6)).abs() < 0.5e-6, "{got}");
        // Inexact ends: the period is the f64 difference of the f32 ends.
        let range = TimeRange::new(0.1, 1.3);
        let (start, d) = (f64::from(range.start()), range.duration());
        let t = start + 833_333.0 * d + 0.5;
        let got = f64::from(range.clip_time(t, Playback::Loop, Ease::Linear));
        assert!((got - (start + 0.5)).abs() < 1e-6, "{got}");
    }

    #[test]
    fn times_inside_the_range_round_like_the_clip() {
        // A request time that rounds to a key time maps to that key.
        let range = TimeRange::new(0.1, 1.3);
        for key in [0.7f32, 0.2, 1.2999998] {
            assert!(key < range.end());
            for t in around(key, key.to_string().parse().unwrap()) {
                for playback in MODES {
                    assert_eq!(range.clip_time(t, playback, Ease::Linear), key, "t={t} {playback:?}");
                }
            }
        }
    }

    #[test]
    fn empty_ranges_and_bad_times_map_to_the_start() {
        let range = TimeRange::new(0.1, 0.1);
        assert_eq!(range.clip_time(5.0, Playback::Loop, Ease::Linear), 0.1);
        let range = TimeRange::new(0.1, 1.3);
        assert_eq!(range.clip_time(f64::NAN, Playback::Loop, Ease::Linear), 0.1);
        assert_eq!(range.clip_time(f64::INFINITY, Playback::Once, Ease::Linear), 0.1);
    }
}
