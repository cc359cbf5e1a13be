//! A clip document: parse → `Clip::build` → sample at arbitrary times in
//! every playback mode and space, and as matrices. Nothing may panic, and
//! every sampled value of a valid clip must be finite.
#![no_main]

use inbetween::anim::{Clip, Ease, Playback, SampleOptions, Sampler, Space};
use inbetween::wire::json::parse_clip;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok((_, spec)) = parse_clip(data) else { return };
    let Ok(clip) = Clip::build(&spec) else { return };
    // Times in and around the clip, extremes, and one taken from the input.
    let tail = data.len().saturating_sub(8);
    let raw = data.get(tail..).and_then(|b| b.try_into().ok()).map_or(0.0, f64::from_le_bytes);
    let (start, end) = (clip.start() as f64, clip.end() as f64);
    let times = [start, end, (start + end) / 2.0, start - 1.0, end + 1.0, -1e30, 1e30, f64::NAN, raw];
    let mut sampler = Sampler::new();
    let mut matrices = Vec::new();
    for playback in [Playback::Once, Playback::Loop, Playback::PingPong] {
        for (ease, space) in [(Ease::Linear, Space::Local), (Ease::EaseInOut, Space::Model)] {
            let options = SampleOptions { playback: Some(playback), ease, space };
            for &t in &times {
                let clip_time = clip.sample(t, &options, &mut sampler);
                assert!(clip_time.is_finite(), "clip time of {t}");
                let pose = sampler.pose();
                if space == Space::Local {
                    // Local values stay finite; model space may overflow f32 legitimately
                    // (a long chain of large finite offsets), which is not a bug.
                    assert!(pose.translations.iter().all(|v| v.is_finite()), "translation at {t}");
                    assert!(pose.rotations.iter().all(|q| q.is_finite()), "rotation at {t}");
                    assert!(pose.scales.iter().all(|v| v.is_finite()), "scale at {t}");
                }
            }
            clip.matrices(times[2], &options, false, &mut sampler, &mut matrices);
            clip.matrices(times[2], &options, true, &mut sampler, &mut matrices);
        }
    }
});
