//! Inverse kinematics benchmarks (docs/ik.md, issue 17; BENCHMARKS.md).
//!
//! One 20-joint body (`ik/body.rs`: hips, three spine joints, neck, head,
//! two arms of shoulder–upper–fore–hand, two legs of thigh–shin–foot) in a
//! lightly bent pose. Each measured call is one `IkSolver::solve` of one
//! constraint, so it includes walking the joint's ancestry to model space
//! (the analytic solvers work on the pose the previous call left, the
//! chain on a fresh copy of the bent pose, a copy of 20 joints included):
//! - `two_bone`: the left leg to targets around its foot, with a pole;
//! - `aim`: the head at targets ahead, by the smallest rotation and with a
//!   roll (`up`, `up_direction`); `aim_root` aims the hips (no ancestors to
//!   walk), which separates the solve from the walk down the spine;
//! - `chain`: both hands (two effectors, ten movable joints, 30 angles,
//!   limits of ±1.5 rad) to targets made by random in-limit angles, cold
//!   (from the animated pose) and warm (from the previous frame's angles,
//!   the targets moving along a circle of 5 cm radius in 90 frames).
//!
//! The mean iterations and convergence of the chain cases are printed
//! before they are timed.
//!
//! Run: `cargo bench --bench ik`.

extern crate inbetween_anim as anim;

use std::hint::black_box;

use anim::ik::{Aim, ChainStart, IkConstraint, IkReport, IkSolver, TwoBone};
use anim::{Pose, Skeleton};
use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3A;

#[path = "ik/body.rs"]
mod body;

use body::{HEAD, HIPS, LEFT_LEG, Rng, body, hands_chain, model, reachable_targets};

/// Solves one constraint on a fresh copy of `rest`.
fn solve_one(
    solver: &mut IkSolver,
    skeleton: &Skeleton,
    rest: &Pose,
    pose: &mut Pose,
    c: &[IkConstraint; 1],
    start: ChainStart,
    reports: &mut Vec<IkReport>,
) {
    pose.copy_from(rest);
    solver.solve(skeleton, pose, c, start, reports);
}

fn analytic(c: &mut Criterion) {
    let clip = body();
    let (skeleton, rest) = (clip.skeleton(), clip.skeleton().rest());
    let m = model(skeleton, rest);
    let mut rng = Rng(0xA11CE);
    let foot = m.translations[LEFT_LEG[2]];
    let legs: Vec<[IkConstraint; 1]> = (0..256)
        .map(|_| {
            let target = foot + rng.vec3(0.3);
            let pole = Some(m.translations[LEFT_LEG[1]] + Vec3A::new(0.0, 0.0, 1.0));
            [IkConstraint::TwoBone(TwoBone { pole, ..TwoBone::new(LEFT_LEG, target) })]
        })
        .collect();
    let head = m.translations[HEAD];
    let looks: Vec<Vec3A> = (0..256).map(|_| head + Vec3A::new(0.0, 0.0, 2.0) + rng.vec3(1.5)).collect();
    let aims: Vec<[IkConstraint; 1]> = looks.iter().map(|&t| [IkConstraint::Aim(Aim::new(HEAD, t))]).collect();
    let rolled: Vec<[IkConstraint; 1]> = looks
        .iter()
        .map(|&t| {
            let up = Aim { up: Some(Vec3A::Y), up_direction: Some(Vec3A::Y), ..Aim::new(HEAD, t) };
            [IkConstraint::Aim(up)]
        })
        .collect();
    let hips = m.translations[HIPS];
    let root: Vec<[IkConstraint; 1]> =
        looks.iter().map(|&t| [IkConstraint::Aim(Aim::new(HIPS, t - head + hips))]).collect();
    let mut g = c.benchmark_group("ik");
    for (name, cases) in [("two_bone", &legs), ("aim", &aims), ("aim_up", &rolled), ("aim_root", &root)] {
        let (mut solver, mut pose, mut reports, mut k) = (IkSolver::new(), rest.clone(), Vec::new(), 0);
        g.bench_function(name, |b| {
            b.iter(|| {
                k = (k + 1) % cases.len();
                solver.solve(skeleton, &mut pose, &cases[k], ChainStart::Cold, &mut reports);
                black_box(&pose);
            })
        });
    }
    g.finish();
}

/// Mean iterations and converged count of solving `cases` in order.
fn chain_stats(skeleton: &Skeleton, rest: &Pose, cases: &[[IkConstraint; 1]], start: ChainStart) -> (f64, usize) {
    let (mut solver, mut pose, mut reports) = (IkSolver::new(), rest.clone(), Vec::new());
    let (mut iterations, mut converged) = (0u64, 0);
    for c in cases {
        solve_one(&mut solver, skeleton, rest, &mut pose, c, start, &mut reports);
        iterations += u64::from(reports[0].iterations);
        converged += usize::from(reports[0].converged);
    }
    (iterations as f64 / cases.len() as f64, converged)
}

fn chain(c: &mut Criterion) {
    let clip = body();
    let (skeleton, rest) = (clip.skeleton(), clip.skeleton().rest());
    let mut rng = Rng(0xC4A1);
    let cold: Vec<[IkConstraint; 1]> =
        (0..128).map(|_| [IkConstraint::Chain(hands_chain(reachable_targets(skeleton, rest, &mut rng)))]).collect();
    // A dragged target: both hands' goals circle 5 cm around a reachable pair, 4° a frame.
    let centre = reachable_targets(skeleton, rest, &mut rng);
    let warm: Vec<[IkConstraint; 1]> = (0..90)
        .map(|k| {
            let phase = k as f32 * 4f32.to_radians();
            let offset = Vec3A::new(phase.cos(), phase.sin(), 0.0) * 0.05;
            [IkConstraint::Chain(hands_chain([centre[0] + offset, centre[1] - offset]))]
        })
        .collect();
    for (name, cases, start) in [("cold", &cold, ChainStart::Cold), ("warm", &warm, ChainStart::Warm)] {
        let (iterations, converged) = chain_stats(skeleton, rest, cases, start);
        println!("ik/chain_{name}: {iterations:.1} iterations on average, {converged}/{} converged", cases.len());
    }
    let mut g = c.benchmark_group("ik");
    for (name, cases, start) in [("chain_cold", &cold, ChainStart::Cold), ("chain_warm", &warm, ChainStart::Warm)] {
        let (mut solver, mut pose, mut reports, mut k) = (IkSolver::new(), rest.clone(), Vec::new(), 0);
        g.bench_function(name, |b| {
            b.iter(|| {
                k = (k + 1) % cases.len();
                solve_one(&mut solver, skeleton, rest, &mut pose, &cases[k], start, &mut reports);
                black_box(&pose);
            })
        });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(std::time::Duration::from_millis(500)).measurement_time(std::time::Duration::from_secs(2)).sample_size(50);
    targets = analytic, chain
}
criterion_main!(benches);
