//! Broadcast tests on a paused tokio clock (docs/broadcasts.md): viewers of one
//! encoding share the very bytes of each tick (one encoding, observed as
//! one allocation), late joiners start at the next tick with `dropped` 0,
//! controls apply from the tick they were stamped with, read-only viewers
//! cannot control, and broadcasts end when deleted or idle.

use std::sync::Arc;
use std::time::Duration;

use serde_json::Value::Null;

use super::tests::{clip, pinned};
use super::*;

fn engine(max_broadcasts: usize) -> Engine {
    Engine::new(EngineConfig { max_streams: 100, max_streams_per_client: 100, max_broadcasts, ..Default::default() })
}

fn create(e: &Engine, fps: u32, idle_secs: u64) -> Arc<Broadcast> {
    let params = StreamParams::new(pinned("c1", clip()), StreamRequest { fps, ..Default::default() }).unwrap();
    let spec =
        BroadcastSpec { params, idle_timeout: Duration::from_secs(idle_secs), description: Null, work_per_sec: 0 };
    e.broadcasts().create(spec, BroadcastCharge::free()).unwrap()
}

/// A gate every control passes.
fn open_gate() -> ControlGate {
    Arc::new(|| Ok(()))
}

fn viewer(e: &Engine, b: &Arc<Broadcast>, encoding: Encoding, controls: bool) -> Subscription {
    b.watch(encoding, e.admit(None).unwrap(), controls.then(open_gate))
}

async fn frame(sub: &mut Subscription) -> Delivered {
    match sub.next().await {
        Next::Frame(f) => f,
        Next::End(r) => panic!("ended early: {r:?}"),
    }
}

/// A JSON frame's motion time.
fn time(f: &Delivered) -> f64 {
    let v: serde_json::Value = serde_json::from_slice(&f.bytes).unwrap();
    v["pose"]["time"].as_f64().unwrap()
}

#[tokio::test(start_paused = true)]
async fn viewers_share_each_ticks_bytes_and_late_joiners_start_at_the_next_tick() {
    let e = engine(4);
    let b = create(&e, 10, 300);
    let mut a = viewer(&e, &b, Encoding::Json, false);
    let mut p = viewer(&e, &b, Encoding::Protobuf, false);
    for seq in 0..5 {
        let (fa, fp) = (frame(&mut a).await, frame(&mut p).await);
        assert_eq!((fa.seq, fa.dropped, fp.seq, fp.dropped), (seq, 0, seq, 0));
    }
    // Joined after tick 4: their first frame is tick 5, with dropped 0.
    let mut c = viewer(&e, &b, Encoding::Json, false);
    let mut q = viewer(&e, &b, Encoding::Protobuf, false);
    for seq in 5..9 {
        let (fa, fc) = (frame(&mut a).await, frame(&mut c).await);
        let (fp, fq) = (frame(&mut p).await, frame(&mut q).await);
        assert_eq!((fc.seq, fc.dropped, fq.seq, fq.dropped), (seq, 0, seq, 0));
        // One encoding per encoding: the same allocation for every viewer.
        assert_eq!(fa.bytes.as_ptr(), fc.bytes.as_ptr(), "seq {seq}: JSON shared");
        if seq > 5 {
            assert_eq!(fp.bytes.as_ptr(), fq.bytes.as_ptr(), "seq {seq}: protobuf shared");
        } else {
            // q's first frame: the shared bytes with its joint names appended.
            assert!(fq.bytes.starts_with(&fp.bytes) && fq.bytes.len() > fp.bytes.len());
        }
        assert!((time(&fa) - seq as f64 / 10.0).abs() < 1e-12);
    }
    assert_eq!(b.status().viewers, 4);
}

#[tokio::test(start_paused = true)]
async fn controls_apply_from_their_stamp_for_every_viewer() {
    let e = engine(4);
    let b = create(&e, 10, 300);
    let mut a = viewer(&e, &b, Encoding::Json, false);
    let mut c = viewer(&e, &b, Encoding::Json, true);
    for _ in 0..3 {
        frame(&mut a).await;
        frame(&mut c).await;
    }
    // Tick 2 is out: the next control is stamped 3, whoever sends it.
    assert_eq!(b.control(Control::Seek(5.0)).map(|(seq, _)| seq), Ok(3));
    let mut times = Vec::new();
    for seq in 3..7 {
        let (fa, fc) = (frame(&mut a).await, frame(&mut c).await);
        assert_eq!((fa.seq, fc.seq), (seq, seq));
        assert_eq!(fa.bytes, fc.bytes);
        times.push((time(&fa) * 1e9).round() / 1e9);
        if seq == 4 {
            // Sent by the controlling viewer (its sink is the broadcast): stamped 5.
            c.control(Control::Pause).await.unwrap();
        }
    }
    assert_eq!(times, [5.0, 5.1, 5.1, 5.1], "seek at 3; pause at 5 holds tick 4's time");
    assert!(b.status().paused);
}

