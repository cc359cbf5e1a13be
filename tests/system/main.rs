//! The system suite: the real `inbetween` binary (`common::ServerProcess`),
//! spawned on free ports and driven over loopback: signals and draining,
//! connection limits, overload, `kill -9` crashes, several nodes on one
//! PostgreSQL schema behind nginx, and the attacks of issue 15 inside a
//! 1 GiB memory cage (`attacks`).
//!
//! The slow runs (the soak, the overload measurement, the invalidation-delay
//! figures) return at once unless `INBETWEEN_SLOW=1`; the scripts in
//! `scripts/` set it.

#[path = "../common/mod.rs"]
mod common;

mod attacks;
mod multinode;
mod ops;
