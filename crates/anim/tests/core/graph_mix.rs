//! A graph as one layer among clip layers (docs/graphs.md, “What composes
//! with a graph”) against the layering rule of docs/motion.md applied by
//! hand in `f64`: the graph-alone pose of each tick and each clip's own pose
//! at the tick's motion time `k/fps` are the inputs, the masks resolved and
//! the blend and additive formulas evaluated here. Also: the mix allocates
//! nothing per tick, and the derived compact ranges hold its poses.

use std::sync::Arc;

use anim::compact::Ranges;
use anim::graph::{
    Blend1dSpec, Graph, GraphPlayer, GraphPost, GraphSpec, NodeKind, NodeSpec, ParameterKind, ParameterSpec, PostRun,
    TopSpec, Value,
};
use anim::ik::IkLimits;
use anim::motion::{LayerMode, LayerSpec, MaskSpec, MotionSpec};
use anim::{Clip, ClipSpec, Cursor, Ease, Pose, Skeleton};

use crate::allocations;
use crate::composition_reference::{add, blend, pose_err, trs};
use crate::random::{Rng, skeleton_clip};
use crate::reference::Trs;

const FPS: f64 = 60.0;

/// Four clips on one skeleton of 8 joints: the graph's two points, a wave
/// and a breath.
fn clips() -> Vec<Clip> {
    let mut rng = Rng::new(4242);
    let first = skeleton_clip(&mut rng, 8);
    let on_first = |mut spec: ClipSpec| {
        spec.skeleton.clone_from(&first.skeleton);
        spec
    };
    let mut specs = vec![first.clone()];
    specs.extend((0..3).map(|_| on_first(skeleton_clip(&mut rng, 8))));
    specs.iter().map(|s| Clip::build(s).unwrap()).collect()
}

/// A blend1d of clips 0 and 1 by `speed` (0..1, default 0.25), in sync.
fn graph(clips: &[Clip]) -> Arc<Graph<&Clip>> {
    let speed =
        ParameterSpec { name: "speed".into(), kind: ParameterKind::Float { default: 0.25, min: 0.0, max: 1.0 } };
    let node = NodeSpec {
        name: "walkrun".into(),
        kind: NodeKind::Blend1d(Blend1dSpec { parameter: 0, points: vec![(0, 0.0), (1, 1.0)], sync: true }),
    };
    let spec = GraphSpec { parameters: vec![speed], nodes: vec![node], top: TopSpec::Output(0) };
    Arc::new(Graph::build(spec, &[&clips[0], &clips[1]]).unwrap())
}

/// A mask of `joint` and its descendants.
fn upper(joint: &str) -> MaskSpec {
    MaskSpec { joints: vec![(joint.into(), 1.0)], descendants: true, default: None }
}

/// The graph's layer's stand-in (the core puts the graph's first clip there).
fn graph_layer<'a>(
    graph: &Arc<Graph<&'a Clip>>,
    weight: f32,
    mode: LayerMode,
    mask: Option<MaskSpec>,
) -> LayerSpec<&'a Clip> {
    LayerSpec { weight, mode, mask, ..LayerSpec::new(*graph.initial_motion().first_clip()) }
}

/// Ticks `0..=ticks` with `speed` set to 0.8 from tick 40: the graph-alone
/// pose and the mixed pose of each.
fn play(graph: &Arc<Graph<&Clip>>, post: &GraphPost<&Clip>, ticks: u64) -> Vec<(Pose, Pose)> {
    let (mut player, mut run) = (GraphPlayer::new(Arc::clone(graph)), PostRun::new(post));
    (0..=ticks)
        .map(|k| {
            if k == 40 {
                player.set(0, Value::Float(0.8)).unwrap();
            }
            player.tick(1.0 / FPS);
            let tau = k as f64 / FPS;
            run.run(post, graph.skeleton(), player.pose(), (tau, tau));
            (player.pose().clone(), run.pose().clone())
        })
        .collect()
}

