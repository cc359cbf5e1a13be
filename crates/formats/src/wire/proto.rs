//! The protobuf wire (`proto/inbetween/v1/animation.proto`, docs/api.md) and its
//! conversions to and from the core.
//!
//! The generated messages and client live in [`pb`]; the server trait in
//! [`server`] (generated separately so that stream frames can be sent
//! pre-encoded, see `build.rs`). Conversions mirror the JSON document
//! exactly: a proto [`pb::Clip`] becomes the same [`ClipSpec`] as the
//! equivalent JSON, and every error carries the JSON pointer of the field at
//! fault in the document shape of docs/clip-format.md §1 (`/tracks/3/values`), so REST and
//! gRPC clients read the same paths. Key arrays are flat on this wire (3 or 4
//! floats per key), so "wrong width" is the one check done here; everything
//! else is [`anim::Clip::build`]'s to judge.

use glam::{Mat4, Quat, Vec3, Vec4};

use std::collections::BTreeMap;

use crate::wire::ik::{EffectorDoc, IkDoc, IkKindDoc, KeysDoc, LimitDoc, TargetDoc, WeightDoc};
use crate::wire::json::{DocError, ParameterValues};
use anim::ik::{IkKind, IkReport, IkSpec};
use anim::motion::{LayerMode, Planar, RootMode, RootMotion, UpAxis};
use anim::{
    Channel, ClipSpec, Ease, Ends, EventSpec, Interpolation, JointSpec, KeyedIkSpec, Keys, MAX_PARAMETER_WIDTH,
    ParameterSpec, Playback, Pose, SkeletonSpec, Space, Speed, TrackSpec, Transform,
};

/// Messages and the client generated from the proto.
#[allow(clippy::all, missing_docs)]
pub mod pb {
    tonic::include_proto!("inbetween.v1");
}

/// The generated server trait (`Animation`) and `AnimationServer`.
#[allow(clippy::all, missing_docs)]
pub mod server {
    include!(concat!(env!("OUT_DIR"), "/server/inbetween.v1.rs"));
}

/// The encoded `FileDescriptorSet` of `proto/`, for server reflection.
pub const FILE_DESCRIPTOR_SET: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/inbetween_descriptor.bin"));

fn invalid(pointer: String, detail: impl Into<String>) -> DocError {
    DocError { code: "invalid_field", pointer, detail: detail.into() }
}

/// Proto enum (open: any `i32` may arrive) → core enum. `Unspecified` maps
/// to `None`, which the caller resolves to the documented default.
macro_rules! proto_enum {
    ($fn_from:ident, $fn_to:ident, $pb:ident => $core:ident { $($pv:ident = $cv:ident),+ $(,)? }) => {
        /// The core value of a wire enum; `Ok(None)` for `*_UNSPECIFIED`.
        ///
        /// # Errors
        /// A number the proto does not define.
        pub fn $fn_from(value: i32, pointer: &str) -> Result<Option<$core>, DocError> {
            match pb::$pb::try_from(value) {
                Ok(pb::$pb::Unspecified) => Ok(None),
                $(Ok(pb::$pb::$pv) => Ok(Some($core::$cv)),)+
                Err(_) => Err(invalid(pointer.to_owned(), format!("{value} is not a valid {}", stringify!($pb)))),
            }
        }

        /// The wire value of a core enum.
        pub fn $fn_to(value: $core) -> pb::$pb {
            match value { $($core::$cv => pb::$pb::$pv),+ }
        }
    };
}

proto_enum!(channel_from_pb, channel_to_pb, Channel => Channel {
    Translation = Translation, Rotation = Rotation, Scale = Scale,
});
proto_enum!(interpolation_from_pb, interpolation_to_pb, Interpolation => Interpolation {
    Step = Step, Linear = Linear, CatmullRom = CatmullRom, CubicHermite = CubicHermite, BSpline = BSpline,
});
proto_enum!(ends_from_pb, ends_to_pb, Ends => Ends {
    Reflect = Reflect, ZeroSlope = ZeroSlope, Wrap = Wrap, Phantom = Phantom,
});
proto_enum!(speed_from_pb, speed_to_pb, Speed => Speed { Keyed = Keyed, Constant = Constant });
proto_enum!(playback_from_pb, playback_to_pb, Playback => Playback { Once = Once, Loop = Loop, PingPong = PingPong });
proto_enum!(ease_from_pb, ease_to_pb, Ease => Ease {
    Linear = Linear, In = EaseIn, Out = EaseOut, InOut = EaseInOut,
});
proto_enum!(space_from_pb, space_to_pb, Space => Space { Local = Local, Model = Model });
proto_enum!(layer_mode_from_pb, layer_mode_to_pb, LayerMode => LayerMode { Blend = Blend, Additive = Additive });
proto_enum!(root_mode_from_pb, root_mode_to_pb, RootMode => RootMode { Report = Report, Extract = Extract });
proto_enum!(up_axis_from_pb, up_axis_to_pb, UpAxis => UpAxis { Y = Y, Z = Z });

/// A composed pose's root motion on the wire.
pub fn root_motion_to_pb(root: RootMotion) -> pb::RootMotion {
    let planar = |p: Planar| pb::Planar { x: p.translation.x, y: p.translation.y, z: p.translation.z, yaw: p.yaw };
    pb::RootMotion { delta: Some(planar(root.delta)), total: Some(planar(root.total)) }
}

/// `pose` keeping only `joints` (indices, in order): names, and 3/4/3 or 16
/// floats per joint.
pub fn select_joints(pose: pb::Pose, joints: &[usize]) -> pb::Pose {
    fn pick<T: Clone>(all: &[T], width: usize, joints: &[usize]) -> Vec<T> {
        joints.iter().flat_map(|&j| all.get(j * width..(j + 1) * width).unwrap_or_default().iter().cloned()).collect()
    }
    pb::Pose {
        joint_names: if pose.joint_names.is_empty() { Vec::new() } else { pick(&pose.joint_names, 1, joints) },
        translations: pick(&pose.translations, 3, joints),
        rotations: pick(&pose.rotations, 4, joints),
        scales: pick(&pose.scales, 3, joints),
        matrices: pick(&pose.matrices, 16, joints),
        ..pose
    }
}

