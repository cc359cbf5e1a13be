//! A file's conventions turned into the server's: the up axis, the unit of
//! length and the playback mode an import asks for ([`ImportOptions::up`],
//! [`ImportOptions::scale`], [`ImportOptions::playback`]), applied to what
//! an importer produced before the clips are built; and the warnings about
//! conventions nobody asked to change (`looks_z_up`,
//! `units_look_like_centimeters`, `units_look_like_inches`).
//!
//! The change is one similarity `C = R·S` of the whole scene: `S` scales
//! every length by `s`, `R` (for `up=z`) turns Z-up into glTF's Y-up by −90°
//! about X. Every joint's model transform `W` becomes `R·S·W·S⁻¹`: every
//! local translation is scaled by `s` and each root's rest and keys are
//! turned by `R` (its translation too), so rotations and scales below the
//! roots are untouched. A skinned mesh follows: positions `C·p`, normals
//! `R·n`, inverse bind matrices `S·B·S⁻¹·R⁻¹`, so that every skinned vertex
//! `W′·B′·p′ = C·(W·B·p)` lands where the old one did, transformed by `C`.

use std::f32::consts::FRAC_PI_2;

use bytes::Bytes;
use glam::{Mat4, Quat, Vec3, Vec4};

use super::spec::{ImportOptions, Imported, UpAxis};
use super::warning::Warning;
use crate::wire::mesh;
use anim::spring::{ChainSpec, ColliderShape};
use anim::{Channel, ClipSpec, Keys, SkeletonSpec, TrackSpec};

/// Warned about: a skeleton lying along Z (its model-space extent along Z
/// the largest, or nearly, and along Y under half of it).
pub const LOOKS_Z_UP: &str = "looks_z_up";
/// Warned about: a skeleton far taller than a person in metres.
pub const UNITS_CENTIMETERS: &str = "units_look_like_centimeters";
pub const UNITS_INCHES: &str = "units_look_like_inches";
/// A skeleton whose largest model-space extent is over this many units is
/// not in metres (the tallest people and most creatures are under 5 m).
pub const MAX_METRES: f32 = 5.0;
/// A skeleton this many units across or more is taken to be in centimetres.
pub const CENTIMETRE_SIZE: f32 = 40.0;
/// Metres per inch, and per the CMU motion-capture database's unit.
pub const INCH: f32 = 0.0254;
pub const CMU_UNIT: f32 = 0.0254 / 0.45;

/// The whole-scene change of `options`: `R` and `s`.
#[derive(Debug, Clone, Copy)]
struct Change {
    turn: Quat,
    scale: f32,
}

impl Change {
    fn of(options: &ImportOptions) -> Option<Change> {
        let turn = match options.up {
            UpAxis::Y => Quat::IDENTITY,
            UpAxis::Z => Quat::from_rotation_x(-FRAC_PI_2),
        };
        (options.up != UpAxis::Y || options.scale != 1.0).then_some(Change { turn, scale: options.scale })
    }

    /// `C·p`: a model-space point.
    fn point(self, p: Vec3) -> Vec3 {
        self.turn * (p * self.scale)
    }

    /// `S·B·S⁻¹·R⁻¹`: an inverse bind matrix.
    fn inverse_bind(self, b: Mat4) -> Mat4 {
        let mut scaled = b;
        scaled.w_axis = (b.w_axis.truncate() * self.scale).extend(b.w_axis.w);
        scaled * Mat4::from_quat(self.turn.inverse())
    }
}

/// Applies `options`' playback, up axis and scale to every clip and mesh of
/// `imported`, then adds the warnings about conventions that still look
/// wrong (checked on the result, so `scale=0.01` silences the centimetres).
/// `skeleton_pointer` is where such a warning points in the file.
pub fn apply(imported: &mut Imported, options: &ImportOptions, skeleton_pointer: &str) {
    for clip in &mut imported.clips {
        clip.playback = options.playback;
    }
    if let Some(change) = Change::of(options) {
        for clip in &mut imported.clips {
            convert_clip(clip, change);
        }
        for chain in imported.springs.iter_mut().flatten() {
            convert_chain(chain, change);
        }
        for character in &mut imported.characters {
            convert_skeleton(&mut character.skeleton, change);
        }
        let mut done: Vec<(Bytes, Bytes)> = Vec::new();
        let character_meshes = imported.characters.iter_mut().filter_map(|c| c.mesh.as_mut());
        for kept in imported.meshes.iter_mut().flatten().chain(character_meshes) {
            // Clips of one skin share their mesh's bytes: converted once.
            if let Some((_, converted)) = done.iter().find(|(old, _)| old.as_ptr() == kept.as_ptr()) {
                *kept = converted.clone();
                continue;
            }
            let converted = convert_mesh(kept, change);
            done.push((std::mem::replace(kept, converted.clone()), converted));
        }
    }
    let mut seen: Vec<&'static str> = Vec::new();
    // What is kept is checked: the clips, or importing characters only, the characters (bind poses).
    let skeletons: Vec<&SkeletonSpec> = if options.characters_only {
        imported.characters.iter().map(|c| &c.skeleton).collect()
    } else {
        imported.clips.iter().filter_map(|c| c.skeleton.as_ref()).collect()
    };
    for skeleton in skeletons {
        for warning in skeleton_warnings(skeleton, options, skeleton_pointer) {
            let code = if warning.code == LOOKS_Z_UP { LOOKS_Z_UP } else { UNITS_CENTIMETERS };
            // Once per import: every clip of a file shares its skeleton's conventions.
            if !seen.contains(&code) {
                seen.push(code);
                imported.warnings.push(warning);
            }
        }
    }
}