/// `clip`'s own pose at motion time `tau` (offset 0, speed 1, its playback).
fn clip_pose(clip: &Clip, tau: f64) -> Pose {
    let mut pose = Pose::default();
    clip.sample_into(clip.clip_time(tau, clip.playback(), Ease::Linear), &mut Cursor::default(), &mut pose);
    pose
}

/// Per joint of `skeleton`, 1 on `joint` and its descendants, else 0.
fn mask_by_hand(skeleton: &Skeleton, joint: &str) -> Vec<f64> {
    let named = skeleton.names().iter().position(|n| n == joint).unwrap();
    let under = |j: usize| {
        let mut at = Some(j);
        while let Some(a) = at {
            if a == named {
                return 1.0;
            }
            at = skeleton.parent(a);
        }
        0.0
    };
    (0..skeleton.len()).map(under).collect()
}

/// One layer as the hand evaluation reads it.
struct ByHand<'a> {
    pose: &'a Pose,
    weight: f64,
    mask: Vec<f64>,
    reference: Option<&'a Pose>,
}

/// docs/motion.md, “How a pose is computed”, in `f64`: from the rest pose,
/// each layer blended or added bottom to top at weight × mask.
fn layered(skeleton: &Skeleton, layers: &[ByHand<'_>]) -> Vec<Trs> {
    let mut out: Vec<Trs> = (0..skeleton.len()).map(|j| trs(skeleton.rest(), j)).collect();
    for layer in layers {
        for (j, at) in out.iter_mut().enumerate() {
            let w = layer.weight * layer.mask[j];
            if w <= 0.0 {
                continue;
            }
            *at = match layer.reference {
                None => blend(*at, trs(layer.pose, j), w),
                Some(reference) => add(*at, trs(layer.pose, j), trs(reference, j), w),
            };
        }
    }
    out
}

/// The graph's first tick with its defaults: an additive graph layer's reference.
fn first_tick(graph: &Arc<Graph<&Clip>>) -> Pose {
    let mut player = GraphPlayer::new(Arc::clone(graph));
    player.tick(1.0 / FPS);
    player.pose().clone()
}

#[test]
fn a_graph_under_a_masked_wave_and_an_additive_breath_is_the_layering_rule_in_f64() {
    let clips = clips();
    let graph = graph(&clips);
    let (wave, breath) = (&clips[2], &clips[3]);
    let layers = vec![
        graph_layer(&graph, 1.0, LayerMode::Blend, None),
        LayerSpec { weight: 0.5, mask: Some(upper("j1")), ..LayerSpec::new(wave) },
        LayerSpec { weight: 0.5, mode: LayerMode::Additive, ..LayerSpec::new(breath) },
    ];
    let post = GraphPost::mixed(MotionSpec { layers, ..MotionSpec::default() }, 0, &graph, &IkLimits::default());
    let post = post.unwrap();
    let skeleton = graph.skeleton();
    let (all, spine) = (vec![1.0; skeleton.len()], mask_by_hand(skeleton, "j1"));
    assert!(spine.contains(&0.0) && spine.contains(&1.0), "the mask covers part of the skeleton");
    let breath_reference = clip_pose(breath, f64::from(breath.start()));
    let (mut worst, mut moved) = (0.0f64, 0.0f64);
    for (k, (alone, mixed)) in play(&graph, &post, 120).iter().enumerate() {
        let tau = k as f64 / FPS;
        let (w, b) = (clip_pose(wave, tau), clip_pose(breath, tau));
        let expected = layered(
            skeleton,
            &[
                ByHand { pose: alone, weight: 1.0, mask: all.clone(), reference: None },
                ByHand { pose: &w, weight: 0.5, mask: spine.clone(), reference: None },
                ByHand { pose: &b, weight: 0.5, mask: all.clone(), reference: Some(&breath_reference) },
            ],
        );
        let err = pose_err(mixed, &expected);
        assert!(err <= 1e-5, "tick {k}: {err}");
        worst = worst.max(err);
        moved = moved.max(pose_err(alone, &expected));
    }
    println!("graph under clip layers: worst error {worst:e}");
    assert!(moved > 1e-2, "the clip layers change the graph's pose (by {moved} at most)");
}

#[test]
fn a_graph_layered_additively_and_masked_over_a_clip_is_the_layering_rule_in_f64() {
    let clips = clips();
    let graph = graph(&clips);
    let base = &clips[2];
    for (mode, weight, mask) in [(LayerMode::Additive, 0.7, None), (LayerMode::Blend, 0.5, Some(upper("j1")))] {
        let layers = vec![LayerSpec::new(base), graph_layer(&graph, weight, mode, mask.clone())];
        let post = GraphPost::mixed(MotionSpec { layers, ..MotionSpec::default() }, 1, &graph, &IkLimits::default());
        let post = post.unwrap();
        let skeleton = base.skeleton();
        let mask = match &mask {
            Some(_) => mask_by_hand(skeleton, "j1"),
            None => vec![1.0; skeleton.len()],
        };
        let reference = first_tick(&graph);
        let reference = (mode == LayerMode::Additive).then_some(&reference);
        for (k, (alone, mixed)) in play(&graph, &post, 90).iter().enumerate() {
            let beneath = clip_pose(base, k as f64 / FPS);
            let expected = layered(
                skeleton,
                &[
                    ByHand { pose: &beneath, weight: 1.0, mask: vec![1.0; skeleton.len()], reference: None },
                    ByHand { pose: alone, weight: f64::from(weight), mask: mask.clone(), reference },
                ],
            );
            let err = pose_err(mixed, &expected);
            assert!(err <= 1e-5, "{mode:?} at tick {k}: {err}");
        }
    }
}

#[test]
fn a_mixed_tick_allocates_nothing_and_stays_in_its_derived_ranges() {
    let clips = clips();
    let graph = graph(&clips);
    let layers = vec![
        LayerSpec { weight: 0.5, ..LayerSpec::new(&clips[2]) },
        graph_layer(&graph, 0.6, LayerMode::Blend, Some(upper("j1"))),
        LayerSpec { weight: 0.5, mode: LayerMode::Additive, ..LayerSpec::new(&clips[3]) },
    ];
    let post = GraphPost::mixed(MotionSpec { layers, ..MotionSpec::default() }, 1, &graph, &IkLimits::default());
    let post = post.unwrap();
    let ranges = Ranges::of_played(&graph, &post, 30.0).unwrap();
    let (mut player, mut run) = (GraphPlayer::new(Arc::clone(&graph)), PostRun::new(&post));
    let tick = |k: u64, player: &mut GraphPlayer<&Clip>, run: &mut PostRun| {
        player.tick(1.0 / FPS);
        run.run(&post, graph.skeleton(), player.pose(), (k as f64 / FPS, k as f64 / FPS));
    };
    for k in 0..3 {
        tick(k, &mut player, &mut run); // warm: buffers take their size
    }
    let before = allocations();
    for k in 3..200 {
        if k == 50 {
            player.set(0, Value::Float(0.9)).unwrap();
        }
        tick(k, &mut player, &mut run);
        assert_eq!(ranges.outside(run.pose()), None, "tick {k}");
    }
    let n = allocations() - before;
    assert_eq!(n, 0, "a mixed tick allocated {n} times over 197 ticks");
}

#[test]
fn a_graph_layer_is_mapped_by_joint_name_and_its_refusals_point_at_it() {
    let clips = clips();
    let graph = graph(&clips);
    let unknown = MaskSpec { joints: vec![("nope".into(), 1.0)], descendants: false, default: None };
    let layers = vec![LayerSpec::new(&clips[2]), graph_layer(&graph, 1.0, LayerMode::Blend, Some(unknown))];
    let err = GraphPost::mixed(MotionSpec { layers, ..MotionSpec::default() }, 1, &graph, &IkLimits::default());
    let err = err.unwrap_err();
    assert_eq!((err.path.to_pointer(), err.kind.code()), ("/layers/1/mask/joints/nope".into(), "unknown_joint"));
}
