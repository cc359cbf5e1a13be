//! TLS on both listeners: real TLS clients with a CA made at run time are
//! served; plaintext and pre-1.2 clients are refused.

use std::sync::Arc;

use formats::wire::proto::pb;
use formats::wire::proto::pb::animation_client::AnimationClient;
use rcgen::{BasicConstraints, CertificateParams, CertifiedIssuer, IsCa, KeyPair};
use server::config::TlsFiles;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tonic::transport::{Certificate, Channel, ClientTlsConfig};

use super::{ADMIN, READER, TestApp, scoped_tokens};

/// A CA and a `localhost` / 127.0.0.1 server certificate it signed, as PEM.
struct TestPki {
    ca_pem: String,
    cert_pem: String,
    key_pem: String,
}

fn make_pki() -> TestPki {
    let mut ca_params = CertificateParams::new(Vec::<String>::new()).unwrap();
    ca_params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    let ca = CertifiedIssuer::self_signed(ca_params, KeyPair::generate().unwrap()).unwrap();
    let leaf_key = KeyPair::generate().unwrap();
    let leaf_params = CertificateParams::new(vec!["localhost".to_owned(), "127.0.0.1".to_owned()]).unwrap();
    let leaf = leaf_params.signed_by(&leaf_key, &ca).unwrap();
    TestPki { ca_pem: ca.pem(), cert_pem: leaf.pem(), key_pem: leaf_key.serialize_pem() }
}

async fn spawn_tls_app(pki: &TestPki) -> TestApp {
    TestApp::builder()
        .configure_in(|c, dir| {
            scoped_tokens(c);
            let (cert, key) = (dir.join("cert.pem"), dir.join("key.pem"));
            std::fs::write(&cert, &pki.cert_pem).unwrap();
            std::fs::write(&key, &pki.key_pem).unwrap();
            c.tls = Some(TlsFiles { cert, key });
        })
        .start()
        .await
}

/// A reqwest client (rustls) that trusts only the test CA.
fn trusting_client(pki: &TestPki) -> reqwest::Client {
    crate::common::http_builder()
        .use_rustls_tls()
        .tls_built_in_root_certs(false)
        .add_root_certificate(reqwest::Certificate::from_pem(pki.ca_pem.as_bytes()).unwrap())
        .build()
        .unwrap()
}

