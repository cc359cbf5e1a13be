//! Broadcasts (docs/broadcasts.md) with real clients: viewers joining at different
//! times over WebSocket (JSON and protobuf) and gRPC `Watch` get the same
//! frames for the same `seq`; a control from one caller reaches every viewer
//! at the tick it was told, with poses equal to an independent
//! `POST /v1/poses` at the same motion time; scopes; idle end; delete; the
//! refusals and their codes.
//!
//! The clip moves `j0` along x at 1 unit/s over [0, 10] s, so a frame's x
//! is its motion time (checked by hand as well as against `/v1/poses`).

use std::collections::BTreeMap;
use std::time::Duration;

use formats::wire::proto::pb;
use futures_util::{SinkExt, StreamExt};
use prost::Message as _;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tonic::Streaming;

use super::websocket::close_frame;
use super::{TestApp, line_clip, within};
use crate::common::app::Ws;
use crate::common::{eventually, eventually_some};
use crate::security::{READER, WRITER, scoped_tokens, with_token};

const FPS: u64 = 20;

/// Creates a broadcast of `clip` (with `token`); returns its summary.
async fn create(app: &TestApp, body: Value, token: Option<&str>) -> (u16, Value, Option<String>) {
    let mut req = app.http.post(app.url("/v1/broadcasts")).json(&body);
    if let Some(t) = token {
        req = req.bearer_auth(t);
    }
    let resp = req.send().await.unwrap();
    let status = resp.status().as_u16();
    let location = resp.headers().get("location").map(|v| v.to_str().unwrap().to_owned());
    (status, resp.json().await.unwrap(), location)
}

async fn broadcast_of(app: &TestApp, clip: &str, token: Option<&str>) -> String {
    let (status, body, location) =
        create(app, json!({"motion": {"layers": [{"clip": clip}]}, "fps": FPS}), token).await;
    assert_eq!(status, 201, "{body}");
    let id = body["id"].as_str().unwrap().to_owned();
    assert_eq!(location.as_deref(), Some(format!("/v1/broadcasts/{id}").as_str()));
    id
}

async fn control(app: &TestApp, id: &str, body: Value, token: Option<&str>) -> (u16, Value) {
    let mut req = app.http.post(app.url(&format!("/v1/broadcasts/{id}/controls"))).json(&body);
    if let Some(t) = token {
        req = req.bearer_auth(t);
    }
    let resp = req.send().await.unwrap();
    (resp.status().as_u16(), resp.json().await.unwrap())
}

/// The tick broadcast `id` is at now (its summary's `seq`).
async fn tick(app: &TestApp, id: &str) -> u64 {
    app.get_json(&format!("/v1/broadcasts/{id}")).await["seq"].as_u64().unwrap()
}

/// Waits until broadcast `id` has stepped to tick `seq`.
async fn until_tick(app: &TestApp, id: &str, seq: u64) {
    let what = format!("broadcast {id} at tick {seq}");
    eventually(Duration::from_secs(10), &what, || async { tick(app, id).await >= seq }).await;
}

async fn watch_ws(app: &TestApp, id: &str, query: &str, token: Option<&str>) -> Ws {
    let mut req = app.ws_url(&format!("/v1/broadcasts/{id}/stream{query}")).into_client_request().unwrap();
    if let Some(t) = token {
        req.headers_mut().insert("authorization", format!("Bearer {t}").parse().unwrap());
    }
    let (ws, resp) = within(5, "the upgrade", tokio_tungstenite::connect_async(req)).await.unwrap();
    assert_eq!(resp.status(), 101);
    ws
}

async fn watch_grpc(app: &TestApp, id: &str, token: Option<&str>) -> Streaming<pb::Frame> {
    let req = with_token(pb::WatchRequest { broadcast_id: id.to_owned(), ..Default::default() }, token);
    app.grpc().await.watch(req).await.unwrap().into_inner()
}

/// The next frame message (text or binary), pings skipped.
async fn next_message(ws: &mut Ws) -> Message {
    loop {
        match within(5, "a frame", ws.next()).await.expect("the socket closed").unwrap() {
            Message::Ping(_) | Message::Pong(_) => {}
            Message::Text(t) if t.starts_with("{\"error\"") => panic!("an error message: {t}"),
            msg => return msg,
        }
    }
}

/// (seq, dropped) of a JSON or protobuf frame message.
fn header(msg: &Message) -> (u64, u64) {
    match msg {
        Message::Text(t) => {
            let v: Value = serde_json::from_str(t).unwrap();
            (v["seq"].as_u64().unwrap(), v["dropped"].as_u64().unwrap())
        }
        Message::Binary(b) => {
            let f = pb::Frame::decode(b.clone()).unwrap();
            (f.seq, f.dropped)
        }
        other => panic!("not a frame: {other:?}"),
    }
}

