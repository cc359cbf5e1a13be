//! An independent reading of the test files and the glTF formulas, in f64.
//!
//! Nothing here uses the importer or the core: the glTF JSON and buffers are
//! read with serde_json and base64 straight from the file, and the
//! interpolation formulas are transcribed from the glTF 2.0 specification
//! (Appendix C), so the tests compare two separate implementations.

// Matrix code reads as the maths does, with indices.
#![allow(clippy::needless_range_loop)]

use std::path::{Path, PathBuf};

use base64::Engine as _;
use serde_json::Value;

/// A real third-party test file, `rel` as in `../shared/testdata`: the
/// repository's own copy in `examples/` when it ships one (the Fox,
/// InterpolationTest, CMU 131_01, byte for byte the same), else the file in
/// `INBETWEEN_TESTDATA` (default `../shared/testdata` beside the clone; README,
/// "The two commands"). The
/// service tests' `common::testdata_path` is the same rule.
pub fn testdata(rel: &str) -> PathBuf {
    let root = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    let shipped = root.join("examples").join(rel);
    if shipped.is_file() { shipped } else { corpus_dir(&root).join(rel) }
}

pub fn read(rel: &str) -> Vec<u8> {
    let path = testdata(rel);
    std::fs::read(&path).unwrap_or_else(|e| {
        panic!("{}: {e} (third-party test files: set INBETWEEN_TESTDATA, README \"The two commands\")", path.display())
    })
}

/// A glTF file as plain JSON plus its decoded buffers.
pub struct RawGltf {
    pub json: Value,
    pub buffers: Vec<Vec<u8>>,
}

