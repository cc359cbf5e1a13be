//! The chain solver (docs/ik.md, “Constraints”, `chain`) on random chains and trees with
//! limits: every iterate inside the limits with `E` never rising (budgets
//! `k = 0, 1, 2, …` return iterates `k`), reachable targets converging,
//! agreement with the analytic two-bone solver, and with seed 003's own
//! algorithm — projected gradient descent with a finite-difference
//! gradient — implemented here in `f64`.

use anim::ik::{
    Chain, ChainStart, DEFAULT_MAX_ITERATIONS, Effector, IkConstraint, IkReport, IkSolver, JointLimits, TwoBone,
};
use anim::{Clip, Pose, Skeleton};
use glam::{DQuat, DVec3, Quat, Vec3A};

use super::{J, M, body, d, joint, model_with};
use crate::random::Rng;

/// A chain problem with what the test knows independently of the solver:
/// the movable joints (the documented default rule), each angle's bounds, and the
/// chain's length.
struct Problem {
    clip: Clip,
    chain: Chain,
    movable: Vec<usize>,
    min: Vec<f64>,
    max: Vec<f64>,
    length: f64,
}

impl Problem {
    fn skeleton(&self) -> &Skeleton {
        self.clip.skeleton()
    }

    fn rest(&self) -> &Pose {
        self.skeleton().rest()
    }

    /// Model transforms for the angles `a` (three per movable joint), `f64`.
    fn model(&self, a: &[f64]) -> Vec<M> {
        let rest = self.rest();
        model_with(self.skeleton(), rest, |j| {
            let q = rest.rotations[j].as_dquat();
            match self.movable.iter().position(|&m| m == j) {
                Some(k) => q * euler(&a[3 * k..3 * k + 3]),
                None => q,
            }
        })
    }

    /// `E(a) = Σ_b ‖x_b(a) − target_b‖²`.
    fn energy(&self, a: &[f64]) -> f64 {
        let model = self.model(a);
        self.chain.effectors.iter().map(|e| (tip(&model[e.joint], e.tip) - d(e.target)).length_squared()).sum()
    }

    fn project(&self, a: &mut [f64]) {
        for (i, v) in a.iter_mut().enumerate() {
            *v = v.max(self.min[i]).min(self.max[i]);
        }
    }

    fn tolerance(&self) -> f64 {
        1e-4 * self.length
    }
}

fn euler(a: &[f64]) -> DQuat {
    DQuat::from_rotation_x(a[0]) * DQuat::from_rotation_y(a[1]) * DQuat::from_rotation_z(a[2])
}

fn tip(m: &M, tip: Vec3A) -> DVec3 {
    m.t + m.q * (m.s * d(tip))
}

/// The default of docs/ik.md, “Constraints”: every ancestor of an effector, plus each effector
/// whose tip is not the origin; in skeleton order.
fn default_movable(skeleton: &Skeleton, effectors: &[Effector]) -> Vec<usize> {
    let mut movable = vec![false; skeleton.len()];
    for e in effectors {
        movable[e.joint] |= e.tip != Vec3A::ZERO;
        let mut j = skeleton.parent(e.joint);
        while let Some(p) = j {
            movable[p] = true;
            j = skeleton.parent(p);
        }
    }
    (0..skeleton.len()).filter(|&j| movable[j]).collect()
}

/// The longest sum of bone lengths from a movable joint down to a tip.
fn chain_length(skeleton: &Skeleton, model: &[M], effectors: &[Effector], movable: &[usize]) -> f64 {
    let mut longest = 0.0f64;
    for e in effectors {
        let (mut j, mut sum) = (e.joint, (model[e.joint].s * d(e.tip)).length());
        loop {
            if movable.contains(&j) {
                longest = longest.max(sum);
            }
            let Some(p) = skeleton.parent(j) else { break };
            sum += (model[p].s * skeleton.rest().translations[j].as_dvec3()).length();
            j = p;
        }
    }
    longest
}

