//! Clock sync with the server, and the server's tick grid in wall-clock time.
//!
//! `Ping` returns the server's wall clock and its monotonic clock (ns since
//! its streaming engine started). From a few pings the load generator takes
//! the one with the shortest round trip (the least queueing, so the best
//! bound on when the server read its clocks) and assumes the server read
//! them half-way through it (the NTP estimate; on loopback the error is a
//! few µs). That gives
//! - the offset server − local wall clock, to put receive times on the
//!   server's clock, and
//! - the wall-clock instant of the engine's epoch, on which every stream's
//!   ticks sit: grid tick `n` of rate `fps` is due at `epoch + ⌊n·10⁹/fps⌋`
//!   ns (docs/api.md, `stream::schedule`), so a frame's due time is known exactly
//!   once its grid tick is.

use serde::Serialize;

/// One `Ping` exchange, all times in ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PingSample {
    /// Local wall clock just before the request was sent.
    pub local_sent: i64,
    /// Local wall clock just after the reply arrived.
    pub local_received: i64,
    pub server_unix: i64,
    pub server_monotonic: u64,
}

/// The estimate from the best ping.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct ClockSync {
    /// Server wall clock minus local wall clock, ns.
    pub offset_ns: i64,
    /// The round trip of the ping used, ns (the estimate's error is at most half of it).
    pub rtt_ns: i64,
    /// The server's wall clock at its engine's epoch (monotonic 0), ns.
    pub grid_epoch_unix_ns: i64,
}

impl ClockSync {
    /// The estimate from the sample with the shortest round trip; `None`
    /// for no samples.
    pub fn from_samples(samples: &[PingSample]) -> Option<ClockSync> {
        let best = samples.iter().min_by_key(|s| s.local_received - s.local_sent)?;
        let rtt = best.local_received - best.local_sent;
        let midpoint = best.local_sent + rtt / 2;
        Some(ClockSync {
            offset_ns: best.server_unix - midpoint,
            rtt_ns: rtt,
            grid_epoch_unix_ns: best.server_unix - i64::try_from(best.server_monotonic).unwrap_or(i64::MAX),
        })
    }

    /// A local wall-clock time on the server's wall clock.
    pub fn to_server(self, local_unix_ns: i64) -> i64 {
        local_unix_ns + self.offset_ns
    }

    /// The server wall-clock time at which grid tick `n` of rate `fps` and
    /// phase `phase_ms` is due.
    pub fn due(&self, fps: u32, phase_ms: u32, n: u64) -> i64 {
        self.grid_epoch_unix_ns
            + i64::from(phase_ms) * 1_000_000
            + (u128::from(n) * 1_000_000_000 / u128::from(fps)) as i64
    }

    /// The last grid tick of rate `fps` and phase `phase_ms` due at or
    /// before server time `t` (0 before tick 0).
    pub fn tick_at_or_before(&self, fps: u32, phase_ms: u32, t: i64) -> u64 {
        let origin = self.grid_epoch_unix_ns + i64::from(phase_ms) * 1_000_000;
        let elapsed = u128::try_from(t - origin).unwrap_or(0);
        let mut n = (elapsed * u128::from(fps) / 1_000_000_000) as u64;
        // Integer rounding in `due` can put the estimate one off either way.
        while n > 0 && self.due(fps, phase_ms, n) > t {
            n -= 1;
        }
        while self.due(fps, phase_ms, n + 1) <= t {
            n += 1;
        }
        n
    }
}

/// Local wall clock, ns since the Unix epoch.
pub fn unix_now_ns() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shortest_round_trip_wins_and_its_midpoint_is_the_server_read() {
        // The server clock is local + 5 ms; its engine started 100 s before unix 1_000 s.
        let sample = |sent: i64, rtt: i64| PingSample {
            local_sent: sent,
            local_received: sent + rtt,
            server_unix: sent + rtt / 2 + 5_000_000,
            server_monotonic: (sent + rtt / 2 + 5_000_000 - 900_000_000_000) as u64,
        };
        let sync = ClockSync::from_samples(&[
            sample(1_000_000_000_000, 900_000),
            sample(1_000_100_000_000, 40_000),
            sample(1_000_200_000_000, 70_000),
        ])
        .unwrap();
        assert_eq!(sync.rtt_ns, 40_000);
        assert_eq!(sync.offset_ns, 5_000_000);
        assert_eq!(sync.grid_epoch_unix_ns, 900_000_000_000);
        assert_eq!(sync.to_server(1), 5_000_001);
        assert_eq!(ClockSync::from_samples(&[]), None);
    }

    #[test]
    fn grid_ticks_are_floor_of_n_billion_over_fps() {
        let sync = ClockSync { offset_ns: 0, rtt_ns: 0, grid_epoch_unix_ns: 1_000 };
        // 60 fps: tick 1 at 16_666_666 ns, tick 3 at exactly 50 ms.
        assert_eq!(sync.due(60, 0, 1), 1_000 + 16_666_666);
        assert_eq!(sync.due(60, 0, 3), 1_000 + 50_000_000);
        assert_eq!(sync.tick_at_or_before(60, 0, 1_000 + 50_000_000), 3);
        assert_eq!(sync.tick_at_or_before(60, 0, 1_000 + 49_999_999), 2);
        assert_eq!(sync.tick_at_or_before(60, 0, 0), 0);
        // Far from the epoch (a day at 240 fps) the estimate stays exact.
        let day = 86_400_000_000_000i64;
        let n = sync.tick_at_or_before(240, 0, 1_000 + day + 1);
        assert_eq!(n, 86_400 * 240);
        // A phase shifts every tick by whole milliseconds.
        assert_eq!(sync.due(60, 7, 3), 1_000 + 7_000_000 + 50_000_000);
        assert_eq!(sync.tick_at_or_before(60, 7, 1_000 + 57_000_000), 3);
        assert_eq!(sync.tick_at_or_before(60, 7, 1_000 + 56_999_999), 2);
    }
}
