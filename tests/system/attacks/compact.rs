//! Compact frames as a lever (docs/compact-frames.md): the tightest bound
//! (`max_error` 1e-6) at the shortest `distance` (1 cm) needs the widest
//! channels, and choosing a layout samples the whole clip. Many such
//! streams of a deep 512-joint chain, every joint turning, held open,
//! while other clients open and close compact streams as fast as they can:
//! each layout and each frame is priced before it runs (and the layout
//! chosen on the work threads), so what does not fit is refused with a
//! documented code and the prober stays within its budget.

use std::time::{Duration, Instant};

use futures_util::StreamExt;
use futures_util::future::join_all;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::target;

type Ws = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

const JOINTS: usize = 512;
/// Compact streams held open, each read.
const HELD: usize = 16;
/// Clients opening and closing compact streams.
const CHURNERS: usize = 8;
const ATTACK: Duration = Duration::from_secs(6);

/// A chain of `JOINTS` joints, each turning about z over 10 s (three keys).
fn turning_chain() -> String {
    let skeleton: Vec<Value> = (0..JOINTS)
        .map(|j| {
            json!({"name": format!("j{j}"), "parent": j.checked_sub(1).map(|p| format!("j{p}")),
                        "rest": {"translation": [0, 0.01, 0]}})
        })
        .collect();
    let (s, c) = (0.05f64.sin(), 0.05f64.cos());
    let tracks: Vec<Value> = (0..JOINTS)
        .map(|j| {
            json!({"joint": format!("j{j}"), "channel": "rotation", "interpolation": "linear",
                        "times": [0, 5, 10], "values": [[0, 0, 0, 1], [0, 0, s, c], [0, 0, 0, 1]]})
        })
        .collect();
    json!({"name": "turning-chain", "skeleton": {"joints": skeleton}, "tracks": tracks}).to_string()
}

/// What one open of a compact stream got: its first binary frame, or the
/// refusal's code (before the upgrade: the problem's; after: the close reason).
async fn open_compact(url: &str) -> Result<Ws, String> {
    match tokio_tungstenite::connect_async(url).await {
        Ok((ws, _)) => Ok(ws),
        Err(tokio_tungstenite::tungstenite::Error::Http(resp)) => {
            let body = resp.body().as_deref().unwrap_or_default();
            let problem: Value = serde_json::from_slice(body).unwrap_or(Value::Null);
            Err(problem["code"].as_str().unwrap_or("no code").to_owned())
        }
        Err(e) => Err(format!("connect: {e}")),
    }
}

/// Reads until a binary frame (`Ok`) or a close (its reason).
async fn first_frame(ws: &mut Ws) -> Result<(), String> {
    loop {
        match tokio::time::timeout(Duration::from_secs(10), ws.next()).await {
            Ok(Some(Ok(Message::Binary(_)))) => return Ok(()),
            Ok(Some(Ok(Message::Close(frame)))) => return Err(frame.map_or("closed".into(), |f| f.reason.to_string())),
            Ok(Some(Ok(_))) => {}
            Ok(Some(Err(e))) => return Err(format!("read: {e}")),
            Ok(None) => return Err("ended".into()),
            Err(_) => return Err("no frame within 10 s".into()),
        }
    }
}

/// The codes a refused compact stream may carry: the work limits and the stream caps.
fn documented(code: &str) -> bool {
    ["too_much_work", "caller_work_limit", "overloaded", "too_many_streams", "stream_rate_too_high", "frame_too_large"]
        .iter()
        .any(|known| code.contains(known))
}

#[tokio::test(flavor = "multi_thread")]
async fn compact_streams_at_the_tightest_bound_are_priced_and_the_probes_hold() {
    let mut target = target(&[]).await;
    let http = crate::common::http_client();
    let id = target.server.create(&http, &turning_chain()).await;
    let url = target.server.ws_url(&format!(
        "/v1/clips/{id}/stream?encoding=compact&max_error=0.000001&distance=0.01&fps=10&playback=loop"
    ));
    let probes = target.probes().await;
    let started = Instant::now();
    // The held streams, each read on its own task until the attack ends.
    let held = (0..HELD).map(|_| {
        let url = url.clone();
        async move {
            let mut ws = match open_compact(&url).await {
                Ok(ws) => ws,
                Err(code) => return (0u64, Some(code)),
            };
            if let Err(reason) = first_frame(&mut ws).await {
                return (0, Some(reason));
            }
            let mut frames = 1u64;
            while started.elapsed() < ATTACK {
                match tokio::time::timeout(Duration::from_secs(5), ws.next()).await {
                    Ok(Some(Ok(Message::Binary(_)))) => frames += 1,
                    Ok(Some(Ok(_))) => {}
                    other => return (frames, Some(format!("{other:?}"))),
                }
            }
            (frames, None)
        }
    });
    // The churners: open, take the first frame (or the refusal), close, again.
    let churn = (0..CHURNERS).map(|_| {
        let url = url.clone();
        async move {
            let (mut opened, mut refused) = (0u32, Vec::new());
            while started.elapsed() < ATTACK {
                match open_compact(&url).await {
                    Ok(mut ws) => match first_frame(&mut ws).await {
                        Ok(()) => {
                            opened += 1;
                            let _ = ws.close(None).await;
                        }
                        Err(reason) => refused.push(reason),
                    },
                    Err(code) => refused.push(code),
                }
            }
            (opened, refused)
        }
    });
    let (held, churned) = tokio::join!(join_all(held), join_all(churn));
    let report = probes.finish();

    let streamed: u64 = held.iter().map(|(frames, _)| frames).sum();
    let opened: u32 = churned.iter().map(|(n, _)| n).sum();
    let refusals: Vec<&String> =
        held.iter().filter_map(|(_, r)| r.as_ref()).chain(churned.iter().flat_map(|(_, r)| r)).collect();
    println!(
        "FIGURE compact attack: {streamed} frames on {HELD} held streams, {opened} churned opens, {} refusals ({:?})",
        refusals.len(),
        refusals.iter().take(3).collect::<Vec<_>>()
    );
    assert!(streamed > 0 || opened > 0, "some compact stream was served");
    for reason in &refusals {
        assert!(documented(reason), "an undocumented refusal: {reason}");
    }
    target.assert_survived("compact streams at the tightest bound", &report);
}
