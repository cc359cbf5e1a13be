//! Engine tests on a paused tokio clock: every frame arrives exactly at its
//! due instant, so counts and schedules are exact and no test sleeps.

use std::sync::Arc;
use std::time::Duration;

use glam::Vec3;
use prost::Message;
use tokio::time::{Instant, advance};

use super::*;
use anim::{Channel, Clip, ClipSpec, EventSpec, Interpolation, Keys, Playback, TrackSpec};
use formats::wire::proto::pb;

/// `root` moves along x with x = t over [0, 10] (so a pose's x is its clip
/// time); `tip` is a second joint; events at 1 and 2.5.
pub(super) fn clip() -> Arc<Clip> {
    let track = |joint: &str| {
        TrackSpec::new(
            joint,
            Channel::Translation,
            Interpolation::Linear,
            vec![0.0, 10.0],
            Keys::Vec3(vec![Vec3::ZERO, Vec3::new(10.0, 0.0, 0.0)]),
        )
    };
    let events = vec![EventSpec { time: 1.0, name: "one".into() }, EventSpec { time: 2.5, name: "two".into() }];
    let spec = ClipSpec {
        name: "line".into(),
        skeleton: None,
        tracks: vec![track("root"), track("tip")],
        events,
        playback: Playback::Loop,
        ..Default::default()
    };
    Arc::new(Clip::build(&spec).unwrap())
}

/// `clip` pinned as version 1 of `id`.
pub(super) fn pinned(id: &str, clip: Arc<Clip>) -> Arc<dyn PinnedClip> {
    Arc::new(Pinned::new(id, 1, clip))
}

fn engine(buffer: usize) -> Engine {
    Engine::new(EngineConfig { buffer, max_streams: 1000, max_streams_per_client: 1000, ..EngineConfig::default() })
}

fn req(fps: u32, encoding: Encoding) -> StreamRequest {
    StreamRequest { fps, encoding, ..Default::default() }
}

fn params(req: StreamRequest) -> StreamParams {
    StreamParams::new(pinned("c1", clip()), req).unwrap()
}

fn watch(e: &Engine, req: StreamRequest) -> Subscription {
    e.watch(params(req), e.admit(None).unwrap(), None)
}

fn play(e: &Engine, req: StreamRequest) -> Subscription {
    e.play(params(req), e.admit(None).unwrap(), None)
}

async fn frame(sub: &mut Subscription) -> Delivered {
    match sub.next().await {
        Next::Frame(f) => f,
        Next::End(r) => panic!("stream ended early: {r:?}"),
    }
}

fn json(f: &Delivered) -> serde_json::Value {
    serde_json::from_slice(&f.bytes).unwrap()
}

fn proto(f: &Delivered) -> pb::Frame {
    pb::Frame::decode(f.bytes.clone()).unwrap()
}

/// The instant frame `seq` of `sub` is due.
fn due(sub: &Subscription, seq: u64) -> Instant {
    sub.grid().at(sub.first_tick() + seq)
}

/// Now is `due`, give or take the timer wheel's 1 ms resolution (tokio
/// rounds sleeps up to the next millisecond; the error never accumulates
/// because every due instant is computed from its index).
#[track_caller]
fn assert_on_time(due: Instant) {
    let now = Instant::now();
    assert!(now >= due && now - due < Duration::from_millis(1), "{:?} late", now.saturating_duration_since(due));
}

fn close(a: f32, b: f64) -> bool {
    (f64::from(a) - b).abs() < 1e-5
}

#[tokio::test(start_paused = true)]
async fn sixty_fps_for_two_seconds_is_120_frames_on_schedule_with_contiguous_seq() {
    let e = engine(4);
    let mut sub = watch(&e, StreamRequest { speed: Some(0.5), ..req(60, Encoding::Json) });
    let t0 = due(&sub, 0);
    let mut n = 0u64;
    loop {
        let f = frame(&mut sub).await;
        if Instant::now() >= t0 + Duration::from_secs(2) {
            break;
        }
        assert_eq!((f.seq, f.dropped), (n, 0));
        assert_on_time(due(&sub, n));
        assert!(close(f.clip_time, n as f64 * 0.5 / 60.0), "frame {n}: clip time {}", f.clip_time);
        let v = json(&f);
        assert_eq!(v["seq"], n);
        assert!(close(v["pose"]["joints"][0]["translation"][0].as_f64().unwrap() as f32, n as f64 * 0.5 / 60.0));
        n += 1;
    }
    assert_eq!(n, 120);
}

