//! Unary modes: `grpc-sample`, `grpc-ping`, `rest-pose`, `rest-health`.
//!
//! Closed loop (default): each worker sends its next request when the
//! previous one is answered; latency is the request's round trip. Open loop
//! (`rate`): worker `w` of `C` owns the scheduled instants
//! `start + (w + i·C)/rate`; it sends each at its instant (or at once if it
//! is behind) and measures latency from the *scheduled* instant, so time a
//! request spent waiting behind a slow one counts — the coordinated-omission
//! correction of wrk2 and HdrHistogram.
//!
//! Each worker records into its own histogram; they are merged at the end.
//! Request times sweep the clip (`t = (i mod 997) · 3 ms`), so the server
//! really samples a different pose each time.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use tokio::time::Instant;
use tonic::transport::Channel;

use super::histogram::Latency;
use super::report::{Report, ServerUsage};
use super::{Env, Mode, Options, procstat, setup};
use formats::wire::proto::pb;
use formats::wire::proto::pb::animation_client::AnimationClient;

/// How long after the window requests scheduled inside it are still sent.
const DEADLINE_GRACE: Duration = Duration::from_secs(1);
/// A request that takes longer counts as a `timeout` error.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(10);

/// One worker's way of making a request.
enum Caller {
    GrpcSample(AnimationClient<Channel>, String),
    GrpcPing(AnimationClient<Channel>),
    Rest(reqwest::Client, String),
}

impl Caller {
    /// Makes request number `i`; `Err` names the kind of failure.
    async fn call(&mut self, i: u64) -> Result<(), String> {
        let t = (i % 997) as f64 * 0.003;
        match self {
            Caller::GrpcSample(client, clip_id) => {
                let req = pb::SampleRequest { clip_id: clip_id.clone(), time: t, ..Default::default() };
                client.sample(req).await.map(drop).map_err(|s| format!("grpc:{:?}", s.code()))
            }
            Caller::GrpcPing(client) => {
                client.ping(pb::PingRequest {}).await.map(drop).map_err(|s| format!("grpc:{:?}", s.code()))
            }
            Caller::Rest(client, url) => {
                let url = if url.ends_with("t=") { format!("{url}{t}") } else { url.clone() };
                let resp = client.get(url).send().await.map_err(|e| reqwest_kind(&e))?;
                let status = resp.status();
                // The whole body is read: a response counts once it has arrived.
                resp.bytes().await.map_err(|e| reqwest_kind(&e))?;
                if status.is_success() { Ok(()) } else { Err(format!("http:{}", status.as_u16())) }
            }
        }
    }
}

fn reqwest_kind(e: &reqwest::Error) -> String {
    if e.is_connect() {
        "connect".into()
    } else if e.is_timeout() {
        "timeout".into()
    } else {
        "io".into()
    }
}

#[derive(Default)]
struct WorkerResult {
    latency: Latency,
    ok: u64,
    errors: BTreeMap<String, u64>,
}

impl WorkerResult {
    fn merge(&mut self, o: WorkerResult) {
        self.latency.merge(&o.latency);
        self.ok += o.ok;
        for (k, v) in o.errors {
            *self.errors.entry(k).or_default() += v;
        }
    }
}

pub async fn run(opts: &Options, env: &Env, workers: usize) -> anyhow::Result<Report> {
    let connections = match opts.mode {
        Mode::RestPose | Mode::RestHealth => workers,
        _ if opts.connections == 0 => workers,
        _ => opts.connections.min(workers),
    };
    let mut callers = callers(opts, env, workers, connections).await?;
    // One request per worker before the clock starts: connections are open
    // and the clip is in the server's cache.
    for (w, caller) in callers.iter_mut().enumerate() {
        if let Err(kind) = caller.call(w as u64).await {
            anyhow::bail!("the first {} request failed: {kind}", opts.mode.as_str());
        }
    }

    let server_before = env.server_pid.and_then(procstat::sample);
    let client_before = procstat::sample_self();
    let start = Instant::now();
    let plan = Plan {
        start,
        deadline: start + opts.duration,
        workers,
        limit: opts.requests,
        rate: opts.rate,
        issued: Arc::new(AtomicU64::new(0)),
    };
    let tasks: Vec<_> =
        callers.into_iter().enumerate().map(|(w, caller)| tokio::spawn(worker(w, caller, plan.clone()))).collect();
    let mut total = WorkerResult::default();
    for task in tasks {
        total.merge(task.await?);
    }
    let elapsed = start.elapsed().as_secs_f64();
    let server_after = env.server_pid.and_then(procstat::sample);
    let client_after = procstat::sample_self();

    let server = match (env.server_pid, server_before, server_after) {
        (Some(pid), Some(b), Some(a)) => Some(ServerUsage {
            pid,
            rss_before_bytes: b.rss_bytes,
            rss_end_bytes: a.rss_bytes,
            rss_per_stream_bytes: None,
            cpu_cores: (a.cpu_secs - b.cpu_secs) / elapsed,
            cpu_us_per_op: (a.cpu_secs - b.cpu_secs) * 1e6 / total.ok.max(1) as f64,
        }),
        _ => None,
    };
    Ok(Report {
        mode: opts.mode.as_str(),
        started_unix: super::clock::unix_now_ns() as f64 / 1e9 - elapsed,
        http: env.http.to_string(),
        grpc: env.grpc.to_string(),
        clip_id: env.clip_id.clone(),
        motion: None,
        joints: None,
        concurrency: workers,
        connections,
        rate: opts.rate,
        elapsed_secs: elapsed,
        ok: total.ok,
        throughput: total.ok as f64 / elapsed,
        latency: Some(total.latency.summary()),
        streams: None,
        errors: total.errors,
        server,
        client_cpu_cores: client_before.zip(client_after).map(|(b, a)| (a.cpu_secs - b.cpu_secs) / elapsed),
        loadavg: None,
        ramp: None,
        floor: None,
    })
}

