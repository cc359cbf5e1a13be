//! glTF 2.0 (JSON or GLB) to clips: one clip per animation.
//!
//! The JSON is parsed and index-validated by the `gltf` crate; everything
//! that touches binary data (the container, buffers, accessors) is done by
//! this module's siblings with bounds checked first. The node graph is
//! checked to be a forest (one parent per node, no cycles) before any walk,
//! and every walk is iterative, so neither a cycle nor a deep chain can
//! hang or overflow the stack.

use std::collections::{HashMap, HashSet};

use ::gltf::Document;
use ::gltf::accessor::Dimensions;
use ::gltf::animation::{Interpolation as GltfInterpolation, Property};
use ::gltf::scene::Transform as GltfTransform;
use glam::{DMat4, Mat4, Quat, Vec3, Vec4};

use super::accessor::{Expect, read_f32};
use super::budget::{Budget, read_document};
use super::buffers::{Buffers, split_glb};
use super::convention;
use super::error::ImportError;
use super::mesh::{MeshPlan, MeshReader, Palette};
use super::names::{clip_name, is_generic_animation_name, unique_names};
use super::source::Source;
use super::spec::{Format, ImportOptions, Imported, ImportedCharacter, Resolver};
use super::vrm_humanoid;
use super::warning::{GENERIC_ANIMATION_NAME, NOT_IMPORTED, Warning};
use anim::lint::{self, Lint, LintCode};
use anim::{
    Channel, ClipSpec, Interpolation, JointSpec, Keys, MAX_PARAMETER_WIDTH, ParameterSpec, Playback, SkeletonSpec,
    TrackSpec, Transform,
};

pub fn import(
    source: &Source,
    format: Format,
    options: &ImportOptions,
    resolver: Option<Resolver<'_>>,
) -> Result<Imported, ImportError> {
    let limits = &options.limits;
    // A GLB is recognised by its magic whatever the caller called it.
    let (json, bin) = if format == Format::Glb || source.head(4)?.starts_with(b"glTF") {
        let glb = split_glb(source, limits.max_document_bytes)?;
        (glb.json, glb.bin)
    } else {
        (read_document(source, "the glTF JSON file", limits)?, None)
    };
    let json = json.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&json);
    let mut root: ::gltf::json::Root =
        ::gltf::json::deserialize::from_slice(json).map_err(|e| ImportError::Json(e.to_string()))?;
    // Morph weights are a parameter as wide as the node's mesh has targets:
    // counted before the meshes go.
    let morph_targets = morph_targets(&root);
    // So are the skinned meshes the viewer draws (read once the document is valid).
    let mesh_plan = MeshPlan::new(&root);
    strip_to_animation(&mut root);
    let doc = Document::from_json(root).map_err(|e| ImportError::InvalidGltf(validation_message(e)))?;
    check_channel_targets(&doc)?;

    let animation_count = doc.animations().len();
    if animation_count > limits.max_clips {
        return Err(ImportError::TooLarge {
            what: "the animations of one file",
            max: limits.max_clips as u64,
            found: animation_count as u64,
        });
    }
    let forest = Forest::new(&doc)?;
    let mut vrm_warnings = Vec::new();
    let (spring_chains, spring_nodes) = super::vrm::chains(json, &forest.names, &mut vrm_warnings)?;
    let human_bones = vrm_humanoid::human_bones(json, forest.names.len(), &mut vrm_warnings)?;
    let mut skins_of: Vec<Vec<usize>> = vec![Vec::new(); doc.nodes().len()];
    for skin in doc.skins() {
        for joint in skin.joints() {
            let of = &mut skins_of[joint.index()];
            if of.last() != Some(&skin.index()) {
                of.push(skin.index());
            }
        }
    }
    let mut ctx = Ctx {
        doc: &doc,
        forest,
        buffers: Buffers::new(&doc, bin, resolver, limits),
        options,
        budget: Budget::new(limits, source.len()),
        rest: HashMap::new(),
        inverse_binds: None,
        skins_of,
        morph_targets,
        warnings: Vec::new(),
        mesh_plan,
        meshes: HashMap::new(),
        mesh_bytes: 0,
        spring_nodes,
        human_bones,
        scene_name: (doc.default_scene().or_else(|| doc.scenes().next()))
            .and_then(|s| s.name().map(str::to_owned))
            .filter(|n| !n.trim().is_empty() && !is_generic_animation_name(n)),
    };
    let (mut clips, mut meshes, mut springs) = (Vec::new(), Vec::new(), Vec::new());
    if !options.characters_only {
        for animation in doc.animations() {
            if let Some((clip, skins)) = ctx.animation(&animation, animation_count)? {
                clips.push(clip);
                // A skinned character's clips carry its spring chains.
                springs.push(if skins.is_empty() { Vec::new() } else { spring_chains.clone() });
                meshes.push(ctx.mesh(skins)?);
            }
        }
        if clips.is_empty() {
            return Err(ImportError::NoAnimations);
        }
    }
    let characters = ctx.characters()?;
    if options.characters_only && characters.is_empty() {
        return Err(ImportError::NoSkins);
    }
    let mut warnings = std::mem::take(&mut ctx.mesh_plan.warnings);
    warnings.append(&mut ctx.warnings);
    warnings.append(&mut vrm_warnings);
    Ok(Imported { clips, meshes, springs, characters, warnings })
}