/// A serial chain of 3–7 joints with one effector, a spine with two arms
/// and an effector on each, or an upper body of 12 joints reaching with
/// both hands; tips half the time; limits on most movable joints; targets
/// where angles `|a| ≤ 1` inside the limits put the tips, so every problem
/// is reachable.
fn problem(rng: &mut Rng) -> Problem {
    let tree = |rng: &mut Rng, parents: &[Option<usize>]| parents.iter().map(|&p| joint(rng, p)).collect::<Vec<J>>();
    let (joints, ends) = match rng.below(3) {
        0 => {
            let n = 3 + rng.below(5);
            let js: Vec<J> = (0..n).map(|i| joint(rng, i.checked_sub(1))).collect();
            (js, vec![n - 1])
        }
        1 => {
            let parents = [None, Some(0), Some(1), Some(2), Some(3), Some(4), Some(2), Some(6), Some(7), Some(0)];
            (tree(rng, &parents), vec![5, 8])
        }
        _ => {
            let parents = [
                None,
                Some(0),
                Some(1),
                Some(2),
                Some(3),
                Some(4),
                Some(5),
                Some(6),
                Some(3),
                Some(8),
                Some(9),
                Some(10),
            ];
            (tree(rng, &parents), vec![7, 11])
        }
    };
    let clip = body(&joints);
    let effectors: Vec<Effector> = ends
        .iter()
        .map(|&joint| {
            let tip = if rng.chance(0.5) { Vec3A::from(super::bone(rng)) } else { Vec3A::ZERO };
            Effector { joint, target: Vec3A::ZERO, tip }
        })
        .collect();
    let movable = default_movable(clip.skeleton(), &effectors);
    let (mut min, mut max, mut limits) = (Vec::new(), Vec::new(), Vec::new());
    for &j in &movable {
        if rng.chance(0.7) {
            let lo: [f32; 3] = std::array::from_fn(|_| rng.range(-1.6, -0.2) as f32);
            let hi: [f32; 3] = std::array::from_fn(|_| rng.range(0.2, 1.6) as f32);
            limits.push(JointLimits { joint: j, min: lo, max: hi });
            min.extend(lo.map(f64::from));
            max.extend(hi.map(f64::from));
        } else {
            min.extend([f64::NEG_INFINITY; 3]);
            max.extend([f64::INFINITY; 3]);
        }
    }
    let chain = Chain { limits, ..Chain::new(effectors) };
    let mut p = Problem { clip, chain, movable, min, max, length: 0.0 };
    let goal: Vec<f64> = (0..p.min.len()).map(|i| rng.range(p.min[i].max(-1.0), p.max[i].min(1.0))).collect();
    let model = p.model(&goal);
    for e in &mut p.chain.effectors {
        e.target = Vec3A::from(tip(&model[e.joint], e.tip).as_vec3());
    }
    p.length = chain_length(p.skeleton(), &model, &p.chain.effectors, &p.movable);
    p
}

/// Solves `p` (with `chain` in place of its own, if given) from `start`;
/// returns the report and the angles found.
fn run(solver: &mut IkSolver, p: &Problem, chain: &Chain, start: ChainStart) -> (IkReport, Pose, Vec<f64>) {
    let (mut pose, mut reports) = (p.rest().clone(), Vec::new());
    solver.solve(p.skeleton(), &mut pose, &[IkConstraint::Chain(chain.clone())], start, &mut reports);
    let (joints, angles) = solver.chain_angles(0).expect("a chain's angles");
    assert_eq!(joints, p.movable.as_slice(), "the movable joints");
    (reports[0], pose, angles.iter().map(|&a| f64::from(a)).collect())
}

#[test]
fn every_iterate_is_inside_the_limits_and_the_energy_never_rises() {
    let mut rng = Rng::new(1801);
    let mut solver = IkSolver::new();
    for case in 0..40 {
        let mut p = problem(&mut rng);
        if case % 3 == 0 {
            // Out of reach: the solve must still only go down.
            for e in &mut p.chain.effectors {
                e.target *= 3.0;
            }
        }
        let (mut previous, mut previous_energy) = (f32::INFINITY, f64::INFINITY);
        for k in 0..=30 {
            let chain = Chain { max_iterations: k, ..p.chain.clone() };
            let (report, pose, a) = run(&mut solver, &p, &chain, ChainStart::Cold);
            for (i, &v) in a.iter().enumerate() {
                assert!(p.min[i] <= v && v <= p.max[i], "case {case}, iterate {k}: angle {i} = {v} out of limits");
            }
            let energy = p.energy(&a);
            let slack = 2e-6 * p.length * previous_energy.sqrt() + 1e-12 * p.length * p.length;
            assert!(energy <= previous_energy + slack, "case {case}: E rose at iterate {k}");
            assert!(report.residual <= previous, "case {case}: the residual rose at iterate {k}");
            assert!(report.iterations <= k, "case {case}");
            let true_residual = p.energy_of_pose(&pose).sqrt();
            assert!((f64::from(report.residual) - true_residual).abs() <= 1e-5 * p.length, "case {case}: {report:?}");
            (previous, previous_energy) = (report.residual, energy);
            if report.iterations < k {
                break;
            }
        }
    }
}

