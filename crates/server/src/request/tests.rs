//! The request rules on their own: each input, its code, class and place.

use super::raw::*;
use super::stream::DEFAULT_FPS;
use super::*;
use crate::error::{ApiError, At};
use crate::stream::Encoding;
use anim::{Ease, Playback, Space};

/// (HTTP status, code, where) of a refusal.
fn refusal(e: ApiError) -> (u16, &'static str, At) {
    let status = e.status().as_u16();
    match e {
        ApiError::BadParameter { code, at, .. } | ApiError::Invalid { code, at, .. } => (status, code, at),
        other => panic!("not a request refusal: {other:?}"),
    }
}

fn param(name: &str) -> At {
    At::Parameter(name.to_owned())
}

fn pointer(p: &str) -> At {
    At::Pointer(p.to_owned())
}

fn pose(t: Option<Raw<'static>>) -> RawPose<'static> {
    RawPose { t, modes: RawModes::default(), format: None, at: in_query }
}

#[test]
fn a_pose_needs_a_finite_time_and_known_names() {
    let ok = pose(Some(Raw::Text("1.5"))).check().unwrap();
    assert_eq!((ok.t, ok.format, ok.options.space, ok.options.ease), (1.5, Format::Trs, Space::Local, Ease::Linear));
    assert_eq!(ok.options.playback, None, "absent playback is the clip's own");
    assert_eq!(refusal(pose(None).check().unwrap_err()), (400, "missing_parameter", param("t")));
    for bad in [Raw::Text("abc"), Raw::Text("NaN"), Raw::Text("1e400"), Raw::Number(f64::INFINITY)] {
        assert_eq!(refusal(pose(Some(bad)).check().unwrap_err()), (400, "bad_number", param("t")), "{bad:?}");
    }
    let mut named = pose(Some(Raw::Number(0.0)));
    named.modes.playback = Some(Raw::Text("ping_pong"));
    named.modes.space = Some(Raw::Enum(2));
    named.format = Some(Raw::Text("skinning"));
    let ok = named.check().unwrap();
    assert_eq!(
        (ok.options.playback, ok.options.space, ok.format),
        (Some(Playback::PingPong), Space::Model, Format::Skinning)
    );
    named.modes.space = Some(Raw::Enum(7));
    assert_eq!(refusal(named.check().unwrap_err()), (400, "bad_parameter", param("space")));
    named.modes.space = None;
    named.format = Some(Raw::Text("euler"));
    assert_eq!(refusal(named.check().unwrap_err()), (400, "bad_parameter", param("format")));
}

#[test]
fn protobuf_zero_is_the_default_of_every_enum() {
    let raw = RawPose {
        t: Some(Raw::Number(0.0)),
        modes: RawModes { space: Some(Raw::Enum(0)), playback: Some(Raw::Enum(0)), ease: Some(Raw::Enum(0)) },
        format: Some(Raw::Enum(0)),
        at: in_body,
    };
    let ok = raw.check().unwrap();
    assert_eq!(
        (ok.options.playback, ok.options.ease, ok.options.space, ok.format),
        (None, Ease::Linear, Space::Local, Format::Trs)
    );
}

fn batch(times: Option<&'static [f64]>, range: Option<(f64, f64, f64)>) -> RawBatch<'static> {
    RawBatch {
        times,
        start: range.map(|r| r.0),
        end: range.map(|r| r.1),
        fps: range.map(|r| r.2),
        modes: RawModes::default(),
        format: None,
        at: in_body,
    }
}

#[test]
fn a_batch_is_times_or_a_range_within_the_limits() {
    let ok = batch(None, Some((0.0, 1.0, 4.0))).check(100).unwrap();
    assert_eq!(ok.times, [0.0, 0.25, 0.5, 0.75, 1.0], "end inclusive on the grid");
    assert_eq!(batch(Some(&[0.5, 2.0]), None).check(2).unwrap().times, [0.5, 2.0]);
    let refused = |b: RawBatch<'static>| refusal(b.check(10).unwrap_err());
    assert_eq!(refused(batch(None, None)), (422, "times_or_range", pointer("")));
    let mut both = batch(Some(&[0.0]), Some((0.0, 1.0, 30.0)));
    assert_eq!(refused(both), (422, "times_or_range", pointer("")));
    both.fps = None;
    assert_eq!(refused(both), (422, "times_or_range", pointer("")), "times with part of a range");
    for fps in [0.0, 0.5, 240.5, 241.0, -30.0] {
        assert_eq!(refused(batch(None, Some((0.0, 1.0, fps)))), (422, "fps_out_of_range", pointer("/fps")), "{fps}");
    }
    assert_eq!(refused(batch(None, Some((2.0, 1.0, 30.0)))), (422, "bad_range", pointer("/end")));
    assert_eq!(refused(batch(Some(&[0.0; 11]), None)), (422, "too_many_poses", pointer("/times")));
    // 0..=1 s at 10 fps is 11 frames, one over.
    assert_eq!(refused(batch(None, Some((0.0, 1.0, 10.0)))), (422, "too_many_poses", pointer("")));
    assert_eq!(refused(batch(Some(&[0.0, f64::NAN]), None)), (400, "bad_number", pointer("/times/1")));
    assert_eq!(refused(batch(None, Some((f64::NAN, 1.0, 30.0)))), (400, "bad_number", pointer("/start")));
}

fn stream(fps: Option<Raw<'static>>) -> RawStream<'static> {
    RawStream {
        fps,
        start: None,
        speed: None,
        modes: RawModes::default(),
        encoding: None,
        max_error: None,
        distance: None,
        max_frames: None,
        paused: false,
        springs: true,
        joints: None,
        parameters: None,
        at: in_query,
    }
}

#[test]
fn a_stream_request_decodes_with_its_defaults() {
    let req = stream(None).check().unwrap();
    assert_eq!(
        (req.fps, req.start, req.speed, req.encoding, req.max_frames),
        (DEFAULT_FPS, None, None, Encoding::Json, 0)
    );
    let mut raw = stream(Some(Raw::Text("60")));
    raw.encoding = Some(Raw::Text("protobuf"));
    raw.max_frames = Some(Raw::Text("5"));
    raw.speed = Some(Raw::Text("-2"));
    let req = raw.check().unwrap();
    assert_eq!((req.fps, req.speed, req.encoding, req.max_frames), (60, Some(-2.0), Encoding::Protobuf, 5));
}

#[test]
fn a_stream_refuses_what_does_not_parse_and_a_zero_frame_limit() {
    let refused = |raw: RawStream<'static>| refusal(raw.check().unwrap_err());
    for fps in ["abc", "2.5", "NaN"] {
        assert_eq!(refused(stream(Some(Raw::Text(fps)))), (400, "bad_number", param("fps")), "{fps}");
    }
    let mut raw = stream(None);
    raw.speed = Some(Raw::Number(f64::NAN));
    assert_eq!(refused(raw), (400, "bad_number", param("speed")));
    raw.speed = None;
    raw.encoding = Some(Raw::Text("xml"));
    assert_eq!(refused(raw), (400, "bad_parameter", param("encoding")));
    raw.encoding = None;
    raw.max_frames = Some(Raw::Text("0"));
    assert_eq!(refused(raw), (422, "max_frames_out_of_range", param("max_frames")));
    // Out-of-range rates decode; the engine's rule refuses them (see `open`).
    assert_eq!(stream(Some(Raw::Text("-1"))).check().unwrap().fps, 0);
    assert_eq!(stream(Some(Raw::Text("1e30"))).check().unwrap().fps, u32::MAX);
}