/// Makes `joints`' rest (parents first) their bind pose: a joint with an
/// inverse bind matrix `B` has the model transform `X·B⁻¹` (where skinning
/// leaves its vertices as authored, in the skeleton's frame), one without
/// keeps its node's place under its parent; each local rest is then its
/// parent's model inverse times its own model transform, in f64. `X` takes
/// the mesh's bind space into the skeleton's: the first bound joint's own
/// node transform times its `B` (exporters put a rotation such as Blender's
/// Z-up to Y-up on a node above the joints, which `B` does not see, so
/// `B⁻¹` alone would lay CesiumMan on its back while its clips stand).
/// A matrix that cannot be inverted or decomposed leaves the node's own rest.
fn bind_pose(joints: &mut [JointSpec]) {
    let index: HashMap<String, usize> = joints.iter().enumerate().map(|(i, j)| (j.name.clone(), i)).collect();
    let mut model: Vec<DMat4> = Vec::with_capacity(joints.len());
    let mut frame: Option<DMat4> = None;
    for joint in joints.iter_mut() {
        let parent = joint.parent.as_ref().and_then(|p| index.get(p)).map_or(DMat4::IDENTITY, |&p| model[p]);
        let r = joint.rest;
        let local = DMat4::from_scale_rotation_translation(
            r.scale.as_dvec3(),
            r.rotation.as_dquat().normalize(),
            r.translation.as_dvec3(),
        );
        let bound = joint.inverse_bind.map(|b| b.as_dmat4()).filter(|b| b.determinant().abs() > 1e-12);
        let Some(b) = bound else {
            model.push(parent * local);
            continue;
        };
        let world = *frame.get_or_insert(parent * local * b) * b.inverse();
        let (s, q, t) = (parent.inverse() * world).to_scale_rotation_translation();
        if s.is_finite() && q.is_finite() && t.is_finite() {
            joint.rest = Transform { translation: t.as_vec3(), rotation: q.normalize().as_quat(), scale: s.as_vec3() };
            model.push(world);
        } else {
            model.push(parent * local);
        }
    }
}

/// Per node, the morph targets of its mesh (its first primitive's: glTF
/// requires every primitive of a mesh to have as many), 0 without a mesh.
fn morph_targets(root: &::gltf::json::Root) -> Vec<usize> {
    (root.nodes.iter())
        .map(|node| {
            let mesh = node.mesh.and_then(|m| root.meshes.get(m.value()));
            mesh.and_then(|m| m.primitives.first()).and_then(|p| p.targets.as_ref()).map_or(0, Vec::len)
        })
        .collect()
}

/// Drops everything an animation import never reads (meshes, materials,
/// textures, images, cameras, extensions) before the crate validates the
/// document: its validation of those parts is not safe on hostile input
/// (gltf-json 1.4.1 indexes a primitive's POSITION accessor before checking
/// it: found by fuzzing), and a file whose meshes need an unsupported
/// extension still has importable animations.
fn strip_to_animation(root: &mut ::gltf::json::Root) {
    root.meshes.clear();
    root.materials.clear();
    root.textures.clear();
    root.images.clear();
    root.samplers.clear();
    root.cameras.clear();
    root.extensions = None;
    root.extensions_used.clear();
    root.extensions_required.clear();
    for node in &mut root.nodes {
        node.mesh = None;
        node.camera = None;
        node.weights = None;
        node.extensions = None;
    }
}

/// The crate's validation skips animation channel targets, and its
/// accessors unwrap them: check the node index and the path here first.
fn check_channel_targets(doc: &Document) -> Result<(), ImportError> {
    let json = doc.as_json();
    for (a, animation) in json.animations.iter().enumerate() {
        for (c, channel) in animation.channels.iter().enumerate() {
            let at = || format!("animations[{a}].channels[{c}].target");
            if channel.target.node.value() >= json.nodes.len() {
                return Err(ImportError::InvalidGltf(format!("{}.node: index out of range", at())));
            }
            if !matches!(channel.target.path, ::gltf::json::validation::Checked::Valid(_)) {
                return Err(ImportError::InvalidGltf(format!("{}.path: not a valid target path", at())));
            }
        }
    }
    Ok(())
}