#[tokio::test(start_paused = true)]
async fn read_only_viewers_cannot_control_and_stop_ends_only_their_own_stream() {
    let e = engine(4);
    let b = create(&e, 10, 300);
    let mut reader = viewer(&e, &b, Encoding::Json, false);
    let mut writer = viewer(&e, &b, Encoding::Json, true);
    assert_eq!(reader.control(Control::Pause).await, Err(ControlError::ReadOnly));
    assert_eq!(b.control(Control::Stop).unwrap_err().code(), "bad_control");
    assert_eq!(b.control(Control::Speed(5000.0)).unwrap_err().code(), "bad_control");
    writer.control(Control::Stop).await.unwrap();
    assert_eq!(writer.next().await, Next::End(EndReason::Stopped));
    frame(&mut reader).await;
    assert!(!b.status().paused, "the refused controls changed nothing");
}

#[tokio::test(start_paused = true)]
async fn broadcasts_end_when_deleted_or_idle_and_are_capped() {
    let e = engine(2);
    let kept = create(&e, 10, 300);
    let idle = create(&e, 10, 2);
    let params = kept.params().clone();
    let spec = BroadcastSpec { params, idle_timeout: Duration::from_secs(1), description: Null, work_per_sec: 0 };
    assert_eq!(e.broadcasts().create(spec, BroadcastCharge::free()).unwrap_err(), BroadcastError::TooMany { limit: 2 });

    let mut v = viewer(&e, &kept, Encoding::Protobuf, false);
    // The time is the behaviour here: past the idle timeout (a paused clock: no wall time).
    tokio::time::sleep(Duration::from_millis(2500)).await;
    assert!(e.broadcasts().get(idle.id()).is_none(), "idle for 2 s: ended");
    assert!(e.broadcasts().get(kept.id()).is_some(), "watched: kept");
    assert!(e.broadcasts().delete(kept.id()));
    loop {
        match v.next().await {
            Next::Frame(_) => {}
            Next::End(reason) => break assert_eq!(reason, EndReason::Ended),
        }
    }
    assert!(e.broadcasts().is_empty());
    assert!(!e.broadcasts().delete(kept.id()));
}

#[tokio::test(start_paused = true)]
async fn a_seek_stamped_for_a_skipped_tick_shows_where_it_would_be_by_now() {
    let e = engine(4);
    let b = create(&e, 10, 300);
    let mut a = viewer(&e, &b, Encoding::Json, false);
    for _ in 0..3 {
        frame(&mut a).await;
    }
    assert_eq!(b.control(Control::Seek(5.0)).map(|(seq, _)| seq), Ok(3));
    // The task wakes 350 ms late: ticks 3 and 4 are never produced.
    tokio::time::advance(Duration::from_millis(350)).await;
    let f = frame(&mut a).await;
    assert_eq!((f.seq, f.dropped), (5, 2));
    assert!((time(&f) - 5.2).abs() < 1e-9, "5 at tick 3, so 5.2 at tick 5: {}", time(&f));
    assert!((time(&frame(&mut a).await) - 5.3).abs() < 1e-9);
}

/// Controls of every kind a broadcast takes, stamped at `ticks`.
fn controls(params: &StreamParams, ticks: [u64; 7]) -> Vec<StampedControl> {
    let fade = Crossfade { to: Arc::clone(&params.motion), duration: 0.4, ease: anim::Ease::EaseInOut, source: None };
    let kinds = [
        Control::Seek(3.0),
        Control::Pause,
        Control::Play,
        Control::Speed(-0.5),
        Control::Layer { index: 0, weight: 0.3, duration: 0.2 },
        Control::Crossfade(fade),
        Control::Speed(2.0),
    ];
    ticks.into_iter().zip(kinds).map(|(seq, control)| StampedControl { seq, id: new_control_id(), control }).collect()
}