impl RawGltf {
    pub fn load(rel: &str) -> RawGltf {
        let bytes = read(rel);
        let (json, bin): (Value, Option<Vec<u8>>) = if bytes.starts_with(b"glTF") {
            let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap()) as usize;
            let json_len = u32_at(12);
            let json = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
            let bin_at = 20 + json_len;
            let bin_len = u32_at(bin_at);
            (json, Some(bytes[bin_at + 8..bin_at + 8 + bin_len].to_vec()))
        } else {
            (serde_json::from_slice(&bytes).unwrap(), None)
        };
        let dir = testdata(rel).parent().unwrap().to_path_buf();
        let buffers = json["buffers"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| match b["uri"].as_str() {
                None => bin.clone().unwrap(),
                Some(uri) if uri.starts_with("data:") => {
                    let payload = &uri[uri.find(',').unwrap() + 1..];
                    base64::engine::general_purpose::STANDARD.decode(payload).unwrap()
                }
                Some(uri) => std::fs::read(dir.join(uri)).unwrap(),
            })
            .collect();
        RawGltf { json, buffers }
    }

    /// The rows of a FLOAT accessor (the test files use no other kind).
    pub fn accessor(&self, index: usize) -> Vec<Vec<f64>> {
        let a = &self.json["accessors"][index];
        assert_eq!(a["componentType"], 5126, "test files use float accessors");
        let width = match a["type"].as_str().unwrap() {
            "SCALAR" => 1,
            "VEC3" => 3,
            "VEC4" => 4,
            "MAT4" => 16,
            other => panic!("{other}"),
        };
        let view = &self.json["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
        let buffer = &self.buffers[view["buffer"].as_u64().unwrap() as usize];
        let start = view["byteOffset"].as_u64().unwrap_or(0) as usize + a["byteOffset"].as_u64().unwrap_or(0) as usize;
        let stride = view["byteStride"].as_u64().map_or(width * 4, |s| s as usize);
        (0..a["count"].as_u64().unwrap() as usize)
            .map(|i| {
                (0..width)
                    .map(|c| {
                        let o = start + i * stride + c * 4;
                        f32::from_le_bytes(buffer[o..o + 4].try_into().unwrap()) as f64
                    })
                    .collect()
            })
            .collect()
    }

    pub fn node(&self, i: usize) -> &Value {
        &self.json["nodes"][i]
    }

    pub fn node_name(&self, i: usize) -> String {
        self.node(i)["name"].as_str().map_or_else(|| format!("node{i}"), str::to_owned)
    }

    pub fn parent_of(&self, i: usize) -> Option<usize> {
        self.json["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .position(|n| n["children"].as_array().is_some_and(|c| c.iter().any(|x| x.as_u64() == Some(i as u64))))
    }

    /// A node's static local matrix (column-major, from `matrix` or TRS).
    pub fn static_local(&self, i: usize) -> Mat {
        let n = self.node(i);
        if let Some(m) = n["matrix"].as_array() {
            let v: Vec<f64> = m.iter().map(|x| x.as_f64().unwrap()).collect();
            return Mat::from_cols(&v);
        }
        let get = |k: &str, d: &[f64]| -> Vec<f64> {
            n[k].as_array().map_or(d.to_vec(), |a| a.iter().map(|x| x.as_f64().unwrap()).collect())
        };
        trs(&get("translation", &[0.0; 3]), &get("rotation", &[0.0, 0.0, 0.0, 1.0]), &get("scale", &[1.0; 3]))
    }
}

/// One glTF sampler, read raw.
pub struct Sampler {
    pub interpolation: String,
    pub times: Vec<f64>,
    /// Per key: `[value]`, or `[in-tangent, value, out-tangent]` for CUBICSPLINE.
    pub keys: Vec<Vec<Vec<f64>>>,
}

impl Sampler {
    pub fn read(raw: &RawGltf, animation: usize, sampler: usize) -> Sampler {
        let s = &raw.json["animations"][animation]["samplers"][sampler];
        let interpolation = s["interpolation"].as_str().unwrap_or("LINEAR").to_owned();
        let times: Vec<f64> = raw.accessor(s["input"].as_u64().unwrap() as usize).into_iter().map(|r| r[0]).collect();
        let out = raw.accessor(s["output"].as_u64().unwrap() as usize);
        let per = if interpolation == "CUBICSPLINE" { 3 } else { 1 };
        let keys = out.chunks(per).map(|c| c.to_vec()).collect();
        Sampler { interpolation, times, keys }
    }

    /// The key value (the middle of a CUBICSPLINE triple).
    pub fn value(&self, k: usize) -> &[f64] {
        let group = &self.keys[k];
        &group[group.len() / 2]
    }

    /// The glTF 2.0 Appendix C evaluation at time `t`, clamped to the keys.
    pub fn eval(&self, t: f64, rotation: bool) -> Vec<f64> {
        let n = self.times.len();
        if t <= self.times[0] {
            return norm_if(self.value(0).to_vec(), rotation);
        }
        if t >= self.times[n - 1] {
            return norm_if(self.value(n - 1).to_vec(), rotation);
        }
        let k = self.times.iter().rposition(|&tk| tk <= t).unwrap();
        let (t0, t1) = (self.times[k], self.times[k + 1]);
        let td = t1 - t0;
        let u = (t - t0) / td;
        let (a, b) = (self.value(k), self.value(k + 1));
        match self.interpolation.as_str() {
            "STEP" => norm_if(a.to_vec(), rotation),
            "LINEAR" if rotation => gltf_slerp(a, b, u),
            "LINEAR" => a.iter().zip(b).map(|(x, y)| x + u * (y - x)).collect(),
            "CUBICSPLINE" => {
                let (bk, ak1) = (&self.keys[k][2], &self.keys[k + 1][0]);
                let (u2, u3) = (u * u, u * u * u);
                let v: Vec<f64> = (0..a.len())
                    .map(|i| {
                        (2.0 * u3 - 3.0 * u2 + 1.0) * a[i]
                            + td * (u3 - 2.0 * u2 + u) * bk[i]
                            + (-2.0 * u3 + 3.0 * u2) * b[i]
                            + td * (u3 - u2) * ak1[i]
                    })
                    .collect();
                norm_if(v, rotation)
            }
            other => panic!("{other}"),
        }
    }
}

fn norm_if(v: Vec<f64>, rotation: bool) -> Vec<f64> {
    if !rotation {
        return v;
    }
    let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    v.iter().map(|x| x / n).collect()
}

/// glTF 2.0 Appendix C "Spherical linear interpolation": the short way,
/// with the sign `s = dot/|dot|` and the angle `a = acos(|dot|)`.
pub fn gltf_slerp(a: &[f64], b: &[f64], u: f64) -> Vec<f64> {
    let a = norm_if(a.to_vec(), true);
    let b = norm_if(b.to_vec(), true);
    let d: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
    let s = if d < 0.0 { -1.0 } else { 1.0 };
    let angle = d.abs().min(1.0).acos();
    if angle < 1e-9 {
        return norm_if(a.iter().zip(&b).map(|(x, y)| x + u * (s * y - x)).collect(), true);
    }
    let (wa, wb) = (((1.0 - u) * angle).sin() / angle.sin(), s * (u * angle).sin() / angle.sin());
    a.iter().zip(&b).map(|(x, y)| wa * x + wb * y).collect()
}

/// A 4×4 matrix, column-major `m[col][row]`, f64.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mat(pub [[f64; 4]; 4]);

impl Mat {
    pub const IDENTITY: Mat =
        Mat([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]);

    pub fn from_cols(v: &[f64]) -> Mat {
        let mut m = [[0.0; 4]; 4];
        for c in 0..4 {
            for r in 0..4 {
                m[c][r] = v[c * 4 + r];
            }
        }
        Mat(m)
    }

    pub fn mul(&self, o: &Mat) -> Mat {
        let mut m = [[0.0; 4]; 4];
        for c in 0..4 {
            for r in 0..4 {
                m[c][r] = (0..4).map(|k| self.0[k][r] * o.0[c][k]).sum();
            }
        }
        Mat(m)
    }

    pub fn translation(t: [f64; 3]) -> Mat {
        let mut m = Mat::IDENTITY;
        m.0[3][0] = t[0];
        m.0[3][1] = t[1];
        m.0[3][2] = t[2];
        m
    }

    /// Rotation by `deg` degrees about axis 0 (X), 1 (Y) or 2 (Z),
    /// written out from cos and sin (no quaternions).
    pub fn axis_rotation(axis: usize, deg: f64) -> Mat {
        let (s, c) = deg.to_radians().sin_cos();
        let mut m = Mat::IDENTITY;
        let (i, j) = match axis {
            0 => (1, 2),
            1 => (2, 0),
            _ => (0, 1),
        };
        // Columns i and j of the 2D rotation in the (i, j) plane.
        m.0[i][i] = c;
        m.0[i][j] = s;
        m.0[j][i] = -s;
        m.0[j][j] = c;
        m
    }

    pub fn max_abs(&self) -> f64 {
        self.0.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()))
    }

    pub fn max_diff(&self, cols: &[f32; 16]) -> f64 {
        let mut d = 0.0f64;
        for c in 0..4 {
            for r in 0..4 {
                d = d.max((self.0[c][r] - cols[c * 4 + r] as f64).abs());
            }
        }
        d
    }

    pub fn position(&self) -> [f64; 3] {
        [self.0[3][0], self.0[3][1], self.0[3][2]]
    }
}

