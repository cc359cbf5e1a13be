//! The skinned meshes of a glTF file, kept for the viewer (issue 20).
//!
//! A clip imported from a skin keeps the triangles that skin deforms: every
//! primitive of every mesh a node binds to one of the clip's skins, with its
//! `POSITION`, `NORMAL`, `JOINTS_0`, `WEIGHTS_0`, indices and, when its
//! material's base colour texture is small enough, that image and its
//! texture coordinates (else the base colour factor). The meshes are found
//! in the raw JSON before the crate validates it (its mesh validation is not
//! safe on hostile input, see `gltf::strip_to_animation`), every index
//! checked here; their accessors are read only once the document is valid,
//! through the same bounds-checked readers as animations.
//!
//! A mesh never stops an import: a primitive that cannot be kept (not
//! triangles, no skin weights, bad data) is left out with a `not_imported`
//! warning, and so is a mesh past [`ImportLimits::max_mesh_bytes`] (all of an
//! import's meshes together; checked
//! from the accessors' counts before anything is read), so memory follows
//! what is kept. Only a source that cannot be read fails the import.

use std::collections::HashMap;

use ::gltf::Document;
use ::gltf::accessor::Dimensions;
use ::gltf::json::Root;
use ::gltf::json::mesh::{Mode, Semantic};
use ::gltf::json::validation::Checked;
use bytes::Bytes;
use glam::Mat4;

use super::accessor::{Expect, read_f32, read_uint, read_view};
use super::buffers::{Buffers, decode_data_uri};
use super::error::ImportError;
use super::image::{HeaderError, read_header};
use super::spec::ImportLimits;
use super::warning::{NOT_IMPORTED, Warning};
use crate::wire::mesh::{self, Material, Mesh, Primitive, Texture};

/// What of the file's meshes could be kept, found before validation.
#[derive(Default)]
pub struct MeshPlan {
    /// Per skin: the primitives of the meshes bound to it.
    by_skin: HashMap<usize, Vec<PrimitivePlan>>,
    images: Vec<ImagePlan>,
    /// Primitives left out while planning.
    pub warnings: Vec<Warning>,
}

/// One primitive's accessors (indices into the document's) and material.
struct PrimitivePlan {
    pointer: String,
    positions: usize,
    normals: Option<usize>,
    joints: usize,
    weights: usize,
    indices: Option<usize>,
    base_color: [f32; 4],
    /// The base colour texture's image and its `TEXCOORD_n` accessor.
    texture: Option<(usize, usize)>,
}

/// Where an image's bytes are: a buffer view, or a `data:` URI.
enum ImagePlan {
    View(usize),
    DataUri(String),
    /// An external URI or nothing: not kept.
    Elsewhere,
}

impl MeshPlan {
    /// Finds every primitive of a mesh on a skinned node, each index
    /// checked against the raw document.
    pub fn new(root: &Root) -> Self {
        let mut plan = MeshPlan { images: root.images.iter().map(image_plan).collect(), ..Default::default() };
        let mut seen = std::collections::HashSet::new();
        for node in &root.nodes {
            let (Some(m), Some(s)) = (node.mesh, node.skin) else { continue };
            let (m, s) = (m.value(), s.value());
            if m >= root.meshes.len() || s >= root.skins.len() || !seen.insert((m, s)) {
                continue;
            }
            for (p, primitive) in root.meshes[m].primitives.iter().enumerate() {
                let pointer = format!("/meshes/{m}/primitives/{p}");
                match primitive_plan(root, primitive, pointer.clone()) {
                    Ok(found) => plan.by_skin.entry(s).or_default().push(found),
                    Err(why) => plan.warnings.push(left_out(&pointer, &why)),
                }
            }
        }
        plan
    }
}

fn left_out(pointer: &str, why: &str) -> Warning {
    Warning::new(
        NOT_IMPORTED,
        pointer,
        format!("the skinned primitive at {pointer} was not kept for the viewer: {why}"),
    )
}