/// Splits a flat float array into keys of `width` numbers.
fn keys(flat: &[f32], width: usize, pointer: String, channel: Channel) -> Result<Keys, DocError> {
    if !flat.len().is_multiple_of(width) {
        return Err(DocError {
            code: "wrong_width",
            pointer,
            detail: format!("{} keys have {width} numbers each; got {} numbers", channel.as_str(), flat.len()),
        });
    }
    Ok(if width == 4 {
        Keys::Vec4(flat.chunks_exact(4).map(Vec4::from_slice).collect())
    } else {
        Keys::Vec3(flat.chunks_exact(3).map(Vec3::from_slice).collect())
    })
}

/// An optional fixed-width part of a transform: empty or exactly `N` floats.
fn part<const N: usize>(flat: &[f32], pointer: String) -> Result<Option<[f32; N]>, DocError> {
    match flat.len() {
        0 => Ok(None),
        n if n == N => Ok(Some(flat.try_into().expect("length checked"))),
        n => Err(DocError { code: "wrong_width", pointer, detail: format!("expected {N} numbers or none, got {n}") }),
    }
}

/// The core's authoring form of a proto clip.
///
/// # Errors
/// Flat arrays of the wrong width, enum numbers the proto does not define,
/// a track without a channel; each with its JSON pointer.
pub fn clip_from_pb(clip: &pb::Clip) -> Result<ClipSpec, DocError> {
    let skeleton = match &clip.skeleton {
        None => None,
        Some(s) => {
            let mut joints = Vec::with_capacity(s.joints.len());
            for (j, joint) in s.joints.iter().enumerate() {
                let at = format!("/skeleton/joints/{j}");
                let rest = joint.rest.clone().unwrap_or_default();
                let translation = part::<3>(&rest.translation, format!("{at}/rest/translation"))?;
                let rotation = part::<4>(&rest.rotation, format!("{at}/rest/rotation"))?;
                let scale = part::<3>(&rest.scale, format!("{at}/rest/scale"))?;
                let inverse_bind = part::<16>(&joint.inverse_bind, format!("{at}/inverse_bind"))?;
                joints.push(JointSpec {
                    name: joint.name.clone(),
                    parent: joint.parent.clone(),
                    rest: Transform {
                        translation: translation.map_or(Vec3::ZERO, Vec3::from),
                        rotation: rotation.map_or(Quat::IDENTITY, Quat::from_array),
                        scale: scale.map_or(Vec3::ONE, Vec3::from),
                    },
                    inverse_bind: inverse_bind.map(|m| Mat4::from_cols_array(&m)),
                });
            }
            Some(SkeletonSpec { joints })
        }
    };
    let mut tracks = Vec::with_capacity(clip.tracks.len());
    for (i, t) in clip.tracks.iter().enumerate() {
        let at = |field: &str| format!("/tracks/{i}/{field}");
        let channel = channel_from_pb(t.channel, &at("channel"))?
            .ok_or_else(|| invalid(at("channel"), "a track needs a channel: translation, rotation or scale"))?;
        let width = channel.width();
        let tangents = |flat: &[f32], field: &str| {
            if flat.is_empty() { Ok(None) } else { keys(flat, width, at(field), channel).map(Some) }
        };
        let ends = match t.ends {
            None => None,
            Some(e) => Some(ends_from_pb(e, &at("ends"))?.unwrap_or_default()),
        };
        tracks.push(TrackSpec {
            joint: t.joint.clone(),
            channel,
            interpolation: interpolation_from_pb(t.interpolation, &at("interpolation"))?
                .unwrap_or(Interpolation::Linear),
            times: t.times.clone(),
            values: keys(&t.values, width, at("values"), channel)?,
            in_tangents: tangents(&t.in_tangents, "in_tangents")?,
            out_tangents: tangents(&t.out_tangents, "out_tangents")?,
            ends,
            tension: t.tension,
            speed: speed_from_pb(t.speed, &at("speed"))?.unwrap_or_default(),
        });
    }
    Ok(ClipSpec {
        name: clip.name.clone(),
        skeleton,
        tracks,
        events: clip.events.iter().map(|e| EventSpec { time: e.time, name: e.name.clone() }).collect(),
        playback: playback_from_pb(clip.playback, "/playback")?.unwrap_or_default(),
        ik: (clip.ik.iter().enumerate())
            .map(|(i, c)| ik_doc_from_pb(c, &format!("/ik/{i}"))?.to_keyed_spec(&format!("/ik/{i}")))
            .collect::<Result<_, _>>()?,
        parameters: (clip.parameters.iter().enumerate())
            .map(|(i, p)| parameter_from_pb(p, &format!("/parameters/{i}")))
            .collect::<Result<_, _>>()?,
    })
}

