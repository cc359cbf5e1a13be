//! Wire formats at the edge: each protocol's types and their conversions to
//! and from the core (`[x, y, z, w]` quaternion order is fixed here).

pub mod character;
pub mod compact;
mod doc;
mod float;
pub mod frame;
pub mod graph;
pub mod graph_inputs;
pub mod grid;
pub mod ik;
pub mod json;
pub mod mesh;
pub mod motion;
pub mod proto;
pub mod proto_graph;
pub mod spring;
