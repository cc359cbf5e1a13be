//! The tick schedule: frame `k` is due at `start + k/fps` on the monotonic
//! clock (docs/api.md).
//!
//! Every due instant is computed from its index with integer nanoseconds
//! (`phase + ⌊n·10⁹/fps⌋` after the engine's epoch), never by adding
//! periods, so the schedule cannot drift however long it runs. Ticks sit on
//! a grid shared by every stream of the same rate and phase, which is what
//! lets streams that start on the same grid tick share one playback (see
//! `hub`). The phase, a whole number of milliseconds within one period,
//! spreads unrelated streams over the period: were every 60 fps stream due
//! at the same instant, each tick would be one burst of thousands of frames
//! whose last ones leave milliseconds late. A stream whose task wakes
//! late does not burst to catch up: [`Schedule::next`] jumps to the latest
//! due tick and reports how many it skipped.

use std::time::Duration;

use tokio::time::{Instant, sleep_until};

/// Skipped ticks a stream frame evaluates at most besides its own (docs/api.md,
/// “Work and its price”): a frame woken late evaluates the latest this
/// many of the ticks it skipped when its graph has springs or root motion,
/// or runs this many frames' spring substeps, and only steps the older
/// ones (a graph's transitions; the chains go on from where they were), so
/// a frame's work is bounded however late it wakes. Every tick is evaluated
/// once at most: a second of playback evaluates at most `fps` + this many.
pub const MAX_CATCH_UP: u64 = 4;

/// What a frame woken late does with the ticks it skipped ([`MAX_CATCH_UP`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct CatchUp {
    /// The latest skipped ticks it evaluates.
    pub evaluated: u64,
    /// The last tick it only steps, whose stream time the spring chains
    /// skip to (`None`: it steps none).
    pub skip_to: Option<u64>,
}

impl CatchUp {
    /// Tick `k`'s catch-up of the `skipped` ticks before it: the latest
    /// [`MAX_CATCH_UP`] evaluated when `evaluate` (a playback with springs
    /// or root motion), the older ones stepped; none evaluated otherwise.
    pub(crate) fn of(k: u64, skipped: u64, evaluate: bool) -> Self {
        let evaluated = if evaluate { skipped.min(MAX_CATCH_UP) } else { 0 };
        CatchUp { evaluated, skip_to: (evaluated < skipped).then(|| k - evaluated - 1) }
    }
}

/// The grid of one rate and phase: tick `n` at
/// `epoch + phase_ms·10⁶ + ⌊n·10⁹/fps⌋ ns`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Grid {
    pub epoch: Instant,
    pub fps: u32,
    /// Whole milliseconds, below [`Grid::phases`]`(fps)`.
    pub phase_ms: u32,
}

impl Grid {
    /// How many whole-millisecond phases fit in one period of `fps`
    /// (`⌈1000/fps⌉`: 17 at 60 fps, phases 0..=16 ms).
    pub fn phases(fps: u32) -> u32 {
        formats::wire::grid::phases(fps)
    }

    fn origin(&self) -> Instant {
        self.epoch + Duration::from_millis(u64::from(self.phase_ms))
    }

    /// The instant of grid tick `n`.
    pub fn at(&self, n: u64) -> Instant {
        self.origin() + Duration::from_nanos((u128::from(n) * 1_000_000_000 / u128::from(self.fps)) as u64)
    }

    /// The first grid tick at or after `now`.
    pub fn next_at_or_after(&self, now: Instant) -> u64 {
        let mut n = self.latest_at_or_before(now);
        while self.at(n) < now {
            n += 1;
        }
        n
    }

    /// The last grid tick at or before `now` (0 if `now` is before tick 0).
    pub fn latest_at_or_before(&self, now: Instant) -> u64 {
        let elapsed = now.saturating_duration_since(self.origin()).as_nanos();
        let mut n = (elapsed * u128::from(self.fps) / 1_000_000_000) as u64;
        // Integer rounding in `at` can put the estimate one off either way.
        while n > 0 && self.at(n) > now {
            n -= 1;
        }
        while self.at(n + 1) <= now {
            n += 1;
        }
        n
    }
}

/// A stream's ticks: its tick `k` is grid tick `first + k`.
#[derive(Debug, Clone)]
pub struct Schedule {
    grid: Grid,
    first: u64,
    next: u64,
    /// Wait on the precise tick timer (`ticker`) rather than tokio's.
    precise: bool,
}

/// One tick to produce: its index in the stream, and how many scheduled
/// ticks before it were skipped because the producer woke late.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tick {
    pub k: u64,
    pub skipped: u64,
}

impl Schedule {
    /// A schedule whose tick 0 is grid tick `first` and whose next tick to
    /// produce is `next`.
    pub fn new(grid: Grid, first: u64, next: u64) -> Self {
        Schedule { grid, first, next, precise: false }
    }

    /// Waits on the precise tick timer thread instead of tokio's timer
    /// (which a test's paused clock controls; the precise one it does not).
    #[must_use]
    pub fn precise(self, precise: bool) -> Self {
        Schedule { precise, ..self }
    }

    /// The same schedule (grid, tick 0, timer) with `next` as its next tick.
    #[must_use]
    pub fn resumed_at(&self, next: u64) -> Self {
        Schedule { next, ..self.clone() }
    }

    /// The grid tick of this stream's tick 0.
    pub fn first(&self) -> u64 {
        self.first
    }

    /// The grid this schedule's ticks sit on.
    pub fn grid(&self) -> Grid {
        self.grid
    }

