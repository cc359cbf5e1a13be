//! The same mistake, the same stable code on both protocols: every failure
//! REST and gRPC share, sent both ways to one real server. The expected code
//! and class are written out here from the documented rule (400: the value
//! does not parse; 422: it parses but breaks a rule), not read from the
//! server; the gRPC status must be the one `status_table` pairs with the
//! HTTP status.

use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Error as WsError;
use tonic::transport::Channel;

use formats::wire::proto::pb;
use formats::wire::proto::pb::animation_client::AnimationClient;
use formats::wire::proto::pb::sample_batch_request::When;

use super::status_table::grpc_codes_for;
use super::{TestApp, WAVE};

const MISSING: &str = "01234567-89ab-7def-8123-456789abcdef";
/// The pose limit the server runs with here.
const MAX_POSES: usize = 50;

/// A REST request.
enum Rest {
    Get(String),
    Post(String, Value),
    /// A WebSocket upgrade (the stream route refuses before upgrading).
    Ws(String),
    /// `GET /v1/stream` and this `open` message (refused in an error message).
    WsOpen(Value),
}

/// Its gRPC twin.
enum Rpc {
    Sample(pb::SampleRequest),
    Batch(pb::SampleBatchRequest),
    Stream(pb::StreamRequest),
    List(pb::ListClipsRequest),
    Motion(pb::SampleMotionRequest),
}

struct Case {
    what: &'static str,
    rest: Rest,
    rpc: Rpc,
    code: &'static str,
    status: u16,
}

fn sample(id: &str, edit: impl FnOnce(&mut pb::SampleRequest)) -> Rpc {
    let mut req = pb::SampleRequest { clip_id: id.to_owned(), time: 0.5, ..Default::default() };
    edit(&mut req);
    Rpc::Sample(req)
}

fn batch(id: &str, when: Option<When>, edit: impl FnOnce(&mut pb::SampleBatchRequest)) -> Rpc {
    let mut req = pb::SampleBatchRequest { clip_id: id.to_owned(), when, ..Default::default() };
    edit(&mut req);
    Rpc::Batch(req)
}

fn times(values: Vec<f64>) -> Option<When> {
    Some(When::Times(pb::Times { values }))
}

fn range(start: f64, end: f64, fps: f64) -> Option<When> {
    Some(When::Range(pb::FrameRange { start, end, fps }))
}

fn stream(id: &str, edit: impl FnOnce(&mut pb::StreamRequest)) -> Rpc {
    let mut req = pb::StreamRequest { clip_id: id.to_owned(), fps: 30, max_frames: 1, ..Default::default() };
    edit(&mut req);
    Rpc::Stream(req)
}

