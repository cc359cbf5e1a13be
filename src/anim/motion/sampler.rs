//! Sampling a [`Motion`]: each layer's clip time, its local pose, then the
//! layering of every output joint, bottom to top, over the rest pose.

use super::layering::{self, Joint};
use super::sync::position;
use super::{ClipSource, LayerMode, LayerTime, Motion, UNMAPPED};
use crate::anim::{Cursor, Ease, Playback, Pose, Space};

/// How a request samples a motion.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotionOptions {
    /// Applied to every layer's clip time after its playback.
    pub ease: Ease,
    pub space: Space,
}

/// Reusable buffers: one per playback or per worker.
#[derive(Debug, Clone, Default)]
pub struct MotionSampler {
    cursors: Vec<Cursor>,
    layer: Pose,
    local: Pose,
    model: Pose,
    space: Space,
    phases: Vec<f64>,
    clip_times: Vec<f32>,
}

impl MotionSampler {
    pub fn new() -> Self {
        Self::default()
    }

    /// The pose of the last sample, in the space it asked for.
    pub fn pose(&self) -> &Pose {
        match self.space {
            Space::Local => &self.local,
            Space::Model => &self.model,
        }
    }

    /// The local pose of the last sample, whatever space was asked for.
    pub fn local(&self) -> &Pose {
        &self.local
    }

    /// Each layer's clip time in the last sample.
    pub fn clip_times(&self) -> &[f32] {
        &self.clip_times
    }
}

impl<C: ClipSource> Motion<C> {
    /// The pose at motion time `tau` with the motion's own weights (a
    /// request's answer). Returns the first layer's clip time.
    pub fn sample(&self, tau: f64, options: &MotionOptions, sampler: &mut MotionSampler) -> f32 {
        let mut phases = std::mem::take(&mut sampler.phases);
        self.phases_at(tau, &self.weights, &mut phases);
        let clip_time = self.sample_with(tau, &phases, &self.weights, options, sampler);
        sampler.phases = phases;
        clip_time
    }

    /// The pose at motion time `tau` with sync-group `phases` (from
    /// [`Motion::phases_at`] or kept by a stream) and live layer
    /// `weights`. Returns the first layer's clip time.
    pub fn sample_with(
        &self,
        tau: f64,
        phases: &[f64],
        weights: &[f32],
        options: &MotionOptions,
        sampler: &mut MotionSampler,
    ) -> f32 {
        let MotionSampler { cursors, layer: scratch, local, clip_times, .. } = sampler;
        cursors.resize_with(self.layers.len(), Cursor::default);
        clip_times.clear();
        for (i, layer) in self.layers.iter().enumerate() {
            let clip = layer.clip.clip();
            let t = match layer.time {
                LayerTime::Free { offset, speed, playback } => {
                    clip.clip_time(offset + speed * tau, playback, options.ease)
                }
                LayerTime::Synced { group } => {
                    let range = clip.range();
                    let at = f64::from(range.start()) + position(phases[group], self.durations[i]);
                    range.clip_time(at, Playback::Loop, options.ease)
                }
            };
            clip_times.push(t);
            if i == 0 && layer.mode == LayerMode::Blend && weights[0] >= 1.0 && layer.mask.iter().all(|m| *m >= 1.0) {
                // The common case, and the bit-for-bit promise: the first
                // full-weight layer is the clip's own pose.
                clip.sample_into(t, &mut cursors[0], local);
                continue;
            }
            if i == 0 {
                local.copy_from(self.skeleton().rest());
            }
            clip.sample_into(t, &mut cursors[i], scratch);
            layer.apply(scratch, weights[i], local);
        }
        if options.space == Space::Model {
            self.skeleton().to_model(&sampler.local, &mut sampler.model);
        }
        sampler.space = options.space;
        sampler.clip_times[0]
    }
}

impl<C> super::Layer<C> {
    /// Layers this layer's `pose` (in its clip's joints) onto `out` (in the
    /// output skeleton's) at layer weight `weight`.
    fn apply(&self, pose: &Pose, weight: f32, out: &mut Pose) {
        for (j, (&source, &mask)) in self.map.iter().zip(&self.mask).enumerate() {
            let w = weight * mask;
            if source == UNMAPPED || w <= 0.0 {
                continue;
            }
            let layer = joint(pose, source as usize);
            let mut joint_now = joint(out, j);
            match &self.reference {
                None => layering::blend(&mut joint_now, &layer, w),
                Some(reference) => layering::add(&mut joint_now, &layer, &joint(reference, source as usize), w),
            }
            out.translations[j] = joint_now.t;
            out.rotations[j] = joint_now.q;
            out.scales[j] = joint_now.s;
        }
    }
}

fn joint(pose: &Pose, j: usize) -> Joint {
    Joint { t: pose.translations[j], q: pose.rotations[j], s: pose.scales[j] }
}
