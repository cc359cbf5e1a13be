//! The [`Player`] (docs/motion.md, “Controls”): crossfades, weight ramps,
//! seeks and root motion across fades, against references written here.
//!
//! A fade's frames are checked against an `f64` blend (lerp, exact
//! short-way slerp) of the two sides' layered local poses, each side
//! sampled on its own with `Motion::sample` at its own motion time (A at
//! `s − origin_A`, B at `s − s_fade_start`), at `α = ease(elapsed /
//! duration)` computed here. Exact claims (no jump at a fade's first tick,
//! only B after it, a seek's pose) are compared bit for bit against the
//! same motion played alone.

use std::sync::Arc;

use anim::motion::{
    LayerSpec, MAX_FADES, MotionOptions, MotionSpec, Planar, Player, PlayerError, RootMotionSpec, push_crossfade,
};
use anim::{
    Channel, Clip, ClipSpec, Ease, Interpolation, Keys, Motion, MotionSampler, Playback, Pose, Space, TrackSpec,
};
use glam::{Quat, Vec3};

use crate::accuracy::TOLERANCE;
use crate::composition_reference::{EASES, Pool, Reference, blend, bound_err, ease, pose_err, random_layers, trs};
use crate::motion::body;
use crate::random::Rng;
use crate::reference::Trs;
use crate::root_motion::{Ground, travel};

type Shared<'a> = Arc<Motion<&'a Clip>>;

/// A motion's layered local pose at motion time `tau`, sampled on its own.
fn alone(motion: &Motion<&Clip>, tau: f64, clip_ease: Ease) -> Pose {
    let mut sampler = MotionSampler::new();
    motion.sample(tau, &MotionOptions { ease: clip_ease, space: Space::Local }, &mut sampler);
    sampler.local().clone()
}

fn f64_pose(pose: &Pose) -> Vec<Trs> {
    (0..pose.len()).map(|j| trs(pose, j)).collect()
}

fn mix(a: &[Trs], b: &[Trs], alpha: f64) -> Vec<Trs> {
    a.iter().zip(b).map(|(&a, &b)| blend(a, b, alpha)).collect()
}

/// A fade's `α` after `elapsed` seconds of a `duration` fade (1 once done).
fn alpha(fade_ease: Ease, elapsed: f64, duration: f64) -> f64 {
    ease(fade_ease, (elapsed / duration).min(1.0))
}

/// Whether a motion has a sync group (whose phase a player accumulates
/// tick by tick, so equal only to the last bits of a fresh sample's).
fn synced(layers: &[LayerSpec<usize>]) -> bool {
    layers.iter().any(|l| l.sync.is_some())
}

/// Asserts `got` is `expected` bit for bit, or within docs/clip-format.md,
/// “Accuracy”, for synced motions.
fn assert_same(got: &Pose, expected: &Pose, exact: bool, what: &str) {
    if exact {
        assert_eq!(got, expected, "{what}");
    } else {
        let err = pose_err(got, &f64_pose(expected));
        assert!(err <= TOLERANCE, "{what}: {err:e}");
    }
}