#[tokio::test(start_paused = true)]
async fn max_frames_ends_the_stream_cleanly_after_that_many() {
    let e = engine(4);
    let mut sub = watch(&e, StreamRequest { max_frames: 5, ..req(30, Encoding::Json) });
    for k in 0..5 {
        assert_eq!(frame(&mut sub).await.seq, k);
    }
    assert_eq!(sub.next().await, Next::End(EndReason::MaxFrames));
}

#[tokio::test(start_paused = true)]
async fn a_late_playback_sends_the_current_frame_and_counts_the_skipped_ones() {
    let e = engine(4);
    let mut sub = watch(&e, req(60, Encoding::Protobuf));
    let f0 = frame(&mut sub).await;
    assert_eq!(f0.seq, 0);
    // The runtime is stuck for 100 ms (six periods): ticks 1..=6 fall due.
    advance(Duration::from_millis(100)).await;
    let f = frame(&mut sub).await;
    assert_eq!((f.seq, f.dropped), (6, 5));
    assert_eq!(proto(&f).dropped, 5);
    assert!(close(f.clip_time, 6.0 / 60.0), "the current frame, not a stale one");
    // No burst: the next frame waits for its own instant.
    let at = Instant::now();
    let f = frame(&mut sub).await;
    assert_eq!((f.seq, f.dropped), (7, 0));
    assert!(Instant::now() > at);
}

#[tokio::test(start_paused = true)]
async fn a_stalled_viewer_drops_its_oldest_frames_and_never_delays_the_others() {
    let e = engine(4);
    let mut steady = watch(&e, req(60, Encoding::Json));
    let mut other = watch(&e, StreamRequest { speed: Some(2.0), ..req(60, Encoding::Json) });
    let mut stalled = watch(&e, req(60, Encoding::Json)); // shares `steady`'s playback
    assert_eq!(due(&stalled, 0), due(&steady, 0), "one playback, one grid");
    assert_eq!(frame(&mut stalled).await.seq, 0);
    // `stalled` reads nothing for two seconds while the others read, each
    // frame at its due instant (`other` may sit on another phase).
    for k in 0..120 {
        let mut pair = [&mut steady, &mut other];
        pair.sort_by_key(|s| due(s, k));
        for sub in pair {
            let at = due(sub, k);
            let f = frame(sub).await;
            assert_eq!((f.seq, f.dropped), (k, 0));
            assert_on_time(at); // no lateness for the other viewers
        }
    }
    // It resumes with the oldest frame its 4-frame buffer still holds.
    let f = frame(&mut stalled).await;
    assert_eq!(f.seq, 119 - 3);
    assert_eq!(f.dropped, 115);
    assert_eq!(json(&f)["dropped"], 115);
    let rest: Vec<u64> = [frame(&mut stalled).await, frame(&mut stalled).await].iter().map(|f| f.dropped).collect();
    assert_eq!(rest, [0, 0]);
}

#[tokio::test(start_paused = true)]
async fn viewers_of_the_same_playback_share_one_evaluation_and_encoding() {
    let e = engine(4);
    let mut subs: Vec<Subscription> = (0..100).map(|_| watch(&e, req(30, Encoding::Protobuf))).collect();
    let mut private = watch(&e, StreamRequest { ease: anim::Ease::EaseIn, ..req(30, Encoding::Protobuf) });
    assert_eq!(e.pending_playbacks(), 2, "100 identical requests, one playback (plus the different one)");
    for _ in 0..3 {
        let frames: Vec<Delivered> = futures_util::future::join_all(subs.iter_mut().map(frame)).await;
        let ptr = frames[0].bytes.as_ptr();
        assert!(frames.iter().all(|f| f.bytes.as_ptr() == ptr && f.seq == frames[0].seq), "the same bytes");
        let p = frame(&mut private).await;
        assert_ne!(p.bytes.as_ptr(), ptr);
    }
    assert_eq!(e.pending_playbacks(), 0, "playbacks leave the registry at their first tick");
}

