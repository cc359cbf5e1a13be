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

use std::sync::Arc;

use super::pinned::StreamMotion;
use anim::Ease;
use anim::ik::{IkConstraint, IkSpec};
use formats::wire::ik::IkDoc;
use formats::wire::json::EaseDoc;

/// A change asked of a playback, applied at its next tick.
#[derive(Debug, Clone, PartialEq)]
pub enum Control {
    Play,
    Pause,
    /// Show this motion time of the current motion at the next tick.
    Seek(f64),
    /// Stream seconds per real second (negative plays backwards).
    Speed(f64),
    /// End the stream cleanly.
    Stop,
    /// Fade to another motion (SPEC §6).
    Crossfade(Crossfade),
    /// Ramp a layer of the current motion to a weight.
    Layer {
        index: usize,
        weight: f32,
        duration: f64,
    },
    /// Replace the stream's IK constraints (SPEC §7), as a client names
    /// them; the subscription resolves them into [`Control::SetIk`].
    Ik(Vec<IkSpec>),
    /// Replace the stream's IK constraints, resolved against its skeleton.
    SetIk(Vec<IkConstraint>),
}

/// A crossfade asked for: its target, already built over pinned clips.
#[derive(Debug, Clone)]
pub struct Crossfade {
    pub to: Arc<StreamMotion>,
    pub duration: f64,
    pub ease: Ease,
    /// `to` as the client wrote it (the JSON motion), so that the control
    /// can be said again: a broadcast stores it for the other nodes.
    pub source: Option<Arc<serde_json::Value>>,
}

impl PartialEq for Crossfade {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.to, &other.to) && self.duration == other.duration && self.ease == other.ease
    }
}

/// The largest accepted `|speed|`.
pub const MAX_SPEED: f64 = 1000.0;

/// The longest crossfade or weight ramp, seconds.
pub const MAX_FADE_SECONDS: f64 = 3600.0;

impl Control {
    /// Checks the numbers a client sent.
    ///
    /// # Errors
    /// A non-finite seek time, or a speed that is not finite or exceeds
    /// [`MAX_SPEED`] in magnitude.
    pub fn validate(self) -> Result<Self, &'static str> {
        let long = |d: f64| !(0.0..=MAX_FADE_SECONDS).contains(&d);
        match self {
            Control::Seek(t) if !t.is_finite() => Err("seek time must be a finite number of seconds"),
            Control::Speed(v) if !v.is_finite() || v.abs() > MAX_SPEED => {
                Err("speed must be a finite number between -1000 and 1000")
            }
            Control::Crossfade(Crossfade { duration, .. }) if long(duration) => {
                Err("a crossfade's duration must be between 0 and 3600 seconds")
            }
            Control::Layer { duration, .. } if long(duration) => {
                Err("a weight ramp's duration must be between 0 and 3600 seconds")
            }
            Control::Layer { weight, .. } if !(0.0..=1.0).contains(&weight) => Err("a layer weight must be in [0, 1]"),
            c => Ok(c),
        }
    }
}

impl Control {
    /// The control message that says this control again (SPEC §5); `None`
    /// for `stop`, resolved IK lists and a crossfade whose motion was not
    /// written down (`Crossfade::source`).
    pub fn to_json(&self) -> Option<serde_json::Value> {
        use serde_json::json;
        Some(match self {
            Control::Crossfade(Crossfade { source: Some(to), duration, ease, .. }) => {
                json!({"op": "crossfade", "to": **to, "duration": duration, "ease": EaseDoc::from(*ease)})
            }
            Control::Ik(specs) => {
                json!({"op": "ik", "constraints": specs.iter().map(IkDoc::from_spec).collect::<Vec<_>>()})
            }
            Control::Play => json!({"op": "play"}),
            Control::Pause => json!({"op": "pause"}),
            Control::Seek(time) => json!({"op": "seek", "time": time}),
            Control::Speed(speed) => json!({"op": "speed", "speed": speed}),
            Control::Layer { index, weight, duration } => {
                json!({"op": "layer", "index": index, "weight": weight, "duration": duration})
            }
            Control::Stop | Control::Crossfade(_) | Control::SetIk(_) => return None,
        })
    }
}

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

    /// Applies `control` so that it takes effect at tick `k` (`k >= 1`).
    /// Returns whether the time jumped (a seek), which ends event continuity.
    pub fn apply(&mut self, control: Control, k: u64) -> bool {
        let prev = k.saturating_sub(1);
        let held = self.time_at(prev);
        match control {
            Control::Pause => {
                (self.anchor_k, self.anchor_t, self.paused) = (prev, held, true);
            }
            Control::Play => {
                (self.anchor_k, self.anchor_t, self.paused) = (prev, held, false);
            }
            Control::Speed(v) => {
                (self.anchor_k, self.anchor_t, self.speed) = (prev, held, v);
            }
            Control::Seek(t) => {
                (self.anchor_k, self.anchor_t) = (k, t);
                return true;
            }
            Control::Stop | Control::Crossfade(_) | Control::Layer { .. } | Control::Ik(_) | Control::SetIk(_) => {}
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `ticks` ticks at 10 fps from t = 1, applying `controls` (tick,
    /// control) before their tick, and returns the times shown.
    fn check(speed: f64, controls: &[(u64, Control)], ticks: u64) -> Vec<f64> {
        let mut p = Playhead::new(1.0, speed, 10, false);
        (0..ticks)
            .map(|k| {
                for (_, c) in controls.iter().filter(|(at, _)| *at == k) {
                    p.apply(c.clone(), k);
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

    #[test]
    fn controls_are_validated() {
        assert!(Control::Seek(f64::NAN).validate().is_err());
        assert!(Control::Speed(f64::INFINITY).validate().is_err());
        assert!(Control::Speed(-1000.5).validate().is_err());
        assert_eq!(Control::Speed(-1000.0).validate(), Ok(Control::Speed(-1000.0)));
    }
}