fn image_plan(image: &::gltf::json::Image) -> ImagePlan {
    match (&image.buffer_view, &image.uri) {
        (Some(view), _) => ImagePlan::View(view.value()),
        (None, Some(uri)) if uri.as_bytes().get(..5).is_some_and(|p| p.eq_ignore_ascii_case(b"data:")) => {
            ImagePlan::DataUri(uri.clone())
        }
        _ => ImagePlan::Elsewhere,
    }
}

fn primitive_plan(
    root: &Root,
    primitive: &::gltf::json::mesh::Primitive,
    pointer: String,
) -> Result<PrimitivePlan, String> {
    if !matches!(primitive.mode, Checked::Valid(Mode::Triangles)) {
        return Err("only triangle lists are kept".into());
    }
    let accessors = root.accessors.len();
    let attribute = |semantic: Semantic| -> Result<Option<usize>, String> {
        match primitive.attributes.get(&Checked::Valid(semantic.clone())) {
            Some(i) if i.value() < accessors => Ok(Some(i.value())),
            Some(i) => Err(format!("{semantic:?} names accessor {}, which does not exist", i.value())),
            None => Ok(None),
        }
    };
    let need = |semantic: Semantic, name: &str| attribute(semantic)?.ok_or(format!("it has no {name}"));
    let indices = match primitive.indices {
        Some(i) if i.value() >= accessors => return Err(format!("its indices name accessor {}", i.value())),
        i => i.map(|i| i.value()),
    };
    let material = primitive.material.and_then(|m| root.materials.get(m.value()));
    let pbr = material.map(|m| &m.pbr_metallic_roughness);
    let base_color = pbr.map_or([1.0; 4], |p| p.base_color_factor.0);
    let texture = pbr.and_then(|p| p.base_color_texture.as_ref()).and_then(|info| {
        let image = root.textures.get(info.index.value())?.source.value();
        let uv = attribute(Semantic::TexCoords(info.tex_coord)).ok()??;
        (image < root.images.len()).then_some((image, uv))
    });
    Ok(PrimitivePlan {
        positions: need(Semantic::Positions, "POSITION")?,
        normals: attribute(Semantic::Normals)?,
        joints: need(Semantic::Joints(0), "JOINTS_0")?,
        weights: need(Semantic::Weights(0), "WEIGHTS_0")?,
        indices,
        base_color: base_color.map(|c| if c.is_finite() { c.clamp(0.0, 1.0) } else { 1.0 }),
        texture,
        pointer,
    })
}

/// The skins' joints, in palette order: each skin's joint nodes, and its
/// inverse bind matrices.
pub struct Palette {
    pub nodes: Vec<usize>,
    pub inverse_binds: Vec<Mat4>,
    /// Where each skin's joints start in the palette.
    pub starts: Vec<(usize, usize)>,
}

/// Reads one clip's mesh: the primitives of `skins`, or `None` (with the
/// reasons in `warnings`) when none could be kept.
pub struct MeshReader<'a, 'r> {
    pub doc: &'a Document,
    /// Bytes the import's meshes may still take (all of them together are
    /// bounded by [`ImportLimits::max_mesh_bytes`]); the caller subtracts what
    /// [`MeshReader::read`] keeps.
    pub budget: u64,
    pub buffers: &'a mut Buffers<'r>,
    pub limits: &'a ImportLimits,
    pub plan: &'a MeshPlan,
    pub warnings: &'a mut Vec<Warning>,
}

