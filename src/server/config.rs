//! Typed, layered configuration: defaults → TOML file (`--config`) → `INBETWEEN_*`
//! environment → command-line flags, each layer overriding the one before.
//!
//! Parsing happens in two stages. [`RawConfig`] is what a layer may say (every
//! field optional; the same struct is the TOML schema and the clap flags, so
//! the two cannot drift apart); [`RawConfig::validate`] turns the merged layers
//! into a [`Config`], which only holds values the server can run with. Tokens
//! and database URLs are [`Secret`]s, which never print.

use std::fmt;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Duration;

use anyhow::{Context, bail};
use serde::Deserialize;

use super::tokens::{Token, TokenSpec};

/// A value that must not reach logs: `Debug` prints `[redacted]`.
#[derive(Clone, PartialEq, Eq, Deserialize)]
#[serde(transparent)]
pub struct Secret(String);

impl Secret {
    pub fn new(s: impl Into<String>) -> Self {
        Secret(s.into())
    }

    /// The secret itself, for the one place that compares or uses it.
    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for Secret {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Secret([redacted])")
    }
}

impl FromStr for Secret {
    type Err = std::convert::Infallible;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(Secret(s.to_owned()))
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    #[default]
    Text,
    Json,
}

/// One layer of configuration. Every field is optional: absent means "ask
/// the layer below". Doubles as the clap flag set and the TOML schema.
#[derive(Debug, Clone, Default, Deserialize, clap::Args)]
#[serde(deny_unknown_fields)]
pub struct RawConfig {
    /// Address to listen on (port 0 picks a free port) [default: 127.0.0.1:8080].
    #[arg(long, env = "INBETWEEN_LISTEN", value_name = "ADDR")]
    pub listen: Option<SocketAddr>,
    /// Address of the gRPC API (port 0 picks a free port) [default: 127.0.0.1:50051].
    #[arg(long, env = "INBETWEEN_GRPC_LISTEN", value_name = "ADDR")]
    pub grpc_listen: Option<SocketAddr>,
    /// Directory of the embedded SQLite store, created if missing [default: ./data].
    #[arg(long, env = "INBETWEEN_DATA_DIR", value_name = "DIR")]
    pub data_dir: Option<PathBuf>,
    /// A store URL instead of --data-dir (`sqlite://path/to/file.db`, or `postgres://user@host/db` for
    /// several nodes sharing one database).
    #[arg(long, env = "INBETWEEN_DATABASE_URL", value_name = "URL", hide_env_values = true)]
    pub database_url: Option<Secret>,
    /// Most database connections this node opens [default: 8].
    #[arg(long, env = "INBETWEEN_DB_MAX_CONNECTIONS", value_name = "N")]
    pub db_max_connections: Option<u32>,
    /// Seconds a request waits for a free database connection before it fails with 503 [default: 10].
    #[arg(long, env = "INBETWEEN_DB_ACQUIRE_TIMEOUT_SECS", value_name = "SECS")]
    pub db_acquire_timeout_secs: Option<u64>,
    /// Retries of a transiently failed database operation, with exponential backoff from 50 ms [default: 3].
    #[arg(long, env = "INBETWEEN_DB_RETRIES", value_name = "N")]
    pub db_retries: Option<u32>,
    /// Start even if the database would acknowledge writes before they are durable (SQLite then runs
    /// with synchronous=NORMAL): a crash or power loss may lose acknowledged clips [default: false].
    #[arg(long, env = "INBETWEEN_UNSAFE_FAST_WRITES", num_args = 0..=1, default_missing_value = "true",
          value_parser = clap::builder::BoolishValueParser::new())]
    pub unsafe_fast_writes: Option<bool>,
    /// Bearer token required by create, replace and delete.
    #[arg(long, env = "INBETWEEN_API_TOKEN", value_name = "TOKEN", hide_env_values = true)]
    pub api_token: Option<Secret>,
    /// Bearer token required to read clips and poses (the write token also works).
    #[arg(long, env = "INBETWEEN_READ_TOKEN", value_name = "TOKEN", hide_env_values = true)]
    pub read_token: Option<Secret>,
    /// A scoped token, as NAME:SCOPE[+SCOPE]:sha256:HEX (repeatable, or comma-separated; TOML:
    /// `[[tokens]]` tables with name, scopes, hash). `inbetween token new` makes one.
    #[arg(long = "token", env = "INBETWEEN_TOKENS", value_name = "NAME:SCOPES:HASH", value_delimiter = ',')]
    pub tokens: Option<Vec<TokenSpec>>,
    /// PEM certificate chain: serve HTTP and gRPC over TLS (1.2+; needs --tls-key).
    #[arg(long, env = "INBETWEEN_TLS_CERT", value_name = "FILE", requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// PEM private key of --tls-cert.
    #[arg(long, env = "INBETWEEN_TLS_KEY", value_name = "FILE", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// Browser origin allowed by CORS (repeatable, or comma-separated; `*` for any) [default: none].
    #[arg(long = "cors-origin", env = "INBETWEEN_CORS_ORIGINS", value_name = "ORIGIN", value_delimiter = ',')]
    pub cors_origins: Option<Vec<String>>,
    /// Log format [default: text]. The filter comes from INBETWEEN_LOG or RUST_LOG.
    #[arg(long, env = "INBETWEEN_LOG_FORMAT", value_enum)]
    pub log_format: Option<LogFormat>,
    /// Seconds to let in-flight requests finish after SIGTERM/Ctrl-C [default: 10].
    #[arg(long, env = "INBETWEEN_DRAIN_TIMEOUT_SECS", value_name = "SECS")]
    pub drain_timeout_secs: Option<u64>,
    #[command(flatten)]
    #[serde(default)]
    pub limits: RawLimits,
}