/// A viewer's frames from its first up to seq `until`: seq → (dropped, message).
async fn collect_ws(mut ws: Ws, until: u64) -> (Vec<u64>, BTreeMap<u64, (u64, Message)>) {
    let mut order = Vec::new();
    let mut frames = BTreeMap::new();
    loop {
        let msg = next_message(&mut ws).await;
        let (seq, dropped) = header(&msg);
        order.push(seq);
        frames.insert(seq, (dropped, msg));
        if seq >= until {
            return (order, frames);
        }
    }
}

async fn collect_grpc(mut frames: Streaming<pb::Frame>, until: u64) -> BTreeMap<u64, pb::Frame> {
    let mut out = BTreeMap::new();
    loop {
        let f = within(5, "a gRPC frame", frames.message()).await.unwrap().expect("a frame");
        let seq = f.seq;
        out.insert(seq, f);
        if seq >= until {
            return out;
        }
    }
}

/// A JSON frame's text with its own `dropped` set to 0: what every viewer shares.
fn shared_text(msg: &Message) -> String {
    let Message::Text(t) = msg else { panic!("not text") };
    let at = t.find("\"dropped\":").unwrap() + "\"dropped\":".len();
    let end = at + t[at..].find(|c: char| !c.is_ascii_digit()).unwrap();
    format!("{}0{}", &t[..at], &t[end..])
}

/// A protobuf frame without its per-viewer parts (dropped, first-frame names).
fn shared_pb(mut f: pb::Frame) -> pb::Frame {
    f.dropped = 0;
    if let Some(p) = f.pose.as_mut() {
        p.joint_names.clear();
    }
    f
}

fn json_of(msg: &Message) -> Value {
    let Message::Text(t) = msg else { panic!("not text") };
    serde_json::from_str(t).unwrap()
}

#[tokio::test]
async fn viewers_joining_at_different_times_get_the_same_frames_for_the_same_seq() {
    let app = TestApp::start().await;
    let clip = app.create_id(&line_clip(2), None).await;
    let id = broadcast_of(&app, &clip, None).await;
    let until = 40;
    // Each group joins 8 ticks (400 ms) after the one before.
    let a = tokio::spawn(collect_ws(watch_ws(&app, &id, "", None).await, until));
    let joined = tick(&app, &id).await;
    until_tick(&app, &id, joined + 8).await;
    let b = tokio::spawn(collect_ws(watch_ws(&app, &id, "?encoding=json", None).await, until));
    let d = tokio::spawn(collect_ws(watch_ws(&app, &id, "?encoding=protobuf", None).await, until));
    let joined = tick(&app, &id).await;
    until_tick(&app, &id, joined + 8).await;
    let c = tokio::spawn(collect_grpc(watch_grpc(&app, &id, None).await, until));
    let e = tokio::spawn(collect_ws(watch_ws(&app, &id, "?encoding=protobuf", None).await, until));
    let (a, b, d, e) = (a.await.unwrap(), b.await.unwrap(), d.await.unwrap(), e.await.unwrap());
    let c = c.await.unwrap();

    // Each viewer's first frame is a tick after it joined, with dropped 0.
    for (name, (order, frames)) in [("a", &a), ("b", &b), ("d", &d), ("e", &e)] {
        assert_eq!(frames[&order[0]].0, 0, "{name}'s first frame has dropped 0");
    }
    assert!(b.0[0] > a.0[0] + 3, "b joined 300 ms after a: {} vs {}", b.0[0], a.0[0]);
    assert!(e.0[0] > b.0[0] + 3, "e joined 300 ms after b");
    assert_eq!(c.values().next().unwrap().dropped, 0);
    assert!(!c.values().next().unwrap().pose.as_ref().unwrap().joint_names.is_empty(), "names in the first frame");

    let mut compared = 0;
    for (seq, (_, msg)) in &b.1 {
        // JSON: the same bytes for the same seq, but for each viewer's own dropped.
        let (_, other) = a.1.get(seq).expect("a saw every seq b saw");
        assert_eq!(shared_text(msg), shared_text(other), "seq {seq}");
        // The pose is the motion at seq/fps (x = time on this clip), start 0, speed 1.
        let v = json_of(msg);
        let x = v["pose"]["joints"][0]["translation"][0].as_f64().unwrap();
        assert!((x - *seq as f64 / FPS as f64).abs() < 1e-5, "seq {seq}: x {x}");
        // Protobuf viewers: identical bytes (after the first frame's names), the
        // same frame over gRPC, and the same tick stamp as the JSON frame.
        if let (Some((_, dm)), Some((_, em))) = (d.1.get(seq), e.1.get(seq)) {
            let (Message::Binary(db), Message::Binary(eb)) = (dm, em) else { panic!("binary frames") };
            let (df, ef) = (pb::Frame::decode(db.clone()).unwrap(), pb::Frame::decode(eb.clone()).unwrap());
            if *seq > e.0[0] && df.dropped == 0 && ef.dropped == 0 {
                assert_eq!(db, eb, "seq {seq}: the same protobuf bytes");
            }
            assert_eq!(shared_pb(df.clone()), shared_pb(ef));
            if let Some(cf) = c.get(seq) {
                assert_eq!(shared_pb(cf.clone()), shared_pb(df.clone()), "seq {seq}: gRPC = WebSocket protobuf");
                compared += 1;
            }
            assert_eq!(df.sent_at_unix_nanos, v["sent_at_unix_nanos"].as_i64().unwrap(), "stamped once per tick");
            assert_eq!(df.clip_time, v["clip_time"].as_f64().unwrap() as f32);
        }
    }
    assert!(compared >= 10, "only {compared} frames seen by all viewers");

    // One evaluation per tick whatever the number of viewers: the summary's
    // viewer count is back to 0 once they left, and the metrics count ticks.
    let metrics = app.http.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
    assert!(metrics.contains("inbetween_broadcast_ticks_total"), "{metrics}");
    app.stop().await;
}

