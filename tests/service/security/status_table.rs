//! REST statuses and gRPC codes agree for every error: each `ApiError`
//! variant's pair against the HTTP ↔ gRPC correspondence written out below
//! (google.rpc.Code's documented HTTP mapping, with this API's 412/413/415/422
//! choices), and real failing requests made on both protocols of one server.

use axum::response::IntoResponse;
use formats::import::ErrorClass;
use formats::wire::proto::pb;
use server::ApiError;
use server::error::At;
use server::stream::{AdmitError, BroadcastError};
use tonic::Code;

use super::{ADMIN, READER, TestApp, WAVE, WRITER, scoped_tokens, wave_pb, with_token};

/// The gRPC codes an HTTP status may pair with.
pub fn grpc_codes_for(status: u16) -> &'static [Code] {
    match status {
        // Malformed (400), unsupported media (415) and rule-breaking (422) input alike.
        400 | 415 | 422 => &[Code::InvalidArgument],
        401 => &[Code::Unauthenticated],
        403 => &[Code::PermissionDenied],
        404 => &[Code::NotFound],
        405 => &[Code::Unimplemented],
        412 => &[Code::FailedPrecondition],
        // A name another clip has (ALREADY_EXISTS), or one several share.
        409 => &[Code::AlreadyExists, Code::FailedPrecondition],
        413 | 429 => &[Code::ResourceExhausted],
        500 => &[Code::Internal],
        // Overloaded or stopping, or a request past its deadline.
        // Shed under overload (RESOURCE_EXHAUSTED, as the hardening issue allows) too.
        503 => &[Code::Unavailable, Code::DeadlineExceeded, Code::ResourceExhausted],
        // A body that did not arrive in time.
        408 => &[Code::DeadlineExceeded],
        _ => &[],
    }
}

/// One of each variant. The match in `variant_index` has no wildcard, so a
/// new variant does not compile until it has a row here.
fn one_of_each() -> Vec<ApiError> {
    vec![
        ApiError::MalformedJson { pointer: String::new(), detail: "x".into() },
        ApiError::invalid("times_not_increasing", "/tracks/0/times/1", "x"),
        ApiError::parameter("bad_time", "t", "x"),
        ApiError::Unauthorized,
        ApiError::Forbidden { needed: "write" },
        ApiError::NotFound { what: "clip" },
        ApiError::NotFound { what: "route" },
        ApiError::MethodNotAllowed,
        ApiError::PreconditionFailed { current: 3 },
        ApiError::PayloadTooLarge { limit: 10, setting: "max_body_bytes" },
        ApiError::UnsupportedMediaType { detail: "x".into() },
        ApiError::TooMany { code: "too_many_poses", pointer: "/times".into(), detail: "x".into() },
        ApiError::TooManyStreams(AdmitError::Global { limit: 1 }),
        ApiError::TooManyStreams(AdmitError::PerClient { limit: 1 }),
        ApiError::TooManyStreams(AdmitError::PerToken { limit: 1 }),
        ApiError::TooManyStreams(AdmitError::ShuttingDown),
        ApiError::TooManyBroadcasts(BroadcastError::TooMany { limit: 1 }),
        ApiError::TooManyBroadcasts(BroadcastError::ShuttingDown),
        ApiError::NotFound { what: "broadcast" },
        ApiError::Import { class: ErrorClass::Malformed, code: "bad_glb", pointer: None, detail: "x".into() },
        ApiError::Import { class: ErrorClass::TooLarge, code: "too_many_keys", pointer: None, detail: "x".into() },
        ApiError::Import { class: ErrorClass::Unprocessable, code: "no_animations", pointer: None, detail: "x".into() },
        ApiError::Import {
            class: ErrorClass::UnsupportedFormat,
            code: "fbx_not_supported",
            pointer: None,
            detail: "x".into(),
        },
        ApiError::NameConflict { code: "name_taken", pointer: "/name".into(), detail: "x".into() },
        ApiError::NameConflict { code: "ambiguous_name", pointer: "/name".into(), detail: "x".into() },
        ApiError::Timeout { secs: 30 },
        ApiError::BodyTimeout { secs: 10 },
        ApiError::Overloaded { retry_after: 1 },
        ApiError::RateLimited { retry_after: 1 },
        ApiError::AnswerTooLargeForUnary { bytes: 20, limit: 10, stream: "SampleStream" },
        ApiError::ClientInFlight { limit: 32, retry_after: 1 },
        ApiError::CallerWorkLimit { held: 10, units: 5, share: 12, retry_after: 1 },
        ApiError::WorkOverloaded { retry_after: 1 },
        ApiError::ClipNotFoundAt { at: At::Pointer("/motion/layers/1/clip".into()), detail: "x".into() },
        ApiError::CharacterNotFoundAt { at: At::Pointer("/motion/character".into()), detail: "x".into() },
        ApiError::GraphNotFoundAt { at: At::Pointer("/motion/layers/0/graph".into()), detail: "x".into() },
        ApiError::Unavailable(None),
        ApiError::WriteRace { attempts: 9, retry_after: 1 },
        ApiError::StoreQueueFull { limit: 64, retry_after: 1 },
        ApiError::Relayed { status: 429, code: "rate_limited", detail: "x".into() },
        ApiError::UploadTooSlow { received: 3, window_secs: 3, min_per_sec: 16384 },
        ApiError::internal(anyhow::anyhow!("disk on fire")),
    ]
}

