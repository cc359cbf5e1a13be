//! Inputs the fuzzers found (`fuzz/`, CONTRIBUTING.md "Fuzzing"), each refused or
//! imported as it should be, never a panic. Small inputs are embedded as
//! found; others are regenerated from the finding's essence.

use formats::import::{Format, ImportOptions, import};
use serde_json::json;

use super::hostile::gltf;

/// import_gltf, crash-ddba4951: a mesh primitive whose POSITION accessor
/// does not exist panicked inside the gltf crate's own validation
/// (gltf-json 1.4.1 mesh.rs:151 indexes before it checks).
const MESH_POSITION_OUT_OF_RANGE: &str = r#"{
  "scene" : 0,
  "scenes" : [
    {
      "nodes" : [ 0 ]
    }
  ],
  
  "nodes" : [
    {
      "mesh" : 0,
      "rotation" : [ 0.0, 0.0, 0.0, 1.0 ]
    }
  ],
  
  "meshes" : [
    {
      "primitives" : [ {
        "attributes" : {
          "POSITION" : 1
        },
        "indices" : 0
      } ]
    }
  ],
  
  "animations": [
    {
      "samplers" : [
        {
          "input" : 2,
          "interpolation" : "LINEAR",
          "output" : 3
        }
      ],
      "channels" : [ {
        "sampler" : 0,
        "target" : {
          "node" : 0,
          "path" : "rotation"
        }
      } ]
    }
  ],

  "buffers" : [
    {
      "uri" : "data:application/octet-stream;base64,AAABAAIAAAAAAAAAAAAAAAAAAAAAAIA/AAAAAAAAAAAAAAAAAACAPwAAAAA=",
      "byteLenfset" : 0,
      "componentType" : 5126,
      "count" : 5,
      "type" : "SCALAR",
      "max" : [ 1.0 ],
      "min" : [ 0.0 ]
    },
    {
      "bufferView" : 2,
      "byteOffset" : 20,
      "componentType" : 5126,
      "count" : 5,
      "type" : "VEC4",
      "max" : [ 0.0, 0.0, 1.0, 1.0 ],
      "min" : [ 0.0, 0.0, 0.0, -0.707 ]
    }
  ],
  
  "asset" : {
    "version" : "2.0"
  }
  
}
"#;

#[test]
fn a_mesh_with_a_missing_position_accessor_is_no_panic() {
    let e = import(MESH_POSITION_OUT_OF_RANGE.as_bytes(), Format::Gltf, &ImportOptions::default()).unwrap_err();
    // What is left wrong is the animation's own accessors (2 and 3 of 2).
    assert_eq!(e.code(), "invalid_gltf", "{e}");
    assert!(e.to_string().contains("animations[0].samplers[0].input"), "{e}");
}

#[test]
fn a_broken_mesh_does_not_stop_a_valid_animation() {
    // Meshes are never read: one referring to nothing is dropped unseen.
    let bytes = gltf(|d| {
        d["meshes"] = json!([{"primitives": [{"attributes": {"POSITION": 99}, "indices": 98, "material": 97}]}]);
        d["nodes"][0]["mesh"] = json!(0);
        d["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    });
    let imported = import(&bytes, Format::Gltf, &ImportOptions::default()).unwrap();
    assert_eq!(imported.clips[0].name, "move");
}