fn validation_message(e: ::gltf::Error) -> String {
    match e {
        ::gltf::Error::Validation(errors) => {
            let shown: Vec<String> = errors.iter().take(5).map(|(path, err)| format!("{path}: {err}")).collect();
            let more = errors.len().saturating_sub(5);
            if more > 0 { format!("{} (and {more} more)", shown.join("; ")) } else { shown.join("; ") }
        }
        other => other.to_string(),
    }
}

/// The node hierarchy, checked to be a forest, with names and an order.
struct Forest {
    parent: Vec<Option<usize>>,
    depth: Vec<usize>,
    /// Depth-first preorder position (scene roots first): parents first.
    order: Vec<usize>,
    names: Vec<String>,
}

impl Forest {
    fn new(doc: &Document) -> Result<Self, ImportError> {
        let n = doc.nodes().len();
        let mut parent: Vec<Option<usize>> = vec![None; n];
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); n];
        for node in doc.nodes() {
            for child in node.children() {
                let c = child.index();
                if c == node.index() {
                    return Err(ImportError::NotATree(format!("node {c} is its own child")));
                }
                if let Some(p) = parent[c] {
                    return Err(ImportError::NotATree(format!(
                        "node {c} is a child of both node {p} and node {}",
                        node.index()
                    )));
                }
                parent[c] = Some(node.index());
                children[node.index()].push(c);
            }
        }
        // Roots: the default (or first) scene's, then any other parentless node.
        let mut roots: Vec<usize> = Vec::new();
        let scene = doc.default_scene().or_else(|| doc.scenes().next());
        if let Some(scene) = scene {
            roots.extend(scene.nodes().map(|n| n.index()).filter(|&i| parent[i].is_none()));
        }
        roots.extend((0..n).filter(|&i| parent[i].is_none()));
        let (mut order, mut depth) = (vec![usize::MAX; n], vec![0; n]);
        let mut next = 0;
        let mut stack: Vec<(usize, usize)> = Vec::new();
        for root in roots {
            if order[root] != usize::MAX {
                continue;
            }
            stack.push((root, 0));
            while let Some((node, d)) = stack.pop() {
                if order[node] != usize::MAX {
                    continue;
                }
                order[node] = next;
                depth[node] = d;
                next += 1;
                stack.extend(children[node].iter().rev().map(|&c| (c, d + 1)));
            }
        }
        // Nodes not reached from any root sit on a cycle (every node has at most one parent).
        if let Some(stuck) = order.iter().position(|&o| o == usize::MAX) {
            return Err(ImportError::NotATree(format!("node {stuck} is on a parent cycle")));
        }
        let names = unique_names(
            doc.nodes()
                .map(|node| match node.name() {
                    Some(s) if !s.is_empty() => s.to_owned(),
                    _ => format!("node{}", node.index()),
                })
                .collect(),
        );
        Ok(Forest { parent, depth, order, names })
    }
}

struct Ctx<'d, 'r> {
    doc: &'d Document,
    forest: Forest,
    buffers: Buffers<'r>,
    options: &'d ImportOptions,
    budget: Budget,
    rest: HashMap<usize, Transform>,
    /// Node → inverse bind matrix, over every skin (first skin wins).
    inverse_binds: Option<HashMap<usize, Mat4>>,
    /// Node → the skins it is a joint of.
    skins_of: Vec<Vec<usize>>,
    /// Node → its mesh's morph targets (0: none).
    morph_targets: Vec<usize>,
    /// Parts not imported, repairs made, and what the lints notice.
    warnings: Vec<Warning>,
    /// The skinned primitives found before validation.
    mesh_plan: MeshPlan,
    /// The mesh kept per set of skins (clips of one skin share it), and
    /// their bytes together (bounded by `max_mesh_bytes`).
    meshes: HashMap<Vec<usize>, Option<bytes::Bytes>>,
    mesh_bytes: u64,
    /// The nodes `VRMC_springBone` chains and colliders use: part of every
    /// skinned clip's skeleton.
    spring_nodes: Vec<usize>,
    /// The roles a VRM humanoid gives its nodes (each character takes those
    /// in its skeleton).
    human_bones: Vec<(anim::character::Role, usize)>,
    /// The default (or first) scene's name, if it says something: what an
    /// animation is named after when neither it nor the file has a name.
    scene_name: Option<String>,
}

/// Where a clip's track came from: its channel and that channel's sampler.
#[derive(Clone, Copy)]
struct ChannelRef {
    channel: usize,
    sampler: usize,
}