/// The `[limits]` table / `--max-*` flags.
#[derive(Debug, Clone, Default, Deserialize, clap::Args)]
#[serde(deny_unknown_fields)]
pub struct RawLimits {
    /// Largest accepted request body, in bytes [default: 16777216].
    #[arg(long, env = "INBETWEEN_MAX_BODY_BYTES", value_name = "BYTES")]
    pub max_body_bytes: Option<usize>,
    /// Most tracks in one clip [default: 4096].
    #[arg(long, env = "INBETWEEN_MAX_TRACKS", value_name = "N")]
    pub max_tracks: Option<usize>,
    /// Most keys in one track [default: 1000000].
    #[arg(long, env = "INBETWEEN_MAX_KEYS_PER_TRACK", value_name = "N")]
    pub max_keys_per_track: Option<usize>,
    /// Most joints in one skeleton [default: 4096].
    #[arg(long, env = "INBETWEEN_MAX_JOINTS", value_name = "N")]
    pub max_joints: Option<usize>,
    /// Most poses one sample request may ask for [default: 10000].
    #[arg(long, env = "INBETWEEN_MAX_POSES", value_name = "N")]
    pub max_poses: Option<usize>,
    /// Seconds a request may take before it is answered 503 [default: 30].
    #[arg(long, env = "INBETWEEN_REQUEST_TIMEOUT_SECS", value_name = "SECS")]
    pub request_timeout_secs: Option<u64>,
    /// Seconds a client may take to send a request's head [default: 10].
    #[arg(long, env = "INBETWEEN_HEADER_READ_TIMEOUT_SECS", value_name = "SECS")]
    pub header_read_timeout_secs: Option<u64>,
    /// Compiled clips kept in memory [default: 1024].
    #[arg(long, env = "INBETWEEN_CACHE_ENTRIES", value_name = "N")]
    pub cache_entries: Option<usize>,
    /// Concurrent streams (gRPC and WebSocket together) [default: 1024].
    #[arg(long, env = "INBETWEEN_MAX_STREAMS", value_name = "N")]
    pub max_streams: Option<usize>,
    /// Concurrent streams per client IP address [default: 64].
    #[arg(long, env = "INBETWEEN_MAX_STREAMS_PER_CLIENT", value_name = "N")]
    pub max_streams_per_client: Option<usize>,
    /// Concurrent streams per bearer token [default: 64].
    #[arg(long, env = "INBETWEEN_MAX_STREAMS_PER_TOKEN", value_name = "N")]
    pub max_streams_per_token: Option<usize>,
    /// Seconds a client may take to send a request's body, once its head is in [default: 10].
    #[arg(long, env = "INBETWEEN_BODY_READ_TIMEOUT_SECS", value_name = "SECS")]
    pub body_read_timeout_secs: Option<u64>,
    /// Requests in flight (REST and gRPC each) before new ones are shed with 503 [default: 64 per core].
    #[arg(long, env = "INBETWEEN_MAX_IN_FLIGHT", value_name = "N")]
    pub max_in_flight: Option<usize>,
    /// Sustained writes per second per caller (token, or address when writes are open) [default: 100].
    #[arg(long, env = "INBETWEEN_WRITE_RATE", value_name = "PER_SEC")]
    pub write_rate: Option<u32>,
    /// Writes a caller may make in a burst above the sustained rate [default: 200].
    #[arg(long, env = "INBETWEEN_WRITE_BURST", value_name = "N")]
    pub write_burst: Option<u32>,
    /// Largest WebSocket message a stream viewer may send (controls) [default: 4096].
    #[arg(long, env = "INBETWEEN_WS_MAX_MESSAGE_BYTES", value_name = "BYTES")]
    pub ws_max_message_bytes: Option<usize>,
    /// Bytes of outgoing WebSocket frames buffered before a write is flushed [default: 131072].
    #[arg(long, env = "INBETWEEN_WS_WRITE_BUFFER_BYTES", value_name = "BYTES")]
    pub ws_write_buffer_bytes: Option<usize>,
    /// Most bytes a WebSocket may hold unsent before the stream fails [default: 16777216].
    #[arg(long, env = "INBETWEEN_WS_MAX_WRITE_BUFFER_BYTES", value_name = "BYTES")]
    pub ws_max_write_buffer_bytes: Option<usize>,
}

