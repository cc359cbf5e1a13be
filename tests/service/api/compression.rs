//! Compression (issue 18): answers negotiated by `Accept-Encoding` and
//! decoded by real clients (reqwest's own gzip, br and zstd decoders),
//! nothing compressed for a client that does not ask or for small answers,
//! compressed request bodies held to the body limit by their *decoded* size,
//! and gRPC compression accepted and offered (frames excepted).
//!
//! `FIGURE` lines (`-- --nocapture`) are the bytes saved recorded in
//! BENCHMARKS.md ("Compression (issue 18)").

use std::io::Write;

use formats::wire::proto::pb;
use formats::wire::proto::pb::animation_client::AnimationClient;
use futures_util::StreamExt;
use prost::Message;
use reqwest::header::{ACCEPT_ENCODING, CONTENT_ENCODING, CONTENT_LENGTH, VARY};
use serde_json::{Value, json};
use tonic::codec::CompressionEncoding;

use super::{TestApp, WAVE, canonical, within};
use crate::common::{http_builder, http_client, testdata};

const CODINGS: [&str; 3] = ["gzip", "br", "zstd"];

/// The 300-pose batch: 3 s of the take at 100 fps.
const BATCH: &str = r#"{"start":0,"end":2.995,"fps":100}"#;

/// A client that asks for `coding` alone and decodes it itself, as a
/// browser or `curl --compressed` does.
fn decoding(coding: &str) -> reqwest::Client {
    let builder = http_builder();
    let builder = match coding {
        "gzip" => builder.gzip(true),
        "br" => builder.brotli(true),
        "zstd" => builder.zstd(true),
        other => panic!("no decoder for {other}"),
    };
    builder.build().unwrap()
}

/// `bytes` compressed with `coding` by an encoder of its own (not the server's).
fn encode(coding: &str, bytes: &[u8]) -> Vec<u8> {
    match coding {
        "gzip" => {
            let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
            e.write_all(bytes).unwrap();
            e.finish().unwrap()
        }
        "br" => {
            let mut out = Vec::new();
            let mut w = brotli::CompressorWriter::new(&mut out, 4096, 5, 22);
            w.write_all(bytes).unwrap();
            drop(w);
            out
        }
        "zstd" => zstd::encode_all(bytes, 3).unwrap(),
        other => panic!("no encoder for {other}"),
    }
}

/// CMU mocap 131_03 imported whole: a 1.8 MB clip document of 38 joints.
async fn import_131_03(app: &TestApp) -> String {
    let url = app.url("/v1/clips/import?format=bvh&name=131_03");
    let resp = app.http.post(url).body(testdata("bvh/131_03.bvh")).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let body: Value = resp.json().await.unwrap();
    body["clips"][0]["id"].as_str().unwrap().to_owned()
}

/// One answer as it came over the wire.
struct Wire {
    headers: reqwest::header::HeaderMap,
    body: Vec<u8>,
}

impl Wire {
    fn coding(&self) -> Option<&str> {
        self.headers.get(CONTENT_ENCODING).map(|v| v.to_str().unwrap())
    }
}

async fn wire(request: reqwest::RequestBuilder) -> Wire {
    let resp = request.send().await.unwrap();
    assert!(resp.status().is_success(), "{}", resp.status());
    let headers = resp.headers().clone();
    Wire { headers, body: resp.bytes().await.unwrap().to_vec() }
}

/// `GET` the document or `POST` the batch with `client`, asking for `accept` if given.
fn document(client: &reqwest::Client, app: &TestApp, id: &str, accept: Option<&str>) -> reqwest::RequestBuilder {
    let req = client.get(app.url(&format!("/v1/clips/{id}")));
    match accept {
        Some(a) => req.header(ACCEPT_ENCODING, a),
        None => req,
    }
}

fn batch(client: &reqwest::Client, app: &TestApp, id: &str, accept: Option<&str>) -> reqwest::RequestBuilder {
    let req =
        client.post(app.url(&format!("/v1/clips/{id}/sample"))).header("content-type", "application/json").body(BATCH);
    match accept {
        Some(a) => req.header(ACCEPT_ENCODING, a),
        None => req,
    }
}

