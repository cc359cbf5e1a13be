//! A compact-frame encoder and decoder allocate nothing per frame once warm
//! (docs/compact-frames.md): a stream's encoder runs on every tick. Its own
//! binary, since `#[global_allocator]` is per binary.

extern crate inbetween_formats as formats;

use std::alloc::{GlobalAlloc, Layout as AllocLayout, System};
use std::cell::Cell;

use anim::compact::{DEFAULT_MAX_ERROR, Layout, Ranges, default_distance};
use anim::{Channel, Clip, ClipSpec, Cursor, Interpolation, JointSpec, Keys, Pose, SkeletonSpec, TrackSpec, Transform};
use formats::wire::compact::{CompactDecoder, CompactEncoder, Header};
use glam::{Quat, Vec3, Vec4};

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: every call is forwarded to `System` unchanged; counting touches
// only a thread-local counter.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: AllocLayout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: AllocLayout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: AllocLayout, size: usize) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.realloc(ptr, layout, size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

/// Eight joints in a chain, each turning about x, the root moving.
fn clip() -> Clip {
    let joints = (0..8)
        .map(|i| JointSpec {
            name: format!("j{i}"),
            parent: (i > 0).then(|| format!("j{}", i - 1)),
            rest: Transform { translation: Vec3::new(0.0, 0.1, 0.0), ..Transform::IDENTITY },
            inverse_bind: None,
        })
        .collect();
    let times: Vec<f32> = (0..5).map(|k| k as f32 / 4.0).collect();
    let mut tracks: Vec<TrackSpec> = (0..8)
        .map(|i| {
            let keys = (0..5).map(|k| Vec4::from(Quat::from_rotation_x(0.2 * (k + i) as f32))).collect();
            TrackSpec::new(&format!("j{i}"), Channel::Rotation, Interpolation::Linear, times.clone(), Keys::Vec4(keys))
        })
        .collect();
    let root = Keys::Vec3((0..5).map(|k| Vec3::new(k as f32 * 0.1, 0.0, 0.0)).collect());
    tracks.push(TrackSpec::new("j0", Channel::Translation, Interpolation::Linear, times, root));
    Clip::build(&ClipSpec {
        name: "alloc".into(),
        skeleton: Some(SkeletonSpec { joints }),
        tracks,
        ..Default::default()
    })
    .expect("the test clip builds")
}

#[test]
fn encoding_and_decoding_a_frame_allocates_nothing_once_warm() {
    let clip = clip();
    let skeleton = clip.skeleton();
    let layout =
        Layout::choose(skeleton, &Ranges::of_clip(&clip, 240.0), DEFAULT_MAX_ERROR, default_distance(skeleton));
    let mut encoder = CompactEncoder::new(layout.clone(), 4);
    let mut decoder = CompactDecoder::new(layout);
    let (mut cursor, mut pose, mut decoded) = (Cursor::default(), Pose::default(), Pose::default());
    let mut frame = |seq: u64, encoder: &mut CompactEncoder, decoder: &mut CompactDecoder| {
        clip.sample_into(seq as f32 / 30.0, &mut cursor, &mut pose);
        let header = Header { seq, clip_time: seq as f32 / 30.0, ..Header::default() };
        let bytes = encoder.encode(&header, &pose, false);
        decoder.decode(bytes, &mut decoded).expect("decodes").key
    };
    // Warm: a key frame and deltas size every buffer.
    for seq in 0..8 {
        frame(seq, &mut encoder, &mut decoder);
    }
    let before = allocations();
    let keys = (8..40).filter(|&seq| frame(seq, &mut encoder, &mut decoder)).count();
    assert_eq!(allocations() - before, 0, "allocations over 32 frames");
    assert_eq!(keys, 8, "key frames every fourth frame were among them");
}
