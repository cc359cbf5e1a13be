//! A GLB read the plain way, for tests that check what the server made of
//! one against the file itself (not against the importer): the JSON chunk
//! as `serde_json`, accessors of the Fox's simple kinds (no sparse, tightly
//! packed or strided, FLOAT or unsigned integers) as `f64`s.

use serde_json::Value;

/// A GLB's JSON and BIN chunk.
pub struct Glb {
    pub json: Value,
    pub bin: Vec<u8>,
}

fn u32_at(b: &[u8], at: usize) -> usize {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap()) as usize
}

impl Glb {
    pub fn read(path: &str) -> Glb {
        let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{path}: {e}"));
        let json_len = u32_at(&bytes, 12);
        let json = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
        let bin_at = 20 + json_len;
        let bin = bytes[bin_at + 8..bin_at + 8 + u32_at(&bytes, bin_at)].to_vec();
        Glb { json, bin }
    }

    /// A buffer view's bytes.
    pub fn view(&self, index: usize) -> &[u8] {
        let view = &self.json["bufferViews"][index];
        let offset = view["byteOffset"].as_u64().unwrap_or(0) as usize;
        &self.bin[offset..offset + view["byteLength"].as_u64().unwrap() as usize]
    }

    /// Accessor `index` as rows of components.
    pub fn accessor(&self, index: usize) -> Vec<Vec<f64>> {
        let acc = &self.json["accessors"][index];
        let view_index = acc["bufferView"].as_u64().unwrap() as usize;
        let components = match acc["type"].as_str().unwrap() {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            "MAT4" => 16,
            other => panic!("accessor type {other}"),
        };
        let (size, read): (usize, fn(&[u8]) -> f64) = match acc["componentType"].as_u64().unwrap() {
            5126 => (4, |b| f32::from_le_bytes(b.try_into().unwrap()) as f64),
            5125 => (4, |b| u32::from_le_bytes(b.try_into().unwrap()) as f64),
            5123 => (2, |b| u16::from_le_bytes(b.try_into().unwrap()) as f64),
            5121 => (1, |b| b[0] as f64),
            other => panic!("component type {other}"),
        };
        let stride =
            self.json["bufferViews"][view_index]["byteStride"].as_u64().map_or(size * components, |s| s as usize);
        let data = &self.view(view_index)[acc["byteOffset"].as_u64().unwrap_or(0) as usize..];
        (0..acc["count"].as_u64().unwrap() as usize)
            .map(|i| (0..components).map(|c| read(&data[i * stride + c * size..][..size])).collect())
            .collect()
    }

    /// The accessor of attribute `name` of the first mesh's first primitive.
    pub fn attribute(&self, name: &str) -> Vec<Vec<f64>> {
        self.accessor(self.json["meshes"][0]["primitives"][0]["attributes"][name].as_u64().unwrap() as usize)
    }

    /// The names of skin `skin`'s joints, in order.
    pub fn skin_joint_names(&self, skin: usize) -> Vec<String> {
        let nodes = &self.json["nodes"];
        (self.json["skins"][skin]["joints"].as_array().unwrap().iter())
            .map(|j| nodes[j.as_u64().unwrap() as usize]["name"].as_str().unwrap().to_owned())
            .collect()
    }
}

/// The Fox of the repository's examples.
pub const FOX: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/gltf/Fox/Fox.glb");

/// The Fox with its texture replaced by `image`, as a `data:` URI.
pub fn fox_with_image(image: &[u8]) -> Vec<u8> {
    formats::testing::glb_with_image(&std::fs::read(FOX).unwrap(), image)
}