impl MeshReader<'_, '_> {
    /// The encoded mesh of the primitives bound to `skins`, whose joints
    /// `palette` lists and `names` names.
    pub fn read(&mut self, skins: &[usize], palette: &Palette, names: &[String]) -> Result<Option<Bytes>, ImportError> {
        let plan = self.plan;
        let primitives: Vec<(usize, &PrimitivePlan)> =
            skins.iter().flat_map(|&s| plan.by_skin.get(&s).into_iter().flatten().map(move |p| (s, p))).collect();
        if primitives.is_empty() {
            return Ok(None);
        }
        if palette.nodes.len() > 1 << 16 {
            let why = format!("the skins have {} joints; a kept mesh has at most 65536", palette.nodes.len());
            self.warnings.push(left_out(&primitives[0].1.pointer, &why));
            return Ok(None);
        }
        if let Some(why) = self.too_large(&primitives, palette.nodes.len()) {
            self.warnings.push(Warning::new(NOT_IMPORTED, primitives[0].1.pointer.clone(), why));
            return Ok(None);
        }
        let mut out = Mesh {
            joints: names.to_vec(),
            inverse_binds: palette.inverse_binds.iter().map(Mat4::to_cols_array).collect(),
            ..Mesh::default()
        };
        let (mut normals, mut uvs, mut textures) = (Some(Vec::new()), Vec::new(), HashMap::new());
        for (skin, primitive) in primitives {
            let base = palette.starts.iter().find(|(s, _)| *s == skin).map_or(0, |(_, b)| *b);
            let joints = palette.joint_count(skin);
            match self.primitive(primitive, base, joints, out.vertex_count()) {
                Ok(read) => append(&mut out, read, &mut normals, &mut uvs, &mut textures, self, primitive)?,
                Err(ImportError::Read(e)) => return Err(ImportError::Read(e)),
                Err(e) => self.warnings.push(left_out(&primitive.pointer, &e.to_string())),
            }
        }
        if out.indices.is_empty() {
            return Ok(None);
        }
        out.normals = normals;
        if out.materials.iter().any(|m| m.texture.is_some()) {
            out.uvs = Some(uvs);
        }
        Ok(Some(Bytes::from(mesh::encode(&out))))
    }

    /// Why the kept mesh would be over the limit, from accessor counts.
    fn too_large(&self, primitives: &[(usize, &PrimitivePlan)], joints: usize) -> Option<String> {
        let count = |i: usize| self.doc.accessors().nth(i).map_or(0, |a| a.count());
        let vertices: usize = primitives.iter().map(|(_, p)| count(p.positions)).sum();
        let indices: usize = primitives.iter().map(|(_, p)| p.indices.map_or(count(p.positions), count)).sum();
        let mut images: Vec<usize> = primitives.iter().filter_map(|(_, p)| p.texture.map(|t| t.0)).collect();
        images.sort_unstable();
        images.dedup();
        let textures = images.len().saturating_mul(self.limits.max_mesh_texture_bytes as usize);
        let bound = Mesh::encoded_len_bound(vertices, indices, joints, textures);
        (bound as u64 > self.budget).then(|| {
            format!(
                "the skinned mesh ({vertices} vertices, {indices} indices) was not kept for the viewer: it would \
                 take up to {bound} bytes, over the {} bytes left of the import's {} (max_mesh_bytes)",
                self.budget, self.limits.max_mesh_bytes
            )
        })
    }

