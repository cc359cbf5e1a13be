//! Spring chains (docs/springs.md) held to an `f64` run of the same
//! algorithm (`reference`), to themselves at other frame rates, to hand
//! computed collisions, to a pendulum's physics, and to their promises:
//! no chains change nothing, a restored state steps on bit for bit, a
//! frame allocates nothing.

mod graph;
mod player;
mod reference;
mod warmup;

use anim::spring::{
    ChainSpec, ColliderShape, ColliderSpec, JointParams, SpringParams, SpringSolver, Springs, SpringsSpec,
};
use anim::{Channel, Clip, ClipSpec, Interpolation, JointSpec, Keys, Pose, SkeletonSpec, TrackSpec, Transform};
use glam::{DQuat, DVec3, Quat, Vec3, Vec3A};

use self::reference::{RefPose, RefSkeleton, RefSprings};

/// A joint of a test rig: name, parent, rest translation and rotation.
type RigJoint = (&'static str, Option<&'static str>, [f64; 3], DQuat);

/// A rig both sides share: the core's skeleton (through a built clip) and
/// the reference's.
struct Rig {
    clip: Clip,
    reference: RefSkeleton,
}

impl Rig {
    fn new(joints: &[RigJoint]) -> Rig {
        let specs = joints
            .iter()
            .map(|&(name, parent, t, q)| JointSpec {
                name: name.into(),
                parent: parent.map(Into::into),
                rest: Transform { translation: DVec3::from(t).as_vec3(), rotation: q.as_quat(), ..Transform::IDENTITY },
                inverse_bind: None,
            })
            .collect();
        let hold = Keys::Vec3(vec![Vec3::ZERO]);
        let track = TrackSpec::new(joints[0].0, Channel::Translation, Interpolation::Linear, vec![0.0], hold);
        let spec = ClipSpec {
            name: "rig".into(),
            skeleton: Some(SkeletonSpec { joints: specs }),
            tracks: vec![track],
            ..Default::default()
        };
        let names = joints.iter().map(|j| j.0.to_owned()).collect::<Vec<_>>();
        let parents = joints.iter().map(|j| j.1.map(|p| names.iter().position(|n| n == p).unwrap())).collect();
        let reference = RefSkeleton {
            names,
            parents,
            rest_t: joints.iter().map(|j| DVec3::from(j.2)).collect(),
            rest_q: joints.iter().map(|j| j.3).collect(),
        };
        Rig { clip: Clip::build(&spec).unwrap(), reference }
    }

    fn springs(&self, chains: Vec<ChainSpec>) -> Springs {
        Springs::build(&SpringsSpec { chains, ..SpringsSpec::default() }, self.clip.skeleton()).unwrap()
    }

    fn model_positions(&self, local: &Pose) -> Vec<DVec3> {
        let mut model = Pose::default();
        self.clip.skeleton().to_model(local, &mut model);
        model.translations.iter().map(|t| Vec3::from(*t).as_dvec3()).collect()
    }
}

fn to_pose(p: &RefPose) -> Pose {
    let n = p.t.len();
    let mut pose = Pose::identity(n);
    for j in 0..n {
        pose.translations[j] = Vec3A::from(p.t[j].as_vec3());
        pose.rotations[j] = p.q[j].as_quat();
    }
    pose
}

/// A body with a tail of three turning joints (one joint between two of
/// them is skipped, as VRM allows) and a leg that carries a collider.
fn tail_rig() -> Rig {
    let i = DQuat::IDENTITY;
    Rig::new(&[
        ("root", None, [0.0, 0.0, 0.0], i),
        ("body", Some("root"), [0.0, 1.0, 0.0], i),
        ("tail1", Some("body"), [0.0, 0.05, -0.15], i),
        ("tail2", Some("tail1"), [0.0, 0.0, -0.2], DQuat::from_rotation_x(0.4)),
        ("mid", Some("tail2"), [0.0, 0.0, -0.1], i),
        ("tail3", Some("mid"), [0.0, -0.05, -0.12], i),
        ("tip", Some("tail3"), [0.0, 0.0, -0.2], i),
        ("leg", Some("body"), [0.1, -0.5, -0.05], i),
    ])
}