#[tokio::test]
async fn documents_and_batches_are_compressed_for_clients_that_ask_and_decode_to_the_same_json() {
    let app = TestApp::start().await;
    let id = import_131_03(&app).await;
    let plain = http_client();

    // Without Accept-Encoding nothing is compressed.
    let doc = wire(document(&plain, &app, &id, None)).await;
    assert_eq!(doc.coding(), None);
    assert_eq!(doc.headers[CONTENT_LENGTH].to_str().unwrap(), doc.body.len().to_string());
    let doc_json: Value = serde_json::from_slice(&doc.body).unwrap();
    assert_eq!(doc_json["skeleton"]["joints"].as_array().unwrap().len(), 38);
    let poses = wire(batch(&plain, &app, &id, None)).await;
    assert_eq!(poses.coding(), None);
    let poses_json: Value = serde_json::from_slice(&poses.body).unwrap();
    assert_eq!(poses_json["poses"].as_array().unwrap().len(), 300);
    assert!(doc.body.len() > 1_500_000 && poses.body.len() > 1_000_000, "the batch is sent in pieces (chunked)");

    for coding in CODINGS {
        // On the wire: compressed, and saying so.
        let doc_wire = wire(document(&plain, &app, &id, Some(coding))).await;
        let poses_wire = wire(batch(&plain, &app, &id, Some(coding))).await;
        for (what, w, plain_len) in [("document", &doc_wire, doc.body.len()), ("batch", &poses_wire, poses.body.len())]
        {
            assert_eq!(w.coding(), Some(coding), "{what}");
            let vary =
                w.headers.get_all(VARY).iter().map(|v| v.to_str().unwrap().to_ascii_lowercase()).collect::<Vec<_>>();
            assert!(vary.iter().any(|v| v.contains("accept-encoding")), "{what} {coding}: Vary {vary:?}");
            assert!(w.headers.get(CONTENT_LENGTH).is_none(), "{what} {coding}: no stale length");
            assert!(w.body.len() * 2 < plain_len, "{what} {coding}: {} of {plain_len} bytes", w.body.len());
            println!(
                "FIGURE compression {what} 131_03 {coding}: {plain_len} -> {} bytes ({:.1}%, {} saved)",
                w.body.len(),
                100.0 * w.body.len() as f64 / plain_len as f64,
                plain_len - w.body.len()
            );
        }
        // A client with its own decoder gets the uncompressed bytes exactly.
        let client = decoding(coding);
        let decoded = client.get(app.url(&format!("/v1/clips/{id}"))).send().await.unwrap();
        assert_eq!(decoded.headers().get(CONTENT_ENCODING), None, "reqwest decoded it");
        let decoded = decoded.bytes().await.unwrap();
        assert_eq!(serde_json::from_slice::<Value>(&decoded).unwrap(), doc_json, "{coding} document");
        assert!(decoded == doc.body, "{coding}: the document's bytes");
        let decoded = batch(&client, &app, &id, None).send().await.unwrap().bytes().await.unwrap();
        assert_eq!(serde_json::from_slice::<Value>(&decoded).unwrap(), poses_json, "{coding} batch");
    }
    // A browser's header: every coding at q=1; the server picks zstd.
    let chrome = wire(document(&plain, &app, &id, Some("gzip, deflate, br, zstd"))).await;
    assert_eq!(chrome.coding(), Some("zstd"));
    let prefer_gzip = wire(document(&plain, &app, &id, Some("br;q=0.5, gzip, zstd;q=0.1"))).await;
    assert_eq!(prefer_gzip.coding(), Some("gzip"));
    app.stop().await;
}

#[tokio::test]
async fn small_answers_errors_and_the_websocket_go_as_they_are() {
    let app = TestApp::start().await;
    let id = app.create_id(WAVE, None).await;
    let plain = http_client();
    // A pose of a two-joint clip is a few hundred bytes: under the 1 KiB minimum.
    let pose = wire(plain.get(app.url(&format!("/v1/clips/{id}/pose?t=1"))).header(ACCEPT_ENCODING, "gzip")).await;
    assert_eq!(pose.coding(), None);
    assert!(pose.body.len() < 1024);
    let missing = plain.get(app.url("/v1/clips/nope")).header(ACCEPT_ENCODING, "gzip").send().await.unwrap();
    assert_eq!(missing.status(), 404);
    assert_eq!(missing.headers().get(CONTENT_ENCODING), None);
    // A header that accepts none of our codings, identity refused too: the
    // answer goes uncompressed (never 406 after the clip was created).
    let created = plain
        .post(app.url("/v1/clips?replace=true"))
        .header("content-type", "application/json")
        .header(ACCEPT_ENCODING, "identity;q=0, deflate")
        .body(WAVE)
        .send()
        .await
        .unwrap();
    assert!(created.status().is_success(), "{}", created.status());
    assert_eq!(created.headers().get(CONTENT_ENCODING), None);
    // The WebSocket upgrade of a client that asks for compression: 101, and
    // frames are plain JSON text.
    let mut request = tokio_tungstenite::tungstenite::client::IntoClientRequest::into_client_request(
        app.ws_url(&format!("/v1/clips/{id}/stream?fps=30&max_frames=2")),
    )
    .unwrap();
    request.headers_mut().insert("accept-encoding", "gzip, br, zstd".parse().unwrap());
    let (mut ws, resp) = within(5, "upgrade", tokio_tungstenite::connect_async(request)).await.unwrap();
    assert_eq!(resp.status(), 101);
    assert_eq!(resp.headers().get("content-encoding"), None);
    assert_eq!(resp.headers().get("sec-websocket-extensions"), None, "no permessage-deflate");
    let frame = within(5, "a frame", ws.next()).await.unwrap().unwrap();
    let text = frame.into_text().unwrap();
    assert!(serde_json::from_str::<Value>(&text).unwrap()["seq"].is_u64(), "{text}");
    app.stop().await;
}