    /// When the next tick is due.
    pub fn due(&self) -> Instant {
        self.grid.at(self.first + self.next)
    }

    /// Waits for the next due tick. If it wakes late, it returns the latest
    /// due tick instead and counts the ones in between as skipped: never a
    /// burst of stale frames. Cancel-safe (nothing changes until it returns).
    pub async fn next(&mut self) -> Tick {
        if self.precise {
            super::ticker::sleep_until(self.due().into_std()).await;
        } else {
            sleep_until(self.due()).await;
        }
        self.take(Instant::now())
    }

    /// The tick to produce at `now` (which must not be before [`Self::due`]).
    fn take(&mut self, now: Instant) -> Tick {
        let latest = self.grid.latest_at_or_before(now).saturating_sub(self.first).max(self.next);
        let tick = Tick { k: latest, skipped: latest - self.next };
        self.next = latest + 1;
        tick
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_late_tick_evaluates_the_latest_four_skipped_and_steps_the_rest() {
        // Tick 20 after 10 skipped (10..=19): 16..=19 evaluated, 10..=15 stepped.
        assert_eq!(CatchUp::of(20, 10, true), CatchUp { evaluated: 4, skip_to: Some(15) });
        assert_eq!(CatchUp::of(20, 4, true), CatchUp { evaluated: 4, skip_to: None });
        assert_eq!(CatchUp::of(20, 2, true), CatchUp { evaluated: 2, skip_to: None });
        assert_eq!(CatchUp::of(20, 10, false), CatchUp { evaluated: 0, skip_to: Some(19) });
        assert_eq!(CatchUp::of(20, 0, false), CatchUp { evaluated: 0, skip_to: None });
        // A first tick late at 5: ticks 0..=4 skipped, 1..=4 evaluated, 0 stepped.
        assert_eq!(CatchUp::of(5, 5, true), CatchUp { evaluated: 4, skip_to: Some(0) });
    }
    use tokio::time::advance;

    fn grid(fps: u32) -> Grid {
        Grid { epoch: Instant::now(), fps, phase_ms: 0 }
    }

    #[test]
    fn due_instants_come_from_the_index_and_never_drift() {
        let g = Grid { epoch: Instant::now(), fps: 60, phase_ms: 0 };
        // 60 fps does not divide 10⁹ ns: summing a rounded period would
        // drift by 40 ns/s; computing from the index keeps tick 60·3600 at
        // exactly one hour.
        assert_eq!(g.at(60 * 3600) - g.epoch, Duration::from_secs(3600));
        assert_eq!(g.at(1) - g.epoch, Duration::from_nanos(16_666_666));
        assert_eq!(g.at(2) - g.epoch, Duration::from_nanos(33_333_333));
        for n in [0, 1, 59, 60, 61, 1_000_003] {
            assert_eq!(g.latest_at_or_before(g.at(n)), n);
            assert_eq!(g.latest_at_or_before(g.at(n + 1) - Duration::from_nanos(1)), n);
            assert_eq!(g.next_at_or_after(g.at(n)), n);
            assert_eq!(g.next_at_or_after(g.at(n) + Duration::from_nanos(1)), n + 1);
        }
    }

    #[test]
    fn phases_shift_the_grid_by_whole_milliseconds_within_one_period() {
        assert_eq!(Grid::phases(60), 17);
        assert_eq!(Grid::phases(50), 20);
        assert_eq!(Grid::phases(240), 5);
        assert_eq!(Grid::phases(1), 1000);
        for fps in [1, 7, 24, 30, 50, 60, 144, 240] {
            let base = Grid { epoch: Instant::now(), fps, phase_ms: 0 };
            let last = Grid { phase_ms: Grid::phases(fps) - 1, ..base };
            // The last phase still falls before the next tick of phase 0.
            assert!(last.at(0) < base.at(1), "{fps} fps");
            assert_eq!(last.at(5) - base.at(5), Duration::from_millis(u64::from(last.phase_ms)));
            for n in [0, 1, 59, 1_000_003] {
                assert_eq!(last.latest_at_or_before(last.at(n)), n);
                assert_eq!(last.latest_at_or_before(last.at(n + 1) - Duration::from_nanos(1)), n);
                assert_eq!(last.next_at_or_after(last.at(n) + Duration::from_nanos(1)), n + 1);
            }
        }
    }

    #[tokio::test(start_paused = true)]
    async fn an_on_time_consumer_gets_every_tick_at_its_instant() {
        let g = grid(30);
        let mut s = Schedule::new(g, 3, 0);
        for k in 0..90 {
            let t = s.next().await;
            assert_eq!(t, Tick { k, skipped: 0 });
            // tokio's timer wheel rounds up to whole milliseconds.
            let late = Instant::now() - g.at(3 + k);
            assert!(late < Duration::from_millis(1), "{late:?}");
        }
    }

    #[tokio::test(start_paused = true)]
    async fn a_late_producer_jumps_to_the_latest_tick_without_a_burst() {
        let g = grid(10);
        let mut s = Schedule::new(g, 0, 0);
        assert_eq!(s.next().await, Tick { k: 0, skipped: 0 });
        // The producer is busy for 0.35 s: ticks 1, 2, 3 fall due meanwhile.
        advance(Duration::from_millis(350)).await;
        assert_eq!(s.next().await, Tick { k: 3, skipped: 2 });
        // No burst: the next tick waits for its own instant (0.4 s).
        let before = Instant::now();
        assert_eq!(s.next().await, Tick { k: 4, skipped: 0 });
        assert!(Instant::now() >= g.at(4));
        assert!(Instant::now() > before);
    }
}