fn cases(id: &str) -> Vec<Case> {
    let pose = |q: &str| Rest::Get(format!("/v1/clips/{id}/pose?{q}"));
    let post = |body: Value| Rest::Post(format!("/v1/clips/{id}/sample"), body);
    let ws = |q: &str| Rest::Ws(format!("/v1/clips/{id}/stream?{q}"));
    let case = |what, rest, rpc, code, status| Case { what, rest, rpc, code, status };
    vec![
        // A value that does not parse: 400.
        case("time not a number", pose("t=NaN"), sample(id, |r| r.time = f64::NAN), "bad_number", 400),
        case("time infinite", pose("t=inf"), sample(id, |r| r.time = f64::INFINITY), "bad_number", 400),
        case("bad space", pose("t=0&space=world"), sample(id, |r| r.space = 7), "bad_parameter", 400),
        case("bad playback", pose("t=0&playback=reverse"), sample(id, |r| r.playback = 9), "bad_parameter", 400),
        case("bad ease", pose("t=0&ease=bouncy"), sample(id, |r| r.ease = 9), "bad_parameter", 400),
        case("bad format", pose("t=0&format=euler"), sample(id, |r| r.format = 9), "bad_parameter", 400),
        case(
            "bad space in a batch",
            post(json!({"times": [0], "space": "world"})),
            batch(id, times(vec![0.0]), |r| r.space = 7),
            "bad_parameter",
            400,
        ),
        case(
            "bad format in a batch",
            post(json!({"times": [0], "format": "euler"})),
            batch(id, times(vec![0.0]), |r| r.format = 9),
            "bad_parameter",
            400,
        ),
        case("stream speed NaN", ws("speed=NaN"), stream(id, |r| r.speed = Some(f64::NAN)), "bad_number", 400),
        case(
            "stream start inf",
            ws("start=inf"),
            stream(id, |r| r.start_time = Some(f64::INFINITY)),
            "bad_number",
            400,
        ),
        case("stream bad playback", ws("playback=sideways"), stream(id, |r| r.playback = 9), "bad_parameter", 400),
        case("stream bad space", ws("space=world"), stream(id, |r| r.space = 7), "bad_parameter", 400),
        case(
            "page size over the limit",
            Rest::Get("/v1/clips?limit=5000".into()),
            Rpc::List(pb::ListClipsRequest { limit: 5000, ..Default::default() }),
            "bad_limit",
            400,
        ),
        case(
            "page cursor not a clip id",
            Rest::Get("/v1/clips?cursor=zzz".into()),
            Rpc::List(pb::ListClipsRequest { cursor: "zzz".into(), ..Default::default() }),
            "bad_cursor",
            400,
        ),
        // Well-formed but wrong: 422.
        case("missing times", post(json!({})), batch(id, None, |_| {}), "times_or_range", 422),
        // The protobuf oneof cannot carry both; its nearest mistake is neither.
        case(
            "times and range both",
            post(json!({"times": [0], "start": 0, "end": 1, "fps": 30})),
            batch(id, None, |_| {}),
            "times_or_range",
            422,
        ),
        case(
            "range reversed",
            post(json!({"start": 2, "end": 1, "fps": 30})),
            batch(id, range(2.0, 1.0, 30.0), |_| {}),
            "bad_range",
            422,
        ),
        case(
            "range fps 0",
            post(json!({"start": 0, "end": 1, "fps": 0})),
            batch(id, range(0.0, 1.0, 0.0), |_| {}),
            "fps_out_of_range",
            422,
        ),
        case(
            "range fps 241",
            post(json!({"start": 0, "end": 1, "fps": 241})),
            batch(id, range(0.0, 1.0, 241.0), |_| {}),
            "fps_out_of_range",
            422,
        ),
        case(
            "too many times",
            post(json!({"times": vec![0.5; MAX_POSES + 1]})),
            batch(id, times(vec![0.5; MAX_POSES + 1]), |_| {}),
            "too_many_poses",
            422,
        ),
        case(
            "too many frames",
            post(json!({"start": 0, "end": 10, "fps": 30})),
            batch(id, range(0.0, 10.0, 30.0), |_| {}),
            "too_many_poses",
            422,
        ),
        case(
            "skinning without inverse binds",
            pose("t=0&format=skinning"),
            sample(id, |r| r.format = pb::Format::Skinning as i32),
            "no_inverse_binds",
            422,
        ),
        case(
            "batch skinning without inverse binds",
            post(json!({"times": [0], "format": "skinning"})),
            batch(id, times(vec![0.0]), |r| r.format = pb::Format::Skinning as i32),
            "no_inverse_binds",
            422,
        ),
        case("stream fps 0", ws("fps=0"), stream(id, |r| r.fps = 0), "fps_out_of_range", 422),
        case("stream fps 241", ws("fps=241"), stream(id, |r| r.fps = 241), "fps_out_of_range", 422),
        case("stream speed 5000", ws("speed=5000"), stream(id, |r| r.speed = Some(5000.0)), "speed_out_of_range", 422),
        // An unknown clip: 404.
        case(
            "pose of an unknown clip",
            Rest::Get(format!("/v1/clips/{MISSING}/pose?t=0")),
            sample(MISSING, |_| {}),
            "clip_not_found",
            404,
        ),
        case(
            "batch of an unknown clip",
            Rest::Post(format!("/v1/clips/{MISSING}/sample"), json!({"times": [0]})),
            batch(MISSING, times(vec![0.0]), |_| {}),
            "clip_not_found",
            404,
        ),
        case(
            "stream of an unknown clip",
            Rest::Ws(format!("/v1/clips/{MISSING}/stream")),
            stream(MISSING, |_| {}),
            "clip_not_found",
            404,
        ),
    ]
}

