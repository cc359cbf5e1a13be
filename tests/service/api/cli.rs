//! `inbetween serve` wiring: the TOML file, environment and flags reach the
//! server in that order of precedence; JSON logs are JSON. `inbetween watch`
//! streams docs/motion.md's example motion files from a real server, and the
//! Fox's locomotion graph driven by `--set` (docs/graphs.md).

use serde_json::{Value, json};

use super::{WAVE, within};
use crate::common::ServerProcess;

#[tokio::test]
async fn file_env_and_flags_layer_and_json_logs_are_json() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("inbetween.toml");
    let data = dir.path().join("data");
    std::fs::write(
        &config,
        format!(
            "listen = \"127.0.0.1:1\"\ndata_dir = {data:?}\napi_token = \"from-file\"\n[limits]\nmax_poses = 3\nmax_tracks = 1\n"
        ),
    )
    .unwrap();
    // `serve()` passes `--listen 127.0.0.1:0`: the flag beats the file's port 1.
    let mut server = ServerProcess::serve()
        .arg("--config")
        .arg(&config)
        .args(["--max-tracks", "4"]) // flags beat the file
        .env("INBETWEEN_API_TOKEN", "from-env") // the environment beats the file
        .env("INBETWEEN_LOG", "info")
        .env("INBETWEEN_LOG_FORMAT", "json")
        .start()
        .await;
    let http = crate::common::http_client();
    let post = |token: &str| {
        http.post(format!("{}/v1/clips", server.base()))
            .bearer_auth(token)
            .header("content-type", "application/json")
            .body(WAVE)
            .send()
    };
    assert_eq!(post("from-file").await.unwrap().status(), 401);
    let created: Value = post("from-env").await.unwrap().json().await.unwrap();
    assert_eq!(created["tracks"], 2, "max_tracks 4 from the flag, not 1 from the file");
    let id = created["id"].as_str().unwrap();
    let sample = http
        .post(format!("{}/v1/clips/{id}/sample", server.base()))
        .json(&serde_json::json!({"times": [0, 1, 2, 3]}))
        .send()
        .await
        .unwrap();
    assert_eq!(sample.status(), 422, "max_poses 3 from the file");
    assert!(data.join("inbetween.db").exists(), "data_dir from the file");

    server.kill();
    let logs = server.logs();
    let lines: Vec<&str> = logs.lines().collect();
    assert!(lines.iter().any(|l| l.contains("clip created")), "{logs}");
    for line in lines {
        serde_json::from_str::<Value>(line).unwrap_or_else(|e| panic!("not JSON ({e}): {line}"));
    }
    assert!(!logs.contains("from-env"), "a token reached the logs");
}

/// `key=value` of a `watch` frame line.
fn field<'a>(line: &'a str, key: &str) -> &'a str {
    let prefix = format!("{key}=");
    line.split(' ').find_map(|word| word.strip_prefix(prefix.as_str())).unwrap_or_else(|| panic!("no {key} in {line}"))
}

fn numbers(text: &str) -> Vec<f64> {
    text.trim_matches(['[', ']']).split(',').map(|x| x.parse().unwrap()).collect()
}

#[tokio::test]
async fn watch_streams_a_motion_file_by_clip_names_and_sends_a_crossfade_at_its_frame() {
    let dir = tempfile::tempdir().unwrap();
    let server = ServerProcess::serve().data_dir(dir.path()).start().await;
    let http = crate::common::http_client();
    let fox = std::fs::read("examples/gltf/Fox/Fox.glb").unwrap();
    let imported: Value =
        http.post(server.url("/v1/clips/import")).body(fox).send().await.unwrap().json().await.unwrap();
    let id = |name: &str| {
        let clips = imported["clips"].as_array().unwrap();
        clips.iter().find(|c| c["name"] == name).unwrap()["id"].as_str().unwrap().to_owned()
    };
    let fps = 5.0;
    let mut watch = tokio::process::Command::from(ServerProcess::command());
    watch.args(["watch", "--server", &server.base(), "--motion", "examples/motions/walk-run.json", "--fps", "5"]);
    watch.args(["--max-frames", "4", "--joints", "b_Hip_01", "--at", "1=@examples/motions/crossfade-to-run.json"]);
    let out = within(30, "watch", watch.stdin(std::process::Stdio::null()).output()).await.unwrap();
    let (stdout, stderr) = (String::from_utf8(out.stdout).unwrap(), String::from_utf8(out.stderr).unwrap());
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stderr.starts_with(&format!("opened {{\"clip\":\"{}\"", id("Walk"))), "{stderr}");
    assert!(stderr.contains("closed 1000 max_frames reached after 4 frames"), "{stderr}");
    assert!(!stderr.contains("error"), "the crossfade was accepted: {stderr}");

    let lines: Vec<&str> = stdout.lines().collect();
    let seqs: Vec<&str> = lines.iter().map(|l| field(l, "seq")).collect();
    assert_eq!(seqs, ["0", "1", "2", "3"]);
    // The file names clips by name; the same motion by id is what POST /v1/poses answers.
    let walk_run = json!({"layers": [{"clip": id("Walk"), "sync": "locomotion"},
                                     {"clip": id("Run"), "weight": 0.3, "sync": "locomotion"}]});
    let hips_at = |t: f64| {
        let body = json!({"motion": walk_run, "time": t, "joints": ["b_Hip_01"]});
        let request = http.post(server.url("/v1/poses")).json(&body).send();
        async move { request.await.unwrap().json::<Value>().await.unwrap()["joints"][0]["translation"].clone() }
    };
    let close = |printed: &str, expected: &Value, what: &str| {
        let expected: Vec<f64> = (0..3).map(|i| expected[i].as_f64().unwrap()).collect();
        let printed = numbers(printed);
        assert!(
            printed.iter().zip(&expected).all(|(a, b)| (a - b).abs() <= 1e-4),
            "{what}: {printed:?} vs {expected:?}"
        );
    };
    // Frames 0 and 1 play walk/run; the crossfade sent on frame 1 starts at
    // a later tick, where Run is at motion time 0 and α = 0 shows A's pose.
    let fade = lines.iter().position(|l| field(l, "time") == "0.0000" && field(l, "seq") != "0").expect("the fade");
    assert!(fade >= 2, "{stdout}");
    for (k, line) in lines[..fade].iter().enumerate() {
        let t = k as f64 / fps;
        assert_eq!(numbers(field(line, "time")), [t], "{line}");
        close(field(line, "b_Hip_01"), &hips_at(t).await, line);
    }
    close(field(lines[fade], "b_Hip_01"), &hips_at(fade as f64 / fps).await, "the fade's first frame is A's pose");
}