/// A parameter track: its flat arrays cut into rows of `width`.
///
/// # Errors
/// `parameter_width` for a width outside 1..=256 (the JSON document's code),
/// `wrong_width` for arrays that are not whole rows, an undefined enum.
fn parameter_from_pb(p: &pb::Parameter, at: &str) -> Result<ParameterSpec, DocError> {
    let width = p.width as usize;
    if !(1..=MAX_PARAMETER_WIDTH).contains(&width) {
        let detail = format!("a parameter's keys have 1 to {MAX_PARAMETER_WIDTH} numbers each, got {width}");
        return Err(DocError { code: "parameter_width", pointer: format!("{at}/width"), detail });
    }
    let rows = |flat: &[f32], field: &str| -> Result<Vec<Vec<f32>>, DocError> {
        if !flat.len().is_multiple_of(width) {
            let detail = format!("parameter keys have {width} numbers each; got {} numbers", flat.len());
            return Err(DocError { code: "wrong_width", pointer: format!("{at}/{field}"), detail });
        }
        Ok(flat.chunks_exact(width).map(<[f32]>::to_vec).collect())
    };
    let tangents = |flat: &[f32], field| if flat.is_empty() { Ok(None) } else { rows(flat, field).map(Some) };
    let ends = match p.ends {
        None => None,
        Some(e) => Some(ends_from_pb(e, &format!("{at}/ends"))?.unwrap_or_default()),
    };
    Ok(ParameterSpec {
        name: p.name.clone(),
        interpolation: interpolation_from_pb(p.interpolation, &format!("{at}/interpolation"))?
            .unwrap_or(Interpolation::Linear),
        times: p.times.clone(),
        values: rows(&p.values, "values")?,
        in_tangents: tangents(&p.in_tangents, "in_tangents")?,
        out_tangents: tangents(&p.out_tangents, "out_tangents")?,
        ends,
        tension: p.tension,
    })
}

/// The proto form of a parameter track (rows flattened; the width is the
/// first row's, all rows of a valid clip having one).
fn parameter_to_pb(p: &ParameterSpec) -> pb::Parameter {
    let flat = |rows: &[Vec<f32>]| rows.iter().flatten().copied().collect::<Vec<f32>>();
    pb::Parameter {
        name: p.name.clone(),
        interpolation: interpolation_to_pb(p.interpolation) as i32,
        times: p.times.clone(),
        width: p.values.first().map_or(0, Vec::len) as u32,
        values: flat(&p.values),
        in_tangents: p.in_tangents.as_deref().map(flat).unwrap_or_default(),
        out_tangents: p.out_tangents.as_deref().map(flat).unwrap_or_default(),
        ends: p.ends.map(|e| ends_to_pb(e) as i32),
        tension: p.tension,
    }
}

/// Adds a pose's parameters (docs/clip-format.md §3) to its message: the packed values,
/// and the names and widths when the pose carries joint names (`named`).
pub fn add_parameters(pose: &mut pb::Pose, values: Option<ParameterValues<'_>>, named: bool) {
    let Some(values) = values else { return };
    let layout = values.layout;
    for p in values.indices() {
        let width = layout.widths()[p];
        pose.parameters.extend((0..width as usize).map(|c| values.value(p, c)));
        if named {
            pose.parameter_names.push(layout.names()[p].clone());
            pose.parameter_widths.push(width);
        }
    }
}

/// The proto form of a clip spec (the inverse of `clip_from_pb`).
pub fn clip_to_pb(spec: &ClipSpec) -> pb::Clip {
    let flat = |k: &Keys| -> Vec<f32> {
        match k {
            Keys::Vec3(v) => v.iter().flat_map(|x| x.to_array()).collect(),
            Keys::Vec4(v) => v.iter().flat_map(|x| x.to_array()).collect(),
        }
    };
    let or_empty = |keep: bool, v: &[f32]| if keep { v.to_vec() } else { Vec::new() };
    pb::Clip {
        name: spec.name.clone(),
        skeleton: spec.skeleton.as_ref().map(|s| pb::Skeleton {
            joints: s
                .joints
                .iter()
                .map(|j| pb::Joint {
                    name: j.name.clone(),
                    parent: j.parent.clone(),
                    rest: Some(pb::Transform {
                        translation: or_empty(j.rest.translation != Vec3::ZERO, &j.rest.translation.to_array()),
                        rotation: or_empty(j.rest.rotation != Quat::IDENTITY, &j.rest.rotation.to_array()),
                        scale: or_empty(j.rest.scale != Vec3::ONE, &j.rest.scale.to_array()),
                    }),
                    inverse_bind: j.inverse_bind.map(|m| m.to_cols_array().to_vec()).unwrap_or_default(),
                })
                .collect(),
        }),
        tracks: spec
            .tracks
            .iter()
            .map(|t| pb::Track {
                joint: t.joint.clone(),
                channel: channel_to_pb(t.channel) as i32,
                interpolation: interpolation_to_pb(t.interpolation) as i32,
                times: t.times.clone(),
                values: flat(&t.values),
                in_tangents: t.in_tangents.as_ref().map(flat).unwrap_or_default(),
                out_tangents: t.out_tangents.as_ref().map(flat).unwrap_or_default(),
                ends: t.ends.map(|e| ends_to_pb(e) as i32),
                tension: t.tension,
                speed: speed_to_pb(t.speed) as i32,
            })
            .collect(),
        events: spec.events.iter().map(|e| pb::Event { time: e.time, name: e.name.clone() }).collect(),
        playback: playback_to_pb(spec.playback) as i32,
        ik: spec.ik.iter().map(ik_to_pb).collect(),
        parameters: spec.parameters.iter().map(parameter_to_pb).collect(),
    }
}

/// A request's or stream control's constraints (fixed targets and
/// weights); `pointer` is the list's place (`/motion/ik`, `/constraints`).
///
/// # Errors
/// As the JSON form ([`IkDoc::to_spec`]): `missing_field`,
/// `keys_not_allowed`, `wrong_width`, undefined enum numbers; each at its
/// pointer (`/motion/ik/1/target`).
pub fn ik_from_pb(list: &[pb::IkConstraint], pointer: &str) -> Result<Vec<IkSpec>, DocError> {
    (list.iter().enumerate())
        .map(|(i, c)| {
            let at = format!("{pointer}/{i}");
            ik_doc_from_pb(c, &at)?.to_spec(&at)
        })
        .collect()
}

