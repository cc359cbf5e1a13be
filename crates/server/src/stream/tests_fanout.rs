//! The broadcast fan-out (`fanout`, `lane`) on a paused clock: a parked
//! WebSocket viewer's frames are written by the fan-out with the very `seq`,
//! `dropped` and bytes its task sends; a socket that cannot take a frame
//! hands the viewer back to its task without a gap, and the fan-out takes
//! it again once the socket can; the end reaches a parked viewer.

use std::convert::Infallible;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::extract::ws::{Message, Utf8Bytes};
use futures_util::{Sink, Stream};
use serde_json::Value::Null;
use tokio::sync::mpsc;

use super::tests::{clip, pinned};
use super::ws::{FrameSocket, WsConfig, close, serve};
use super::*;

/// What the server sent, and whether the fan-out wrote it.
type Sent = (Message, bool);

/// An in-memory socket whose direct writer (the fan-out's way in) sends to
/// the same place as its task's messages.
struct MemSocket {
    out: mpsc::UnboundedSender<Sent>,
    inc: mpsc::UnboundedReceiver<Message>,
    writer: Arc<MemWriter>,
}

struct MemWriter {
    out: mpsc::UnboundedSender<Sent>,
    /// Takes no frame while set (as a socket with bytes still queued).
    busy: AtomicBool,
}

impl DirectWrite for MemWriter {
    fn try_frame(&self, encoding: Encoding, frame: &mut dyn FnMut() -> bytes::Bytes) -> Direct {
        assert_eq!(encoding, Encoding::Json);
        if self.busy.load(Ordering::SeqCst) {
            return Direct::Busy;
        }
        let _ = self.out.send((Message::Text(Utf8Bytes::try_from(frame()).unwrap()), true));
        Direct::Written
    }

    fn idle(&self) -> bool {
        !self.busy.load(Ordering::SeqCst)
    }
}

impl FrameSocket for MemSocket {
    fn direct(&self) -> Option<Arc<dyn DirectWrite>> {
        Some(Arc::clone(&self.writer) as Arc<dyn DirectWrite>)
    }
}

impl Stream for MemSocket {
    type Item = Result<Message, Infallible>;
    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Self::Item>> {
        self.inc.poll_recv(cx).map(|m| m.map(Ok))
    }
}

impl Sink<Message> for MemSocket {
    type Error = Infallible;
    fn poll_ready(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<Result<(), Infallible>> {
        Poll::Ready(Ok(()))
    }
    fn start_send(self: Pin<&mut Self>, item: Message) -> Result<(), Infallible> {
        let _ = self.out.send((item, false));
        Ok(())
    }
    fn poll_flush(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<Result<(), Infallible>> {
        Poll::Ready(Ok(()))
    }
    fn poll_close(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<Result<(), Infallible>> {
        Poll::Ready(Ok(()))
    }
}

/// The next frame the socket got: its `seq`, `dropped`, bytes, and whether
/// the fan-out wrote it.
async fn next_frame(out: &mut mpsc::UnboundedReceiver<Sent>) -> (u64, u64, bytes::Bytes, bool) {
    match out.recv().await.expect("the server hung up") {
        (Message::Text(text), direct) => {
            let v: serde_json::Value = serde_json::from_str(&text).unwrap();
            let bytes = bytes::Bytes::copy_from_slice(text.as_bytes());
            (v["seq"].as_u64().unwrap(), v["dropped"].as_u64().unwrap(), bytes, direct)
        }
        other => panic!("expected a JSON frame, got {other:?}"),
    }
}

#[tokio::test(start_paused = true)]
async fn a_parked_viewer_gets_from_the_fanout_what_its_task_would_send_and_its_end() {
    let e = Engine::new(EngineConfig { max_streams: 10, max_streams_per_client: 10, ..Default::default() });
    let params = StreamParams::new(pinned("c1", clip()), StreamRequest { fps: 30, ..Default::default() }).unwrap();
    let spec = BroadcastSpec { params, idle_timeout: Duration::from_secs(60), description: Null, work_per_sec: 0 };
    let b = e.broadcasts().create(spec, BroadcastCharge::free()).unwrap();
    // Two viewers from the same tick: one through the fan-out, one read here as its task would.
    let mut reference = b.watch(Encoding::Json, e.admit(None).unwrap(), None);
    let (out_tx, mut out) = mpsc::unbounded_channel();
    let (_to_server, inc) = mpsc::unbounded_channel();
    let writer = Arc::new(MemWriter { out: out_tx.clone(), busy: AtomicBool::new(false) });
    let socket = MemSocket { out: out_tx, inc, writer: Arc::clone(&writer) };
    let task =
        tokio::spawn(serve(socket, b.watch(Encoding::Json, e.admit(None).unwrap(), None), WsConfig::default(), None));

    let mut expect = None;
    let mut by_fanout = Vec::new();
    for i in 0..60 {
        // Frames 20..30 find the socket busy: the task sends them.
        writer.busy.store((20..30).contains(&i), Ordering::SeqCst);
        let (seq, dropped, bytes, direct) = next_frame(&mut out).await;
        let Next::Frame(want) = reference.next().await else { panic!("the reference viewer ended") };
        assert_eq!((seq, dropped), (expect.unwrap_or(seq), 0), "frame {i}: no gap, whoever sent it");
        assert_eq!((seq, &bytes), (want.seq, &want.bytes), "frame {i}: the bytes the task sends");
        expect = Some(seq + 1);
        by_fanout.push(direct);
    }
    // The first frame is the task's; from the next on the fan-out writes them,
    // except while the socket is busy (and the first frame after, which
    // the task sends before parking again).
    assert!(!by_fanout[0] && by_fanout[2..20].iter().all(|&d| d), "{by_fanout:?}");
    assert!(by_fanout[21..30].iter().all(|&d| !d), "{by_fanout:?}");
    assert!(by_fanout[32..].iter().all(|&d| d), "{by_fanout:?}");

    assert!(e.broadcasts().delete(b.id()));
    loop {
        match out.recv().await.expect("a close frame") {
            (Message::Close(Some(f)), _) => {
                assert_eq!(f.code, close::NORMAL);
                break;
            }
            (Message::Text(_), _) => {}
            other => panic!("unexpected {other:?}"),
        }
    }
    task.await.unwrap();
}
