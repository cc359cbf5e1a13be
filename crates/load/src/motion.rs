//! The motions `--motion` streams play, each as its JSON for the WebSocket
//! `open` message and its gRPC `Motion`.
//!
//! `three-layers` (issue 16) is what a game character typically runs —
//! locomotion blended from two synced cycles of different lengths, and an
//! upper-body action masked on top (docs/motion.md's example without its additive
//! layer). Its clips are generated chains of the run's joint count
//! ([`Chain`]), the first being the clip a clip run streams, so a motion
//! run and a clip run send the same joints in frames of the same size and
//! differ only in the work per tick: three clip samples and two blends
//! instead of one sample.
//!
//! `foot-ik` (issue 17, `super::walk`) is a walk with both feet planted by
//! two-bone IK.

use std::collections::BTreeMap;

use serde_json::Value;

use super::chain::{Chain, chain, chain_clip};
use super::walk;
use anim::ik::IkSpec;
use anim::motion::MotionSpec;
use anim::{IkTarget, KeyedIkSpec};
use formats::wire::motion::{LayerDoc, MaskDoc, MotionDoc};
use formats::wire::proto::{self, pb};

/// What every stream of a run plays instead of the clip.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MotionChoice {
    /// Walk and run (weights 1 and 0.3, one sync group) under an upper-body
    /// layer masked to the chain's upper half.
    ThreeLayers,
    /// A walk in place with two `two_bone` constraints planting the feet
    /// (`super::walk`).
    FootIk,
}

impl MotionChoice {
    pub fn as_str(self) -> &'static str {
        match self {
            MotionChoice::ThreeLayers => "three-layers",
            MotionChoice::FootIk => "foot-ik",
        }
    }

    /// The fewest `--joints` its clips can have.
    pub fn min_joints(self) -> usize {
        match self {
            MotionChoice::ThreeLayers => 1,
            MotionChoice::FootIk => walk::MIN_JOINTS,
        }
    }
}

/// A motion's uploaded clips.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MotionClips {
    ThreeLayers(LayerClips),
    FootIk { walk: String },
}

impl MotionClips {
    /// The first layer's clip (the run's clip id in its report).
    pub fn first(&self) -> &str {
        match self {
            MotionClips::ThreeLayers(c) => &c.walk,
            MotionClips::FootIk { walk } => walk,
        }
    }
}

/// The sync group of the two locomotion layers.
pub const SYNC_GROUP: &str = "locomotion";
/// The run layer's weight: 70 % walk, 30 % run.
pub const RUN_WEIGHT: f32 = 0.3;

/// The uploaded clips of the three-layer motion, in layer order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LayerClips {
    pub walk: String,
    pub run: String,
    pub upper: String,
}

/// The clip documents of the three layers, `joints` joints each: walk is
/// the standard load clip (3 s), run a wider, quicker 2 s cycle, the
/// upper-body action a slower 4 s one.
pub fn clip_docs(joints: usize) -> [Value; 3] {
    let run =
        Chain { name: format!("load-run-{joints}"), joints, duration: 2.0, amplitude: 0.5, period: 3.0, stride: 2.5 };
    let upper =
        Chain { name: format!("load-upper-{joints}"), joints, duration: 4.0, amplitude: 0.8, period: 8.0, stride: 0.0 };
    [chain_clip(joints), chain(&run), chain(&upper)]
}

/// The joint whose subtree the upper-body layer drives: the chain's middle
/// (`j{joints/2}` and every joint after it).
pub fn upper_body_root(joints: usize) -> String {
    format!("j{}", joints / 2)
}

