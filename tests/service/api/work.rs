//! Work has a price (docs/api.md, “Work and its price”): IK priced by its
//! iteration budget over the chain's joints, whether a request asks for it
//! or a clip keys it, refused before it runs; work that outlives the
//! request's timeout, or whose client leaves, stops at once; a caller over
//! its share of the node is told 429, the node over its capacity 503.

use std::time::{Duration, Instant};

use formats::wire::proto::pb;
use serde_json::{Value, json};
use tonic::Code;

use super::TestApp;
use crate::common::{chain_clip, eventually};

/// `n` chain constraints on the last of `joints` joints toward a point
/// out of reach, `iterations` at most each.
fn chains(n: usize, joints: usize, iterations: u32) -> Value {
    let one = json!({"kind": "chain", "effectors": [{"joint": format!("j{}", joints - 1), "target": [50, 50, 0]}],
                     "max_iterations": iterations, "tolerance": 1e-9});
    Value::Array(vec![one; n])
}

fn chain_ik(joints: usize, iterations: u32) -> Value {
    chains(1, joints, iterations)
}

fn motion(id: &str, ik: Value) -> Value {
    json!({"layers": [{"clip": id}], "ik": ik})
}

async fn post(app: &TestApp, path: &str, body: &Value) -> (u16, Value) {
    let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
    (resp.status().as_u16(), resp.json().await.unwrap_or(Value::Null))
}

/// A WebSocket open refused before the upgrade: its status and code.
async fn ws_refusal(app: &TestApp, path: &str) -> (u16, String) {
    match tokio_tungstenite::connect_async(app.ws_url(path)).await {
        Err(tokio_tungstenite::tungstenite::Error::Http(resp)) => {
            let status = resp.status().as_u16();
            let problem: Value = serde_json::from_slice(&resp.into_body().unwrap_or_default()).unwrap();
            (status, problem["code"].as_str().unwrap_or_default().to_owned())
        }
        other => panic!("the stream was not refused: {:?}", other.map(|_| ())),
    }
}

fn grpc_error_code(status: &tonic::Status) -> String {
    status.metadata().get("x-error-code").map(|v| v.to_str().unwrap().to_owned()).unwrap_or_default()
}

/// [`chain_ik`] as a gRPC motion.
/// The chain constraint's point target mirrored in x.
fn flip_x(constraint: &mut pb::IkConstraint) {
    use pb::ik_constraint::Kind;
    use pb::ik_target::Target;
    let Some(Kind::Chain(chain)) = &mut constraint.kind else { return };
    for effector in &mut chain.effectors {
        if let Some(pb::IkTarget { target: Some(Target::Point(point)) }) = &mut effector.target {
            point.x = -point.x;
        }
    }
}

fn motion_pb(id: &str, joints: usize, iterations: u32) -> pb::Motion {
    let target = pb::Vec3 { x: 50.0, y: 50.0, z: 0.0 };
    let effector = pb::IkEffector {
        joint: format!("j{}", joints - 1),
        target: Some(pb::IkTarget { target: Some(pb::ik_target::Target::Point(target)) }),
        tip: None,
    };
    let chain = pb::IkChain {
        effectors: vec![effector],
        max_iterations: Some(iterations),
        tolerance: Some(1e-9),
        ..Default::default()
    };
    pb::Motion {
        layers: vec![pb::Layer { clip_id: id.to_owned(), ..Default::default() }],
        ik: vec![pb::IkConstraint { kind: Some(pb::ik_constraint::Kind::Chain(chain)) }],
        ..Default::default()
    }
}

