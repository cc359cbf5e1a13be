//! Hardening (issue 9, malformed input): the committed corpus replayed
//! against the real server over real HTTP and gRPC, and the fuzz corpus and
//! past crashes replayed through the fuzz targets' own code.

mod admission;
mod corpus;
mod fuzz_replay;

use std::path::PathBuf;

/// The repository root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}
