//! Compact frames in the engine on a paused clock (docs/compact-frames.md):
//! a broadcast encodes each tick once per layout for all its compact
//! viewers, a viewer that lagged past a key frame is sent that key frame
//! before the delta frame after it (so every frame it receives decodes),
//! and controls that leave a layout bring a new one, on a stream and on a
//! broadcast (each of its layouts at the control's tick).

use std::sync::Arc;
use std::time::Duration;

use formats::wire::compact::{CompactDecoder, LayoutDoc};
use serde_json::Value::Null;

use super::tests::{clip, pinned};
use super::*;

fn engine() -> Engine {
    Engine::new(EngineConfig { max_streams: 100, max_streams_per_client: 100, max_broadcasts: 4, ..Default::default() })
}

fn broadcast(e: &Engine, fps: u32) -> Arc<Broadcast> {
    let params = StreamParams::new(pinned("c1", clip()), StreamRequest { fps, ..Default::default() }).unwrap();
    let spec = BroadcastSpec { params, idle_timeout: Duration::from_secs(300), description: Null, work_per_sec: 0 };
    e.broadcasts().create(spec, BroadcastCharge::free()).unwrap()
}

fn layout(b: &Broadcast, max_error: f32) -> Arc<CompactLayout> {
    Arc::new(CompactLayout::of_clip(b.params().clip(), max_error, None, b.params().fps))
}

fn decoder(layout: &CompactLayout) -> CompactDecoder {
    let doc: LayoutDoc = serde_json::from_str(&layout.document).unwrap();
    CompactDecoder::of_document(&doc)
}

async fn frame(sub: &mut Subscription) -> Delivered {
    match sub.next().await {
        Next::Frame(f) => f,
        Next::End(r) => panic!("ended early: {r:?}"),
    }
}

/// Decodes what a viewer was sent for one tick (a key frame first, if any):
/// the decoded frames' (seq, key, dropped).
fn decode(d: &mut CompactDecoder, f: &Delivered) -> Vec<(u64, bool, u64)> {
    let mut pose = anim::Pose::default();
    let mut out = Vec::new();
    for bytes in f.prelude.iter().chain([&f.bytes]) {
        let decoded = d.decode(bytes, &mut pose).unwrap_or_else(|e| panic!("seq {}: {e}", f.seq));
        out.push((decoded.header.seq, decoded.key, decoded.header.dropped));
    }
    out
}

#[tokio::test(start_paused = true)]
async fn viewers_of_a_layout_share_its_bytes_and_a_lagging_one_gets_the_key_frame_first() {
    let e = engine();
    let b = broadcast(&e, 10);
    let l = layout(&b, 1e-4);
    assert_eq!(l.key_interval, 10, "a key frame at least once a second");
    let mut steady = b.watch_compact((Arc::clone(&l), ReachSig::default()), e.admit(None).unwrap(), None).unwrap();
    let mut slow = b.watch_compact((Arc::clone(&l), ReachSig::default()), e.admit(None).unwrap(), None).unwrap();
    let (mut ds, mut dl) = (decoder(&l), decoder(&l));
    for seq in 0..3 {
        let (a, c) = (frame(&mut steady).await, frame(&mut slow).await);
        assert_eq!(a.bytes.as_ptr(), c.bytes.as_ptr(), "seq {seq}: one encoding for both viewers");
        assert_eq!(decode(&mut ds, &a), [(seq, seq == 0, 0)]);
        decode(&mut dl, &c);
    }
    // `slow` stops reading while 20 ticks go by: its buffer (8 frames) keeps
    // the newest only, deltas of the key frame of tick 10 it never had.
    let mut keys = Vec::new();
    for seq in 3..23 {
        let a = frame(&mut steady).await;
        let decoded = decode(&mut ds, &a);
        assert_eq!(decoded, [(seq, seq % 10 == 0, 0)], "key frames every 10 ticks, deltas between");
        keys.extend(decoded.iter().filter(|d| d.1).map(|d| d.0));
    }
    assert_eq!(keys, [10, 20]);
    let late = frame(&mut slow).await;
    assert!(late.prelude.is_some(), "the key frame it missed comes first");
    assert!(late.seq > 10 && late.seq < 20, "the oldest frame kept is a delta of tick 10: {}", late.seq);
    let decoded = decode(&mut dl, &late);
    assert_eq!(decoded[0], (10, true, 7), "key frame 10, after seq 2: 7 ticks missed");
    assert_eq!(decoded[1], (late.seq, false, late.seq - 11), "then its delta, the gap since the key frame");
    // From then on, every frame decodes in order with no key frame sent twice.
    for _ in 0..12 {
        let f = frame(&mut slow).await;
        assert!(f.prelude.is_none(), "seq {}: it has its key frame", f.seq);
        decode(&mut dl, &f);
    }
}