fn variant_index(e: &ApiError) -> usize {
    match e {
        ApiError::MalformedJson { .. } => 0,
        ApiError::Invalid { .. } => 1,
        ApiError::BadParameter { .. } => 2,
        ApiError::Unauthorized => 3,
        ApiError::Forbidden { .. } => 4,
        ApiError::NotFound { .. } => 5,
        ApiError::MethodNotAllowed => 6,
        ApiError::PreconditionFailed { .. } => 7,
        ApiError::PayloadTooLarge { .. } => 8,
        ApiError::UnsupportedMediaType { .. } => 9,
        ApiError::TooMany { .. } => 10,
        ApiError::TooManyStreams(_) => 11,
        ApiError::Import { .. } => 12,
        ApiError::Timeout { .. } => 13,
        ApiError::Unavailable(_) => 14,
        ApiError::Internal(_) => 15,
        ApiError::BodyTimeout { .. } => 16,
        ApiError::Overloaded { .. } => 17,
        ApiError::RateLimited { .. } => 18,
        ApiError::AnswerTooLargeForUnary { .. } => 19,
        ApiError::ClientInFlight { .. } => 20,
        ApiError::ClipNotFoundAt { .. } => 21,
        ApiError::TooManyBroadcasts(_) => 22,
        ApiError::WriteRace { .. } => 23,
        ApiError::UploadTooSlow { .. } => 24,
        ApiError::CallerWorkLimit { .. } => 25,
        ApiError::WorkOverloaded { .. } => 26,
        ApiError::StoreQueueFull { .. } => 27,
        ApiError::Relayed { .. } => 28,
        ApiError::NameConflict { .. } => 29,
        ApiError::CharacterNotFoundAt { .. } => 30,
        ApiError::GraphNotFoundAt { .. } => 31,
    }
}

#[tokio::test]
async fn every_variant_pairs_its_status_with_the_matching_grpc_code() {
    let errors = one_of_each();
    let covered: std::collections::BTreeSet<usize> = errors.iter().map(variant_index).collect();
    assert_eq!(covered.len(), 32, "one_of_each misses a variant");
    for k in 0..errors.len() {
        // `ApiError` is not `Clone`: one fresh copy per mapping.
        let (e, twin) = (one_of_each().swap_remove(k), one_of_each().swap_remove(k));
        let (status, grpc, code) = (e.status().as_u16(), e.grpc_code(), e.code());
        assert!(grpc_codes_for(status).contains(&grpc), "{code}: HTTP {status} but gRPC {grpc:?}");
        // The same stable code on both wires, and the problem body's status is the HTTP one.
        let response = e.into_response();
        assert_eq!(response.status().as_u16(), status);
        let body = axum::body::to_bytes(response.into_body(), 1 << 16).await.unwrap();
        let problem: serde_json::Value = serde_json::from_slice(&body).unwrap();
        assert_eq!((problem["status"].as_u64(), problem["code"].as_str()), (Some(status as u64), Some(code)));
        assert!(!problem["detail"].as_str().unwrap().contains("disk on fire"), "internals leaked");
        let status_pb = tonic::Status::from(twin);
        assert_eq!(status_pb.code(), grpc);
        assert_eq!(status_pb.metadata().get("x-error-code").unwrap(), code);
        assert!(!status_pb.message().contains("disk on fire"), "internals leaked over gRPC");
    }
}

