//! The stream caps, per client address and global, for both transports.

use tonic::Code;

use super::websocket::{close_frame, next_frame};
use super::{TestApp, WAVE, stream_request, within};

#[tokio::test]
async fn too_many_streams_get_resource_exhausted_and_a_close_with_a_reason() {
    let app = TestApp::builder()
        .configure(|c| {
            c.limits.max_streams = 3;
            c.limits.max_streams_per_client = 2;
        })
        .start()
        .await;
    let id = app.create_id(WAVE, None).await;
    let mut grpc = app.grpc().await;
    let mut a = grpc.stream_frames(stream_request(&id, 10, 1.0)).await.unwrap().into_inner();
    let mut ws = app.ws(&format!("/v1/clips/{id}/stream?fps=10")).await;
    within(5, "a", a.message()).await.unwrap().unwrap();
    next_frame(&mut ws).await;

    // This client (127.0.0.1) holds 2 streams: the third is refused.
    let err = grpc.stream_frames(stream_request(&id, 10, 1.0)).await.unwrap_err();
    assert_eq!(err.code(), Code::ResourceExhausted);
    assert!(err.message().contains("too_many_streams"), "{}", err.message());
    let mut refused = app.ws(&format!("/v1/clips/{id}/stream?fps=10")).await;
    let (code, reason) = close_frame(&mut refused).await;
    assert_eq!(code, 1013, "try again later");
    assert!(reason.contains("per-client"), "{reason}");

    // A slot frees when a stream ends.
    drop(a);
    let mut again = None;
    for _ in 0..50 {
        match grpc.stream_frames(stream_request(&id, 10, 1.0)).await {
            Ok(s) => {
                again = Some(s.into_inner());
                break;
            }
            Err(e) => {
                assert_eq!(e.code(), Code::ResourceExhausted);
                tokio::task::yield_now().await;
                // The server notices the cancelled stream at its next tick.
                let _ = within(5, "a frame on the open socket", next_frame(&mut ws)).await;
            }
        }
    }
    let mut again = again.expect("the slot was freed");
    within(5, "a frame", again.message()).await.unwrap().unwrap();
}