#[tokio::test(start_paused = true)]
async fn joint_names_travel_once_per_stream_even_for_a_viewer_that_missed_frame_zero() {
    let e = engine(2);
    let mut a = watch(&e, req(30, Encoding::Protobuf));
    let mut b = watch(&e, req(30, Encoding::Protobuf));
    let f0 = proto(&frame(&mut a).await);
    assert_eq!(f0.pose.unwrap().joint_names, ["root", "tip"]);
    let f1 = proto(&frame(&mut a).await);
    assert!(f1.pose.as_ref().unwrap().joint_names.is_empty());
    assert_eq!(f1.pose.unwrap().translations.len(), 6);
    for _ in 0..5 {
        frame(&mut a).await;
    }
    // `b` read nothing yet: its first frame is a late one, patched with names.
    let fb = frame(&mut b).await;
    assert!(fb.seq > 0);
    let pb_frame = proto(&fb);
    assert_eq!(pb_frame.pose.unwrap().joint_names, ["root", "tip"]);
    assert_eq!(pb_frame.dropped, fb.seq);
    assert!(proto(&frame(&mut b).await).pose.unwrap().joint_names.is_empty());
}

/// The clip times of `n` frames of `sub`, after applying `controls` (frame
/// index → control) just before that frame.
async fn clip_times(sub: &mut Subscription, n: u64, controls: &[(u64, Control)]) -> Vec<f64> {
    let mut out = Vec::new();
    for k in 0..n {
        for (_, c) in controls.iter().filter(|(at, _)| *at == k) {
            sub.control(c.clone()).await.unwrap();
        }
        let f = frame(sub).await;
        assert_eq!((f.seq, f.dropped), (k, 0));
        out.push((f64::from(f.clip_time) * 1e4).round() / 1e4);
    }
    out
}

#[tokio::test(start_paused = true)]
async fn play_controls_act_on_the_next_tick() {
    let e = engine(4);
    let mut sub = play(&e, StreamRequest { start: Some(1.0), ..req(10, Encoding::Json) });
    let controls = [(2, Control::Pause), (4, Control::Play), (5, Control::Seek(5.0)), (7, Control::Speed(-2.0))];
    let t = clip_times(&mut sub, 9, &controls).await;
    assert_eq!(t, [1.0, 1.1, 1.1, 1.1, 1.2, 5.0, 5.1, 4.9, 4.7]);
    sub.control(Control::Stop).await.unwrap();
    assert_eq!(sub.next().await, Next::End(EndReason::Stopped));
}

#[tokio::test(start_paused = true)]
async fn a_viewer_that_sends_a_control_forks_and_the_others_play_on() {
    let e = engine(4);
    let mut a = watch(&e, req(10, Encoding::Json));
    let mut b = watch(&e, req(10, Encoding::Json));
    let ta = clip_times(&mut a, 3, &[]).await;
    let tb = clip_times(&mut b, 3, &[]).await;
    assert_eq!(ta, tb);
    a.control(Control::Pause).await.unwrap();
    let (fa, fb) = (frame(&mut a).await, frame(&mut b).await);
    assert_eq!((fa.seq, fa.dropped, fb.seq), (3, 0, 3), "the fork continues the schedule");
    assert!(close(fa.clip_time, 0.2), "paused at the previous time: {}", fa.clip_time);
    assert!(close(fb.clip_time, 0.3));
    // Frames from the fork carry no names again (JSON has them per pose) and
    // keep seq contiguous.
    a.control(Control::Speed(3.0)).await.unwrap();
    a.control(Control::Play).await.unwrap();
    let fa = frame(&mut a).await;
    assert_eq!((fa.seq, fa.dropped), (4, 0));
    assert!(close(fa.clip_time, 0.5), "{}", fa.clip_time);
    a.control(Control::Stop).await.unwrap();
    assert_eq!(a.next().await, Next::End(EndReason::Stopped));
    assert!(close(frame(&mut b).await.clip_time, 0.4));
    b.control(Control::Stop).await.unwrap();
    assert_eq!(b.next().await, Next::End(EndReason::Stopped));
}

#[tokio::test(start_paused = true)]
async fn events_crossed_since_the_last_frame_are_delivered() {
    let e = engine(4);
    let mut sub = watch(&e, StreamRequest { speed: Some(4.0), ..req(4, Encoding::Protobuf) });
    // Clip time advances by 1 per frame: 0, 1 ("one"), 2, 3 ("two"), ...
    let names: Vec<Vec<String>> = {
        let mut out = Vec::new();
        for _ in 0..12 {
            out.push(proto(&frame(&mut sub).await).events.into_iter().map(|e| e.name).collect());
        }
        out
    };
    let expect = |k: usize| match k {
        1 | 11 => vec!["one".to_string()],
        3 => vec!["two".to_string()],
        _ => vec![],
    };
    for (k, got) in names.iter().enumerate() {
        assert_eq!(got, &expect(k), "frame {k}");
    }
}