fn tail_chain() -> ChainSpec {
    ChainSpec {
        params: SpringParams { stiffness: 1.0, drag: 0.3, gravity: Vec3::new(0.0, -20.0, 0.0), radius: 0.03 },
        joint_params: vec![(
            "tail3".into(),
            JointParams { drag: Some(0.5), radius: Some(0.01), ..JointParams::default() },
        )],
        colliders: vec![
            ColliderSpec {
                joint: "body".into(),
                shape: ColliderShape::Sphere { offset: Vec3::new(0.0, 0.0, -0.6), radius: 0.07 },
            },
            ColliderSpec {
                joint: "leg".into(),
                shape: ColliderShape::Capsule {
                    offset: Vec3::new(-0.25, 0.6, -0.7),
                    tail: Vec3::new(0.05, 0.6, -0.7),
                    radius: 0.05,
                },
            },
        ],
        ..ChainSpec::new("tail", &["tail1", "tail2", "tail3", "tip"])
    }
}

/// The body swaying, turning and bobbing; the tail joints' own rotation
/// keys (a fixed twist) are there to be ignored.
fn tail_motion(rig: &RefSkeleton, t: f64) -> RefPose {
    let mut pose = RefPose { t: rig.rest_t.clone(), q: rig.rest_q.clone() };
    pose.t[0] = DVec3::new(0.5 * (2.0 * t).sin(), 0.05 * (7.0 * t).sin(), 0.3 * (0.7 * t).sin());
    pose.q[0] = DQuat::from_rotation_y((1.3 * t).sin());
    pose.q[1] = DQuat::from_rotation_x(0.35 * (2.5 * t).sin());
    pose.q[4] = DQuat::from_rotation_y(0.3 * (4.0 * t).sin());
    for j in [2, 3, 5] {
        pose.q[j] = DQuat::from_rotation_z(0.7);
    }
    pose
}

/// Frames at `fps` for `seconds`, each as model positions: the solver's.
fn run(rig: &Rig, springs: &Springs, fps: u32, seconds: u32) -> Vec<(f64, Vec<DVec3>)> {
    let mut solver = SpringSolver::new(springs);
    let motion = |t: f64, pose: &mut Pose| *pose = to_pose(&tail_motion(&rig.reference, t));
    let mut frames = Vec::new();
    for n in 0..=fps * seconds {
        let t = f64::from(n) / f64::from(fps);
        let mut pose = to_pose(&tail_motion(&rig.reference, t));
        solver.frame(springs, t, &mut pose, motion);
        frames.push((t, rig.model_positions(&pose)));
    }
    frames
}

#[test]
fn spring_joints_stay_within_a_millimetre_of_the_f64_reference_over_ten_seconds() {
    let rig = tail_rig();
    let chains = vec![tail_chain()];
    let springs = rig.springs(chains.clone());
    let ours = run(&rig, &springs, 60, 10);
    let hz = springs.substep_hz();
    let mut reference = RefSprings::new(&rig.reference, &chains, hz, &tail_motion(&rig.reference, 0.0));
    let mut k = 1u32;
    let mut worst: f64 = 0.0;
    for (t, positions) in &ours {
        while f64::from(k) / hz <= t + 1e-9 {
            reference.step(&tail_motion(&rig.reference, f64::from(k) / hz));
            k += 1;
        }
        let expected = reference.positions(&tail_motion(&rig.reference, *t));
        for j in 2..7 {
            worst = worst.max(positions[j].distance(expected[j]));
        }
    }
    assert!(reference.pushes > 100, "the colliders must be hit for the test to mean something: {}", reference.pushes);
    assert!(worst < 1e-3, "a spring joint strayed {worst} m from the f64 reference");
    let still = rig.model_positions(&to_pose(&tail_motion(&rig.reference, 10.0)));
    assert!(ours.last().unwrap().1[6].distance(still[6]) > 0.01, "the tail must swing away from its keyed pose");
}

#[test]
fn frame_rates_agree_at_shared_instants() {
    let rig = tail_rig();
    let springs = rig.springs(vec![tail_chain()]);
    let size = 0.8; // the rig's extent, metres
    let base = run(&rig, &springs, 120, 3);
    for fps in [30, 60, 24, 50] {
        let other = run(&rig, &springs, fps, 3);
        let mut shared = 0;
        for (t, positions) in &other {
            let Some((_, expected)) = base.iter().find(|(s, _)| s == t) else { continue };
            if (t * 2.0).fract() != 0.0 {
                continue;
            }
            shared += 1;
            for (a, b) in positions.iter().zip(expected) {
                assert!(a.distance(*b) <= 1e-5 * size, "{fps} fps at {t} s: {a} vs {b}");
            }
        }
        assert_eq!(shared, 7, "{fps} fps shares 0, 0.5, …, 3 s with 120 fps");
    }
}

