//! The JSON graph (docs/graphs.md): the example parses and compiles, and each
//! refusal names its code and the JSON pointer of the field at fault.

use anim::graph::{Graph, GraphPlayer, Value};
use anim::{Channel, Clip, ClipSpec, Interpolation, JointSpec, Keys, Playback, SkeletonSpec, TrackSpec, Transform};
use formats::wire::graph::GraphDoc;
use formats::wire::json::DocError;
use glam::Vec3;
use serde_json::json;

/// The example of docs/graphs.md, clip ids as they are.
fn example() -> serde_json::Value {
    json!({"name": "locomotion",
     "parameters": {"speed": {"type": "float", "default": 0, "min": 0, "max": 6},
                    "direction": {"type": "float", "default": 0, "min": -180, "max": 180},
                    "crouch": {"type": "bool"}, "jump": {"type": "trigger"}},
     "nodes": {
       "walkrun": {"blend1d": {"parameter": "speed", "points": [
           {"clip": "ID-idle", "at": 0}, {"clip": "ID-walk", "at": 1.5}, {"clip": "ID-run", "at": 5}]}},
       "strafe": {"blend2d": {"x": "direction", "y": "speed", "points": [
           {"clip": "ID-idle", "at": [0, 0]}, {"clip": "ID-walk", "at": [0, 1.5]},
           {"clip": "ID-left", "at": [-90, 1.5]}, {"clip": "ID-right", "at": [90, 1.5]}]}},
       "jump": {"clip": "ID-jump", "playback": "once"},
       "aiming": {"layers": [{"node": "strafe"}, {"clip": "ID-aim", "mask": {"joints": {"spine": 1}, "descendants": true}}]}},
     "machine": {"initial": "move",
       "states": {"move": {"node": "walkrun"}, "jump": {"node": "jump"}, "crouch": {"node": "aiming"}},
       "transitions": [
         {"from": "move", "to": "jump", "when": {"trigger": "jump"}, "duration": 0.1},
         {"from": "jump", "to": "move", "when": {"exit_time": 0.9}, "duration": 0.2},
         {"from": "*", "to": "crouch", "when": {"parameter": "crouch", "eq": true}, "duration": 0.25}]}})
}

/// A looping one-second clip on a hips → spine skeleton, its hips at `x`.
fn clip(name: &str, x: f32) -> Clip {
    let joint = |name: &str, parent: Option<&str>| JointSpec {
        name: name.into(),
        parent: parent.map(Into::into),
        rest: Transform::IDENTITY,
        inverse_bind: None,
    };
    let keys = Keys::Vec3(vec![Vec3::ZERO, Vec3::new(x, 0.0, 0.0)]);
    let track = TrackSpec::new("hips", Channel::Translation, Interpolation::Linear, vec![0.0, 1.0], keys);
    let skeleton = Some(SkeletonSpec { joints: vec![joint("hips", None), joint("spine", Some("hips"))] });
    Clip::build(&ClipSpec {
        name: name.into(),
        skeleton,
        tracks: vec![track],
        playback: Playback::Loop,
        ..Default::default()
    })
    .unwrap()
}

/// Every `ID-…` resolves; anything else is 404 `unknown_clip` at its pointer.
fn compile(doc: serde_json::Value) -> Result<Graph<Clip>, DocError> {
    let doc: GraphDoc = serde_json::from_value(doc).map_err(|e| DocError {
        code: "invalid_document",
        pointer: String::new(),
        detail: e.to_string(),
    })?;
    doc.compile("", |id, at| {
        if id.starts_with("ID-") {
            Ok(clip(id, id.len() as f32))
        } else {
            Err(DocError { code: "unknown_clip", pointer: at.to_owned(), detail: format!("no clip {id}") })
        }
    })
}

fn refusal(edit: impl FnOnce(&mut serde_json::Value)) -> (String, &'static str) {
    let mut doc = example();
    edit(&mut doc);
    let e = compile(doc).map(|_| ()).unwrap_err();
    (e.pointer, e.code)
}

fn at<'a>(doc: &'a mut serde_json::Value, pointer: &str) -> &'a mut serde_json::Value {
    doc.pointer_mut(pointer).unwrap_or_else(|| panic!("{pointer} in the example"))
}

#[test]
fn the_example_compiles_and_plays_its_machine() {
    let graph = std::sync::Arc::new(compile(example()).unwrap());
    let names: Vec<&str> = graph.state_names().collect();
    assert_eq!(names, ["crouch", "jump", "move"]);
    let mut player = GraphPlayer::new(std::sync::Arc::clone(&graph));
    player.tick(0.0);
    assert_eq!(player.report().state(), "move");
    player.set(graph.parameter_index("jump").unwrap(), Value::Bool(true)).unwrap();
    player.tick(1.0 / 60.0);
    let report = player.report();
    assert_eq!(report.state(), "jump");
    assert_eq!(report.transition().map(|t| (t.from, t.to, t.alpha)), Some(("move", "jump", 0.0)));
}