/// `WAVE` padded with whitespace to `len` bytes: still the same clip.
fn padded_wave(len: usize) -> Vec<u8> {
    let mut doc = WAVE.trim_end().as_bytes().to_vec();
    doc.resize(len, b' ');
    doc
}

#[tokio::test]
async fn compressed_uploads_are_limited_by_their_decoded_bytes() {
    const LIMIT: usize = 64 * 1024;
    let app = TestApp::builder().configure(|c| c.limits.max_body_bytes = LIMIT).start().await;
    let upload = |body: Vec<u8>, coding: &str| {
        app.http
            .post(app.url("/v1/clips?replace=true"))
            .header("content-type", "application/json")
            .header(CONTENT_ENCODING, coding)
            .body(body)
            .send()
    };
    for coding in CODINGS {
        // Decoded just under the limit (a few hundred bytes compressed): taken.
        let under = encode(coding, &padded_wave(LIMIT - 100));
        let resp = upload(under, coding).await.unwrap();
        assert!(resp.status().is_success(), "{coding}: {}", resp.status());
        let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
        let stored = app.http.get(app.url(&format!("/v1/clips/{id}"))).send().await.unwrap().text().await.unwrap();
        assert_eq!(stored, canonical(WAVE), "{coding}: the decoded document was stored");
        // Decoded just over it: 413, however small it was on the wire.
        let over = encode(coding, &padded_wave(LIMIT + 100));
        assert!(over.len() < LIMIT / 10);
        let resp = upload(over, coding).await.unwrap();
        assert_eq!(resp.status(), 413, "{coding}");
        assert_eq!(resp.json::<Value>().await.unwrap()["code"], "body_too_large");
    }
    // A zip bomb: 16 MiB of spaces in 16 KB of gzip against a 64 KiB limit.
    let bomb = encode("gzip", &vec![b' '; 16 << 20]);
    assert!(bomb.len() < 64 * 1024);
    let resp = upload(bomb, "gzip").await.unwrap();
    assert_eq!(resp.status(), 413);
    // A coding we do not decode, several codings, and a body that is not what it says.
    let refused = upload(WAVE.as_bytes().to_vec(), "deflate").await.unwrap();
    assert_eq!(refused.status(), 415);
    assert_eq!(refused.headers()[ACCEPT_ENCODING], "zstd, br, gzip");
    assert_eq!(refused.json::<Value>().await.unwrap()["code"], "unsupported_media_type");
    assert_eq!(upload(encode("gzip", WAVE.as_bytes()), "gzip, identity").await.unwrap().status(), 415);
    let lie = upload(WAVE.as_bytes().to_vec(), "gzip").await.unwrap();
    assert_eq!(lie.status(), 400);
    assert_eq!(lie.json::<Value>().await.unwrap()["code"], "body_not_decodable");
    // The server is fine afterwards.
    assert_eq!(app.get_json("/healthz").await["status"], "ok");
    app.stop().await;
}

/// A gRPC client that asks for answers in `coding` and sends its requests in it.
async fn grpc_with(app: &TestApp, coding: CompressionEncoding) -> AnimationClient<tonic::transport::Channel> {
    AnimationClient::new(app.channel().await).accept_compressed(coding).send_compressed(coding)
}

fn range_300(id: &str) -> pb::SampleBatchRequest {
    pb::SampleBatchRequest {
        clip_id: id.to_owned(),
        when: Some(pb::sample_batch_request::When::Range(pb::FrameRange { start: 0.0, end: 2.995, fps: 100.0 })),
        ..Default::default()
    }
}