/// A root holding a chain of `bones` bones of 0.5 m out horizontally: a
/// pendulum.
fn pendulum(bones: usize, drag: f32) -> (Rig, Springs) {
    let i = DQuat::IDENTITY;
    let names = ["a", "b", "c", "d"];
    let mut joints: Vec<RigJoint> = vec![("root", None, [0.0; 3], i), ("a", Some("root"), [0.0; 3], i)];
    for k in 1..=bones {
        joints.push((names[k], Some(names[k - 1]), [0.5, 0.0, 0.0], i));
    }
    let rig = Rig::new(&joints);
    let params = SpringParams { stiffness: 0.0, drag, gravity: Vec3::new(0.0, -9.81, 0.0), radius: 0.0 };
    let springs = rig.springs(vec![ChainSpec { params, ..ChainSpec::new("arm", &names[..=bones]) }]);
    (rig, springs)
}

/// Kinetic plus potential energy per unit mass of the tails, with the
/// velocity of the last substep and the potential at its midpoint.
fn energy(solver: &SpringSolver, hz: f64) -> f64 {
    let state = solver.state();
    (state.current.iter().zip(&state.previous))
        .map(|(c, p)| {
            let v = (Vec3::from(*c - *p)).as_dvec3() * hz;
            0.5 * v.length_squared() + 9.81 * f64::from(c.y + p.y) / 2.0
        })
        .sum()
}

/// Frames at 120 fps (one substep each) of a pendulum on a still root for
/// `seconds`: the energy at each turning point of the last tail (where its
/// horizontal motion reverses), and the final pose in model space.
fn swing(bones: usize, drag: f32, seconds: u32) -> (Vec<f64>, Vec<DVec3>) {
    let (rig, springs) = pendulum(bones, drag);
    let mut solver = SpringSolver::new(&springs);
    let rest = rig.clip.skeleton().rest().clone();
    let still = |_: f64, pose: &mut Pose| pose.copy_from(&rest);
    let (mut turns, mut heading) = (Vec::new(), 0.0f32);
    let mut frame = rest.clone();
    for n in 0..=120 * seconds {
        frame.copy_from(&rest);
        solver.frame(&springs, f64::from(n) / 120.0, &mut frame, still);
        let state = solver.state();
        let dx = state.current[bones - 1].x - state.previous[bones - 1].x;
        if dx * heading < 0.0 {
            turns.push(energy(&solver, springs.substep_hz()));
        }
        if dx != 0.0 {
            heading = dx;
        }
    }
    (turns, rig.model_positions(&frame))
}

#[test]
fn a_pendulum_with_drag_loses_energy_monotonically_and_comes_to_rest_hanging() {
    for drag in [0.001, 0.004, 0.01] {
        // Turns while it still swings (near rest, rounding reverses it at random).
        let (turns, _) = swing(1, drag, 10);
        let turns: Vec<f64> = turns.into_iter().filter(|&e| e > -9.81 * 0.5 + 1e-3).collect();
        assert!(turns.len() >= 3, "drag {drag}: the pendulum must swing: {turns:?}");
        for pair in turns.windows(2) {
            assert!(pair[1] < pair[0], "drag {drag}: energy rose from {} to {} between turns", pair[0], pair[1]);
        }
        assert!(turns[0] > -4.9 + 0.5, "drag {drag}: the first swing keeps energy above hanging: {}", turns[0]);
    }
    for bones in [1, 2, 3] {
        let (_, hanging) = swing(bones, 0.05, 40);
        for k in 1..=bones {
            let expected = DVec3::new(0.0, -0.5 * k as f64, 0.0);
            assert!(
                hanging[k + 1].distance(expected) < 1e-3,
                "{bones} bones: joint {k} at {} not hanging",
                hanging[k + 1]
            );
        }
    }
}

