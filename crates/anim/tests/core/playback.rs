//! docs/clip-format.md, 2.6–2.7: request time → clip time, at hand-computed times.
//!
//! `once` clamps, `loop` wraps modulo the duration, `ping_pong` reflects,
//! and the ease warps normalised time. The clip used is a linear
//! translation `x = t` over `[1, 3]` so that a pose reads back its own
//! clip time; every expected value below is worked out by hand.

use anim::{Channel, Clip, ClipSpec, Ease, Interpolation, Keys, Playback, SampleOptions, Sampler, Space, TrackSpec};
use glam::Vec3;

/// `x(t) = t` on `[start, end]`.
fn ramp(start: f32, end: f32, playback: Playback) -> Clip {
    let track = TrackSpec::new(
        "root",
        Channel::Translation,
        Interpolation::Linear,
        vec![start, end],
        Keys::Vec3(vec![Vec3::new(start, 0.0, 0.0), Vec3::new(end, 0.0, 0.0)]),
    );
    Clip::build(&ClipSpec {
        name: "ramp".into(),
        skeleton: None,
        tracks: vec![track],
        events: vec![],
        playback,
        ..Default::default()
    })
    .unwrap()
}

const EXACT: f32 = 1e-6;

fn check(clip: &Clip, t: f64, playback: Playback, ease: Ease, expected: f32) {
    let ct = clip.clip_time(t, playback, ease);
    assert!((ct - expected).abs() <= EXACT, "{playback:?} {ease:?} t = {t}: clip time {ct}, expected {expected}");
    let mut sampler = Sampler::new();
    let options = SampleOptions { playback: Some(playback), ease, space: Space::Local };
    let returned = clip.sample(t, &options, &mut sampler);
    assert_eq!(returned, ct);
    let x = sampler.pose().translations[0].x;
    assert!((x - expected).abs() <= EXACT, "{playback:?} {ease:?} t = {t}: pose x {x}, expected {expected}");
}

#[test]
fn once_clamps_to_the_range() {
    let clip = ramp(1.0, 3.0, Playback::Once);
    for (t, x) in [(-5.0, 1.0), (0.0, 1.0), (1.0, 1.0), (1.5, 1.5), (2.75, 2.75), (3.0, 3.0), (3.5, 3.0), (1e9, 3.0)] {
        check(&clip, t, Playback::Once, Ease::Linear, x);
    }
}

#[test]
fn loop_wraps_modulo_the_duration() {
    let clip = ramp(1.0, 3.0, Playback::Loop);
    for (t, x) in [(1.0, 1.0), (2.5, 2.5), (3.0, 1.0), (3.5, 1.5), (4.75, 2.75), (7.25, 1.25), (0.5, 2.5), (-2.0, 2.0)]
    {
        check(&clip, t, Playback::Loop, Ease::Linear, x);
    }
}

#[test]
fn ping_pong_reflects() {
    let clip = ramp(1.0, 3.0, Playback::PingPong);
    // Forward over [1, 3], back over [3, 5], forward over [5, 7], ...
    for (t, x) in [(1.0, 1.0), (2.0, 2.0), (3.0, 3.0), (3.5, 2.5), (4.5, 1.5), (5.0, 1.0), (5.5, 1.5), (0.5, 1.5)] {
        check(&clip, t, Playback::PingPong, Ease::Linear, x);
    }
}

#[test]
fn ease_warps_normalised_time() {
    let clip = ramp(1.0, 3.0, Playback::Once);
    // x = 1/4 of the way: ease_in 1/16, ease_out 1 - 9/16 = 7/16,
    // ease_in_out 3/16 - 2/64 = 5/32; at 1/2, 1/4, 3/4, 1/2.
    let cases = [
        (1.5, Ease::EaseIn, 1.0 + 2.0 / 16.0),
        (1.5, Ease::EaseOut, 1.0 + 2.0 * 7.0 / 16.0),
        (1.5, Ease::EaseInOut, 1.0 + 2.0 * 5.0 / 32.0),
        (2.0, Ease::EaseIn, 1.5),
        (2.0, Ease::EaseOut, 2.5),
        (2.0, Ease::EaseInOut, 2.0),
        (3.0, Ease::EaseIn, 3.0),
        (1.0, Ease::EaseOut, 1.0),
    ];
    for (t, ease, x) in cases {
        check(&clip, t, Playback::Once, ease, x);
    }
    // Ease applies after the playback mapping: one period on, the same warp.
    check(&clip, 3.5, Playback::Loop, Ease::EaseIn, 1.0 + 2.0 / 16.0);
    check(&clip, 4.5, Playback::PingPong, Ease::EaseOut, 1.0 + 2.0 * 7.0 / 16.0);
}