/// The request, four times over: chains over 4,096 joints at the
/// largest iteration budget, a few KB of JSON, once seconds of CPU per pose.
#[tokio::test]
async fn a_chain_over_4096_joints_is_refused_before_it_runs() {
    let app = TestApp::start().await;
    let id = app.create_id(&chain_clip(4096, json!([])), None).await;
    let started = Instant::now();
    let body = json!({"motion": motion(&id, chains(4, 4096, 1000)), "time": 0.5});
    let (status, problem) = post(&app, "/v1/poses", &body).await;
    assert_eq!((status, problem["code"].as_str()), (422, Some("too_much_work")), "{problem}");
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.contains("work units") && detail.contains("max_request_work"), "{detail}");
    assert!(started.elapsed() < Duration::from_secs(5), "refused after {:?}", started.elapsed());
    let mut motion = motion_pb(&id, 4096, 1000);
    motion.ik = vec![motion.ik[0].clone(); 32];
    let request = pb::SampleMotionRequest { motion: Some(motion), time: 0.5, ..Default::default() };
    let refused = app.grpc().await.sample_motion(request).await.unwrap_err();
    assert_eq!((refused.code(), grpc_error_code(&refused).as_str()), (Code::InvalidArgument, "too_much_work"));
    assert_eq!(app.state.work.pool().steps(), 0, "no pose was evaluated");
}

/// IK keyed in a clip uploads in a moment and is priced at every read.
#[tokio::test]
async fn ik_keyed_in_a_clip_is_priced_when_read() {
    let app = TestApp::start().await;
    let id = app.create_id(&chain_clip(4096, chains(4, 4096, 1000)), None).await;
    let resp = app.http.get(app.url(&format!("/v1/clips/{id}/pose?t=0.5"))).send().await.unwrap();
    assert_eq!(resp.status(), 422);
    let problem: Value = resp.json().await.unwrap();
    assert_eq!(problem["code"], "too_much_work", "{problem}");
    let request = pb::SampleRequest { clip_id: id.clone(), time: 0.5, ..Default::default() };
    let refused = app.grpc().await.sample(request).await.unwrap_err();
    assert_eq!(grpc_error_code(&refused), "too_much_work", "{refused:?}");
    // A stream of it is priced per second of playback, refused before the upgrade.
    assert_eq!(ws_refusal(&app, &format!("/v1/clips/{id}/stream?fps=30")).await, (422, "too_much_work".into()));
    assert_eq!(app.state.work.pool().steps(), 0, "no pose was evaluated");
}

/// One pose of 32 chains over 4,096 joints toward points out of reach,
/// on alternate sides (x = ±50), so that every solve starts far from its
/// target and runs its iterations: many seconds of work on any machine.
fn heavy_pose(id: &str) -> Value {
    let mut ik = chains(32, 4096, 1000);
    for chain in ik.as_array_mut().unwrap().iter_mut().skip(1).step_by(2) {
        chain["effectors"][0]["target"] = json!([-50, 50, 0]);
    }
    json!({"motion": motion(id, ik), "time": 0.5})
}

