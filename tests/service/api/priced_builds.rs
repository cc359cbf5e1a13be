//! Builds and compression have a price (docs/api.md, “Work and its
//! price”): an upload pays for reading its body, then for building what it
//! holds (its constant-speed tables at their bound); a motion build pays
//! per joint of each layer; a compressed answer pays for its compression.
//! Each is refused over `max_request_work` before it runs, with its price
//! and the limit in the detail.

use formats::wire::json::parse_clip;
use formats::wire::proto::{clip_to_pb, pb};
use serde_json::{Value, json};
use tonic::Code;

use super::TestApp;
use crate::common::{chain_clip, looping_hermite};

/// A server whose requests may cost `limit` work units each.
async fn limited(limit: u64) -> TestApp {
    TestApp::builder().configure(|c| c.limits.max_request_work = limit).start().await
}

/// The price a `too_much_work` detail names ("… costs N work units …").
fn price_in(detail: &str) -> u64 {
    let after = detail.split("costs ").nth(1).unwrap_or_else(|| panic!("no price in {detail}"));
    after.split(' ').next().unwrap().parse().unwrap()
}

async fn refusal(resp: reqwest::Response) -> (u16, String, String) {
    let status = resp.status().as_u16();
    let problem: Value = resp.json().await.unwrap();
    let field = |name: &str| problem[name].as_str().unwrap_or_default().to_owned();
    (status, field("code"), field("detail"))
}

async fn upload(app: &TestApp, body: String) -> reqwest::Response {
    app.http.post(app.url("/v1/clips")).header("content-type", "application/json").body(body).send().await.unwrap()
}

/// One constant-speed Hermite track of 41 keys: 40 segments of arc-length
/// table at 100,000 build units of 25 ns each (250,000 work units of 10 ns),
/// plus 41 keys × 3 components × (value, in and out tangent) and 8 for the
/// track's name.
const HERMITE_BUILD: u64 = 40 * 250_000 + 41 * 3 * 3 + 8;

#[tokio::test]
async fn an_upload_is_priced_by_its_body_then_by_what_it_builds() {
    let app = limited(1_000_000).await;
    // The body: a byte a unit, refused before it is parsed.
    let padded = format!("{{\"name\": \"big\", \"tracks\": []{}}}", " ".repeat(1_100_000));
    let length = padded.len() as u64;
    let (status, code, detail) = refusal(upload(&app, padded).await).await;
    assert_eq!((status, code.as_str()), (422, "too_much_work"), "{detail}");
    assert!(detail.starts_with("reading this clip document") && detail.contains("1000000"), "{detail}");
    assert_eq!(price_in(&detail), length);
    // A small body whose build is dear.
    let doc = looping_hermite("dear", 1, 41, 1.0);
    let (status, code, detail) = refusal(upload(&app, doc.clone()).await).await;
    assert_eq!((status, code.as_str()), (422, "too_much_work"), "{detail}");
    assert!(detail.starts_with("building this clip"), "{detail}");
    assert_eq!(price_in(&detail), HERMITE_BUILD);
    // gRPC's PutClip builds the same spec at the same price.
    let spec = parse_clip(doc.as_bytes()).unwrap().1;
    let put = pb::PutClipRequest { clip: Some(clip_to_pb(&spec)), ..Default::default() };
    let refused = app.grpc().await.put_clip(put).await.unwrap_err();
    let code = refused.metadata().get("x-error-code").map(|v| v.to_str().unwrap().to_owned());
    assert_eq!((refused.code(), code.as_deref()), (Code::InvalidArgument, Some("too_much_work")));
    assert_eq!(price_in(refused.message()), HERMITE_BUILD, "{}", refused.message());
    let listed: Value = app.http.get(app.url("/v1/clips")).send().await.unwrap().json().await.unwrap();
    assert_eq!(listed["clips"], json!([]), "nothing was stored");
    assert_eq!(app.state.work.meter().held(), 0);
    app.stop().await;
    // Under the default limit the same document is built and stored.
    let app = TestApp::start().await;
    assert_eq!(upload(&app, looping_hermite("dear", 1, 41, 1.0)).await.status(), 201);
    app.stop().await;
}