/// The motion time a JSON frame shows, and its x.
fn time_and_x(msg: &Message) -> (f64, f64) {
    let v = json_of(msg);
    (v["pose"]["time"].as_f64().unwrap(), v["pose"]["joints"][0]["translation"][0].as_f64().unwrap())
}

#[tokio::test]
async fn a_control_reaches_every_viewer_at_the_seq_it_returns() {
    let app = TestApp::start().await;
    let clip = app.create_id(&line_clip(2), None).await;
    let id = broadcast_of(&app, &clip, None).await;
    let mut ws = watch_ws(&app, &id, "", None).await;
    let grpc = watch_grpc(&app, &id, None).await;
    let first = header(&next_message(&mut ws).await).0;

    let (status, seek) = control(&app, &id, json!({"op": "seek", "time": 5.0}), None).await;
    assert_eq!(status, 200, "{seek}");
    let k = seek["seq"].as_u64().unwrap();
    assert!(k > first, "the seek applies from a tick after the viewer's first frame");
    until_tick(&app, &id, k + 4).await;
    let (status, pause) = control(&app, &id, json!({"op": "pause"}), None).await;
    assert_eq!(status, 200, "{pause}");
    let p = pause["seq"].as_u64().unwrap();
    assert!(p > k + 3);
    let summary: Value = app.get_json(&format!("/v1/broadcasts/{id}")).await;
    assert_eq!(summary["state"], "paused");
    assert_eq!(
        (summary["motion"]["layers"][0]["clip"].as_str(), summary["space"].as_str()),
        (Some(&*clip), Some("local"))
    );
    assert_eq!(
        (summary["fps"].as_u64(), summary["speed"].as_f64(), summary["viewers"].as_u64()),
        (Some(FPS), Some(1.0), Some(2))
    );
    // The summary's seq is the tick now; a control is stamped with the first tick due 50 ms (the default
    // `broadcast_control_lead_ms`) from when it arrived: at 20 fps one or two ticks on. The summary is
    // read after the answer, so on a loaded machine its tick may be past the stamp: that bound is a
    // latency, checked in the slow runs.
    let now = summary["seq"].as_u64().unwrap();
    assert!(p <= now + 2, "the summary's seq is the tick now: {summary}, the pause's {p}");
    if crate::common::latency_checked() {
        assert!(now < p, "the summary read at once is before the pause's stamp: {summary}, the pause's {p}");
    }
    assert!(summary["joints"].is_null());

    let until = p + 5;
    let (_, frames) = collect_ws(ws, until).await;
    let grpc = collect_grpc(grpc, until).await;
    let fps = FPS as f64;
    for (&seq, (_, msg)) in &frames {
        let (t, x) = time_and_x(msg);
        // By hand: seq/fps before the seek; 5 from tick k on; held at tick p−1's from p on.
        let expected = if seq < k {
            seq as f64 / fps
        } else if seq < p {
            5.0 + (seq - k) as f64 / fps
        } else {
            5.0 + (p - 1 - k) as f64 / fps
        };
        assert!((t - expected).abs() < 1e-9, "seq {seq}: time {t}, expected {expected} (k {k}, p {p})");
        assert!((x - expected).abs() < 1e-5, "seq {seq}: x {x}");
        // The gRPC viewer saw the same pose at the same seq.
        if let Some(g) = grpc.get(&seq) {
            let pose = g.pose.as_ref().unwrap();
            assert_eq!(pose.translations[0], x as f32, "seq {seq}: gRPC and WebSocket poses");
        }
    }
    // Around each control, the frames equal an independent evaluation at their motion time.
    for seq in [k - 1, k, k + 1, p - 1, p, p + 2] {
        let Some((_, msg)) = frames.get(&seq) else { continue };
        let (t, _) = time_and_x(msg);
        let pose = app.post_json("/v1/poses", &json!({"motion": {"layers": [{"clip": clip}]}, "time": t})).await;
        assert_eq!(json_of(msg)["pose"]["joints"], pose["joints"], "seq {seq}");
    }
    assert!(frames.contains_key(&k) && frames.contains_key(&p), "the control ticks were delivered");

    // `Play` bound to the broadcast controls it too.
    let (tx, rx) = tokio::sync::mpsc::channel(4);
    let bind = pb::playback_control::Op::Broadcast(pb::BindBroadcast { broadcast_id: id.clone() });
    tx.send(pb::PlaybackControl { op: Some(bind) }).await.unwrap();
    let mut play = app.grpc().await.play(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    within(5, "a bound frame", play.message()).await.unwrap().expect("a frame");
    let resume = pb::playback_control::Op::Play(pb::Resume {});
    tx.send(pb::PlaybackControl { op: Some(resume) }).await.unwrap();
    let summary = format!("/v1/broadcasts/{id}");
    eventually(Duration::from_secs(5), "playing again", || async {
        app.get_json(&summary).await["state"] == "playing"
    })
    .await;
    drop(tx);
    app.stop().await;
}

#[tokio::test]
async fn a_read_only_token_watches_but_cannot_control() {
    let app = TestApp::builder().configure(scoped_tokens).start().await;
    let clip = app.create_id(&line_clip(1), Some(WRITER)).await;
    let body = json!({"motion": {"layers": [{"clip": clip}]}, "fps": FPS});
    let (status, refused, _) = create(&app, body, Some(READER)).await;
    assert_eq!((status, refused["code"].as_str()), (403, Some("insufficient_scope")));
    let id = broadcast_of(&app, &clip, Some(WRITER)).await;

    // The reader watches (WebSocket and gRPC) ...
    let mut reader = watch_ws(&app, &id, "", Some(READER)).await;
    next_message(&mut reader).await;
    let mut frames = watch_grpc(&app, &id, Some(READER)).await;
    within(5, "a gRPC frame", frames.message()).await.unwrap().expect("a frame");
    // ... but neither controls over REST, nor on its socket, nor with a bound Play.
    let (status, refused) = control(&app, &id, json!({"op": "pause"}), Some(READER)).await;
    assert_eq!((status, refused["code"].as_str()), (403, Some("insufficient_scope")));
    reader.send(Message::Text(json!({"op": "pause"}).to_string().into())).await.unwrap();
    let error = loop {
        match within(5, "the refusal", reader.next()).await.unwrap().unwrap() {
            Message::Text(t) if t.contains("\"error\"") => break serde_json::from_str::<Value>(&t).unwrap(),
            _ => {}
        }
    };
    assert_eq!(error["error"]["code"], "insufficient_scope");
    let (tx, rx) = tokio::sync::mpsc::channel(1);
    let bind = pb::playback_control::Op::Broadcast(pb::BindBroadcast { broadcast_id: id.clone() });
    tx.send(pb::PlaybackControl { op: Some(bind) }).await.unwrap();
    let stream = tokio_stream::wrappers::ReceiverStream::new(rx);
    let status = app.grpc().await.play(with_token(stream, Some(READER))).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::PermissionDenied);
    let summary: Value = app
        .http
        .get(app.url(&format!("/v1/broadcasts/{id}")))
        .bearer_auth(READER)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(summary["state"], "playing", "nothing the reader sent took effect");

    // The writer's socket controls it for everyone.
    let mut writer = watch_ws(&app, &id, "", Some(WRITER)).await;
    writer.send(Message::Text(json!({"op": "pause"}).to_string().into())).await.unwrap();
    eventually(Duration::from_secs(5), "paused", || async {
        let req = app.http.get(app.url(&format!("/v1/broadcasts/{id}"))).bearer_auth(READER);
        req.send().await.unwrap().json::<Value>().await.unwrap()["state"] == "paused"
    })
    .await;
    app.stop().await;
}

