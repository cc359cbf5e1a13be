//! A motion's IK and springs on a graph's pose (docs/graphs.md, “What
//! composes with a graph”): without them the pose is the graph's exactly;
//! springs on a graph of one clip at one substep per tick are that clip
//! motion's stream; a run restored from its state steps on bit for bit; a
//! two-bone constraint reaches its target with its bones' lengths kept.

use std::sync::Arc;

use anim::graph::{
    ClipNodeSpec, Graph, GraphPlayer, GraphPost, GraphSpec, NodeKind, NodeSpec, PostRun, TickRange, TopSpec,
};
use anim::ik::{IkLimits, IkSpec, TwoBoneSpec};
use anim::spring::{ChainSpec, SpringsSpec};
use anim::{Clip, Pose};
use glam::Vec3;

use super::player::{farthest, model, motion, stream, swinging};

/// A graph whose only node plays `clip`.
fn one_clip(clip: &Clip) -> Arc<Graph<&Clip>> {
    let node =
        NodeSpec { name: "swing".into(), kind: NodeKind::Clip(ClipNodeSpec { clip: 0, playback: None, speed: 1.0 }) };
    let spec = GraphSpec { parameters: Vec::new(), nodes: vec![node], top: TopSpec::Output(0) };
    Arc::new(Graph::build(spec, &[clip]).unwrap())
}

fn tail_springs() -> SpringsSpec {
    let mut chain = ChainSpec::new("tail", &["tail0", "tail1", "tail2", "tip"]);
    chain.params.gravity = Vec3::new(0.0, -9.81, 0.0);
    SpringsSpec { chains: vec![chain], ..SpringsSpec::default() }
}

fn post<'a>(clip: &Clip, ik: &[IkSpec], springs: &SpringsSpec) -> GraphPost<&'a Clip> {
    GraphPost::build(ik, springs, clip.skeleton(), &IkLimits::default()).unwrap()
}

/// Ticks `0..=ticks` of `graph` at `fps` with `post` run on each: the graph's
/// pose and the pose after the stages.
fn play(graph: &Arc<Graph<&Clip>>, post: &GraphPost<&Clip>, fps: u32, ticks: u32) -> Vec<(Pose, Pose)> {
    let (mut player, mut run) = (GraphPlayer::new(Arc::clone(graph)), PostRun::new(post));
    let dt = 1.0 / f64::from(fps);
    (0..=ticks)
        .map(|k| {
            player.tick(dt);
            run.run(
                post,
                graph.skeleton(),
                player.pose(),
                (f64::from(k) / f64::from(fps), f64::from(k) / f64::from(fps)),
            );
            (player.pose().clone(), run.pose().clone())
        })
        .collect()
}

#[test]
fn without_ik_or_springs_the_pose_is_the_graphs_bit_for_bit() {
    let clip = swinging();
    let graph = one_clip(&clip);
    let none = post(&clip, &[], &SpringsSpec::default());
    assert!(none.is_empty());
    for (k, (graph_pose, after)) in play(&graph, &none, 60, 90).iter().enumerate() {
        assert_eq!(graph_pose, after, "tick {k}");
    }
}

#[test]
fn springs_on_a_one_clip_graph_at_one_substep_per_tick_are_the_clip_motions_stream() {
    // At 120 fps and 120 substeps per second every substep lands on a tick,
    // where the clip motion's substep sees its own pose too: the two agree
    // (to the graph's node time, summed tick by tick, against the stream's k/fps).
    let clip = swinging();
    let graph = one_clip(&clip);
    let sprung = post(&clip, &[], &tail_springs());
    let frames = play(&graph, &sprung, 120, 240);
    let reference = stream(&motion(&clip, true), 120, 0.0, 240);
    let mut moved = 0.0f32;
    for (k, ((graph_pose, after), expected)) in frames.iter().zip(&reference).enumerate() {
        let got = model(&clip, after);
        assert!(farthest(&got, &model(&clip, expected)) <= 1e-5, "tick {k}");
        moved = moved.max(farthest(&got, &model(&clip, graph_pose)));
    }
    assert!(moved > 0.01, "the tail swings away from the animated pose (by {moved} m at most)");
}