/// The same failing request on both protocols, and the stable code both must carry.
struct Case {
    what: &'static str,
    status: u16,
    grpc: Code,
    code: &'static str,
}

#[tokio::test]
async fn real_failures_agree_on_both_protocols() {
    let app = TestApp::builder().configure(scoped_tokens).start().await;
    let id = app.create_id(WAVE, Some(ADMIN)).await;
    let missing = "01234567-89ab-7def-8123-456789abcdef";
    let mut grpc = app.grpc().await;
    let http = &app.http;
    let clip_url = app.url(&format!("/v1/clips/{id}"));
    let mut bad_clip = wave_pb();
    bad_clip.tracks[0].times.reverse();
    let bad_doc = {
        let mut doc: serde_json::Value = serde_json::from_str(super::WAVE).unwrap();
        let times = doc["tracks"][0]["times"].as_array_mut().unwrap();
        times.reverse();
        doc.to_string()
    };

    let cases = [
        Case { what: "write without a token", status: 401, grpc: Code::Unauthenticated, code: "unauthorized" },
        Case { what: "write with a read token", status: 403, grpc: Code::PermissionDenied, code: "insufficient_scope" },
        Case { what: "read a missing clip", status: 404, grpc: Code::NotFound, code: "clip_not_found" },
        Case {
            what: "replace at a stale version",
            status: 412,
            grpc: Code::FailedPrecondition,
            code: "version_mismatch",
        },
        Case {
            what: "replace with keys out of order",
            status: 422,
            grpc: Code::InvalidArgument,
            code: "times_not_increasing",
        },
        Case { what: "too many poses", status: 422, grpc: Code::InvalidArgument, code: "too_many_poses" },
    ];
    for (k, case) in cases.iter().enumerate() {
        let put = |token: Option<&str>| {
            let mut r = http.put(&clip_url).header("content-type", "application/json").body(super::WAVE);
            if let Some(t) = token {
                r = r.bearer_auth(t);
            }
            r
        };
        let put_pb = |clip: pb::Clip, if_version: Option<u64>| pb::PutClipRequest {
            clip_id: id.clone(),
            clip: Some(clip),
            if_version,
            ..Default::default()
        };
        let (rest, rpc) = match k {
            0 => (put(None), grpc.put_clip(with_token(put_pb(wave_pb(), None), None)).await.map(drop)),
            1 => (put(Some(READER)), grpc.put_clip(with_token(put_pb(wave_pb(), None), Some(READER))).await.map(drop)),
            2 => (
                http.get(app.url(&format!("/v1/clips/{missing}"))).bearer_auth(READER),
                grpc.get_clip(with_token(pb::GetClipRequest { clip_id: missing.into() }, Some(READER))).await.map(drop),
            ),
            3 => (
                put(Some(WRITER)).header("if-match", "\"999\""),
                grpc.put_clip(with_token(put_pb(wave_pb(), Some(999)), Some(WRITER))).await.map(drop),
            ),
            4 => (
                put(Some(WRITER)).body(bad_doc.clone()),
                grpc.put_clip(with_token(put_pb(bad_clip.clone(), None), Some(WRITER))).await.map(drop),
            ),
            _ => {
                let range = pb::FrameRange { start: 0.0, end: 1000.0, fps: 240.0 };
                let req = pb::SampleBatchRequest {
                    clip_id: id.clone(),
                    when: Some(pb::sample_batch_request::When::Range(range)),
                    ..Default::default()
                };
                (
                    http.post(format!("{clip_url}/sample"))
                        .bearer_auth(READER)
                        .json(&serde_json::json!({"start": 0, "end": 1000, "fps": 240})),
                    grpc.sample_batch(with_token(req, Some(READER))).await.map(drop),
                )
            }
        };
        let resp = rest.send().await.unwrap();
        let status = resp.status().as_u16();
        let problem: serde_json::Value = resp.json().await.unwrap();
        let err = rpc.expect_err(case.what);
        assert_eq!((status, err.code()), (case.status, case.grpc), "{}: {problem} / {err:?}", case.what);
        assert!(grpc_codes_for(status).contains(&err.code()), "{}", case.what);
        assert_eq!(problem["code"], case.code, "{}: REST code", case.what);
        assert_eq!(
            err.metadata().get("x-error-code").unwrap().to_str().unwrap(),
            case.code,
            "{}: the same stable code over gRPC",
            case.what
        );
    }
    app.stop().await;
}
