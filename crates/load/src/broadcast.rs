//! `ws-broadcast` setup: the one broadcast (docs/broadcasts.md) whose viewers the run
//! opens, created over REST before the viewers and deleted after them, and
//! the server's broadcast counters from `/metrics`.
//!
//! The broadcast plays the run's clip (as a one-layer motion) or its
//! `--motion`; the viewers are opened by `streams` like any WebSocket
//! stream, on `GET /v1/broadcasts/{id}/stream`. Lateness needs nothing
//! new: a viewer's `seq` is the broadcast's tick, one grid tick per `seq`,
//! and the watch answer carries the grid phase, so `lateness` puts frame
//! `k` on the broadcast's grid time for `k`.

use anyhow::{Context, bail};
use reqwest::Url;
use serde_json::{Value, json};

/// How long a broadcast the load generator left behind (a killed run)
/// lives on without viewers.
const IDLE_TIMEOUT_SECS: u32 = 60;

/// The motion a broadcast of `clip_id` alone plays.
pub fn clip_motion(clip_id: &str) -> Value {
    json!({"layers": [{"clip": clip_id}]})
}

/// `POST /v1/broadcasts` of `motion` at `fps`; returns its id.
pub async fn create(http: &Url, motion: &Value, fps: u32) -> anyhow::Result<String> {
    let url = http.join("/v1/broadcasts")?;
    let body = json!({"motion": motion, "fps": fps, "idle_timeout_secs": IDLE_TIMEOUT_SECS});
    let resp = reqwest::Client::new()
        .post(url.clone())
        .json(&body)
        .send()
        .await
        .with_context(|| format!("creating the broadcast at {url}"))?;
    let status = resp.status();
    let reply: Value = resp.json().await.context("reading the broadcast reply")?;
    if status != 201 {
        bail!("creating the broadcast: {status}: {reply}");
    }
    reply["id"].as_str().map(str::to_owned).context("the broadcast reply has no id")
}

/// `DELETE /v1/broadcasts/{id}`: its viewers are closed with 1000. A
/// failure is only logged: the idle timeout ends it anyway.
pub async fn delete(http: &Url, id: &str) {
    let Ok(url) = http.join(&format!("/v1/broadcasts/{id}")) else { return };
    match reqwest::Client::new().delete(url).send().await {
        Ok(r) if r.status() == 204 => {}
        Ok(r) => tracing::warn!(status = %r.status(), id, "deleting the load broadcast"),
        Err(e) => tracing::warn!(error = %e, id, "deleting the load broadcast"),
    }
}

/// The server's broadcast counters: (broadcasts created, broadcast ticks
/// evaluated); `None` if `/metrics` cannot be read.
pub async fn counters(http: &Url) -> Option<(u64, u64)> {
    let text = reqwest::get(http.join("/metrics").ok()?).await.ok()?.text().await.ok()?;
    Some((read_counter(&text, "inbetween_broadcasts_total"), read_counter(&text, "inbetween_broadcast_ticks_total")))
}

/// The value of the unlabelled sample `name` in a Prometheus text page (0 if absent).
pub fn read_counter(text: &str, name: &str) -> u64 {
    text.lines()
        .find(|l| l.split([' ', '{']).next() == Some(name))
        .and_then(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
        .map_or(0, |v| v as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counters_are_read_by_exact_name() {
        let page = "# TYPE inbetween_broadcasts_total counter\ninbetween_broadcasts_total 3\n\
                    inbetween_broadcast_ticks_total 1250\ninbetween_broadcasts 1\n";
        assert_eq!(read_counter(page, "inbetween_broadcasts_total"), 3);
        assert_eq!(read_counter(page, "inbetween_broadcast_ticks_total"), 1250);
        assert_eq!(read_counter(page, "inbetween_broadcasts"), 1);
        assert_eq!(read_counter(page, "inbetween_broadcast_viewers"), 0);
    }

    #[test]
    fn a_clip_is_broadcast_as_a_one_layer_motion() {
        assert_eq!(clip_motion("c1"), json!({"layers": [{"clip": "c1"}]}));
    }
}