/// A server that admits the heavy request (its price is within the limit),
/// with a 4,096-joint chain stored in `dir` (uploaded under the default
/// timeout: its build takes a while in a debug build).
async fn generous(dir: &std::path::Path, timeout_secs: u64) -> (TestApp, String) {
    let id = {
        let app = TestApp::builder().data_dir(dir).write_token("w").start().await;
        let id = app.create_id(&chain_clip(4096, json!([])), Some("w")).await;
        app.stop().await;
        id
    };
    let app = TestApp::builder()
        .data_dir(dir)
        .write_token("w")
        .configure(|c| {
            c.limits.max_request_work = u64::MAX;
            c.limits.request_timeout = Duration::from_secs(timeout_secs);
        })
        .start()
        .await;
    // Loaded (and built) before the clock of any timed request starts.
    assert_eq!(app.http.get(app.url(&format!("/v1/clips/{id}/skeleton"))).send().await.unwrap().status(), 200);
    (app, id)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn work_past_the_request_timeout_is_answered_503_and_stops() {
    let dir = tempfile::tempdir().unwrap();
    let (app, id) = generous(dir.path(), 2).await;
    let (status, problem) = post(&app, "/v1/poses", &heavy_pose(&id)).await;
    assert_eq!((status, problem["code"].as_str()), (503, Some("request_timeout")), "{problem}");
    let answered = Instant::now();
    let pool = app.state.work.pool();
    eventually(Duration::from_secs(2), "the abandoned work stops", || async { pool.cancelled() >= 1 }).await;
    eprintln!("the work stopped {:?} after the 503", answered.elapsed());
    assert_eq!(app.state.work.meter().held(), 0, "its price was given back");
    // gRPC: DEADLINE_EXCEEDED, the same code.
    let mut motion = motion_pb(&id, 4096, 1000);
    motion.ik = vec![motion.ik[0].clone(); 32];
    for constraint in motion.ik.iter_mut().skip(1).step_by(2) {
        flip_x(constraint);
    }
    let request = pb::SampleMotionRequest { motion: Some(motion), time: 0.5, ..Default::default() };
    let refused = app.grpc().await.sample_motion(request).await.unwrap_err();
    assert_eq!((refused.code(), grpc_error_code(&refused).as_str()), (Code::DeadlineExceeded, "request_timeout"));
    eventually(Duration::from_secs(2), "the gRPC work stops too", || async { pool.cancelled() >= 2 }).await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_leaves_stops_its_work() {
    let dir = tempfile::tempdir().unwrap();
    let (app, id) = generous(dir.path(), 30).await;
    let pool = app.state.work.pool();
    let request = app.http.post(app.url("/v1/poses")).json(&heavy_pose(&id)).send();
    let left = tokio::time::timeout(Duration::from_millis(500), request).await;
    assert!(left.is_err(), "the request was still running when its client left");
    let since = Instant::now();
    eventually(Duration::from_secs(2), "the work stops", || async { pool.cancelled() >= 1 }).await;
    eprintln!("the work stopped {:?} after its client left", since.elapsed());
    assert_eq!(app.state.work.meter().held(), 0);
    app.stop().await;
}

/// While one caller's heavy request runs, its next is 429; another
/// caller's is 503 once the node's capacity is held; both say when to
/// come back. Stream opens get the same codes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn callers_share_the_node_and_the_node_has_a_capacity() {
    let app = TestApp::builder()
        .write_token("w")
        .configure(|c| {
            c.limits.max_request_work = u64::MAX;
            c.limits.node_work_per_sec = 1_000_000;
        })
        .start()
        .await;
    let id = app.create_id(&chain_clip(4096, json!([])), Some("w")).await;
    let meter = app.state.work.meter();
    let heavy = app.http.post(app.url("/v1/poses")).bearer_auth("w").json(&heavy_pose(&id)).send();
    let running = tokio::spawn(heavy);
    // Its pose's price, the node's whole capacity and more (its motion's
    // build, before, holds far less).
    let holds = || async { meter.held() > 1_000_000 };
    eventually(Duration::from_secs(5), "the heavy request holds its price", holds).await;
    let light = json!({"motion": motion(&id, json!([])), "time": 0.5});
    let resp = app.http.post(app.url("/v1/poses")).bearer_auth("w").json(&light).send().await.unwrap();
    assert_eq!(resp.status(), 429);
    assert_eq!(resp.headers()["retry-after"], "1");
    let problem: Value = resp.json().await.unwrap();
    assert_eq!(problem["code"], "caller_work_limit", "{problem}");
    // Anonymous: another caller (its address), on a node whose capacity is held.
    let heavier = json!({"motion": motion(&id, chain_ik(4096, 10)), "time": 0.5});
    let resp = app.http.post(app.url("/v1/poses")).json(&heavier).send().await.unwrap();
    assert_eq!(resp.status(), 503);
    assert!(resp.headers().contains_key("retry-after"));
    let problem: Value = resp.json().await.unwrap();
    assert_eq!(problem["code"], "overloaded", "{problem}");
    let request = pb::SampleMotionRequest { motion: Some(motion_pb(&id, 4096, 10)), time: 0.5, ..Default::default() };
    let refused = app.grpc().await.sample_motion(request).await.unwrap_err();
    assert_eq!((refused.code(), grpc_error_code(&refused).as_str()), (Code::Unavailable, "overloaded"));
    let refused = ws_refusal(&app, &format!("/v1/clips/{id}/stream?fps=60")).await;
    assert_eq!(refused, (503, "overloaded".into()), "a stream open is charged too");
    running.abort();
    eventually(Duration::from_secs(5), "the node is free again", || async { meter.held() == 0 }).await;
    app.stop().await;
}