fn log_of(controls: &[StampedControl]) -> ControlLog {
    let mut log = ControlLog::default();
    for c in controls {
        log.insert(c.clone());
    }
    log
}

/// Tick `k`'s JSON frame (`sent_at` fixed, so equal frames are equal bytes).
fn bytes_at(p: &mut Program, k: u64, log: &ControlLog) -> bytes::Bytes {
    p.step_to(k, log);
    p.encode(Encoding::Json, 0).bytes
}

#[test]
fn frames_are_a_function_of_the_definition_the_controls_and_the_tick() {
    let params = StreamParams::new(pinned("c1", clip()), StreamRequest { fps: 10, ..Default::default() }).unwrap();
    let all = controls(&params, [5, 9, 12, 15, 18, 100, 130]);
    let full = log_of(&all);
    // The reference: every control known from the start, every tick stepped.
    let mut reference = Program::new(&params);
    let frames: Vec<_> = (0..200).map(|k| bytes_at(&mut reference, k, &full)).collect();
    assert_ne!(frames[4], frames[5], "the seek shows at its stamp");

    // A node that hears the controls late: stepped without them, then rewound.
    let mut late = Program::new(&params);
    let mut log = log_of(&all[..1]);
    for k in 0..140 {
        if k == 11 || k == 140 - 1 {
            // Hears the ones stamped 9 (before 11, a rewind to tick 0) ... and at 139 the ones stamped 100 and 130
            // (a rewind to the snapshot before 100).
            let heard = if k == 11 { &all[1..5] } else { &all[5..] };
            let earliest = heard.iter().map(|c| c.seq).min().unwrap();
            for c in heard {
                log.insert(c.clone());
            }
            let again = late.rewind_before(earliest).expect("after the start");
            assert!(again <= k - earliest + super::broadcast_program::SNAPSHOT_EVERY, "{again} ticks again");
        }
        let got = bytes_at(&mut late, k, &log);
        if k >= 11 && !(100..139).contains(&k) {
            assert_eq!(got, frames[k as usize], "tick {k} after the rewind");
        }
    }
    for k in 140..200 {
        assert_eq!(bytes_at(&mut late, k, &log), frames[k as usize], "tick {k}");
    }
    // A node that starts late: replays from tick 0.
    for k in [0u64, 63, 64, 101, 199] {
        let mut fresh = Program::replay(&params, &full, k.checked_sub(1));
        assert_eq!(bytes_at(&mut fresh, k, &full), frames[k as usize], "a late start at tick {k}");
    }
}

/// On the real clock: a copy places its ticks by the wall clock (`created_at`).
#[tokio::test]
async fn a_copy_adopted_from_the_stored_controls_sends_the_same_bytes() {
    let (e1, e2) = (engine(4), engine(4));
    let b1 = create(&e1, 10, 300);
    let mut v1 = viewer(&e1, &b1, Encoding::Json, false);
    for _ in 0..3 {
        frame(&mut v1).await;
    }
    let mut stamped = Vec::new();
    for control in [Control::Seek(2.0), Control::Speed(-1.5), Control::Layer { index: 0, weight: 0.5, duration: 0.3 }] {
        let (seq, control) = b1.prepare(control).unwrap();
        let c = StampedControl { seq, id: new_control_id(), control };
        b1.accept(c.clone());
        stamped.push(c);
        frame(&mut v1).await;
    }
    // Another node, later (three ticks on): the definition, `created_at` and the stored controls.
    for _ in 0..3 {
        frame(&mut v1).await;
    }
    let spec = b1.spec().clone();
    let b2 = e2
        .broadcasts()
        .adopt(b1.id(), spec, b1.created_at_unix_nanos(), stamped.clone(), BroadcastCharge::free(), None)
        .unwrap();
    let mut v2 = viewer(&e2, &b2, Encoding::Json, false);
    let strip = |f: &Delivered| {
        let mut v: serde_json::Value = serde_json::from_slice(&f.bytes).unwrap();
        v.as_object_mut().unwrap().remove("sent_at_unix_nanos");
        v
    };
    let mut seen = std::collections::BTreeMap::new();
    for _ in 0..10 {
        let f = frame(&mut v1).await;
        seen.insert(f.seq, strip(&f));
    }
    let mut shared = 0;
    for _ in 0..8 {
        let f = frame(&mut v2).await;
        if let Some(other) = seen.get(&f.seq) {
            assert_eq!(&strip(&f), other, "seq {}", f.seq);
            shared += 1;
        }
    }
    assert!(shared >= 5, "{shared} frames compared");
    // Heard twice (NOTIFY and a resync): taken once.
    b2.heard(stamped[0].clone());
    assert_eq!(b2.control_ids().len(), 3);
}