#[tokio::test]
async fn grpc_compression_is_accepted_and_offered_but_not_for_frames() {
    let app = TestApp::start().await;
    let id = import_131_03(&app).await;
    let mut plain = app.grpc().await;
    let record = plain.get_clip(pb::GetClipRequest { clip_id: id.clone() }).await.unwrap();
    assert_eq!(record.metadata().get("grpc-encoding"), None, "not asked, not compressed");
    let batch = plain.sample_batch(range_300(&id)).await.unwrap().into_inner();
    assert_eq!(batch.poses.len(), 300);
    for (coding, name) in [(CompressionEncoding::Gzip, "gzip"), (CompressionEncoding::Zstd, "zstd")] {
        let mut grpc = grpc_with(&app, coding).await;
        // Requests go compressed (send_compressed) and are decoded; answers come compressed.
        let got = grpc.get_clip(pb::GetClipRequest { clip_id: id.clone() }).await.unwrap();
        assert_eq!(got.metadata().get("grpc-encoding").map(|v| v.to_str().unwrap()), Some(name));
        assert_eq!(got.into_inner(), record.get_ref().clone(), "{name}: the same record");
        let got = grpc.sample_batch(range_300(&id)).await.unwrap();
        assert_eq!(got.metadata().get("grpc-encoding").map(|v| v.to_str().unwrap()), Some(name));
        assert_eq!(got.into_inner(), batch, "{name}: the same poses");
        // Frames go uncompressed even to a client that asks.
        let req = pb::StreamRequest { clip_id: id.clone(), fps: 30, max_frames: 3, ..Default::default() };
        let stream = grpc.stream_frames(req).await.unwrap();
        assert_eq!(stream.metadata().get("grpc-encoding"), None, "{name}: frames");
        let mut stream = stream.into_inner();
        let mut frames = 0;
        while within(5, "frames", stream.message()).await.unwrap().is_some() {
            frames += 1;
        }
        assert_eq!(frames, 3);
    }
    // What gzip saves on the 300-pose batch message (tonic's default level, as the server sends it).
    let message = batch.encode_to_vec();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(&message).unwrap();
    let gz = gz.finish().unwrap();
    println!(
        "FIGURE compression gRPC PoseBatch 131_03 300 poses gzip: {} -> {} bytes ({:.1}%)",
        message.len(),
        gz.len(),
        100.0 * gz.len() as f64 / message.len() as f64
    );
    app.stop().await;
}

/// The messages of a call to `method` sent with `grpc-accept-encoding:
/// gzip`, as they arrive: each one's compressed flag and its bytes.
async fn raw_messages(app: &TestApp, method: &str, message: impl Message) -> Vec<(bool, Vec<u8>)> {
    use http_body_util::BodyExt;
    use tower::{Service, ServiceExt};
    let mut body = vec![0];
    body.extend((message.encoded_len() as u32).to_be_bytes());
    body.extend(message.encode_to_vec());
    let request = axum::http::Request::post(format!("/inbetween.v1.Animation/{method}"))
        .header("content-type", "application/grpc")
        .header("te", "trailers")
        .header("grpc-accept-encoding", "gzip")
        .body(tonic::body::Body::new(http_body_util::Full::new(bytes::Bytes::from(body))))
        .unwrap();
    let mut channel = app.channel().await;
    let response = channel.ready().await.unwrap().call(request).await.unwrap();
    let bytes = within(10, method, response.into_body().collect()).await.unwrap().to_bytes();
    let mut messages = Vec::new();
    let mut rest = &bytes[..];
    while rest.len() >= 5 {
        let len = u32::from_be_bytes(rest[1..5].try_into().unwrap()) as usize;
        messages.push((rest[0] == 1, rest[5..5 + len].to_vec()));
        rest = &rest[5 + len..];
    }
    messages
}