/// One bone from the origin along +x, length 1, that neither swings nor
/// falls (stiffness 0, drag 1), radius 0.1, with one collider on `root`.
fn pushed_once(shape: ColliderShape) -> Vec3A {
    let i = DQuat::IDENTITY;
    let rig = Rig::new(&[
        ("root", None, [0.0; 3], i),
        ("a", Some("root"), [0.0; 3], i),
        ("b", Some("a"), [1.0, 0.0, 0.0], i),
    ]);
    let chain = ChainSpec {
        params: SpringParams { stiffness: 0.0, drag: 1.0, gravity: Vec3::ZERO, radius: 0.1 },
        colliders: vec![ColliderSpec { joint: "root".into(), shape }],
        ..ChainSpec::new("bone", &["a", "b"])
    };
    let springs = rig.springs(vec![chain]);
    let mut solver = SpringSolver::new(&springs);
    let rest = rig.clip.skeleton().rest().clone();
    let still = |_: f64, pose: &mut Pose| pose.copy_from(&rest);
    let mut frame = rest.clone();
    solver.frame(&springs, 0.0, &mut frame, still);
    assert_eq!(frame.rotations[1], Quat::IDENTITY, "the first frame shows the rest pose");
    assert_eq!(solver.state().current[0], Vec3A::X, "at rest the tail is inside the collider, unpushed");
    frame.copy_from(&rest);
    solver.frame(&springs, 1.0 / 120.0, &mut frame, still);
    solver.state().current[0]
}

#[test]
fn tails_are_pushed_out_of_colliders_then_put_back_at_their_length() {
    // The tail at (1, 0, 0) is 0.5 from a centre at (1, −0.5, 0), inside the
    // reach 0.6 + 0.1: pushed straight up to (1, 0.2, 0), then back on the
    // unit sphere about the joint, (1, 0.2, 0)/√1.04, which leaves it
    // 0.69639 from the centre: a little inside, as the algorithm leaves it.
    let up = DVec3::new(1.0, 0.2, 0.0) / 1.04f64.sqrt();
    let centre = DVec3::new(1.0, -0.5, 0.0);
    let sphere = pushed_once(ColliderShape::Sphere { offset: Vec3::new(1.0, -0.5, 0.0), radius: 0.6 });
    assert!(Vec3::from(sphere).as_dvec3().distance(up) < 1e-6, "sphere: {sphere} vs {up}");
    assert!((up.distance(centre) - 0.696_39).abs() < 1e-5);
    // A capsule whose nearest point to the tail is inside its segment acts
    // as that sphere.
    let across =
        ColliderShape::Capsule { offset: Vec3::new(0.5, -0.5, 0.0), tail: Vec3::new(1.5, -0.5, 0.0), radius: 0.6 };
    assert!(Vec3::from(pushed_once(across)).as_dvec3().distance(up) < 1e-6);
    // One whose segment ends at (0.8, −0.5, 0) pushes away from that end.
    let end = DVec3::new(0.8, -0.5, 0.0);
    let delta = DVec3::X - end;
    let pushed = DVec3::X + delta / delta.length() * (0.7 - delta.length());
    let expected = pushed.normalize();
    let short =
        ColliderShape::Capsule { offset: Vec3::new(-1.0, -0.5, 0.0), tail: Vec3::new(0.8, -0.5, 0.0), radius: 0.6 };
    let got = Vec3::from(pushed_once(short)).as_dvec3();
    assert!(got.distance(expected) < 1e-6, "capsule end: {got} vs {expected}");
    // A collider the tail is outside of leaves it alone.
    let far = pushed_once(ColliderShape::Sphere { offset: Vec3::new(3.0, 0.0, 0.0), radius: 0.5 });
    assert_eq!(far, Vec3A::X);
}

#[test]
fn without_chains_the_pose_is_exactly_the_input_pose() {
    let rig = tail_rig();
    let springs = Springs::none(rig.clip.skeleton());
    assert!(springs.is_empty());
    let mut solver = SpringSolver::new(&springs);
    for n in 0..120 {
        let t = f64::from(n) / 60.0;
        let input = to_pose(&tail_motion(&rig.reference, t));
        let mut pose = input.clone();
        solver.frame(&springs, t, &mut pose, |_, _| panic!("no chain needs the motion"));
        assert_eq!(pose, input);
    }
}

#[test]
fn a_solver_restored_from_its_state_makes_the_same_frames_bit_for_bit() {
    let rig = tail_rig();
    let springs = rig.springs(vec![tail_chain()]);
    let motion = |t: f64, pose: &mut Pose| *pose = to_pose(&tail_motion(&rig.reference, t));
    let frame = |solver: &mut SpringSolver, n: u32| {
        let t = f64::from(n) / 50.0;
        let mut pose = to_pose(&tail_motion(&rig.reference, t));
        solver.frame(&springs, t, &mut pose, motion);
        pose
    };
    let mut original = SpringSolver::new(&springs);
    for n in 0..100 {
        frame(&mut original, n);
    }
    let mut restored = SpringSolver::from_state(&springs, original.state()).unwrap();
    for n in 100..250 {
        assert_eq!(frame(&mut original, n), frame(&mut restored, n), "frame {n}");
    }
    // A state of another shape is refused, not trusted.
    let mut wrong = original.state();
    wrong.previous.pop();
    assert!(SpringSolver::from_state(&springs, wrong).is_err());
}