#[tokio::test]
async fn idle_broadcasts_end_and_watched_ones_do_not() {
    let app = TestApp::start().await;
    let clip = app.create_id(&line_clip(1), None).await;
    let motion = json!({"layers": [{"clip": clip}]});
    let (_, idle, _) = create(&app, json!({"motion": motion, "fps": 30, "idle_timeout_secs": 1}), None).await;
    let (_, watched, _) = create(&app, json!({"motion": motion, "fps": 30, "idle_timeout_secs": 1}), None).await;
    let (idle, watched) = (idle["id"].as_str().unwrap(), watched["id"].as_str().unwrap());
    let mut ws = watch_ws(&app, watched, "", None).await;
    let status = |id: String| {
        let req = app.http.get(app.url(&format!("/v1/broadcasts/{id}")));
        async move { req.send().await.unwrap().status().as_u16() }
    };
    assert_eq!(status(idle.to_owned()).await, 200);
    // Read frames for 2 s: the idle one ends after 1 s, the watched one goes on.
    let until = tokio::time::Instant::now() + Duration::from_secs(2);
    while tokio::time::Instant::now() < until {
        next_message(&mut ws).await;
    }
    let gone: Value = app.get_json(&format!("/v1/broadcasts/{idle}")).await;
    assert_eq!(gone["code"], "broadcast_not_found");
    assert_eq!(status(watched.to_owned()).await, 200);
    let list: Value = app.get_json("/v1/broadcasts").await;
    let ids: Vec<&str> = list["broadcasts"].as_array().unwrap().iter().map(|b| b["id"].as_str().unwrap()).collect();
    assert_eq!(ids, [watched]);
    // Once its viewer leaves, it ends too.
    ws.close(None).await.unwrap();
    eventually(Duration::from_secs(5), "the watched broadcast to end", || async {
        status(watched.to_owned()).await == 404
    })
    .await;
    app.stop().await;
}