impl RawConfig {
    /// Reads a TOML layer.
    ///
    /// # Errors
    /// The file cannot be read, is not TOML, or names an unknown key.
    pub fn from_toml_file(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))
    }

    /// This layer over `lower`: a field set here wins.
    pub fn over(self, lower: RawConfig) -> RawConfig {
        let (l, ll) = (self.limits, lower.limits);
        RawConfig {
            listen: self.listen.or(lower.listen),
            grpc_listen: self.grpc_listen.or(lower.grpc_listen),
            data_dir: self.data_dir.or(lower.data_dir),
            database_url: self.database_url.or(lower.database_url),
            db_max_connections: self.db_max_connections.or(lower.db_max_connections),
            db_acquire_timeout_secs: self.db_acquire_timeout_secs.or(lower.db_acquire_timeout_secs),
            db_retries: self.db_retries.or(lower.db_retries),
            unsafe_fast_writes: self.unsafe_fast_writes.or(lower.unsafe_fast_writes),
            api_token: self.api_token.or(lower.api_token),
            read_token: self.read_token.or(lower.read_token),
            tokens: self.tokens.or(lower.tokens),
            tls_cert: self.tls_cert.or(lower.tls_cert),
            tls_key: self.tls_key.or(lower.tls_key),
            cors_origins: self.cors_origins.or(lower.cors_origins),
            log_format: self.log_format.or(lower.log_format),
            drain_timeout_secs: self.drain_timeout_secs.or(lower.drain_timeout_secs),
            limits: RawLimits {
                max_body_bytes: l.max_body_bytes.or(ll.max_body_bytes),
                max_tracks: l.max_tracks.or(ll.max_tracks),
                max_keys_per_track: l.max_keys_per_track.or(ll.max_keys_per_track),
                max_joints: l.max_joints.or(ll.max_joints),
                max_poses: l.max_poses.or(ll.max_poses),
                request_timeout_secs: l.request_timeout_secs.or(ll.request_timeout_secs),
                header_read_timeout_secs: l.header_read_timeout_secs.or(ll.header_read_timeout_secs),
                cache_entries: l.cache_entries.or(ll.cache_entries),
                max_streams: l.max_streams.or(ll.max_streams),
                max_streams_per_client: l.max_streams_per_client.or(ll.max_streams_per_client),
                max_streams_per_token: l.max_streams_per_token.or(ll.max_streams_per_token),
                body_read_timeout_secs: l.body_read_timeout_secs.or(ll.body_read_timeout_secs),
                max_in_flight: l.max_in_flight.or(ll.max_in_flight),
                write_rate: l.write_rate.or(ll.write_rate),
                write_burst: l.write_burst.or(ll.write_burst),
                ws_max_message_bytes: l.ws_max_message_bytes.or(ll.ws_max_message_bytes),
                ws_write_buffer_bytes: l.ws_write_buffer_bytes.or(ll.ws_write_buffer_bytes),
                ws_max_write_buffer_bytes: l.ws_max_write_buffer_bytes.or(ll.ws_max_write_buffer_bytes),
            },
        }
    }

    /// Fills defaults and checks every value.
    ///
    /// # Errors
    /// A value the server cannot run with (zero limits, an empty token, an
    /// unsupported database URL, a malformed CORS origin).
    pub fn validate(self) -> anyhow::Result<Config> {
        let d = Limits::default();
        let l = self.limits;
        let positive = |name: &str, v: Option<usize>, default: usize| -> anyhow::Result<usize> {
            match v {
                Some(0) => bail!("{name} must be at least 1"),
                Some(v) => Ok(v),
                None => Ok(default),
            }
        };
        let secs = |name: &str, v: Option<u64>, default: Duration| -> anyhow::Result<Duration> {
            match v {
                Some(0) => bail!("{name} must be at least 1 second"),
                Some(v) => Ok(Duration::from_secs(v)),
                None => Ok(default),
            }
        };
        let limits = Limits {
            max_body_bytes: positive("max_body_bytes", l.max_body_bytes, d.max_body_bytes)?,
            max_tracks: positive("max_tracks", l.max_tracks, d.max_tracks)?,
            max_keys_per_track: positive("max_keys_per_track", l.max_keys_per_track, d.max_keys_per_track)?,
            max_joints: positive("max_joints", l.max_joints, d.max_joints)?,
            max_poses: positive("max_poses", l.max_poses, d.max_poses)?,
            request_timeout: secs("request_timeout_secs", l.request_timeout_secs, d.request_timeout)?,
            header_read_timeout: secs("header_read_timeout_secs", l.header_read_timeout_secs, d.header_read_timeout)?,
            cache_entries: positive("cache_entries", l.cache_entries, d.cache_entries)?,
            max_streams: positive("max_streams", l.max_streams, d.max_streams)?,
            max_streams_per_client: positive(
                "max_streams_per_client",
                l.max_streams_per_client,
                d.max_streams_per_client,
            )?,
            max_streams_per_token: positive("max_streams_per_token", l.max_streams_per_token, d.max_streams_per_token)?,
            body_read_timeout: secs("body_read_timeout_secs", l.body_read_timeout_secs, d.body_read_timeout)?,
            max_in_flight: positive("max_in_flight", l.max_in_flight, d.max_in_flight)?,
            write_rate: positive("write_rate", l.write_rate.map(|r| r as usize), d.write_rate as usize)? as u32,
            write_burst: positive("write_burst", l.write_burst.map(|b| b as usize), d.write_burst as usize)? as u32,
            ws_max_message_bytes: positive("ws_max_message_bytes", l.ws_max_message_bytes, d.ws_max_message_bytes)?,
            ws_write_buffer_bytes: positive("ws_write_buffer_bytes", l.ws_write_buffer_bytes, d.ws_write_buffer_bytes)?,
            ws_max_write_buffer_bytes: positive(
                "ws_max_write_buffer_bytes",
                l.ws_max_write_buffer_bytes,
                d.ws_max_write_buffer_bytes,
            )?,
        };
        if limits.ws_max_write_buffer_bytes <= limits.ws_write_buffer_bytes {
            bail!("ws_max_write_buffer_bytes must be larger than ws_write_buffer_bytes");
        }
        let store = match (self.database_url, self.data_dir) {
            (Some(_), Some(_)) => bail!("give either data_dir or database_url, not both"),
            (Some(url), None) => {
                let url = url.expose();
                if url.starts_with("sqlite:") {
                    StoreConfig::SqliteUrl(Secret::new(url))
                } else if url.starts_with("postgres:") || url.starts_with("postgresql:") {
                    StoreConfig::Postgres(Secret::new(url))
                } else {
                    bail!("database_url must start with sqlite: or postgres:")
                }
            }
            (None, dir) => StoreConfig::DataDir(dir.unwrap_or_else(|| PathBuf::from("data"))),
        };
        let db = {
            let d = crate::store::PoolSettings::default();
            crate::store::PoolSettings {
                max_connections: match self.db_max_connections {
                    Some(0) => bail!("db_max_connections must be at least 1"),
                    n => n.unwrap_or(d.max_connections),
                },
                acquire_timeout: secs("db_acquire_timeout_secs", self.db_acquire_timeout_secs, d.acquire_timeout)?,
                retry: crate::store::RetryPolicy { retries: self.db_retries.unwrap_or(d.retry.retries), ..d.retry },
                durability: if self.unsafe_fast_writes.unwrap_or(false) {
                    crate::store::Durability::UnsafeFast
                } else {
                    crate::store::Durability::Required
                },
            }
        };
        let token = |name: &str, t: Option<Secret>| -> anyhow::Result<Option<Secret>> {
            match t {
                Some(t) if t.expose().trim().is_empty() => bail!("{name} must not be empty"),
                Some(t) if t.expose().chars().any(|c| c.is_whitespace() || c.is_control()) => {
                    bail!("{name} must not contain spaces or control characters")
                }
                t => Ok(t),
            }
        };
        let tokens = self.tokens.unwrap_or_default();
        let mut names = std::collections::HashSet::new();
        let mut checked = Vec::with_capacity(tokens.len());
        for spec in tokens {
            let t = spec.validate().map_err(anyhow::Error::msg)?;
            if !names.insert(t.name.clone()) {
                bail!("two tokens are named `{}`", t.name);
            }
            checked.push(t);
        }
        let tls = match (self.tls_cert, self.tls_key) {
            (Some(cert), Some(key)) => Some(TlsFiles { cert, key }),
            (None, None) => None,
            _ => bail!("tls_cert and tls_key go together"),
        };
        let cors = match self.cors_origins.unwrap_or_default() {
            origins if origins.is_empty() => Cors::Off,
            origins if origins.iter().any(|o| o == "*") => {
                if origins.len() > 1 {
                    bail!("cors origin `*` cannot be combined with other origins");
                }
                Cors::Any
            }
            origins => {
                for o in &origins {
                    let ok = (o.starts_with("http://") || o.starts_with("https://"))
                        && !o.ends_with('/')
                        && axum::http::HeaderValue::from_str(o).is_ok();
                    if !ok {
                        bail!("cors origin `{o}` must look like https://host[:port], without a path");
                    }
                }
                Cors::Origins(origins)
            }
        };
        Ok(Config {
            listen: self.listen.unwrap_or_else(|| SocketAddr::from(([127, 0, 0, 1], 8080))),
            grpc_listen: self.grpc_listen.unwrap_or_else(|| SocketAddr::from(([127, 0, 0, 1], 50051))),
            store,
            db,
            write_token: token("api_token", self.api_token)?,
            read_token: token("read_token", self.read_token)?,
            tokens: checked,
            tls,
            cors,
            log_format: self.log_format.unwrap_or_default(),
            drain_timeout: Duration::from_secs(self.drain_timeout_secs.unwrap_or(10)),
            limits,
        })
    }
}

