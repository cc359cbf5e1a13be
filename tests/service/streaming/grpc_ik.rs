//! IK over gRPC (docs/ik.md) with a real tonic client: a clip whose two-bone
//! target is keyed, uploaded with `PutClip` and sampled; a request-time aim
//! in `SampleMotion`; a motion stream's constraints; the `Play` stream's
//! `ik` control; and the refusals with their codes and pointers.
//!
//! The skeleton is a leg under `hip` (thigh and shin 1 long, straight down
//! at rest) and a `head` above it. Every expected position is worked out
//! here: keyed targets by lerping the keys by hand, aims from the returned
//! model-space pose.

use formats::wire::proto::pb;
use glam::{Quat, Vec3};
use pb::ik_constraint::Kind;
use pb::playback_control::Op;
use tonic::Code;

use super::{TestApp, within};

fn v3([x, y, z]: [f32; 3]) -> pb::Vec3 {
    pb::Vec3 { x, y, z }
}

fn point(p: [f32; 3]) -> Option<pb::IkTarget> {
    Some(pb::IkTarget { target: Some(pb::ik_target::Target::Point(v3(p))) })
}

fn joint(name: &str, parent: Option<&str>, y: f32) -> pb::Joint {
    pb::Joint {
        name: name.into(),
        parent: parent.map(Into::into),
        rest: Some(pb::Transform { translation: vec![0.0, y, 0.0], ..Default::default() }),
        inverse_bind: Vec::new(),
    }
}

/// The leg and head, standing still over [0, 2] s, with `ik`.
fn leg(name: &str, ik: Vec<pb::IkConstraint>) -> pb::Clip {
    pb::Clip {
        name: name.into(),
        skeleton: Some(pb::Skeleton {
            joints: vec![
                joint("hip", None, 0.0),
                joint("knee", Some("hip"), -1.0),
                joint("foot", Some("knee"), -1.0),
                joint("head", Some("hip"), 1.0),
            ],
        }),
        tracks: vec![pb::Track {
            joint: "hip".into(),
            channel: pb::Channel::Translation as i32,
            interpolation: pb::Interpolation::Linear as i32,
            times: vec![0.0, 2.0],
            values: vec![0.0; 6],
            ..Default::default()
        }],
        ik,
        ..Default::default()
    }
}

fn two_bone(target: Option<pb::IkTarget>) -> pb::IkConstraint {
    pb::IkConstraint {
        kind: Some(Kind::TwoBone(pb::IkTwoBone {
            joints: vec!["hip".into(), "knee".into(), "foot".into()],
            target,
            pole: Some(v3([0.0, -1.0, 2.0])),
            weight: None,
        })),
    }
}

/// The keyed foot target: linear from `FROM` at 0 s to `TO` at 2 s.
const FROM: [f32; 3] = [0.5, -1.5, 0.0];
const TO: [f32; 3] = [0.0, -1.2, 0.5];

fn keyed_two_bone() -> pb::IkConstraint {
    let keys = pb::IkKeys {
        interpolation: pb::Interpolation::Linear as i32,
        times: vec![0.0, 2.0],
        values: [FROM, TO].concat(),
        ..Default::default()
    };
    two_bone(Some(pb::IkTarget { target: Some(pb::ik_target::Target::Keys(keys)) }))
}

async fn put(grpc: &mut Client, clip: pb::Clip) -> String {
    grpc.put_clip(pb::PutClipRequest { clip: Some(clip), ..Default::default() }).await.unwrap().into_inner().id
}

type Client = pb::animation_client::AnimationClient<tonic::transport::Channel>;

/// Joint `j`'s model-space position in a model-space pose.
fn position(pose: &pb::Pose, j: usize) -> Vec3 {
    Vec3::from_slice(&pose.translations[3 * j..3 * j + 3])
}

fn rotation(pose: &pb::Pose, j: usize) -> Quat {
    Quat::from_slice(&pose.rotations[4 * j..4 * j + 4])
}

fn assert_near(a: Vec3, b: Vec3, tol: f32, what: &str) {
    assert!(a.distance(b) <= tol, "{what}: {a} vs {b} (distance {})", a.distance(b));
}

fn assert_report(pose: &pb::Pose, reports: &[pb::IkKind], what: &str) {
    let kinds: Vec<i32> = pose.ik.iter().map(|r| r.kind).collect();
    assert_eq!(kinds, reports.iter().map(|k| *k as i32).collect::<Vec<_>>(), "{what}: the reports in order");
    for r in &pose.ik {
        assert!(r.converged && r.residual < 1e-4, "{what}: {r:?}");
    }
}