/// A constraint message as the JSON document it stands for, so both wires
/// share one set of shape rules ([`IkDoc`]'s). The proto cannot name a
/// field its kind does not take; empty strings and lists are absent (the
/// JSON's missing fields). Only flat keys are checked here: their width,
/// naming the first incomplete key (`/ik/0/target/values/3`).
pub(super) fn ik_doc_from_pb(c: &pb::IkConstraint, pointer: &str) -> Result<IkDoc, DocError> {
    use pb::ik_constraint::Kind;
    let names = |v: &[String]| (!v.is_empty()).then(|| v.to_vec());
    let target = |t: &Option<pb::IkTarget>, at: String| target_doc(t.as_ref(), &at);
    let weight = |w: &Option<pb::IkWeight>| weight_doc(w.as_ref(), &format!("{pointer}/weight"));
    let mut doc;
    match &c.kind {
        None => {
            let detail = "a constraint needs its kind: two_bone, aim or chain";
            return Err(DocError { code: "missing_field", pointer: format!("{pointer}/kind"), detail: detail.into() });
        }
        Some(Kind::TwoBone(t)) => {
            doc = IkDoc::empty(IkKindDoc::TwoBone);
            doc.joints = names(&t.joints);
            doc.target = target(&t.target, format!("{pointer}/target"))?;
            doc.pole = t.pole.as_ref().map(vec3);
            doc.weight = weight(&t.weight)?;
        }
        Some(Kind::Aim(a)) => {
            doc = IkDoc::empty(IkKindDoc::Aim);
            doc.joint = (!a.joint.is_empty()).then(|| a.joint.clone());
            doc.target = target(&a.target, format!("{pointer}/target"))?;
            (doc.forward, doc.up, doc.up_direction) =
                (a.forward.as_ref().map(vec3), a.up.as_ref().map(vec3), a.up_direction.as_ref().map(vec3));
            doc.weight = weight(&a.weight)?;
        }
        Some(Kind::Chain(ch)) => {
            doc = IkDoc::empty(IkKindDoc::Chain);
            doc.effectors = if ch.effectors.is_empty() { None } else { Some(effector_docs(ch, pointer)?) };
            doc.joints = names(&ch.joints);
            doc.limits = if ch.limits.is_empty() { None } else { Some(limit_docs(ch, pointer)?) };
            (doc.max_iterations, doc.tolerance) = (ch.max_iterations, ch.tolerance);
            doc.weight = weight(&ch.weight)?;
        }
    }
    Ok(doc)
}

fn vec3(v: &pb::Vec3) -> [f32; 3] {
    [v.x, v.y, v.z]
}

fn effector_docs(ch: &pb::IkChain, pointer: &str) -> Result<Vec<EffectorDoc>, DocError> {
    (ch.effectors.iter().enumerate())
        .map(|(i, e)| {
            let at = format!("{pointer}/effectors/{i}/target");
            let target = target_doc(e.target.as_ref(), &at)?.ok_or_else(|| DocError {
                code: "missing_field",
                pointer: at,
                detail: "an effector needs `target`".into(),
            })?;
            Ok(EffectorDoc { joint: e.joint.clone(), target, tip: e.tip.as_ref().map(vec3) })
        })
        .collect()
}

/// The limits by joint name (the JSON object's order: sorted).
fn limit_docs(ch: &pb::IkChain, pointer: &str) -> Result<BTreeMap<String, LimitDoc>, DocError> {
    let mut limits = BTreeMap::new();
    for (joint, l) in &ch.limits {
        let bound = |v: &Option<pb::Vec3>, field: &str| {
            v.as_ref().map(vec3).ok_or_else(|| {
                let at = anim::Path::root().field("limits").key(joint).to_pointer();
                let pointer = format!("{pointer}{at}/{field}");
                DocError { code: "missing_field", pointer, detail: format!("a joint's limits need `{field}`") }
            })
        };
        limits.insert(joint.clone(), LimitDoc { min: bound(&l.min, "min")?, max: bound(&l.max, "max")? });
    }
    Ok(limits)
}

fn target_doc(t: Option<&pb::IkTarget>, pointer: &str) -> Result<Option<TargetDoc>, DocError> {
    use pb::ik_target::Target;
    Ok(match t.and_then(|t| t.target.as_ref()) {
        None => None,
        Some(Target::Point(p)) => Some(TargetDoc::Point(vec3(p))),
        Some(Target::Keys(k)) => Some(TargetDoc::Keys(keys_doc(k, 3, pointer)?)),
    })
}

fn weight_doc(w: Option<&pb::IkWeight>, pointer: &str) -> Result<Option<WeightDoc>, DocError> {
    use pb::ik_weight::Weight;
    Ok(match w.and_then(|w| w.weight.as_ref()) {
        None => None,
        Some(Weight::Value(v)) => Some(WeightDoc::Fixed(*v)),
        Some(Weight::Keys(k)) => Some(WeightDoc::Keys(keys_doc(k, 1, pointer)?)),
    })
}

/// Flat keys of `width` numbers each as the JSON's rows.
fn keys_doc(k: &pb::IkKeys, width: usize, pointer: &str) -> Result<KeysDoc, DocError> {
    let rows = |flat: &[f32], field: &str| -> Result<Vec<Vec<f32>>, DocError> {
        if !flat.len().is_multiple_of(width) {
            let key = flat.len() / width;
            let detail = format!("keys here have {width} numbers each; got {} numbers, key {key} is short", flat.len());
            return Err(DocError { code: "wrong_width", pointer: format!("{pointer}/{field}/{key}"), detail });
        }
        Ok(flat.chunks_exact(width).map(<[f32]>::to_vec).collect())
    };
    let tangents = |flat: &[f32], field: &str| if flat.is_empty() { Ok(None) } else { rows(flat, field).map(Some) };
    let at = |field: &str| format!("{pointer}/{field}");
    let ends = match k.ends {
        None => None,
        Some(e) => Some(ends_from_pb(e, &at("ends"))?.unwrap_or_default().into()),
    };
    Ok(KeysDoc {
        interpolation: interpolation_from_pb(k.interpolation, &at("interpolation"))?
            .unwrap_or(Interpolation::Linear)
            .into(),
        times: k.times.clone(),
        values: rows(&k.values, "values")?,
        in_tangents: tangents(&k.in_tangents, "in_tangents")?,
        out_tangents: tangents(&k.out_tangents, "out_tangents")?,
        ends,
        tension: k.tension,
        speed: speed_from_pb(k.speed, &at("speed"))?.map(Into::into),
    })
}