    /// One primitive's arrays, joint indices moved to the palette and
    /// vertex indices past the `first_vertex` already kept.
    fn primitive(
        &mut self,
        p: &PrimitivePlan,
        base: usize,
        joints: usize,
        first_vertex: usize,
    ) -> Result<ReadPrimitive, ImportError> {
        // POSITION and indices were counted against the budget; the other attributes have as many elements.
        let pointer = p.pointer.as_str();
        let positions = self.floats(p.positions, Dimensions::Vec3, false, pointer, "POSITION", usize::MAX)?;
        let vertices = positions.len() / 3;
        let per_vertex = |values: Vec<f32>, width: usize, what: &str| -> Result<Vec<f32>, ImportError> {
            if values.len() != vertices * width {
                return Err(ImportError::InvalidGltf(format!("{what} has a different count from POSITION")));
            }
            Ok(values)
        };
        let normals = match p.normals {
            Some(n) => {
                Some(per_vertex(self.floats(n, Dimensions::Vec3, false, pointer, "NORMAL", vertices)?, 3, "NORMAL")?)
            }
            None => None,
        };
        let weights = self.floats(p.weights, Dimensions::Vec4, true, pointer, "WEIGHTS_0", vertices)?;
        let weights = per_vertex(weights, 4, "WEIGHTS_0")?;
        let raw_joints = self.uints(p.joints, Dimensions::Vec4, pointer, "JOINTS_0", vertices)?;
        if raw_joints.len() != vertices * 4 {
            return Err(ImportError::InvalidGltf("JOINTS_0 has a different count from POSITION".into()));
        }
        if let Some(bad) = raw_joints.iter().find(|&&j| j as usize >= joints) {
            return Err(ImportError::InvalidGltf(format!("JOINTS_0 names joint {bad}; the skin has {joints}")));
        }
        let joint_indices = raw_joints.iter().map(|&j| (j as usize + base) as u16).collect();
        let indices = match p.indices {
            Some(i) => self.uints(i, Dimensions::Scalar, pointer, "indices", usize::MAX)?,
            None => (0..vertices as u32).collect(),
        };
        if indices.len() % 3 != 0 {
            return Err(ImportError::InvalidGltf(format!("{} indices are not whole triangles", indices.len())));
        }
        if let Some(bad) = indices.iter().find(|&&i| i as usize >= vertices) {
            return Err(ImportError::InvalidGltf(format!("index {bad} is not below the {vertices} vertices")));
        }
        let indices = indices.into_iter().map(|i| i + first_vertex as u32).collect();
        let uvs = match p.texture {
            Some((_, uv)) => Some(per_vertex(
                self.floats(uv, Dimensions::Vec2, true, pointer, "TEXCOORD", vertices)?,
                2,
                "TEXCOORD",
            )?),
            None => None,
        };
        Ok(ReadPrimitive { positions, normals, weights, joint_indices, indices, uvs })
    }

    fn floats(
        &mut self,
        accessor: usize,
        dims: Dimensions,
        normalized_ints: bool,
        pointer: &str,
        name: &str,
        max_count: usize,
    ) -> Result<Vec<f32>, ImportError> {
        let acc = accessor_of(self.doc, accessor)?;
        let what = format!("{pointer} {name}");
        read_f32(&acc, self.buffers, &Expect { what: &what, dims, normalized_ints, max_count })
    }

    fn uints(
        &mut self,
        accessor: usize,
        dims: Dimensions,
        pointer: &str,
        name: &str,
        max_count: usize,
    ) -> Result<Vec<u32>, ImportError> {
        let acc = accessor_of(self.doc, accessor)?;
        let what = format!("{pointer} {name}");
        read_uint(&acc, self.buffers, &Expect { what: &what, dims, normalized_ints: false, max_count })
    }

    /// The image's bytes when it is a PNG or JPEG within the texture limit;
    /// `None` (a warning) otherwise.
    fn texture(&mut self, image: usize, pointer: &str) -> Result<Option<Texture>, ImportError> {
        let max = self.limits.max_mesh_texture_bytes;
        let bytes = match self.plan.images.get(image) {
            Some(ImagePlan::View(view)) => {
                let Some(v) = self.doc.views().nth(*view) else { return Ok(None) };
                if v.length() as u64 > max {
                    self.warnings.push(texture_too_large(image, v.length() as u64, max));
                    return Ok(None);
                }
                match read_view(&v, self.buffers, &format!("image {image}")) {
                    Ok(b) => b,
                    Err(ImportError::Read(e)) => return Err(ImportError::Read(e)),
                    Err(e) => {
                        self.warnings.push(left_out(pointer, &e.to_string()));
                        return Ok(None);
                    }
                }
            }
            Some(ImagePlan::DataUri(uri)) => {
                if (uri.len() as u64).saturating_mul(3) / 4 > max + 4 {
                    self.warnings.push(texture_too_large(image, uri.len() as u64 * 3 / 4, max));
                    return Ok(None);
                }
                match decode_data_uri(uri) {
                    Ok(b) => Bytes::from(b),
                    Err(_) => return Ok(None),
                }
            }
            _ => {
                self.warnings.push(Warning::new(
                    NOT_IMPORTED,
                    format!("/images/{image}"),
                    format!("image {image} was not kept for the viewer: only embedded images are (a GLB's, or data: URIs); the base colour factor is used"),
                ));
                return Ok(None);
            }
        };
        match checked_header(&bytes, image, self.limits.max_texture_pixels) {
            Ok(mime_type) => Ok(Some(Texture { mime_type: mime_type.into(), bytes })),
            Err(warning) => {
                self.warnings.push(warning);
                Ok(None)
            }
        }
    }
}

