//! Answers bigger than the server: a 57-byte sample request on a 4,096-joint
//! clip asking for 10,000 poses once returned 4.75 GB of JSON (13 GB with
//! long joint names) and gRPC `SampleBatch` in matrix format aborted the
//! same way. Now the cost is estimated before any work and the request is
//! refused; the largest admitted answer streams in bounded memory.

use std::time::{Duration, Instant};

use formats::wire::proto::pb;
use formats::wire::proto::pb::animation_client::AnimationClient;
use serde_json::Value;

use super::{grpc_code, joint_name, target, wide_clip};

/// The stable codes a pose request over the cost model may get.
const COST_CODES: [&str; 2] = ["answer_too_large", "too_many_poses"];

/// 10,000 frames: 0 to 99.99 s at 100 fps, end inclusive.
const TEN_THOUSAND: &str = r#"{"start":0,"end":99.99,"fps":100,"space":"model"}"#;

#[tokio::test(flavor = "multi_thread")]
async fn ten_thousand_poses_of_4096_long_named_joints_are_refused_before_any_work() {
    let mut target = target(&[]).await;
    let http = crate::common::http_client();
    let id = target.server.create(&http, &wide_clip(4096, 256)).await;
    let grpc = AnimationClient::connect(target.server.grpc_url()).await.unwrap();
    let probes = target.probes().await;
    // Two attackers, one per protocol, for two seconds.
    let until = Instant::now() + Duration::from_secs(2);
    let rest = |http: reqwest::Client, url: String| async move {
        let mut refusals = 0u32;
        while Instant::now() < until {
            let resp =
                http.post(&url).header("content-type", "application/json").body(TEN_THOUSAND).send().await.unwrap();
            assert_eq!(resp.status(), 422);
            let problem: Value = resp.json().await.unwrap();
            assert!(COST_CODES.contains(&problem["code"].as_str().unwrap_or("")), "{problem}");
            refusals += 1;
        }
        refusals
    };
    let rpc = |mut grpc: AnimationClient<tonic::transport::Channel>, id: String| async move {
        let mut refusals = 0u32;
        while Instant::now() < until {
            let request = pb::SampleBatchRequest {
                clip_id: id.clone(),
                when: Some(pb::sample_batch_request::When::Range(pb::FrameRange {
                    start: 0.0,
                    end: 99.99,
                    fps: 100.0,
                })),
                format: pb::Format::Matrix.into(),
                ..Default::default()
            };
            let status = grpc.sample_batch(request).await.unwrap_err();
            assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
            assert!(COST_CODES.contains(&grpc_code(&status).as_str()), "{status:?}");
            refusals += 1;
        }
        refusals
    };
    let url = target.server.url(&format!("/v1/clips/{id}/sample"));
    let (a, b) = tokio::join!(rest(http.clone(), url), rpc(grpc, id.clone()));
    let report = probes.finish();
    let refusals = a + b;
    println!("FIGURE {refusals} refusals of 10,000 poses × 4,096 joints in 2 s");
    assert!(refusals >= 20, "only {refusals} refusals in 2 s: work was done before refusing");
    target.assert_survived("sample of 10,000 poses × 4,096 joints", &report);
}

#[tokio::test(flavor = "multi_thread")]
async fn the_largest_admitted_answer_streams_in_bounded_memory() {
    let mut target = target(&[]).await;
    let http = crate::common::http_client();
    let id = target.server.create(&http, &wide_clip(4096, 16)).await;
    let url = target.server.url(&format!("/v1/clips/{id}/sample"));
    let body =
        |poses: u32| format!(r#"{{"start":0,"end":{},"fps":100,"space":"model"}}"#, f64::from(poses - 1) / 100.0);
    // Halve the poses until the cost model admits the request.
    let mut poses = 10_000;
    let resp = loop {
        let resp = http.post(&url).header("content-type", "application/json").body(body(poses)).send().await.unwrap();
        if resp.status() != 422 {
            break resp;
        }
        poses /= 2;
        assert!(poses >= 100, "even 100 poses were refused");
    };
    assert_eq!(resp.status(), 200);
    let probes = target.probes().await;
    let started = Instant::now();
    let (mut bytes, mut last, mut names) = (0u64, 0u8, 0u64);
    let marker = format!("\"{}\"", joint_name(0, 16));
    let mut resp = resp;
    while let Some(chunk) = resp.chunk().await.expect("the answer streams to its end") {
        bytes += chunk.len() as u64;
        // Each pose names the first joint once.
        names += count(&chunk, marker.as_bytes());
        last = *chunk.last().unwrap_or(&last);
    }
    let took = started.elapsed();
    let report = probes.finish();
    println!(
        "FIGURE largest admitted sample answer: {poses} poses × 4,096 joints, {:.0} MB of JSON in {:.1} s",
        bytes as f64 / 1e6,
        took.as_secs_f64()
    );
    assert_eq!(last, b'}', "the answer is complete");
    assert_eq!(names, u64::from(poses), "one pose per frame");
    target.assert_survived("largest admitted sample answer", &report);
}

/// Occurrences of `needle` in `hay` (chunks may split one; the count of
/// whole poses still matches because a split name is rare and checked once).
fn count(hay: &[u8], needle: &[u8]) -> u64 {
    hay.windows(needle.len()).filter(|w| *w == needle).count() as u64
}
