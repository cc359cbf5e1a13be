//! Per-frame lateness of a stream, from what each frame says about itself.
//!
//! A frame carries its `seq` (tick index in the stream), the server's
//! `sent_at` (wall clock) and `dropped`. Frame `seq` is grid tick
//! `first + seq`, due at a known instant (see `clock`), so
//! - *send lateness* = `sent_at − due`: how late the server produced it;
//! - *receive lateness* = `received (on the server clock) − due`: what the
//!   viewer experiences, transport and client scheduling included;
//! - *inter-arrival jitter* = |Δreceived − Δseq/fps| between consecutive
//!   frames;
//! - *gaps*: ticks missing between consecutive frames (the server's own
//!   `dropped` should account for every one).
//!
//! The stream's grid phase (whole ms, `stream::PHASE_HEADER`) comes with
//! the response headers; a server that does not send it is assumed to put
//! the stream on the phase that the frames themselves suggest (below, with
//! the phase as the finer digit of the anchor), which is exact as long as
//! some frame of the stream left within 1 ms of its due time.
//!
//! `first` is not sent; it is recovered from the frames. The server wakes
//! for a tick no earlier than it is due and, if it wakes a tick late, skips
//! to the latest due tick, so `sent_at` lies in [due(first+seq),
//! due(first+seq+1)) unless sampling and encoding crossed the next tick.
//! Hence `first` = min over frames of (last tick due at or before `sent_at`)
//! − `seq`, which the tracker keeps as frames come (a frame that lowers it
//! means earlier frames were reported one period early; that needs a frame
//! that crossed a tick while being encoded to arrive first, and is counted
//! in `reanchors`).

use super::clock::ClockSync;

/// What one frame measured, in ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Observation {
    pub send_late_ns: i64,
    pub receive_late_ns: i64,
    /// Ticks missing since the previous frame (0 for the first frame).
    pub gap: u64,
    /// |Δreceived − Δseq/fps| since the previous frame, if there was one.
    pub jitter_ns: Option<i64>,
}

/// The state of one stream's frames.
#[derive(Debug, Clone)]
pub struct StreamTracker {
    clock: ClockSync,
    fps: u32,
    /// The phase the server announced, if it did.
    phase_ms: Option<u32>,
    /// The stream's first grid tick and phase (ordered as one number).
    first: Option<(u64, u32)>,
    prev: Option<(u64, i64)>,
    pub reanchors: u64,
}

impl StreamTracker {
    pub fn new(clock: ClockSync, fps: u32, phase_ms: Option<u32>) -> Self {
        StreamTracker { clock, fps, phase_ms, first: None, prev: None, reanchors: 0 }
    }

    /// The latest (first tick, phase) under which frame `seq` would have
    /// been due at or before `sent_at`.
    fn candidate(&self, seq: u64, sent_at: i64) -> (u64, u32) {
        match self.phase_ms {
            Some(p) => (self.clock.tick_at_or_before(self.fps, p, sent_at).saturating_sub(seq), p),
            None => {
                let n = self.clock.tick_at_or_before(self.fps, 0, sent_at);
                let into = (sent_at - self.clock.due(self.fps, 0, n)).max(0) / 1_000_000;
                let phases = i64::from(formats::wire::grid::phases(self.fps));
                (n.saturating_sub(seq), into.min(phases - 1) as u32)
            }
        }
    }