/// The next frame of `sub` that brings a new layout, decoded by `d` (a
/// key frame in it); the frames before it decode in the old layout.
async fn relayout(sub: &mut Subscription, d: &mut CompactDecoder) -> (u64, Arc<str>) {
    for _ in 0..20 {
        let f = frame(sub).await;
        if let Some((seq, doc)) = f.layout.clone() {
            assert_eq!(seq, f.seq, "it names the first frame in it");
            d.relayout(&serde_json::from_str(&doc).unwrap());
            assert!(decode(d, &f)[0].1, "the first frame in a new layout is a key frame");
            return (seq, doc);
        }
        decode(d, &f);
    }
    panic!("no new layout in 20 frames")
}

#[tokio::test(start_paused = true)]
async fn layouts_are_encoded_apart_and_each_follows_a_layer_ramp_into_a_new_layout() {
    let e = engine();
    let b = broadcast(&e, 10);
    let (fine, coarse) = (layout(&b, 1e-5), layout(&b, 1e-3));
    let mut a = b.watch_compact((Arc::clone(&fine), ReachSig::default()), e.admit(None).unwrap(), None).unwrap();
    let mut c = b.watch_compact((Arc::clone(&coarse), ReachSig::default()), e.admit(None).unwrap(), None).unwrap();
    let (fa, fc) = (frame(&mut a).await, frame(&mut c).await);
    assert_eq!(fa.seq, fc.seq);
    assert!(fa.bytes.len() > fc.bytes.len(), "a tighter bound takes more bits: {fa:?} {fc:?}");
    let (mut da, mut dc) = (decoder(&fine), decoder(&coarse));
    decode(&mut da, &fa);
    decode(&mut dc, &fc);
    // A layer ramp plays poses outside the clip's own ranges: both layouts widen, at the same tick.
    let ramp = Control::Layer { index: 0, weight: 0.5, duration: 0.0 };
    let (stamp, _) = b.control(ramp).unwrap();
    let ((sa, doc_a), (sc, doc_c)) = (relayout(&mut a, &mut da).await, relayout(&mut c, &mut dc).await);
    assert_eq!((sa, sc), (stamp, stamp), "each viewer's new layout from the ramp's tick");
    assert_ne!((&*doc_a, &*doc_c), (&*fine.document, &*coarse.document));
    assert_ne!(doc_a, doc_c, "one layout per bound");
    // A seek stays within them.
    b.control(Control::Seek(0.5)).unwrap();
    for _ in 0..3 {
        let f = frame(&mut a).await;
        assert!(f.layout.is_none(), "seq {}: the derived ranges hold it", f.seq);
        decode(&mut da, &f);
    }
    drop((a, c));
    // A watch opened now chooses the layout of what the broadcast has played: the very same.
    let reach = b.reach();
    let again = reach.layout(b.params(), 1e-5, None).unwrap();
    assert_eq!(*again.document, *doc_a);
    assert!(b.watch_compact((Arc::new(again), reach.sig()), e.admit(None).unwrap(), None).is_ok());
}

/// A layer ramp on a compact clip stream leaves its observed ranges: the
/// next frame carries a new layout and is a key frame in it. The new,
/// derived ranges hold any weights, so another ramp brings none.
#[tokio::test(start_paused = true)]
async fn a_layer_ramp_on_a_clip_stream_brings_a_new_layout_once() {
    let e = engine();
    let params = StreamParams::new(pinned("c1", clip()), StreamRequest { fps: 10, ..Default::default() }).unwrap();
    let l = Arc::new(CompactLayout::of_clip(params.clip(), 1e-4, None, 10));
    let mut sub = e.play(params.with_compact(Arc::clone(&l)), e.admit(None).unwrap(), None);
    let mut d = decoder(&l);
    for _ in 0..2 {
        let f = frame(&mut sub).await;
        assert!(f.layout.is_none(), "the opened layout holds the clip");
        decode(&mut d, &f);
    }
    sub.control(Control::Layer { index: 0, weight: 0.5, duration: 0.0 }).await.unwrap();
    let f = frame(&mut sub).await;
    let (seq, doc) = f.layout.clone().expect("a new layout");
    assert_eq!(seq, f.seq, "it names the first frame in it");
    assert_ne!(*doc, *l.document);
    d.relayout(&serde_json::from_str(&doc).unwrap());
    assert!(decode(&mut d, &f)[0].1, "the first frame in a new layout is a key frame");
    sub.control(Control::Layer { index: 0, weight: 1.0, duration: 0.0 }).await.unwrap();
    for _ in 0..3 {
        let f = frame(&mut sub).await;
        assert!(f.layout.is_none(), "seq {}: the derived ranges hold any weight", f.seq);
        decode(&mut d, &f);
    }
}

