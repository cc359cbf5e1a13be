//! The motions a stream's player may be evaluating at once, as its
//! controls left them: what a crossfade or an `ik` control is priced at
//! (docs/api.md, “Work and its price”).
//!
//! `anim::motion::Player` keeps a fade chain: the motion playing on top
//! and, beneath it, every fade still in progress, each evaluating the
//! motion it fades from; a crossfade beyond `MAX_FADES` finishes the
//! oldest at once. A fade ends once `duration` seconds of stream time have
//! moved, which pauses hold and speed changes, so whoever checks a control
//! (on the transport's task, ahead of the ticks) cannot tell that one has
//! ended: every fade begun counts until the player would drop it.

use std::collections::VecDeque;
use std::sync::Arc;

use anim::motion::push_crossfade;

use super::pinned::StreamMotion;

/// The motions a player may evaluate each tick, oldest first, the one
/// playing last (see the module docs).
#[derive(Debug, Clone)]
pub(crate) struct FadeChain {
    motions: VecDeque<Arc<StreamMotion>>,
}

impl FadeChain {
    /// A stream that plays `motion` alone.
    pub(crate) fn new(motion: &Arc<StreamMotion>) -> Self {
        FadeChain { motions: VecDeque::from([Arc::clone(motion)]) }
    }

    /// The chain after a crossfade to `to`: every motion still fading, and
    /// `to` on top, the oldest gone past `anim::motion::MAX_FADES` fades (as
    /// the player drops it).
    #[must_use]
    pub(crate) fn crossfaded(&self, to: &Arc<StreamMotion>) -> Self {
        let mut motions = self.motions.clone();
        push_crossfade(&mut motions, Arc::clone(to));
        FadeChain { motions }
    }

    /// The motion playing (the latest crossfade's target).
    pub(crate) fn playing(&self) -> &Arc<StreamMotion> {
        self.motions.back().expect("a chain always holds the motion playing")
    }

    /// Every motion a tick may evaluate, the one playing last (as
    /// `work::price::stream_frame` takes them).
    pub(crate) fn motions(&self) -> Vec<&StreamMotion> {
        self.motions.iter().map(|m| &**m).collect()
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;

    use anim::ik::IkConstraint;
    use anim::motion::{LayerSpec, MAX_FADES, MotionOptions, MotionSpec, Player};
    use anim::{Ease, Motion};

    use super::*;
    use crate::stream::control::{Control, ControlCheck, ControlError, Crossfade, Repricing};
    use crate::stream::tests::{clip, pinned};
    use crate::stream::{StreamParams, StreamRequest};
    use crate::work::price;

    /// `layers` layers of the two-joint test clip: `2 × layers` units a pose.
    fn motion(layers: usize) -> Arc<StreamMotion> {
        let c = pinned("c1", clip());
        let layers = (0..layers).map(|_| LayerSpec::new(Arc::clone(&c))).collect();
        Arc::new(Motion::build(MotionSpec { layers, ..MotionSpec::default() }).unwrap())
    }

    /// The per-frame price of every control the check priced.
    #[derive(Debug, Default)]
    struct Priced(Mutex<Vec<u64>>);

    impl Repricing for Priced {
        fn reprice(&self, motions: &[&StreamMotion], ik: &[IkConstraint]) -> Result<(), ControlError> {
            let ik = motions.first().map_or(0, |m| price::ik(ik, m.skeleton()));
            self.0.lock().unwrap().push(price::stream_frame(motions, ik, 30));
            Ok(())
        }

        fn admit(&self) -> Result<(), ControlError> {
            Ok(())
        }

        fn charge_layout(&self, _units: u64) -> Result<crate::stream::LayoutRunner, ControlError> {
            Ok(Box::new(|job| Box::pin(async move { Ok(job()) })))
        }
    }

    fn fade(to: &Arc<StreamMotion>) -> Control {
        Control::Crossfade(Crossfade { to: Arc::clone(to), duration: 60.0, ease: Ease::Linear, source: None })
    }

    #[test]
    fn a_crossfade_during_a_fade_and_an_ik_control_are_priced_at_every_motion_still_fading() {
        let params = StreamParams::new(pinned("c1", clip()), StreamRequest { fps: 30, ..Default::default() }).unwrap();
        let priced = Arc::new(Priced::default());
        let mut check = ControlCheck::new(&params).priced_by(Some(Arc::clone(&priced) as Arc<dyn Repricing>));
        let (two, three, one) = (motion(2), motion(3), motion(1));
        check.check(fade(&two)).unwrap();
        check.check(fade(&three)).unwrap();
        check.check(Control::Ik(Vec::new())).unwrap();
        // Two joints a layer: the stream's motion (1 layer) under a fade to 2
        // layers, then both under a fade to 3, the IK on that whole mix.
        assert_eq!(*priced.0.lock().unwrap(), [2 * (1 + 2), 2 * (1 + 2 + 3), 2 * (1 + 2 + 3)]);
        // Past MAX_FADES fades the oldest leaves: MAX_FADES + 1 one-layer motions.
        for _ in 0..MAX_FADES + 3 {
            check.check(fade(&one)).unwrap();
        }
        assert_eq!(priced.0.lock().unwrap().last(), Some(&(2 * (MAX_FADES as u64 + 1))));
    }

    #[test]
    fn the_chain_holds_as_many_motions_as_the_player_evaluates_while_no_fade_ends() {
        let first = motion(1);
        let (mut player, mut chain) = (Player::new(Arc::clone(&first)), FadeChain::new(&first));
        let options = MotionOptions::default();
        for k in 0..MAX_FADES + 4 {
            player.sample(k as f64 / 30.0, &options);
            let to = motion(1 + k % 3);
            player.crossfade(Arc::clone(&to), 60.0, Ease::Linear).unwrap();
            chain = chain.crossfaded(&to);
            assert_eq!(chain.motions().len(), player.fades() + 1, "after crossfade {k}");
            assert!(Arc::ptr_eq(chain.playing(), player.motion()));
        }
    }
}