fn accessor_of(doc: &Document, index: usize) -> Result<::gltf::Accessor<'_>, ImportError> {
    doc.accessors().nth(index).ok_or_else(|| ImportError::InvalidGltf(format!("no accessor {index}")))
}

/// The image's type when its header is a PNG's or a JPEG's declaring at
/// most `max_pixels`; else the warning that leaves it out.
fn checked_header(bytes: &[u8], image: usize, max_pixels: u64) -> Result<&'static str, Warning> {
    let left_out = |why: String| {
        let detail = format!("image {image} was not kept for the viewer: {why}; the base colour factor is used");
        Warning::new(NOT_IMPORTED, format!("/images/{image}"), detail)
    };
    match read_header(bytes) {
        Ok(h) if h.pixels() > max_pixels => Err(left_out(format!(
            "it declares {} × {} pixels, over the limit of {max_pixels} (max_texture_pixels)",
            h.width, h.height
        ))),
        Ok(h) => Ok(h.mime_type),
        Err(HeaderError::NotPngOrJpeg) => Err(left_out("it is neither PNG nor JPEG".into())),
        Err(HeaderError::Malformed(what)) => Err(left_out(format!("its header is malformed ({what})"))),
    }
}

fn texture_too_large(image: usize, found: u64, max: u64) -> Warning {
    Warning::new(
        NOT_IMPORTED,
        format!("/images/{image}"),
        format!(
            "image {image} ({found} bytes) was not kept for the viewer: over the limit of {max} bytes \
             (max_mesh_texture_bytes); the base colour factor is used"
        ),
    )
}

/// One primitive's arrays as read.
struct ReadPrimitive {
    positions: Vec<f32>,
    normals: Option<Vec<f32>>,
    weights: Vec<f32>,
    joint_indices: Vec<u16>,
    indices: Vec<u32>,
    uvs: Option<Vec<f32>>,
}

/// Appends a primitive to the mesh: its arrays, a material, its texture
/// (each image read once per mesh).
fn append(
    out: &mut Mesh,
    read: ReadPrimitive,
    normals: &mut Option<Vec<f32>>,
    uvs: &mut Vec<f32>,
    textures: &mut HashMap<usize, Option<u32>>,
    reader: &mut MeshReader,
    plan: &PrimitivePlan,
) -> Result<(), ImportError> {
    let vertices = read.positions.len() / 3;
    let first = out.indices.len() as u32;
    let texture = match plan.texture {
        Some((image, _)) => match textures.get(&image) {
            Some(t) => *t,
            None => {
                let kept = reader.texture(image, &plan.pointer)?.map(|t| {
                    out.textures.push(t);
                    out.textures.len() as u32 - 1
                });
                textures.insert(image, kept);
                kept
            }
        },
        None => None,
    };
    out.positions.extend_from_slice(&read.positions);
    *normals = match (normals.take(), read.normals) {
        (Some(mut all), Some(n)) => {
            all.extend_from_slice(&n);
            Some(all)
        }
        _ => None,
    };
    match read.uvs {
        Some(u) if texture.is_some() => uvs.extend_from_slice(&u),
        _ => uvs.resize(uvs.len() + vertices * 2, 0.0),
    }
    out.weights.extend_from_slice(&read.weights);
    out.joint_indices.extend_from_slice(&read.joint_indices);
    let count = read.indices.len() as u32;
    out.indices.extend(read.indices);
    out.materials.push(Material { base_color: plan.base_color, texture });
    out.primitives.push(Primitive { first, count, material: out.materials.len() as u32 - 1 });
    Ok(())
}