/// The HTTP status and problem `code` of a REST refusal.
async fn rest_refusal(app: &TestApp, rest: &Rest) -> (u16, String) {
    let (status, body) = match rest {
        Rest::Get(path) => {
            let resp = app.http.get(app.url(path)).send().await.unwrap();
            (resp.status().as_u16(), resp.bytes().await.unwrap().to_vec())
        }
        Rest::Post(path, body) => {
            let resp = app.http.post(app.url(path)).json(body).send().await.unwrap();
            (resp.status().as_u16(), resp.bytes().await.unwrap().to_vec())
        }
        Rest::Ws(path) => {
            let url = format!("ws://{}{path}", app.addr);
            match tokio_tungstenite::connect_async(url).await {
                Err(WsError::Http(resp)) => (resp.status().as_u16(), resp.body().clone().unwrap_or_default()),
                other => panic!("{path}: the upgrade should be refused, got {:?}", other.map(drop)),
            }
        }
        Rest::WsOpen(open) => {
            use futures_util::{SinkExt, StreamExt};
            use tokio_tungstenite::tungstenite::Message;
            let mut ws = app.ws("/v1/stream").await;
            ws.send(Message::Text(open.to_string().into())).await.unwrap();
            let Some(Ok(Message::Text(text))) = ws.next().await else { panic!("{open}: no error message") };
            let error: Value = serde_json::from_str(&text).unwrap();
            let status = error["error"]["status"].as_u64().unwrap_or_default() as u16;
            (status, serde_json::to_vec(&error["error"]).unwrap())
        }
    };
    let problem: Value = serde_json::from_slice(&body).unwrap_or_else(|_| panic!("not problem+json: {body:?}"));
    (status, problem["code"].as_str().unwrap_or_default().to_owned())
}

/// The gRPC refusal of `rpc`.
async fn rpc_refusal(grpc: &mut AnimationClient<Channel>, rpc: Rpc) -> tonic::Status {
    let result = match rpc {
        Rpc::Sample(req) => grpc.sample(req).await.map(drop),
        Rpc::Batch(req) => grpc.sample_batch(req).await.map(drop),
        Rpc::Stream(req) => grpc.stream_frames(req).await.map(drop),
        Rpc::List(req) => grpc.list_clips(req).await.map(drop),
        Rpc::Motion(req) => grpc.sample_motion(req).await.map(drop),
    };
    result.expect_err("the call should be refused")
}

#[tokio::test]
async fn every_shared_failure_has_one_code_on_both_protocols() {
    let app = TestApp::builder().configure(|c| c.limits.max_poses = MAX_POSES).start().await;
    let id = app.create_id(WAVE, None).await;
    let mut grpc = app.grpc().await;
    let cases = cases(&id);
    assert!(cases.len() >= 25);
    for case in cases {
        let (status, code) = rest_refusal(&app, &case.rest).await;
        assert_eq!((status, code.as_str()), (case.status, case.code), "{}: REST", case.what);
        let refused = rpc_refusal(&mut grpc, case.rpc).await;
        let grpc_code = refused.metadata().get("x-error-code").map(|v| v.to_str().unwrap().to_owned());
        assert_eq!(grpc_code.as_deref(), Some(case.code), "{}: gRPC {refused:?}", case.what);
        assert!(refused.message().starts_with(&format!("{}: ", case.code)), "{}: {}", case.what, refused.message());
        assert!(
            grpc_codes_for(status).contains(&refused.code()),
            "{}: HTTP {status} but gRPC {:?}",
            case.what,
            refused.code()
        );
    }
    app.stop().await;
}

/// The cost model's refusals (issue 15), one code on both protocols:
/// checked on servers whose limits the small example clip can reach.
#[tokio::test]
async fn the_cost_refusals_have_one_code_on_both_protocols() {
    let cost_cases = |id: &str| {
        let post = |body: Value| Rest::Post(format!("/v1/clips/{id}/sample"), body);
        let ws = |q: &str| Rest::Ws(format!("/v1/clips/{id}/stream?{q}"));
        let case = |what, rest, rpc, code, status| Case { what, rest, rpc, code, status };
        vec![
            // 10,000 poses × 2 joints: over max_joint_poses (10,000).
            case(
                "poses × joints over the work limit",
                post(json!({"start": 0, "end": 9999, "fps": 1})),
                batch(id, range(0.0, 9999.0, 1.0), |_| {}),
                "too_many_poses",
                422,
            ),
            // 200 poses: over 4 KiB as JSON (~100 KB) and as protobuf (~16 KB).
            case(
                "answer over max_answer_bytes",
                post(json!({"start": 0, "end": 199, "fps": 1})),
                batch(id, range(0.0, 199.0, 1.0), |_| {}),
                "answer_too_large",
                422,
            ),
            case("frame over max_frame_bytes", ws("fps=1"), stream(id, |r| r.fps = 1), "frame_too_large", 422),
        ]
    };
    let app = TestApp::builder()
        .configure(|c| {
            c.limits.max_joint_poses = 10_000;
            c.limits.max_answer_bytes = 4096;
            c.limits.max_frame_bytes = 64;
        })
        .start()
        .await;
    let id = app.create_id(WAVE, None).await;
    check_both_ways(&app, cost_cases(&id)).await;
    app.stop().await;

    // A frame of the example clip is a few hundred bytes: 30 of them a second are over 1,000 bytes/s.
    let app = TestApp::builder().configure(|c| c.limits.max_stream_bytes_per_sec = 1000).start().await;
    let id = app.create_id(WAVE, None).await;
    let ws = Rest::Ws(format!("/v1/clips/{id}/stream?fps=30"));
    let rate = Case {
        what: "stream over its byte rate",
        rest: ws,
        rpc: stream(&id, |_| {}),
        code: "stream_rate_too_high",
        status: 422,
    };
    check_both_ways(&app, vec![rate]).await;
    app.stop().await;
}