/// `layers` additive layers over the 4,096-joint chain `id`.
fn additive(id: &str, layers: usize) -> Value {
    let layer = json!({"clip": id, "mode": "additive"});
    json!({"motion": {"layers": vec![layer; layers]}, "time": 0.5, "joints": ["j0"]})
}

#[tokio::test]
async fn a_motion_build_is_priced_before_it_runs() {
    let app = limited(1_000_000).await;
    let id = app.create_id(&chain_clip(4096, json!([])), None).await;
    let pose = |layers| app.http.post(app.url("/v1/poses")).json(&additive(&id, layers)).send();
    // Each layer maps 4,096 joints onto the output's 4,096 at 6 units a
    // joint, and samples its 4,096-joint reference pose at 1 a joint.
    let per_layer = (4096 + 4096) * 6 + 4096;
    let (status, code, detail) = refusal(pose(32).await.unwrap()).await;
    assert_eq!((status, code.as_str()), (422, "too_much_work"), "{detail}");
    assert!(detail.starts_with("building this motion") && detail.contains("1000000"), "{detail}");
    assert_eq!(price_in(&detail), 32 * per_layer);
    assert_eq!(app.state.motions.len(), 0, "the refused motion was never built");
    // 8 layers cost 425,984: built, cached, and their pose evaluated.
    assert_eq!(pose(8).await.unwrap().status(), 200);
    assert_eq!(app.state.motions.len(), 1);
    app.stop().await;
}

/// A server whose requests may cost `limit`, over a 64-joint clip stored
/// in `dir` under the default limit (an upload pays too); its id.
async fn limited_with_clip(dir: &std::path::Path, limit: u64) -> (TestApp, String) {
    let app = TestApp::builder().data_dir(dir).start().await;
    let id = app.create_id(&chain_clip(64, json!([])), None).await;
    app.stop().await;
    (TestApp::builder().data_dir(dir).configure(|c| c.limits.max_request_work = limit).start().await, id)
}

/// A `/sample` of 200 poses of the 64-joint clip `id`: an answer of about
/// 3 MB, asked for in `coding`.
async fn big_answer(app: &TestApp, id: &str, coding: &str) -> (u16, String, String) {
    let times: Vec<f64> = (0..200).map(|k| f64::from(k) * 0.005).collect();
    let resp = (app.http.post(app.url(&format!("/v1/clips/{id}/sample"))))
        .header("accept-encoding", coding)
        .json(&json!({"times": times}))
        .send()
        .await
        .unwrap();
    let status = resp.status().as_u16();
    if status == 200 {
        return (status, String::new(), String::new());
    }
    refusal(resp).await
}

/// The units of a `too_much_work` detail: the whole price, then the encoding's
/// and the compression's ("… {E} to encode the answer and {C} to compress it").
fn parts(detail: &str) -> (u64, u64, u64) {
    let before = |what: &str| {
        let head = detail.split(what).next().unwrap();
        head.rsplit(' ').find(|w| !w.is_empty()).unwrap().trim_matches(',').parse::<u64>().unwrap()
    };
    (price_in(detail), before(" to encode"), before(" to compress"))
}