#[test]
fn unknown_fields_are_refused() {
    let (_, code) = refusal(|d| at(d, "/nodes/jump")["loop"] = json!(true));
    assert_eq!(code, "invalid_document");
    let (_, code) = refusal(|d| at(d, "/machine/transitions/0/when")["trigger_name"] = json!("jump"));
    assert_eq!(code, "invalid_document");
}

/// A change to the example.
type Edit = Box<dyn FnOnce(&mut serde_json::Value)>;

#[test]
fn each_refusal_points_at_its_field() {
    let cases: Vec<(Edit, &str, &str)> = vec![
        (
            Box::new(|d| *at(d, "/nodes/walkrun/blend1d/parameter") = json!("pace")),
            "/nodes/walkrun/blend1d/parameter",
            "unknown_parameter",
        ),
        (
            Box::new(|d| *at(d, "/nodes/strafe/blend2d/y") = json!("crouch")),
            "/nodes/strafe/blend2d/y",
            "parameter_type",
        ),
        (Box::new(|d| *at(d, "/machine/states/move/node") = json!("run")), "/machine/states/move/node", "unknown_node"),
        (
            Box::new(|d| *at(d, "/nodes/aiming/layers/0/node") = json!("strafer")),
            "/nodes/aiming/layers/0/node",
            "unknown_node",
        ),
        (
            Box::new(|d| *at(d, "/machine/transitions/1/to") = json!("walk")),
            "/machine/transitions/1/to",
            "unknown_state",
        ),
        (
            Box::new(|d| *at(d, "/machine/transitions/0/from") = json!("fly")),
            "/machine/transitions/0/from",
            "unknown_state",
        ),
        (Box::new(|d| *at(d, "/machine/initial") = json!("idle")), "/machine/initial", "unknown_state"),
        (Box::new(|d| *at(d, "/parameters/speed/default") = json!(7)), "/parameters/speed/default", "parameter_range"),
        (
            Box::new(|d| at(d, "/nodes/jump")["blend1d"] = json!({"parameter": "speed", "points": []})),
            "/nodes/jump",
            "node_kind",
        ),
        (
            Box::new(|d| at(d, "/machine/transitions/2/when")["ne"] = json!(false)),
            "/machine/transitions/2/when",
            "condition_kind",
        ),
        (
            Box::new(|d| *at(d, "/machine/transitions/2/when") = json!({"parameter": "crouch", "gt": true})),
            "/machine/transitions/2/when/gt",
            "parameter_type",
        ),
        (
            Box::new(|d| {
                *at(d, "/machine/transitions/0/when") = json!({"any": [{"exit_time": 1}, {"trigger": "crouch"}]})
            }),
            "/machine/transitions/0/when/any/1/trigger",
            "parameter_type",
        ),
        (
            Box::new(|d| *at(d, "/machine/transitions/1/when/exit_time") = json!(-1)),
            "/machine/transitions/1/when/exit_time",
            "bad_number",
        ),
        (
            Box::new(|d| *at(d, "/machine/transitions/1/duration") = json!(-0.5)),
            "/machine/transitions/1/duration",
            "bad_number",
        ),
        (
            Box::new(|d| {
                *at(d, "/nodes/strafe/blend2d/points/2/at") = json!([0, 3]);
                *at(d, "/nodes/strafe/blend2d/points/3/at") = json!([0, 4.5]);
            }),
            "/nodes/strafe/blend2d/points",
            "degenerate_blend_space",
        ),
        (
            Box::new(|d| *at(d, "/nodes/walkrun/blend1d/points/2/at") = json!(0)),
            "/nodes/walkrun/blend1d/points",
            "degenerate_blend_space",
        ),
        (
            Box::new(|d| *at(d, "/parameters/direction") = json!({"type": "float"})),
            "/nodes/strafe/blend2d/x",
            "unbounded_axis",
        ),
        (
            Box::new(|d| *at(d, "/nodes/strafe") = json!({"layers": [{"node": "aiming"}]})),
            "/nodes/aiming",
            "node_cycle",
        ),
        (
            Box::new(|d| at(d, "/nodes/aiming/layers/0")["weight"] = json!(0.5)),
            "/nodes/aiming/layers/0/node",
            "entry_not_stackable",
        ),
        (
            Box::new(|d| *at(d, "/nodes/aiming/layers/1/mask/joints") = json!({"tail": 1})),
            "/nodes/aiming/layers/1/mask/joints/tail",
            "unknown_joint",
        ),
        (Box::new(|d| *at(d, "/nodes/jump/clip") = json!("missing")), "/nodes/jump/clip", "unknown_clip"),
        (Box::new(|d| d["output"] = json!("walkrun")), "", "graph_top"),
    ];
    for (edit, pointer, code) in cases {
        assert_eq!(refusal(edit), (pointer.to_owned(), code));
    }
}