#[tokio::test(start_paused = true)]
async fn a_withdrawn_control_leaves_the_frames_as_without_it() {
    let e = engine(4);
    let b = create(&e, 10, 300);
    let mut v = viewer(&e, &b, Encoding::Json, false);
    frame(&mut v).await;
    // Withdrawn before its tick: never shown.
    let (seq, seek) = b.prepare(Control::Seek(7.0)).unwrap();
    let id = new_control_id();
    b.accept(StampedControl { seq, id: Arc::clone(&id), control: seek });
    b.revoke(&id);
    // Withdrawn after its tick: the frames after the withdrawal are as if it had never been.
    let (late, pause) = b.prepare(Control::Pause).unwrap();
    let id = new_control_id();
    b.accept(StampedControl { seq: late, id: Arc::clone(&id), control: pause });
    let mut times = Vec::new();
    for _ in 0..3 {
        times.push((time(&frame(&mut v).await) * 1e9).round() / 1e9);
    }
    b.revoke(&id);
    for _ in 0..3 {
        times.push((time(&frame(&mut v).await) * 1e9).round() / 1e9);
    }
    assert_eq!((seq, late), (1, 1));
    assert_eq!(times, [0.0, 0.0, 0.0, 0.4, 0.5, 0.6], "paused from tick 1, then playing as if never paused");
}

/// Issue 19: a broadcast's tick never waits behind the viewers it wakes.
/// With the precise timer (the server's) its task runs on the producers'
/// thread, so while both workers of the runtime that created it are busy,
/// it still produces every tick: a viewer reading on another thread gets
/// each one in turn, none dropped. (On the workers, it produced nothing
/// while they were busy and then skipped to the latest tick.)
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broadcast_produces_every_tick_while_the_workers_are_busy() {
    let config = EngineConfig { precise_timer: true, buffer: 64, max_broadcasts: 4, ..Default::default() };
    let e = Engine::new(config);
    let b = create(&e, 100, 300);
    let mut sub = viewer(&e, &b, Encoding::Json, false);
    let (started, ticking) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        rt.block_on(async move {
            let mut frames = Vec::new();
            for i in 0..50 {
                frames.push(frame(&mut sub).await);
                if i == 5 {
                    started.send(()).unwrap();
                }
            }
            frames
        })
    });
    ticking.recv().unwrap();
    // Then both workers held (not yielding) for 300 ms, i.e. 30 ticks: the
    // barrier makes the two hogs run on the two workers at once.
    let both = Arc::new(std::sync::Barrier::new(2));
    let hogs: Vec<_> = (0..2)
        .map(|_| {
            let both = Arc::clone(&both);
            tokio::spawn(async move {
                both.wait();
                // The time is the behaviour here: a worker held without yielding.
                std::thread::sleep(Duration::from_millis(300));
            })
        })
        .collect();
    for hog in hogs {
        hog.await.unwrap();
    }
    let frames = reader.join().unwrap();
    let first = frames[0].seq;
    let seqs: Vec<(u64, u64)> = frames.iter().map(|f| (f.seq, f.dropped)).collect();
    if std::env::var("INBETWEEN_SLOW").is_ok_and(|v| v == "1") {
        let every: Vec<(u64, u64)> = (first..first + 50).map(|seq| (seq, 0)).collect();
        assert_eq!(seqs, every, "every tick, in turn, none dropped");
        return;
    }
    // On a loaded machine the producers' thread itself may miss a tick or two;
    // on the workers it missed all 30 of the hogged ones.
    let dropped: u64 = frames.iter().map(|f| f.dropped).sum();
    for pair in frames.windows(2) {
        assert_eq!(pair[1].seq, pair[0].seq + 1 + pair[1].dropped, "a gap is what was dropped: {seqs:?}");
    }
    assert!(dropped < 10, "the hogged ticks were produced: {dropped} dropped in {seqs:?}");
}