#[tokio::test]
async fn delete_closes_viewers_with_1000_and_grpc_ok() {
    let app = TestApp::start().await;
    let clip = app.create_id(&line_clip(1), None).await;
    let id = broadcast_of(&app, &clip, None).await;
    let mut ws = watch_ws(&app, &id, "", None).await;
    let mut frames = watch_grpc(&app, &id, None).await;
    next_message(&mut ws).await;
    within(5, "a gRPC frame", frames.message()).await.unwrap().expect("a frame");
    let resp = app.http.delete(app.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap();
    assert_eq!(resp.status(), 204);
    assert_eq!(close_frame(&mut ws).await, (1000, "the broadcast ended".to_owned()));
    let end = within(5, "the gRPC end", async {
        loop {
            match frames.message().await {
                Ok(Some(_)) => {}
                other => return other,
            }
        }
    })
    .await;
    assert!(matches!(end, Ok(None)), "gRPC ends with OK: {end:?}");
    let again = app.http.delete(app.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap();
    assert_eq!(again.status(), 404);
    app.stop().await;
}

#[tokio::test]
async fn shutdown_closes_viewers_with_1001_and_unavailable() {
    let app = TestApp::start().await;
    let clip = app.create_id(&line_clip(1), None).await;
    let id = broadcast_of(&app, &clip, None).await;
    let mut ws = watch_ws(&app, &id, "", None).await;
    let mut frames = watch_grpc(&app, &id, None).await;
    next_message(&mut ws).await;
    within(5, "a gRPC frame", frames.message()).await.unwrap().expect("a frame");
    let stopping = tokio::spawn(app.stop());
    assert_eq!(close_frame(&mut ws).await.0, 1001);
    let end = within(5, "the gRPC end", async {
        loop {
            match frames.message().await {
                Ok(Some(_)) => {}
                other => return other,
            }
        }
    })
    .await;
    assert_eq!(end.unwrap_err().code(), tonic::Code::Unavailable);
    stopping.await.unwrap();
}

#[tokio::test]
async fn bad_requests_are_refused_with_stable_codes() {
    let app = TestApp::builder().configure(|c| c.limits.max_broadcasts = 2).start().await;
    let clip = app.create_id(&line_clip(1), None).await;
    let motion = json!({"layers": [{"clip": clip}]});
    let cases = [
        (json!({"motion": motion, "fps": 0}), 422, "fps_out_of_range", Some("/fps")),
        (json!({"motion": motion, "fps": 1.5}), 400, "bad_number", Some("/fps")),
        (json!({"motion": motion, "format": "matrix"}), 422, "format_not_streamable", Some("/format")),
        (json!({"motion": motion, "format": "xyz"}), 400, "bad_parameter", Some("/format")),
        (
            json!({"motion": motion, "idle_timeout_secs": 0}),
            422,
            "idle_timeout_out_of_range",
            Some("/idle_timeout_secs"),
        ),
        (json!({"motion": motion, "joints": ["nope"]}), 422, "unknown_joint", Some("/joints/0")),
        (json!({"motion": motion, "colour": 1}), 422, "invalid_field", None),
        (
            json!({"motion": {"layers": [{"clip": "00000000-0000-7000-8000-000000000000"}]}}),
            404,
            "clip_not_found",
            Some("/motion/layers/0/clip"),
        ),
    ];
    for (body, status, code, pointer) in cases {
        let (got, problem, _) = create(&app, body.clone(), None).await;
        assert_eq!((got, problem["code"].as_str()), (status, Some(code)), "{body}: {problem}");
        if let Some(pointer) = pointer {
            assert_eq!(problem["pointer"], pointer, "{body}");
        }
    }
    let not_json = app.http.post(app.url("/v1/broadcasts")).header("content-type", "application/json").body("{");
    assert_eq!(not_json.send().await.unwrap().json::<Value>().await.unwrap()["code"], "malformed_json");

    let id = broadcast_of(&app, &clip, None).await;
    let controls = [
        (json!({"op": "fly"}), "bad_control"),
        (json!({"op": "stop"}), "bad_control"),
        (json!({"op": "speed", "speed": 5000}), "bad_control"),
        (json!({"op": "layer", "index": 3, "weight": 1}), "bad_control"),
    ];
    for (body, code) in controls {
        let (status, problem) = control(&app, &id, body.clone(), None).await;
        assert_eq!((status, problem["code"].as_str()), (422, Some(code)), "{body}: {problem}");
    }
    let fade =
        json!({"op": "crossfade", "to": {"layers": [{"clip": "00000000-0000-7000-8000-000000000000"}]}, "duration": 1});
    let (status, problem) = control(&app, &id, fade, None).await;
    assert_eq!(
        (status, problem["code"].as_str(), problem["pointer"].as_str()),
        (404, Some("clip_not_found"), Some("/to/layers/0/clip"))
    );

    let missing = "00000000-0000-7000-8000-000000000000";
    let (status, problem) = control(&app, missing, json!({"op": "play"}), None).await;
    assert_eq!((status, problem["code"].as_str()), (404, Some("broadcast_not_found")));
    let problem: Value = app.get_json(&format!("/v1/broadcasts/{missing}")).await;
    assert_eq!(problem["code"], "broadcast_not_found");
    let plain = app.http.get(app.url(&format!("/v1/broadcasts/{id}/stream"))).send().await.unwrap();
    assert_eq!(plain.json::<Value>().await.unwrap()["code"], "websocket_upgrade_required");
    let mut req = app.ws_url(&format!("/v1/broadcasts/{id}/stream?encoding=xml")).into_client_request().unwrap();
    req.headers_mut().insert("x-test", "1".parse().unwrap());
    let Err(tokio_tungstenite::tungstenite::Error::Http(resp)) = tokio_tungstenite::connect_async(req).await else {
        panic!("a bad encoding is refused before the upgrade");
    };
    assert_eq!(resp.status(), 400);
    let status = app
        .grpc()
        .await
        .watch(pb::WatchRequest { broadcast_id: missing.into(), ..Default::default() })
        .await
        .unwrap_err();
    assert_eq!(status.code(), tonic::Code::NotFound);

    // max_broadcasts = 2: the third is refused until one ends.
    let second = broadcast_of(&app, &clip, None).await;
    let (status, problem, _) = create(&app, json!({"motion": motion}), None).await;
    assert_eq!((status, problem["code"].as_str()), (429, Some("too_many_broadcasts")), "{problem}");
    app.http.delete(app.url(&format!("/v1/broadcasts/{second}"))).send().await.unwrap();
    assert_eq!(create(&app, json!({"motion": motion}), None).await.0, 201);

    // The OpenAPI document describes the shapes.
    let doc: Value = app.get_json("/openapi.json").await;
    for schema in ["CreateBroadcast", "BroadcastSummary", "BroadcastList", "ControlApplied"] {
        assert!(doc["components"]["schemas"].get(schema).is_some(), "{schema} in /openapi.json");
    }
    app.stop().await;
}

/// docs/broadcasts.md's last bullet, on one node with SQLite: a broadcast and its
/// controls are stored, so after a restart it is live again at the tick the
/// wall clock says, with its controls applied (the seek's time plus the
/// ticks since its stamp).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stored_broadcast_resumes_after_a_restart_at_the_tick_the_clock_says() {
    let data = tempfile::tempdir().unwrap();
    let app = TestApp::builder().data_dir(data.path()).start().await;
    let clip = app.create_id(&line_clip(1), None).await;
    let id = broadcast_of(&app, &clip, None).await;
    let (status, answer) = control(&app, &id, json!({"op": "seek", "time": 2.0}), None).await;
    assert_eq!(status, 200, "{answer}");
    let stamp = answer["seq"].as_u64().unwrap();
    let created_at = app.state.streams.broadcasts().get(&id).unwrap().created_at_unix_nanos();
    until_tick(&app, &id, stamp).await;
    app.stop().await;
    // The time is the behaviour here: the clock moves on while the server is
    // down, to 12 ticks past the seek's stamp (the check below wants over 10).
    let due = created_at + (stamp + 12) as i64 * 1_000_000_000 / FPS as i64;
    let left = u64::try_from(due - server::stream::unix_nanos()).unwrap_or(0);
    tokio::time::sleep(Duration::from_nanos(left)).await;

    let app = TestApp::builder().data_dir(data.path()).start().await;
    let summary: Value = eventually_some(Duration::from_secs(5), "the summary", || async {
        let resp = app.http.get(app.url("/v1/broadcasts")).send().await.unwrap();
        let list: Value = resp.json().await.unwrap();
        list["broadcasts"].as_array().unwrap().iter().find(|b| b["id"] == id.as_str()).cloned()
    })
    .await;
    let by_clock = (server::stream::unix_nanos() - created_at) as f64 * FPS as f64 / 1e9;
    let seq = summary["seq"].as_u64().unwrap();
    assert!((seq as f64 - by_clock).abs() <= 2.0, "resumed at seq {seq}, the clock says {by_clock:.1}");
    assert!(seq > stamp + 10, "{seq}: over 0.8 s after the seek at {stamp}");

    let mut ws = watch_ws(&app, &id, "", None).await;
    for _ in 0..3 {
        let msg = next_message(&mut ws).await;
        let (k, _) = header(&msg);
        let (time, x) = time_and_x(&msg);
        let want = 2.0 + (k - stamp) as f64 / FPS as f64;
        assert!((time - want).abs() < 1e-9, "seq {k}: time {time}, the seek at {stamp} says {want}");
        assert!((x - want).abs() < 1e-5, "seq {k}: x {x}");
    }
    drop(ws);
    app.stop().await;
}

/// A stored broadcast is rebuilt from its clips at the versions it was made
/// of; when a clip was replaced meanwhile, a node that must rebuild it (here:
/// the same node after a restart) answers a stable 404, not a server error.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stored_broadcast_whose_clip_was_replaced_is_not_found_after_a_restart() {
    let data = tempfile::tempdir().unwrap();
    let app = TestApp::builder().data_dir(data.path()).start().await;
    let clip = app.create_id(&line_clip(1), None).await;
    let id = broadcast_of(&app, &clip, None).await;
    let replaced = app
        .http
        .put(app.url(&format!("/v1/clips/{clip}")))
        .header("content-type", "application/json")
        .body(line_clip(1))
        .send()
        .await
        .unwrap();
    assert_eq!(replaced.status(), 200);
    app.stop().await;

    let app = TestApp::builder().data_dir(data.path()).start().await;
    let resp = app.http.get(app.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap();
    assert_eq!(resp.status(), 404);
    let problem: Value = resp.json().await.unwrap();
    assert_eq!(problem["code"], "clip_not_found", "{problem}");
    assert!(problem["detail"].as_str().unwrap().contains("replaced"), "{problem}");
    app.stop().await;
}

/// A clip of `line_clip(1)`'s joint moving along y instead of x.
fn rising_clip() -> String {
    json!({"name": "rising", "tracks": [{"joint": "j0", "channel": "translation", "interpolation": "linear",
        "times": [0.0, 10.0], "values": [[0.0, 0.0, 0.0], [0.0, 10.0, 0.0]]}]})
    .to_string()
}

/// A viewer's socket may send every control REST takes (docs/broadcasts.md): its
/// crossfade and `ik` reach every viewer and are stored as sent, so after a
/// restart the broadcast plays the faded-to clip with the constraint solved.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sockets_crossfade_and_ik_are_stored_and_survive_a_restart() {
    let data = tempfile::tempdir().unwrap();
    let app = TestApp::builder().data_dir(data.path()).start().await;
    let along_x = app.create_id(&line_clip(1), None).await;
    let along_y = app.create_id(&rising_clip(), None).await;
    let id = broadcast_of(&app, &along_x, None).await;
    let mut controller = watch_ws(&app, &id, "", None).await;
    let mut other = watch_ws(&app, &id, "", None).await;
    next_message(&mut controller).await;
    let fade = json!({"op": "crossfade", "to": {"layers": [{"clip": along_y}]}, "duration": 0});
    let aim = json!({"op": "ik", "constraints": [{"kind": "aim", "joint": "j0", "target": [0, 0, 50], "forward": [1, 0, 0]}]});
    for msg in [fade, aim] {
        controller.send(Message::Text(msg.to_string().into())).await.unwrap();
    }
    // Both arrive at every viewer: the joint rises along y, and the aim is reported solved.
    let faded_and_aimed = |msg: &Message| {
        let pose = &json_of(msg)["pose"];
        let translation = &pose["joints"][0]["translation"];
        let faded = translation[0].as_f64() == Some(0.0) && translation[1].as_f64().unwrap() > 0.0;
        let report = &pose["ik"][0];
        faded && report["kind"] == "aim" && report["converged"] == true
    };
    for ws in [&mut controller, &mut other] {
        within(5, "the socket's controls applied", async { while !faded_and_aimed(&next_message(ws).await) {} }).await;
    }
    drop((controller, other));
    app.stop().await;

    let app = TestApp::builder().data_dir(data.path()).start().await;
    let summary = app.url(&format!("/v1/broadcasts/{id}"));
    eventually(Duration::from_secs(5), "the resumed broadcast", || async {
        app.http.get(&summary).send().await.unwrap().status() == 200
    })
    .await;
    let mut ws = watch_ws(&app, &id, "", None).await;
    for _ in 0..3 {
        let msg = next_message(&mut ws).await;
        assert!(faded_and_aimed(&msg), "after the restart: {}", json_of(&msg)["pose"]);
        // The aim points j0's x axis at the target from where the faded-to clip put it.
        let joint = &json_of(&msg)["pose"]["joints"][0];
        let r: Vec<f64> = serde_json::from_value(joint["rotation"].clone()).unwrap();
        let p: Vec<f64> = serde_json::from_value(joint["translation"].clone()).unwrap();
        let (x, y, z, w) = (r[0], r[1], r[2], r[3]);
        // The first column of the rotation matrix: the turned x axis.
        let axis = [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)];
        let to = [-p[0], -p[1], 50.0 - p[2]];
        let cross =
            [axis[1] * to[2] - axis[2] * to[1], axis[2] * to[0] - axis[0] * to[2], axis[0] * to[1] - axis[1] * to[0]];
        let dot: f64 = axis.iter().zip(to).map(|(a, b)| a * b).sum();
        let angle = cross.iter().map(|v| v * v).sum::<f64>().sqrt().atan2(dot);
        assert!(angle < 1e-5, "x axis {axis:?} is {angle} rad off the direction to the target {to:?}");
    }
    drop(ws);
    app.stop().await;
}

