//! The stream tick grid as clients see it: which header carries a stream's
//! phase, and how many phases one period of a rate holds. A client that
//! measures lateness needs both; the server's scheduler (`stream::schedule`)
//! places its ticks by the same rule.

/// The response header (WebSocket upgrade) and gRPC response metadata key
/// that tells a stream's client the phase of its grid, in whole ms: frame
/// `seq` is due `phase + ⌊(first + seq)·10⁹/fps⌋` ns after the engine's
/// epoch (`Ping`'s monotonic clock), for the stream's first grid tick
/// `first`.
pub const PHASE_HEADER: &str = "inbetween-grid-phase-ms";

/// How many whole-millisecond phases fit in one period of `fps`
/// (`⌈1000/fps⌉`: 17 at 60 fps, phases 0..=16 ms).
///
/// ```
/// assert_eq!(inbetween_formats::wire::grid::phases(60), 17);
/// assert_eq!(inbetween_formats::wire::grid::phases(1), 1000);
/// ```
pub fn phases(fps: u32) -> u32 {
    1000u32.div_ceil(fps.max(1))
}