/// The proto form of a clip's constraint (the inverse of the clip
/// conversion's, through the same JSON document).
pub fn ik_to_pb(spec: &KeyedIkSpec) -> pb::IkConstraint {
    use pb::ik_constraint::Kind;
    let doc = IkDoc::from_keyed_spec(spec);
    let v = |a: Option<[f32; 3]>| a.map(|[x, y, z]| pb::Vec3 { x, y, z });
    let target = |t: &Option<TargetDoc>| t.as_ref().map(target_to_pb);
    let weight = doc.weight.as_ref().map(|w| pb::IkWeight {
        weight: Some(match w {
            WeightDoc::Fixed(w) => pb::ik_weight::Weight::Value(*w),
            WeightDoc::Keys(k) => pb::ik_weight::Weight::Keys(keys_to_pb(k)),
        }),
    });
    let kind = match doc.kind {
        IkKindDoc::TwoBone => Kind::TwoBone(pb::IkTwoBone {
            joints: doc.joints.clone().unwrap_or_default(),
            target: target(&doc.target),
            pole: v(doc.pole),
            weight,
        }),
        IkKindDoc::Aim => Kind::Aim(pb::IkAim {
            joint: doc.joint.clone().unwrap_or_default(),
            target: target(&doc.target),
            forward: v(doc.forward),
            up: v(doc.up),
            up_direction: v(doc.up_direction),
            weight,
        }),
        IkKindDoc::Chain => Kind::Chain(pb::IkChain {
            effectors: (doc.effectors.iter().flatten())
                .map(|e| pb::IkEffector {
                    joint: e.joint.clone(),
                    target: Some(target_to_pb(&e.target)),
                    tip: v(e.tip),
                })
                .collect(),
            joints: doc.joints.clone().unwrap_or_default(),
            limits: (doc.limits.iter().flatten())
                .map(|(joint, l)| (joint.clone(), pb::IkLimit { min: v(Some(l.min)), max: v(Some(l.max)) }))
                .collect(),
            max_iterations: doc.max_iterations,
            tolerance: doc.tolerance,
            weight,
        }),
    };
    pb::IkConstraint { kind: Some(kind) }
}

fn target_to_pb(t: &TargetDoc) -> pb::IkTarget {
    use pb::ik_target::Target;
    pb::IkTarget {
        target: Some(match t {
            TargetDoc::Point([x, y, z]) => Target::Point(pb::Vec3 { x: *x, y: *y, z: *z }),
            TargetDoc::Keys(k) => Target::Keys(keys_to_pb(k)),
        }),
    }
}

fn keys_to_pb(k: &KeysDoc) -> pb::IkKeys {
    let flat = |rows: &[Vec<f32>]| rows.iter().flatten().copied().collect::<Vec<f32>>();
    pb::IkKeys {
        interpolation: interpolation_to_pb(k.interpolation.into()) as i32,
        times: k.times.clone(),
        values: flat(&k.values),
        in_tangents: k.in_tangents.as_deref().map(flat).unwrap_or_default(),
        out_tangents: k.out_tangents.as_deref().map(flat).unwrap_or_default(),
        ends: k.ends.map(|e| ends_to_pb(e.into()) as i32),
        tension: k.tension,
        speed: k.speed.map_or(pb::Speed::Unspecified, |s| speed_to_pb(s.into())) as i32,
    }
}

/// The wire value of a report's kind.
pub fn ik_kind_to_pb(kind: IkKind) -> pb::IkKind {
    match kind {
        IkKind::TwoBone => pb::IkKind::TwoBone,
        IkKind::Aim => pb::IkKind::Aim,
        IkKind::Chain => pb::IkKind::Chain,
    }
}

/// A pose's IK reports (docs/ik.md) on the wire.
pub fn ik_reports_to_pb(reports: &[IkReport]) -> Vec<pb::IkReport> {
    (reports.iter())
        .map(|r| pb::IkReport {
            kind: ik_kind_to_pb(r.kind) as i32,
            residual: r.residual,
            iterations: r.iterations,
            converged: r.converged,
        })
        .collect()
}

/// A pose as packed floats. `names` only when the reply is the first (or
/// only) pose of its call or stream.
pub fn pose_to_pb(names: Option<&[String]>, pose: &Pose, time: f64, clip_time: f32, space: Space) -> pb::Pose {
    pb::Pose {
        joint_names: names.map(<[String]>::to_vec).unwrap_or_default(),
        translations: pose.translations.iter().flat_map(|v| v.to_array()).collect(),
        rotations: pose.rotations.iter().flat_map(|q| q.to_array()).collect(),
        scales: pose.scales.iter().flat_map(|v| v.to_array()).collect(),
        time,
        clip_time,
        matrices: Vec::new(),
        space: space_to_pb(space) as i32,
        root_motion: None,
        ik: Vec::new(),
        ..Default::default()
    }
}

