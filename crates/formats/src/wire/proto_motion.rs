//! The protobuf motion (`Motion` of `proto/inbetween/v1/animation.proto`)
//! as the JSON motion document it stands for ([`MotionDoc`],
//! docs/motion.md), so both wires share one set of rules: the document's
//! own (`to_spec`), the graph layer's (`graph_layer` in the service) and
//! the service's lookups. Every field of the JSON motion has its twin here
//! — layers (a clip or a graph, retarget), root motion, IK, the character
//! and its retarget, spring chains and their substep rate — and a graph
//! request's timed `inputs`. Empty strings and lists are the JSON's absent
//! fields; the refusals that only the protobuf can make (an undefined enum
//! number, an unset oneof, a missing required message) are at the pointer
//! of the JSON field.

use std::collections::BTreeMap;

use super::doc::DocError;
use super::graph_inputs::{InputDoc, escape};
use super::motion::{
    FeetDoc, LayerDoc, LayerModeDoc, MaskDoc, MotionDoc, RetargetDoc, RootModeDoc, RootMotionDoc, SourcePoseDoc,
    TranslationDoc, UpAxisDoc,
};
use super::proto::{ik_doc_from_pb, layer_mode_from_pb, pb, playback_from_pb, root_mode_from_pb, up_axis_from_pb};
use super::proto_graph::value_from_proto;
use super::spring::{CapsuleDoc, ColliderDoc, JointParamsDoc, SphereDoc, SpringDoc};
use anim::graph::Value;
use anim::motion::{LayerMode, RootMode, UpAxis};
use anim::spring::SpringParams;

fn invalid(pointer: String, detail: impl Into<String>) -> DocError {
    DocError { code: "invalid_field", pointer, detail: detail.into() }
}

/// A protobuf motion → the JSON motion document, clip, graph and character
/// references still to be looked up.
///
/// # Errors
/// An undefined enum number, a `SourcePose` or collider naming neither of
/// its kinds, a capsule without its `tail`, an IK constraint of the wrong
/// shape (as [`MotionDoc::to_spec`] refuses them), each at its JSON pointer
/// under `/motion`.
pub fn motion_doc_from_pb(motion: &pb::Motion) -> Result<MotionDoc, DocError> {
    let layers = (motion.layers.iter().enumerate())
        .map(|(i, l)| layer_doc(l, &format!("/motion/layers/{i}")))
        .collect::<Result<_, _>>()?;
    let root_motion = match &motion.root_motion {
        None => None,
        Some(r) => Some(RootMotionDoc {
            joint: text(&r.joint),
            mode: match root_mode_from_pb(r.mode, "/motion/root_motion/mode")?.unwrap_or_default() {
                RootMode::Report => RootModeDoc::Report,
                RootMode::Extract => RootModeDoc::Extract,
            },
            up: match up_axis_from_pb(r.up, "/motion/root_motion/up")?.unwrap_or_default() {
                UpAxis::Y => UpAxisDoc::Y,
                UpAxis::Z => UpAxisDoc::Z,
            },
        }),
    };
    let ik = (motion.ik.iter().enumerate())
        .map(|(i, c)| ik_doc_from_pb(c, &format!("/motion/ik/{i}")))
        .collect::<Result<_, _>>()?;
    let springs = (motion.springs.iter().enumerate())
        .map(|(i, s)| spring_doc(s, &format!("/motion/springs/{i}")))
        .collect::<Result<_, _>>()?;
    Ok(MotionDoc {
        layers,
        root_motion,
        ik,
        springs,
        spring_substep_hz: motion.spring_substep_hz,
        character: text(&motion.character),
        retarget: motion.retarget.as_ref().map(|r| retarget_doc(r, "/motion/retarget")).transpose()?,
    })
}

/// A graph request's `inputs` as the JSON's, for the one check of
/// `graph_inputs::inputs` against the graph.
///
/// # Errors
/// `bad_number` for a number that is not finite (JSON cannot send one), at
/// `/inputs/i/set/name`. An unset value is JSON's `null`, which the check
/// refuses as `parameter_type`.
pub fn inputs_from_pb(inputs: &[pb::GraphInput]) -> Result<Vec<InputDoc>, DocError> {
    let input = |(i, input): (usize, &pb::GraphInput)| {
        let set = (input.set.iter())
            .map(|(name, value)| {
                let json = match value_from_proto(value) {
                    None => serde_json::Value::Null,
                    Some(Value::Bool(b)) => serde_json::Value::Bool(b),
                    Some(Value::Float(n)) => {
                        serde_json::Number::from_f64(n).map(serde_json::Value::Number).ok_or_else(|| DocError {
                            code: "bad_number",
                            pointer: format!("/inputs/{i}/set/{}", escape(name)),
                            detail: format!("a parameter's value is a finite number, got {n}"),
                        })?
                    }
                };
                Ok((name.clone(), json))
            })
            .collect::<Result<BTreeMap<_, _>, DocError>>()?;
        Ok(InputDoc { time: input.time, set })
    };
    inputs.iter().enumerate().map(input).collect()
}