#[test]
fn a_reset_shows_the_rest_pose_and_restarts_from_it() {
    let rig = tail_rig();
    let springs = rig.springs(vec![tail_chain()]);
    let motion = |t: f64, pose: &mut Pose| *pose = to_pose(&tail_motion(&rig.reference, t));
    let mut solver = SpringSolver::new(&springs);
    let mut fresh = SpringSolver::new(&springs);
    let mut pose = Pose::default();
    for n in 0..90 {
        let t = f64::from(n) / 30.0;
        motion(t, &mut pose);
        solver.frame(&springs, t, &mut pose, motion);
    }
    solver.reset();
    let rest = rig.clip.skeleton().rest();
    for n in 90..150 {
        let t = f64::from(n) / 30.0;
        let (mut a, mut b) = (Pose::default(), Pose::default());
        motion(t, &mut a);
        motion(t, &mut b);
        solver.frame(&springs, t, &mut a, motion);
        fresh.frame(&springs, t, &mut b, motion);
        if n == 90 {
            for j in springs.spring_joints() {
                assert_eq!(a.rotations[j], rest.rotations[j], "joint {j} at rest on the reset's frame");
            }
            // The fresh solver starts here too.
        }
        assert_eq!(a, b, "a reset solver is a new one from its frame on");
        if n == 90 {
            fresh = solver.clone();
        }
    }
}

#[test]
fn a_frame_allocates_nothing_once_warm() {
    let rig = tail_rig();
    let springs = rig.springs(vec![tail_chain()]);
    let poses: Vec<Pose> = (0..=240).map(|k| to_pose(&tail_motion(&rig.reference, f64::from(k) / 120.0))).collect();
    let mut solver = SpringSolver::new(&springs);
    let mut pose = poses[0].clone();
    let motion = |t: f64, pose: &mut Pose| pose.copy_from(&poses[(t * 120.0).round() as usize]);
    solver.frame(&springs, 0.0, &mut pose, motion);
    solver.frame(&springs, 1.0 / 60.0, &mut pose, motion);
    let before = crate::allocations();
    for n in 2..=120 {
        let t = f64::from(n) / 60.0;
        pose.copy_from(&poses[2 * n as usize]);
        solver.frame(&springs, t, &mut pose, motion);
    }
    assert_eq!(crate::allocations() - before, 0);
}

#[test]
fn stateless_samples_are_one_run_from_rest_after_the_warmup() {
    let rig = tail_rig();
    let springs = rig.springs(vec![tail_chain()]);
    let motion = |t: f64, pose: &mut Pose| *pose = to_pose(&tail_motion(&rig.reference, t));
    let times = [2.0, 2.25, 2.5, 3.0];
    let from = anim::spring::warmup_start(0.0, times[0], anim::spring::DEFAULT_WARMUP);
    assert_eq!((from, anim::spring::warmup_start(0.0, 0.5, 1.0)), (1.0, 0.0));
    let mut frames = Vec::new();
    SpringSolver::new(&springs).run_from_rest(&springs, from, &times, motion, |_, pose| frames.push(pose.clone()));
    // The same as a stream that reset at `from` and showed these frames.
    let mut stream = SpringSolver::new(&springs);
    let mut pose = Pose::default();
    motion(from, &mut pose);
    stream.frame(&springs, from, &mut pose, motion);
    for (&t, expected) in times.iter().zip(&frames) {
        motion(t, &mut pose);
        stream.frame(&springs, t, &mut pose, motion);
        assert_eq!(&pose, expected, "at {t} s");
    }
    // A pose at the motion's start shows the rest pose.
    let mut at_start = Vec::new();
    SpringSolver::new(&springs).run_from_rest(&springs, 0.0, &[0.0], motion, |_, pose| at_start.push(pose.clone()));
    for j in springs.spring_joints() {
        assert_eq!(at_start[0].rotations[j], rig.clip.skeleton().rest().rotations[j]);
    }
}