impl Problem {
    /// `E` of a solved local pose (the rotations as written).
    fn energy_of_pose(&self, pose: &Pose) -> f64 {
        let model = super::model_f64(self.skeleton(), pose);
        self.chain.effectors.iter().map(|e| (tip(&model[e.joint], e.tip) - d(e.target)).length_squared()).sum()
    }
}

#[test]
fn reachable_targets_converge_within_the_default_budget() {
    let mut rng = Rng::new(1802);
    let mut solver = IkSolver::new();
    let (total, mut converged, mut iterations) = (1000, 0, 0);
    for case in 0..total {
        let p = problem(&mut rng);
        let (report, pose, _) = run(&mut solver, &p, &p.chain, ChainStart::Cold);
        let residual = p.energy_of_pose(&pose).sqrt();
        assert!((f64::from(report.residual) - residual).abs() <= 1e-5 * p.length, "case {case}: {report:?}");
        if report.converged {
            assert!(residual <= p.tolerance() * (1.0 + 1e-3), "case {case}: converged at {residual:e}");
            converged += 1;
            iterations += report.iterations;
        } else {
            assert!(report.iterations <= DEFAULT_MAX_ITERATIONS, "case {case}");
            assert!(residual > p.tolerance() * (1.0 - 1e-3), "case {case}: not converged at {residual:e}");
        }
    }
    let rate = f64::from(converged) / f64::from(total);
    println!("chain: {converged}/{total} converged, {:.1} iterations on average", iterations as f64 / converged as f64);
    assert!(rate >= 0.95, "only {converged} of {total} reachable problems converged");
}

#[test]
fn an_unlimited_two_bone_chain_agrees_with_the_analytic_solver() {
    let mut rng = Rng::new(1803);
    for case in 0..100 {
        let js =
            vec![joint(&mut rng, None), joint(&mut rng, Some(0)), joint(&mut rng, Some(1)), joint(&mut rng, Some(2))];
        let clip = body(&js);
        let skeleton = clip.skeleton();
        let rest = skeleton.rest().clone();
        let model = super::model_f64(skeleton, &rest);
        let (a, b, c) = (model[1].t, model[2].t, model[3].t);
        let (l1, l2) = ((b - a).length(), (c - b).length());
        let (lo, hi) = ((l1 - l2).abs(), l1 + l2);
        let reachable = case % 4 != 0;
        let distance = if reachable { lo + (hi - lo) * rng.range(0.05, 0.95) } else { hi * rng.range(1.1, 2.0) };
        let target = Vec3A::from((a + rng.axis().as_dvec3() * distance).as_vec3());
        let mut analytic = rest.clone();
        super::solve(skeleton, &mut analytic, &[IkConstraint::TwoBone(TwoBone::new([1, 2, 3], target))]);
        let effector = Effector { joint: 3, target, tip: Vec3A::ZERO };
        let chain = Chain { joints: Some(vec![1, 2]), tolerance: Some(1e-5 * hi as f32), ..Chain::new(vec![effector]) };
        let mut numeric = rest.clone();
        let report = super::solve(skeleton, &mut numeric, &[IkConstraint::Chain(chain)])[0];
        let ends = [&analytic, &numeric].map(|pose| super::model_f64(skeleton, pose)[3].t);
        let gap = (ends[0] - ends[1]).length();
        // Reachable: both on the target. Out of reach: both at the nearest point, the chain's
        // sideways only as well as f32 positions resolve E there (a sideways miss g raises E by
        // about g², below the rounding of E ≈ |target − a|² once g ≲ 1e-3).
        let bound = if reachable { 2e-5 * hi } else { 1e-3 * hi };
        assert!(gap <= bound, "case {case}: ends {gap:e} apart (l1 + l2 = {hi}), {report:?}");
        assert_eq!(report.converged, reachable, "case {case}: {report:?}");
    }
}