impl Palette {
    /// The palette of `skins`: each skin's joints and inverse binds
    /// (identity without them), skins in the order given.
    pub fn read(
        doc: &Document,
        buffers: &mut Buffers,
        skins: &[usize],
        max_joints: usize,
    ) -> Result<Palette, ImportError> {
        let mut palette = Palette { nodes: Vec::new(), inverse_binds: Vec::new(), starts: Vec::new() };
        for skin in skins.iter().filter_map(|&s| doc.skins().nth(s)) {
            let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
            let binds = match skin.inverse_bind_matrices() {
                Some(acc) => {
                    let what = format!("skin {} inverseBindMatrices", skin.index());
                    let expect = Expect {
                        what: &what,
                        dims: Dimensions::Mat4,
                        normalized_ints: false,
                        max_count: max_joints.max(joints.len()),
                    };
                    read_f32(&acc, buffers, &expect)?.chunks_exact(16).map(Mat4::from_cols_slice).collect()
                }
                None => vec![Mat4::IDENTITY; joints.len()],
            };
            palette.starts.push((skin.index(), palette.nodes.len()));
            palette.nodes.extend(&joints);
            palette.inverse_binds.extend(binds.into_iter().chain(std::iter::repeat(Mat4::IDENTITY)).take(joints.len()));
        }
        Ok(palette)
    }

    fn joint_count(&self, skin: usize) -> usize {
        let Some(i) = self.starts.iter().position(|(s, _)| *s == skin) else { return 0 };
        let end = self.starts.get(i + 1).map_or(self.nodes.len(), |(_, b)| *b);
        end - self.starts[i].1
    }
}

#[cfg(test)]
mod tests {
    use crate::import::{Format, ImportOptions, import};
    use crate::testing::{glb_with, glb_with_image};
    use crate::wire::mesh::decode;

    const FOX: &[u8] = include_bytes!("../../../../examples/gltf/Fox/Fox.glb");

    #[test]
    fn the_fox_keeps_one_skinned_mesh_shared_by_its_clips() {
        let imported = import(FOX, Format::Glb, &ImportOptions::default()).unwrap();
        assert_eq!(imported.meshes.len(), imported.clips.len());
        let first = imported.meshes[0].clone().unwrap();
        assert!(imported.meshes.iter().all(|m| m.as_ref() == Some(&first)));
        let mesh = decode(&first).unwrap();
        assert_eq!((mesh.vertex_count(), mesh.indices.len(), mesh.joints.len()), (1728, 1728, 24));
        assert!(mesh.normals.is_none() && mesh.uvs.is_some());
        assert_eq!(mesh.textures.len(), 1);
        assert_eq!(mesh.textures[0].mime_type, "image/png");
        let joints: Vec<&str> =
            imported.clips[0].skeleton.as_ref().unwrap().joints.iter().map(|j| j.name.as_str()).collect();
        assert!(mesh.joints.iter().all(|j| joints.contains(&j.as_str())));
        let tight = ImportOptions {
            limits: crate::import::ImportLimits { max_mesh_texture_bytes: 1000, ..Default::default() },
            ..Default::default()
        };
        let imported = import(FOX, Format::Glb, &tight).unwrap();
        let mesh = decode(imported.meshes[0].as_ref().unwrap()).unwrap();
        assert!(mesh.textures.is_empty() && mesh.uvs.is_none());
        assert!(imported.warnings.iter().any(|w| w.pointer == "/images/0" && w.code == "not_imported"));
    }

