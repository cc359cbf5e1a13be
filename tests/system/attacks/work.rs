//! Work with no price: one chain IK constraint over a 4,096-joint chain
//! (1.8 KB of JSON) once cost 8.7 s of CPU per pose; four such requests took
//! `/healthz` and `Ping` down for most of 40 s and ran on after their
//! clients left; a refused 4,096-joint stream open cost 7.9 ms, forty
//! poses' worth, so 1,024 refusals stalled the probes for 9–20 s. Now every
//! request is priced from counts before it runs (docs/api.md, “Work and its
//! price”), runs on work threads bounded by the cores at a lower priority
//! than the probes, and stops when its client leaves.

use std::time::{Duration, Instant};

use futures_util::future::join_all;
use serde_json::{Value, json};

use super::{Target, target};
use crate::common::chain_clip;

/// `n` chain constraints over the whole chain, `iterations` at most each.
fn chains(n: usize, iterations: u32) -> Value {
    let one = json!({"kind": "chain", "effectors": [{"joint": "j4095", "target": [50, 50, 0]}],
                     "max_iterations": iterations, "tolerance": 1e-9});
    Value::Array(vec![one; n])
}

fn chain_ik(iterations: u32) -> Value {
    chains(1, iterations)
}

/// The server's CPU time so far (user + system), from `/proc/PID/stat`.
fn cpu(target: &Target) -> Duration {
    let stat = std::fs::read_to_string(format!("/proc/{}/stat", target.server.pid())).unwrap_or_default();
    // Fields after the command's closing parenthesis: utime is the 12th, stime the 13th.
    let fields: Vec<&str> = stat.rsplit_once(')').map_or("", |(_, rest)| rest).split_whitespace().collect();
    let ticks = |i: usize| fields.get(i).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    // In USER_HZ ticks, which Linux fixes at 100 per second for /proc.
    Duration::from_millis((ticks(11) + ticks(12)) * 10)
}

#[tokio::test(flavor = "multi_thread")]
async fn ik_chains_over_4096_joints_are_refused_by_their_price() {
    let mut target = target(&[]).await;
    let http = crate::common::http_client();
    let id = target.server.create(&http, &chain_clip(4096, json!([]))).await;
    let body = json!({"motion": {"layers": [{"clip": id}], "ik": chains(4, 1000)}, "time": 0.5}).to_string();
    let probes = target.probes().await;
    let until = Instant::now() + Duration::from_secs(2);
    let attacker = |http: reqwest::Client, url: String, body: String| async move {
        let mut refusals = 0u32;
        while Instant::now() < until {
            let resp = http.post(&url).header("content-type", "application/json").body(body.clone()).send().await;
            let resp = resp.unwrap();
            assert_eq!(resp.status(), 422);
            let problem: Value = resp.json().await.unwrap();
            assert_eq!(problem["code"], "too_much_work", "{problem}");
            refusals += 1;
        }
        refusals
    };
    let url = target.server.url("/v1/poses");
    let refusals: u32 = join_all((0..4).map(|_| attacker(http.clone(), url.clone(), body.clone()))).await.iter().sum();
    let report = probes.finish();
    println!("FIGURE {refusals} refusals of a 1,000-iteration chain over 4,096 joints in 2 s");
    assert!(refusals >= 40, "only {refusals} refusals in 2 s: work was done before refusing");
    target.assert_survived("IK chains over 4,096 joints", &report);
}