#[test]
fn frames_during_a_fade_are_the_blend_of_both_sides() {
    let mut worst = 0.0f64;
    for seed in 0..6u64 {
        let mut rng = Rng::new(1700 + seed);
        let joints = 2 + rng.below(7);
        let pool = Pool::shared_skeleton(&mut rng, 4, joints);
        for case in 0..8 {
            let (a_layers, b_layers) = (random_layers(&mut rng, &pool), random_layers(&mut rng, &pool));
            let (a, b): (Shared, Shared) = (Arc::new(pool.motion(&a_layers)), Arc::new(pool.motion(&b_layers)));
            // Forward or backward play; a duration half a tick off the tick grid.
            let dt = rng.range(0.01, 0.05) * if rng.chance(0.3) { -1.0 } else { 1.0 };
            let fade_ticks = 2 + rng.below(20);
            let duration = (fade_ticks as f64 + 0.5) * dt.abs();
            let (fade_ease, clip_ease) = (EASES[rng.below(4)], EASES[rng.below(4)]);
            let s0 = rng.range(-1.0, 2.0);
            let before = 2 + rng.below(5);
            let what = format!("seed {seed} case {case}");

            let mut player = Player::new(a.clone());
            let mut a_only = Player::new(a.clone());
            for k in 0..before + fade_ticks + 4 {
                let s = s0 + k as f64 * dt;
                if k == before {
                    player.crossfade(b.clone(), duration, fade_ease).unwrap();
                }
                let space = [Space::Local, Space::Model][rng.below(2)];
                let options = MotionOptions { ease: clip_ease, space };
                player.sample(s, &options);
                a_only.sample(s, &options);
                let a_pose = alone(&a, s, clip_ease);
                if k < before {
                    assert_same(player.pose(), a_only.pose(), true, &format!("{what}: before the fade, tick {k}"));
                    if space == Space::Local {
                        let what = format!("{what}: A alone, tick {k}");
                        assert_same(player.pose(), &a_pose, !synced(&a_layers), &what);
                    }
                    continue;
                }
                let fade_start = s0 + before as f64 * dt;
                let elapsed = (s - fade_start).abs();
                let b_pose = alone(&b, s - fade_start, clip_ease);
                assert_eq!(player.motion_time(), s - fade_start, "{what}: B's motion time at tick {k}");
                if k == before {
                    assert_eq!(player.pose(), a_only.pose(), "{what}: the fade's first tick is A's pose (no jump)");
                }
                if elapsed >= duration {
                    assert_eq!(player.fades(), 0, "{what}: tick {k}");
                    assert_eq!(player.alpha(), 1.0);
                    if space == Space::Local {
                        assert_same(player.pose(), &b_pose, !synced(&b_layers), &format!("{what}: after, tick {k}"));
                    }
                    continue;
                }
                let alpha = alpha(fade_ease, elapsed, duration);
                assert_eq!(player.fades(), 1, "{what}: tick {k}");
                assert!((f64::from(player.alpha()) - alpha).abs() < 1e-6, "{what}: α {} vs {alpha}", player.alpha());
                let local = mix(&f64_pose(&a_pose), &f64_pose(&b_pose), alpha);
                let expected = match space {
                    Space::Local => local,
                    Space::Model => Reference { pool: &pool, layers: &a_layers }.model(&local),
                };
                let err = pose_err(player.pose(), &expected);
                worst = worst.max(err);
                assert!(err <= TOLERANCE, "{what}: tick {k} α={alpha} {space:?}: {err:e}\n{a_layers:?}\n{b_layers:?}");
            }
        }
    }
    println!("crossfade vs f64 reference: worst error {worst:.3e}");
}