    #[test]
    fn a_texture_declaring_too_many_pixels_or_a_malformed_header_is_left_out_with_the_mesh_kept() {
        use crate::testing::{jpeg_header, png_header};
        let huge_png = png_header(16_000, 16_000);
        let mut malformed = png_header(64, 64);
        malformed[12..16].copy_from_slice(b"IDAT");
        let cases: [(&str, Vec<u8>, &str); 4] = [
            ("16,000² PNG", huge_png, "16000 × 16000 pixels, over the limit of 16777216 (max_texture_pixels)"),
            ("JPEG over the limit", jpeg_header(4097, 4096), "4097 × 4096 pixels"),
            ("malformed PNG", malformed, "header is malformed"),
            ("neither", b"GIF89a".to_vec(), "neither PNG nor JPEG"),
        ];
        for (what, image, why) in cases {
            let imported = import(&glb_with_image(FOX, &image), Format::Glb, &ImportOptions::default()).unwrap();
            assert_eq!(imported.clips.len(), 3, "{what}");
            let mesh = decode(imported.meshes[0].as_ref().expect("the mesh is kept")).unwrap();
            assert!(mesh.textures.is_empty() && mesh.uvs.is_none(), "{what}");
            assert_eq!(mesh.vertex_count(), 1728, "{what}");
            let warned = imported
                .warnings
                .iter()
                .any(|w| w.pointer == "/images/0" && w.code == "not_imported" && w.detail.contains(why));
            assert!(warned, "{what}: {:?}", imported.warnings);
        }
        // At the limit, kept: 4096 × 4096, and a JPEG.
        for image in [png_header(4096, 4096), jpeg_header(4096, 4096)] {
            let imported = import(&glb_with_image(FOX, &image), Format::Glb, &ImportOptions::default()).unwrap();
            let mesh = decode(imported.meshes[0].as_ref().unwrap()).unwrap();
            assert_eq!(mesh.textures.len(), 1);
            assert!(imported.warnings.iter().all(|w| w.pointer != "/images/0"), "{:?}", imported.warnings);
        }
    }

    /// A change to a glTF document.
    type Edit = dyn FnOnce(&mut serde_json::Value);

    #[test]
    fn a_mesh_that_cannot_be_kept_leaves_the_clips_and_a_warning() {
        let cases: [(&str, Box<Edit>); 4] = [
            // JOINTS_0 claims a billion elements: refused by its count before its bounds, never allocated.
            ("huge joints", Box::new(|d| d["accessors"][2]["count"] = (1u64 << 30).into())),
            ("joint past the skin", Box::new(|d| d["skins"][0]["joints"] = serde_json::json!([2, 3, 4]))),
            ("points", Box::new(|d| d["meshes"][0]["primitives"][0]["mode"] = 0.into())),
            (
                "no weights",
                Box::new(|d| {
                    d["meshes"][0]["primitives"][0]["attributes"].as_object_mut().unwrap().remove("WEIGHTS_0");
                }),
            ),
        ];
        for (what, edit) in cases {
            let imported = import(&glb_with(FOX, edit), Format::Glb, &ImportOptions::default())
                .unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_eq!(imported.clips.len(), 3, "{what}");
            assert!(imported.meshes.iter().all(Option::is_none), "{what}");
            let warned =
                imported.warnings.iter().any(|w| w.pointer == "/meshes/0/primitives/0" && w.code == "not_imported");
            assert!(warned, "{what}: {:?}", imported.warnings);
        }
        let small = ImportOptions {
            limits: crate::import::ImportLimits { max_mesh_bytes: 50_000, ..Default::default() },
            ..Default::default()
        };
        let imported = import(FOX, Format::Glb, &small).unwrap();
        assert!(imported.meshes.iter().all(Option::is_none));
        assert!(imported.warnings.iter().any(|w| w.detail.contains("max_mesh_bytes")), "{:?}", imported.warnings);
    }
}