/// One caller per worker: gRPC workers share `connections` channels
/// round-robin; each REST worker has its own keep-alive connection.
async fn callers(opts: &Options, env: &Env, workers: usize, connections: usize) -> anyhow::Result<Vec<Caller>> {
    let mut callers = Vec::with_capacity(workers);
    match opts.mode {
        Mode::GrpcSample | Mode::GrpcPing => {
            let channels = setup::channels(&env.grpc, connections).await?;
            for w in 0..workers {
                let client = AnimationClient::new(channels[w % connections].clone());
                callers.push(match opts.mode {
                    Mode::GrpcSample => Caller::GrpcSample(client, env.clip_id.clone()),
                    _ => Caller::GrpcPing(client),
                });
            }
        }
        _ => {
            let url = match opts.mode {
                Mode::RestPose => format!("{}v1/clips/{}/pose?t=", env.http, env.clip_id),
                _ => format!("{}healthz", env.http),
            };
            for _ in 0..workers {
                // One client per worker: one keep-alive connection each. No
                // Accept-Encoding even where reqwest's decoders are compiled in
                // (test builds): the figures are of the uncompressed path.
                let client =
                    reqwest::Client::builder().pool_max_idle_per_host(1).no_gzip().no_brotli().no_zstd().build()?;
                callers.push(Caller::Rest(client, url.clone()));
            }
        }
    }
    Ok(callers)
}

/// The schedule every worker shares: the window, the request budget and,
/// in open loop, the rate.
#[derive(Clone)]
struct Plan {
    start: Instant,
    deadline: Instant,
    workers: usize,
    /// `--requests`: the total over all workers.
    limit: Option<u64>,
    /// `--rate`: open loop.
    rate: Option<f64>,
    /// Requests taken so far, over all workers.
    issued: Arc<AtomicU64>,
}

/// Worker `w`'s loop: requests until the window or the budget ends,
/// timed from their scheduled instant (see the module doc).
async fn worker(w: usize, mut caller: Caller, plan: Plan) -> WorkerResult {
    let Plan { start, deadline, workers, limit, rate, issued } = plan;
    let mut out = WorkerResult::default();
    let mut i = 0u64;
    loop {
        let n = issued.fetch_add(1, Ordering::Relaxed);
        if limit.is_some_and(|max| n >= max) {
            break;
        }
        let scheduled = match rate {
            Some(r) => {
                let at = start + Duration::from_secs_f64((w as f64 + (i * workers as u64) as f64) / r);
                tokio::time::sleep_until(at).await;
                at
            }
            None => Instant::now(),
        };
        if scheduled >= deadline {
            break;
        }
        // Bounded in time: a request scheduled inside the window is
        // still sent (and its wait counted) for a grace second after
        // it; past that, those the server was too slow to let us
        // send are counted, not sent.
        if let Some(r) = rate
            && Instant::now() >= deadline + DEADLINE_GRACE
        {
            let left = ((deadline - start).as_secs_f64() * r) as u64;
            let unsent = (left.saturating_sub(w as u64)).div_ceil(workers as u64).saturating_sub(i);
            *out.errors.entry("unsent_past_deadline".into()).or_default() += unsent;
            break;
        }
        i += 1;
        match tokio::time::timeout(REQUEST_TIMEOUT, caller.call(n)).await {
            Ok(Ok(())) => {
                out.latency.record(scheduled.elapsed());
                out.ok += 1;
            }
            Ok(Err(kind)) => *out.errors.entry(kind).or_default() += 1,
            Err(_) => *out.errors.entry("timeout".into()).or_default() += 1,
        }
    }
    out
}
