//! Sync groups (docs/motion.md): layers that share one normalised phase, so walk
//! and run cycles of different lengths stay in step.
//!
//! The group's cycle length is the share-weighted mean of its layers'
//! durations, `D = Σ e_l·D_l / Σ e_l`, where a layer's share `e_l` is its
//! weight times `(1 − weight_k)` of every later layer of the group (what is
//! left of it after the layers above blend over it). The phase advances at
//! `speed / D` cycles per second; layer `l` plays `start_l + frac(φ)·D_l`.

/// One group: its member layers in stacking order, and the first member's
/// phase at motion time 0 and speed.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct SyncGroup {
    pub name: String,
    pub members: Vec<usize>,
    pub phase0: f64,
    pub speed: f64,
}

impl SyncGroup {
    /// `D` for the layers' current `weights`, from each layer's duration;
    /// the plain mean when every share is 0, and 0 for a group of
    /// zero-length clips.
    pub fn cycle(&self, durations: &[f64], weights: &[f32]) -> f64 {
        let (mut shared, mut total) = (0.0, 0.0);
        let mut above = 1.0;
        for &l in self.members.iter().rev() {
            let w = f64::from(weights[l]);
            let share = w * above;
            above *= 1.0 - w;
            shared += share * durations[l];
            total += share;
        }
        if total > 0.0 {
            shared / total
        } else {
            self.members.iter().map(|&l| durations[l]).sum::<f64>() / self.members.len() as f64
        }
    }

    /// The phase at motion time `tau` when the weights have not changed.
    pub fn phase_at(&self, tau: f64, durations: &[f64], weights: &[f32]) -> f64 {
        self.phase0 + self.rate(durations, weights) * tau
    }

    /// Cycles per second of motion time.
    pub fn rate(&self, durations: &[f64], weights: &[f32]) -> f64 {
        let cycle = self.cycle(durations, weights);
        if cycle > 0.0 { self.speed / cycle } else { 0.0 }
    }
}

/// The position within a clip of `duration` at phase `phase`: the
/// fractional cycle times the duration.
pub(super) fn position(phase: f64, duration: f64) -> f64 {
    phase.rem_euclid(1.0) * duration
}

#[cfg(test)]
mod tests {
    use super::*;

    fn group(members: Vec<usize>) -> SyncGroup {
        SyncGroup { name: "g".into(), members, phase0: 0.0, speed: 1.0 }
    }

    #[test]
    fn the_cycle_is_the_share_weighted_mean_of_durations() {
        // walk (1 s, weight 1) under run (0.6 s, weight 0.3): shares 0.7 and 0.3.
        let g = group(vec![0, 1]);
        let d = g.cycle(&[1.0, 0.6], &[1.0, 0.3]);
        assert!((d - (0.7 * 1.0 + 0.3 * 0.6)).abs() < 1e-7, "{d}"); // f32 weights
        // Run at weight 1 hides walk entirely.
        assert_eq!(g.cycle(&[1.0, 0.6], &[1.0, 1.0]), 0.6);
        // All weights 0: the plain mean.
        assert!((g.cycle(&[1.0, 0.6], &[0.0, 0.0]) - 0.8).abs() < 1e-12);
    }

    #[test]
    fn the_phase_advances_one_cycle_per_group_cycle() {
        let g = SyncGroup { phase0: 0.25, speed: 2.0, ..group(vec![0, 1]) };
        let (durations, weights) = ([1.0, 0.5], [1.0, 0.5]);
        let d = g.cycle(&durations, &weights);
        assert!((g.phase_at(d, &durations, &weights) - 2.25).abs() < 1e-12);
        assert!((position(2.25, 0.5) - 0.125).abs() < 1e-12);
        assert_eq!(position(-0.25, 1.0), 0.75);
    }
}