#[test]
fn a_crossfade_during_a_crossfade_nests_and_starts_where_the_old_one_was() {
    for seed in 0..6u64 {
        let mut rng = Rng::new(1710 + seed);
        let pool = Pool::shared_skeleton(&mut rng, 4, 5);
        let layers: Vec<_> = (0..3).map(|_| random_layers(&mut rng, &pool)).collect();
        let motions: Vec<Shared> = layers.iter().map(|l| Arc::new(pool.motion(l))).collect();
        let dt = rng.range(0.01, 0.04);
        let (d1, d2) = ((20.5 + rng.below(10) as f64) * dt, (10.5 + rng.below(20) as f64) * dt);
        let (e1, e2) = (EASES[rng.below(4)], EASES[rng.below(4)]);
        let (start1, start2) = (3, 3 + 5 + rng.below(12));
        let mut player = Player::new(motions[0].clone());
        let mut one_fade = Player::new(motions[0].clone());
        let options = MotionOptions::default();
        for k in 0..start2 + 45 {
            let s = k as f64 * dt;
            if k == start1 {
                player.crossfade(motions[1].clone(), d1, e1).unwrap();
                one_fade.crossfade(motions[1].clone(), d1, e1).unwrap();
            }
            if k == start2 {
                player.crossfade(motions[2].clone(), d2, e2).unwrap();
            }
            player.sample(s, &options);
            one_fade.sample(s, &options);
            if k == start2 {
                assert_eq!(player.pose(), one_fade.pose(), "seed {seed}: the new fade starts where the old one was");
                assert_eq!(player.fades(), 2);
            }
            if k < start2 {
                continue;
            }
            let (s1, s2) = (start1 as f64 * dt, start2 as f64 * dt);
            let ab = mix(
                &f64_pose(&alone(&motions[0], s, Ease::Linear)),
                &f64_pose(&alone(&motions[1], s - s1, Ease::Linear)),
                alpha(e1, s - s1, d1),
            );
            let expected = mix(&ab, &f64_pose(&alone(&motions[2], s - s2, Ease::Linear)), alpha(e2, s - s2, d2));
            let err = pose_err(player.pose(), &expected);
            assert!(err <= TOLERANCE, "seed {seed} tick {k}: {err:e}\n{layers:?}");
            let fading = usize::from(s - s1 < d1 && s - s2 < d2) + usize::from(s - s2 < d2);
            assert_eq!(player.fades(), fading, "seed {seed} tick {k}");
        }
    }
}

/// The largest component change between two poses.
fn step(a: &Pose, b: &Pose) -> f64 {
    f64_pose(a).iter().zip(f64_pose(b)).map(|(&x, y)| bound_err(x, y)).fold(0.0, f64::max)
}

fn ping_pong(clip: &Clip) -> Shared<'_> {
    let layer = LayerSpec { playback: Some(Playback::PingPong), ..LayerSpec::new(clip) };
    Arc::new(Motion::build(MotionSpec { layers: vec![layer], root_motion: None, ..Default::default() }).unwrap())
}

#[test]
fn a_second_crossfade_mid_fade_does_not_jump() {
    // Smooth clips far apart: any tick that restarted a fade or dropped
    // the one in progress would move the hips by metres, while a tick of
    // these fades moves them by centimetres.
    let a = body("a", 1.0, 0.0, 2.0, 0.0);
    let b = body("b", 0.7, 5.0, 6.0, 1.0);
    let c = body("c", 1.3, -4.0, -3.0, -1.2);
    let dt = 1.0 / 60.0;
    let mut player = Player::new(ping_pong(&a));
    let mut previous: Option<Pose> = None;
    let mut steps = Vec::new();
    for k in 0..150 {
        if k == 30 {
            player.crossfade(ping_pong(&b), 1.0, Ease::Linear).unwrap();
        }
        if k == 54 {
            player.crossfade(ping_pong(&c), 1.0, Ease::EaseInOut).unwrap();
        }
        player.sample(f64::from(k) * dt, &MotionOptions::default());
        if let Some(p) = &previous {
            steps.push(step(p, player.pose()));
        }
        previous = Some(player.pose().clone());
    }
    let largest = steps.iter().copied().fold(0.0, f64::max);
    assert!(largest < 0.6, "largest tick step {largest} (a jump is metres)");
    for k in 1..steps.len() - 1 {
        let around = steps[k - 1].max(steps[k + 1]);
        assert!(steps[k] <= 2.0 * around + 1e-6, "tick {k}: step {} against {around} around it", steps[k]);
    }
}

