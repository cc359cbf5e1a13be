//! What operators read (issue 18): the access log line of every 4xx and
//! 5xx with its fields, none for 2xx at sampling 0, and one startup line with
//! the effective configuration in which no token or database password
//! appears — read from the JSON logs of the real binary.

use serde_json::Value;

use crate::common::{ServerProcess, http_client, pg};

/// The JSON log lines of `logs` whose target is `target`.
fn lines_of(logs: &str, target: &str) -> Vec<Value> {
    logs.lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .filter(|v| v["target"] == target)
        .collect()
}

/// The one startup line's `config` field.
fn startup_config(logs: &str) -> String {
    let starting: Vec<Value> = lines_of(logs, "inbetween_server")
        .into_iter()
        .filter(|v| {
            v["fields"]["message"].as_str().unwrap_or("").starts_with("starting with the effective configuration")
        })
        .collect();
    assert_eq!(starting.len(), 1, "one startup line in\n{logs}");
    starting[0]["fields"]["config"].as_str().unwrap().to_owned()
}

#[tokio::test]
async fn every_failure_gets_an_access_line_and_startup_states_the_configuration() {
    const WRITE: &str = "plain-write-secret-71";
    const READ: &str = "plain-read-secret-72";
    const SCOPED: &str = "scoped-read-secret-73";
    let hash = server::tokens::TokenHash::of(SCOPED.as_bytes());
    let dir = tempfile::tempdir().unwrap();
    let mut server = ServerProcess::serve()
        .data_dir(dir.path())
        .args(["--api-token", WRITE, "--read-token", READ, "--token", &format!("ci:read:{hash}")])
        .args(["--access-log-sample", "0"])
        .env("INBETWEEN_LOG", "info")
        .env("INBETWEEN_LOG_FORMAT", "json")
        .start()
        .await;
    let http = http_client();
    let missing = "01900000-0000-7000-8000-000000000000";
    let resp = http
        .get(server.url(&format!("/v1/clips/{missing}")))
        .bearer_auth(SCOPED)
        .header("x-request-id", "rid-issue-18")
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 404);
    assert_eq!(http.get(server.url("/no/such/route")).bearer_auth(READ).send().await.unwrap().status(), 404);
    assert_eq!(http.get(server.url("/v1/clips")).bearer_auth("a-wrong-token").send().await.unwrap().status(), 401);
    for _ in 0..20 {
        assert_eq!(http.get(server.url("/healthz")).send().await.unwrap().status(), 200);
    }
    server.kill();
    let logs = server.logs();

    let access: Vec<Value> = lines_of(&logs, "inbetween::access").into_iter().map(|v| v["fields"].clone()).collect();
    assert_eq!(access.len(), 3, "the three failures and no 200 at sampling 0:\n{logs}");
    let line = access.iter().find(|f| f["request_id"] == "rid-issue-18").expect("the 404's line");
    assert_eq!(line["message"], "request");
    assert_eq!(line["method"], "GET");
    assert_eq!(line["route"], "/v1/clips/{id}", "the template, never the id");
    assert_eq!(line["status"], 404);
    assert_eq!(line["caller"], "ci", "the token's name");
    assert_eq!(line["client"], "127.0.0.1");
    let latency = line["latency_ms"].as_f64().expect("latency in ms");
    assert!((0.0..10_000.0).contains(&latency), "{latency}");
    let unmatched = access.iter().find(|f| f["route"] == "unmatched").expect("the unknown route's line");
    assert_eq!((unmatched["status"].as_u64(), unmatched["caller"].as_str()), (Some(404), Some("read-token")));
    assert!(unmatched["request_id"].as_str().unwrap().len() >= 32, "a generated request id");
    let refused = access.iter().find(|f| f["status"] == 401).expect("the 401's line");
    assert_eq!((refused["route"].as_str(), refused["caller"].as_str()), (Some("/v1/clips"), Some("unauthenticated")));
    assert!(!logs.contains(missing), "a clip id in the logs:\n{logs}");

    let config = startup_config(&logs);
    for setting in
        ["access_log_sample: 0.0", "compression: Compression { enabled: true, min_bytes: 1024 }", "max_body_bytes"]
    {
        assert!(config.contains(setting), "{setting} in {config}");
    }
    assert!(config.contains("write_token: Some(Secret([redacted]))"), "{config}");
    for secret in [WRITE, READ, SCOPED] {
        assert!(!logs.contains(secret), "{secret} reached the logs:\n{logs}");
    }
}

#[tokio::test]
async fn the_startup_line_names_the_database_but_not_its_password() {
    let Some(schema) = pg::Schema::create("startup_line").await else { return };
    let url = schema.url("");
    // The same server with a password in the URL (a trusting test server ignores it).
    let Some((scheme, rest)) = url.split_once("://") else { panic!("{url}") };
    let Some((user, host)) = rest.split_once('@') else {
        eprintln!("SKIPPED: the test PostgreSQL URL has no user to add a password to");
        return;
    };
    if user.contains(':') {
        eprintln!("SKIPPED: the test PostgreSQL URL already carries a password");
        return;
    }
    let with_password = format!("{scheme}://{user}:pg-pass-word-74@{host}");
    let mut server = ServerProcess::serve()
        .args(["--database-url", &with_password])
        .env("INBETWEEN_LOG", "info")
        .env("INBETWEEN_LOG_FORMAT", "json")
        .start()
        .await;
    server.kill();
    let logs = server.logs();
    let config = startup_config(&logs);
    assert!(
        config.contains(&format!("Postgres(\"{scheme}://{user}:***@{}", host.split('?').next().unwrap())),
        "{config}"
    );
    assert!(!logs.contains("pg-pass-word-74"), "the password reached the logs:\n{logs}");
    schema.drop_now().await;
}