/// A stream's pricing that takes any price and runs each new layout's
/// choice on a thread of its own, as the server's work pool does (or
/// refuses it once begun, as at the pool's deadline).
#[derive(Debug, Default)]
struct LayoutsOffTask {
    charged: std::sync::Mutex<Vec<u64>>,
    /// Jobs run on the runner's thread.
    ran: Arc<std::sync::atomic::AtomicUsize>,
    time_out: bool,
}

impl Repricing for LayoutsOffTask {
    fn reprice(&self, _: &[&pinned::StreamMotion], _: &[anim::ik::IkConstraint]) -> Result<(), ControlError> {
        Ok(())
    }

    fn admit(&self) -> Result<(), ControlError> {
        Ok(())
    }

    fn charge_layout(&self, units: u64) -> Result<LayoutRunner, ControlError> {
        self.charged.lock().unwrap().push(units);
        let (ran, time_out) = (Arc::clone(&self.ran), self.time_out);
        Ok(Box::new(move |job| {
            Box::pin(async move {
                let (tx, rx) = tokio::sync::oneshot::channel();
                std::thread::spawn(move || {
                    ran.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                    let _ = tx.send(job());
                });
                let chosen = rx.await.expect("the job ran");
                if time_out {
                    return Err(ControlError::Invalid("timed out"));
                }
                Ok(chosen)
            })
        }))
    }
}

/// A control that leaves a compact stream's layout has its new layout
/// charged to the stream and chosen by the runner the stream's pricing
/// gives (the work pool), not on the task that sent it; a choice refused
/// once begun refuses the control and leaves the stream as it was, so the
/// next such control needs a layout again.
#[tokio::test]
async fn a_new_layout_is_chosen_by_the_streams_runner_and_a_refused_one_changes_nothing() {
    let e = engine();
    for time_out in [false, true] {
        let params = StreamParams::new(pinned("c1", clip()), StreamRequest { fps: 10, ..Default::default() }).unwrap();
        let l = Arc::new(CompactLayout::of_clip(params.clip(), 1e-4, None, 10));
        let pricing = Arc::new(LayoutsOffTask { time_out, ..LayoutsOffTask::default() });
        let permit = e.admit(None).unwrap().priced(Arc::clone(&pricing) as Arc<dyn Repricing>);
        let mut sub = e.play(params.with_compact(Arc::clone(&l)), permit, None);
        assert!(frame(&mut sub).await.layout.is_none());
        let ramp = Control::Layer { index: 0, weight: 0.5, duration: 0.0 };
        let sent = sub.control(ramp.clone()).await;
        assert_eq!(pricing.ran.load(std::sync::atomic::Ordering::SeqCst), 1, "the runner chose it");
        assert_eq!(pricing.charged.lock().unwrap().len(), 1);
        if !time_out {
            sent.unwrap();
            assert!(frame(&mut sub).await.layout.is_some(), "the new layout goes with the control");
            continue;
        }
        assert_eq!(sent, Err(ControlError::Invalid("timed out")));
        assert!(frame(&mut sub).await.layout.is_none(), "refused: the stream keeps its layout");
        assert!(sub.control(ramp).await.is_err(), "and the next ramp needs a new one again");
        assert_eq!(pricing.charged.lock().unwrap().len(), 2);
    }
}

#[test]
fn compact_parameters_are_checked() {
    let check = |max_error, distance| CompactRequest { max_error, distance }.check().map_err(|e| e.code);
    assert_eq!(check(None, None), Ok((anim::compact::DEFAULT_MAX_ERROR, None)));
    assert_eq!(check(Some(1e-6), Some(0.01)), Ok((1e-6, Some(0.01))));
    assert_eq!(check(Some(9.9e-7), None), Err("max_error_out_of_range"));
    assert_eq!(check(Some(f64::NAN), None), Err("max_error_out_of_range"));
    assert_eq!(check(None, Some(0.009)), Err("distance_out_of_range"));
    assert_eq!(check(None, Some(f64::INFINITY)), Err("distance_out_of_range"));
}