#[test]
fn fades_hold_while_paused_and_a_zero_duration_cuts() {
    let a = body("a", 1.0, 0.0, 2.0, 0.3);
    let b = body("b", 0.7, 5.0, 6.0, 1.0);
    let (ma, mb) = (ping_pong(&a), ping_pong(&b));
    let options = MotionOptions::default();
    let mut player = Player::new(ma.clone());
    player.sample(0.5, &options);
    player.crossfade(mb.clone(), 0.4, Ease::Linear).unwrap();
    player.sample(0.6, &options); // the fade's first tick
    player.sample(0.7, &options);
    let (held, alpha) = (player.pose().clone(), player.alpha());
    assert!((f64::from(alpha) - 0.25).abs() < 1e-6, "{alpha}");
    for _ in 0..5 {
        player.sample(0.7, &options);
        assert_eq!((player.pose(), player.alpha(), player.fades()), (&held, alpha, 1), "paused: nothing moves");
    }
    player.sample(0.8, &options);
    assert!((f64::from(player.alpha()) - 0.5).abs() < 1e-6, "the fade carries on: {}", player.alpha());

    // A zero-duration crossfade cuts: the next tick is the target at motion time 0, alone.
    player.crossfade(ma.clone(), 0.0, Ease::Linear).unwrap();
    player.sample(0.9, &options);
    assert_eq!(player.fades(), 0);
    assert_eq!(player.pose(), &alone(&ma, 0.0, Ease::Linear));
    assert_eq!(player.motion_time(), 0.0);
    player.sample(1.0, &options);
    assert_eq!(player.pose(), &alone(&ma, 1.0 - 0.9, Ease::Linear));
}

/// Two layers, hips at x = 0 and x = 1: the hips' x is layer 1's weight.
fn weight_meter<'a>(zero: &'a Clip, one: &'a Clip, weight: f32) -> Shared<'a> {
    let layers = vec![LayerSpec::new(zero), LayerSpec { weight, ..LayerSpec::new(one) }];
    Arc::new(Motion::build(MotionSpec { layers, root_motion: None, ..Default::default() }).unwrap())
}

#[test]
fn a_ramp_moves_a_layer_weight_linearly() {
    let (zero, one) = (body("zero", 1.0, 0.0, 0.0, 0.0), body("one", 1.0, 1.0, 1.0, 0.0));
    let mut player = Player::new(weight_meter(&zero, &one, 0.2));
    let options = MotionOptions::default();
    let weight = |p: &Player<&Clip>| f64::from(p.pose().translations[0].x);
    player.sample(0.0, &options);
    assert!((weight(&player) - 0.2).abs() < 1e-7);
    // From the weight at the last tick, over 0.5 s counted from that tick; backward play counts too.
    player.ramp(1, 0.9, 0.5).unwrap();
    let mut s = 0.0;
    for n in 1..=14 {
        s += if n > 6 { -0.05 } else { 0.05 };
        player.sample(s, &options);
        let expected = 0.2 + 0.7 * (f64::from(n) * 0.05 / 0.5).min(1.0);
        assert!((weight(&player) - expected).abs() < 1e-6, "tick {n}: {} vs {expected}", weight(&player));
        if n == 4 {
            for _ in 0..3 {
                player.sample(s, &options); // paused: the ramp holds
                assert!((weight(&player) - expected).abs() < 1e-6);
            }
        }
    }
    // Duration 0 sets the weight at once.
    player.ramp(1, 0.3, 0.0).unwrap();
    player.sample(s + 0.05, &options);
    assert!((weight(&player) - 0.3).abs() < 1e-7, "{}", weight(&player));
}