/// Where clips are stored.
#[derive(Debug, Clone, PartialEq)]
pub enum StoreConfig {
    /// `DIR/inbetween.db`, the directory created if missing.
    DataDir(PathBuf),
    /// A `sqlite:` URL.
    SqliteUrl(Secret),
    /// A `postgres:` URL: the shared store of a multi-node deployment.
    Postgres(Secret),
}

/// The PEM files of `--tls-cert` / `--tls-key` (read when the server is built).
#[derive(Debug, Clone, PartialEq)]
pub struct TlsFiles {
    pub cert: PathBuf,
    pub key: PathBuf,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Cors {
    Off,
    Any,
    Origins(Vec<String>),
}

/// Input limits. Everything past one is refused with a 4xx, never
/// half-processed.
#[derive(Debug, Clone, PartialEq)]
pub struct Limits {
    pub max_body_bytes: usize,
    pub max_tracks: usize,
    pub max_keys_per_track: usize,
    pub max_joints: usize,
    pub max_poses: usize,
    pub request_timeout: Duration,
    /// How long a connection may take to send a request head (slowloris guard).
    pub header_read_timeout: Duration,
    pub cache_entries: usize,
    /// Concurrent streams, all clients together, and per client address.
    pub max_streams: usize,
    pub max_streams_per_client: usize,
    /// Concurrent streams per bearer token (keyed by a hash of the token).
    pub max_streams_per_token: usize,
    /// How long a request body may take to arrive (slow-body guard): 408.
    pub body_read_timeout: Duration,
    /// Requests in flight per protocol before new ones are shed (503 /
    /// `RESOURCE_EXHAUSTED`), so an overload never queues without bound.
    pub max_in_flight: usize,
    /// The per-caller write token bucket: refill per second, and its size.
    pub write_rate: u32,
    pub write_burst: u32,
    /// WebSocket limits: inbound message and frame size, and the outgoing
    /// buffer (flush threshold, and the most a slow viewer may hold).
    pub ws_max_message_bytes: usize,
    pub ws_write_buffer_bytes: usize,
    pub ws_max_write_buffer_bytes: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_body_bytes: 16 * 1024 * 1024,
            max_tracks: 4096,
            max_keys_per_track: 1_000_000,
            max_joints: 4096,
            max_poses: 10_000,
            request_timeout: Duration::from_secs(30),
            header_read_timeout: Duration::from_secs(10),
            cache_entries: 1024,
            max_streams: 1024,
            max_streams_per_client: 64,
            max_streams_per_token: 64,
            body_read_timeout: Duration::from_secs(10),
            max_in_flight: 64 * std::thread::available_parallelism().map_or(1, std::num::NonZero::get),
            write_rate: 100,
            write_burst: 200,
            ws_max_message_bytes: 4096,
            ws_write_buffer_bytes: 128 * 1024,
            ws_max_write_buffer_bytes: 16 * 1024 * 1024,
        }
    }
}