/// An animation's channels: joint tracks (with where each came from, in
/// step), morph-weight parameters, and the nodes they animate.
#[derive(Default)]
struct Channels {
    tracks: Vec<TrackSpec>,
    refs: Vec<ChannelRef>,
    parameters: Vec<ParameterSpec>,
    animated: Vec<usize>,
}

impl Ctx<'_, '_> {
    /// One animation as a clip, or `None` (a `not_imported` warning) when
    /// it animates no translation, rotation, scale or morph weights.
    fn animation(
        &mut self,
        animation: &::gltf::Animation,
        animation_count: usize,
    ) -> Result<Option<(ClipSpec, Vec<usize>)>, ImportError> {
        let a = animation.index();
        let own = animation.name().filter(|s| !s.is_empty());
        let base = own.map_or_else(|| format!("animation{a}"), str::to_owned);
        let generic = own.filter(|own| is_generic_animation_name(own));
        // An unnamed or generically named animation is named after its file, else its scene.
        let file = self.options.file_name.as_ref().or(self.scene_name.as_ref());
        let name = match (&self.options.name, animation_count, own.filter(|_| generic.is_none()), file) {
            (Some(prefix), 1, ..) => prefix.clone(),
            (Some(prefix), ..) => format!("{prefix}/{base}"),
            (None, _, Some(own), _) => own.to_owned(),
            (None, 1, None, Some(file)) => file.clone(),
            (None, _, None, Some(file)) => format!("{file}/{base}"),
            (None, _, None, None) => base.clone(),
        };
        if let (Some(generic), None) = (generic, &self.options.name) {
            self.warnings.push(Warning::new(
                GENERIC_ANIMATION_NAME,
                format!("/animations/{a}/name"),
                format!(
                    "animation {a} is named '{generic}', a name exporters give every animation: the clip is named \
                     '{name}' instead (after the file, else the scene); choose one with name="
                ),
            ));
        }
        let Channels { tracks, refs, parameters, animated } = self.channel_tracks(animation, &base)?;
        if tracks.is_empty() && parameters.is_empty() {
            self.warnings.push(Warning::new(
                NOT_IMPORTED,
                format!("/animations/{a}"),
                format!(
                    "animation '{base}' was not imported: it animates no translation, rotation, scale or morph \
                     weights"
                ),
            ));
            return Ok(None);
        }
        let (nodes, skins) = self.clip_nodes(&animated)?;
        let joints = self.joints(&nodes, !skins.is_empty())?;
        let clip = ClipSpec {
            name: clip_name(&name),
            skeleton: Some(SkeletonSpec { joints }),
            tracks,
            events: Vec::new(),
            playback: Playback::Once,
            parameters,
            ..Default::default()
        };
        let lints = lint::lint(&clip);
        self.warnings.extend(lints.iter().map(|l| Warning::from_lint(l, lint_pointer(a, &refs, l))));
        self.warnings.extend(scaled_translation(&clip, &refs, a));
        Ok(Some((clip, skins)))
    }

    /// One character per skin: its joints and their ancestors at the bind
    /// pose, with the mesh bound to it. Named after `name` (importing
    /// characters only), else the file, else the scene, plus `/<skin name>`
    /// when the file has several skins; without any of these, after the skin.
    fn characters(&mut self) -> Result<Vec<ImportedCharacter>, ImportError> {
        let skins: Vec<(usize, Option<String>, Vec<usize>)> = (self.doc.skins())
            .map(|s| (s.index(), s.name().map(str::to_owned), s.joints().map(|j| j.index()).collect()))
            .collect();
        let own_name = self.options.name.as_ref().filter(|_| self.options.characters_only);
        let base = own_name.or(self.options.file_name.as_ref()).or(self.scene_name.as_ref()).cloned();
        let several = skins.len() > 1;
        let mut characters = Vec::with_capacity(skins.len());
        for (index, skin_name, skin_joints) in skins {
            let (nodes, skins) = self.clip_nodes(&skin_joints)?;
            let mut joints = self.joints(&nodes, true)?;
            bind_pose(&mut joints);
            let skin_name = skin_name.filter(|n| !n.trim().is_empty()).unwrap_or_else(|| format!("skin{index}"));
            let name = match (&base, several) {
                (Some(base), false) => base.clone(),
                (Some(base), true) => format!("{base}/{skin_name}"),
                (None, _) => skin_name,
            };
            let mesh = self.mesh(skins)?;
            let roles =
                vrm_humanoid::character_roles(&self.human_bones, &nodes, &self.forest.names, &mut self.warnings);
            let skeleton = SkeletonSpec { joints };
            characters.push(ImportedCharacter { name: clip_name(&name), skeleton, mesh, roles });
        }
        Ok(characters)
    }

