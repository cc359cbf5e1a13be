//! `inbetween serve` wiring: the TOML file, environment and flags reach the
//! server in that order of precedence; JSON logs are JSON.

use serde_json::Value;

use super::WAVE;
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
    let http = reqwest::Client::new();
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