/// The `set` map of a control, resolved against the example.
fn set(values: serde_json::Value, pointer: &str) -> Result<Vec<(usize, Value)>, (String, &'static str)> {
    let graph = compile(example()).unwrap();
    let set: formats::wire::graph_inputs::SetDoc = serde_json::from_value(values).unwrap();
    formats::wire::graph_inputs::parameters(&graph, &set, pointer).map_err(|e| (e.pointer, e.code))
}

#[test]
fn set_values_are_checked_not_clamped_each_at_its_pointer() {
    // The example's parameters in name order: crouch 0, direction 1, jump 2, speed 3.
    let got = set(json!({"speed": 2.5, "jump": true, "crouch": false}), "/parameters").unwrap();
    assert_eq!(got, [(0, Value::Bool(false)), (2, Value::Bool(true)), (3, Value::Float(2.5))]);
    assert_eq!(set(json!({"speed": 6}), "/parameters").unwrap(), [(3, Value::Float(6.0))], "max is in range");
    let cases = [
        (json!({"pace": 1}), "/parameters/pace", "unknown_parameter"),
        (json!({"speed": true}), "/parameters/speed", "parameter_type"),
        (json!({"speed": "fast"}), "/parameters/speed", "parameter_type"),
        (json!({"jump": 1}), "/parameters/jump", "parameter_type"),
        (json!({"crouch": null}), "/parameters/crouch", "parameter_type"),
        (json!({"speed": 6.5}), "/parameters/speed", "parameter_out_of_range"),
        (json!({"direction": -181}), "/parameters/direction", "parameter_out_of_range"),
        (json!({"a/b": 1}), "/parameters/a~1b", "unknown_parameter"),
    ];
    for (values, pointer, code) in cases {
        assert_eq!(set(values.clone(), "/parameters"), Err((pointer.to_owned(), code)), "{values}");
    }
}

#[test]
fn inputs_are_due_at_their_ticks_and_point_into_the_list() {
    use formats::wire::graph_inputs::{InputDoc, inputs};
    let graph = compile(example()).unwrap();
    let list: Vec<InputDoc> = serde_json::from_value(json!([
        {"time": 0.5, "set": {"speed": 2.5}},
        {"time": 0.1, "set": {"jump": true}}
    ]))
    .unwrap();
    let got = inputs(&graph, &list, 60.0, "/inputs").unwrap();
    // 0.1 s is tick 6, 0.5 s tick 30 (hand-computed at 60 fps); sorted by tick.
    assert_eq!(got.settings(), [(6, 2, Value::Bool(true)), (30, 3, Value::Float(2.5))]);
    let bad: Vec<InputDoc> = serde_json::from_value(json!([
        {"time": 0.5, "set": {"speed": 2.5}},
        {"time": 1, "set": {"speed": 7}}
    ]))
    .unwrap();
    let e = inputs(&graph, &bad, 60.0, "/inputs").unwrap_err();
    assert_eq!((e.pointer.as_str(), e.code), ("/inputs/1/set/speed", "parameter_out_of_range"));
    let bad = [InputDoc { time: -1.0, set: Default::default() }];
    let e = inputs(&graph, &bad, 60.0, "/inputs").unwrap_err();
    assert_eq!((e.pointer.as_str(), e.code), ("/inputs/0/time", "bad_time"));
    let unknown: Result<Vec<InputDoc>, _> = serde_json::from_value(json!([{"time": 0, "set": {}, "at": 1}]));
    assert!(unknown.is_err(), "unknown fields are refused");
}

#[test]
fn the_report_is_the_state_the_transition_and_the_weights_of_the_blends_played() {
    let graph = std::sync::Arc::new(compile(example()).unwrap());
    let mut player = GraphPlayer::new(std::sync::Arc::clone(&graph));
    player.set(graph.parameter_index("speed").unwrap(), Value::Float(2.5)).unwrap();
    player.tick(0.0);
    let mut out = Vec::new();
    formats::wire::graph_inputs::write_report(&mut out, &player.report());
    // speed 2.5 between walk (1.5) and run (5): u = 1/3.5, so 1 − u and u.
    let u = 1.0 / 3.5;
    let expected = json!({"state": "move", "weights": {"walkrun": [0.0, 1.0 - u, u]}});
    let written: serde_json::Value = serde_json::from_slice(&[b"{\"_\":0".as_slice(), &out, b"}"].concat()).unwrap();
    assert_eq!(written["graph"], expected);
    player.set(graph.parameter_index("jump").unwrap(), Value::Bool(true)).unwrap();
    player.tick(1.0 / 60.0);
    let mut out = Vec::new();
    formats::wire::graph_inputs::write_report(&mut out, &player.report());
    let written: serde_json::Value = serde_json::from_slice(&[b"{\"_\":0".as_slice(), &out, b"}"].concat()).unwrap();
    assert_eq!(written["graph"]["transition"], json!({"from": "move", "to": "jump", "alpha": 0.0}));
    assert_eq!(written["graph"]["state"], "jump");
}