    /// The mesh of the primitives bound to `skins` (their joints all in the
    /// clip's skeleton, as [`Ctx::clip_nodes`] includes them), read once per
    /// set of skins.
    fn mesh(&mut self, skins: Vec<usize>) -> Result<Option<bytes::Bytes>, ImportError> {
        if skins.is_empty() {
            return Ok(None);
        }
        if let Some(kept) = self.meshes.get(&skins) {
            return Ok(kept.clone());
        }
        let palette = Palette::read(self.doc, &mut self.buffers, &skins, self.options.limits.max_joints)?;
        let names: Vec<String> = palette.nodes.iter().map(|&n| self.forest.names[n].clone()).collect();
        let kept = MeshReader {
            doc: self.doc,
            budget: self.options.limits.max_mesh_bytes.saturating_sub(self.mesh_bytes),
            buffers: &mut self.buffers,
            limits: &self.options.limits,
            plan: &self.mesh_plan,
            warnings: &mut self.warnings,
        }
        .read(&skins, &palette, &names)?;
        self.mesh_bytes += kept.as_ref().map_or(0, |m| m.len() as u64);
        self.meshes.insert(skins, kept.clone());
        Ok(kept)
    }

    /// The animation's channels as tracks, each with where it came from
    /// and the node it animates; morph-target weights become a parameter
    /// named after the node (docs/clip-format.md §3), a second channel for the same
    /// property of a node is refused, and the track count (parameters
    /// included) is capped.
    fn channel_tracks(&mut self, animation: &::gltf::Animation, base: &str) -> Result<Channels, ImportError> {
        let a = animation.index();
        let max_tracks = self.options.limits.max_tracks;
        let mut out = Channels::default();
        let mut seen: HashSet<(usize, u8)> = HashSet::new();
        for channel in animation.channels() {
            let c = channel.index();
            let target = channel.target();
            let node = target.node().index();
            let (kind, property) = match target.property() {
                Property::Translation => (Some(Channel::Translation), "translation"),
                Property::Rotation => (Some(Channel::Rotation), "rotation"),
                Property::Scale => (Some(Channel::Scale), "scale"),
                Property::MorphTargetWeights => (None, "weights"),
            };
            if !seen.insert((node, kind.map_or(3, |k| k as u8))) {
                return Err(ImportError::InvalidGltf(format!(
                    "animation {a} has two channels for the {property} of node {node}"
                )));
            }
            let count = out.tracks.len() + out.parameters.len();
            if count >= max_tracks {
                return Err(ImportError::TooLarge {
                    what: "the tracks of one clip",
                    max: max_tracks as u64,
                    found: count as u64 + 1,
                });
            }
            let what = format!("animation {a} channel {c}");
            let name = self.forest.names[node].clone();
            if kind.is_none() && self.morph_targets[node] == 0 {
                self.warnings.push(Warning::new(
                    NOT_IMPORTED,
                    format!("/animations/{a}/channels/{c}"),
                    format!(
                        "animation '{base}' channel {c} (node '{name}' weights) was not imported: the node has no \
                         mesh with morph targets to weigh"
                    ),
                ));
                continue;
            }
            match kind {
                Some(kind) => {
                    let mut track = self.track(&channel.sampler(), kind, &name, &what)?;
                    if self.options.fix_hemispheres {
                        self.fix_hemispheres(&mut track, format!("/animations/{a}/channels/{c}"));
                    }
                    out.tracks.push(track);
                    out.refs.push(ChannelRef { channel: c, sampler: channel.sampler().index() });
                }
                None => out.parameters.push(self.weights(&channel.sampler(), node, &name, &what)?),
            }
            out.animated.push(node);
        }
        Ok(out)
    }

    /// A morph-weights channel as a parameter named after its node, as wide
    /// as the node's mesh has morph targets (at least one: a node without
    /// them is not imported) (glTF 2.0 §3.11: the output
    /// holds that many scalars per key, × 3 for CUBICSPLINE).
    fn weights(
        &mut self,
        sampler: &::gltf::animation::Sampler,
        node: usize,
        name: &str,
        what: &str,
    ) -> Result<ParameterSpec, ImportError> {
        let width = self.morph_targets[node];
        if width > MAX_PARAMETER_WIDTH {
            let (max, found) = (MAX_PARAMETER_WIDTH as u64, width as u64);
            return Err(ImportError::TooLarge { what: "the morph targets of one animated node", max, found });
        }
        let (times, flat, interpolation) = self.keys(sampler, Dimensions::Scalar, width, what)?;
        let per_key = if interpolation == Interpolation::CubicHermite { 3 } else { 1 };
        // Key i's row k of its per-key group (CUBICSPLINE: in-tangent, value, out-tangent).
        let rows = |k: usize| -> Vec<Vec<f32>> {
            (0..times.len()).map(|i| flat[(i * per_key + k) * width..][..width].to_vec()).collect()
        };
        let values = rows(if per_key == 3 { 1 } else { 0 });
        let mut parameter = ParameterSpec::new(name, interpolation, times.clone(), values);
        if per_key == 3 {
            parameter.in_tangents = Some(rows(0));
            parameter.out_tangents = Some(rows(2));
        }
        Ok(parameter)
    }