#[test]
fn the_request_overrides_the_clip_default() {
    let clip = ramp(1.0, 3.0, Playback::Loop);
    let mut sampler = Sampler::new();
    let t = clip.sample(3.5, &SampleOptions::default(), &mut sampler);
    assert_eq!(t, 1.5, "the clip's own loop");
    let once = SampleOptions { playback: Some(Playback::Once), ..Default::default() };
    assert_eq!(clip.sample(3.5, &once, &mut sampler), 3.0, "overridden by once");
}

/// A single instant clip has no duration to wrap: every mode gives its time.
#[test]
fn a_zero_length_clip_maps_everything_to_its_time() {
    let track = TrackSpec::new("j", Channel::Translation, Interpolation::Linear, vec![2.0], Keys::Vec3(vec![Vec3::X]));
    let spec = ClipSpec {
        name: "c".into(),
        skeleton: None,
        tracks: vec![track],
        events: vec![],
        playback: Playback::Loop,
        ..Default::default()
    };
    let clip = Clip::build(&spec).unwrap();
    for playback in [Playback::Once, Playback::Loop, Playback::PingPong] {
        for t in [-1.0, 2.0, 7.5, f64::NAN, f64::INFINITY] {
            assert_eq!(clip.clip_time(t, playback, Ease::EaseInOut), 2.0);
        }
    }
}

/// Streams loop a clip for hours: the phase after many periods must be as
/// exact as after the first. With keys at `0.1` and `1.0` (as `f32`) the
/// duration is `1.0 − 0.1f32 = 0.89999999850988…`, which `f32` cannot hold;
/// wrapping by a rounded duration drifts by the rounding every period.
#[test]
fn long_loops_do_not_drift() {
    let (start, end) = (0.1f32, 1.0f32);
    let clip = ramp(start, end, Playback::Loop);
    let duration = end as f64 - start as f64;
    for periods in [1.0, 1e3, 1e5] {
        // A quarter of the way into the period: clip time start + d/4.
        let t = start as f64 + periods * duration + 0.25 * duration;
        let expected = start as f64 + 0.25 * duration;
        let got = clip.clip_time(t, Playback::Loop, Ease::Linear) as f64;
        assert!(
            (got - expected).abs() <= 1e-6,
            "after {periods} periods: clip time {got}, expected {expected} (off by {:e} s)",
            got - expected
        );
        let bounced = clip.clip_time(t + periods * duration, Playback::PingPong, Ease::Linear) as f64;
        assert!((bounced - expected).abs() <= 1e-6, "ping-pong after {periods} periods: {bounced} vs {expected}");
    }
}

/// `{start, end, fps}` requests: `start + k/fps` up to and including `end`.
#[test]
fn frame_ranges_include_both_ends() {
    use anim::{frame_count, frame_times};
    assert_eq!(frame_count(0.0, 1.0, 30.0), 31);
    assert_eq!(frame_count(0.0, 0.3, 10.0), 4, "0.3·10 rounds below 3 in f64; the frame at 0.3 still counts");
    assert_eq!(frame_count(2.0, 2.0, 60.0), 1);
    assert_eq!(frame_count(0.0, 1.0, 4.0), 5);
    for (s, e, f) in
        [(1.0, 0.0, 30.0), (0.0, 1.0, 0.0), (0.0, 1.0, -5.0), (f64::NAN, 1.0, 30.0), (0.0, f64::INFINITY, 30.0)]
    {
        assert_eq!(frame_count(s, e, f), 0, "({s}, {e}, {f})");
    }
    let t: Vec<f64> = frame_times(-0.5, 0.5, 4.0).collect();
    assert_eq!(t, [-0.5, -0.25, 0.0, 0.25, 0.5]);
}
