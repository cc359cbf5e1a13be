//! The unary RPCs against the same server's REST answers, and the gRPC
//! plumbing: status codes, the write token, health and reflection.

use formats::wire::proto::pb;
use serde_json::Value;
use tonic::Code;

use super::{TestApp, WAVE};

/// The REST pose's joints as flat arrays (translations, rotations, scales).
fn rest_flat(pose: &Value) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<String>) {
    let (mut t, mut r, mut s, mut names) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for j in pose["joints"].as_array().unwrap() {
        let nums = |k: &str| j[k].as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect::<Vec<_>>();
        t.extend(nums("translation"));
        r.extend(nums("rotation"));
        s.extend(nums("scale"));
        names.push(j["name"].as_str().unwrap().to_owned());
    }
    (t, r, s, names)
}

#[tokio::test]
async fn sample_and_sample_batch_equal_the_rest_poses() {
    let app = TestApp::start().await;
    let id = app.create_id(WAVE, None).await;
    let mut grpc = app.grpc().await;
    for (space, space_pb) in [("local", pb::Space::Local), ("model", pb::Space::Model)] {
        let times = [0.0, 0.4, 1.25, 2.999, 4.5];
        let rest: Value = app
            .post_json(&format!("/v1/clips/{id}/sample"), &serde_json::json!({"times": times, "space": space}))
            .await;
        let batch = grpc
            .sample_batch(pb::SampleBatchRequest {
                clip_id: id.clone(),
                when: Some(pb::sample_batch_request::When::Times(pb::Times { values: times.to_vec() })),
                space: space_pb as i32,
                ..Default::default()
            })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(batch.joint_names, ["root", "arm"]);
        assert_eq!(batch.poses.len(), times.len());
        for (k, &t) in times.iter().enumerate() {
            let one = app.get_json(&format!("/v1/clips/{id}/pose?t={t}&space={space}")).await;
            let unary = grpc
                .sample(pb::SampleRequest {
                    clip_id: id.clone(),
                    time: t,
                    space: space_pb as i32,
                    ..Default::default()
                })
                .await
                .unwrap()
                .into_inner();
            let (tr, ro, sc, names) = rest_flat(&one);
            assert_eq!(unary.joint_names, names, "names in the unary reply");
            assert_eq!((&unary.translations, &unary.rotations, &unary.scales), (&tr, &ro, &sc), "{space} t={t}");
            assert_eq!(unary.clip_time, one["clip_time"].as_f64().unwrap() as f32);
            let b = &batch.poses[k];
            assert!(b.joint_names.is_empty(), "names once per batch");
            assert_eq!((&b.translations, &b.rotations, &b.scales), (&tr, &ro, &sc), "batch {space} t={t}");
            let (tr2, ..) = rest_flat(&rest["poses"][k]);
            assert_eq!(tr2, tr);
        }
    }
    // A frame range gives start + k/fps up to and including end.
    let range = grpc
        .sample_batch(pb::SampleBatchRequest {
            clip_id: id.clone(),
            when: Some(pb::sample_batch_request::When::Range(pb::FrameRange { start: 0.0, end: 1.0, fps: 4.0 })),
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let times: Vec<f64> = range.poses.iter().map(|p| p.time).collect();
    assert_eq!(times, [0.0, 0.25, 0.5, 0.75, 1.0]);
    // Matrices: 16 floats per joint, and the model matrix of the root holds
    // its translation in the last column.
    let m = grpc
        .sample(pb::SampleRequest { clip_id: id, time: 1.0, format: pb::Format::Matrix as i32, ..Default::default() })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(m.matrices.len(), 32);
    assert!(m.translations.is_empty());
    assert_eq!(&m.matrices[12..15], &[1.0, 0.0, 0.0], "root at [1, 0, 0] at t = 1 (a key)");
}

#[tokio::test]
async fn errors_map_to_grpc_status_codes() {
    let app = TestApp::builder().write_token("s3cret").start().await;
    let id = app.create_id(WAVE, Some("s3cret")).await;
    let mut grpc = app.grpc().await;
    let code = |r: Result<tonic::Response<pb::Pose>, tonic::Status>| r.unwrap_err().code();

    let missing = "01234567-89ab-7def-8123-456789abcdef".to_owned();
    assert_eq!(
        code(grpc.sample(pb::SampleRequest { clip_id: missing.clone(), ..Default::default() }).await),
        Code::NotFound
    );
    assert_eq!(
        code(grpc.sample(pb::SampleRequest { clip_id: "nope".into(), ..Default::default() }).await),
        Code::NotFound
    );
    let nan = pb::SampleRequest { clip_id: id.clone(), time: f64::NAN, ..Default::default() };
    assert_eq!(code(grpc.sample(nan).await), Code::InvalidArgument);
    let bad_enum = pb::SampleRequest { clip_id: id.clone(), space: 7, ..Default::default() };
    assert_eq!(code(grpc.sample(bad_enum).await), Code::InvalidArgument);

    // Writes need the token in the `authorization` metadata.
    let clip = Some(formats::wire::proto::clip_to_pb(&formats::wire::json::parse_clip(WAVE.as_bytes()).unwrap().1));
    let put = pb::PutClipRequest { clip: clip.clone(), ..Default::default() };
    let err = grpc.put_clip(put.clone()).await.unwrap_err();
    assert_eq!(err.code(), Code::Unauthenticated);
    let mut req = tonic::Request::new(put.clone());
    req.metadata_mut().insert("authorization", "Bearer wrong".parse().unwrap());
    assert_eq!(grpc.put_clip(req).await.unwrap_err().code(), Code::Unauthenticated);
    fn authed<T>(msg: T) -> tonic::Request<T> {
        let mut req = tonic::Request::new(msg);
        req.metadata_mut().insert("authorization", "Bearer s3cret".parse().unwrap());
        req
    }
    // Names identify clips: the wave uploaded above holds its name (ALREADY_EXISTS, as REST's 409).
    let taken = grpc.put_clip(authed(put)).await.unwrap_err();
    assert_eq!(
        (taken.code(), taken.metadata().get("x-error-code").unwrap().to_str().unwrap()),
        (Code::AlreadyExists, "name_taken")
    );
    assert!(taken.message().contains("(at /name)"), "{}", taken.message());
    let mut clip = clip;
    clip.as_mut().unwrap().name = "wave over grpc".into();
    let put = pb::PutClipRequest { clip: clip.clone(), ..Default::default() };
    let created = grpc.put_clip(authed(put)).await.unwrap().into_inner();
    assert_eq!((created.version, created.joints, created.tracks, created.end), (1, 2, 2, 3.0));

    // A clip that breaks a rule: INVALID_ARGUMENT naming the field.
    let mut broken = clip.clone().unwrap();
    broken.tracks[0].times = vec![0.0, 2.0, 1.0, 3.0];
    let err = grpc.put_clip(authed(pb::PutClipRequest { clip: Some(broken), ..Default::default() })).await.unwrap_err();
    assert_eq!(err.code(), Code::InvalidArgument);
    assert!(err.message().contains("/tracks/0/times"), "{}", err.message());
    assert_eq!(err.metadata().get("x-error-code").unwrap(), "times_not_increasing");

    // Replace with a stale version: FAILED_PRECONDITION.
    let stale = pb::PutClipRequest {
        clip_id: created.id.clone(),
        clip: clip.clone(),
        if_version: Some(7),
        ..Default::default()
    };
    assert_eq!(grpc.put_clip(authed(stale)).await.unwrap_err().code(), Code::FailedPrecondition);
    let replace = pb::PutClipRequest { clip_id: created.id.clone(), clip, if_version: Some(1), ..Default::default() };
    assert_eq!(grpc.put_clip(authed(replace)).await.unwrap().into_inner().version, 2);

    // Get, list, delete.
    let record = grpc.get_clip(pb::GetClipRequest { clip_id: created.id.clone() }).await.unwrap().into_inner();
    assert_eq!(record.summary.unwrap().version, 2);
    assert_eq!(record.clip.unwrap().tracks.len(), 2);
    let list = grpc.list_clips(pb::ListClipsRequest { limit: 1, ..Default::default() }).await.unwrap().into_inner();
    assert_eq!(list.clips.len(), 1);
    let rest = grpc
        .list_clips(pb::ListClipsRequest { limit: 1, cursor: list.next_cursor, ..Default::default() })
        .await
        .unwrap()
        .into_inner();
    assert_eq!((rest.clips.len(), rest.next_cursor.as_str()), (1, ""));
    let del = pb::DeleteClipRequest { clip_id: created.id.clone() };
    assert_eq!(grpc.delete_clip(del.clone()).await.unwrap_err().code(), Code::Unauthenticated);
    grpc.delete_clip(authed(del)).await.unwrap();
    let gone = pb::SampleRequest { clip_id: created.id, ..Default::default() };
    assert_eq!(code(grpc.sample(gone).await), Code::NotFound);
}

#[tokio::test]
async fn ping_returns_the_server_clocks() {
    let app = TestApp::start().await;
    let mut grpc = app.grpc().await;
    let before = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos() as i64;
    let a = grpc.ping(pb::PingRequest {}).await.unwrap().into_inner();
    let b = grpc.ping(pb::PingRequest {}).await.unwrap().into_inner();
    let after = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos() as i64;
    assert!(before <= a.server_unix_nanos && a.server_unix_nanos <= after);
    assert!(b.server_monotonic_nanos >= a.server_monotonic_nanos);
}

#[tokio::test]
async fn health_reports_serving_and_reflection_lists_the_service() {
    use tonic_health::pb::health_check_response::ServingStatus;
    use tonic_health::pb::{HealthCheckRequest, health_client::HealthClient};
    let app = TestApp::start().await;
    let channel = app.channel().await;
    let mut health = HealthClient::new(channel.clone());
    let check = |service: &str| HealthCheckRequest { service: service.to_owned() };
    for service in ["", "inbetween.v1.Animation"] {
        let status = health.check(check(service)).await.unwrap().into_inner().status;
        assert_eq!(status, ServingStatus::Serving as i32, "{service:?}");
    }

    {
        use tonic_reflection::pb::v1::ServerReflectionRequest;
        use tonic_reflection::pb::v1::server_reflection_client::ServerReflectionClient;
        use tonic_reflection::pb::v1::server_reflection_request::MessageRequest;
        use tonic_reflection::pb::v1::server_reflection_response::MessageResponse;
        let mut client = ServerReflectionClient::new(channel.clone());
        let req = ServerReflectionRequest {
            host: String::new(),
            message_request: Some(MessageRequest::ListServices(String::new())),
        };
        let mut replies = client.server_reflection_info(tokio_stream::iter([req])).await.unwrap().into_inner();
        let reply = replies.message().await.unwrap().unwrap();
        let Some(MessageResponse::ListServicesResponse(list)) = reply.message_response else { panic!("{reply:?}") };
        let names: Vec<String> = list.service.into_iter().map(|s| s.name).collect();
        assert!(names.contains(&"inbetween.v1.Animation".to_owned()), "{names:?}");
        assert!(names.contains(&"grpc.health.v1.Health".to_owned()), "{names:?}");
    }
    {
        // The older v1alpha protocol, spoken by grpcurl and Python grpcio-reflection.
        use tonic_reflection::pb::v1alpha::ServerReflectionRequest;
        use tonic_reflection::pb::v1alpha::server_reflection_client::ServerReflectionClient;
        use tonic_reflection::pb::v1alpha::server_reflection_request::MessageRequest;
        use tonic_reflection::pb::v1alpha::server_reflection_response::MessageResponse;
        let mut client = ServerReflectionClient::new(channel);
        let req = ServerReflectionRequest {
            host: String::new(),
            message_request: Some(MessageRequest::FileContainingSymbol("inbetween.v1.Animation".into())),
        };
        let mut replies = client.server_reflection_info(tokio_stream::iter([req])).await.unwrap().into_inner();
        let reply = replies.message().await.unwrap().unwrap();
        let Some(MessageResponse::FileDescriptorResponse(files)) = reply.message_response else { panic!("{reply:?}") };
        assert!(!files.file_descriptor_proto.is_empty());
    }
}