/// A spring chain's lengths scaled and its gravity (model space) turned;
/// collider offsets are in their joints' frames, so only scaled.
fn convert_chain(chain: &mut ChainSpec, change: Change) {
    let s = change.scale;
    // A vector of model space changes as a point does (`C·g`).
    chain.params.gravity = change.point(chain.params.gravity);
    chain.params.radius *= s;
    for (_, p) in &mut chain.joint_params {
        p.gravity = p.gravity.map(|g| change.point(g));
        p.radius = p.radius.map(|r| r * s);
    }
    for collider in &mut chain.colliders {
        collider.shape = match collider.shape {
            ColliderShape::Sphere { offset, radius } => {
                ColliderShape::Sphere { offset: offset * s, radius: radius * s }
            }
            ColliderShape::Capsule { offset, tail, radius } => {
                ColliderShape::Capsule { offset: offset * s, tail: tail * s, radius: radius * s }
            }
        };
    }
}

/// The rest pose, keys and inverse binds of one clip, changed by `change`.
fn convert_clip(clip: &mut ClipSpec, change: Change) {
    let Some(skeleton) = &mut clip.skeleton else { return };
    let roots = convert_skeleton(skeleton, change);
    for track in &mut clip.tracks {
        let root = roots.contains(&track.joint);
        convert_track(track, change, root);
    }
}

/// The rest pose and inverse binds of one skeleton, changed by `change`;
/// returns its roots' names.
fn convert_skeleton(skeleton: &mut SkeletonSpec, change: Change) -> Vec<String> {
    let roots: Vec<String> = skeleton.joints.iter().filter(|j| j.parent.is_none()).map(|j| j.name.clone()).collect();
    for joint in &mut skeleton.joints {
        joint.rest.translation *= change.scale;
        if joint.parent.is_none() {
            joint.rest.translation = change.turn * joint.rest.translation;
            joint.rest.rotation = (change.turn * joint.rest.rotation).normalize();
        }
        joint.inverse_bind = joint.inverse_bind.map(|b| change.inverse_bind(b));
    }
    roots
}

/// One track's keys (and tangents, which transform as the keys do: the map is linear).
fn convert_track(track: &mut TrackSpec, change: Change, root: bool) {
    let turn = if root { change.turn } else { Quat::IDENTITY };
    let map = |keys: &mut Keys| match (track.channel, keys) {
        (Channel::Translation, Keys::Vec3(values)) => values.iter_mut().for_each(|v| *v = turn * (*v * change.scale)),
        (Channel::Rotation, Keys::Vec4(values)) if root => {
            values.iter_mut().for_each(|v| *v = Vec4::from(turn * Quat::from_vec4(*v)));
        }
        _ => {}
    };
    map(&mut track.values);
    track.in_tangents.as_mut().map(map);
    track.out_tangents.as_mut().map(map);
}

/// The mesh in the changed frame; bytes that do not decode (none the
/// importer wrote) are kept as they are.
fn convert_mesh(bytes: &Bytes, change: Change) -> Bytes {
    let Ok(mut m) = mesh::decode(bytes) else { return bytes.clone() };
    for p in m.positions.chunks_exact_mut(3) {
        p.copy_from_slice(&change.point(Vec3::from_slice(p)).to_array());
    }
    for n in m.normals.iter_mut().flat_map(|n| n.chunks_exact_mut(3)) {
        n.copy_from_slice(&(change.turn * Vec3::from_slice(n)).to_array());
    }
    for b in &mut m.inverse_binds {
        *b = change.inverse_bind(Mat4::from_cols_array(b)).to_cols_array();
    }
    Bytes::from(mesh::encode(&m))
}