/// The three-layer motion over `clips`: walk (1) and run (0.3) in one sync
/// group, then the upper-body clip at full weight masked to
/// [`upper_body_root`] and its descendants.
pub fn three_layers(clips: &LayerClips, joints: usize) -> MotionDoc {
    let layer = |clip: &str, weight: f32| LayerDoc { weight, ..LayerDoc::new(clip) };
    let synced = |clip: &str, weight: f32| LayerDoc { sync: Some(SYNC_GROUP.to_owned()), ..layer(clip, weight) };
    let mask = MaskDoc { joints: BTreeMap::from([(upper_body_root(joints), 1.0)]), descendants: true, default: None };
    MotionDoc {
        layers: vec![
            synced(&clips.walk, 1.0),
            synced(&clips.run, RUN_WEIGHT),
            LayerDoc { mask: Some(mask), ..layer(&clips.upper, 1.0) },
        ],
        root_motion: None,
        character: None,
        retarget: None,
        ik: Vec::new(),
        springs: Vec::new(),
        spring_substep_hz: None,
    }
}

/// A motion ready to stream: its JSON for the WebSocket `open` message
/// and its protobuf for `StreamRequest.motion`, made once per run.
#[derive(Debug, Clone)]
pub struct Playable {
    pub json: Value,
    pub pb: pb::Motion,
    /// Its layer is a stored graph: streams open at time 0 (a graph plays
    /// from its start) and may take `set` controls.
    pub graph: bool,
}

impl Playable {
    pub fn new(clips: &MotionClips, joints: usize) -> Playable {
        let doc = match clips {
            MotionClips::ThreeLayers(clips) => three_layers(clips, joints),
            MotionClips::FootIk { walk } => walk::foot_ik(walk),
        };
        let json = serde_json::to_value(&doc).unwrap_or_default();
        let spec = doc.to_spec("/motion").expect("the load generator's motions are well formed");
        Playable { json, pb: to_pb(&spec), graph: false }
    }

    /// A motion document as a file holds it (`--motion-file`), its clip
    /// names already looked up; WebSocket streams only (no protobuf form).
    pub fn from_json(json: Value) -> Playable {
        let layers = json["layers"].as_array().map_or(&[][..], Vec::as_slice);
        let graph = layers.iter().any(|l| l.get("graph").is_some());
        Playable { json, pb: pb::Motion::default(), graph }
    }

    /// The first layer's clip or graph (the run's clip id in its report).
    pub fn first(&self) -> String {
        let first = &self.json["layers"][0];
        first["clip"].as_str().or_else(|| first["graph"].as_str()).unwrap_or_default().to_owned()
    }
}

/// A graph parameter a stream sets once a second, cycling through its
/// values (`--set NAME=V1,V2,…`): the settings a game sends as it plays.
#[derive(Debug, Clone, PartialEq)]
pub struct SetCycle {
    pub parameter: String,
    pub values: Vec<Value>,
}

impl SetCycle {
    /// Parses `NAME=V1,V2,…`, each value a number or `true`/`false`.
    pub fn parse(text: &str) -> Result<SetCycle, String> {
        let (name, values) = text.split_once('=').ok_or("expected NAME=V1,V2,…")?;
        let values = (values.split(','))
            .map(|v| serde_json::from_str::<Value>(v.trim()).map_err(|_| format!("{v:?} is not a number or boolean")))
            .collect::<Result<Vec<_>, _>>()?;
        if name.is_empty() || values.is_empty() || values.iter().any(|v| !(v.is_number() || v.is_boolean())) {
            return Err("expected NAME=V1,V2,… with numbers or booleans".into());
        }
        Ok(SetCycle { parameter: name.to_owned(), values })
    }

    /// The `set` control of its `k`th second.
    pub fn control(&self, k: usize) -> String {
        let value = &self.values[k % self.values.len()];
        serde_json::json!({"op": "set", "parameters": {&self.parameter: value}}).to_string()
    }
}