#[test]
fn a_ramp_changes_the_sync_phase_rate_without_a_jump() {
    // walk (1 s) and run (0.5 s) in one group; run ramps 0 → 1, so the
    // group's cycle goes from 1 s to 0.5 s. The phase integrates the rate
    // of the weights shown at each tick over the next interval.
    let (walk, run) = (body("walk", 1.0, 0.0, 1.0, 0.0), body("run", 0.5, 0.0, 1.0, 0.0));
    let synced = |clip, weight| LayerSpec { sync: Some("g".into()), weight, ..LayerSpec::new(clip) };
    let motion = Arc::new(
        Motion::build(MotionSpec {
            layers: vec![synced(&walk, 1.0), synced(&run, 0.0)],
            root_motion: None,
            ..Default::default()
        })
        .unwrap(),
    );
    let cycle = |w: f64| (1.0 - w) * 1.0 + w * 0.5; // shares 1 − w and w
    let mut player = Player::new(motion);
    let (dt, options) = (0.03, MotionOptions::default());
    player.sample(0.3, &options);
    let mut phase = 0.3; // φ_0 = 0, D = 1
    assert!((player.first_layer_position().x - phase).abs() < 1e-12);
    player.ramp(1, 1.0, 0.4).unwrap();
    let mut shown = 0.0;
    let mut s = 0.3;
    for n in 1..=30 {
        s += dt;
        player.sample(s, &options);
        phase += dt / cycle(shown);
        shown = (f64::from(n) * dt / 0.4).min(1.0);
        let x = player.first_layer_position().x;
        assert!((x - phase).abs() < 1e-6, "tick {n}: phase {x} vs {phase}");
    }
    // A phase recomputed from the current weights (φ_0 + τ/D) would have jumped.
    let recomputed = s / cycle(1.0);
    assert!((recomputed - phase).abs() > 0.1, "the test tells the two apart: {recomputed} vs {phase}");
}

#[test]
fn a_seek_shows_the_given_motion_time_and_moves_a_fade_with_it() {
    let mut rng = Rng::new(1720);
    let pool = Pool::shared_skeleton(&mut rng, 3, 6);
    let (la, lb) = (random_layers(&mut rng, &pool), random_layers(&mut rng, &pool));
    let (a, b): (Shared, Shared) = (Arc::new(pool.motion(&la)), Arc::new(pool.motion(&lb)));
    let options = MotionOptions::default();
    let mut player = Player::new(a.clone());
    for k in 0..5 {
        player.sample(f64::from(k) * 0.04, &options);
    }
    player.seek(2.5);
    player.sample(0.2, &options);
    assert!((player.motion_time() - 2.5).abs() < 1e-12);
    assert_eq!(player.pose(), &alone(&a, 2.5, Ease::Linear), "a seek's tick is the motion at that time, exactly");
    player.sample(0.24, &options);
    assert!((player.motion_time() - 2.54).abs() < 1e-12);
    assert!(pose_err(player.pose(), &f64_pose(&alone(&a, 2.54, Ease::Linear))) <= TOLERANCE);

    // During a fade: B shows the seek's time, A jumps by as much, α holds for the tick.
    player.crossfade(b.clone(), 0.5, Ease::Linear).unwrap();
    player.sample(0.28, &options); // first tick: B at 0, A at 2.58
    player.sample(0.38, &options); // B at 0.1, A at 2.68, α = 0.2
    let alpha = player.alpha();
    player.seek(1.0);
    player.sample(0.42, &options);
    assert_eq!(player.alpha(), alpha, "a seek does not advance the fade");
    assert!((player.motion_time() - 1.0).abs() < 1e-12);
    let expected = mix(
        &f64_pose(&alone(&a, 2.68 + (1.0 - 0.1), Ease::Linear)),
        &f64_pose(&alone(&b, 1.0, Ease::Linear)),
        f64::from(alpha),
    );
    let err = pose_err(player.pose(), &expected);
    assert!(err <= TOLERANCE, "{err:e}");
}

/// A root-motion motion of one looping layer.
fn walking(clip: &Clip) -> Shared<'_> {
    let layer = LayerSpec { playback: Some(Playback::Loop), ..LayerSpec::new(clip) };
    Arc::new(
        Motion::build(MotionSpec {
            layers: vec![layer],
            root_motion: Some(RootMotionSpec::default()),
            ..Default::default()
        })
        .unwrap(),
    )
}

fn ground(p: Planar) -> Ground {
    Ground { x: p.translation.x, z: p.translation.z, yaw: p.yaw }
}

