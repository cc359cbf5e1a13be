//! Which clip events a frame delivers: the ones the clip time passed since
//! the previous frame (docs/api.md), in the order they were crossed.
//!
//! A playhead moves in request time; the clip time follows it through the
//! playback mode (docs/clip-format.md §2.7) and the ease. Between two frames the request
//! time moves in a straight line, so the clip time sweeps a few monotonic
//! pieces: one for `once` (clamped), one per cycle for `loop` (jumping from
//! the end back to the start, or the other way when playing backwards), one
//! per half-period for `ping_pong` (turning at the ends). Ease is monotonic,
//! so an event lies on a piece exactly when its time lies between the clip
//! times of the piece's ends.
//!
//! Each piece includes its far end and excludes its near end when the near
//! end continues the previous piece (a ping-pong turn, or the previous
//! frame's own position): an event exactly at a frame's clip time is
//! delivered with that frame and not again with the next. A loop's jump
//! includes both ends, so events at the clip's first and last instants both
//! fire once per cycle. A frame with no predecessor (the first, or the first
//! after a seek) delivers only the events exactly at its clip time. Events
//! outside the clip's range are never reached. A frame delivers at most
//! [`MAX_EVENTS_PER_FRAME`] events (a tiny looping clip played very fast
//! would otherwise repeat its events without bound); beyond that the
//! earliest crossed are kept.

use anim::{Clip, Ease, Playback};

/// The most events one frame carries.
pub const MAX_EVENTS_PER_FRAME: usize = 256;

/// A monotonic stretch of clip positions (`0..=duration`): from `from`
/// (included or not) to `to` (included).
#[derive(Debug, Clone, Copy)]
struct Piece {
    from: f64,
    from_included: bool,
    to: f64,
}

/// Writes into `out` the indices (into `clip.events()`) of the events
/// crossed going from request time `from` (`None`: no previous frame) to
/// `to`, in crossing order. Allocation-free once `out` has capacity.
pub fn crossed(clip: &Clip, playback: Playback, ease: Ease, from: Option<f64>, to: f64, out: &mut Vec<u32>) {
    out.clear();
    let events = clip.events();
    if events.is_empty() {
        return;
    }
    let Some(from) = from.filter(|f| f.is_finite() && to.is_finite()) else {
        let at = clip.clip_time(to, playback, ease);
        let lo = events.partition_point(|e| e.time < at);
        let hi = events.partition_point(|e| e.time <= at);
        out.extend((lo..hi).take(MAX_EVENTS_PER_FRAME).map(|i| i as u32));
        return;
    };
    let range = clip.range();
    let duration = range.duration();
    // Offsets from the start, and clip times, as sampling computes them
    // (docs/clip-format.md §2.7's seam rule included), so a frame's events match its pose.
    let (xa, xb) = (range.offset(from), range.offset(to));
    if xa == xb || duration.is_nan() || duration <= 0.0 {
        return;
    }
    let clip_time = |p: f64| f64::from(range.at(p, ease));
    let mut emit = |piece: Piece| {
        let (a, b) = (clip_time(piece.from), clip_time(piece.to));
        if a <= b {
            let lo =
                events.partition_point(|e| f64::from(e.time) < a || (!piece.from_included && f64::from(e.time) == a));
            let hi = events.partition_point(|e| f64::from(e.time) <= b);
            for i in lo..hi.max(lo) {
                if out.len() == MAX_EVENTS_PER_FRAME {
                    return false;
                }
                out.push(i as u32);
            }
        } else {
            let lo = events.partition_point(|e| f64::from(e.time) < b);
            let hi =
                events.partition_point(|e| f64::from(e.time) < a || (piece.from_included && f64::from(e.time) == a));
            for i in (lo..hi.max(lo)).rev() {
                if out.len() == MAX_EVENTS_PER_FRAME {
                    return false;
                }
                out.push(i as u32);
            }
        }
        true
    };
    let forward = xb > xa;
    match playback {
        Playback::Once => {
            let (pa, pb) = (xa.clamp(0.0, duration), xb.clamp(0.0, duration));
            if pa != pb {
                emit(Piece { from: pa, from_included: false, to: pb });
            }
        }
        Playback::Loop => {
            // (cycle, position) as sampling wraps them: a position that
            // rounds to the end is the next cycle's start.
            let ((ca, pa), (cb, pb)) = (range.cycle(xa), range.cycle(xb));
            for c in cycle_range(ca, cb, forward) {
                let (near, far) = if forward { (0.0, duration) } else { (duration, 0.0) };
                let piece = Piece {
                    from: if c == ca { pa } else { near },
                    from_included: c != ca,
                    to: if c == cb { pb } else { far },
                };
                if !emit(piece) {
                    break;
                }
            }
        }
        Playback::PingPong => {
            let (ca, cb) = ((xa / duration).floor(), (xb / duration).floor());
            let fold = |x: f64, c: f64| {
                let p = x - c * duration;
                (if c.rem_euclid(2.0) == 0.0 { p } else { duration - p }).clamp(0.0, duration)
            };
            for c in cycle_range(ca, cb, forward) {
                let (lo, hi) = (c * duration, (c + 1.0) * duration);
                let (x0, x1) = if forward { (xa.max(lo), xb.min(hi)) } else { (xa.min(hi), xb.max(lo)) };
                if x0 == x1 {
                    continue;
                }
                if !emit(Piece { from: fold(x0, c), from_included: false, to: fold(x1, c) }) {
                    break;
                }
            }
        }
    }
}

