//! The build budget (issue 15): a clip's constant-speed tables cost work
//! (quadrature evaluations plus arc-length pieces) counted over the whole
//! clip, checked while it is spent; and a built clip's heap estimate agrees
//! with what the allocator saw it keep.

use anim::{Channel, Clip, ClipError, ClipSpec, DEFAULT_BUILD_WORK, Interpolation, Keys, Playback, Speed, TrackSpec};
use glam::Vec3;

use crate::live_bytes;
use crate::random::{Kind, Rng, skeleton_clip, track};

/// Key `i` of a wiggly path: coordinates within ±10, so every segment is
/// long enough (≥ 1) that its table's tolerance is the absolute one.
fn key(i: usize) -> (Vec3, Vec3) {
    let x = i as f32;
    let value = Vec3::new(3.0 * x, 8.0 * (x * 1.3).sin(), 6.0 * (x * 0.7).cos()) * Vec3::new(0.1, 1.0, 1.0);
    let tangent = Vec3::new(9.0 * (x * 2.1).cos(), -7.0 * (x * 0.9).sin(), 5.0);
    (value, tangent)
}

/// A constant-speed Hermite translation of `joint` through keys `from..to`.
fn hermite(joint: &str, from: usize, to: usize) -> TrackSpec {
    let (values, tangents): (Vec<Vec3>, Vec<Vec3>) = (from..to).map(key).unzip();
    let times = (from..to).map(|i| i as f32 * 0.5).collect();
    let mut t = TrackSpec::new(joint, Channel::Translation, Interpolation::CubicHermite, times, Keys::Vec3(values));
    t.in_tangents = Some(Keys::Vec3(tangents.clone()));
    t.out_tangents = Some(Keys::Vec3(tangents));
    t.speed = Speed::Constant;
    t
}

fn clip(tracks: Vec<TrackSpec>) -> ClipSpec {
    ClipSpec {
        name: "budget".into(),
        skeleton: None,
        tracks,
        events: vec![],
        playback: Playback::Once,
        ..Default::default()
    }
}

fn refusal(result: Result<Clip, ClipError>) -> (&'static str, String, u64) {
    let e = result.expect_err("the build should have been refused");
    let spent = match e.kind {
        anim::ClipErrorKind::BuildBudgetExceeded { spent, .. } => spent,
        _ => 0,
    };
    (e.kind.code(), e.path.to_pointer(), spent)
}

#[test]
fn a_clip_at_its_cost_builds_and_one_unit_less_is_refused() {
    let spec = clip(vec![hermite("a", 0, 3), hermite("b", 3, 6)]);
    let cost = Clip::build(&spec).unwrap().build_work();
    assert!(cost > 4 * 1000, "every segment costs quadrature and pieces: {cost}");
    let at_cost = Clip::build_within(&spec, cost).expect("exactly the budget builds");
    assert_eq!((at_cost.build_work(), at_cost), (cost, Clip::build(&spec).unwrap()));
    let (code, pointer, spent) = refusal(Clip::build_within(&spec, cost - 1));
    assert_eq!((code, pointer.as_str()), ("build_budget_exceeded", "/tracks/1"), "the last track tips it over");
    assert_eq!(spent, cost, "the last unit of work is the one over");
    let (_, pointer, _) = refusal(Clip::build_within(&spec, cost / 4));
    assert_eq!(pointer, "/tracks/0");
}

#[test]
fn the_cost_is_the_same_however_the_curve_is_split_into_tracks() {
    let whole = Clip::build(&clip(vec![hermite("a", 0, 7)])).unwrap().build_work();
    let halves = Clip::build(&clip(vec![hermite("a", 0, 4), hermite("b", 3, 7)])).unwrap().build_work();
    let segments: Vec<TrackSpec> = (0..6).map(|i| hermite(&format!("j{i}"), i, i + 2)).collect();
    let one_per_segment = Clip::build(&clip(segments)).unwrap().build_work();
    assert!(whole > 6 * 1000, "{whole}");
    assert_eq!((halves, one_per_segment), (whole, whole));
}

#[test]
fn a_hostile_clip_stops_at_the_budget_not_after_its_work() {
    // 1,000 tracks of 400 keys: far over any budget; refused after about
    // the limit's worth of work (a few units past it), not after all of it.
    let tracks: Vec<TrackSpec> = (0..1000).map(|i| hermite(&format!("j{i}"), i, i + 400)).collect();
    let spec = clip(tracks);
    let started = std::time::Instant::now();
    let (code, pointer, spent) = refusal(Clip::build_within(&spec, 100_000));
    assert_eq!(code, "build_budget_exceeded");
    assert!((100_001..100_010).contains(&spent), "spent {spent}");
    assert!(pointer.starts_with("/tracks/"), "{pointer}");
    assert!(started.elapsed().as_secs_f64() < 5.0, "{:?}", started.elapsed());
}

#[test]
fn clips_without_constant_speed_cost_nothing() {
    let mut rng = Rng::new(15);
    for _ in 0..8 {
        let spec = skeleton_clip(&mut rng, 6);
        let keyed = spec.tracks.iter().all(|t| t.speed == Speed::Keyed);
        let clip = Clip::build_within(&spec, if keyed { 0 } else { DEFAULT_BUILD_WORK }).unwrap();
        assert_eq!(clip.build_work() == 0, keyed);
    }
}

/// What building `spec` left allocated on this thread: the clip's heap.
fn retained(spec: &ClipSpec) -> (Clip, usize) {
    let before = live_bytes();
    let clip = Clip::build(spec).unwrap();
    (clip, (live_bytes() - before) as usize)
}

#[test]
fn heap_bytes_is_what_the_allocator_saw_the_clip_keep() {
    let mut rng = Rng::new(1515);
    let mut specs: Vec<ClipSpec> = (0..6).map(|_| skeleton_clip(&mut rng, 12)).collect();
    specs.push(clip(vec![hermite("a", 0, 5), hermite("b", 3, 6)]));
    let kind = Kind::new(Channel::Translation, Interpolation::CatmullRom).constant_speed();
    specs.push(clip((0..6).map(|i| track(&mut rng, &format!("j{i}"), kind, 4)).collect()));
    for spec in &specs {
        let (clip, kept) = retained(spec);
        let estimate = clip.heap_bytes();
        assert!(kept > 0);
        assert!(
            estimate.abs_diff(kept) <= kept / 20,
            "{} tracks: estimate {estimate} B, allocator {kept} B",
            spec.tracks.len()
        );
    }
}

#[test]
fn a_raised_cancel_flag_stops_the_build_at_once() {
    let spec = clip(vec![hermite("a", 0, 3), hermite("b", 3, 6)]);
    let lowered = std::sync::atomic::AtomicBool::new(false);
    let clip = Clip::build_cancellable(&spec, DEFAULT_BUILD_WORK, &lowered).unwrap();
    assert_eq!(clip, Clip::build(&spec).unwrap());
    let raised = std::sync::atomic::AtomicBool::new(true);
    let e = Clip::build_cancellable(&spec, DEFAULT_BUILD_WORK, &raised).unwrap_err();
    assert_eq!((e.kind.code(), e.path.to_pointer()), ("build_cancelled", "/tracks/0".to_owned()));
}
