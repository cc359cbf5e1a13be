//! Broadcast tests on a paused tokio clock (SPEC §9): viewers of one
//! encoding share the very bytes of each tick (one encoding, observed as
//! one allocation), late joiners start at the next tick with `dropped` 0,
//! controls apply from the tick they were stamped with, read-only viewers
//! cannot control, and broadcasts end when deleted or idle.

use std::sync::Arc;
use std::time::Duration;

use super::tests::{clip, pinned};
use super::*;

fn engine(max_broadcasts: usize) -> Engine {
    Engine::new(EngineConfig { max_streams: 100, max_streams_per_client: 100, max_broadcasts, ..Default::default() })
}

fn create(e: &Engine, fps: u32, idle_secs: u64) -> Arc<Broadcast> {
    let params = StreamParams::new(pinned("c1", clip()), StreamRequest { fps, ..Default::default() }).unwrap();
    let spec =
        BroadcastSpec { params, idle_timeout: Duration::from_secs(idle_secs), description: serde_json::Value::Null };
    e.broadcasts().create(spec).unwrap()
}

fn viewer(e: &Engine, b: &Arc<Broadcast>, encoding: Encoding, controls: bool) -> Subscription {
    b.watch(encoding, e.admit(None).unwrap(), controls)
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
    assert_eq!(b.control(Control::Seek(5.0)), Ok(3));
    let mut times = Vec::new();
    for seq in 3..7 {
        let (fa, fc) = (frame(&mut a).await, frame(&mut c).await);
        assert_eq!((fa.seq, fc.seq), (seq, seq));
        assert_eq!(fa.bytes, fc.bytes);
        times.push((time(&fa) * 1e9).round() / 1e9);
        if seq == 4 {
            // Sent by the controlling viewer (its sink is the broadcast): stamped 5.
            c.control(Control::Pause).unwrap();
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
    assert_eq!(reader.control(Control::Pause), Err(ControlError::ReadOnly));
    assert_eq!(b.control(Control::Stop).unwrap_err().code(), "bad_control");
    assert_eq!(b.control(Control::Speed(5000.0)).unwrap_err().code(), "bad_control");
    writer.control(Control::Stop).unwrap();
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
    let spec = BroadcastSpec { params, idle_timeout: Duration::from_secs(1), description: serde_json::Value::Null };
    assert_eq!(e.broadcasts().create(spec).unwrap_err(), BroadcastError::TooMany { limit: 2 });

    let mut v = viewer(&e, &kept, Encoding::Protobuf, false);
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
    assert_eq!(b.control(Control::Seek(5.0)), Ok(3));
    // The task wakes 350 ms late: ticks 3 and 4 are never produced.
    tokio::time::advance(Duration::from_millis(350)).await;
    let f = frame(&mut a).await;
    assert_eq!((f.seq, f.dropped), (5, 2));
    assert!((time(&f) - 5.2).abs() < 1e-9, "5 at tick 3, so 5.2 at tick 5: {}", time(&f));
    assert!((time(&frame(&mut a).await) - 5.3).abs() < 1e-9);
}
