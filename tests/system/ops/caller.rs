//! One caller identity for the write rate limit: a token counts only when
//! the server knows it. On a server without tokens the `Authorization`
//! header means nothing, so a client that invents a fresh bearer token for
//! every write is still one caller, its address, and runs out of budget.
//! With tokens, a known token is one caller from any address. Clients bind
//! 127.0.0.1 and 127.0.0.2 (both loopback) to be two addresses.

use std::net::{IpAddr, Ipv4Addr};

use formats::wire::proto::pb;
use formats::wire::proto::pb::animation_client::AnimationClient;
use server::tokens::{TokenHash, new_token};

use super::{ServerProcess, WAVE, start};

/// The write budget of these servers: a burst of 3, then one per second.
const LIMIT: [&str; 4] = ["--write-rate", "1", "--write-burst", "3"];

fn client_from(last_octet: u8) -> reqwest::Client {
    let local = IpAddr::V4(Ipv4Addr::new(127, 0, 0, last_octet));
    crate::common::http_builder().local_address(local).build().unwrap()
}

/// `POST /v1/clips` of the wave clip (under a fresh name) with `Authorization: Bearer <token>`.
async fn post_with(server: &ServerProcess, http: &reqwest::Client, token: &str) -> reqwest::Response {
    http.post(server.url("/v1/clips"))
        .header("content-type", "application/json")
        .bearer_auth(token)
        .body(crate::common::fresh_name(WAVE))
        .send()
        .await
        .unwrap()
}

/// Asserts a 429 `rate_limited` whose `Retry-After` is the 1 s a token takes
/// to come back at one per second (2 if the clock ticked in between).
async fn assert_rate_limited(response: reqwest::Response) {
    assert_eq!(response.status(), 429);
    let retry: u64 = response.headers()["retry-after"].to_str().unwrap().parse().unwrap();
    assert!((1..=2).contains(&retry), "retry-after {retry}");
    let body: serde_json::Value = response.json().await.unwrap();
    assert_eq!(body["code"], "rate_limited");
}

#[tokio::test(flavor = "multi_thread")]
async fn without_tokens_fresh_bearer_headers_do_not_escape_the_write_limit() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("data"), &LIMIT).await;
    let first = client_from(1);
    for _ in 0..3 {
        assert_eq!(post_with(&server, &first, &new_token().unwrap()).await.status(), 201);
    }
    assert_rate_limited(post_with(&server, &first, &new_token().unwrap()).await).await;
    // The budget is the address's: another address still has its own.
    let second = client_from(2);
    assert_eq!(post_with(&server, &second, &new_token().unwrap()).await.status(), 201);
}

#[tokio::test(flavor = "multi_thread")]
async fn without_tokens_fresh_bearer_metadata_does_not_escape_the_grpc_write_limit() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("data"), &LIMIT).await;
    let mut grpc = AnimationClient::connect(server.grpc_url()).await.unwrap();
    let put = || {
        let spec = formats::wire::json::parse_clip(crate::common::fresh_name(WAVE).as_bytes()).unwrap().1;
        let clip = Some(formats::wire::proto::clip_to_pb(&spec));
        let mut request = tonic::Request::new(pb::PutClipRequest { clip, ..Default::default() });
        let header = format!("Bearer {}", new_token().unwrap());
        request.metadata_mut().insert("authorization", header.parse().unwrap());
        request
    };
    for _ in 0..3 {
        grpc.put_clip(put()).await.unwrap();
    }
    let refused = grpc.put_clip(put()).await.unwrap_err();
    assert_eq!(refused.code(), tonic::Code::ResourceExhausted, "{refused:?}");
    // Nothing was stored by the refused call: three clips, not four.
    let listed = grpc.list_clips(pb::ListClipsRequest::default()).await.unwrap().into_inner();
    assert_eq!(listed.clips.len(), 3);
}

#[tokio::test(flavor = "multi_thread")]
async fn a_known_token_is_one_caller_from_every_address() {
    let dir = tempfile::tempdir().unwrap();
    let token = new_token().unwrap();
    let entry = format!("ci:write:{}", TokenHash::of(token.as_bytes()));
    let flags = [&LIMIT[..], &["--token", &entry]].concat();
    let server = start(&dir.path().join("data"), &flags).await;
    let (first, second) = (client_from(1), client_from(2));
    for _ in 0..3 {
        assert_eq!(post_with(&server, &first, &token).await.status(), 201);
    }
    // The same token from another address draws on the same budget.
    assert_rate_limited(post_with(&server, &second, &token).await).await;
    // A token the server does not know is refused as before, not counted.
    for _ in 0..5 {
        let unknown = post_with(&server, &second, &new_token().unwrap()).await;
        assert_eq!(unknown.status(), 401);
    }
}
