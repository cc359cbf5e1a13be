//! SIGTERM: readiness flips at once, WebSockets get 1001, gRPC streams end
//! UNAVAILABLE, acknowledged uploads are durable, a request cut off is never
//! acknowledged, and the process exits by the drain deadline even with
//! clients that hold connections open and read nothing.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use formats::wire::proto::pb;
use formats::wire::proto::pb::animation_client::AnimationClient;
use futures_util::StreamExt;
use tokio_tungstenite::tungstenite::Message;

use super::{WAVE, raw_grpc_call, raw_http, read_to_close, start};

const DRAIN_SECS: u64 = 3;

#[tokio::test(flavor = "multi_thread")]
async fn sigterm_drains_streams_and_uploads_and_exits_by_the_deadline() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let drain = DRAIN_SECS.to_string();
    let mut server = start(&data, &["--drain-timeout-secs", &drain]).await;
    let http = crate::common::http_client();
    let id = server.create(&http, WAVE).await;

    // A WebSocket viewer and a gRPC stream, both receiving.
    let (mut ws, _) =
        tokio_tungstenite::connect_async(format!("ws://{}/v1/clips/{id}/stream?fps=30", server.http)).await.unwrap();
    let mut grpc = AnimationClient::connect(format!("http://{}", server.grpc)).await.unwrap();
    let request = pb::StreamRequest { clip_id: id.clone(), fps: 30, speed: Some(1.0), ..Default::default() };
    let mut frames = grpc.stream_frames(request).await.unwrap().into_inner();
    frames.message().await.unwrap().expect("a first gRPC frame");
    // Clients that ignore GOAWAY and hold connections: an HTTP/1 request
    // whose body never comes, a half-sent head, an HTTP/2 call whose message
    // never comes.
    let head = "POST /v1/clips HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 500\r\n\r\n{";
    let mut stuck_upload = raw_http(server.http, head).await;
    let _half_head = raw_http(server.http, "GET /healthz HTTP/1.1\r\nHost: x\r\n").await;
    let _stuck_call = raw_grpc_call(server.grpc, "/inbetween.v1.Animation/Sample").await;

    // Uploaders running through the signal: what they see acknowledged must survive.
    let acked = Arc::new(Mutex::new(Vec::<String>::new()));
    let uploaders: Vec<_> = (0..4)
        .map(|_| {
            let (http, url, acked) = (http.clone(), server.url("/v1/clips"), acked.clone());
            tokio::spawn(async move {
                loop {
                    let body = crate::common::fresh_name(WAVE);
                    let sent = http.post(&url).header("content-type", "application/json").body(body).send().await;
                    match sent {
                        Ok(r) if r.status() == 201 => {
                            let Ok(v) = r.json::<serde_json::Value>().await else { continue };
                            acked.lock().unwrap().push(v["id"].as_str().unwrap().to_owned());
                        }
                        // Pacing the retry of a refused write: not a wait on anything.
                        Ok(_) => tokio::time::sleep(Duration::from_millis(5)).await,
                        Err(_) => return,
                    }
                }
            })
        })
        .collect();
    let uploading = || async { acked.lock().unwrap().len() >= 4 };
    crate::common::eventually(Duration::from_secs(10), "uploads acknowledged before the signal", uploading).await;

    let term = Instant::now();
    server.signal("TERM");
    // Readiness: 503 or refused within 1 s.
    let (probe, readyz) = (crate::common::http_client(), server.url("/readyz"));
    let unready = || async { !probe.get(&readyz).send().await.is_ok_and(|r| r.status() == 200) };
    crate::common::eventually(Duration::from_secs(1), "not ready within 1 s of SIGTERM", unready).await;
    let ready_flipped = term.elapsed();
    // The WebSocket: close 1001.
    let ws_close = tokio::time::timeout(Duration::from_secs(DRAIN_SECS), async {
        while let Some(msg) = ws.next().await {
            if let Ok(Message::Close(frame)) = msg {
                return frame.map(|f| u16::from(f.code));
            }
        }
        None
    })
    .await
    .expect("the WebSocket is closed before the deadline");
    assert_eq!(ws_close, Some(1001));
    // The gRPC stream: UNAVAILABLE.
    let end = tokio::time::timeout(Duration::from_secs(DRAIN_SECS), async {
        loop {
            match frames.message().await {
                Ok(Some(_)) => {}
                Ok(None) => return None,
                Err(status) => return Some(status.code()),
            }
        }
    })
    .await
    .expect("the gRPC stream ends before the deadline");
    assert_eq!(end, Some(tonic::Code::Unavailable));
    // The process exits by the drain deadline (plus scheduling slack).
    let status = server.wait_exit(Duration::from_secs(DRAIN_SECS + 3)).await;
    let exited = term.elapsed();
    let status = status.unwrap_or_else(|| panic!("still running {exited:?} after SIGTERM"));
    assert!(status.success(), "a drained shutdown exits 0, not {status}");
    assert!(
        exited >= Duration::from_secs(DRAIN_SECS) - Duration::from_millis(100),
        "the stuck clients held it to the deadline: {exited:?}"
    );
    for u in uploaders {
        u.await.unwrap();
    }
    // The upload whose body never came was not acknowledged.
    let (reply, closed) = read_to_close(&mut stuck_upload, Duration::from_secs(1)).await;
    let reply = String::from_utf8_lossy(&reply);
    assert!(closed && !reply.contains(" 201 "), "a cut-off upload was acknowledged: {reply}");
    println!(
        "shutdown: ready flipped after {ready_flipped:?}, exit after {exited:?} (drain {DRAIN_SECS} s), {} uploads acked during the run",
        acked.lock().unwrap().len()
    );
    // Every acknowledged upload is there after a restart.
    let server = start(&data, &[]).await;
    let acked = acked.lock().unwrap().clone();
    assert!(!acked.is_empty(), "some uploads were acknowledged");
    for id in &acked {
        let r = http.get(server.url(&format!("/v1/clips/{id}"))).send().await.unwrap();
        assert_eq!(r.status(), 200, "acknowledged clip {id} is missing");
    }
}