fn assert_planar(got: Planar, expected: Ground, what: &str) {
    let g = ground(got);
    for (a, b) in [(g.x, expected.x), (g.z, expected.z), (g.yaw, expected.yaw)] {
        assert!((a - b).abs() <= TOLERANCE * b.abs().max(1.0), "{what}: {g:?} vs {expected:?}");
    }
}

#[test]
fn root_motion_deltas_are_lerped_across_a_fade_and_the_total_accumulates() {
    let straight = travel(1.0, Vec3::new(2.0, 0.0, 0.0), 0.0);
    let turning = travel(0.8, Vec3::new(0.0, 0.0, 1.5), 0.6);
    let (a, b) = (walking(&straight), walking(&turning));
    let (dt, duration, start) = (0.05, 0.6 + 0.025, 12);
    let mut player = Player::new(a.clone());
    let (mut a_alone, mut b_alone) = (MotionSampler::new(), MotionSampler::new());
    let mut total = Ground::ID;
    let options = MotionOptions::default();
    for k in 0..40 {
        let s = f64::from(k) * dt;
        if k == start {
            player.crossfade(b.clone(), duration, Ease::EaseInOut).unwrap();
        }
        player.sample(s, &options);
        a.sample(s, &options, &mut a_alone);
        let da = ground(a_alone.root_motion().unwrap().delta);
        let delta = if k < start {
            da
        } else {
            let fade_start = f64::from(start) * dt;
            b.sample(s - fade_start, &options, &mut b_alone);
            let db = ground(b_alone.root_motion().unwrap().delta);
            let w = alpha(Ease::EaseInOut, s - fade_start, duration);
            Ground { x: da.x + (db.x - da.x) * w, z: da.z + (db.z - da.z) * w, yaw: da.yaw + (db.yaw - da.yaw) * w }
        };
        total = total.then(delta);
        let got = player.root_motion().expect("root motion");
        assert_planar(got.delta, delta, &format!("delta at tick {k}"));
        assert_planar(got.total, total, &format!("total at tick {k}"));
    }
    assert!(total.x > 1.0 && total.z > 1.0 && total.yaw > 0.5, "both sides travelled: {total:?}");
    // A seek has no delta; the total stays.
    player.seek(0.1);
    player.sample(2.0, &options);
    let got = player.root_motion().unwrap();
    assert_eq!(got.delta, Planar::IDENTITY);
    assert_planar(got.total, total, "total after a seek");
}

/// `push_crossfade` keeps a list of the player's motions as its crossfades
/// do: one more than its fades, the newest, while no fade ends.
#[test]
fn a_list_pushed_by_push_crossfade_holds_the_players_motions() {
    let clips = [body("a", 1.0, 0.0, 2.0, 0.3), body("b", 0.7, 5.0, 6.0, 1.0)];
    let motions: Vec<Shared> = clips.iter().map(ping_pong).collect();
    let mut player = Player::new(motions[0].clone());
    let (mut all, mut targets) = (std::collections::VecDeque::from([0]), std::collections::VecDeque::new());
    for i in 1..=3 * MAX_FADES {
        player.crossfade(motions[i % 2].clone(), 60.0, Ease::Linear).unwrap();
        push_crossfade(&mut all, i);
        push_crossfade(&mut targets, i);
        assert_eq!(all.len(), player.fades() + 1, "after crossfade {i}");
        assert_eq!(all.len(), (i + 1).min(MAX_FADES + 1));
        assert_eq!((all.back(), all.front()), (Some(&i), Some(&(i + 1).saturating_sub(MAX_FADES + 1))));
        assert_eq!(targets.len(), i.min(MAX_FADES + 1), "the targets alone: the latest the player can hold");
        assert_eq!(targets.back(), Some(&i));
    }
}