    /// [`ImportOptions::fix_hemispheres`] on one track, said in a warning.
    fn fix_hemispheres(&mut self, track: &mut TrackSpec, pointer: String) {
        let flipped = lint::make_hemisphere_continuous(track);
        if flipped > 0 {
            self.warnings.push(Warning::new(
                LintCode::RotationHemisphereFlips.as_str(),
                pointer,
                format!(
                    "{flipped} of {} CUBICSPLINE rotation keys of '{}' were in the opposite hemisphere to the key \
                     before; they were flipped (value and tangents) so the rotation turns the short way, as \
                     fix=hemisphere asked",
                    track.values.len(),
                    track.joint
                ),
            ));
        }
    }

    /// The nodes of the clip's skeleton, parents first, and the skins among
    /// them: the animated nodes, every joint of the skins they
    /// belong to, then every ancestor. Depth and count are checked as the
    /// set grows, so the work per animation stays bounded by the limits,
    /// not by the file.
    fn clip_nodes(&mut self, animated: &[usize]) -> Result<(Vec<usize>, Vec<usize>), ImportError> {
        let limits = self.options.limits;
        let too_many = |found: usize| ImportError::TooLarge {
            what: "the joints of one clip",
            max: limits.max_joints as u64,
            found: found as u64,
        };
        let mut included: HashSet<usize> = animated.iter().copied().collect();
        let mut skins: Vec<usize> = animated.iter().flat_map(|&n| self.skins_of[n].iter().copied()).collect();
        skins.sort_unstable();
        skins.dedup();
        for &skin in &skins {
            for joint in self.doc.skins().nth(skin).into_iter().flat_map(|s| s.joints()) {
                included.insert(joint.index());
                if included.len() > limits.max_joints {
                    return Err(too_many(included.len()));
                }
            }
        }
        if !skins.is_empty() {
            included.extend(self.spring_nodes.iter().copied());
            if included.len() > limits.max_joints {
                return Err(too_many(included.len()));
            }
        }
        if included.iter().any(|&n| self.forest.depth[n] >= limits.max_depth) {
            return Err(ImportError::TooDeep { max: limits.max_depth });
        }
        let mut stack: Vec<usize> = included.iter().copied().collect();
        while let Some(node) = stack.pop() {
            if let Some(p) = self.forest.parent[node]
                && included.insert(p)
            {
                if included.len() > limits.max_joints {
                    return Err(too_many(included.len()));
                }
                stack.push(p);
            }
        }
        self.budget.take(included.len())?;
        let mut nodes: Vec<usize> = included.into_iter().collect();
        nodes.sort_by_key(|&n| self.forest.order[n]);
        Ok((nodes, skins))
    }

    /// The skeleton's joints for `nodes`: names, parents and rest poses,
    /// with inverse bind matrices only when a skin is involved.
    fn joints(&mut self, nodes: &[usize], skinned: bool) -> Result<Vec<JointSpec>, ImportError> {
        let binds: Vec<Option<Mat4>> = if skinned {
            let all = self.inverse_binds()?;
            nodes.iter().map(|n| all.get(n).copied()).collect()
        } else {
            vec![None; nodes.len()]
        };
        let mut joints = Vec::with_capacity(nodes.len());
        for (&node, inverse_bind) in nodes.iter().zip(binds) {
            joints.push(JointSpec {
                name: self.forest.names[node].clone(),
                parent: self.forest.parent[node].map(|p| self.forest.names[p].clone()),
                rest: self.rest(node)?,
                inverse_bind,
            });
        }
        Ok(joints)
    }