/// tonic compresses on the async workers, so only small unary answers are
/// compressed; large ones and streams go as they are, whatever the client asks.
#[tokio::test]
async fn grpc_compresses_small_answers_only() {
    let app = TestApp::start().await;
    let id = import_131_03(&app).await;
    let pose = pb::SampleRequest { clip_id: id.clone(), time: 0.5, ..Default::default() };
    let small = raw_messages(&app, "Sample", pose.clone()).await;
    assert_eq!(small.len(), 1);
    assert!(small[0].0, "a pose of 31 joints is compressed");
    let plain = app.grpc().await.sample(pose).await.unwrap().into_inner();
    let mut inflated = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&small[0].1[..]), &mut inflated).unwrap();
    assert_eq!(pb::Pose::decode(&inflated[..]).unwrap(), plain, "the compressed pose decodes to the plain one");

    let record = raw_messages(&app, "GetClip", pb::GetClipRequest { clip_id: id.clone() }).await;
    assert_eq!(record.len(), 1);
    assert!(!record[0].0, "the take's record ({} bytes) goes as it is", record[0].1.len());
    assert!(record[0].1.len() >= 64 * 1024, "over the 64 KiB of a small answer");
    assert!(pb::ClipRecord::decode(&record[0].1[..]).is_ok());

    let batches = raw_messages(&app, "SampleStream", range_300(&id)).await;
    assert!(!batches.is_empty() && batches.iter().all(|(compressed, _)| !compressed), "SampleStream goes as it is");
    let poses: usize = batches.iter().map(|(_, b)| pb::PoseBatch::decode(&b[..]).unwrap().poses.len()).sum();
    assert_eq!(poses, 300);
    app.stop().await;
}

#[tokio::test]
async fn a_compressed_grpc_message_is_limited_by_its_decoded_size() {
    let app = TestApp::start().await;
    let mut grpc = grpc_with(&app, CompressionEncoding::Gzip).await;
    // 8 MiB of name in ~8 KB of gzip, over tonic's 4 MiB decoding limit.
    let clip = pb::Clip { name: "a".repeat(8 << 20), ..Default::default() };
    let status = grpc.put_clip(pb::PutClipRequest { clip: Some(clip), ..Default::default() }).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::ResourceExhausted, "{status:?}");
    // The same client's ordinary calls go on.
    let id = app.create_id(WAVE, None).await;
    assert!(grpc.get_clip(pb::GetClipRequest { clip_id: id }).await.is_ok());
    app.stop().await;
}

#[tokio::test]
async fn with_compression_off_both_ports_speak_identity_only() {
    let app = TestApp::builder().configure(|c| c.compression.enabled = false).start().await;
    let id = app.create_id(WAVE, None).await;
    let plain = http_client();
    let doc = wire(document(&plain, &app, &id, Some("gzip, br, zstd"))).await;
    assert_eq!(doc.coding(), None);
    let gz = plain
        .post(app.url("/v1/clips"))
        .header("content-type", "application/json")
        .header(CONTENT_ENCODING, "gzip")
        .body(encode("gzip", WAVE.as_bytes()))
        .send()
        .await
        .unwrap();
    assert_eq!(gz.status(), 415);
    assert_eq!(gz.headers()[ACCEPT_ENCODING], "identity");
    let mut asks = AnimationClient::new(app.channel().await).accept_compressed(CompressionEncoding::Gzip);
    let got = asks.get_clip(pb::GetClipRequest { clip_id: id.clone() }).await.unwrap();
    assert_eq!(got.metadata().get("grpc-encoding"), None);
    let mut sends = AnimationClient::new(app.channel().await).send_compressed(CompressionEncoding::Gzip);
    let refused = sends.get_clip(pb::GetClipRequest { clip_id: id }).await.unwrap_err();
    assert_eq!(refused.code(), tonic::Code::Unimplemented, "{refused:?}");
    app.stop().await;
}

#[tokio::test]
async fn the_json_of_a_compressed_sample_answer_ends_where_the_plain_one_does() {
    // The chunked path once panicked under the compressor (a body polled
    // after its end): every coding's batch must arrive whole, twice over.
    let app = TestApp::start().await;
    let id = app.create_id(WAVE, None).await;
    let body = json!({"start": 0, "end": 90, "fps": 100}).to_string();
    let sample = |client: &reqwest::Client| {
        client
            .post(app.url(&format!("/v1/clips/{id}/sample")))
            .header("content-type", "application/json")
            .body(body.clone())
            .send()
    };
    let plain = sample(&http_client()).await.unwrap();
    assert!(plain.content_length().is_none(), "sent in pieces");
    let plain: Value = plain.json().await.unwrap();
    assert_eq!(plain["poses"].as_array().unwrap().len(), 9001);
    for coding in CODINGS {
        for _ in 0..2 {
            let resp = sample(&decoding(coding)).await.unwrap();
            assert_eq!(resp.status(), 200);
            assert_eq!(resp.json::<Value>().await.unwrap(), plain, "{coding}");
        }
    }
    app.stop().await;
}
