//! What a run needs before the load starts: the clip, the gRPC channels, a
//! clock sync, and the server's stream counters.

use anyhow::{Context, bail};
use reqwest::Url;
use serde_json::Value;
use tonic::transport::Channel;

use super::chain::chain_clip;
use super::clock::{ClockSync, PingSample, unix_now_ns};
use super::motion::{LayerClips, MotionChoice, MotionClips, clip_docs};
use super::walk::walk_clip;
use formats::wire::proto::pb;
use formats::wire::proto::pb::animation_client::AnimationClient;

/// Uploads [`chain_clip`] and returns its id.
pub async fn upload_chain(http: &Url, joints: usize) -> anyhow::Result<String> {
    upload_clip(http, &chain_clip(joints)).await
}

/// Uploads the clips `choice` plays, `joints` joints each.
pub async fn upload_motion_clips(http: &Url, choice: MotionChoice, joints: usize) -> anyhow::Result<MotionClips> {
    Ok(match choice {
        MotionChoice::ThreeLayers => MotionClips::ThreeLayers(upload_layer_clips(http, joints).await?),
        MotionChoice::FootIk => MotionClips::FootIk { walk: upload_clip(http, &walk_clip(joints)).await? },
    })
}

/// Uploads the clips of the three-layer motion (`motion::clip_docs`).
async fn upload_layer_clips(http: &Url, joints: usize) -> anyhow::Result<LayerClips> {
    let [walk, run, upper] = clip_docs(joints);
    Ok(LayerClips {
        walk: upload_clip(http, &walk).await?,
        run: upload_clip(http, &run).await?,
        upper: upload_clip(http, &upper).await?,
    })
}

/// Uploads a clip document and returns its id: a new version of the clip
/// of that name when an earlier run left it (names identify clips).
pub async fn upload_clip(http: &Url, clip: &Value) -> anyhow::Result<String> {
    let url = http.join("/v1/clips?replace=true")?;
    let resp = reqwest::Client::new()
        .post(url.clone())
        .json(clip)
        .send()
        .await
        .with_context(|| format!("uploading the load clip to {url}"))?;
    let status = resp.status();
    let body: Value = resp.json().await.context("reading the upload reply")?;
    if status != 201 && status != 200 {
        bail!("uploading the load clip: {status}: {body}");
    }
    body["id"].as_str().map(str::to_owned).context("the upload reply has no id")
}

/// `n` HTTP/2 connections to the gRPC server.
pub async fn channels(grpc: &Url, n: usize) -> anyhow::Result<Vec<Channel>> {
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let ch = Channel::from_shared(grpc.to_string())?
            .connect()
            .await
            .with_context(|| format!("connecting to the gRPC server at {grpc}"))?;
        out.push(ch);
    }
    Ok(out)
}

/// Pings the server a few times and keeps the best estimate (see `clock`).
pub async fn clock_sync(channel: Channel) -> anyhow::Result<ClockSync> {
    let mut client = AnimationClient::new(channel);
    let mut samples = Vec::new();
    for _ in 0..16 {
        let local_sent = unix_now_ns();
        let reply = client.ping(pb::PingRequest {}).await.context("Ping for the clock sync")?.into_inner();
        let local_received = unix_now_ns();
        samples.push(PingSample {
            local_sent,
            local_received,
            server_unix: reply.server_unix_nanos,
            server_monotonic: reply.server_monotonic_nanos,
        });
    }
    ClockSync::from_samples(&samples).context("no ping answered")
}

/// The server's stream counters from `/metrics`: (playbacks started, ticks
/// evaluated); `None` if they cannot be read.
pub async fn stream_counters(http: &Url) -> Option<(u64, u64)> {
    let text = reqwest::get(http.join("/metrics").ok()?).await.ok()?.text().await.ok()?;
    let read = |name: &str| {
        text.lines()
            .find(|l| l.split([' ', '{']).next() == Some(name))
            .and_then(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
            .map(|v| v as u64)
    };
    Some((read("inbetween_stream_playbacks_total").unwrap_or(0), read("inbetween_stream_ticks_total").unwrap_or(0)))
}