/// Composed motions (docs/motion.md): `POST /v1/poses` and `SampleMotion` refuse
/// the same mistakes with the same codes.
#[tokio::test]
async fn the_motion_refusals_have_one_code_on_both_protocols() {
    let app = TestApp::start().await;
    let id = app.create_id(WAVE, None).await;
    let layer = |weight: Option<f32>, mask: Option<(&str, f32)>, clip: &str| {
        let rest = json!({"clip": clip, "weight": weight.unwrap_or(1.0),
                          "mask": mask.map(|(j, w)| json!({"joints": {j: w}})).unwrap_or(json!({"default": 1}))});
        let mask = mask.map(|(j, w)| pb::Mask { joints: [(j.to_owned(), w)].into(), ..Default::default() });
        let rpc = pb::Layer { clip_id: clip.to_owned(), weight, mask, ..Default::default() };
        (rest, rpc)
    };
    // Each mistake three ways: a pose (POST /v1/poses, SampleMotion) and a
    // stream (the WebSocket's open message, StreamFrames).
    let case = |what, layers: Vec<(Value, pb::Layer)>, joints: Vec<&str>, code, status| {
        let (rest_layers, rpc_layers): (Vec<Value>, Vec<pb::Layer>) = layers.into_iter().unzip();
        let body = json!({"motion": {"layers": rest_layers}, "time": 0.5, "joints": joints});
        let motion = Some(pb::Motion { layers: rpc_layers, ..Default::default() });
        let joints: Vec<String> = joints.iter().map(|j| (*j).to_owned()).collect();
        let req =
            pb::SampleMotionRequest { motion: motion.clone(), time: 0.5, joints: joints.clone(), ..Default::default() };
        let open = json!({"op": "open", "motion": body["motion"], "joints": body["joints"], "max_frames": 1});
        let stream = pb::StreamRequest { fps: 30, max_frames: 1, motion, joints, ..Default::default() };
        [
            Case { what, rest: Rest::Post("/v1/poses".into(), body), rpc: Rpc::Motion(req), code, status },
            Case { what, rest: Rest::WsOpen(open), rpc: Rpc::Stream(stream), code, status },
        ]
    };
    let all = vec!["root", "arm"];
    let cases = vec![
        case("a weight over 1", vec![layer(Some(1.5), None, &id)], all.clone(), "weight_out_of_range", 422),
        case(
            "a mask joint not in the skeleton",
            vec![layer(None, Some(("tail", 1.0)), &id)],
            all.clone(),
            "unknown_joint",
            422,
        ),
        case("a subset joint not in the skeleton", vec![layer(None, None, &id)], vec!["tail"], "unknown_joint", 422),
        case("no layers", vec![], all.clone(), "no_layers", 422),
        case("a layer's clip that does not exist", vec![layer(None, None, MISSING)], all, "clip_not_found", 404),
    ];
    check_both_ways(&app, cases.into_iter().flatten().collect()).await;
    app.stop().await;
}

async fn check_both_ways(app: &TestApp, cases: Vec<Case>) {
    let mut grpc = app.grpc().await;
    for case in cases {
        let (status, code) = rest_refusal(app, &case.rest).await;
        assert_eq!((status, code.as_str()), (case.status, case.code), "{}: REST", case.what);
        let refused = rpc_refusal(&mut grpc, case.rpc).await;
        let grpc_code = refused.metadata().get("x-error-code").map(|v| v.to_str().unwrap().to_owned());
        assert_eq!(grpc_code.as_deref(), Some(case.code), "{}: gRPC {refused:?}", case.what);
        assert!(
            grpc_codes_for(status).contains(&refused.code()),
            "{}: HTTP {status} but gRPC {:?}",
            case.what,
            refused.code()
        );
    }
}