/// A validated configuration: every value is one the server can run with.
#[derive(Debug, Clone)]
pub struct Config {
    pub listen: SocketAddr,
    /// The gRPC API's own port (see `server::grpc`).
    pub grpc_listen: SocketAddr,
    pub store: StoreConfig,
    /// Pool size, retries and the durability requirement of the store.
    pub db: crate::store::PoolSettings,
    pub write_token: Option<Secret>,
    pub read_token: Option<Secret>,
    /// Scoped tokens (hashes), beside the plain write and read tokens.
    pub tokens: Vec<Token>,
    /// Serve both listeners over TLS with these files.
    pub tls: Option<TlsFiles>,
    pub cors: Cors,
    pub log_format: LogFormat,
    pub drain_timeout: Duration,
    pub limits: Limits,
}

impl Config {
    /// Defaults with the given listen address and data directory (tests use
    /// `127.0.0.1:0` and a temporary directory). The gRPC API listens on the
    /// same IP address, on a free port.
    pub fn new(listen: SocketAddr, data_dir: impl Into<PathBuf>) -> Config {
        let raw = RawConfig {
            listen: Some(listen),
            grpc_listen: Some(SocketAddr::new(listen.ip(), 0)),
            data_dir: Some(data_dir.into()),
            ..RawConfig::default()
        };
        raw.validate().expect("the defaults are valid")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upper_layers_win_and_defaults_fill_the_rest() {
        let file: RawConfig = toml::from_str(
            "listen = \"127.0.0.1:9000\"\napi_token = \"from-file\"\n[limits]\nmax_poses = 5\nmax_tracks = 7\n",
        )
        .unwrap();
        let flags = RawConfig {
            api_token: Some(Secret::new("from-flag")),
            limits: RawLimits { max_poses: Some(9), ..RawLimits::default() },
            ..RawConfig::default()
        };
        let c = flags.over(file).validate().unwrap();
        assert_eq!(c.listen, "127.0.0.1:9000".parse().unwrap());
        assert_eq!(c.write_token.as_ref().map(Secret::expose), Some("from-flag"));
        assert_eq!((c.limits.max_poses, c.limits.max_tracks, c.limits.max_joints), (9, 7, 4096));
        assert_eq!(c.store, StoreConfig::DataDir(PathBuf::from("data")));
    }

    #[test]
    fn scoped_tokens_come_from_toml_and_flags() {
        let hash = crate::server::tokens::TokenHash::of(b"t");
        let file: RawConfig = toml::from_str(&format!(
            "[[tokens]]\nname = \"ci\"\nscopes = [\"write\"]\nhash = \"{hash}\"\n\
             [[tokens]]\nname = \"ops\"\nscopes = [\"admin\"]\nhash = \"{hash}\"\n"
        ))
        .unwrap();
        let c = file.clone().validate().unwrap();
        assert_eq!(c.tokens.iter().map(|t| &*t.name).collect::<Vec<_>>(), ["ci", "ops"]);
        // The flag form replaces the file's list.
        let flags =
            RawConfig { tokens: Some(vec![format!("viewer:read:{hash}").parse().unwrap()]), ..Default::default() };
        let c = flags.over(file).validate().unwrap();
        assert_eq!(c.tokens.len(), 1);
        let twice = format!("[[tokens]]\nname = \"a\"\nscopes = [\"read\"]\nhash = \"{hash}\"\n");
        let dup: RawConfig = toml::from_str(&format!("{twice}{twice}")).unwrap();
        assert!(dup.validate().is_err(), "duplicate names");
        assert!(
            toml::from_str::<RawConfig>("[[tokens]]\nname = \"a\"\nscopes = [\"read\"]\ntoken = \"plain\"\n").is_err()
        );
    }

    #[test]
    fn secrets_never_print() {
        let c = RawConfig { api_token: Some(Secret::new("hunter2")), ..RawConfig::default() }.validate().unwrap();
        assert!(!format!("{c:?}").contains("hunter2"));
    }

    #[test]
    fn unknown_keys_and_bad_values_are_refused() {
        assert!(toml::from_str::<RawConfig>("lisen = \"x\"").is_err());
        let zero = RawConfig { limits: RawLimits { max_poses: Some(0), ..Default::default() }, ..Default::default() };
        assert!(zero.validate().is_err());
        let mysql = RawConfig { database_url: Some(Secret::new("mysql://x")), ..Default::default() };
        assert!(mysql.validate().is_err());
        let pool = RawConfig { db_max_connections: Some(0), ..Default::default() };
        assert!(pool.validate().is_err());
        let cors = RawConfig { cors_origins: Some(vec!["*".into(), "https://a.b".into()]), ..Default::default() };
        assert!(cors.validate().is_err());
    }

    #[test]
    fn store_settings_come_from_the_layers() {
        let pg = RawConfig {
            database_url: Some(Secret::new("postgres://u@h/db")),
            db_max_connections: Some(3),
            db_retries: Some(0),
            unsafe_fast_writes: Some(true),
            ..Default::default()
        };
        let c = pg.validate().unwrap();
        assert_eq!(c.store, StoreConfig::Postgres(Secret::new("postgres://u@h/db")));
        assert_eq!((c.db.max_connections, c.db.retry.retries), (3, 0));
        assert_eq!(c.db.durability, crate::store::Durability::UnsafeFast);
        let d = RawConfig::default().validate().unwrap();
        assert_eq!(d.db.durability, crate::store::Durability::Required);
        let file: RawConfig = toml::from_str("unsafe_fast_writes = true\ndb_acquire_timeout_secs = 2\n").unwrap();
        let c = file.validate().unwrap();
        assert_eq!(
            (c.db.durability, c.db.acquire_timeout),
            (crate::store::Durability::UnsafeFast, Duration::from_secs(2))
        );
    }
}
