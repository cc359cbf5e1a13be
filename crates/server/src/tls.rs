//! TLS for both listeners (`--tls-cert` / `--tls-key`, PEM), with rustls on
//! the ring provider. rustls implements TLS 1.2 and 1.3 only, so an older
//! client fails the handshake; this module names both versions explicitly so
//! that stays true whatever rustls's defaults become.
//!
//! The HTTP listener ([`super::listen`]) wraps each accepted socket with
//! [`Acceptor`] inside the connection's own task, under the header-read
//! timeout, so a client that stalls its handshake holds nothing but its task.
//! The gRPC listener gets the same files through tonic's `ServerTlsConfig`
//! (tonic's `tls-ring` feature), which adds the `h2` ALPN.

use std::sync::Arc;

use anyhow::Context;
use rustls::ServerConfig;
use rustls_pki_types::pem::PemObject;
use rustls_pki_types::{CertificateDer, PrivateKeyDer};

use super::config::TlsFiles;

/// The PEM certificate chain and key, read once at startup.
pub struct TlsMaterial {
    cert_pem: Vec<u8>,
    key_pem: Vec<u8>,
}

impl TlsMaterial {
    /// Reads and checks both files (the key must match the certificate).
    ///
    /// # Errors
    /// A file cannot be read, holds no certificate or key, or the two do not
    /// form a usable server identity.
    pub fn load(files: &TlsFiles) -> anyhow::Result<TlsMaterial> {
        let cert_pem = std::fs::read(&files.cert).with_context(|| format!("reading {}", files.cert.display()))?;
        let key_pem = std::fs::read(&files.key).with_context(|| format!("reading {}", files.key.display()))?;
        let material = TlsMaterial { cert_pem, key_pem };
        material.http_config().context("the TLS certificate and key")?;
        Ok(material)
    }

    /// The rustls configuration of the HTTP listener (ALPN `http/1.1`).
    ///
    /// # Errors
    /// No certificate or key in the PEM, or a key that does not fit.
    pub fn http_config(&self) -> anyhow::Result<Arc<ServerConfig>> {
        let certs = CertificateDer::pem_slice_iter(&self.cert_pem)
            .collect::<Result<Vec<_>, _>>()
            .context("parsing the certificate PEM")?;
        anyhow::ensure!(!certs.is_empty(), "the certificate file holds no certificate");
        let key = PrivateKeyDer::from_pem_slice(&self.key_pem).context("parsing the private key PEM")?;
        let provider = Arc::new(rustls::crypto::ring::default_provider());
        let mut config = ServerConfig::builder_with_provider(provider)
            .with_protocol_versions(&[&rustls::version::TLS13, &rustls::version::TLS12])?
            .with_no_client_auth()
            .with_single_cert(certs, key)?;
        config.alpn_protocols = vec![b"http/1.1".to_vec()];
        Ok(Arc::new(config))
    }

    /// The gRPC listener's TLS settings; `handshake_timeout` bounds a stalled handshake.
    pub fn grpc_config(&self, handshake_timeout: std::time::Duration) -> tonic::transport::ServerTlsConfig {
        let identity = tonic::transport::Identity::from_pem(&self.cert_pem, &self.key_pem);
        tonic::transport::ServerTlsConfig::new().identity(identity).timeout(handshake_timeout)
    }
}

/// Accepts TLS on the HTTP listener's sockets.
pub type Acceptor = tokio_rustls::TlsAcceptor;