#[test]
fn a_run_restored_from_its_state_shows_its_tick_and_steps_on_bit_for_bit() {
    let clip = swinging();
    let graph = one_clip(&clip);
    let sprung = post(&clip, &[], &tail_springs());
    let uninterrupted = play(&graph, &sprung, 60, 150);
    let (mut player, mut run) = (GraphPlayer::new(Arc::clone(&graph)), PostRun::new(&sprung));
    let dt = 1.0 / 60.0;
    for k in 0..=70u32 {
        player.tick(dt);
        run.run(&sprung, graph.skeleton(), player.pose(), (f64::from(k) / 60.0, f64::from(k) / 60.0));
    }
    let mut player = GraphPlayer::from_state(Arc::clone(&graph), player.state()).unwrap();
    let mut run = PostRun::from_state(&sprung, run.spring_state()).unwrap();
    run.run(&sprung, graph.skeleton(), player.pose(), (70.0 / 60.0, 70.0 / 60.0));
    assert_eq!(run.pose(), &uninterrupted[70].1, "the restored run shows the tick it was taken after");
    for k in 71..=150u32 {
        player.tick(dt);
        run.run(&sprung, graph.skeleton(), player.pose(), (f64::from(k) / 60.0, f64::from(k) / 60.0));
        assert_eq!(run.pose(), &uninterrupted[k as usize].1, "tick {k}");
    }
    assert!(PostRun::from_state(&sprung, None).is_err(), "springs need their state");
}

#[test]
fn a_two_bone_constraint_on_a_graph_reaches_its_target_and_keeps_the_bones() {
    let clip = swinging();
    let graph = one_clip(&clip);
    let target = Vec3::new(0.08, 0.95, -0.2);
    let joints = ["tail0", "tail1", "tail2"].map(str::to_owned);
    let ik = [IkSpec::TwoBone(TwoBoneSpec { joints, target, pole: None, weight: None })];
    let solved = post(&clip, &ik, &SpringsSpec::default());
    let mut reached = 0;
    for (k, (graph_pose, after)) in play(&graph, &solved, 30, 30).iter().enumerate() {
        let (before, got) = (model(&clip, graph_pose), model(&clip, after));
        for (parent, child) in [(1, 2), (2, 3)] {
            let length = got[parent].distance(got[child]);
            assert!((length - 0.1).abs() <= 1e-5, "tick {k}: bone {parent}→{child} is {length}");
        }
        // Within reach of the chain's root (two bones of 0.1 m), the effector is on the target.
        if before[1].distance(target) <= 0.19 {
            assert!(got[3].distance(target) <= 1e-4, "tick {k}: effector at {:?}", got[3]);
            reached += 1;
        }
        assert_eq!(got[0], before[0], "tick {k}: the body is the graph's");
    }
    assert!(reached >= 5, "the target was within reach on {reached} ticks");
}

#[test]
fn a_request_runs_its_springs_from_rest_a_warmup_before_its_first_tick() {
    let clip = swinging();
    let sprung = post(&clip, &[], &tail_springs());
    let plain = post(&clip, &[], &SpringsSpec::default());
    let range = |start: f64| TickRange::new(start, start + 1.0, 60.0).unwrap();
    // 3 s at 60 fps is tick 180: the springs start at rest at 2 s, tick 120.
    assert_eq!((range(3.0).first, sprung.first_run(&range(3.0))), (180, 120));
    // Less than a warmup after 0: from tick 0, as a stream.
    assert_eq!(sprung.first_run(&range(0.5)), 0);
    assert_eq!(plain.first_run(&range(3.0)), 180, "without springs, the first answered tick");
}

#[test]
fn a_restart_shows_the_rest_rotations_and_the_chain_runs_on_from_them() {
    let clip = swinging();
    let graph = one_clip(&clip);
    let sprung = post(&clip, &[], &tail_springs());
    let (mut player, mut run) = (GraphPlayer::new(Arc::clone(&graph)), PostRun::new(&sprung));
    let tail = |pose: &Pose| [1, 2, 3].map(|j| pose.rotations[j]);
    let dt = 1.0 / 60.0;
    for k in 0..=90u32 {
        if k == 60 {
            run.restart_springs();
        }
        player.tick(dt);
        run.run(&sprung, graph.skeleton(), player.pose(), (f64::from(k) / 60.0, f64::from(k) / 60.0));
        // The clip keys only the body: its tail is at rest rotations.
        let at_rest = tail(run.pose()) == tail(player.pose());
        match k {
            0 | 60 => assert!(at_rest, "tick {k} shows the rest rotations"),
            59 | 61.. => assert!(!at_rest, "tick {k}: the chain swings"),
            _ => {}
        }
    }
}