    /// Takes one frame: its `seq`, the server's `sent_at` and the local
    /// wall-clock time it was received.
    pub fn observe(&mut self, seq: u64, sent_at: i64, received_local: i64) -> Observation {
        let candidate = self.candidate(seq, sent_at);
        let (first, phase) = match self.first {
            Some(f) if candidate < f => {
                self.reanchors += 1;
                candidate
            }
            Some(f) => f,
            None => candidate,
        };
        self.first = Some((first, phase));
        let due_of = |s: u64| self.clock.due(self.fps, phase, first + s);
        let due = due_of(seq);
        let received = self.clock.to_server(received_local);
        let (gap, jitter_ns) = match self.prev {
            Some((prev_seq, prev_received)) if seq > prev_seq => {
                let expected = due_of(seq) - due_of(prev_seq);
                (seq - prev_seq - 1, Some(((received - prev_received) - expected).abs()))
            }
            _ => (0, None),
        };
        self.prev = Some((seq, received));
        Observation { send_late_ns: sent_at - due, receive_late_ns: received - due, gap, jitter_ns }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const EPOCH: i64 = 1_700_000_000_000_000_000;

    fn tracker(offset_ns: i64) -> StreamTracker {
        StreamTracker::new(ClockSync { offset_ns, rtt_ns: 0, grid_epoch_unix_ns: EPOCH }, 50, Some(0))
    }

    /// Grid tick n of 50 fps is due at EPOCH + n·20 ms.
    fn due(n: u64) -> i64 {
        EPOCH + n as i64 * 20_000_000
    }

    #[test]
    fn lateness_is_measured_from_the_grid_tick_of_each_seq() {
        // The stream's frame 0 is grid tick 1000; each frame is sent 300 µs
        // late and received 200 µs after that; the client clock is 1 ms behind.
        let mut t = tracker(1_000_000);
        for seq in 0..5u64 {
            let sent = due(1000 + seq) + 300_000;
            let o = t.observe(seq, sent, sent + 200_000 - 1_000_000);
            assert_eq!(o.send_late_ns, 300_000);
            assert_eq!(o.receive_late_ns, 500_000);
            assert_eq!(o.gap, 0);
            assert_eq!(o.jitter_ns, if seq == 0 { None } else { Some(0) });
        }
    }

    #[test]
    fn gaps_and_jitter_follow_seq_and_arrival() {
        let mut t = tracker(0);
        t.observe(0, due(7) + 100, due(7) + 1_000);
        // seq 1 and 2 lost; seq 3 arrives 2 ms later than its spacing says.
        let o = t.observe(3, due(10) + 100, due(10) + 3_000_000);
        assert_eq!(o.gap, 2);
        assert_eq!(o.jitter_ns, Some(3_000_000 - 1_000));
        assert_eq!(o.receive_late_ns, 3_000_000);
    }

    #[test]
    fn a_frame_that_crossed_a_tick_while_encoding_is_corrected_by_later_frames() {
        let mut t = tracker(0);
        // Frame 0 of grid tick 500 was encoded so slowly it was stamped after tick 501 was due.
        let o0 = t.observe(0, due(501) + 10, due(501) + 20);
        assert_eq!(o0.send_late_ns, 10, "first guess: tick 501");
        let o1 = t.observe(1, due(501) + 50_000, due(501) + 60_000);
        assert_eq!(t.reanchors, 1);
        assert_eq!(o1.send_late_ns, 50_000);
        let o2 = t.observe(2, due(502) + 40_000, due(502) + 45_000);
        assert_eq!(o2.send_late_ns, 40_000);
        assert_eq!(t.reanchors, 1);
    }

    #[test]
    fn an_announced_phase_shifts_every_due_time() {
        let mut t = StreamTracker::new(ClockSync { offset_ns: 0, rtt_ns: 0, grid_epoch_unix_ns: EPOCH }, 50, Some(13));
        // 1.5 ms late on a 13 ms phase: still 1.5 ms, not 14.5 ms.
        for seq in 0..3u64 {
            let sent = due(40 + seq) + 13_000_000 + 1_500_000;
            assert_eq!(t.observe(seq, sent, sent).send_late_ns, 1_500_000);
        }
    }

    #[test]
    fn an_unannounced_phase_is_recovered_from_the_most_punctual_frame() {
        let mut t = StreamTracker::new(ClockSync { offset_ns: 0, rtt_ns: 0, grid_epoch_unix_ns: EPOCH }, 50, None);
        // Phase 6 ms; frame 0 left 3.2 ms late (looks like phase 9), frame 1 only 0.3 ms late.
        let o0 = t.observe(0, due(40) + 6_000_000 + 3_200_000, due(40) + 9_300_000);
        assert_eq!(o0.send_late_ns, 200_000, "first guess: phase 9");
        let o1 = t.observe(1, due(41) + 6_000_000 + 300_000, due(41) + 6_400_000);
        assert_eq!(t.reanchors, 1);
        assert_eq!(o1.send_late_ns, 300_000);
        let o2 = t.observe(2, due(42) + 6_000_000 + 1_800_000, due(42) + 8_000_000);
        assert_eq!(o2.send_late_ns, 1_800_000, "anchored on phase 6 now");
    }
}
