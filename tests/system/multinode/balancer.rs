//! `deploy/nginx.conf`, the load balancer of the compose deployment, run for
//! real in front of three nodes: the shipped file with only the compose host
//! names and ports replaced by this machine's. Uploads, poses, a WebSocket
//! stream and gRPC calls go through it, and the gRPC calls of one client
//! channel must land on every node (per-call balancing, docs/operations.md, "Scaling out over PostgreSQL").
//!
//! Needs nginx (Debian's package); skips without it unless
//! `INBETWEEN_REQUIRE_NGINX=1` (CI installs it).

use std::path::Path;
use std::process::{Child, Command, Stdio};

use super::*;
use formats::wire::proto::pb;
use formats::wire::proto::pb::animation_client::AnimationClient;

/// A running nginx on a config derived from `deploy/nginx.conf`.
struct Nginx {
    child: Child,
    http: String,
    grpc: String,
    _dir: tempfile::TempDir,
}

impl Drop for Nginx {
    /// SIGTERM, not SIGKILL: the master must take its workers down with it.
    fn drop(&mut self) {
        let _ = Command::new("kill").arg("-TERM").arg(self.child.id().to_string()).status();
        let _ = self.child.wait();
    }
}

/// nginx's version as (major, minor, patch), or `None` if it is not installed.
fn nginx_version() -> Option<(u32, u32, u32)> {
    let out = Command::new("nginx").arg("-v").output().ok()?;
    let text = String::from_utf8_lossy(&out.stderr);
    let v = text.split("nginx/").nth(1)?.split_whitespace().next()?;
    let mut parts = v.split('.').map(|p| p.parse().unwrap_or(0));
    Some((parts.next()?, parts.next()?, parts.next().unwrap_or(0)))
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// The shipped config, pointed at `nodes` and listening on free ports.
fn config(nodes: &[&Node; 3], http_port: u16, grpc_port: u16, dir: &Path, version: (u32, u32, u32)) -> String {
    let mut conf = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/deploy/nginx.conf")).unwrap();
    for (i, node) in nodes.iter().enumerate() {
        conf = conf
            .replace(&format!("node{}:8080", i + 1), &node.http.to_string())
            .replace(&format!("node{}:50051", i + 1), &node.grpc.to_string());
    }
    assert!(conf.contains("listen 8080;") && conf.contains("listen 50051;"), "deploy/nginx.conf changed shape");
    conf = conf
        .replace("listen 8080;", &format!("listen 127.0.0.1:{http_port};"))
        .replace("listen 50051;", &format!("listen 127.0.0.1:{grpc_port};"));
    // `http2 on;` is nginx ≥ 1.25.1 (the compose image is 1.27); older
    // ones (Debian 12 ships 1.22) say the same with `listen … http2`.
    if version < (1, 25, 1) {
        conf = conf
            .replace(&format!("listen 127.0.0.1:{grpc_port};"), &format!("listen 127.0.0.1:{grpc_port} http2;"))
            .replace("http2 on;", "");
    }
    // Temporary files and logs under the test's directory.
    let d = dir.display();
    conf.replacen(
        "http {",
        &format!(
            "http {{\n    access_log off;\n    client_body_temp_path {d}/body;\n    proxy_temp_path {d}/proxy;\n    \
             fastcgi_temp_path {d}/fastcgi;\n    uwsgi_temp_path {d}/uwsgi;\n    scgi_temp_path {d}/scgi;"
        ),
        1,
    )
}

impl Nginx {
    /// Starts nginx in front of `nodes`; `None` (skip) if it is not installed.
    async fn start(nodes: &[&Node; 3]) -> Option<Nginx> {
        let Some(version) = nginx_version() else {
            assert!(
                !std::env::var("INBETWEEN_REQUIRE_NGINX").is_ok_and(|v| v == "1"),
                "nginx is required (INBETWEEN_REQUIRE_NGINX=1) but not installed"
            );
            eprintln!(
                "skipping: nginx is not installed (apt-get install nginx); set INBETWEEN_REQUIRE_NGINX=1 to fail"
            );
            return None;
        };
        let dir = tempfile::tempdir().unwrap();
        let (http_port, grpc_port) = (free_port(), free_port());
        let conf = dir.path().join("nginx.conf");
        std::fs::write(&conf, config(nodes, http_port, grpc_port, dir.path(), version)).unwrap();
        // nginx with everything (prefix, config, log, pid) under `dir`.
        let nginx = |globals: &str| {
            let mut c = Command::new("nginx");
            c.arg("-p")
                .arg(dir.path())
                .arg("-c")
                .arg(&conf)
                .arg("-e")
                .arg(dir.path().join("error.log"))
                .arg("-g")
                .arg(format!("{globals} pid {}/nginx.pid;", dir.path().display()));
            c
        };
        let check = nginx("").arg("-t").output().unwrap();
        let log_path = dir.path().join("error.log");
        let log = move || std::fs::read_to_string(&log_path).unwrap_or_default();
        assert!(check.status.success(), "nginx -t: {}{}", String::from_utf8_lossy(&check.stderr), log());
        let child = nginx("daemon off;").stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
        let lb = Nginx {
            child,
            http: format!("http://127.0.0.1:{http_port}"),
            grpc: format!("http://127.0.0.1:{grpc_port}"),
            _dir: dir,
        };
        let http = crate::common::http_client();
        let started = Instant::now();
        while !http.get(format!("{}/healthz", lb.http)).send().await.is_ok_and(|r| r.status() == 200) {
            assert!(started.elapsed() < Duration::from_secs(10), "nginx did not come up: {}", log());
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        Some(lb)
    }
}

/// `inbetween_poses_evaluated_total` of `node`.
async fn poses_evaluated(http: &reqwest::Client, node: &Node) -> u64 {
    let text = http.get(node.url("/metrics")).send().await.unwrap().text().await.unwrap();
    text.lines()
        .find_map(|l| l.strip_prefix("inbetween_poses_evaluated_total "))
        .map_or(0, |v| v.trim().parse::<f64>().unwrap() as u64)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_shipped_nginx_config_balances_http_websocket_and_each_grpc_call() {
    let Some(schema) = Schema::create("nginx").await else { return };
    let [a, b, c] = start_all(&schema, ["node-a", "node-b", "node-c"]).await;
    let Some(lb) = Nginx::start(&[&a, &b, &c]).await else {
        drop((a, b, c));
        schema.drop_now().await;
        return;
    };
    let http = crate::common::http_client();

    // REST through the balancer: upload, then poses (any node answers).
    let resp = http
        .post(format!("{}/v1/clips", lb.http))
        .header("content-type", "application/json")
        .body(marker_doc(7))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 201);
    let id = resp.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_owned();
    for _ in 0..6 {
        let pose: Value =
            http.get(format!("{}/v1/clips/{id}/pose?t=1", lb.http)).send().await.unwrap().json().await.unwrap();
        assert_eq!(pose["joints"][0]["translation"][0].as_f64().unwrap().round(), 7.0);
    }

    // A WebSocket stream through the upgrade proxying.
    let url = format!("{}/v1/clips/{id}/stream?fps=30", lb.http.replace("http://", "ws://"));
    let (mut ws, _) = tokio_tungstenite::connect_async(url).await.expect("the upgrade passes through nginx");
    let mut next_seq = 0;
    for _ in 0..3 {
        let msg = tokio::time::timeout(Duration::from_secs(5), ws.next()).await.unwrap().unwrap().unwrap();
        let frame: Value = serde_json::from_str(msg.to_text().unwrap()).unwrap();
        let seq = frame["seq"].as_u64().unwrap();
        assert_eq!(seq, next_seq + frame["dropped"].as_u64().unwrap(), "frames in order, gaps reported");
        next_seq = seq + 1;
    }
    drop(ws);

    // gRPC: 30 calls on one channel spread over every node.
    let before = [poses_evaluated(&http, &a).await, poses_evaluated(&http, &b).await, poses_evaluated(&http, &c).await];
    let mut grpc = AnimationClient::connect(lb.grpc.clone()).await.unwrap();
    for _ in 0..30 {
        let pose = grpc
            .sample(pb::SampleRequest { clip_id: id.clone(), time: 1.0, ..Default::default() })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(pose.translations.first().map(|x| x.round()), Some(7.0), "the marker clip");
    }
    let after = [poses_evaluated(&http, &a).await, poses_evaluated(&http, &b).await, poses_evaluated(&http, &c).await];
    let calls: Vec<u64> = after.iter().zip(before).map(|(x, y)| x - y).collect();
    assert_eq!(calls.iter().sum::<u64>(), 30, "every call evaluated one pose: {calls:?}");
    assert!(calls.iter().all(|&n| n > 0), "one channel's calls reached every node: {calls:?}");

    drop(lb);
    drop((a, b, c));
    schema.drop_now().await;
}