/// `examples/graphs/NAME` compiled against `clips`, each `name:X` resolved by clip name.
fn shipped_graph(name: &str, clips: &[Clip]) -> std::sync::Arc<Graph<Clip>> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/graphs/").to_owned() + name;
    let doc: GraphDoc = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let graph = doc.compile("", |id, at| {
        let name = id.strip_prefix("name:").unwrap_or(id);
        let clip = clips.iter().find(|c| c.name() == name);
        clip.cloned().ok_or_else(|| DocError { code: "unknown_clip", pointer: at.to_owned(), detail: id.to_owned() })
    });
    std::sync::Arc::new(graph.unwrap_or_else(|e| panic!("{name}: {} at {}: {}", e.code, e.pointer, e.detail)))
}

/// The states a player passes through over `seconds` at 60 fps with
/// `inputs` `(time, name, value)`, each with the tick it became current.
fn states_played(
    graph: &std::sync::Arc<Graph<Clip>>,
    seconds: f64,
    inputs: &[(f64, &str, Value)],
) -> Vec<(u64, String)> {
    let settings = inputs.iter().map(|&(t, name, v)| (t, graph.parameter_index(name).unwrap(), v));
    let inputs = anim::graph::Inputs::new(60.0, settings);
    let range = anim::graph::TickRange::new(0.0, seconds, 60.0).unwrap();
    let mut states: Vec<(u64, String)> = Vec::new();
    GraphPlayer::new(std::sync::Arc::clone(graph))
        .play(&range, &inputs, |k, p| {
            let state = p.report().state();
            if states.last().is_none_or(|(_, s)| s != state) {
                states.push((k, state.to_owned()));
            }
        })
        .unwrap();
    states
}

fn named(states: &[(u64, &str)]) -> Vec<(u64, String)> {
    states.iter().map(|&(k, s)| (k, s.to_owned())).collect()
}

#[test]
fn the_shipped_fox_graph_walks_runs_and_surveys() {
    let imported = super::import_file("gltf/Fox/Fox.glb", &formats::import::ImportOptions::default());
    let clips: Vec<Clip> = imported.clips.iter().map(super::build).collect();
    let graph = shipped_graph("fox-locomotion.json", &clips);
    let states = states_played(
        &graph,
        8.0,
        &[(1.0, "speed", Value::Float(2.5)), (2.0, "survey", Value::Bool(true)), (7.0, "speed", Value::Float(0.0))],
    );
    // speed at 1 s is tick 60, the trigger at 2 s tick 120, speed 0 at 7 s
    // tick 420. The look (Survey once, from tick 120) exits at the first
    // tick where (k − 120)/60 s has played 0.9 of Survey's length.
    let survey = clips.iter().find(|c| c.name() == "Survey").unwrap().range().duration();
    let back = (121..).find(|&k: &u64| (k - 120) as f64 / 60.0 / survey >= 0.9).unwrap();
    assert_eq!(back, 305, "Survey lasts 3.4166667 s: docs/graphs.md's worked example says tick 305");
    assert_eq!(states, named(&[(0, "idle"), (60, "move"), (120, "look"), (back, "move"), (420, "idle")]));
}

#[test]
fn the_shipped_cmu_graph_blends_the_two_imports_and_strolls() {
    use anim::Interpolation;
    let import = |name: &str, interpolation| {
        let options = formats::import::ImportOptions {
            bvh_interpolation: interpolation,
            name: Some(name.to_owned()),
            ..Default::default()
        };
        super::build(&super::import_file("bvh/131_01.bvh", &options).clips[0])
    };
    let clips = [import("walk", Interpolation::CatmullRom), import("walk-smooth", Interpolation::BSpline)];
    let graph = shipped_graph("cmu-walk.json", &clips);
    let inputs = [(0.5, "smooth", Value::Float(0.5)), (1.0, "slow", Value::Bool(true))];
    assert_eq!(states_played(&graph, 2.0, &inputs), named(&[(0, "walk"), (60, "stroll")]));
}