#[tokio::test]
async fn grpc_put_clip_with_keyed_ik_samples_the_foot_on_its_keyed_target() {
    let app = TestApp::start().await;
    let mut grpc = app.grpc().await;
    let clip = leg("keyed leg", vec![keyed_two_bone()]);
    let id = put(&mut grpc, clip.clone()).await;
    let lerp = |t: f32| Vec3::from(FROM).lerp(Vec3::from(TO), t / 2.0);
    for t in [0.0f32, 0.5, 1.0, 1.7, 2.0] {
        let request = pb::SampleRequest {
            clip_id: id.clone(),
            time: f64::from(t),
            space: pb::Space::Model as i32,
            ..Default::default()
        };
        let pose = grpc.sample(request).await.unwrap().into_inner();
        assert_near(position(&pose, 2), lerp(t), 1e-4, &format!("the foot at t = {t}"));
        assert_near(position(&pose, 0), Vec3::ZERO, 0.0, "the hip does not move");
        assert_report(&pose, &[pb::IkKind::TwoBone], &format!("t = {t}"));
        // REST reports the same solve.
        let rest = app.get_json(&format!("/v1/clips/{id}/pose?t={t}&space=model")).await;
        assert_eq!(rest["ik"][0]["kind"], "two_bone");
        let residual = rest["ik"][0]["residual"].as_f64().unwrap() as f32;
        assert_eq!(residual, pose.ik[0].residual, "t = {t}: REST and gRPC report the same residual");
    }
    // A batch carries reports in every pose.
    let times = pb::Times { values: vec![0.25, 1.25] };
    let batch = grpc
        .sample_batch(pb::SampleBatchRequest {
            clip_id: id.clone(),
            when: Some(pb::sample_batch_request::When::Times(times)),
            space: pb::Space::Model as i32,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    for (pose, t) in batch.poses.iter().zip([0.25f32, 1.25]) {
        assert_near(position(pose, 2), lerp(t), 1e-4, &format!("batch foot at t = {t}"));
        assert_report(pose, &[pb::IkKind::TwoBone], "batch");
    }
    // The stored clip gives its constraint back as it was put.
    let record = grpc.get_clip(pb::GetClipRequest { clip_id: id.clone() }).await.unwrap().into_inner();
    assert_eq!(record.clip.unwrap().ik, clip.ik);
    // The clip's JSON document has it too, keyed.
    let doc = app.get_json(&format!("/v1/clips/{id}")).await;
    assert_eq!(doc["ik"][0]["target"]["times"], serde_json::json!([0.0, 2.0]), "{doc}");
    assert_eq!(doc["ik"][0]["joints"], serde_json::json!(["hip", "knee", "foot"]), "{doc}");
    app.stop().await;
}

#[tokio::test]
async fn grpc_sample_motion_aims_the_head_and_refuses_unknown_joints() {
    let app = TestApp::start().await;
    let mut grpc = app.grpc().await;
    let id = put(&mut grpc, leg("plain leg", Vec::new())).await;
    let target = [1.0f32, 2.5, 2.0];
    let aim = pb::IkConstraint {
        kind: Some(Kind::Aim(pb::IkAim { joint: "head".into(), target: point(target), ..Default::default() })),
    };
    let layer = pb::Layer { clip_id: id.clone(), ..Default::default() };
    let motion = |ik| pb::Motion { layers: vec![layer.clone()], ik, ..Default::default() };
    let request = pb::SampleMotionRequest {
        motion: Some(motion(vec![aim])),
        time: 0.5,
        space: pb::Space::Model as i32,
        ..Default::default()
    };
    let pose = grpc.sample_motion(request.clone()).await.unwrap().into_inner();
    assert_eq!(pose.ik.len(), 1);
    let report = &pose.ik[0];
    assert_eq!(report.kind, pb::IkKind::Aim as i32);
    assert!(report.converged && report.residual < 1e-5, "{report:?}");
    // The head's forward axis (local +z), in model space, points at the target.
    let (head, turn) = (position(&pose, 3), rotation(&pose, 3));
    let forward = turn * Vec3::Z;
    let wanted = (Vec3::from(target) - head).normalize();
    assert!(forward.dot(wanted) > 0.0, "{forward} faces away from {wanted}");
    assert!(forward.cross(wanted).length() < 2e-5, "{forward} vs {wanted}");
    // The batch carries the report in each pose.
    let batch = grpc
        .sample_motion_batch(pb::SampleMotionBatchRequest {
            motion: request.motion.clone(),
            when: Some(pb::sample_motion_batch_request::When::Times(pb::Times { values: vec![0.0, 1.0] })),
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    assert!(batch.poses.iter().all(|p| p.ik.len() == 1 && p.ik[0].kind == pb::IkKind::Aim as i32));

    // Refusals: INVALID_ARGUMENT with the rule's code and the JSON pointer.
    let unknown = pb::IkConstraint {
        kind: Some(Kind::Aim(pb::IkAim { joint: "neck".into(), target: point(target), ..Default::default() })),
    };
    let keyed = keyed_two_bone();
    for (ik, code, pointer) in [
        (vec![two_bone(point(target)), unknown], "unknown_joint", "/motion/ik/1/joint"),
        (vec![keyed], "keys_not_allowed", "/motion/ik/0/target"),
        (vec![two_bone(None)], "missing_field", "/motion/ik/0/target"),
    ] {
        let bad = pb::SampleMotionRequest { motion: Some(motion(ik)), ..request.clone() };
        let status = grpc.sample_motion(bad).await.unwrap_err();
        assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
        assert_eq!(status.metadata().get("x-error-code").unwrap(), code, "{status:?}");
        assert!(status.message().contains(&format!("(at {pointer})")), "{pointer}: {}", status.message());
    }
    app.stop().await;
}

/// The next frame (bounded wait).
async fn next(frames: &mut tonic::Streaming<pb::Frame>) -> pb::Frame {
    within(5, "a frame", frames.message()).await.unwrap().expect("the stream ended")
}

fn unix_nanos() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos() as i64
}

/// Sends `ik` and returns the first frame produced after the control's
/// tick: frames until one stamped after the send (the tick that may or may
/// not have seen it), then the next one.
async fn control_and_wait(
    tx: &tokio::sync::mpsc::Sender<pb::PlaybackControl>,
    frames: &mut tonic::Streaming<pb::Frame>,
    constraints: Vec<pb::IkConstraint>,
) -> pb::Frame {
    let sent = unix_nanos();
    tx.send(pb::PlaybackControl { op: Some(Op::Ik(pb::IkControl { constraints })) }).await.unwrap();
    let mut frame = next(frames).await;
    while frame.sent_at_unix_nanos <= sent {
        frame = next(frames).await;
    }
    let tick = frame.seq;
    while frame.seq <= tick + 1 {
        frame = next(frames).await;
    }
    frame
}

#[tokio::test]
async fn grpc_play_ik_control_moves_the_foot_onto_each_new_target_and_refuses_unknown_joints() {
    let app = TestApp::start().await;
    let mut grpc = app.grpc().await;
    let id = put(&mut grpc, leg("plain leg", Vec::new())).await;
    let (tx, rx) = tokio::sync::mpsc::channel(8);
    let stream = pb::StreamRequest {
        clip_id: id.clone(),
        fps: 30,
        space: pb::Space::Model as i32,
        playback: pb::Playback::Loop as i32,
        ..Default::default()
    };
    tx.send(pb::PlaybackControl { op: Some(Op::Open(pb::Open { stream: Some(stream), paused: false })) })
        .await
        .unwrap();
    let mut frames = grpc.play(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    let first = next(&mut frames).await;
    let pose = first.pose.as_ref().unwrap();
    assert!(pose.ik.is_empty(), "no constraints yet");
    assert_near(position(pose, 2), Vec3::new(0.0, -2.0, 0.0), 1e-6, "the foot at rest");

    // A dragged target: each new one is reached within a frame of the control.
    for target in [[0.4f32, -1.5, 0.3], [-0.3, -1.1, 0.6], [0.0, -1.9, -0.2]] {
        let frame = control_and_wait(&tx, &mut frames, vec![two_bone(point(target))]).await;
        let pose = frame.pose.as_ref().unwrap();
        assert_near(position(pose, 2), Vec3::from(target), 1e-4, &format!("the foot at {target:?}"));
        assert_report(pose, &[pb::IkKind::TwoBone], "the stream's constraint");
        let again = next(&mut frames).await;
        assert_near(position(again.pose.as_ref().unwrap(), 2), Vec3::from(target), 1e-4, "and it stays there");
    }
    // An empty list removes the constraints: the foot falls back to rest.
    let frame = control_and_wait(&tx, &mut frames, Vec::new()).await;
    assert!(frame.pose.as_ref().unwrap().ik.is_empty());
    assert_near(position(frame.pose.as_ref().unwrap(), 2), Vec3::new(0.0, -2.0, 0.0), 1e-6, "back at rest");

    // An unknown joint ends the stream with INVALID_ARGUMENT and its pointer.
    let bad = pb::IkConstraint {
        kind: Some(Kind::TwoBone(pb::IkTwoBone {
            joints: vec!["hip".into(), "shin".into(), "foot".into()],
            target: point([0.0, -1.5, 0.0]),
            ..Default::default()
        })),
    };
    tx.send(pb::PlaybackControl { op: Some(Op::Ik(pb::IkControl { constraints: vec![bad] })) }).await.unwrap();
    let status = loop {
        match within(5, "the refusal", frames.message()).await {
            Ok(Some(_)) => {}
            Ok(None) => panic!("the stream ended OK"),
            Err(status) => break status,
        }
    };
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "unknown_joint", "{status:?}");
    assert!(status.message().contains("(at /constraints/0/joints/1)"), "{}", status.message());
    app.stop().await;
}

#[tokio::test]
async fn grpc_motion_streams_solve_their_constraints_and_refuse_keys_in_controls() {
    let app = TestApp::start().await;
    let mut grpc = app.grpc().await;
    let keyed = put(&mut grpc, leg("keyed leg", vec![keyed_two_bone()])).await;
    let plain = put(&mut grpc, leg("plain leg", Vec::new())).await;
    // `StreamRequest.motion.ik` after a clip's own keyed constraint: both
    // report, the request's last, and the request's wins the foot.
    let target = [0.3f32, -1.6, -0.4];
    let motion = pb::Motion {
        layers: vec![pb::Layer { clip_id: keyed.clone(), ..Default::default() }],
        ik: vec![two_bone(point(target))],
        ..Default::default()
    };
    let request = pb::StreamRequest {
        fps: 30,
        max_frames: 3,
        space: pb::Space::Model as i32,
        motion: Some(motion),
        ..Default::default()
    };
    let mut frames = grpc.stream_frames(request).await.unwrap().into_inner();
    for _ in 0..3 {
        let frame = next(&mut frames).await;
        let pose = frame.pose.as_ref().unwrap();
        assert_report(pose, &[pb::IkKind::TwoBone, pb::IkKind::TwoBone], "clip, then request");
        assert_near(position(pose, 2), Vec3::from(target), 1e-4, "the request's target");
    }
    // A motion stream with an unknown joint in its constraints is refused as it opens.
    let bad = pb::Motion {
        layers: vec![pb::Layer { clip_id: plain.clone(), ..Default::default() }],
        ik: vec![pb::IkConstraint {
            kind: Some(Kind::Chain(pb::IkChain {
                effectors: vec![pb::IkEffector { joint: "toe".into(), target: point(target), tip: None }],
                ..Default::default()
            })),
        }],
        ..Default::default()
    };
    let status =
        grpc.stream_frames(pb::StreamRequest { fps: 30, motion: Some(bad), ..Default::default() }).await.unwrap_err();
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "unknown_joint");
    assert!(status.message().contains("(at /motion/ik/0/effectors/0/joint)"), "{}", status.message());

    // A keyed target in a `Play` control is refused where it sits.
    let (tx, rx) = tokio::sync::mpsc::channel(8);
    let open = pb::StreamRequest { clip_id: plain, fps: 30, ..Default::default() };
    tx.send(pb::PlaybackControl { op: Some(Op::Open(pb::Open { stream: Some(open), paused: false })) }).await.unwrap();
    let mut frames = grpc.play(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    next(&mut frames).await;
    let control = pb::IkControl { constraints: vec![two_bone(point(target)), keyed_two_bone()] };
    tx.send(pb::PlaybackControl { op: Some(Op::Ik(control)) }).await.unwrap();
    let status = loop {
        match within(5, "the refusal", frames.message()).await {
            Ok(Some(_)) => {}
            Ok(None) => panic!("the stream ended OK"),
            Err(status) => break status,
        }
    };
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert_eq!(status.metadata().get("x-error-code").unwrap(), "keys_not_allowed");
    assert!(status.message().contains("(at /constraints/1/target)"), "{}", status.message());
    app.stop().await;
}