#[test]
fn many_crossfades_keep_at_most_max_fades() {
    let clips = [body("a", 1.0, 0.0, 2.0, 0.3), body("b", 0.7, 5.0, 6.0, 1.0), body("c", 1.3, -4.0, -3.0, -1.2)];
    let motions: Vec<Shared> = clips.iter().map(ping_pong).collect();
    let mut player = Player::new(motions[0].clone());
    let options = MotionOptions::default();
    let (mut s, mut most) = (0.0, 0);
    for i in 0..4 * MAX_FADES {
        player.crossfade(motions[i % 3].clone(), 1.0, Ease::Linear).unwrap();
        most = most.max(player.fades());
        if i % 3 != 2 {
            s += 0.01;
            player.sample(s, &options);
            most = most.max(player.fades());
        }
        assert!(player.fades() <= MAX_FADES, "{} fades after crossfade {i}", player.fades());
        assert!(player.pose().translations.iter().all(|t| t.is_finite()));
    }
    assert_eq!(most, MAX_FADES, "the bound is reached, not just respected");
    for _ in 0..110 {
        s += 0.01;
        player.sample(s, &options);
    }
    assert_eq!(player.fades(), 0, "all fades end after their duration");
}

#[test]
fn refusals_say_why_and_change_nothing() {
    let a = body("a", 1.0, 0.0, 2.0, 0.3);
    let (zero, one) = (body("zero", 1.0, 0.0, 0.0, 0.0), body("one", 1.0, 1.0, 1.0, 0.0));
    let mut player = Player::new(weight_meter(&zero, &one, 0.5));
    let options = MotionOptions::default();
    player.sample(0.0, &options);
    assert_eq!(player.ramp(2, 0.5, 1.0), Err(PlayerError::NoSuchLayer { index: 2, layers: 2 }));
    assert_eq!(player.ramp(0, 1.5, 1.0), Err(PlayerError::Weight(1.5)));
    assert_eq!(player.ramp(0, -0.1, 1.0), Err(PlayerError::Weight(-0.1)));
    assert!(matches!(player.ramp(0, f32::NAN, 1.0), Err(PlayerError::Weight(w)) if w.is_nan()));
    for bad in [-0.5, f64::INFINITY] {
        assert_eq!(player.ramp(1, 0.5, bad), Err(PlayerError::Duration(bad)));
        assert_eq!(player.crossfade(ping_pong(&a), bad, Ease::Linear), Err(PlayerError::Duration(bad)));
    }
    assert!(matches!(player.ramp(1, 0.5, f64::NAN), Err(PlayerError::Duration(d)) if d.is_nan()));
    assert!(
        matches!(player.crossfade(ping_pong(&a), f64::NAN, Ease::Linear), Err(PlayerError::Duration(d)) if d.is_nan())
    );
    // Another skeleton: the travel clip's hips → leg, not the body's four joints.
    let other = travel(1.0, Vec3::X, 0.0);
    assert_eq!(player.crossfade(ping_pong(&other), 0.5, Ease::Linear), Err(PlayerError::Skeleton));
    // Same names, another hierarchy: also refused.
    let mut renamed = ClipSpec {
        name: "flat".into(),
        skeleton: None,
        tracks: vec![],
        events: vec![],
        playback: Playback::Loop,
        ..Default::default()
    };
    for name in ["hips", "spine", "arm", "leg"] {
        renamed.tracks.push(TrackSpec::new(
            name,
            Channel::Rotation,
            Interpolation::Linear,
            vec![0.0],
            Keys::Vec4(vec![Quat::IDENTITY.into()]),
        ));
    }
    let flat = Clip::build(&renamed).unwrap();
    assert_eq!(player.crossfade(ping_pong(&flat), 0.5, Ease::Linear), Err(PlayerError::Skeleton));
    // Nothing changed: no fade, the weight still 0.5.
    player.sample(0.1, &options);
    assert_eq!(player.fades(), 0);
    assert!((player.pose().translations[0].x - 0.5).abs() < 1e-7);
}