/// `T·R·S` from a translation, an `[x, y, z, w]` quaternion and a scale.
pub fn trs(t: &[f64], q: &[f64], s: &[f64]) -> Mat {
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    let (x, y, z, w) = (q[0] / n, q[1] / n, q[2] / n, q[3] / n);
    let r = [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + z * w), 2.0 * (x * z - y * w)],
        [2.0 * (x * y - z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + x * w)],
        [2.0 * (x * z + y * w), 2.0 * (y * z - x * w), 1.0 - 2.0 * (x * x + y * y)],
    ];
    let mut m = Mat::IDENTITY;
    for c in 0..3 {
        for row in 0..3 {
            m.0[c][row] = r[c][row] * s[c];
        }
        m.0[3][c] = t[c];
    }
    m
}

/// The larger of `|a − b|` and `|a + b|`'s smaller: quaternion distance up to sign.
pub fn quat_diff(a: &[f64], b: [f32; 4]) -> f64 {
    let plus = (0..4).map(|i| (a[i] - b[i] as f64).abs()).fold(0.0, f64::max);
    let minus = (0..4).map(|i| (a[i] + b[i] as f64).abs()).fold(0.0, f64::max);
    plus.min(minus)
}

pub fn vec_diff(a: &[f64], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - *y as f64).abs()).fold(0.0, f64::max)
}

/// Where the third-party files the repository does not ship are:
/// `INBETWEEN_TESTDATA`, else `shared/testdata` beside the clone (where CI
/// keeps them).
fn corpus_dir(root: &Path) -> PathBuf {
    std::env::var_os("INBETWEEN_TESTDATA").map(PathBuf::from).unwrap_or_else(|| root.join("../shared/testdata"))
}
