//! The skinned mesh a glTF import keeps for the viewer, and its compact
//! binary form (`GET /v1/clips/{id}/mesh`, docs/mesh-format.md).
//!
//! The form is a small JSON header followed by little-endian typed arrays,
//! each at a 4-byte aligned offset, so a browser reads it with one
//! `JSON.parse` and a typed-array view per array, without copying:
//!
//! ```text
//! 0        "INBM"                     magic
//! 4        u32  version (1)
//! 8        u32  H: the header's length, a multiple of 4 (padded with spaces)
//! 12       H bytes of JSON header     counts, joint names, where each array is
//! 12 + H   body                       the arrays and textures, offsets from here
//! ```
//!
//! The store keeps these bytes as they are; the server never decodes them
//! after the import wrote them ([`decode`] is the format's own check).

use bytes::Bytes;
use serde::{Deserialize, Serialize};

/// The first four bytes of the format.
pub const MAGIC: &[u8; 4] = b"INBM";
/// The version this module writes and reads.
pub const VERSION: u32 = 1;
/// The answer's media type.
pub const CONTENT_TYPE: &str = "application/vnd.inbetween.mesh";

/// A skinned triangle mesh: every primitive the import kept, concatenated
/// into one vertex and one index array, with a material per primitive.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mesh {
    /// The joint palette: clip joint names. A vertex's joint index `k`
    /// means `joints[k]`, whose inverse bind matrix is `inverse_binds[k]`.
    pub joints: Vec<String>,
    /// Column-major 4×4, one per palette entry.
    pub inverse_binds: Vec<[f32; 16]>,
    /// `x, y, z` per vertex (the bind pose, model space).
    pub positions: Vec<f32>,
    /// `x, y, z` per vertex; `None` when any primitive had none (the page
    /// then shades flat, as glTF asks of meshes without normals).
    pub normals: Option<Vec<f32>>,
    /// `u, v` per vertex (glTF convention: `v` down from the image's top),
    /// present when a material keeps a texture.
    pub uvs: Option<Vec<f32>>,
    /// Four palette indices per vertex (`JOINTS_0`).
    pub joint_indices: Vec<u16>,
    /// Four weights per vertex (`WEIGHTS_0`, as floats).
    pub weights: Vec<f32>,
    /// Triangles, three vertex indices each.
    pub indices: Vec<u32>,
    pub primitives: Vec<Primitive>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
}

/// A run of `indices` drawn with one material.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Primitive {
    /// First index (into `indices`) and how many.
    pub first: u32,
    pub count: u32,
    /// Into `materials`.
    pub material: u32,
}

/// What the page needs of a glTF material: the base colour factor, and its
/// texture when the import kept it (small enough).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Material {
    pub base_color: [f32; 4],
    /// Into `textures`.
    pub texture: Option<u32>,
}

/// An image as the file held it (PNG or JPEG bytes).
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    pub mime_type: String,
    pub bytes: Bytes,
}

impl Mesh {
    pub fn vertex_count(&self) -> usize {
        self.positions.len() / 3
    }

    /// Bytes of [`encode`]'s output, from the counts alone (a bound the
    /// importer checks before it reads anything).
    pub fn encoded_len_bound(vertices: usize, indices: usize, joints: usize, texture_bytes: usize) -> usize {
        let per_vertex = 4 * (3 + 3 + 2 + 4) + 2 * 4;
        let names = joints * 64;
        4096 + names + vertices * per_vertex + indices * 4 + joints * 64 + texture_bytes + 64
    }
}

/// The strong entity tag the mesh is served with: `"m-"` and 32 hex digits
/// of the SHA-256 of its bytes.
pub fn etag(bytes: &[u8]) -> String {
    use sha2::Digest as _;
    let digest = sha2::Sha256::digest(bytes);
    let hex: String = digest[..16].iter().map(|b| format!("{b:02x}")).collect();
    format!("\"m-{hex}\"")
}

/// One array of the body, as the header describes it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ArrayRef {
    /// Bytes from the body's start (a multiple of 4) and the array's length.
    pub offset: u32,
    pub length: u32,
    /// `f32`, `u8`, `u16` or `u32`.
    #[serde(rename = "type")]
    pub kind: ArrayType,
    /// Components per element.
    pub components: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ArrayType {
    F32,
    U8,
    U16,
    U32,
}

impl ArrayType {
    fn size(self) -> usize {
        match self {
            ArrayType::U8 => 1,
            ArrayType::U16 => 2,
            ArrayType::F32 | ArrayType::U32 => 4,
        }
    }
}

