//! The protobuf wire (`proto/inbetween/v1/animation.proto`, SPEC §4) and its
//! conversions to and from the core.
//!
//! The generated messages and client live in [`pb`]; the server trait in
//! [`server`] (generated separately so that stream frames can be sent
//! pre-encoded, see `build.rs`). Conversions mirror the JSON document
//! exactly: a proto [`pb::Clip`] becomes the same [`ClipSpec`] as the
//! equivalent JSON, and every error carries the JSON pointer of the field at
//! fault in the document shape of SPEC §1 (`/tracks/3/values`), so REST and
//! gRPC clients read the same paths. Key arrays are flat on this wire (3 or 4
//! floats per key), so "wrong width" is the one check done here; everything
//! else is [`crate::anim::Clip::build`]'s to judge.

use glam::{Mat4, Quat, Vec3, Vec4};

use crate::anim::motion::{
    LayerMode, LayerSpec, MaskSpec, MotionSpec, Planar, RootMode, RootMotion, RootMotionSpec, UpAxis,
};
use crate::anim::{
    Channel, ClipSpec, Ease, Ends, EventSpec, Interpolation, JointSpec, Keys, Playback, Pose, SkeletonSpec, Space,
    Speed, TrackSpec, Transform,
};
use crate::wire::json::DocError;

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
    Step = Step, Linear = Linear, CatmullRom = CatmullRom, CubicHermite = CubicHermite,
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

/// A protobuf motion → the core's authoring form, clip ids still to be
/// looked up; enum numbers the proto does not define are refused at their
/// pointer (`/motion/layers/1/mode`).
///
/// # Errors
/// An undefined enum number.
pub(crate) fn motion_from_pb(motion: &pb::Motion) -> Result<MotionSpec<String>, DocError> {
    let layers = motion
        .layers
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let at = |field: &str| format!("/motion/layers/{i}/{field}");
            Ok(LayerSpec {
                clip: l.clip_id.clone(),
                weight: l.weight.unwrap_or(1.0),
                mode: layer_mode_from_pb(l.mode, &at("mode"))?.unwrap_or_default(),
                mask: l.mask.as_ref().map(|m| MaskSpec {
                    joints: m.joints.iter().map(|(name, w)| (name.clone(), *w)).collect(),
                    descendants: m.descendants,
                    default: m.default_weight,
                }),
                offset: l.offset,
                speed: l.speed.unwrap_or(1.0),
                playback: playback_from_pb(l.playback, &at("playback"))?,
                sync: (!l.sync.is_empty()).then(|| l.sync.clone()),
                reference_time: l.reference_time,
            })
        })
        .collect::<Result<Vec<_>, DocError>>()?;
    let root_motion = match &motion.root_motion {
        None => None,
        Some(r) => Some(RootMotionSpec {
            joint: (!r.joint.is_empty()).then(|| r.joint.clone()),
            mode: root_mode_from_pb(r.mode, "/motion/root_motion/mode")?.unwrap_or_default(),
            up: up_axis_from_pb(r.up, "/motion/root_motion/up")?.unwrap_or_default(),
        }),
    };
    Ok(MotionSpec { layers, root_motion })
}

/// A composed pose's root motion on the wire.
pub(crate) fn root_motion_to_pb(root: RootMotion) -> pb::RootMotion {
    let planar = |p: Planar| pb::Planar { x: p.translation.x, y: p.translation.y, z: p.translation.z, yaw: p.yaw };
    pb::RootMotion { delta: Some(planar(root.delta)), total: Some(planar(root.total)) }
}

/// `pose` keeping only `joints` (indices, in order): names, and 3/4/3 or 16
/// floats per joint.
pub(crate) fn select_joints(pose: pb::Pose, joints: &[usize]) -> pb::Pose {
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
pub(crate) fn clip_from_pb(clip: &pb::Clip) -> Result<ClipSpec, DocError> {
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
    })
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
    }
}

/// A pose as packed floats. `names` only when the reply is the first (or
/// only) pose of its call or stream.
pub(crate) fn pose_to_pb(names: Option<&[String]>, pose: &Pose, time: f64, clip_time: f32, space: Space) -> pb::Pose {
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
    }
}

/// Column-major 4×4 matrices per joint (`FORMAT_MATRIX`/`FORMAT_SKINNING`),
/// always in model space.
pub(crate) fn matrices_to_pb(names: Option<&[String]>, matrices: &[Mat4], time: f64, clip_time: f32) -> pb::Pose {
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
    use crate::anim::Clip;
    use crate::wire::json::{ClipDoc, parse_clip};

    fn wave() -> ClipSpec {
        let body = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/wave.json")).unwrap();
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

    #[test]
    fn poses_are_packed_in_joint_order() {
        let clip = Clip::build(&wave()).unwrap();
        let mut sampler = crate::anim::Sampler::new();
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