/// Seed 003's solver: projected gradient descent on `E` with a
/// finite-difference gradient (`h = 1e-7`), a step kept only if `E`
/// decreases (halved until it does, doubled after), from `a = 0`.
/// Returns the final `E` and the iterations it took.
fn seed_descent(p: &Problem, max_iterations: usize) -> (f64, usize) {
    const H: f64 = 1e-7;
    let n = 3 * p.movable.len();
    let mut a = vec![0.0; n];
    p.project(&mut a);
    let mut energy = p.energy(&a);
    let mut step = 1.0 / (p.length * p.length);
    let (mut gradient, mut probe) = (vec![0.0; n], vec![0.0; n]);
    for iteration in 0..max_iterations {
        if energy.sqrt() <= p.tolerance() {
            return (energy, iteration);
        }
        for i in 0..n {
            probe.copy_from_slice(&a);
            probe[i] += H;
            gradient[i] = (p.energy(&probe) - energy) / H;
        }
        loop {
            probe.iter_mut().zip(&a).zip(&gradient).for_each(|((t, a), g)| *t = a - step * g);
            p.project(&mut probe);
            let lower = p.energy(&probe);
            if lower < energy {
                (a, probe, energy, step) = (probe.clone(), a, lower, step * 2.0);
                break;
            }
            step *= 0.5;
            if step < 1e-30 {
                return (energy, iteration);
            }
        }
    }
    (energy, max_iterations)
}

#[test]
fn the_seeds_projected_gradient_descent_and_the_solver_agree_where_it_converges() {
    let mut rng = Rng::new(1804);
    let mut solver = IkSolver::new();
    let (mut compared, mut seed_iterations, mut our_iterations) = (0, 0, 0);
    for case in 0..80 {
        let p = problem(&mut rng);
        let (seed_energy, iterations) = seed_descent(&p, 10_000);
        if seed_energy.sqrt() > p.tolerance() {
            continue;
        }
        let (report, pose, _) = run(&mut solver, &p, &p.chain, ChainStart::Cold);
        let ours = p.energy_of_pose(&pose).sqrt();
        assert!(report.converged && ours <= p.tolerance() * (1.0 + 1e-3), "case {case}: {ours:e} vs the seed's");
        compared += 1;
        seed_iterations += iterations;
        our_iterations += report.iterations as usize;
    }
    println!("seed descent: {seed_iterations} iterations over {compared} problems, the solver {our_iterations}");
    assert!(compared >= 8, "the reference converged on only {compared} problems");
}

#[test]
fn the_default_tolerance_is_a_ten_thousandth_of_the_chain_and_the_solve_stops_there() {
    // Three unit bones up y and a tip of 0.5: the chain is 3.5 long.
    let j = |parent, y| J { parent, t: glam::Vec3::new(0.0, y, 0.0), q: Quat::IDENTITY, s: 1.0 };
    let clip = body(&[j(None, 0.0), j(Some(0), 1.0), j(Some(1), 1.0), j(Some(2), 1.0)]);
    let target = Vec3A::new(1.2, 2.0, 0.7);
    let effector = Effector { joint: 3, target, tip: Vec3A::new(0.0, 0.5, 0.0) };
    let chain = Chain::new(vec![effector]);
    let solve_with = |max_iterations| {
        let mut pose = clip.skeleton().rest().clone();
        let c = IkConstraint::Chain(Chain { max_iterations, ..chain.clone() });
        super::solve(clip.skeleton(), &mut pose, &[c])[0]
    };
    let done = solve_with(100);
    assert!(done.converged && done.residual <= 3.5e-4 && done.iterations > 0, "{done:?}");
    let before = solve_with(done.iterations - 1);
    assert!(!before.converged && before.residual > 3.5e-4, "{before:?}");
}

#[test]
fn warm_starts_follow_a_moving_target_in_fewer_iterations() {
    let mut rng = Rng::new(1805);
    let (mut warm_total, mut cold_total) = (0, 0);
    for case in 0..40 {
        let p = problem(&mut rng);
        let mut solver = IkSolver::new();
        let (first, ..) = run(&mut solver, &p, &p.chain, ChainStart::Cold);
        if !first.converged {
            continue;
        }
        let mut moved = p.chain.clone();
        let shift = Vec3A::from(rng.vec3(0.02 * p.length));
        moved.effectors.iter_mut().for_each(|e| e.target += shift);
        let (warm, ..) = run(&mut solver, &p, &moved, ChainStart::Warm);
        let (cold, ..) = run(&mut IkSolver::new(), &p, &moved, ChainStart::Cold);
        assert!(warm.converged || !cold.converged, "case {case}: warm {warm:?}, cold {cold:?}");
        warm_total += warm.iterations;
        cold_total += cold.iterations;
    }
    println!("iterations after a small move: warm {warm_total}, cold {cold_total}");
    assert!(2 * warm_total < cold_total, "warm {warm_total} vs cold {cold_total}");
}