/// The arrays of the body by name (`normal` and `uv` may be absent).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Arrays {
    pub position: ArrayRef,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normal: Option<ArrayRef>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uv: Option<ArrayRef>,
    pub joints: ArrayRef,
    pub weights: ArrayRef,
    pub indices: ArrayRef,
    pub inverse_binds: ArrayRef,
}

/// A texture in the header: its media type and where its bytes are.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TextureRef {
    pub mime_type: String,
    pub offset: u32,
    pub length: u32,
}

/// The JSON header. Fields a reader does not know are ignored (a change old
/// readers would misread gets a new version instead).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub vertices: u32,
    pub joints: Vec<String>,
    pub arrays: Arrays,
    pub primitives: Vec<Primitive>,
    pub materials: Vec<Material>,
    pub textures: Vec<TextureRef>,
}

/// The body as it is written: each piece 4-byte aligned.
#[derive(Default)]
struct Body {
    bytes: Vec<u8>,
}

impl Body {
    fn push(&mut self, data: &[u8], kind: ArrayType, components: u32) -> ArrayRef {
        let offset = self.bytes.len() as u32;
        self.bytes.extend_from_slice(data);
        self.bytes.resize(self.bytes.len().next_multiple_of(4), 0);
        ArrayRef { offset, length: data.len() as u32, kind, components }
    }

    fn floats(&mut self, values: &[f32], components: u32) -> ArrayRef {
        let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.push(&data, ArrayType::F32, components)
    }
}