/// docs/broadcasts.md "Checkpoints": a broadcast holding `broadcast_max_journal`
/// controls since its newest checkpoint refuses more with a stable code (and
/// the broadcast plays on); once a checkpoint lets the old ones go, it takes
/// controls again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broadcast_with_a_full_journal_refuses_controls_until_its_next_checkpoint() {
    let app = TestApp::builder()
        .configure(|c| {
            c.limits.broadcast_max_journal = 3;
            c.limits.broadcast_checkpoint = Duration::from_secs(1);
        })
        .start()
        .await;
    let clip = app.create_id(&line_clip(1), None).await;
    let id = broadcast_of(&app, &clip, None).await;
    let accepted = std::sync::atomic::AtomicU32::new(0);
    let refusal = eventually_some(Duration::from_secs(5), "a refusal", || async {
        let (status, answer) = control(&app, &id, json!({"op": "speed", "speed": 1.0}), None).await;
        match status {
            200 => {
                accepted.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                None
            }
            _ => Some((status, answer)),
        }
    })
    .await;
    let accepted = accepted.into_inner();
    assert_eq!(refusal.0, 422, "{}", refusal.1);
    assert_eq!(refusal.1["code"], "broadcast_journal_full", "{}", refusal.1);
    assert!(refusal.1["detail"].as_str().unwrap().contains("broadcast_max_journal"), "{}", refusal.1);
    assert!(accepted >= 3, "{accepted} controls taken before the refusal");
    // The broadcast plays on; after the checkpoints that let those controls go, controls are taken again.
    let at = tick(&app, &id).await;
    until_tick(&app, &id, at + 1).await;
    eventually(Duration::from_secs(10), "a control taken after the next checkpoints", || async {
        control(&app, &id, json!({"op": "speed", "speed": 1.0}), None).await.0 == 200
    })
    .await;
    app.stop().await;
}