/// The same motion as gRPC's `Motion` (`StreamRequest.motion`).
pub fn to_pb(spec: &MotionSpec<String>) -> pb::Motion {
    let layers = spec
        .layers
        .iter()
        .map(|l| pb::Layer {
            clip_id: l.clip.clone(),
            weight: Some(l.weight),
            mode: proto::layer_mode_to_pb(l.mode).into(),
            mask: l.mask.as_ref().map(|m| pb::Mask {
                joints: m.joints.iter().cloned().collect(),
                descendants: m.descendants,
                default_weight: m.default,
            }),
            offset: l.offset,
            speed: Some(l.speed),
            playback: l.playback.map_or(0, |p| proto::playback_to_pb(p).into()),
            sync: l.sync.clone().unwrap_or_default(),
            reference_time: l.reference_time,
            ..Default::default()
        })
        .collect();
    let root_motion = spec.root_motion.as_ref().map(|r| pb::RootMotionOptions {
        joint: r.joint.clone().unwrap_or_default(),
        mode: proto::root_mode_to_pb(r.mode).into(),
        up: proto::up_axis_to_pb(r.up).into(),
    });
    pb::Motion { layers, root_motion, ik: spec.ik.iter().map(ik_to_pb).collect(), ..Default::default() }
}

/// A request-time constraint as the proto's, through the clip form's
/// converter (every target a fixed point, the weight fixed).
fn ik_to_pb(spec: &IkSpec) -> pb::IkConstraint {
    let targets = match spec {
        IkSpec::TwoBone(c) => vec![c.target],
        IkSpec::Aim(c) => vec![c.target],
        IkSpec::Chain(c) => c.effectors.iter().map(|e| e.target).collect(),
    };
    let targets = targets.into_iter().map(IkTarget::Fixed).collect();
    proto::ik_to_pb(&KeyedIkSpec { constraint: spec.clone(), targets, weight: None })
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;
    use anim::motion::{Motion, MotionOptions, MotionSampler};
    use anim::{Clip, Cursor, Pose};
    use formats::wire::json::parse_clip;
    use formats::wire::proto_motion;

    const JOINTS: usize = 8;

    fn ids() -> LayerClips {
        LayerClips { walk: "W".into(), run: "R".into(), upper: "U".into() }
    }

    fn built(doc: &Value) -> Clip {
        let (_, spec) = parse_clip(&serde_json::to_vec(doc).unwrap()).expect("a valid clip document");
        Clip::build(&spec).expect("builds")
    }

    /// The angle about z of joint `j` of `clip` at clip time `t` (every
    /// chain rotation turns about z).
    fn angle(clip: &Clip, t: f64, j: usize) -> f64 {
        let mut pose = Pose::identity(clip.joint_count());
        clip.sample_into(t as f32, &mut Cursor::default(), &mut pose);
        angle_of(&pose, j)
    }

    fn angle_of(pose: &Pose, j: usize) -> f64 {
        let q = pose.rotations[j];
        2.0 * f64::from(q.z).atan2(f64::from(q.w))
    }

    /// As the server reads each: the JSON text through `MotionDoc`, the
    /// protobuf through its converter.
    fn as_read_from_json_and_protobuf(doc: &MotionDoc) -> (MotionSpec<String>, MotionSpec<String>) {
        let text = serde_json::to_string(doc).unwrap();
        let from_json = serde_json::from_str::<MotionDoc>(&text).unwrap().to_spec("/motion").unwrap();
        let from_pb = proto_motion::motion_doc_from_pb(&to_pb(&doc.to_spec("/motion").unwrap())).unwrap();
        let from_pb = from_pb.to_spec("/motion").unwrap();
        (from_json, from_pb)
    }

    #[test]
    fn the_json_and_protobuf_motions_say_the_same() {
        let doc = three_layers(&ids(), JOINTS);
        let (from_json, from_pb) = as_read_from_json_and_protobuf(&doc);
        assert_eq!(format!("{from_json:?}"), format!("{from_pb:?}"));
        let v = serde_json::to_value(&doc).unwrap();
        assert_eq!(v["layers"][0]["sync"], SYNC_GROUP);
        assert_eq!(v["layers"][1]["sync"], SYNC_GROUP);
        assert_eq!(v["layers"][1]["weight"], 0.3f32);
        assert_eq!(v["layers"][2]["mask"], serde_json::json!({"joints": {"j4": 1.0}, "descendants": true}));
        assert_eq!(v["layers"][2].get("sync"), None);
    }

    /// The foot-ik motion's two constraints survive both wires: the same
    /// legs, targets and poles as the walk module's.
    #[test]
    fn the_foot_ik_motion_says_the_same_over_both_wires() {
        let (from_json, from_pb) = as_read_from_json_and_protobuf(&walk::foot_ik("W"));
        assert_eq!(format!("{from_json:?}"), format!("{from_pb:?}"));
        assert_eq!(from_pb.ik.len(), 2);
        for (i, c) in from_pb.ik.iter().enumerate() {
            let IkSpec::TwoBone(c) = c else { panic!("{c:?} is not two_bone") };
            assert_eq!(c.joints, walk::LEGS[i].map(str::to_owned));
            assert_eq!(
                (c.target.to_array(), c.pole.map(|p| p.to_array())),
                (walk::FOOT_TARGETS[i], Some(walk::POLES[i]))
            );
            assert_eq!(c.weight, None);
        }
    }

    #[test]
    fn the_clips_share_the_joints_but_not_the_cycle() {
        let clips = clip_docs(JOINTS).map(|d| built(&d));
        assert_eq!(clips.each_ref().map(|c| c.joint_count()), [JOINTS; 3]);
        assert_eq!(clips.each_ref().map(|c| c.duration()), [3.0, 2.0, 4.0]);
        assert_eq!(clip_docs(JOINTS)[0], chain_clip(JOINTS), "walk is the clip a clip run streams");
    }

    /// The built motion against a pose derived by hand: below the mask,
    /// walk and run sampled at one normalised phase of the weighted cycle
    /// length D = (0.7·3 + 0.3·2) s and mixed 70/30 (two turns about z
    /// blend by their angles); from the mask's joint on, the upper clip.
    #[test]
    fn the_motion_blends_synced_locomotion_under_a_masked_upper_body() {
        let [walk, run, upper] = clip_docs(JOINTS).map(|d| built(&d));
        let by_id = HashMap::from([("W", &walk), ("R", &run), ("U", &upper)]);
        let spec = three_layers(&ids(), JOINTS).to_spec("/motion").unwrap();
        let spec = spec.try_map(|_, id| by_id.get(id.as_str()).copied().ok_or(id)).unwrap();
        let motion = Motion::build(spec).expect("a valid motion");
        let cycle = 0.7 * 3.0 + 0.3 * 2.0;
        let mut sampler = MotionSampler::new();
        for tau in [0.0, 0.45, 1.3, 2.69, 4.1, 7.77] {
            motion.sample(tau, &MotionOptions::default(), &mut sampler);
            let phase = (tau / cycle).fract();
            for j in 0..JOINTS {
                let got = angle_of(sampler.pose(), j);
                let want = if j >= JOINTS / 2 {
                    angle(&upper, tau % 4.0, j)
                } else {
                    let (w, r) = (angle(&walk, phase * 3.0, j), angle(&run, phase * 2.0, j));
                    w + 0.3 * (r - w)
                };
                assert!((got - want).abs() < 1e-5, "τ {tau}, j{j}: {got} vs {want}");
            }
        }
    }

    /// `--set NAME=V1,V2,…`: numbers and booleans, cycled one a second; a
    /// missing name, value or `=`, or a value of another kind, refused.
    #[test]
    fn a_set_cycle_parses_and_cycles() {
        let cycle = SetCycle::parse("speed=0.5, 2.5,true").unwrap();
        assert_eq!(cycle.parameter, "speed");
        let controls: Vec<Value> = (0..4).map(|k| serde_json::from_str(&cycle.control(k)).unwrap()).collect();
        let values: Vec<&Value> = controls.iter().map(|c| &c["parameters"]["speed"]).collect();
        assert_eq!(
            values,
            [&serde_json::json!(0.5), &serde_json::json!(2.5), &serde_json::json!(true), &serde_json::json!(0.5)]
        );
        assert!(controls.iter().all(|c| c["op"] == "set"));
        for bad in ["speed", "=1", "speed=", "speed=fast", "speed=[1]", "speed=1,,2"] {
            assert!(SetCycle::parse(bad).is_err(), "{bad}");
        }
    }
}