/// Cycle indices from `a` to `b` in the direction of travel, bounded so that
/// a huge jump cannot spin (each cycle crossed delivers at least one event
/// when the clip has any in range, so the event cap ends it sooner).
fn cycle_range(a: f64, b: f64, forward: bool) -> impl Iterator<Item = f64> {
    let n = ((b - a).abs() as u64).min(MAX_EVENTS_PER_FRAME as u64 + 1);
    (0..=n).map(move |i| if forward { a + i as f64 } else { a - i as f64 })
}

#[cfg(test)]
mod tests {
    use super::*;
    use anim::{Channel, ClipSpec, EventSpec, Interpolation, Keys, TrackSpec};
    use glam::Vec3;

    /// A clip over [0, 4] with events at 0, 1, 2, 4 named by their time.
    fn clip() -> Clip {
        let track = TrackSpec::new(
            "root",
            Channel::Translation,
            Interpolation::Linear,
            vec![0.0, 4.0],
            Keys::Vec3(vec![Vec3::ZERO, Vec3::X]),
        );
        let events = [0.0, 1.0, 2.0, 4.0].map(|t| EventSpec { time: t, name: format!("{t}") }).to_vec();
        Clip::build(&ClipSpec {
            name: "e".into(),
            skeleton: None,
            tracks: vec![track],
            events,
            playback: Playback::Once,
            ..Default::default()
        })
        .unwrap()
    }

    /// The names of the events crossed from `from` to `to`.
    fn check(playback: Playback, from: Option<f64>, to: f64) -> Vec<String> {
        let clip = clip();
        let mut out = Vec::new();
        crossed(&clip, playback, Ease::Linear, from, to, &mut out);
        out.iter().map(|&i| clip.events()[i as usize].name.clone()).collect()
    }

    #[test]
    fn a_first_frame_delivers_only_the_events_at_its_time() {
        assert_eq!(check(Playback::Once, None, 0.0), ["0"]);
        assert_eq!(check(Playback::Once, None, 0.5), [] as [&str; 0]);
        assert_eq!(check(Playback::Loop, None, 5.0), ["1"]);
    }

    #[test]
    fn once_delivers_the_events_between_frames_in_order_and_each_once() {
        assert_eq!(check(Playback::Once, Some(0.0), 1.0), ["1"]);
        assert_eq!(check(Playback::Once, Some(1.0), 2.5), ["2"]);
        assert_eq!(check(Playback::Once, Some(0.0), 10.0), ["1", "2", "4"]);
        assert_eq!(check(Playback::Once, Some(10.0), 20.0), [] as [&str; 0], "held at the end");
        assert_eq!(check(Playback::Once, Some(4.0), -1.0), ["2", "1", "0"], "backwards, in crossing order");
        assert_eq!(check(Playback::Once, Some(3.0), 3.0), [] as [&str; 0], "paused");
    }

    #[test]
    fn consecutive_frames_split_the_events_without_loss_or_repeats() {
        for playback in [Playback::Once, Playback::Loop, Playback::PingPong] {
            for step in [0.1f64, 0.25, 1.0, 0.7, -0.3, -1.0] {
                let mut all = check(playback, None, 0.0);
                let mut t = 0.0f64;
                let end = if step > 0.0 { 12.0 } else { -12.0 };
                let mut prev = t;
                while (end - t) * step.signum() > 0.0 {
                    t = ((prev + step) * 1.0e9).round() / 1.0e9;
                    all.extend(check(playback, Some(prev), t));
                    prev = t;
                }
                let mut once = check(playback, None, 0.0);
                once.extend(check(playback, Some(0.0), prev));
                assert_eq!(all, once, "{playback:?} step {step}");
            }
        }
    }

    #[test]
    fn loop_wraps_and_fires_both_ends_once_per_cycle() {
        assert_eq!(check(Playback::Loop, Some(3.5), 4.5), ["4", "0"]);
        assert_eq!(check(Playback::Loop, Some(0.0), 8.0), ["1", "2", "4", "0", "1", "2", "4", "0"]);
        assert_eq!(check(Playback::Loop, Some(0.5), -0.5), ["0", "4"], "backwards across the seam");
        assert_eq!(check(Playback::Loop, Some(9.5), 6.5), ["1", "0", "4"]);
    }

    #[test]
    fn ping_pong_turns_at_the_ends_without_repeating_the_turning_event() {
        // Forward to 4, back down: 4 fires once at the turn.
        // Request 6.5 is clip time 1.5 on the way back.
        assert_eq!(check(Playback::PingPong, Some(3.0), 6.5), ["4", "2"]);
        assert_eq!(check(Playback::PingPong, Some(6.5), 9.0), ["1", "0", "1"]);
        assert_eq!(check(Playback::PingPong, Some(0.5), -1.5), ["0", "1"], "backwards through the start");
    }

    #[test]
    fn ease_moves_the_crossing_with_the_warped_time() {
        let clip = clip();
        let mut out = Vec::new();
        // ease_in: clip time 4·(x/4)² — request 2 → clip time 1, so event "1"
        // (at clip time 1) is crossed exactly at request time 2.
        crossed(&clip, Playback::Once, Ease::EaseIn, Some(0.0), 1.9, &mut out);
        assert!(out.is_empty());
        crossed(&clip, Playback::Once, Ease::EaseIn, Some(1.9), 2.0, &mut out);
        assert_eq!(out, [1]);
    }

    #[test]
    fn a_huge_jump_is_capped() {
        assert_eq!(check(Playback::Loop, Some(0.0), 1.0e12).len(), MAX_EVENTS_PER_FRAME);
    }
}