#[test]
fn a_warm_start_for_other_joints_is_a_cold_start_and_solves_are_deterministic() {
    let mut rng = Rng::new(1806);
    let p = problem(&mut rng);
    let mut solver = IkSolver::new();
    let (cold, cold_pose, _) = run(&mut IkSolver::new(), &p, &p.chain, ChainStart::Cold);
    let (again, again_pose, _) = run(&mut solver, &p, &p.chain, ChainStart::Cold);
    assert_eq!((cold, &cold_pose), (again, &again_pose));
    // The solver now holds angles for `p`'s joints; a chain over fewer joints must not use them.
    let fewer = Chain { joints: Some(p.movable[1..].to_vec()), ..p.chain.clone() };
    let mut pose = p.rest().clone();
    let (mut reports, mut fresh_reports) = (Vec::new(), Vec::new());
    solver.solve(p.skeleton(), &mut pose, &[IkConstraint::Chain(fewer.clone())], ChainStart::Warm, &mut reports);
    let mut fresh = p.rest().clone();
    let c = [IkConstraint::Chain(fewer)];
    IkSolver::new().solve(p.skeleton(), &mut fresh, &c, ChainStart::Cold, &mut fresh_reports);
    assert_eq!((reports, pose), (fresh_reports, fresh));
}

#[test]
fn only_movable_joints_turn_and_weight_zero_changes_nothing() {
    let mut rng = Rng::new(1807);
    for _ in 0..20 {
        let p = problem(&mut rng);
        let (_, pose, _) = run(&mut IkSolver::new(), &p, &p.chain, ChainStart::Cold);
        for j in (0..pose.len()).filter(|j| !p.movable.contains(j)) {
            assert_eq!(pose.rotations[j], p.rest().rotations[j], "joint {j} is not movable");
        }
        assert_eq!((&pose.translations, &pose.scales), (&p.rest().translations, &p.rest().scales));
        let still = Chain { weight: 0.0, ..p.chain.clone() };
        let (report, pose, _) = run(&mut IkSolver::new(), &p, &still, ChainStart::Cold);
        assert_eq!(&pose, p.rest());
        assert!((f64::from(report.residual) - p.energy_of_pose(&pose).sqrt()).abs() <= 1e-5 * p.length);
    }
}

/// The angle-axis `DQuat` helper above must be the solver's convention:
/// `q_anim·Rx·Ry·Rz` reproduces a solved pose from its angles.
#[test]
fn the_reported_angles_reproduce_the_solved_rotations() {
    let mut rng = Rng::new(1808);
    let p = problem(&mut rng);
    let (_, pose, a) = run(&mut IkSolver::new(), &p, &p.chain, ChainStart::Cold);
    for (k, &j) in p.movable.iter().enumerate() {
        let expected = p.rest().rotations[j].as_dquat() * euler(&a[3 * k..3 * k + 3]);
        let gap = super::quat_angle(expected, pose.rotations[j].as_dquat());
        assert!(gap <= 2e-6, "joint {j}: {gap:e} rad apart");
    }
}

#[path = "../../../benches/ik/body.rs"]
mod bench_body;

/// The benchmark's body reaching with both hands (ten movable joints, 30
/// angles within ±1.5 rad, arms starting straight): the problems `cargo
/// bench --bench ik` times, and the ones that showed a step must drop the
/// angles it would push out of their limits, not just clip them.
#[test]
fn the_benchmark_body_reaches_with_both_hands() {
    let clip = bench_body::body();
    let (skeleton, rest) = (clip.skeleton(), clip.skeleton().rest());
    let mut rng = bench_body::Rng(0xC4A1);
    let (total, mut converged) = (400, 0);
    let (mut solver, mut reports) = (IkSolver::new(), Vec::new());
    for case in 0..total {
        let chain = bench_body::hands_chain(bench_body::reachable_targets(skeleton, rest, &mut rng));
        let mut pose = rest.clone();
        solver.solve(skeleton, &mut pose, &[IkConstraint::Chain(chain.clone())], ChainStart::Cold, &mut reports);
        let model = super::model_f64(skeleton, &pose);
        let residual = chain.effectors.iter().map(|e| (model[e.joint].t - d(e.target)).length_squared()).sum::<f64>();
        assert!((f64::from(reports[0].residual) - residual.sqrt()).abs() < 1e-5, "case {case}: {:?}", reports[0]);
        converged += usize::from(reports[0].converged);
    }
    println!("bench body: {converged}/{total} converged");
    assert!(converged * 100 >= 95 * total, "only {converged} of {total} converged");
}