/// Column-major 4×4 matrices per joint (`FORMAT_MATRIX`/`FORMAT_SKINNING`),
/// always in model space.
pub fn matrices_to_pb(names: Option<&[String]>, matrices: &[Mat4], time: f64, clip_time: f32) -> pb::Pose {
    pb::Pose {
        joint_names: names.map(<[String]>::to_vec).unwrap_or_default(),
        matrices: matrices.iter().flat_map(|m| m.to_cols_array()).collect(),
        time,
        clip_time,
        space: pb::Space::Model as i32,
        ..Default::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::json::{ClipDoc, parse_clip};
    use anim::Clip;

    /// A motion message read as the service reads it: the JSON document it
    /// stands for, then that document's spec.
    fn motion_from_pb(motion: &pb::Motion) -> Result<anim::motion::MotionSpec<String>, DocError> {
        crate::wire::proto_motion::motion_doc_from_pb(motion)?.to_spec("/motion")
    }

    fn wave() -> ClipSpec {
        let body = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/wave.json")).unwrap();
        parse_clip(&body).unwrap().1
    }

    #[test]
    fn a_clip_survives_the_round_trip_through_proto() {
        let spec = wave();
        let back = clip_from_pb(&clip_to_pb(&spec)).unwrap();
        assert_eq!(back, spec);
        assert_eq!(Clip::build(&back).unwrap(), Clip::build(&spec).unwrap());
    }

    #[test]
    fn the_proto_document_survives_the_json_document() {
        let spec = wave();
        let doc = ClipDoc::from_spec(&spec);
        let back = clip_from_pb(&clip_to_pb(&doc.to_spec().unwrap())).unwrap();
        assert_eq!(ClipDoc::from_spec(&back), doc);
    }

    fn check_error(edit: impl FnOnce(&mut pb::Clip), code: &str, pointer: &str) {
        let mut clip = clip_to_pb(&wave());
        edit(&mut clip);
        let err = clip_from_pb(&clip).unwrap_err();
        assert_eq!((err.code, err.pointer.as_str()), (code, pointer), "{err}");
    }

    #[test]
    fn errors_carry_the_json_pointer_of_the_field() {
        check_error(|c| c.tracks[1].values.truncate(11), "wrong_width", "/tracks/1/values");
        check_error(|c| c.tracks[0].channel = 0, "invalid_field", "/tracks/0/channel");
        check_error(|c| c.tracks[0].channel = 42, "invalid_field", "/tracks/0/channel");
        check_error(|c| c.tracks[1].ends = Some(9), "invalid_field", "/tracks/1/ends");
        check_error(|c| c.playback = -1, "invalid_field", "/playback");
        check_error(
            |c| c.skeleton.as_mut().unwrap().joints[1].rest.as_mut().unwrap().translation = vec![1.0, 2.0],
            "wrong_width",
            "/skeleton/joints/1/rest/translation",
        );
        check_error(
            |c| c.skeleton.as_mut().unwrap().joints[0].inverse_bind = vec![0.0; 15],
            "wrong_width",
            "/skeleton/joints/0/inverse_bind",
        );
    }

    #[test]
    fn a_proto_clip_with_a_core_error_reports_the_cores_path() {
        let mut clip = clip_to_pb(&wave());
        clip.tracks[0].times[2] = 0.5; // not increasing
        let spec = clip_from_pb(&clip).unwrap();
        let err: DocError = Clip::build(&spec).unwrap_err().into();
        assert!(err.pointer.starts_with("/tracks/0/times"), "{err}");
    }

    /// A leg and a head with one constraint of each kind, using every
    /// field: keyed targets (linear, Catmull-Rom with ends and tension,
    /// Hermite with tangents, constant speed), keyed and fixed weights,
    /// poles, axes, limits.
    const IK_CLIP: &str = r#"{
        "name": "ik",
        "skeleton": {"joints": [
            {"name": "hip"},
            {"name": "knee", "parent": "hip", "rest": {"translation": [0, -1, 0]}},
            {"name": "foot", "parent": "knee", "rest": {"translation": [0, -1, 0]}},
            {"name": "head", "parent": "hip", "rest": {"translation": [0, 1, 0]}}
        ]},
        "tracks": [{"joint": "hip", "channel": "translation", "times": [0, 2], "values": [[0, 0, 0], [0, 0, 0]]}],
        "ik": [
            {"kind": "two_bone", "joints": ["hip", "knee", "foot"], "pole": [0, -1, 2],
             "target": {"interpolation": "catmull_rom", "times": [0, 1, 2],
                        "values": [[0.5, -1.5, 0], [0.2, -1.4, 0.3], [0, -1.2, 0.5]],
                        "ends": "zero_slope", "tension": 0.25, "speed": "constant"},
             "weight": {"interpolation": "step", "times": [0, 1.5], "values": [[1], [0.5]]}},
            {"kind": "aim", "joint": "head", "target": [1, 2, 3], "forward": [1, 0, 0], "up": [0, 1, 0],
             "up_direction": [0, 0, 1], "weight": 0.75},
            {"kind": "chain", "effectors": [
                {"joint": "foot", "target": {"interpolation": "cubic_hermite", "times": [0, 2],
                    "values": [[0, -2, 0], [0.5, -1.5, 0]],
                    "in_tangents": [[0, 0, 0], [1, 0, 0]], "out_tangents": [[0, 1, 0], [0, 0, 0]]},
                 "tip": [0, -0.1, 0]},
                {"joint": "head", "target": [0, 1, 0.5]}],
             "joints": ["hip", "knee"],
             "limits": {"knee": {"min": [-1, -1, -1], "max": [1, 1, 1]}, "hip": {"min": [0, 0, 0], "max": [0.5, 0.5, 0.5]}},
             "max_iterations": 50, "tolerance": 0.001, "weight": 0.5}
        ]
    }"#;

    fn ik_clip() -> ClipSpec {
        parse_clip(IK_CLIP.as_bytes()).unwrap().1
    }

    #[test]
    fn a_clip_with_keyed_ik_round_trips_json_proto_json() {
        let spec = ik_clip();
        assert_eq!(spec.ik.len(), 3);
        let pb = clip_to_pb(&spec);
        let back = clip_from_pb(&pb).unwrap();
        assert_eq!(back, spec);
        assert_eq!(ClipDoc::from_spec(&back), ClipDoc::from_spec(&spec));
        let json: serde_json::Value = serde_json::to_value(ClipDoc::from_spec(&back)).unwrap();
        let original: serde_json::Value = serde_json::from_str(IK_CLIP).unwrap();
        let limits = |v: &serde_json::Value| -> BTreeMap<String, LimitDoc> {
            serde_json::from_value(v["ik"][2]["limits"].clone()).unwrap()
        };
        let values = |v: &serde_json::Value| -> Vec<Vec<f32>> {
            serde_json::from_value(v["ik"][0]["target"]["values"].clone()).unwrap()
        };
        assert_eq!(limits(&json), limits(&original));
        assert_eq!(values(&json), values(&original));
        // The proto's shape, built by hand: flat keys, one float per weight key.
        let pb::ik_constraint::Kind::TwoBone(leg) = pb.ik[0].kind.clone().unwrap() else { panic!("two_bone first") };
        let Some(pb::ik_target::Target::Keys(keys)) = leg.target.unwrap().target else { panic!("keyed target") };
        assert_eq!(keys.values, [0.5, -1.5, 0.0, 0.2, -1.4, 0.3, 0.0, -1.2, 0.5]);
        assert_eq!((keys.ends, keys.tension, keys.speed), (Some(pb::Ends::ZeroSlope as i32), Some(0.25), 2));
        let Some(pb::ik_weight::Weight::Keys(w)) = leg.weight.unwrap().weight else { panic!("keyed weight") };
        assert_eq!((w.values, w.interpolation), (vec![1.0, 0.5], pb::Interpolation::Step as i32));
        assert_eq!(Clip::build(&back).unwrap(), Clip::build(&spec).unwrap());
    }

    /// A request's constraints are the JSON's: `ik_from_pb(ik_to_pb(x))`
    /// equals the JSON form's `to_spec` for fixed constraints.
    #[test]
    fn request_constraints_match_the_json_form() {
        let json = serde_json::json!([
            {"kind": "two_bone", "joints": ["hip", "knee", "foot"], "target": [0.3, -1.5, 0.2]},
            {"kind": "aim", "joint": "head", "target": [1, 2, 3], "weight": 0.5},
            {"kind": "chain", "effectors": [{"joint": "foot", "target": [0, -1.8, 0.3]}], "max_iterations": 7}
        ]);
        let docs: Vec<IkDoc> = serde_json::from_value(json).unwrap();
        let from_json: Vec<IkSpec> =
            docs.iter().enumerate().map(|(i, d)| d.to_spec(&format!("/motion/ik/{i}")).unwrap()).collect();
        let keyed = |c: &IkSpec| {
            let targets = (0..c.target_count()).map(|_| anim::IkTarget::Fixed(Vec3::ZERO)).collect();
            KeyedIkSpec { constraint: c.clone(), targets, weight: None }
        };
        // Targets travel in the keyed form's `targets`: put them back.
        let list: Vec<pb::IkConstraint> = (from_json.iter())
            .map(|c| {
                let mut k = keyed(c);
                k.targets = match c {
                    IkSpec::TwoBone(t) => vec![anim::IkTarget::Fixed(t.target)],
                    IkSpec::Aim(a) => vec![anim::IkTarget::Fixed(a.target)],
                    IkSpec::Chain(ch) => ch.effectors.iter().map(|e| anim::IkTarget::Fixed(e.target)).collect(),
                };
                ik_to_pb(&k)
            })
            .collect();
        assert_eq!(ik_from_pb(&list, "/motion/ik").unwrap(), from_json);
        let motion = pb::Motion { ik: list, ..Default::default() };
        assert_eq!(motion_from_pb(&motion).unwrap().ik, from_json);
    }

    fn check_ik_error(edit: impl FnOnce(&mut [pb::IkConstraint]), code: &str, pointer: &str) {
        let mut clip = clip_to_pb(&ik_clip());
        edit(&mut clip.ik);
        let err = clip_from_pb(&clip).unwrap_err();
        assert_eq!((err.code, err.pointer.as_str()), (code, pointer), "{err}");
    }

    fn two_bone(c: &mut pb::IkConstraint) -> &mut pb::IkTwoBone {
        match c.kind.as_mut() {
            Some(pb::ik_constraint::Kind::TwoBone(t)) => t,
            _ => panic!("not two_bone"),
        }
    }

    fn chain(c: &mut pb::IkConstraint) -> &mut pb::IkChain {
        match c.kind.as_mut() {
            Some(pb::ik_constraint::Kind::Chain(t)) => t,
            _ => panic!("not chain"),
        }
    }

    fn keys_of(t: &mut Option<pb::IkTarget>) -> &mut pb::IkKeys {
        match t.as_mut().and_then(|t| t.target.as_mut()) {
            Some(pb::ik_target::Target::Keys(k)) => k,
            _ => panic!("not keyed"),
        }
    }

    #[test]
    fn ik_errors_carry_the_json_pointer_of_the_field() {
        check_ik_error(
            |ik| keys_of(&mut two_bone(&mut ik[0]).target).values.truncate(7),
            "wrong_width",
            "/ik/0/target/values/2",
        );
        check_ik_error(
            |ik| keys_of(&mut chain(&mut ik[2]).effectors[0].target).in_tangents.push(1.0),
            "wrong_width",
            "/ik/2/effectors/0/target/in_tangents/2",
        );
        check_ik_error(
            |ik| keys_of(&mut two_bone(&mut ik[0]).target).interpolation = 42,
            "invalid_field",
            "/ik/0/target/interpolation",
        );
        check_ik_error(
            |ik| keys_of(&mut two_bone(&mut ik[0]).target).ends = Some(9),
            "invalid_field",
            "/ik/0/target/ends",
        );
        check_ik_error(|ik| two_bone(&mut ik[0]).joints.pop().map(drop).unwrap_or(()), "wrong_width", "/ik/0/joints");
        check_ik_error(|ik| two_bone(&mut ik[0]).joints.clear(), "missing_field", "/ik/0/joints");
        check_ik_error(|ik| two_bone(&mut ik[0]).target = None, "missing_field", "/ik/0/target");
        check_ik_error(
            |ik| two_bone(&mut ik[0]).target = Some(pb::IkTarget { target: None }),
            "missing_field",
            "/ik/0/target",
        );
        check_ik_error(|ik| ik[1].kind = None, "missing_field", "/ik/1/kind");
        check_ik_error(
            |ik| {
                let Some(pb::ik_constraint::Kind::Aim(a)) = ik[1].kind.as_mut() else { panic!() };
                a.joint.clear();
            },
            "missing_field",
            "/ik/1/joint",
        );
        check_ik_error(|ik| chain(&mut ik[2]).effectors[1].target = None, "missing_field", "/ik/2/effectors/1/target");
        check_ik_error(|ik| chain(&mut ik[2]).effectors.clear(), "missing_field", "/ik/2/effectors");
        check_ik_error(
            |ik| chain(&mut ik[2]).limits.get_mut("knee").unwrap().max = None,
            "missing_field",
            "/ik/2/limits/knee/max",
        );
        check_ik_error(
            |ik| {
                let Some(pb::ik_weight::Weight::Keys(w)) =
                    two_bone(&mut ik[0]).weight.as_mut().unwrap().weight.as_mut()
                else {
                    panic!()
                };
                w.speed = 7;
            },
            "invalid_field",
            "/ik/0/weight/speed",
        );
    }

    #[test]
    fn the_cores_ik_refusals_name_the_proto_clips_fields() {
        let mut clip = clip_to_pb(&ik_clip());
        two_bone(&mut clip.ik[0]).joints[1] = "shin".into();
        let err: DocError = Clip::build(&clip_from_pb(&clip).unwrap()).unwrap_err().into();
        assert_eq!((err.code, err.pointer.as_str()), ("unknown_joint", "/ik/0/joints/1"), "{err}");
        let mut clip = clip_to_pb(&ik_clip());
        keys_of(&mut two_bone(&mut clip.ik[0]).target).times[1] = 3.0;
        let err: DocError = Clip::build(&clip_from_pb(&clip).unwrap()).unwrap_err().into();
        assert!(err.pointer.starts_with("/ik/0/target/times"), "{err}");
    }

    #[test]
    fn keys_in_a_request_are_refused_where_they_sit() {
        let clip = clip_to_pb(&ik_clip());
        // The weight is looked at first, as in the JSON form.
        let err = ik_from_pb(&clip.ik[..1], "/motion/ik").unwrap_err();
        assert_eq!((err.code, err.pointer.as_str()), ("keys_not_allowed", "/motion/ik/0/weight"));
        let mut fixed_weight = clip.ik[0].clone();
        two_bone(&mut fixed_weight).weight = Some(pb::IkWeight { weight: Some(pb::ik_weight::Weight::Value(0.5)) });
        let err = ik_from_pb(&[fixed_weight], "/motion/ik").unwrap_err();
        assert_eq!((err.code, err.pointer.as_str()), ("keys_not_allowed", "/motion/ik/0/target"));
        let mut fixed_target = clip.ik[0].clone();
        two_bone(&mut fixed_target).target =
            Some(pb::IkTarget { target: Some(pb::ik_target::Target::Point(pb::Vec3 { x: 0.0, y: -1.0, z: 0.0 })) });
        let err = ik_from_pb(&[clip.ik[1].clone(), fixed_target], "/constraints").unwrap_err();
        assert_eq!((err.code, err.pointer.as_str()), ("keys_not_allowed", "/constraints/1/weight"));
        let err = ik_from_pb(&clip.ik[2..], "/to/ik").unwrap_err();
        assert_eq!((err.code, err.pointer.as_str()), ("keys_not_allowed", "/to/ik/0/effectors/0/target"));
        let motion = pb::Motion { ik: vec![clip.ik[1].clone(), pb::IkConstraint::default()], ..Default::default() };
        let err = motion_from_pb(&motion).unwrap_err();
        assert_eq!((err.code, err.pointer.as_str()), ("missing_field", "/motion/ik/1/kind"));
    }

    #[test]
    fn reports_keep_their_kind_and_numbers() {
        use anim::ik::{IkKind, IkReport};
        let reports = [
            IkReport { kind: IkKind::Chain, residual: 0.25, iterations: 12, converged: false },
            IkReport { kind: IkKind::Aim, residual: 0.0, iterations: 0, converged: true },
        ];
        let pb = ik_reports_to_pb(&reports);
        assert_eq!(
            pb[0],
            pb::IkReport { kind: pb::IkKind::Chain as i32, residual: 0.25, iterations: 12, converged: false }
        );
        assert_eq!(pb[1].kind, pb::IkKind::Aim as i32);
        assert!(pb[1].converged);
    }

    #[test]
    fn poses_are_packed_in_joint_order() {
        let clip = Clip::build(&wave()).unwrap();
        let mut sampler = anim::Sampler::new();
        let ct = clip.sample(1.25, &Default::default(), &mut sampler);
        let p = pose_to_pb(Some(clip.skeleton().names()), sampler.pose(), 1.25, ct, Space::Local);
        assert_eq!(p.joint_names, ["root", "arm"]);
        assert_eq!(p.translations.len(), 6);
        assert_eq!(p.rotations.len(), 8);
        assert_eq!(&p.translations[3..6], &[0.0, 1.0, 0.0]); // the arm's rest translation
        assert_eq!(&p.translations[0..3], &sampler.pose().translations[0].to_array());
        assert_eq!(&p.rotations[4..8], &sampler.pose().rotations[1].to_array());
    }
}
