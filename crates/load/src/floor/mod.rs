//! The streaming floor (issue 19): the least work that can deliver the
//! server's frames, measured in the same invocation as the server scenario.
//!
//! `inbetween load --floor` takes one frame the server sent (the whole frame,
//! so the floor sends the same size and content), starts this module's bare
//! sender as its own process (`inbetween load-floor`, a hidden subcommand) so
//! that its CPU can be read from `/proc` alone, and runs the same number of
//! streams at the same fps and duration against it with the same receive
//! code (`streams`). The report puts the floor's CPU per delivered frame
//! beside the server's: the ratio is how much the server spends per frame
//! beyond what any sender of those bytes must (evaluation, encoding, HTTP/2
//! or WebSocket bookkeeping, copies, scheduling).
//!
//! The sender itself is `sender`; this module starts it and measures it.

use std::path::Path;
use std::time::Duration;

use anyhow::Context;
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};

use crate::clock::ClockSync;
use crate::report::Report;
use crate::streams;
use crate::{Env, Options};
use sender::Hello;

pub(crate) mod sender;

pub use crate::report::FloorReport;
pub use sender::{Kind, MAX_COPIES, Tally, Target, Template, run_sender, serve, ws_header};

/// Measures the floor of a finished server run (module doc): `bin` is the
/// `inbetween` binary that serves as the floor process.
pub async fn measure(opts: &Options, env: &Env, n: usize, bin: &Path, server: &Report) -> anyhow::Result<FloorReport> {
    let kind = Kind::of(opts);
    let frame = streams::sample_frame(opts, env).await.context("taking a frame from the server for the floor")?;
    let mut child = tokio::process::Command::new(bin)
        .args(["load-floor", "--kind", kind.as_str(), "--fps", &opts.fps.to_string()])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .with_context(|| format!("starting the floor: {}", bin.display()))?;
    let pid = child.id().context("the floor exited at once")?;
    let mut stdin = child.stdin.take().context("the floor's stdin")?;
    stdin.write_all(&(frame.len() as u32).to_be_bytes()).await?;
    stdin.write_all(&frame).await?;
    stdin.flush().await?;
    let mut lines = BufReader::new(child.stdout.take().context("the floor's stdout")?).lines();
    let hello = lines.next_line().await?.context("the floor stopped before saying its port")?;
    let hello: Hello = serde_json::from_str(&hello).with_context(|| format!("the floor said {hello:?}"))?;
    let clock = ClockSync { offset_ns: 0, rtt_ns: 0, grid_epoch_unix_ns: hello.epoch_unix_ns };
    let target = Target { port: hello.port, pid, clock };
    let run = streams::run(opts, env, n, Some(&target)).await;
    drop(stdin);
    let sent = match tokio::time::timeout(Duration::from_secs(10), lines.next_line()).await {
        Ok(Ok(Some(line))) => serde_json::from_str::<Tally>(&line).ok(),
        _ => None,
    };
    let _ = tokio::time::timeout(Duration::from_secs(5), child.wait()).await;
    let run = run?;
    let streams = run.streams.as_ref().context("a stream run reports its streams")?;
    let usage = run.server.as_ref();
    let cpu_us_per_frame = usage.map_or(f64::NAN, |u| u.cpu_us_per_op);
    let server_us = server.server.as_ref().map(|u| u.cpu_us_per_op);
    Ok(FloorReport {
        kind: kind.as_str(),
        frame_bytes: frame.len(),
        streams: n,
        opened: streams.opened,
        connections: run.connections,
        elapsed_secs: run.elapsed_secs,
        frames: run.ok,
        frames_per_stream_per_sec: streams.frames_per_stream_per_sec,
        loss_ratio: streams.loss_ratio,
        send_lateness: streams.send_lateness,
        receive_lateness: streams.receive_lateness,
        cpu_cores: usage.map_or(f64::NAN, |u| u.cpu_cores),
        cpu_us_per_frame,
        server_to_floor: server_us.filter(|_| cpu_us_per_frame > 0.0).map(|s| s / cpu_us_per_frame),
        client_cpu_cores: run.client_cpu_cores,
        sent,
        errors: run.errors,
    })
}
