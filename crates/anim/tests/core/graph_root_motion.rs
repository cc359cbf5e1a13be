//! Root motion on a graph (docs/graphs.md, “What composes with a graph”)
//! against a float64 reference written here: a synced 1D blend of two
//! turning walks at a fixed parameter steps, each tick, by its points'
//! deltas over the sync group's phase step, mixed by their blend weights
//! (`Σ w_k · Δ_k`, translation and yaw), a step crossing `n` seams taking
//! `n` whole cycles of each walk; the player allocates nothing per tick
//! through a transition's crossfade.

use std::sync::Arc;

use anim::graph::{
    Blend1dSpec, ClipNodeSpec, Condition, Graph, GraphPlayer, GraphSpec, MachineSpec, NodeKind, NodeOptions, NodeSpec,
    ParameterKind, ParameterSpec, StateSpec, TopSpec, TransitionSpec, Value,
};
use anim::motion::RootMotionSpec;
use anim::{Clip, Ease};
use glam::Vec3;

use crate::allocations;
use crate::root_motion::{Ground, assert_ground, root_ground, travel};

/// Two walks, `(duration, distance on x, turn)`.
const WALKS: [(f32, f32, f32); 2] = [(0.25, 1.0, 0.3), (0.5, 3.0, -0.5)];
/// The blend's parameter: weights `(1 − PACE, PACE)`, exact in f32.
const PACE: f64 = 0.25;

fn walks() -> [Clip; 2] {
    WALKS.map(|(duration, x, turn)| travel(duration, Vec3::new(x, 0.0, 0.0), turn))
}

/// `walk` blends the two on `pace`; the trigger `halt` fades to `stop`
/// (the second alone) over 0.3 s.
fn graph(clips: &[Clip; 2]) -> Arc<Graph<&Clip>> {
    let parameters = vec![
        ParameterSpec { name: "pace".into(), kind: ParameterKind::Float { default: PACE, min: 0.0, max: 1.0 } },
        ParameterSpec { name: "halt".into(), kind: ParameterKind::Trigger },
    ];
    let blend = Blend1dSpec { parameter: 0, points: vec![(0, 0.0), (1, 1.0)], sync: true };
    let nodes = vec![
        NodeSpec { name: "walk".into(), kind: NodeKind::Blend1d(blend) },
        NodeSpec { name: "stop".into(), kind: NodeKind::Clip(ClipNodeSpec { clip: 1, playback: None, speed: 1.0 }) },
    ];
    let halt = TransitionSpec {
        from: Some(0),
        to: 1,
        when: Condition::Trigger(1),
        duration: 0.3,
        ease: Ease::Linear,
        interruptible: true,
    };
    let states = vec![StateSpec { name: "walk".into(), node: 0 }, StateSpec { name: "stop".into(), node: 1 }];
    let top = TopSpec::Machine(MachineSpec { initial: 0, states, transitions: vec![halt] });
    let spec = GraphSpec { parameters, nodes, top };
    let options = NodeOptions { root_motion: Some(RootMotionSpec::default()), ..NodeOptions::default() };
    Arc::new(Graph::build_with(spec, &clips.each_ref().map(|c| c), &options).unwrap())
}

/// The reference delta of one walk from phase `a` to phase `b` (in
/// cycles): `M(c_a)⁻¹·M(end)·Cⁿ⁻¹·M(start)⁻¹·M(c_b)` over `n` seams.
fn walk_delta(clip: &Clip, (a, b): (f64, f64)) -> Ground {
    let duration = f64::from(clip.end());
    let at = |phase: f64| root_ground(clip, (phase.rem_euclid(1.0) * duration) as f32);
    let seams = b.floor() as i64 - a.floor() as i64;
    if seams == 0 {
        return at(a).inverse().then(at(b));
    }
    let (start, end) = (root_ground(clip, 0.0), root_ground(clip, clip.end()));
    // The cycle's yaw is the walk's whole turn (under half a turn: no wrapping to undo).
    let cycle =
        Ground { yaw: f64::from(WALKS.iter().find(|w| w.0 == clip.end()).unwrap().2), ..start.inverse().then(end) };
    let mut delta = at(a).inverse().then(end);
    for _ in 1..seams {
        delta = delta.then(cycle);
    }
    delta.then(start.inverse()).then(at(b))
}

#[test]
fn a_blend_s_root_steps_by_its_walks_deltas_over_the_synced_phase_mixed_by_weight() {
    let clips = walks();
    let graph = graph(&clips);
    let w = [1.0 - PACE, PACE];
    let cycle: f64 = (0..2).map(|k| w[k] * f64::from(WALKS[k].0)).sum();
    for fps in [60.0, 9.0, 1.0] {
        let mut player = GraphPlayer::new(Arc::clone(&graph));
        let mut total = Ground::ID;
        for k in 0..=(4.0 * fps) as u32 {
            player.tick(1.0 / fps);
            let got = player.root_motion().expect("the nodes report root motion");
            if k > 0 {
                let phases = (f64::from(k - 1) / fps / cycle, f64::from(k) / fps / cycle);
                let (a, b) = (walk_delta(&clips[0], phases), walk_delta(&clips[1], phases));
                let mixed = |x: f64, y: f64| w[0] * x + w[1] * y;
                let delta = Ground { x: mixed(a.x, b.x), z: mixed(a.z, b.z), yaw: mixed(a.yaw, b.yaw) };
                assert_ground(got.delta, delta, 1e-4, &format!("{fps} fps, tick {k}'s delta"));
                total = total.then(delta);
            }
            assert_ground(got.total, total, 1e-3, &format!("{fps} fps, tick {k}'s total"));
        }
    }
}

#[test]
fn a_warm_graph_player_with_root_motion_allocates_nothing_per_tick_through_a_crossfade() {
    let clips = walks();
    let mut player = GraphPlayer::new(graph(&clips));
    for _ in 0..3 {
        player.tick(1.0 / 60.0);
    }
    let before = allocations();
    for k in 0..60 {
        if k == 10 {
            player.set(1, Value::Bool(true)).unwrap();
        }
        player.tick(1.0 / 60.0);
        std::hint::black_box((player.pose(), player.root_motion()));
    }
    assert_eq!(allocations() - before, 0, "60 ticks, a transition's crossfade among them");
    assert_eq!(player.current(), 1, "the transition fired");
}
