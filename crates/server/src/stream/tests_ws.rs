//! The WebSocket loop driven through in-memory channels on a paused clock.

use std::convert::Infallible;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use axum::extract::ws::{CloseFrame, Message};
use futures_util::{Sink, Stream};
use glam::Vec3;
use tokio::sync::mpsc;

use super::ws::{WsConfig, close, serve};
use super::*;
use anim::{Channel, Clip, ClipSpec, Interpolation, Keys, Playback, TrackSpec};

/// One end of an in-memory WebSocket: what the server sends goes to `out`,
/// what the test sends comes from `inc`.
struct MemSocket {
    out: mpsc::UnboundedSender<Message>,
    inc: mpsc::UnboundedReceiver<Message>,
}

impl Stream for MemSocket {
    type Item = Result<Message, Infallible>;
    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Self::Item>> {
        self.inc.poll_recv(cx).map(|m| m.map(Ok))
    }
}

impl super::ws::FrameSocket for MemSocket {}

impl Sink<Message> for MemSocket {
    type Error = Infallible;
    fn poll_ready(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<Result<(), Infallible>> {
        Poll::Ready(Ok(()))
    }
    fn start_send(self: Pin<&mut Self>, item: Message) -> Result<(), Infallible> {
        let _ = self.out.send(item);
        Ok(())
    }
    fn poll_flush(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<Result<(), Infallible>> {
        Poll::Ready(Ok(()))
    }
    fn poll_close(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<Result<(), Infallible>> {
        Poll::Ready(Ok(()))
    }
}

/// The client's end.
struct Client {
    to_server: mpsc::UnboundedSender<Message>,
    from_server: mpsc::UnboundedReceiver<Message>,
    task: tokio::task::JoinHandle<()>,
}

impl Client {
    async fn recv(&mut self) -> Message {
        self.from_server.recv().await.expect("the server hung up without a close frame")
    }

    async fn json_frame(&mut self) -> serde_json::Value {
        match self.recv().await {
            Message::Text(t) => serde_json::from_str(&t).unwrap(),
            other => panic!("expected a text frame, got {other:?}"),
        }
    }

    fn send(&self, text: &str) {
        self.to_server.send(Message::Text(text.into())).unwrap();
    }

    async fn close_frame(&mut self) -> CloseFrame {
        loop {
            match self.recv().await {
                Message::Close(Some(f)) => return f,
                Message::Close(None) => panic!("a close frame without a reason"),
                _ => {}
            }
        }
    }
}

fn clip() -> Arc<Clip> {
    let track = TrackSpec::new(
        "root",
        Channel::Translation,
        Interpolation::Linear,
        vec![0.0, 10.0],
        Keys::Vec3(vec![Vec3::ZERO, Vec3::new(10.0, 0.0, 0.0)]),
    );
    let spec = ClipSpec {
        name: "l".into(),
        skeleton: None,
        tracks: vec![track],
        events: vec![],
        playback: Playback::Once,
        ..Default::default()
    };
    Arc::new(Clip::build(&spec).unwrap())
}

fn connect(engine: &Engine, req: StreamRequest, config: WsConfig) -> Client {
    let (out_tx, out_rx) = mpsc::unbounded_channel();
    let (in_tx, in_rx) = mpsc::unbounded_channel();
    let params = StreamParams::new(super::tests::pinned("c1", clip()), req).unwrap();
    let sub = engine.watch(params, engine.admit(None).unwrap(), None);
    let task = tokio::spawn(serve(MemSocket { out: out_tx, inc: in_rx }, sub, config, None));
    Client { to_server: in_tx, from_server: out_rx, task }
}

fn req(fps: u32, encoding: Encoding, max_frames: u64) -> StreamRequest {
    StreamRequest { fps, encoding, max_frames, ..Default::default() }
}

const KEEPALIVE: WsConfig = WsConfig { keepalive: Duration::from_secs(3600) };

#[tokio::test(start_paused = true)]
async fn json_text_frames_then_a_normal_close_after_max_frames() {
    let e = Engine::new(EngineConfig::default());
    let mut c = connect(&e, req(10, Encoding::Json, 3), KEEPALIVE);
    for k in 0..3u64 {
        let v = c.json_frame().await;
        assert_eq!(v["seq"], k);
        assert_eq!(v["dropped"], 0);
        let x = v["pose"]["joints"][0]["translation"][0].as_f64().unwrap();
        assert!((x - k as f64 / 10.0).abs() < 1e-6);
    }
    let f = c.close_frame().await;
    assert_eq!((f.code, f.reason.as_str()), (close::NORMAL, "max_frames reached"));
    c.task.await.unwrap();
    assert_eq!(e.active_streams(), 0, "the slot is free once the loop ends");
}

#[tokio::test(start_paused = true)]
async fn protobuf_frames_are_binary() {
    use prost::Message as _;
    let e = Engine::new(EngineConfig::default());
    let mut c = connect(&e, req(10, Encoding::Protobuf, 2), KEEPALIVE);
    for k in 0..2 {
        match c.recv().await {
            Message::Binary(b) => assert_eq!(formats::wire::proto::pb::Frame::decode(b).unwrap().seq, k),
            other => panic!("expected binary, got {other:?}"),
        }
    }
}

#[tokio::test(start_paused = true)]
async fn control_messages_act_on_the_next_frame_and_bad_ones_get_an_error() {
    let e = Engine::new(EngineConfig::default());
    let mut c = connect(&e, req(10, Encoding::Json, 0), KEEPALIVE);
    assert_eq!(c.json_frame().await["seq"], 0);
    c.send(r#"{"op":"seek","time":5}"#);
    let v = c.json_frame().await;
    assert_eq!((v["seq"].as_u64(), v["clip_time"].as_f64()), (Some(1), Some(5.0)));
    c.send(r#"{"op":"pause"}"#);
    assert_eq!(c.json_frame().await["clip_time"], 5.0);
    assert_eq!(c.json_frame().await["clip_time"], 5.0);
    c.send(r#"{"op":"speed","speed":-10}"#);
    c.send(r#"{"op":"play"}"#);
    assert_eq!(c.json_frame().await["clip_time"], 4.0);
    c.send(r#"{"op":"warp"}"#);
    let err = c.json_frame().await;
    assert_eq!(err["error"]["code"], "bad_control");
    c.send(r#"{"op":"speed","speed":1e9}"#);
    assert_eq!(c.json_frame().await["error"]["code"], "bad_control");
    let v = c.json_frame().await;
    assert_eq!(v["clip_time"], 3.0, "the stream went on");
    c.send(r#"{"op":"stop"}"#);
    let f = c.close_frame().await;
    assert_eq!((f.code, f.reason.as_str()), (close::NORMAL, "stopped"));
}

#[tokio::test(start_paused = true)]
async fn shutdown_closes_with_going_away() {
    let e = Engine::new(EngineConfig::default());
    let mut c = connect(&e, req(10, Encoding::Json, 0), KEEPALIVE);
    c.json_frame().await;
    e.shutdown();
    let f = c.close_frame().await;
    assert_eq!(f.code, close::GOING_AWAY);
    c.task.await.unwrap();
    assert!(e.drained(Duration::from_millis(1)).await);
}

#[tokio::test(start_paused = true)]
async fn a_client_that_answers_pings_stays_and_one_that_does_not_is_closed() {
    let e = Engine::new(EngineConfig::default());
    let config = WsConfig { keepalive: Duration::from_secs(2) };
    let mut c = connect(&e, req(1, Encoding::Json, 0), config);
    let mut pings = 0;
    // Ten seconds of a polite client: frames and pings, which it answers.
    while pings < 5 {
        match c.recv().await {
            Message::Ping(p) => {
                pings += 1;
                c.to_server.send(Message::Pong(p)).unwrap();
            }
            Message::Text(_) => {}
            other => panic!("unexpected {other:?}"),
        }
    }
    // Now it stops answering: closed at the next keepalive tick.
    let f = c.close_frame().await;
    assert_eq!((f.code, f.reason.as_str()), (close::POLICY, "keepalive timeout"));
    c.task.await.unwrap();
}