/// Four requests each within the price limit, from one caller: one runs,
/// the others are told to come back (the caller's share); the probes keep
/// answering while it runs, and clients that leave stop their work.
#[tokio::test(flavor = "multi_thread")]
async fn four_heavy_pose_requests_share_the_node_and_stop_when_abandoned() {
    let mut target = target(&[]).await;
    let http = crate::common::http_client();
    let id = target.server.create(&http, &chain_clip(4096, json!([]))).await;
    // The largest budget the default price limit admits, halving from 1,000.
    let url = target.server.url("/v1/poses");
    let body = |iterations: u32| json!({"motion": {"layers": [{"clip": id}], "ik": chain_ik(iterations)}, "time": 0.5});
    let mut iterations = 1000;
    loop {
        let resp = http.post(&url).json(&body(iterations)).timeout(Duration::from_millis(200)).send().await;
        match resp {
            Ok(r) if r.status() == 422 => iterations /= 2,
            _ => break,
        }
        assert!(iterations >= 1, "no budget was admitted");
    }
    let probes = target.probes().await;
    let started = Instant::now();
    // Each client gives up after 5 s, as an impatient caller would.
    let requests = (0..4).map(|_| {
        let (http, url, body) = (http.clone(), url.clone(), body(iterations));
        async move {
            match http.post(&url).json(&body).timeout(Duration::from_secs(5)).send().await {
                Ok(resp) => {
                    let status = resp.status().as_u16();
                    let code = resp.json::<Value>().await.ok().and_then(|p| p["code"].as_str().map(str::to_owned));
                    (status, code.unwrap_or_default())
                }
                Err(e) if e.is_timeout() => (0, "left".to_owned()),
                Err(e) => panic!("{e}"),
            }
        }
    });
    let answers = join_all(requests).await;
    let report = probes.finish();
    for (status, code) in &answers {
        let documented = matches!(
            (status, code.as_str()),
            (200, _) | (429, "caller_work_limit") | (503, "overloaded") | (0, "left")
        );
        assert!(documented, "an undocumented answer: {status} {code}");
    }
    let refused = answers.iter().filter(|(s, _)| *s == 429 || *s == 503).count();
    assert!(refused >= 2, "one caller ran more than its share at once: {answers:?}");
    // Work whose client left stops: the CPU stops climbing.
    let idle = || async {
        let before = cpu(&target);
        let _ = reqwest::get(target.server.url("/healthz")).await;
        tokio::time::sleep(Duration::from_millis(200)).await;
        cpu(&target) - before < Duration::from_millis(100)
    };
    crate::common::eventually(Duration::from_secs(5), "the abandoned work stops", idle).await;
    println!(
        "FIGURE 4 heavy pose requests ({iterations} iterations over 4,096 joints): {answers:?} in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    target.assert_survived("4 heavy pose requests", &report);
}

#[tokio::test(flavor = "multi_thread")]
async fn refused_heavy_stream_opens_cost_less_than_a_pose() {
    let mut target = target(&[]).await;
    let http = crate::common::http_client();
    let heavy = target.server.create(&http, &chain_clip(4096, chains(4, 1000))).await;
    let plain = target.server.create(&http, &chain_clip(4096, json!([]))).await;
    // What one pose of the plain clip costs the server.
    let poses = 64;
    let before = cpu(&target);
    for _ in 0..poses {
        let resp = http.get(target.server.url(&format!("/v1/clips/{plain}/pose?t=0.5"))).send().await.unwrap();
        assert_eq!(resp.status(), 200);
        resp.bytes().await.unwrap();
    }
    let per_pose = (cpu(&target) - before) / poses;
    let probes = target.probes().await;
    let opens = 1024;
    let path = format!("/v1/clips/{heavy}/stream?fps=30");
    let before = (cpu(&target), Instant::now());
    for _ in 0..opens {
        match tokio_tungstenite::connect_async(target.server.ws_url(&path)).await {
            Err(tokio_tungstenite::tungstenite::Error::Http(resp)) => {
                assert_eq!(resp.status().as_u16(), 422);
                let problem: Value = serde_json::from_slice(&resp.into_body().unwrap_or_default()).unwrap();
                assert_eq!(problem["code"], "too_much_work", "{problem}");
            }
            other => panic!("the heavy stream was not refused: {:?}", other.map(|_| ())),
        }
    }
    let (per_refusal, took) = ((cpu(&target) - before.0) / opens, before.1.elapsed());
    let report = probes.finish();
    println!(
        "FIGURE {opens} refused 4,096-joint stream opens in {:.1} s: {:.2} ms of server CPU each; one pose {:.2} ms",
        took.as_secs_f64(),
        per_refusal.as_secs_f64() * 1e3,
        per_pose.as_secs_f64() * 1e3
    );
    assert!(per_refusal < per_pose, "a refusal ({per_refusal:?}) costs more than a pose ({per_pose:?})");
    target.assert_survived("1,024 refused heavy stream opens", &report);
}