/// The joints' model-space rest positions (parents listed first, as the
/// importers list them; a joint whose parent is not before it counts as a root).
pub fn rest_positions(skeleton: &SkeletonSpec) -> Vec<Vec3> {
    let mut world: Vec<Mat4> = Vec::with_capacity(skeleton.joints.len());
    for joint in &skeleton.joints {
        let local =
            Mat4::from_scale_rotation_translation(joint.rest.scale, joint.rest.rotation, joint.rest.translation);
        let parent = joint.parent.as_ref().and_then(|p| skeleton.joints.iter().position(|j| &j.name == p));
        let parent = parent.filter(|&p| p < world.len()).map_or(Mat4::IDENTITY, |p| world[p]);
        world.push(parent * local);
    }
    world.iter().map(|w| w.w_axis.truncate()).collect()
}

/// The size of the box around the points, per axis.
fn extent(points: &[Vec3]) -> Vec3 {
    let (lo, hi) = points.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
    if points.is_empty() { Vec3::ZERO } else { hi - lo }
}

/// The unit and up-axis warnings about one clip's skeleton: only for a
/// character (a skin, or a BVH body), not for a scene of animated objects.
fn skeleton_warnings(skeleton: &SkeletonSpec, options: &ImportOptions, pointer: &str) -> Vec<Warning> {
    let character = skeleton.joints.iter().any(|j| j.inverse_bind.is_some()) || pointer == "/HIERARCHY";
    if !character || skeleton.joints.len() < 3 {
        return Vec::new();
    }
    let size = extent(&rest_positions(skeleton));
    let mut out = Vec::new();
    if let Some(w) = units_warning(size.max_element(), options.scale, pointer) {
        out.push(w);
    }
    if size.z > 0.0 && size.z >= 0.8 * size.x && size.y < 0.5 * size.z {
        out.push(Warning::new(
            LOOKS_Z_UP,
            pointer,
            format!(
                "the skeleton lies along Z (its rest pose spans {:.3} along X, {:.3} along Y, {:.3} along Z): the \
                 file looks Z-up, and glTF and this server are Y-up, so it plays lying down{}",
                size.x,
                size.y,
                size.z,
                match options.up {
                    UpAxis::Y => "; import it with up=z",
                    UpAxis::Z => " even after up=z: was the file Y-up already?",
                }
            ),
        ));
    }
    out
}

/// The unit warning for a skeleton `size` units across (after `scale`):
/// centimetres from [`CENTIMETRE_SIZE`] units (a fox of 1 m is 100, a person
/// 170), else inches, or the CMU database's unit of 1/0.45 inch (5.64 cm),
/// which its BVH conversions keep (a person about 30 units tall).
fn units_warning(size: f32, scale: f32, pointer: &str) -> Option<Warning> {
    if !(size > MAX_METRES && size.is_finite()) {
        return None;
    }
    let (code, unit, fix) = if size >= CENTIMETRE_SIZE {
        (UNITS_CENTIMETERS, format!("centimetres ({:.2} m)", size * 0.01), format!("scale={}", 0.01 * scale))
    } else {
        let unit =
            format!("inches ({:.2} m), or the CMU mocap unit of 1/0.45 inch ({:.2} m)", size * INCH, size * CMU_UNIT);
        (UNITS_INCHES, unit, format!("scale={} (inches) or scale={} (CMU)", INCH * scale, CMU_UNIT * scale))
    };
    Some(Warning::new(
        code,
        pointer,
        format!(
            "the skeleton spans {size:.1} units in its rest pose, far more than a body in metres (the unit of glTF \
             and of this server): the file looks like it is in {unit}; import it with {fix}"
        ),
    ))
}

/// A track whose joint's parent chain scales it far from 1 (Mixamo files
/// through Blender: an `Armature` node scaled 0.01 over a pose in
/// centimetres): its translation keys, and root motion read from them, are
/// in other units than the pose. `None` when the parent scale is within
/// 0.1–10.
pub fn parent_scale(clip: &ClipSpec, joint: &str) -> Option<f32> {
    let skeleton = clip.skeleton.as_ref()?;
    let mut scale = 1.0f32;
    let mut at = skeleton.joints.iter().find(|j| j.name == joint)?.parent.clone();
    let mut steps = 0;
    while let Some(name) = at {
        let parent = skeleton.joints.iter().find(|j| j.name == name)?;
        scale *= parent.rest.scale.abs().max_element();
        at = parent.parent.clone();
        steps += 1;
        if steps > skeleton.joints.len() {
            return None;
        }
    }
    (!(0.1..=10.0).contains(&scale)).then_some(scale)
}

#[cfg(test)]
mod tests {
    use super::*;
    use anim::{Interpolation, JointSpec, Transform};

