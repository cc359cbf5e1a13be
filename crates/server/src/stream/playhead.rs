//! The playhead: which stream time each tick shows, and how playback
//! controls change it.
//!
//! While playing, tick `k` shows `t_k = t_{k-1} + speed/fps`; while paused,
//! `t_k = t_{k-1}`. A control received between two ticks acts on the next
//! tick: `pause` holds `t_{k-1}`, `play` and `speed` continue from `t_{k-1}`,
//! `seek` makes `t_k` the given time. The time is computed from an anchor
//! `(k_a, t_a)` as `t_a + speed·(k - k_a)/fps` rather than accumulated, so a
//! stream hours long shows the same times a fresh computation would.
//!
//! The motions on a stream's player (`anim::motion::Player`) show their
//! own motion times, offset from the stream time; a `seek` names the
//! current motion's time and is the player's to apply.

/// The largest accepted `|speed|`.
pub const MAX_SPEED: f64 = 1000.0;

/// The playhead of one playback.
#[derive(Debug, Clone, PartialEq)]
pub struct Playhead {
    fps: f64,
    anchor_k: u64,
    anchor_t: f64,
    speed: f64,
    paused: bool,
}

impl Playhead {
    /// Tick 0 shows `start`.
    pub fn new(start: f64, speed: f64, fps: u32, paused: bool) -> Self {
        Playhead { fps: f64::from(fps), anchor_k: 0, anchor_t: start, speed, paused }
    }

    /// The request time shown at tick `k` (for `k` at or after the anchor).
    pub fn time_at(&self, k: u64) -> f64 {
        if self.paused {
            self.anchor_t
        } else {
            self.anchor_t + self.speed * (k.saturating_sub(self.anchor_k)) as f64 / self.fps
        }
    }

    pub fn speed(&self) -> f64 {
        self.speed
    }

    pub fn paused(&self) -> bool {
        self.paused
    }

    /// Holds the time of tick `k - 1` from tick `k` (`k >= 1`) on.
    pub fn pause(&mut self, k: u64) {
        self.reanchor(k);
        self.paused = true;
    }

    /// Plays on from the time of tick `k - 1`.
    pub fn play(&mut self, k: u64) {
        self.reanchor(k);
        self.paused = false;
    }

    /// Steps by `speed` from the time of tick `k - 1`.
    pub fn set_speed(&mut self, speed: f64, k: u64) {
        self.reanchor(k);
        self.speed = speed;
    }

    /// Shows time `t` at tick `k`, then plays (or holds) on from there.
    pub fn seek(&mut self, t: f64, k: u64) {
        (self.anchor_k, self.anchor_t) = (k, t);
    }

    /// Its anchor tick and time, speed and pause (a broadcast checkpoint).
    pub(super) fn parts(&self) -> (u64, f64, f64, bool) {
        (self.anchor_k, self.anchor_t, self.speed, self.paused)
    }

    /// A playhead at `fps` from [`Playhead::parts`].
    pub(super) fn from_parts(fps: u32, (anchor_k, anchor_t, speed, paused): (u64, f64, f64, bool)) -> Self {
        Playhead { fps: f64::from(fps), anchor_k, anchor_t, speed, paused }
    }

    /// Anchors at tick `k - 1` and the time it shows now (before a change
    /// of speed or pause takes effect).
    fn reanchor(&mut self, k: u64) {
        let prev = k.saturating_sub(1);
        (self.anchor_k, self.anchor_t) = (prev, self.time_at(prev));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A playhead change, as the controls ask it.
    #[derive(Clone, Copy)]
    enum Control {
        Play,
        Pause,
        Seek(f64),
        Speed(f64),
    }

    /// Runs `ticks` ticks at 10 fps from t = 1, applying `controls` (tick,
    /// control) before their tick, and returns the times shown.
    fn check(speed: f64, controls: &[(u64, Control)], ticks: u64) -> Vec<f64> {
        let mut p = Playhead::new(1.0, speed, 10, false);
        (0..ticks)
            .map(|k| {
                for (_, c) in controls.iter().filter(|(at, _)| *at == k) {
                    match *c {
                        Control::Play => p.play(k),
                        Control::Pause => p.pause(k),
                        Control::Seek(t) => p.seek(t, k),
                        Control::Speed(v) => p.set_speed(v, k),
                    }
                }
                (p.time_at(k) * 1e9).round() / 1e9
            })
            .collect()
    }

    #[test]
    fn playing_advances_by_speed_over_fps_per_tick() {
        assert_eq!(check(1.0, &[], 4), [1.0, 1.1, 1.2, 1.3]);
        assert_eq!(check(-2.0, &[], 3), [1.0, 0.8, 0.6]);
        assert_eq!(check(0.0, &[], 3), [1.0, 1.0, 1.0]);
    }

    #[test]
    fn pause_holds_the_previous_time_and_play_continues_from_it() {
        let t = check(1.0, &[(2, Control::Pause), (5, Control::Play)], 7);
        assert_eq!(t, [1.0, 1.1, 1.1, 1.1, 1.1, 1.2, 1.3]);
    }

    #[test]
    fn seek_shows_its_time_at_the_next_tick_and_playing_continues_from_there() {
        let t = check(1.0, &[(2, Control::Seek(5.0))], 4);
        assert_eq!(t, [1.0, 1.1, 5.0, 5.1]);
        let t = check(1.0, &[(1, Control::Pause), (2, Control::Seek(5.0))], 4);
        assert_eq!(t, [1.0, 1.0, 5.0, 5.0], "a seek while paused stays paused");
    }

    #[test]
    fn speed_changes_the_step_from_the_previous_time() {
        let t = check(1.0, &[(2, Control::Speed(-1.0))], 5);
        assert_eq!(t, [1.0, 1.1, 1.0, 0.9, 0.8]);
    }

    #[test]
    fn long_playback_does_not_accumulate_rounding() {
        let p = Playhead::new(0.0, 1.0, 60, false);
        assert_eq!(p.time_at(60 * 3600 * 24), 86_400.0);
    }
}
