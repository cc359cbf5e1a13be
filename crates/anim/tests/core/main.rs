//! The evaluation core's test suite (docs/clip-format.md, issue 2).
//!
//! One binary, one module per concern. `reference` is an independent `f64`
//! evaluator written from docs/clip-format.md, “Evaluation math” alone;
//! `accuracy` holds the core to it; `lecture` checks the lecture's worked
//! examples; `b_spline` the uniform B-spline against the lecture's basis
//! matrix; `properties` states what must hold for any keys; `validation` pins
//! each error code and path; `alloc` proves the hot path allocation-free;
//! `budget` holds builds to their work budget and clips to their byte estimate;
//! `cli` runs the real binary; `import` checks the importers against real
//! third-party files; `parameters` holds parameters (docs/clip-format.md,
//! “Parameters”) to hand-computed values; `ik` holds the IK solvers to
//! docs/ik.md (and the chain to seed 003's own algorithm); `root_motion` and
//! `root_motion_cycles` hold root motion to a planar `f64` reference;
//! `character` reads roles from real and synthetic rigs and holds
//! retargeting to an `f64` reference and its properties.
//!
//! The counting allocator lives here because `#[global_allocator]` is
//! per binary. It counts per thread, so tests running in parallel do not
//! disturb each other's counts.

mod accuracy;
mod alloc;
mod b_spline;
mod behaviour;
mod budget;
pub mod character;
mod compact;
mod composition_reference;
mod crossfade;
mod graph_mix;
mod graph_root_motion;
mod ik;
mod lecture;
mod motion;
mod parameters;
mod playback;
mod player_state;
mod properties;
mod random;
mod reference;
mod root_motion;
mod root_motion_cycles;
mod soa;
mod springs;

extern crate inbetween_anim as anim;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
    /// Bytes allocated minus bytes freed by this thread (as requested).
    static LIVE_BYTES: Cell<i64> = const { Cell::new(0) };
}

fn live(delta: i64) {
    let _ = LIVE_BYTES.try_with(|c| c.set(c.get() + delta));
}

// SAFETY: every call is forwarded to `System` unchanged; counting touches
// only a const-initialised thread-local without a destructor, which itself
// never allocates.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        live(layout.size() as i64);
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        live(layout.size() as i64);
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        live(new_size as i64 - layout.size() as i64);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        live(-(layout.size() as i64));
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Bytes the calling thread has allocated and not freed (frees of memory
/// another thread allocated count here too, so measure on one thread).
pub fn live_bytes() -> i64 {
    LIVE_BYTES.with(Cell::get)
}

/// Allocations (including reallocations) made so far by the calling thread.
pub fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

/// A joint named `name` under `parent`, at rest `t` from it, unrotated and
/// unscaled, without an inverse bind: the test rigs' usual joint.
pub fn rest_joint(name: &str, parent: Option<&str>, t: [f32; 3]) -> anim::JointSpec {
    anim::JointSpec {
        name: name.into(),
        parent: parent.map(Into::into),
        rest: anim::Transform {
            translation: glam::Vec3::from(t),
            rotation: glam::Quat::IDENTITY,
            scale: glam::Vec3::ONE,
        },
        inverse_bind: None,
    }
}