/// The mesh in the binary form: joint indices as `u8` when the palette has
/// at most 256 joints, indices as `u16` when there are at most 65,536
/// vertices, everything else `f32`.
pub fn encode(mesh: &Mesh) -> Vec<u8> {
    let mut body = Body::default();
    let position = body.floats(&mesh.positions, 3);
    let normal = mesh.normals.as_ref().map(|n| body.floats(n, 3));
    let uv = mesh.uvs.as_ref().map(|u| body.floats(u, 2));
    let joints = if mesh.joints.len() <= 256 {
        let data: Vec<u8> = mesh.joint_indices.iter().map(|&j| j as u8).collect();
        body.push(&data, ArrayType::U8, 4)
    } else {
        let data: Vec<u8> = mesh.joint_indices.iter().flat_map(|j| j.to_le_bytes()).collect();
        body.push(&data, ArrayType::U16, 4)
    };
    let weights = body.floats(&mesh.weights, 4);
    let indices = if mesh.vertex_count() <= 1 << 16 {
        let data: Vec<u8> = mesh.indices.iter().flat_map(|&i| (i as u16).to_le_bytes()).collect();
        body.push(&data, ArrayType::U16, 1)
    } else {
        let data: Vec<u8> = mesh.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
        body.push(&data, ArrayType::U32, 1)
    };
    let flat: Vec<f32> = mesh.inverse_binds.iter().flatten().copied().collect();
    let inverse_binds = body.floats(&flat, 16);
    let textures = (mesh.textures.iter())
        .map(|t| {
            let at = body.push(&t.bytes, ArrayType::U8, 1);
            TextureRef { mime_type: t.mime_type.clone(), offset: at.offset, length: at.length }
        })
        .collect();
    let header = Header {
        vertices: mesh.vertex_count() as u32,
        joints: mesh.joints.clone(),
        arrays: Arrays { position, normal, uv, joints, weights, indices, inverse_binds },
        primitives: mesh.primitives.clone(),
        materials: mesh.materials.clone(),
        textures,
    };
    let mut json = serde_json::to_vec(&header).unwrap_or_default();
    json.resize(json.len().next_multiple_of(4), b' ');
    let mut out = Vec::with_capacity(12 + json.len() + body.bytes.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(&json);
    out.extend_from_slice(&body.bytes);
    out
}

/// Reads the binary form back, checking every offset (the format's own
/// test, and a reader for tools).
///
/// # Errors
/// Bytes that are not this format, or whose arrays do not fit.
pub fn decode(bytes: &[u8]) -> Result<Mesh, String> {
    if bytes.len() < 12 || &bytes[..4] != MAGIC {
        return Err("not an inbetween mesh (magic INBM)".into());
    }
    let word = |at: usize| u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]) as usize;
    if word(4) != VERSION as usize {
        return Err(format!("version {} is not {VERSION}", word(4)));
    }
    let header_len = word(8);
    let json = bytes.get(12..12 + header_len).ok_or("the header runs past the end")?;
    let header: Header = serde_json::from_slice(json).map_err(|e| format!("header: {e}"))?;
    let body = &bytes[12 + header_len..];
    let slice = |a: &ArrayRef| -> Result<&[u8], String> {
        let (from, len) = (a.offset as usize, a.length as usize);
        if from % 4 != 0 || len % a.kind.size() != 0 {
            return Err(format!("array at {from} is misaligned"));
        }
        body.get(from..from + len).ok_or_else(|| format!("array at {from}+{len} runs past the end"))
    };
    let floats = |a: &ArrayRef| -> Result<Vec<f32>, String> {
        if a.kind != ArrayType::F32 {
            return Err("expected f32".into());
        }
        Ok(slice(a)?.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect())
    };
    let uints = |a: &ArrayRef| -> Result<Vec<u32>, String> {
        let data = slice(a)?;
        Ok(match a.kind {
            ArrayType::U8 => data.iter().map(|&b| u32::from(b)).collect(),
            ArrayType::U16 => data.chunks_exact(2).map(|b| u32::from(u16::from_le_bytes([b[0], b[1]]))).collect(),
            ArrayType::U32 => data.chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
            ArrayType::F32 => return Err("expected integers".into()),
        })
    };
    let a = &header.arrays;
    let binds = floats(&a.inverse_binds)?;
    let textures = (header.textures.iter())
        .map(|t| {
            let at = ArrayRef { offset: t.offset, length: t.length, kind: ArrayType::U8, components: 1 };
            Ok(Texture { mime_type: t.mime_type.clone(), bytes: Bytes::copy_from_slice(slice(&at)?) })
        })
        .collect::<Result<_, String>>()?;
    let mesh = Mesh {
        joints: header.joints,
        inverse_binds: binds.chunks_exact(16).map(|m| m.try_into().unwrap_or([0.0; 16])).collect(),
        positions: floats(&a.position)?,
        normals: a.normal.as_ref().map(floats).transpose()?,
        uvs: a.uv.as_ref().map(floats).transpose()?,
        joint_indices: uints(&a.joints)?.into_iter().map(|j| j as u16).collect(),
        weights: floats(&a.weights)?,
        indices: uints(&a.indices)?,
        primitives: header.primitives,
        materials: header.materials,
        textures,
    };
    if mesh.vertex_count() != header.vertices as usize || mesh.joint_indices.len() != 4 * mesh.vertex_count() {
        return Err("the arrays disagree with the vertex count".into());
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle(joints: usize, vertices: usize) -> Mesh {
        Mesh {
            joints: (0..joints).map(|j| format!("j{j}")).collect(),
            inverse_binds: (0..joints).map(|j| [j as f32; 16]).collect(),
            positions: (0..vertices * 3).map(|i| i as f32 * 0.5).collect(),
            normals: Some(vec![0.0; vertices * 3]),
            uvs: None,
            joint_indices: (0..vertices * 4).map(|i| (i % joints) as u16).collect(),
            weights: vec![0.25; vertices * 4],
            indices: (0..vertices as u32).collect(),
            primitives: vec![Primitive { first: 0, count: vertices as u32, material: 0 }],
            materials: vec![Material { base_color: [1.0, 0.5, 0.25, 1.0], texture: Some(0) }],
            textures: vec![Texture { mime_type: "image/png".into(), bytes: Bytes::from_static(b"\x89PNG12345") }],
        }
    }

    #[test]
    fn encodes_and_decodes_small_and_wide_meshes() {
        for (joints, vertices) in [(3, 3), (300, 70_002)] {
            let mesh = triangle(joints, vertices);
            let bytes = encode(&mesh);
            assert_eq!(&bytes[..4], MAGIC);
            assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()) % 4, 0);
            assert!(bytes.len() <= Mesh::encoded_len_bound(vertices, vertices, joints, 9));
            assert_eq!(decode(&bytes).unwrap(), mesh);
        }
        let small: Header = {
            let bytes = encode(&triangle(3, 3));
            let len = u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize;
            serde_json::from_slice(&bytes[12..12 + len]).unwrap()
        };
        assert_eq!((small.arrays.joints.kind, small.arrays.indices.kind), (ArrayType::U8, ArrayType::U16));
        assert!(decode(b"INBM\x02\0\0\0\0\0\0\0").is_err());
    }
}