fn text(s: &str) -> Option<String> {
    (!s.is_empty()).then(|| s.to_owned())
}

fn layer_doc(l: &pb::Layer, at: &str) -> Result<LayerDoc, DocError> {
    Ok(LayerDoc {
        clip: l.clip_id.clone(),
        graph: text(&l.graph),
        weight: l.weight.unwrap_or(1.0),
        mode: match layer_mode_from_pb(l.mode, &format!("{at}/mode"))?.unwrap_or_default() {
            LayerMode::Blend => LayerModeDoc::Blend,
            LayerMode::Additive => LayerModeDoc::Additive,
        },
        mask: l.mask.as_ref().map(|m| MaskDoc {
            joints: m.joints.iter().map(|(name, w)| (name.clone(), *w)).collect(),
            descendants: m.descendants,
            default: m.default_weight,
        }),
        offset: l.offset,
        speed: l.speed.unwrap_or(1.0),
        playback: playback_from_pb(l.playback, &format!("{at}/playback"))?.map(Into::into),
        sync: text(&l.sync),
        reference_time: l.reference_time,
        retarget: l.retarget.as_ref().map(|r| retarget_doc(r, &format!("{at}/retarget"))).transpose()?,
    })
}

/// A `SourcePose` message (a retarget's `source_pose` or `target_pose`, at `at`).
fn pose_doc(pose: Option<&pb::SourcePose>, at: &str) -> Result<Option<SourcePoseDoc>, DocError> {
    use pb::source_pose::Pose;
    Ok(match pose.map(|p| &p.pose) {
        None => None,
        Some(None) => return Err(invalid(at.to_owned(), "a reference pose is a `time` or `rotations`")),
        Some(Some(Pose::Time(t))) => Some(SourcePoseDoc::Time(*t)),
        Some(Some(Pose::Rotations(r))) => Some(SourcePoseDoc::Rotations(
            r.joints.iter().map(|(name, q)| (name.clone(), [q.x, q.y, q.z, q.w])).collect(),
        )),
    })
}

fn retarget_doc(r: &pb::Retarget, at: &str) -> Result<RetargetDoc, DocError> {
    let source_pose = pose_doc(r.source_pose.as_ref(), &format!("{at}/source_pose"))?;
    let target_pose = pose_doc(r.target_pose.as_ref(), &format!("{at}/target_pose"))?;
    let translation = match pb::RetargetTranslation::try_from(r.translation) {
        Ok(pb::RetargetTranslation::Unspecified | pb::RetargetTranslation::Hips) => TranslationDoc::Hips,
        Ok(pb::RetargetTranslation::None) => TranslationDoc::None,
        Ok(pb::RetargetTranslation::All) => TranslationDoc::All,
        Err(_) => {
            let detail = format!("{} is not a valid RetargetTranslation", r.translation);
            return Err(invalid(format!("{at}/translation"), detail));
        }
    };
    Ok(RetargetDoc {
        source_pose,
        translation,
        target_pose,
        feet: r.feet.as_ref().map(|_| FeetDoc::Plant),
        contact_height: r.feet.as_ref().and_then(|f| f.contact_height),
        contact_speed: r.feet.as_ref().and_then(|f| f.contact_speed),
    })
}

fn vec3(v: Option<&pb::Vec3>) -> Option<[f32; 3]> {
    v.map(|v| [v.x, v.y, v.z])
}

fn spring_doc(s: &pb::Spring, at: &str) -> Result<SpringDoc, DocError> {
    let defaults = SpringParams::default();
    let joint_params = (s.joint_params.iter())
        .map(|(name, p)| {
            let doc = JointParamsDoc {
                stiffness: p.stiffness,
                drag: p.drag,
                gravity: vec3(p.gravity.as_ref()),
                radius: p.radius,
            };
            (name.clone(), doc)
        })
        .collect();
    let colliders = (s.colliders.iter().enumerate())
        .map(|(k, c)| collider_doc(c, &format!("{at}/colliders/{k}")))
        .collect::<Result<_, _>>()?;
    Ok(SpringDoc {
        name: s.name.clone(),
        joints: s.joints.clone(),
        stiffness: s.stiffness.unwrap_or(defaults.stiffness),
        drag: s.drag.unwrap_or(defaults.drag),
        gravity: vec3(s.gravity.as_ref()).unwrap_or_default(),
        radius: s.radius.unwrap_or(defaults.radius),
        joint_params,
        colliders,
    })
}