    /// One channel's sampler as a track (glTF 2.0 §3.11, Appendix C).
    fn track(
        &mut self,
        sampler: &::gltf::animation::Sampler,
        channel: Channel,
        joint: &str,
        what: &str,
    ) -> Result<TrackSpec, ImportError> {
        let dims = if channel == Channel::Rotation { Dimensions::Vec4 } else { Dimensions::Vec3 };
        let (times, flat, interpolation) = self.keys(sampler, dims, 1, what)?;
        let cubic = interpolation == Interpolation::CubicHermite;
        let (per_key, width) = (if cubic { 3 } else { 1 }, channel.width());
        let rows = |k: usize| -> Keys {
            // Key i's row k of its per-key group (CUBICSPLINE: in-tangent, value, out-tangent).
            let row = |i: usize| &flat[(i * per_key + k) * width..][..width];
            if width == 4 {
                Keys::Vec4((0..times.len()).map(|i| Vec4::from_slice(row(i))).collect())
            } else {
                Keys::Vec3((0..times.len()).map(|i| Vec3::from_slice(row(i))).collect())
            }
        };
        let mut track = TrackSpec::new(joint, channel, interpolation, times.clone(), rows(if cubic { 1 } else { 0 }));
        if cubic {
            track.in_tangents = Some(rows(0));
            track.out_tangents = Some(rows(2));
        }
        Ok(track)
    }

    /// A sampler's key times and its output as flat floats (`elements`
    /// elements of `dims` per key, × 3 for CUBICSPLINE), reading only the
    /// accessors' own bytes; and the interpolation it names.
    fn keys(
        &mut self,
        sampler: &::gltf::animation::Sampler,
        dims: Dimensions,
        elements: usize,
        what: &str,
    ) -> Result<(Vec<f32>, Vec<f32>, Interpolation), ImportError> {
        let max_keys = self.options.limits.max_keys_per_track;
        let input = sampler.input();
        let output = sampler.output();
        self.budget.take(input.count())?;
        let times = read_f32(
            &input,
            &mut self.buffers,
            &Expect {
                what: &format!("{what} input"),
                dims: Dimensions::Scalar,
                normalized_ints: false,
                max_count: max_keys,
            },
        )?;
        for i in 1..times.len() {
            if times[i] <= times[i - 1] {
                return Err(ImportError::TimesNotIncreasing {
                    what: what.to_owned(),
                    previous: times[i - 1],
                    current: times[i],
                });
            }
        }
        let cubic = sampler.interpolation() == GltfInterpolation::CubicSpline;
        let per_key = if cubic { 3 } else { 1 };
        let expected = times.len() * per_key * elements;
        if output.count() != expected {
            let each = if elements > 1 { format!(" × {elements} morph targets") } else { String::new() };
            return Err(ImportError::InvalidGltf(format!(
                "{what}: the output has {} elements, expected {expected} ({} keys{each}{})",
                output.count(),
                times.len(),
                if cubic { " × 3 for CUBICSPLINE" } else { "" }
            )));
        }
        let flat = read_f32(
            &output,
            &mut self.buffers,
            &Expect {
                what: &format!("{what} output"),
                dims,
                // Rotations and morph weights may be stored as normalised integers (glTF 2.0 §3.11).
                normalized_ints: dims != Dimensions::Vec3,
                max_count: max_keys.saturating_mul(3).saturating_mul(elements),
            },
        )?;
        let interpolation = match sampler.interpolation() {
            GltfInterpolation::Step => Interpolation::Step,
            GltfInterpolation::Linear => Interpolation::Linear,
            GltfInterpolation::CubicSpline => Interpolation::CubicHermite,
        };
        Ok((times, flat, interpolation))
    }

    /// The node's local transform as TRS (decomposing a `matrix`).
    fn rest(&mut self, node: usize) -> Result<Transform, ImportError> {
        if let Some(t) = self.rest.get(&node) {
            return Ok(*t);
        }
        let n = self.doc.nodes().nth(node).ok_or_else(|| ImportError::InvalidGltf(format!("no node {node}")))?;
        let t = match n.transform() {
            GltfTransform::Decomposed { translation, rotation, scale } => {
                let t = Transform {
                    translation: Vec3::from(translation),
                    rotation: Quat::from_array(rotation),
                    scale: Vec3::from(scale),
                };
                if !(t.translation.is_finite() && Vec4::from(t.rotation).is_finite() && t.scale.is_finite()) {
                    return Err(ImportError::NonFinite { what: format!("node {node}'s transform") });
                }
                t
            }
            GltfTransform::Matrix { matrix } => decompose(node, Mat4::from_cols_array_2d(&matrix))?,
        };
        self.rest.insert(node, t);
        Ok(t)
    }

