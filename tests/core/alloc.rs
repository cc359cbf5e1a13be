//! The hot path allocates nothing (SPEC: sampling into caller-owned
//! buffers). Counted with the per-thread counting allocator of `main.rs`,
//! so tests on other threads cannot disturb the count.

use glam::Mat4;
use inbetween::anim::{Clip, Cursor, Ease, Playback, Pose, SampleOptions, Sampler, Space};

use crate::allocations;
use crate::random::{Rng, skeleton_clip};

/// Clips with every interpolation mode, some with hierarchies.
fn clips() -> Vec<Clip> {
    let mut rng = Rng::new(700);
    (0..8).map(|_| Clip::build(&skeleton_clip(&mut rng, 8)).unwrap()).collect()
}

/// Times across and beyond each clip, forwards, then jumping about.
fn times(clip: &Clip) -> Vec<f64> {
    let (a, b) = (clip.start() as f64, clip.end() as f64);
    let mut t: Vec<f64> = (0..=100).map(|k| a - 0.5 + (b - a + 1.0) * k as f64 / 100.0).collect();
    t.extend((0..50).map(|k| b + 3.7 - (k as f64 * 0.731) % (b - a + 5.0)));
    t
}

/// Runs `f` and returns how many allocations it made on this thread.
fn count(f: impl FnOnce()) -> u64 {
    let before = allocations();
    f();
    allocations() - before
}

#[test]
fn the_counter_sees_allocations() {
    assert!(count(|| drop(std::hint::black_box(vec![1u8; 10]))) >= 1, "a test that cannot fail is a defect");
}

#[test]
fn sample_into_allocates_nothing_once_warm() {
    for clip in clips() {
        let (mut cursor, mut pose) = (Cursor::default(), Pose::default());
        clip.sample_into(clip.start(), &mut cursor, &mut pose); // warm: buffers take their size
        let times = times(&clip);
        let n = count(|| {
            for &t in &times {
                clip.sample_into(t as f32, &mut cursor, &mut pose);
            }
        });
        assert_eq!(n, 0, "sample_into allocated {n} times over {} samples", times.len());
    }
}

#[test]
fn sample_allocates_nothing_once_warm_in_both_spaces() {
    for clip in clips() {
        let mut sampler = Sampler::new();
        let times = times(&clip);
        for space in [Space::Local, Space::Model] {
            for playback in [Playback::Once, Playback::Loop, Playback::PingPong] {
                let options = SampleOptions { playback: Some(playback), ease: Ease::EaseInOut, space };
                clip.sample(0.0, &options, &mut sampler); // warm
                let n = count(|| {
                    for &t in &times {
                        clip.sample(t, &options, &mut sampler);
                        std::hint::black_box(sampler.pose());
                    }
                });
                assert_eq!(n, 0, "sample ({space:?}, {playback:?}) allocated {n} times");
            }
        }
    }
}

#[test]
fn matrices_allocate_nothing_once_warm() {
    for clip in clips() {
        let mut sampler = Sampler::new();
        let mut out: Vec<Mat4> = Vec::new();
        let options = SampleOptions::default();
        clip.matrices(0.0, &options, false, &mut sampler, &mut out); // warm
        let times = times(&clip);
        let n = count(|| {
            for &t in &times {
                clip.matrices(t, &options, false, &mut sampler, &mut out);
            }
        });
        assert_eq!(n, 0, "matrices allocated {n} times");
    }
}