#[tokio::test]
async fn a_compressed_answer_is_priced_for_its_compression() {
    let dir = tempfile::tempdir().unwrap();
    let (app, id) = limited_with_clip(dir.path(), 1).await;
    let (status, code, identity) = big_answer(&app, &id, "identity").await;
    assert_eq!((status, code.as_str()), (422, "too_much_work"), "{identity}");
    let (whole, encode, compress) = parts(&identity);
    assert_eq!(compress, 0, "{identity}");
    // The answer's size bound: encoding is one unit per 8 bytes of it.
    let bytes = (8 * (encode - 1) + 1)..=(8 * encode);
    for (coding, ns_per_byte) in [("br", 14), ("gzip", 10), ("zstd", 8)] {
        let (_, code, detail) = big_answer(&app, &id, coding).await;
        assert_eq!(code, "too_much_work", "{detail}");
        let (priced, encoded, compressed) = parts(&detail);
        assert_eq!(encoded, encode, "{detail}");
        // Level 1 of each (an answer over 64 KiB), in units of 10 ns.
        let (least, most) = (bytes.start() * ns_per_byte / 10, (bytes.end() * ns_per_byte).div_ceil(10));
        assert!((least..=most).contains(&compressed), "{coding}: {compressed} not in {least}..={most}");
        assert_eq!(priced, whole + compressed, "{coding}: {detail}");
    }
    app.stop().await;
    // A limit between the two prices: identity is answered, br refused.
    let between = whole + (bytes.end() * 14 / 10) / 2;
    let app = TestApp::builder().data_dir(dir.path()).configure(|c| c.limits.max_request_work = between).start().await;
    assert_eq!(big_answer(&app, &id, "identity").await.0, 200);
    let (status, code, detail) = big_answer(&app, &id, "br").await;
    assert_eq!((status, code.as_str()), (422, "too_much_work"), "{detail}");
    app.stop().await;
}

/// The detail of a gRPC refusal of `Sample` (one pose of `id`) or, with
/// `poses`, of `SampleBatch`, from a client that accepts `coding`.
async fn grpc_refusal(app: &TestApp, id: &str, coding: tonic::codec::CompressionEncoding, poses: u32) -> String {
    let mut grpc = app.grpc().await.accept_compressed(coding);
    let status = if poses == 1 {
        grpc.sample(pb::SampleRequest { clip_id: id.into(), time: 0.5, ..Default::default() }).await.unwrap_err()
    } else {
        let times = (0..poses).map(|k| f64::from(k) * 0.005).collect();
        let when = Some(pb::sample_batch_request::When::Times(pb::Times { values: times }));
        grpc.sample_batch(pb::SampleBatchRequest { clip_id: id.into(), when, ..Default::default() }).await.unwrap_err()
    };
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    status.message().to_owned()
}

/// tonic compresses small unary answers at gzip 6 and zstd 3 (REST's
/// small-answer levels), larger ones not at all: the price says the same.
#[tokio::test]
async fn a_grpc_answer_is_priced_for_the_compression_tonic_gives_it() {
    use tonic::codec::CompressionEncoding::{Gzip, Zstd};
    let dir = tempfile::tempdir().unwrap();
    let (app, id) = limited_with_clip(dir.path(), 1).await;
    let plain = app.grpc().await.sample(pb::SampleRequest { clip_id: id.clone(), ..Default::default() }).await;
    let (whole, encode, compress) = parts(plain.unwrap_err().message());
    assert_eq!(compress, 0);
    let bytes = (8 * (encode - 1) + 1)..=(8 * encode);
    for (coding, ns_per_byte) in [(Gzip, 39), (Zstd, 13)] {
        let detail = grpc_refusal(&app, &id, coding, 1).await;
        let (priced, encoded, compressed) = parts(&detail);
        assert_eq!(encoded, encode, "{detail}");
        let (least, most) = (bytes.start() * ns_per_byte / 10, (bytes.end() * ns_per_byte).div_ceil(10));
        assert!((least..=most).contains(&compressed), "{coding:?}: {compressed} not in {least}..={most}");
        assert_eq!(priced, whole + compressed, "{detail}");
        // 200 poses of 64 joints: over 64 KiB, sent as they are, so nothing to compress.
        let (_, _, compressed) = parts(&grpc_refusal(&app, &id, coding, 200).await);
        assert_eq!(compressed, 0, "{coding:?}: a large answer is not compressed");
    }
    app.stop().await;
}