    fn joint(name: &str, parent: Option<&str>, t: Vec3) -> JointSpec {
        JointSpec {
            name: name.into(),
            parent: parent.map(Into::into),
            rest: Transform { translation: t, ..Transform::IDENTITY },
            inverse_bind: None,
        }
    }

    /// A two-joint chain along +Z, Z-up: hips at height 1 m, head 0.7 m above.
    fn z_up_clip() -> ClipSpec {
        let joints =
            vec![joint("hips", None, Vec3::new(0.0, 0.0, 1.0)), joint("head", Some("hips"), Vec3::new(0.0, 0.0, 0.7))];
        let track = TrackSpec::new(
            "hips",
            Channel::Translation,
            Interpolation::Linear,
            vec![0.0, 1.0],
            Keys::Vec3(vec![Vec3::new(0.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 1.0)]),
        );
        ClipSpec {
            name: "c".into(),
            skeleton: Some(SkeletonSpec { joints }),
            tracks: vec![track],
            ..Default::default()
        }
    }

    #[test]
    fn up_z_turns_the_roots_so_z_becomes_y_and_scale_scales_every_translation() {
        let mut clip = z_up_clip();
        convert_clip(&mut clip, Change { turn: Quat::from_rotation_x(-FRAC_PI_2), scale: 0.5 });
        let positions = rest_positions(clip.skeleton.as_ref().unwrap());
        // By hand: (x, y, z) ↦ (x, z, −y), then × 0.5.
        assert!(positions[0].abs_diff_eq(Vec3::new(0.0, 0.5, 0.0), 1e-6), "{:?}", positions[0]);
        assert!(positions[1].abs_diff_eq(Vec3::new(0.0, 0.85, 0.0), 1e-6), "{:?}", positions[1]);
        let Keys::Vec3(keys) = &clip.tracks[0].values else { unreachable!() };
        assert!(keys[1].abs_diff_eq(Vec3::new(1.0, 0.5, 0.0), 1e-6), "{:?}", keys[1]);
    }

    #[test]
    fn a_skinned_vertex_lands_where_it_did_transformed_by_the_change() {
        // One joint at (1, 2, 3) turned 30° about Y, bound where it stands.
        let world = Mat4::from_rotation_translation(Quat::from_rotation_y(0.5), Vec3::new(1.0, 2.0, 3.0));
        let bind = world.inverse();
        let p = Vec3::new(0.3, -0.2, 0.9);
        let change = Change { turn: Quat::from_rotation_x(-FRAC_PI_2), scale: 0.01 };
        // The joint as convert_clip leaves a root: turned, its translation scaled.
        let (s, r, t) = world.to_scale_rotation_translation();
        let new_world = Mat4::from_scale_rotation_translation(s, change.turn * r, change.turn * (t * 0.01));
        let skinned = new_world.transform_point3(change.inverse_bind(bind).transform_point3(change.point(p)));
        let expected = change.point(world.transform_point3(bind.transform_point3(p)));
        assert!(skinned.abs_diff_eq(expected, 1e-5), "{skinned:?} vs {expected:?}");
    }

    #[test]
    fn a_skeleton_along_z_is_said_to_look_z_up_and_one_in_centimetres_to_be_in_centimetres() {
        let clip = z_up_clip();
        let mut skinned = clip.clone();
        skinned.skeleton.as_mut().unwrap().joints.push(joint("toe", Some("hips"), Vec3::new(0.1, 0.0, -1.0)));
        for j in &mut skinned.skeleton.as_mut().unwrap().joints {
            j.inverse_bind = Some(Mat4::IDENTITY);
        }
        let codes = |c: &ClipSpec, o: &ImportOptions| -> Vec<String> {
            skeleton_warnings(c.skeleton.as_ref().unwrap(), o, "/nodes").into_iter().map(|w| w.code).collect()
        };
        assert_eq!(codes(&skinned, &ImportOptions::default()), [LOOKS_Z_UP]);
        assert_eq!(codes(&clip, &ImportOptions::default()), Vec::<String>::new(), "not a character: no skin");
        let mut big = skinned.clone();
        convert_clip(&mut big, Change { turn: Quat::from_rotation_x(-FRAC_PI_2), scale: 100.0 });
        assert_eq!(codes(&big, &ImportOptions::default()), [UNITS_CENTIMETERS], "170 units tall: centimetres");
        let mut inches = skinned;
        convert_clip(&mut inches, Change { turn: Quat::from_rotation_x(-FRAC_PI_2), scale: 17.0 });
        assert_eq!(codes(&inches, &ImportOptions::default()), [UNITS_INCHES], "29 units tall: inches, or CMU units");
    }
}