    /// Every skin's inverse bind matrices by joint node, read once.
    fn inverse_binds(&mut self) -> Result<&HashMap<usize, Mat4>, ImportError> {
        if self.inverse_binds.is_none() {
            let mut map: HashMap<usize, Mat4> = HashMap::new();
            let max_joints = self.options.limits.max_joints;
            for skin in self.doc.skins() {
                let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
                let matrices = match skin.inverse_bind_matrices() {
                    Some(acc) => {
                        if acc.count() < joints.len() {
                            return Err(ImportError::InvalidGltf(format!(
                                "skin {} has {} joints but {} inverse bind matrices",
                                skin.index(),
                                joints.len(),
                                acc.count()
                            )));
                        }
                        let what = format!("skin {} inverseBindMatrices", skin.index());
                        let expect = Expect {
                            what: &what,
                            dims: Dimensions::Mat4,
                            normalized_ints: false,
                            max_count: max_joints.max(joints.len()),
                        };
                        let flat = read_f32(&acc, &mut self.buffers, &expect)?;
                        flat.chunks_exact(16).map(Mat4::from_cols_slice).collect()
                    }
                    None => vec![Mat4::IDENTITY; joints.len()],
                };
                for (&node, m) in joints.iter().zip(matrices) {
                    match map.get(&node) {
                        None => {
                            map.insert(node, m);
                        }
                        Some(old) if !old.abs_diff_eq(m, 1e-6) => self.warnings.push(Warning::new(
                            NOT_IMPORTED,
                            format!("/skins/{}/inverseBindMatrices", skin.index()),
                            format!(
                                "skin {}'s inverse bind matrix of node {node} was not imported: the node is a joint \
                                 of an earlier skin with a different one, which is kept",
                                skin.index()
                            ),
                        )),
                        Some(_) => {}
                    }
                }
            }
            self.inverse_binds = Some(map);
        }
        Ok(self.inverse_binds.get_or_insert_with(HashMap::new))
    }
}

/// The first translation track whose joint's parents scale it far from 1
/// (a Mixamo file through Blender: `Armature` scaled 0.01 over hips keyed in
/// centimetres), as a warning: its keys, and root motion read from them, are
/// not in the pose's units.
fn scaled_translation(clip: &ClipSpec, refs: &[ChannelRef], a: usize) -> Option<Warning> {
    let (i, track, parents) = (clip.tracks.iter().enumerate())
        .filter(|(_, t)| t.channel == Channel::Translation)
        .find_map(|(i, t)| convention::parent_scale(clip, &t.joint).map(|s| (i, t, s)))?;
    let (code, unit) = if (parents.ln() - 0.0254f32.ln()).abs() < (parents.ln() - 0.01f32.ln()).abs() {
        (convention::UNITS_INCHES, "inches")
    } else {
        (convention::UNITS_CENTIMETERS, "centimetres")
    };
    let pointer =
        refs.get(i).map_or_else(|| format!("/animations/{a}"), |r| format!("/animations/{a}/channels/{}", r.channel));
    Some(Warning::new(
        code,
        pointer,
        format!(
            "the translation keys of '{}' are in {unit} while the pose is in metres: its parents scale it by {parents} \
             (a Mixamo file exported through Blender does this), so root motion read from them moves {} times too \
             far; apply the armature's scale before exporting (Blender: Object ▸ Apply ▸ All Transforms on the \
             armature, then export glTF again)",
            track.joint,
            1.0 / parents
        ),
    ))
}

/// Where in the glTF file a lint about track `lint.track` of animation `a`
/// points: a time warning at its sampler's `input`, any other at its channel.
fn lint_pointer(a: usize, refs: &[ChannelRef], lint: &Lint) -> String {
    let Some(r) = refs.get(lint.track) else { return format!("/animations/{a}") };
    match lint.field {
        "times" => format!("/animations/{a}/samplers/{}/input", r.sampler),
        _ => format!("/animations/{a}/channels/{}", r.channel),
    }
}

/// A node `matrix` as TRS. glTF requires node matrices to be decomposable;
/// one that is not (shear, projection, zero scale) is refused, since
/// importing it as some other TRS would silently change the model.
fn decompose(node: usize, m: Mat4) -> Result<Transform, ImportError> {
    if !m.is_finite() {
        return Err(ImportError::NonFinite { what: format!("node {node}'s matrix") });
    }
    let d = m.as_dmat4();
    let unsupported = |why: &str| Err(ImportError::Unsupported(format!("node {node}'s matrix {why}: it is not a TRS")));
    if d.row(3).distance(glam::DVec4::W) > 1e-6 {
        return unsupported("has a projective last row");
    }
    let (scale, rotation, translation) = d.to_scale_rotation_translation();
    if !(scale.is_finite() && rotation.is_finite()) || scale.abs().min_element() < 1e-12 {
        return unsupported("is singular");
    }
    let back = DMat4::from_scale_rotation_translation(scale, rotation, translation);
    let size = d.to_cols_array().iter().fold(1.0f64, |a, x| a.max(x.abs()));
    if !back.abs_diff_eq(d, 1e-4 * size) {
        return unsupported("has shear");
    }
    Ok(Transform {
        translation: translation.as_vec3(),
        rotation: rotation.normalize().as_quat(),
        scale: scale.as_vec3(),
    })
}
