//! inbetween: a keyframe-animation server. See `ARCHITECTURE.md` for the
//! codemap; `anim` is the pure evaluation core the service layers wrap.

pub mod anim;
pub mod cli;
#[doc(hidden)]
pub mod fuzzing;
pub mod import;
pub mod load;
mod panics;
pub mod server;
pub mod store;
pub mod stream;
mod sync;
pub mod wire;