#[tokio::test(start_paused = true)]
async fn shutdown_ends_every_stream_with_a_final_status_and_frees_the_slots() {
    let e = engine(4);
    let mut a = watch(&e, req(30, Encoding::Json));
    let mut b = play(&e, req(30, Encoding::Protobuf));
    frame(&mut a).await;
    frame(&mut b).await;
    e.shutdown();
    assert_eq!(a.next().await, Next::End(EndReason::Shutdown));
    assert_eq!(b.next().await, Next::End(EndReason::Shutdown));
    assert!(matches!(e.admit(None), Err(AdmitError::ShuttingDown)));
    assert!(!e.drained(Duration::from_millis(10)).await, "the subscriptions are still held");
    drop((a, b));
    assert!(e.drained(Duration::from_millis(10)).await);
}

#[tokio::test(start_paused = true)]
async fn a_playback_keeps_the_clip_version_it_started_on() {
    // The engine holds an `Arc` of the compiled clip: whatever the store
    // does afterwards, this stream's frames come from this clip.
    let e = engine(4);
    let c = clip();
    let weak = Arc::downgrade(&c);
    let sub =
        e.watch(StreamParams::new(pinned("c1", c), req(30, Encoding::Json)).unwrap(), e.admit(None).unwrap(), None);
    assert!(weak.upgrade().is_some(), "alive while streamed although the caller dropped it");
    drop(sub);
    // The playback notices at its next tick that nobody watches and ends (the
    // clock is paused: this sleep jumps to that tick and takes no wall time).
    tokio::time::sleep(Duration::from_millis(100)).await;
    assert!(weak.upgrade().is_none(), "released once the stream ends");
}

#[test]
fn stream_requests_are_validated() {
    let check = |r: StreamRequest| StreamParams::new(pinned("c", clip()), r).map(|_| ()).map_err(|e| e.field);
    assert_eq!(check(req(0, Encoding::Json)), Err("fps"));
    assert_eq!(check(req(241, Encoding::Json)), Err("fps"));
    assert_eq!(check(req(240, Encoding::Json)), Ok(()));
    assert_eq!(check(StreamRequest { speed: Some(f64::NAN), ..req(1, Encoding::Json) }), Err("speed"));
    assert_eq!(check(StreamRequest { speed: Some(-1000.0), ..req(1, Encoding::Json) }), Ok(()));
    assert_eq!(check(StreamRequest { start: Some(f64::INFINITY), ..req(1, Encoding::Json) }), Err("start"));
}

/// A one-layer motion of the test clip with root motion reported, looping.
fn root_motion_params(req: StreamRequest) -> StreamParams {
    use anim::motion::{LayerSpec, MotionSpec, RootMotionSpec};
    let spec = MotionSpec {
        layers: vec![LayerSpec::new(pinned("c1", clip()))],
        root_motion: Some(RootMotionSpec::default()),
        ..Default::default()
    };
    let motion = Arc::new(anim::Motion::build(spec).unwrap());
    StreamParams::of_motion(motion, "motion under test".into(), req).unwrap()
}

fn root_total_x(f: &Delivered) -> f64 {
    json(f)["pose"]["root_motion"]["total"]["translation"][0].as_f64().unwrap()
}

#[tokio::test(start_paused = true)]
async fn a_fork_carries_the_root_motion_total_on_across_loop_seams() {
    let e = engine(4);
    // 10 s loops at speed 4 and 2 fps: 2 units per frame, a seam every 5 frames.
    let req = StreamRequest { speed: Some(4.0), ..req(2, Encoding::Json) };
    let mut sub = e.watch(root_motion_params(req), e.admit(None).unwrap(), None);
    for k in 0..7 {
        let f = frame(&mut sub).await;
        assert!((root_total_x(&f) - 2.0 * k as f64).abs() < 1e-9, "frame {k}: {}", root_total_x(&f));
    }
    // A control forks a private playback from frame 6; the total goes on from 12.
    sub.control(Control::Speed(4.0)).await.unwrap();
    for k in 7..13 {
        let f = frame(&mut sub).await;
        assert_eq!(f.seq, k);
        assert!((root_total_x(&f) - 2.0 * k as f64).abs() < 1e-9, "frame {k}: {}", root_total_x(&f));
    }
}