#[tokio::test]
async fn watch_follows_a_broadcast_sends_its_controls_and_exits_cleanly_when_it_is_deleted() {
    let dir = tempfile::tempdir().unwrap();
    let server = ServerProcess::serve().data_dir(dir.path()).start().await;
    let http = crate::common::http_client();
    let upload = http.post(server.url("/v1/clips")).header("content-type", "application/json").body(WAVE);
    let clip: Value = upload.send().await.unwrap().json().await.unwrap();
    let body = json!({"motion": {"layers": [{"clip": clip["id"]}]}, "fps": 10});
    let created: Value =
        http.post(server.url("/v1/broadcasts")).json(&body).send().await.unwrap().json().await.unwrap();
    let id = created["id"].as_str().unwrap().to_owned();

    let mut watch = tokio::process::Command::from(ServerProcess::command());
    watch.args(["watch", "--server", &server.base(), "--broadcast", &id, "--at", r#"0={"op":"seek","time":0.25}"#]);
    let running = watch.stdin(std::process::Stdio::null()).output();
    let deleting = async {
        // Deleted once the watch's seek has arrived and a few ticks (0.5 s) have shown it.
        let metrics = server.url("/metrics");
        let seek_arrived = || async {
            let text = http.get(&metrics).send().await.unwrap().text().await.unwrap();
            crate::common::metric(&text, "inbetween_broadcast_controls_total").is_some_and(|n| n >= 1.0)
        };
        let wait = std::time::Duration::from_secs(20);
        crate::common::eventually(wait, "the watch's seek arrived", seek_arrived).await;
        let summary = server.url(&format!("/v1/broadcasts/{id}"));
        let tick = || async { http.get(&summary).send().await.unwrap().json::<Value>().await.unwrap()["seq"].as_u64() };
        let then = tick().await.unwrap();
        crate::common::eventually(wait, "5 ticks past the seek", || async { tick().await >= Some(then + 5) }).await;
        let resp = http.delete(server.url(&format!("/v1/broadcasts/{id}"))).send().await.unwrap();
        assert_eq!(resp.status(), 204);
    };
    let (out, ()) = within(30, "watch", async { tokio::join!(running, deleting) }).await;
    let out = out.unwrap();
    let (stdout, stderr) = (String::from_utf8(out.stdout).unwrap(), String::from_utf8(out.stderr).unwrap());
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stderr.contains("closed 1000 the broadcast ended"), "{stderr}");
    // The seek sent on the first frame shows 0.25 at a later tick, then plays on from there.
    let lines: Vec<&str> = stdout.lines().collect();
    let at = lines.iter().position(|l| field(l, "time") == "0.2500").expect("the seek's frame");
    assert!(at >= 1, "{stdout}");
    assert_eq!(field(lines[at + 1], "time"), "0.3500", "{stdout}");
}

#[tokio::test]
async fn watch_drives_a_graph_with_set_and_prints_its_states() {
    let dir = tempfile::tempdir().unwrap();
    let server = ServerProcess::serve().data_dir(dir.path()).start().await;
    let http = crate::common::http_client();
    let fox = std::fs::read("examples/gltf/Fox/Fox.glb").unwrap();
    let imported: Value =
        http.post(server.url("/v1/clips/import")).body(fox).send().await.unwrap().json().await.unwrap();
    let mut doc = std::fs::read_to_string("examples/graphs/fox-locomotion.json").unwrap();
    for clip in imported["clips"].as_array().unwrap() {
        doc = doc.replace(&format!("name:{}", clip["name"].as_str().unwrap()), clip["id"].as_str().unwrap());
    }
    let graph: Value = http
        .post(server.url("/v1/graphs"))
        .header("content-type", "application/json")
        .body(doc)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let id = graph["id"].as_str().unwrap_or_else(|| panic!("{graph}"));
    let mut watch = tokio::process::Command::from(ServerProcess::command());
    watch.args(["watch", "--server", &server.base(), "--graph", id, "--fps", "20", "--max-frames", "30"]);
    watch.args(["--set", "speed=2.5", "--set", "10:survey=true"]);
    let out = within(30, "watch", watch.stdin(std::process::Stdio::null()).output()).await.unwrap();
    let (stdout, stderr) = (String::from_utf8(out.stdout).unwrap(), String::from_utf8(out.stderr).unwrap());
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let states: Vec<(u64, &str)> =
        stdout.lines().map(|l| (field(l, "seq").parse().unwrap(), field(l, "state"))).collect();
    assert_eq!(states.len(), 30, "{stdout}");
    // Idle until the opening set lands, then moving (its transition shown as idle>move@α), then, after
    // frame 10's survey, looking.
    let moving = states.iter().position(|(_, s)| s.starts_with("idle>move@")).expect("the move fires");
    assert!(states[..moving].iter().all(|(_, s)| *s == "idle"), "{stdout}");
    let look = states.iter().position(|(_, s)| s.starts_with("move>look@")).expect("the survey fires");
    assert!(states[look].0 > 10, "the survey was sent on frame 10: {stdout}");
}

/// `inbetween import FILE --server URL [--token T]`, its standard output as
/// JSON, or its failure's standard error.
async fn import_to(server: &str, file: &std::path::Path, token: Option<&str>) -> Result<Value, String> {
    let mut command = tokio::process::Command::from(ServerProcess::command());
    command.arg("import").arg(file).args(["--server", server]).stdin(std::process::Stdio::null());
    if let Some(token) = token {
        command.args(["--token", token]);
    }
    let out = within(60, "inbetween import --server", command.output()).await.unwrap();
    match out.status.success() {
        true => Ok(serde_json::from_slice(&out.stdout).unwrap()),
        false => Err(String::from_utf8_lossy(&out.stderr).into_owned()),
    }
}

/// `import --server` sends the file itself to the import route: the Fox's
/// clips arrive with the skinned mesh a clip document cannot carry, with the
/// caller's token (refused without it); a `.gltf` travels with the `.bin`
/// beside it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn import_to_a_server_sends_the_file_with_its_mesh_and_buffers() {
    use crate::common::testdata_path;
    use crate::security::{WRITER, scoped_tokens};
    let app = crate::common::TestApp::builder().configure(scoped_tokens).start().await;
    let base = app.url("");
    let fox = testdata_path("gltf/Fox/Fox.glb");

    let refused = import_to(&base, &fox, None).await.unwrap_err();
    assert!(refused.contains("401"), "{refused}");
    let printed = import_to(&base, &fox, Some(WRITER)).await.unwrap();
    let names: Vec<&str> = printed["clips"].as_array().unwrap().iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["Survey", "Walk", "Run"]);
    let codes: Vec<&str> =
        printed["warnings"].as_array().unwrap().iter().map(|w| w["code"].as_str().unwrap()).collect();
    assert_eq!(codes, ["units_look_like_centimeters"], "the Fox is in centimetres");
    for clip in printed["clips"].as_array().unwrap() {
        let id = clip["id"].as_str().unwrap();
        let mesh = app.http.get(app.url(&format!("/v1/clips/{id}/mesh"))).bearer_auth(WRITER).send().await.unwrap();
        assert_eq!(mesh.status(), 200, "{id}");
        assert_eq!(&mesh.bytes().await.unwrap()[..4], b"INBM", "{id}: the mesh format's magic");
    }

    let gltf = testdata_path("gltf/InterpolationTest/InterpolationTest.gltf");
    let printed = import_to(&base, &gltf, Some(WRITER)).await.unwrap();
    let local = {
        let out =
            std::process::Command::new(env!("CARGO_BIN_EXE_inbetween")).arg("import").arg(&gltf).output().unwrap();
        serde_json::from_slice::<Value>(&out.stdout).unwrap()
    };
    assert_eq!(printed["clips"].as_array().unwrap().len(), local["clips"].as_array().unwrap().len());
    for (created, doc) in printed["clips"].as_array().unwrap().iter().zip(local["clips"].as_array().unwrap()) {
        let id = created["id"].as_str().unwrap();
        let stored: Value = app
            .http
            .get(app.url(&format!("/v1/clips/{id}")))
            .bearer_auth(WRITER)
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        assert_eq!(stored["tracks"], doc["tracks"], "{id}: the server read the .bin as the CLI did");
    }
    app.stop().await;
}