/// A rustls client that trusts only the test CA and speaks only `versions`.
fn rustls_client(pki: &TestPki, versions: &[&'static rustls::SupportedProtocolVersion]) -> tokio_rustls::TlsConnector {
    use rustls_pki_types::CertificateDer;
    use rustls_pki_types::pem::PemObject;
    let mut roots = rustls::RootCertStore::empty();
    roots.add(CertificateDer::from_pem_slice(pki.ca_pem.as_bytes()).unwrap()).unwrap();
    let config = rustls::ClientConfig::builder_with_provider(Arc::new(rustls::crypto::ring::default_provider()))
        .with_protocol_versions(versions)
        .unwrap()
        .with_root_certificates(roots)
        .with_no_client_auth();
    tokio_rustls::TlsConnector::from(Arc::new(config))
}

#[tokio::test]
async fn https_and_grpc_over_tls_are_served_to_clients_that_trust_the_ca() {
    let pki = make_pki();
    let app = spawn_tls_app(&pki).await;
    let port = app.addr.port();

    // reqwest (rustls) with the test CA: a read and a write, by name and by IP.
    let client = trusting_client(&pki);
    let health = client.get(format!("https://localhost:{port}/healthz")).send().await.unwrap();
    assert_eq!(health.status(), 200);
    let created = client
        .post(format!("https://127.0.0.1:{port}/v1/clips"))
        .bearer_auth(ADMIN)
        .header("content-type", "application/json")
        .body(super::WAVE)
        .send()
        .await
        .unwrap();
    assert_eq!(created.status(), 201);

    // A client that does not trust the CA is refused by its own check.
    let untrusting = crate::common::http_builder().use_rustls_tls().tls_built_in_root_certs(false).build().unwrap();
    assert!(untrusting.get(format!("https://localhost:{port}/healthz")).send().await.is_err());

    // gRPC over TLS (tonic, rustls on ring).
    let tls = ClientTlsConfig::new().ca_certificate(Certificate::from_pem(&pki.ca_pem)).domain_name("localhost");
    let channel = Channel::from_shared(format!("https://localhost:{}", app.grpc_addr.port()))
        .unwrap()
        .tls_config(tls)
        .unwrap()
        .connect()
        .await
        .unwrap();
    let mut grpc = AnimationClient::new(channel);
    grpc.ping(pb::PingRequest::default()).await.unwrap();
    let list = grpc.list_clips(super::with_token(pb::ListClipsRequest::default(), Some(READER))).await.unwrap();
    assert_eq!(list.into_inner().clips.len(), 1);

    // Plaintext gRPC to the TLS port fails.
    let plain = Channel::from_shared(format!("http://{}", app.grpc_addr)).unwrap().connect().await;
    if let Ok(channel) = plain {
        assert!(AnimationClient::new(channel).ping(pb::PingRequest::default()).await.is_err());
    }
    app.stop().await;
}

#[tokio::test]
async fn tls_1_2_and_1_3_are_accepted_and_older_or_plaintext_clients_are_refused() {
    let pki = make_pki();
    let app = spawn_tls_app(&pki).await;
    let name = rustls_pki_types::ServerName::try_from("localhost").unwrap();

    for (label, version) in [("TLS 1.2", &rustls::version::TLS12), ("TLS 1.3", &rustls::version::TLS13)] {
        let tcp = TcpStream::connect(app.addr).await.unwrap();
        let mut tls = rustls_client(&pki, &[version]).connect(name.clone(), tcp).await.expect(label);
        assert_eq!(tls.get_ref().1.protocol_version(), Some(version.version), "{label}");
        tls.write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n").await.unwrap();
        let mut reply = Vec::new();
        tls.read_to_end(&mut reply).await.unwrap();
        assert!(reply.starts_with(b"HTTP/1.1 200"), "{label}: {}", String::from_utf8_lossy(&reply));
    }

    // A TLS 1.1-only ClientHello (record version 3.1, client_version 3.2, no
    // supported_versions extension): the server answers with an alert, never a ServerHello.
    let mut tcp = TcpStream::connect(app.addr).await.unwrap();
    tcp.write_all(&tls11_client_hello()).await.unwrap();
    let mut reply = Vec::new();
    let _ = tokio::time::timeout(std::time::Duration::from_secs(10), tcp.read_to_end(&mut reply)).await;
    assert!(!reply.is_empty(), "the server should answer the hello");
    assert_eq!(reply[0], 0x15, "an alert record, not a handshake: {reply:02x?}");
    assert_eq!(reply[5], 2, "a fatal alert");
    // rustls answers handshake_failure (40); protocol_version (70) would do as well.
    assert!([40, 70].contains(&reply[6]), "alert {}", reply[6]);

    // Plain HTTP on the TLS port gets no HTTP answer.
    let mut tcp = TcpStream::connect(app.addr).await.unwrap();
    tcp.write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\n\r\n").await.unwrap();
    let mut reply = Vec::new();
    let _ = tokio::time::timeout(std::time::Duration::from_secs(10), tcp.read_to_end(&mut reply)).await;
    assert!(!reply.starts_with(b"HTTP/"), "plaintext was served: {}", String::from_utf8_lossy(&reply));
    app.stop().await;
}

/// A WebSocket stream over TLS: the frames, which the server writes itself
/// (header and shared bytes, `server::rest::socket`), arrive whole and in
/// order through rustls, then the normal close.
#[tokio::test]
async fn a_websocket_stream_over_tls_delivers_its_frames_and_closes_normally() {
    use futures_util::StreamExt;
    use tokio_tungstenite::tungstenite::Message;
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;

    let pki = make_pki();
    let app = spawn_tls_app(&pki).await;
    let port = app.addr.port();
    let client = trusting_client(&pki);
    let created: serde_json::Value = client
        .post(format!("https://localhost:{port}/v1/clips"))
        .bearer_auth(ADMIN)
        .header("content-type", "application/json")
        .body(super::WAVE)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let id = created["id"].as_str().unwrap();
    let name = rustls_pki_types::ServerName::try_from("localhost").unwrap();
    let tcp = TcpStream::connect(app.addr).await.unwrap();
    let tls = rustls_client(&pki, &[&rustls::version::TLS13]).connect(name, tcp).await.unwrap();
    let mut request =
        format!("wss://localhost:{port}/v1/clips/{id}/stream?fps=60&max_frames=5").into_client_request().unwrap();
    request.headers_mut().insert("authorization", format!("Bearer {READER}").parse().unwrap());
    let (mut ws, response) = tokio_tungstenite::client_async(request, tls).await.unwrap();
    assert_eq!(response.status(), 101);
    let mut seqs = Vec::new();
    let close = loop {
        let next = tokio::time::timeout(std::time::Duration::from_secs(5), ws.next()).await;
        match next.expect("a frame or the close within 5 s").expect("the socket closed").unwrap() {
            Message::Text(text) => {
                let frame: serde_json::Value = serde_json::from_str(&text).unwrap();
                assert!(frame["pose"]["joints"].is_array(), "{text}");
                seqs.push(frame["seq"].as_u64().unwrap());
            }
            Message::Close(frame) => break frame.expect("a close frame with a code"),
            other => panic!("unexpected {other:?}"),
        }
    };
    assert_eq!(seqs.len(), 5, "{seqs:?}");
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{seqs:?}");
    assert_eq!(u16::from(close.code), 1000);
    app.stop().await;
}

/// A minimal TLS 1.1 ClientHello offering TLS_RSA_WITH_AES_128_CBC_SHA.
fn tls11_client_hello() -> Vec<u8> {
    let mut body = vec![0x03, 0x02]; // client_version TLS 1.1
    body.extend([0x42; 32]); // random
    body.push(0); // session id
    body.extend([0x00, 0x02, 0x00, 0x2f]); // one cipher suite
    body.extend([0x01, 0x00]); // null compression
    let mut handshake = vec![0x01, 0, 0, body.len() as u8];
    handshake.extend(body);
    let mut record = vec![0x16, 0x03, 0x01, 0, handshake.len() as u8];
    record.extend(handshake);
    record
}
