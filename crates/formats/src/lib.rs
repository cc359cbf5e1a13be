//! inbetween's formats: the wire documents clients send and receive (JSON,
//! protobuf, mesh bytes) and the importers that turn third-party files (glTF,
//! GLB, BVH) into clips. Everything here is a pure translation between bytes
//! and the core's types (`anim`); nothing runs a server.

pub mod import;
pub mod wire;

#[doc(hidden)]
pub mod fuzzing;
#[doc(hidden)]
pub mod testing;