/// A collider naming neither shape becomes the JSON's collider with
/// neither, which the document's check refuses (`invalid_collider`).
fn collider_doc(c: &pb::SpringCollider, at: &str) -> Result<ColliderDoc, DocError> {
    use pb::spring_collider::Shape;
    let (mut sphere, mut capsule) = (None, None);
    match &c.shape {
        None => {}
        Some(Shape::Sphere(s)) => {
            sphere = Some(SphereDoc { offset: vec3(s.offset.as_ref()).unwrap_or_default(), radius: s.radius });
        }
        Some(Shape::Capsule(cap)) => {
            let Some(tail) = vec3(cap.tail.as_ref()) else {
                return Err(invalid(format!("{at}/capsule/tail"), "a capsule needs its `tail`"));
            };
            let offset = vec3(cap.offset.as_ref()).unwrap_or_default();
            capsule = Some(CapsuleDoc { offset, tail, radius: cap.radius });
        }
    }
    Ok(ColliderDoc { joint: c.joint.clone(), sphere, capsule })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v3(x: f32, y: f32, z: f32) -> Option<pb::Vec3> {
        Some(pb::Vec3 { x, y, z })
    }

    /// Every field of the JSON motion, written by hand as protobuf.
    fn every_field() -> pb::Motion {
        let rotations = pb::JointRotations {
            joints: [("LeftArm".to_owned(), pb::Quaternion { x: 0.0, y: 0.0, z: 0.6, w: 0.8 })].into(),
        };
        let capsule = pb::SpringCapsule { offset: None, tail: v3(0.0, 0.2, 0.0), radius: 0.05 };
        let sphere = pb::SpringSphere { offset: v3(0.0, 0.1, 0.0), radius: 0.1 };
        pb::Motion {
            layers: vec![
                pb::Layer {
                    clip_id: "walk".into(),
                    weight: Some(0.75),
                    mode: pb::LayerMode::Additive as i32,
                    mask: Some(pb::Mask {
                        joints: [("spine".to_owned(), 0.5)].into(),
                        descendants: true,
                        default_weight: Some(0.1),
                    }),
                    offset: 0.25,
                    speed: Some(-1.5),
                    playback: pb::Playback::PingPong as i32,
                    sync: "loco".into(),
                    reference_time: Some(0.4),
                    retarget: Some(pb::Retarget {
                        source_pose: Some(pb::SourcePose { pose: Some(pb::source_pose::Pose::Time(0.5)) }),
                        translation: pb::RetargetTranslation::All as i32,
                        target_pose: None,
                        feet: Some(pb::PlantFeet::default()),
                    }),
                    ..Default::default()
                },
                pb::Layer { graph: "name:loco".into(), ..Default::default() },
            ],
            root_motion: Some(pb::RootMotionOptions {
                joint: "hips".into(),
                mode: pb::RootMode::Extract as i32,
                up: pb::UpAxis::Z as i32,
            }),
            ik: Vec::new(),
            character: "name:cesium".into(),
            retarget: Some(pb::Retarget {
                source_pose: Some(pb::SourcePose { pose: Some(pb::source_pose::Pose::Rotations(rotations.clone())) }),
                translation: pb::RetargetTranslation::None as i32,
                target_pose: Some(pb::SourcePose { pose: Some(pb::source_pose::Pose::Rotations(rotations)) }),
                feet: Some(pb::PlantFeet { contact_height: Some(0.03), contact_speed: Some(0.2) }),
            }),
            springs: vec![
                pb::Spring {
                    name: "tail".into(),
                    joints: vec!["t0".into(), "t1".into(), "t2".into()],
                    stiffness: Some(2.0),
                    drag: Some(0.5),
                    gravity: v3(0.0, -9.81, 0.0),
                    radius: Some(0.03),
                    joint_params: [(
                        "t1".to_owned(),
                        pb::SpringJointParams {
                            stiffness: Some(0.5),
                            drag: None,
                            gravity: v3(0.0, -1.0, 0.0),
                            radius: None,
                        },
                    )]
                    .into(),
                    colliders: vec![
                        pb::SpringCollider {
                            joint: "hips".into(),
                            shape: Some(pb::spring_collider::Shape::Sphere(sphere)),
                        },
                        pb::SpringCollider {
                            joint: "hips".into(),
                            shape: Some(pb::spring_collider::Shape::Capsule(capsule)),
                        },
                    ],
                },
                pb::Spring { name: "ear".into(), joints: vec!["e0".into(), "e1".into()], ..Default::default() },
            ],
            spring_substep_hz: Some(240.0),
        }
    }

    #[test]
    fn a_protobuf_motion_is_the_json_motion_it_mirrors() {
        let json: MotionDoc = serde_json::from_str(
            r#"{"layers": [
                {"clip": "walk", "weight": 0.75, "mode": "additive",
                 "mask": {"joints": {"spine": 0.5}, "descendants": true, "default": 0.1},
                 "offset": 0.25, "speed": -1.5, "playback": "ping_pong", "sync": "loco", "reference_time": 0.4,
                 "retarget": {"source_pose": {"time": 0.5}, "translation": "all", "feet": "plant"}},
                {"graph": "name:loco"}
            ],
            "root_motion": {"joint": "hips", "mode": "extract", "up": "z"},
            "character": "name:cesium",
            "retarget": {"source_pose": {"rotations": {"LeftArm": [0, 0, 0.6, 0.8]}}, "translation": "none",
                         "target_pose": {"rotations": {"LeftArm": [0, 0, 0.6, 0.8]}}, "feet": "plant",
                         "contact_height": 0.03, "contact_speed": 0.2},
            "springs": [
                {"name": "tail", "joints": ["t0", "t1", "t2"], "stiffness": 2, "drag": 0.5, "gravity": [0, -9.81, 0],
                 "radius": 0.03, "joint_params": {"t1": {"stiffness": 0.5, "gravity": [0, -1, 0]}},
                 "colliders": [{"joint": "hips", "sphere": {"offset": [0, 0.1, 0], "radius": 0.1}},
                               {"joint": "hips", "capsule": {"tail": [0, 0.2, 0], "radius": 0.05}}]},
                {"name": "ear", "joints": ["e0", "e1"]}
            ],
            "spring_substep_hz": 240}"#,
        )
        .unwrap();
        assert_eq!(motion_doc_from_pb(&every_field()).unwrap(), json);
        assert_eq!(
            motion_doc_from_pb(&pb::Motion::default()).unwrap(),
            serde_json::from_str(r#"{"layers": []}"#).unwrap()
        );
    }

    #[test]
    fn what_only_protobuf_can_say_is_refused_at_the_json_pointer() {
        let refused = |edit: fn(&mut pb::Motion)| {
            let mut motion = every_field();
            edit(&mut motion);
            let e = motion_doc_from_pb(&motion).unwrap_err();
            (e.code, e.pointer)
        };
        let at = |code, pointer: &str| (code, pointer.to_owned());
        assert_eq!(
            refused(|m| m.layers[0].retarget.as_mut().unwrap().translation = 9),
            at("invalid_field", "/motion/layers/0/retarget/translation")
        );
        assert_eq!(
            refused(|m| m.retarget.as_mut().unwrap().source_pose = Some(pb::SourcePose { pose: None })),
            at("invalid_field", "/motion/retarget/source_pose")
        );
        assert_eq!(
            refused(|m| {
                let capsule = pb::SpringCapsule { offset: None, tail: None, radius: 0.05 };
                m.springs[0].colliders[1].shape = Some(pb::spring_collider::Shape::Capsule(capsule));
            }),
            at("invalid_field", "/motion/springs/0/colliders/1/capsule/tail")
        );
        assert_eq!(refused(|m| m.layers[1].mode = 7), at("invalid_field", "/motion/layers/1/mode"));
        // A collider of neither shape is the JSON's, which the document refuses.
        let mut motion = every_field();
        motion.springs[0].colliders[0].shape = None;
        let doc = motion_doc_from_pb(&motion).unwrap();
        let e = doc.springs("/motion").unwrap_err();
        assert_eq!((e.code, e.pointer.as_str()), ("invalid_collider", "/motion/springs/0/colliders/0"));
    }

    #[test]
    fn inputs_are_the_json_inputs_and_a_number_json_cannot_say_is_refused() {
        let set = |pairs: Vec<(&str, Option<pb::graph_value::Value>)>| {
            pairs.into_iter().map(|(n, v)| (n.to_owned(), pb::GraphValue { value: v })).collect()
        };
        use pb::graph_value::Value::{Flag, Number};
        let inputs = [
            pb::GraphInput { time: 1.0, set: set(vec![("speed", Some(Number(2.5)))]) },
            pb::GraphInput { time: 2.0, set: set(vec![("jump", Some(Flag(true))), ("unset", None)]) },
        ];
        let json: Vec<InputDoc> = serde_json::from_str(
            r#"[{"time": 1, "set": {"speed": 2.5}}, {"time": 2, "set": {"jump": true, "unset": null}}]"#,
        )
        .unwrap();
        assert_eq!(inputs_from_pb(&inputs).unwrap(), json);
        let nan = [pb::GraphInput { time: 0.0, set: set(vec![("a/b", Some(Number(f64::NAN)))]) }];
        let e = inputs_from_pb(&nan).unwrap_err();
        assert_eq!((e.code, e.pointer.as_str()), ("bad_number", "/inputs/0/set/a~1b"));
    }
}
