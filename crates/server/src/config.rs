//! Typed, layered configuration: defaults → TOML file (`--config`) → `INBETWEEN_*`
//! environment → command-line flags, each layer overriding the one before.
//!
//! Every setting is one row of a `settings!` table: its name and value
//! type, its default, the check it must pass, its TOML key, flag, environment
//! variable, value name and help. From the rows come the layer struct
//! ([`RawConfig`], [`RawLimits`]: every field optional, absent meaning "ask
//! the layer below"; at once the clap flags and the TOML schema, so the two
//! cannot drift apart), the merge of two layers ([`RawConfig::over`]), and
//! the checked values with their defaults filled in, and the settings table
//! of docs/configuration.md (`doc`: a row's `doc` text, else its help). What several settings
//! decide together (the store, its pool, TLS, tokens) is checked after that,
//! one short function per concern, into a [`Config`], which only holds values
//! the server can run with. Tokens and database URLs are [`Secret`]s, which
//! never print. Plain data: nothing here imports another server module but
//! the token types (`server::tokens`).

use std::collections::HashSet;
use std::fmt;
use std::net::{IpAddr, SocketAddr};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Duration;

use anyhow::{Context, bail};
use serde::Deserialize;

use super::tokens::{Token, TokenSpec};
use crate::store::{Durability, PoolSettings, RetryPolicy};

#[cfg(test)]
mod doc;

/// Declares a table of settings, one row each:
///
/// ```text
/// #[arg(extra clap attributes)]
/// name: Type [= default] => check -> Checked,
///     "toml_key", "flag", "INBETWEEN_VAR", "VALUE", [shown "default as text",] "help" [, doc "for the docs"];
/// ```
///
/// and generates the layer struct (`Option<Type>` fields, renamed to the
/// TOML key, with the flag, variable and help — the default appended — for
/// clap), `over` (merge two layers), the checked struct (`Checked` fields,
/// documented by the help) and `checked`, which fills in each default and
/// runs `check(toml_key, value)`. A row without a default checks an
/// `Option<Type>`. One nested table (`[limits]`) may follow the rows.
macro_rules! settings {
    (
        layer: $(#[$raw_meta:meta])* $raw_vis:vis struct $Raw:ident,
        checked: $(#[$checked_meta:meta])* $checked_vis:vis struct $Checked:ident,
        $(nested: $sub:ident: $SubRaw:ident => $SubChecked:ident,)?
        table: $table:literal,
        rows: {
            $(
                $(#[$arg:meta])*
                $name:ident: $ty:ty $(= $default:expr)? => $check:ident -> $out:ty,
                $toml:literal, $flag:literal, $env:literal, $value:literal, $(shown $shown:literal,)? $help:literal
                $(, doc $doc:literal)?;
            )*
        }
    ) => {
        $(#[$raw_meta])*
        #[derive(Debug, Clone, Default, Deserialize, clap::Args)]
        #[serde(deny_unknown_fields)]
        $raw_vis struct $Raw {
            $(
                #[serde(rename = $toml)]
                #[arg(long = $flag, env = $env, value_name = $value)]
                #[arg(help = setting_help!($help $(, shown $shown)? $(, default $default)?))]
                $(#[$arg])*
                pub $name: Option<$ty>,
            )*
            $(
                #[command(flatten)]
                #[serde(default)]
                pub $sub: $SubRaw,
            )?
        }

        $(#[$checked_meta])*
        $checked_vis struct $Checked {
            $(
                #[doc = $help]
                pub $name: $out,
            )*
            $(pub $sub: $SubChecked,)?
        }

        impl $Raw {
            /// This layer over `lower`: a setting given here wins.
            pub fn over(self, lower: $Raw) -> $Raw {
                $Raw {
                    $($name: self.$name.or(lower.$name),)*
                    $($sub: self.$sub.over(lower.$sub),)?
                }
            }

            /// Fills in the defaults and checks each setting on its own.
            fn checked(self) -> anyhow::Result<$Checked> {
                Ok($Checked {
                    $($name: $check($toml, setting_value!(self.$name $(, $default)?))?,)*
                    $($sub: self.$sub.checked()?,)?
                })
            }

            /// The TOML key, flag and environment variable of every row.
            #[cfg(test)]
            const NAMES: &'static [[&'static str; 3]] = &[$([$toml, $flag, $env]),*];

            /// Every row as docs/configuration.md shows it, then the nested table's.
            #[cfg(test)]
            fn doc_rows() -> Vec<doc::Row> {
                let rows = vec![$(doc::Row {
                    table: $table,
                    toml: $toml,
                    flag: $flag,
                    env: $env,
                    value: $value,
                    ty: stringify!($ty),
                    default: setting_default!($(shown $shown)? $(, default $default)?),
                    meaning: setting_doc!($help $(, $doc)?),
                }),*];
                #[allow(unused_mut)]
                let mut rows = rows;
                $(rows.extend($SubRaw::doc_rows());)?
                rows
            }
        }
    };
}

/// A row's default as the document shows it: the `shown` text as is, a
/// value in code style, or none.
#[cfg(test)]
macro_rules! setting_default {
    (shown $shown:literal $(, default $default:expr)?) => {
        doc::Default::Shown($shown)
    };
    (, default $default:expr) => {
        doc::Default::Value($default.to_string())
    };
    () => {
        doc::Default::None
    };
}

/// A row's meaning in the document: its `doc` text, else its help.
#[cfg(test)]
macro_rules! setting_doc {
    ($help:literal, $doc:literal) => {
        $doc
    };
    ($help:literal) => {
        $help
    };
}

/// A row's help, with its default when it has one.
macro_rules! setting_help {
    ($help:literal, shown $shown:literal $(, default $default:expr)?) => {
        concat!($help, " [default: ", $shown, "]")
    };
    ($help:literal, default $default:expr) => {
        format!("{} [default: {}]", $help, $default)
    };
    ($help:literal) => {
        $help
    };
}

/// A layer's value of a row, or the row's default.
macro_rules! setting_value {
    ($value:expr, $default:expr) => {
        $value.unwrap_or_else(|| $default)
    };
    ($value:expr) => {
        $value
    };
}

settings! {
    layer:
    /// One layer of configuration (flags, environment, or the TOML file).
    pub struct RawConfig,
    checked:
    /// [`RawConfig`] with defaults filled in and each value checked.
    struct Settings,
    nested: limits: RawLimits => Limits,
    table: "",
    rows: {
        listen: SocketAddr = SocketAddr::from(([127, 0, 0, 1], 8080)) => as_given -> SocketAddr,
            "listen", "listen", "INBETWEEN_LISTEN", "ADDR",
            "Address to listen on (port 0 picks a free port)",
            doc "The HTTP address: REST, WebSocket streams, the viewer, the OpenAPI document (port 0 picks a free port)";
        grpc_listen: SocketAddr = SocketAddr::from(([127, 0, 0, 1], 50051)) => as_given -> SocketAddr,
            "grpc_listen", "grpc-listen", "INBETWEEN_GRPC_LISTEN", "ADDR",
            "Address of the gRPC API (port 0 picks a free port)",
            doc "The gRPC address (port 0 picks a free port)";
        data_dir: PathBuf => as_given -> Option<PathBuf>,
            "data_dir", "data-dir", "INBETWEEN_DATA_DIR", "DIR", shown "./data",
            "Directory of the embedded SQLite store, created if missing",
            doc "Directory of the embedded SQLite store `DIR/inbetween.db`, created if missing";
        #[arg(hide_env_values = true)]
        database_url: Secret => as_given -> Option<Secret>,
            "database_url", "database-url", "INBETWEEN_DATABASE_URL", "URL",
            "A store URL instead of --data-dir (`sqlite://path/to/file.db`, or `postgres://user@host/db` for \
             several nodes sharing one database)",
            doc "A store URL instead of `--data-dir` (giving both is an error): `sqlite://path/file.db` (directory \
             created if missing), or PostgreSQL for several nodes, e.g. `postgres://user:password@host:5432/db` (the \
             tables are created on first start; [operations.md](operations.md#scaling-out-over-postgresql))";
        db_max_connections: u32 = PoolSettings::default().max_connections => positive -> u32,
            "db_max_connections", "db-max-connections", "INBETWEEN_DB_MAX_CONNECTIONS", "N",
            "Most database connections this node opens",
            doc "Database connections this node opens at most";
        db_acquire_timeout: u64 = PoolSettings::default().acquire_timeout.as_secs() => seconds -> Duration,
            "db_acquire_timeout_secs", "db-acquire-timeout-secs", "INBETWEEN_DB_ACQUIRE_TIMEOUT_SECS", "SECS",
            "Seconds a request waits for a free database connection before it fails with 503",
            doc "Seconds a request waits for a free database connection before it is answered 503";
        db_retries: u32 = RetryPolicy::default().retries => as_given -> u32,
            "db_retries", "db-retries", "INBETWEEN_DB_RETRIES", "N",
            "Retries of a transiently failed database operation, with exponential backoff from 50 ms";
        #[arg(num_args = 0..=1, default_missing_value = "true")]
        #[arg(value_parser = clap::builder::BoolishValueParser::new())]
        unsafe_fast_writes: bool = false => as_given -> bool,
            "unsafe_fast_writes", "unsafe-fast-writes", "INBETWEEN_UNSAFE_FAST_WRITES", "BOOL",
            "Start even if the database would acknowledge writes before they are durable (SQLite then runs \
             with synchronous=NORMAL): a crash or power loss may lose acknowledged clips",
            doc "Start even if the database would acknowledge writes before they are durable (SQLite then runs with \
             `synchronous=NORMAL`); without it the server refuses such a database";
        #[arg(hide_env_values = true)]
        api_token: Secret => plain_token -> Option<Secret>,
            "api_token", "api-token", "INBETWEEN_API_TOKEN", "TOKEN",
            "Bearer token required by create, replace and delete",
            doc "Plain bearer token for writes (create, replace, delete, import); without any write token, writes are \
             open";
        #[arg(hide_env_values = true)]
        read_token: Secret => plain_token -> Option<Secret>,
            "read_token", "read-token", "INBETWEEN_READ_TOKEN", "TOKEN",
            "Bearer token required to read clips and poses (the write token also works)",
            doc "Plain bearer token for reads (clips, poses, streams; the write token also reads); without it, reads are \
             open";
        #[arg(value_delimiter = ',')]
        tokens: Vec<TokenSpec> => scoped_tokens -> Vec<Token>,
            "tokens", "token", "INBETWEEN_TOKENS", "NAME:SCOPES:HASH",
            "A scoped token, as NAME:SCOPE[+SCOPE]:sha256:HEX (repeatable, or comma-separated; TOML: \
             `[[tokens]]` tables with name, scopes, hash). `inbetween token new` makes one",
            doc "Scoped tokens by hash, `NAME:SCOPE[+SCOPE]:sha256:HEX` \
             ([operations.md](operations.md#tokens-and-scopes)); `inbetween token new` makes one";
        #[arg(requires = "tls_key")]
        tls_cert: PathBuf => as_given -> Option<PathBuf>,
            "tls_cert", "tls-cert", "INBETWEEN_TLS_CERT", "FILE",
            "PEM certificate chain: serve HTTP and gRPC over TLS (1.2+; needs --tls-key)",
            doc "PEM certificate chain: serve HTTP and gRPC over TLS 1.2 or 1.3 (needs `--tls-key`)";
        #[arg(requires = "tls_cert")]
        tls_key: PathBuf => as_given -> Option<PathBuf>,
            "tls_key", "tls-key", "INBETWEEN_TLS_KEY", "FILE",
            "PEM private key of --tls-cert",
            doc "PEM private key of `--tls-cert`";
        #[arg(value_delimiter = ',')]
        cors_origins: Vec<String> => cors -> Cors,
            "cors_origins", "cors-origin", "INBETWEEN_CORS_ORIGINS", "ORIGIN", shown "none",
            "Browser origin allowed by CORS (repeatable, or comma-separated; `*` for any)",
            doc "Browser origins allowed by CORS; `*` allows any";
        #[arg(value_enum)]
        log_format: LogFormat = LogFormat::Text => as_given -> LogFormat,
            "log_format", "log-format", "INBETWEEN_LOG_FORMAT", "FORMAT",
            "Log format; the filter comes from INBETWEEN_LOG or RUST_LOG",
            doc "`text` or `json` logs on stderr; the filter is `INBETWEEN_LOG` or `RUST_LOG` (default `info`)";
        drain_timeout: u64 = 10 => seconds_or_none -> Duration,
            "drain_timeout_secs", "drain-timeout-secs", "INBETWEEN_DRAIN_TIMEOUT_SECS", "SECS",
            "Seconds to let in-flight requests finish after SIGTERM/Ctrl-C",
            doc "Seconds in-flight requests get to finish after SIGTERM or Ctrl-C (0: do not wait)";
        #[arg(value_delimiter = ',')]
        trusted_proxies: Vec<String> => trusted_proxies -> TrustedProxies,
            "trusted_proxies", "trusted-proxy", "INBETWEEN_TRUSTED_PROXIES", "IP_OR_CIDR", shown "none",
            "Reverse proxy address or CIDR (repeatable, or comma-separated) whose X-Forwarded-For / Forwarded \
             header names the client; from any other peer those headers are ignored",
            doc "IPs or CIDRs of reverse proxies: only from them does `X-Forwarded-For` / `Forwarded` name the client";
        #[arg(num_args = 0..=1, default_missing_value = "true")]
        #[arg(value_parser = clap::builder::BoolishValueParser::new())]
        compression: bool = true => as_given -> bool,
            "compression", "compression", "INBETWEEN_COMPRESSION", "BOOL",
            "Compress answers for clients that ask (REST: gzip, br or zstd by Accept-Encoding; gRPC: gzip or zstd \
             by grpc-accept-encoding) and decode request bodies and gRPC messages sent compressed, whose byte \
             limits count decoded bytes; false: identity only, both ways",
            doc "Compress answers for clients that ask (REST: zstd, br or gzip by `Accept-Encoding`; gRPC: gzip or zstd \
             by `grpc-accept-encoding`, unary answers under 64 KiB only) and decode compressed request bodies and gRPC \
             messages, their limits counting decoded bytes; `false`: identity only, both ways \
             ([api.md](api.md#compression))";
        compression_min_bytes: usize = 1024 => as_given -> usize,
            "compression_min_bytes", "compression-min-bytes", "INBETWEEN_COMPRESSION_MIN_BYTES", "BYTES",
            "Smallest REST answer compressed (a known length under it goes as it is; answers sent in pieces are \
             always compressed)",
            doc "A REST answer of a known length under it goes uncompressed (answers sent in pieces are always compressed \
             when asked)";
        access_log_sample: f64 = 0.01 => fraction -> f64,
            "access_log_sample", "access-log-sample", "INBETWEEN_ACCESS_LOG_SAMPLE", "FRACTION",
            "Fraction of REST requests answered 1xx-3xx that get an access log line (target inbetween::access); \
             every 4xx and 5xx gets one",
            doc "The share of REST requests answered 1xx–3xx that get an access log line; every 4xx and 5xx gets one \
             ([operations.md](operations.md#logs))";
    }
}

settings! {
    layer:
    /// The `[limits]` table / `--max-*` flags.
    pub struct RawLimits,
    checked:
    /// Input and resource limits. Everything past one is refused with a 4xx
    /// (or shed with a 503), never half-processed.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Limits,
    table: "limits",
    rows: {
        max_body_bytes: usize = 16 * 1024 * 1024 => positive -> usize,
            "max_body_bytes", "max-body-bytes", "INBETWEEN_MAX_BODY_BYTES", "BYTES",
            "Largest accepted request body, in bytes",
            doc "Request bodies held in memory (413 `body_too_large`); for an import, what is held whole: a `.gltf` or \
             `.bvh` file, a GLB's JSON chunk (413 `document_too_large`)";
        max_import_resolved_bytes: usize = 64 * 1024 * 1024 => positive -> usize,
            "max_import_resolved_bytes", "max-import-resolved-bytes", "INBETWEEN_MAX_IMPORT_RESOLVED_BYTES", "BYTES",
            "Bytes of glTF buffers one import may read (every buffer's byteLength, even when shared)",
            doc "GlTF buffers named by URI (`data:`, or the multipart parts beside a `.gltf`) one import opens, each \
             buffer's `byteLength` counted even when several share a part (413 `resolved_bytes_too_large`); a GLB's \
             own BIN chunk is bounded by `max_import_bytes` instead";
        max_import_bytes: usize = 256 * 1024 * 1024 => positive -> usize,
            "max_import_bytes", "max-import-bytes", "INBETWEEN_MAX_IMPORT_BYTES", "BYTES",
            "Largest file `POST /v1/clips/import` accepts: spooled to a temporary file, of which only the glTF JSON \
             and the animation data are read",
            doc "The largest file `POST /v1/clips/import` takes, spooled to a temporary file (in `$TMPDIR`) as it \
             arrives, of which only the glTF JSON and the animation and skin data are read (413 `body_too_large`). Uploads \
             take slots: `max_import_uploads` per node, `max_import_uploads_per_caller` per caller";
        max_import_uploads: usize = 8 => positive -> usize,
            "max_import_uploads", "max-import-uploads", "INBETWEEN_MAX_IMPORT_UPLOADS", "N",
            "Import uploads spooled at once, all callers together (their disk is at most this many times \
             max_import_bytes); as many more may wait import_slot_wait_secs for a slot";
        max_import_uploads_per_caller: usize = 2 => positive -> usize,
            "max_import_uploads_per_caller", "max-import-uploads-per-caller", "INBETWEEN_MAX_IMPORT_UPLOADS_PER_CALLER",
            "N",
            "Import uploads one caller (its token's name, or its address) may spool at once";
        import_slot_wait: u64 = 2 => seconds_or_none -> Duration,
            "import_slot_wait_secs", "import-slot-wait-secs", "INBETWEEN_IMPORT_SLOT_WAIT_SECS", "SECS",
            "Seconds an import waits for an upload slot (its caller's and the node's) before it is answered 503 \
             `overloaded` with Retry-After (0: not at all)";
        min_upload_bytes_per_sec: u64 = 16 * 1024 => as_given -> u64,
            "min_upload_bytes_per_sec", "min-upload-bytes-per-sec", "INBETWEEN_MIN_UPLOAD_BYTES_PER_SEC", "BYTES",
            "Slowest import upload: one that brings fewer bytes per second over the last upload_rate_window_secs \
             (checked once it has been sending that long) is cut off with 408 `body_timeout` and its slot freed \
             (0: no floor)";
        upload_rate_window: u64 = 3 => seconds -> Duration,
            "upload_rate_window_secs", "upload-rate-window-secs", "INBETWEEN_UPLOAD_RATE_WINDOW_SECS", "SECS",
            "Seconds over which an import upload's arrival rate is measured, and its grace before the first check";
        max_texture_pixels: u64 = 4096 * 4096 => positive -> u64,
            "max_texture_pixels", "max-texture-pixels", "INBETWEEN_MAX_TEXTURE_PIXELS", "PIXELS",
            "Largest texture a glTF import keeps with its mesh, as width × height read from the image's header \
             (PNG IHDR, JPEG SOF); over it the mesh is kept without it and a `not_imported` warning says why";
        max_tracks: usize = 4096 => positive -> usize,
            "max_tracks", "max-tracks", "INBETWEEN_MAX_TRACKS", "N",
            "Most tracks in one clip",
            doc "Tracks in one clip (422 `too_many_tracks`)";
        max_keys_per_track: usize = 1_000_000 => positive -> usize,
            "max_keys_per_track", "max-keys-per-track", "INBETWEEN_MAX_KEYS_PER_TRACK", "N",
            "Most keys in one track",
            doc "Keys in one track (422 `too_many_keys`)";
        max_joints: usize = 4096 => positive -> usize,
            "max_joints", "max-joints", "INBETWEEN_MAX_JOINTS", "N",
            "Most joints in one skeleton",
            doc "Joints in one skeleton (422 `too_many_joints`)";
        max_parameters: usize = 1024 => positive -> usize,
            "max_parameters", "max-parameters", "INBETWEEN_MAX_PARAMETERS", "N",
            "Most parameter tracks (docs/clip-format.md §3: morph weights, camera or light values) in one clip",
            doc "Parameter tracks per clip (422 `too_many_parameters`); each key has at most 256 numbers";
        max_poses: usize = 10_000 => positive -> usize,
            "max_poses", "max-poses", "INBETWEEN_MAX_POSES", "N",
            "Most poses one sample request may ask for",
            doc "Poses per sample request";
        max_joint_poses: usize = 16 * 1024 * 1024 => positive -> usize,
            "max_joint_poses", "max-joint-poses", "INBETWEEN_MAX_JOINT_POSES", "N",
            "Most poses × joints one sample request may ask for (the evaluation work it costs)",
            doc "Poses × joints per sample request (422 `too_many_poses`)";
        max_answer_bytes: usize = 256 * 1024 * 1024 => positive -> usize,
            "max_answer_bytes", "max-answer-bytes", "INBETWEEN_MAX_ANSWER_BYTES", "BYTES",
            "Largest encoded answer (joint names included) one pose request may produce, estimated before \
             anything is evaluated",
            doc "The largest pose answer, as estimated before evaluating (422 `answer_too_large`)";
        max_frame_bytes: usize = 1024 * 1024 => positive -> usize,
            "max_frame_bytes", "max-frame-bytes", "INBETWEEN_MAX_FRAME_BYTES", "BYTES",
            "Largest encoded stream frame, estimated when the stream opens",
            doc "The largest stream frame, as estimated when it opens (422 `frame_too_large`)";
        max_stream_bytes_per_sec: usize = 64 * 1024 * 1024 => positive -> usize,
            "max_stream_bytes_per_sec", "max-stream-bytes-per-sec", "INBETWEEN_MAX_STREAM_BYTES_PER_SEC", "BYTES",
            "Most bytes per second one stream may send (fps × the frame estimate)",
            doc "Fps × frame estimate of one stream (422 `stream_rate_too_high`)";
        request_timeout: u64 = 30 => seconds -> Duration,
            "request_timeout_secs", "request-timeout-secs", "INBETWEEN_REQUEST_TIMEOUT_SECS", "SECS",
            "Seconds a request may take before it is answered 503",
            doc "Seconds a request may take before it is answered 503 `request_timeout`";
        header_read_timeout: u64 = 10 => seconds -> Duration,
            "header_read_timeout_secs", "header-read-timeout-secs", "INBETWEEN_HEADER_READ_TIMEOUT_SECS", "SECS",
            "Seconds a client may take to send a request's head (slowloris guard)",
            doc "A connection that takes longer to send a request head is closed";
        cache_entries: usize = 1024 => positive -> usize,
            "cache_entries", "cache-entries", "INBETWEEN_CACHE_ENTRIES", "N",
            "Compiled clips kept in memory",
            doc "Compiled clips in memory";
        cache_bytes: usize = 256 * 1024 * 1024 => positive -> usize,
            "cache_bytes", "cache-bytes", "INBETWEEN_CACHE_BYTES", "BYTES",
            "Heap bytes the caches keep together: compiled clips and built motions (additive layers' reference \
             poses included); the least recently used entry of any of them leaves first, and an entry larger than \
             this is used once and not kept",
            doc "Heap bytes the caches keep together: compiled clips and built motions (additive layers' reference \
             poses included), the least recently used entry of either evicted first; an entry larger than this is \
             used once and not kept (`inbetween_cache_bytes` on `/metrics`)";
        motion_cache_entries: usize = 1024 => positive -> usize,
            "motion_cache_entries", "motion-cache-entries", "INBETWEEN_MOTION_CACHE_ENTRIES", "N",
            "Built motions (composed requests' layer stacks) kept in memory, keyed by the motion and its clip \
             versions (least recently used leave first); their bytes count on cache_bytes",
            doc "Built motions in memory, keyed by the motion and its layers' clip versions, so a composed request \
             repeated every frame is not rebuilt; their bytes count on `cache_bytes`; a replaced, deleted or evicted \
             clip drops its motions (`inbetween_motion_cache_{hits,misses}_total`, `inbetween_motion_cache_entries` \
             on `/metrics`)";
        max_graph_bytes: usize = 1024 * 1024 => positive -> usize,
            "max_graph_bytes", "max-graph-bytes", "INBETWEEN_MAX_GRAPH_BYTES", "BYTES",
            "Largest graph document POST/PUT /v1/graphs accepts (over it: 413 body_too_large)",
            doc "Bytes of one graph document (docs/graphs.md), REST body or gRPC message (over it: 413 \
             `body_too_large`, before it is parsed)";
        max_graph_nodes: usize = 256 => positive -> usize,
            "max_graph_nodes", "max-graph-nodes", "INBETWEEN_MAX_GRAPH_NODES", "N",
            "Nodes of one graph (over it: 422 too_many_nodes at /nodes)",
            doc "Nodes of one graph (over it: 422 `too_many_nodes` at `/nodes`); each is built as a motion when the \
             graph is checked and again when it is first used";
        max_blend_points: usize = 32 => positive -> usize,
            "max_blend_points", "max-blend-points", "INBETWEEN_MAX_BLEND_POINTS", "N",
            "Points of one blend1d or blend2d node (at most 32: each is a layer; over it: 422 too_many_points)",
            doc "Points of one `blend1d` or `blend2d` node, at most 32 (each point is a layer of the node's motion): \
             over it 422 `too_many_points` at the node's `points`, checked before the blend space is triangulated";
        graph_cache_entries: usize = 256 => positive -> usize,
            "graph_cache_entries", "graph-cache-entries", "INBETWEEN_GRAPH_CACHE_ENTRIES", "N",
            "Built graphs and characters kept in memory, each by id at one version; their bytes count on cache_bytes",
            doc "Built graphs (blend spaces triangulated, every state's motion built) and checked characters kept in \
             memory, each kind up to this many, by id at one version; their bytes count on `cache_bytes`; a \
             replaced or deleted one, on any node, leaves";
        max_build_work: u64 = anim::DEFAULT_BUILD_WORK => positive -> u64,
            "max_build_work", "max-build-work", "INBETWEEN_MAX_BUILD_WORK", "UNITS",
            "Work one clip's build may take: quadrature evaluations plus arc-length pieces of its constant-speed \
             tables, over the whole clip (over it: 422 build_budget_exceeded)",
            doc "Work units one clip's build may take (quadrature evaluations plus arc-length pieces of its \
             constant-speed tables, over the whole clip; the default is about 0.4 s of one core): over it an upload, \
             import or `PutClip` is refused with 422 `build_budget_exceeded`";
        ik_max_constraints: usize = 32 => positive -> usize,
            "ik_max_constraints", "ik-max-constraints", "INBETWEEN_IK_MAX_CONSTRAINTS", "N",
            "IK constraints in one clip, motion or stream control (over it: 422 too_many_constraints)",
            doc "IK constraints in one clip, motion or `ik` stream control (over it: 422 `too_many_constraints`)";
        ik_max_effectors: usize = 16 => positive -> usize,
            "ik_max_effectors", "ik-max-effectors", "INBETWEEN_IK_MAX_EFFECTORS", "N",
            "Effectors of one chain constraint (over it: 422 too_many_effectors)",
            doc "Effectors of one `chain` constraint (over it: 422 `too_many_effectors`)";
        ik_max_iterations: u32 = 1000 => positive -> u32,
            "ik_max_iterations", "ik-max-iterations", "INBETWEEN_IK_MAX_ITERATIONS", "N",
            "The largest max_iterations a chain constraint may ask for (over it: 422 too_many_iterations)",
            doc "The largest `max_iterations` a `chain` may ask for (over it: 422 `too_many_iterations`)";
        max_request_work: u64 = 100_000_000 => positive -> u64,
            "max_request_work", "max-request-work", "INBETWEEN_MAX_REQUEST_WORK", "UNITS",
            "Work one request may cost, and one stream per second of playback, in work units (docs/api.md, \
             “Work and its price”; over it: 422 too_much_work)";
        node_work_per_sec: u64 = 0 => as_given -> u64,
            "node_work_per_sec", "node-work-per-sec", "INBETWEEN_NODE_WORK_PER_SEC", "UNITS",
            "Work units per second this node can do, all work threads together; 0 measures it at startup (logged). \
             Work held over it is refused 503 overloaded";
        caller_work_share: f64 = 0.5 => fraction -> f64,
            "caller_work_share", "caller-work-share", "INBETWEEN_CALLER_WORK_SHARE", "FRACTION",
            "Share of the node's work capacity one caller's requests and streams may hold at once (over it: 429 \
             caller_work_limit)";
        broadcast_work_share: f64 = 0.5 => fraction -> f64,
            "broadcast_work_share", "broadcast-work-share", "INBETWEEN_BROADCAST_WORK_SHARE", "FRACTION",
            "Share of one core that all broadcasts' ticks may take together, on their one producers' thread (over it: \
             503 overloaded at create or control); the rest keeps every tick on time when the machine is busy";
        work_threads: usize = cores() => positive -> usize,
            "work_threads", "work-threads", "INBETWEEN_WORK_THREADS", "N", shown "one per core",
            "Threads that evaluate poses, solve IK and encode answers; more work waits for them in order";
        max_streams: usize = 1024 => positive -> usize,
            "max_streams", "max-streams", "INBETWEEN_MAX_STREAMS", "N",
            "Concurrent streams (gRPC and WebSocket together)",
            doc "Concurrent streams (gRPC and WebSocket)";
        max_streams_per_client: usize = 64 => positive -> usize,
            "max_streams_per_client", "max-streams-per-client", "INBETWEEN_MAX_STREAMS_PER_CLIENT", "N",
            "Concurrent streams per client IP address",
            doc "Per client IP address";
        max_streams_per_token: usize = 64 => positive -> usize,
            "max_streams_per_token", "max-streams-per-token", "INBETWEEN_MAX_STREAMS_PER_TOKEN", "N",
            "Concurrent streams per configured token (by its name)",
            doc "Per configured token, from any address";
        max_broadcasts: usize = 64 => positive -> usize,
            "max_broadcasts", "max-broadcasts", "INBETWEEN_MAX_BROADCASTS", "N",
            "Live broadcasts at once (docs/broadcasts.md; over it: 429 too_many_broadcasts); their viewers count as streams",
            doc "Live broadcasts; their viewers count as streams";
        broadcast_control_lead: u64 = 50 => lead_millis -> Duration,
            "broadcast_control_lead_ms", "broadcast-control-lead-ms", "INBETWEEN_BROADCAST_CONTROL_LEAD_MS", "MS",
            "How far ahead a broadcast control is stamped, so that it is stored and every node hears of it before its tick (0..=10000)",
            doc "A broadcast control is stamped with the first tick due this long from now, so that it is stored and \
             every node hears of it first (0..=10000; [broadcasts.md](broadcasts.md#many-nodes))";
        broadcast_checkpoint: u64 = 10 => seconds -> Duration,
            "broadcast_checkpoint_secs", "broadcast-checkpoint-secs", "INBETWEEN_BROADCAST_CHECKPOINT_SECS", "SECS",
            "Seconds of broadcast time between a broadcast's stored checkpoints, from which a restarted or late node \
             steps on",
            doc "Broadcast time between a broadcast's checkpoints; a restarted or late node replays at most about one \
             of these, a second and the time it was down ([broadcasts.md](broadcasts.md#checkpoints))";
        broadcast_max_journal: usize = 1024 => positive -> usize,
            "broadcast_max_journal", "broadcast-max-journal", "INBETWEEN_BROADCAST_MAX_JOURNAL", "N",
            "Controls a broadcast holds since its newest checkpoint; more are refused (422 broadcast_journal_full)",
            doc "Controls a broadcast holds since its newest checkpoint; more are refused with 422 \
             `broadcast_journal_full` until the next one";
        body_read_timeout: u64 = 10 => seconds -> Duration,
            "body_read_timeout_secs", "body-read-timeout-secs", "INBETWEEN_BODY_READ_TIMEOUT_SECS", "SECS",
            "Seconds a client may take to send a request's body, once its head is in (answered 408)",
            doc "A body that takes longer to arrive is answered 408";
        max_in_flight: usize = 64 * cores() => positive -> usize,
            "max_in_flight", "max-in-flight", "INBETWEEN_MAX_IN_FLIGHT", "N", shown "64 per core",
            "Requests in flight (REST and gRPC each) before new ones are shed with 503",
            doc "Requests in flight, per protocol; more are shed with 503 / `RESOURCE_EXHAUSTED`";
        write_rate: u32 = 100 => positive -> u32,
            "write_rate", "write-rate", "INBETWEEN_WRITE_RATE", "PER_SEC",
            "Sustained writes per second per caller (its token's name, or its address without one)",
            doc "Sustained writes per second per caller, REST and gRPC together (over it: 429 with `Retry-After` / \
             `RESOURCE_EXHAUSTED`)";
        write_burst: u32 = 200 => positive -> u32,
            "write_burst", "write-burst", "INBETWEEN_WRITE_BURST", "N",
            "Writes a caller may make in a burst above the sustained rate",
            doc "Writes in a burst per caller";
        ws_max_message_bytes: usize = 4096 => positive -> usize,
            "ws_max_message_bytes", "ws-max-message-bytes", "INBETWEEN_WS_MAX_MESSAGE_BYTES", "BYTES",
            "Largest WebSocket message a stream viewer may send (controls)",
            doc "The largest control a viewer may send";
        ws_write_buffer_bytes: usize = 128 * 1024 => positive -> usize,
            "ws_write_buffer_bytes", "ws-write-buffer-bytes", "INBETWEEN_WS_WRITE_BUFFER_BYTES", "BYTES",
            "Bytes of outgoing WebSocket frames buffered before a write is flushed",
            doc "Bytes of the server's own messages (errors, `opened`, pongs) buffered before a flush; frames are written \
             from the playback's shared bytes, never buffered per viewer";
        ws_max_write_buffer_bytes: usize = 16 * 1024 * 1024 => positive -> usize,
            "ws_max_write_buffer_bytes", "ws-max-write-buffer-bytes", "INBETWEEN_WS_MAX_WRITE_BUFFER_BYTES", "BYTES",
            "Most bytes a WebSocket may hold unsent before the stream fails (at most stream_buffer_bytes is used)",
            doc "The smaller of it and `stream_buffer_bytes` is what a WebSocket may hold unsent";
        request_message_timeout: u64 = 10 => seconds -> Duration,
            "request_message_timeout_secs", "request-message-timeout-secs", "INBETWEEN_REQUEST_MESSAGE_TIMEOUT_SECS",
            "SECS",
            "Seconds a gRPC call may take to send its first message (a Play its `open`); answered DEADLINE_EXCEEDED",
            doc "A gRPC call whose first message (a `Play`'s `open`) takes longer ends `DEADLINE_EXCEEDED` `body_timeout`";
        http2_max_concurrent_streams: u32 = 256 => positive -> u32,
            "http2_max_concurrent_streams", "http2-max-concurrent-streams", "INBETWEEN_HTTP2_MAX_CONCURRENT_STREAMS",
            "N",
            "Requests and streams one HTTP/2 connection may have open at once (advertised on both ports)",
            doc "Streams per HTTP/2 connection, advertised on both ports";
        max_in_flight_per_client: usize = 32 => positive -> usize,
            "max_in_flight_per_client", "max-in-flight-per-client", "INBETWEEN_MAX_IN_FLIGHT_PER_CLIENT", "N",
            "Requests one caller (its token's name, or its address) may have in flight, REST and gRPC together \
             (answered 429 `client_in_flight_limit`)",
            doc "Requests per caller, REST and gRPC together, counted once a request's body (first message) has arrived; \
             more: 429 `client_in_flight_limit` / `RESOURCE_EXHAUSTED`";
        idle_timeout: u64 = 60 => seconds -> Duration,
            "idle_timeout_secs", "idle-timeout-secs", "INBETWEEN_IDLE_TIMEOUT_SECS", "SECS",
            "Seconds a connection (either port) may stay open with no request or stream before it is closed",
            doc "A connection (either port, HTTP/1.1 or HTTP/2) with no request or stream open this long is closed";
        write_stall_timeout: u64 = 30 => seconds -> Duration,
            "write_stall_timeout_secs", "write-stall-timeout-secs", "INBETWEEN_WRITE_STALL_TIMEOUT_SECS", "SECS",
            "Seconds a write to a client may make no progress (it stopped reading an answer or a stream) before its \
             connection is closed",
            doc "A connection (either port) whose writes make no progress this long — a client that stopped reading an \
             answer or a stream — is closed, and whatever it held (in-flight slots, buffers) is freed";
        max_connections: usize = 4096 => positive -> usize,
            "max_connections", "max-connections", "INBETWEEN_MAX_CONNECTIONS", "N",
            "Open connections per port; connections over it are closed at accept",
            doc "Open connections per port; more are closed at accept (`inbetween_connections_refused_total`)";
        stream_buffer_bytes: usize = 256 * 1024 => positive -> usize,
            "stream_buffer_bytes", "stream-buffer-bytes", "INBETWEEN_STREAM_BUFFER_BYTES", "BYTES",
            "Bytes of frames a stream viewer may leave unread before its stream is closed (slow consumer)",
            doc "A viewer that leaves more unread is closed (WebSocket 1008 / `RESOURCE_EXHAUSTED` `slow_consumer`)";
        max_compressed_answers: usize = 4 * cores() => positive -> usize,
            "max_compressed_answers", "max-compressed-answers", "INBETWEEN_MAX_COMPRESSED_ANSWERS", "N",
            shown "4 per core",
            "REST and gRPC answers compressed at once (each holds an encoder: at most 2.5 MiB at the levels used); an \
             answer that finds them all busy is sent uncompressed";
        max_arriving_bytes: usize = 256 * 1024 * 1024 => positive -> usize,
            "max_arriving_bytes", "max-arriving-bytes", "INBETWEEN_MAX_ARRIVING_BYTES", "BYTES",
            "Bytes of request bodies and first gRPC messages held at once, all requests together, from arrival \
             until the request ends; a request that would pass it is answered 503 `overloaded`",
            doc "Request bodies and first gRPC messages held at once, from arrival to the end of their request; a request \
             that would pass it is answered 503 `overloaded` (at least `max_body_bytes`)";
    }
}

/// The machine's cores, for defaults that scale with them.
fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, std::num::NonZero::get)
}

// The checks of single settings: `check(toml_key, value)`.

fn as_given<T>(_: &str, value: T) -> anyhow::Result<T> {
    Ok(value)
}

fn positive<T: PartialEq + Default>(name: &str, value: T) -> anyhow::Result<T> {
    if value == T::default() {
        bail!("{name} must be at least 1");
    }
    Ok(value)
}

fn seconds(name: &str, secs: u64) -> anyhow::Result<Duration> {
    if secs == 0 {
        bail!("{name} must be at least 1 second");
    }
    Ok(Duration::from_secs(secs))
}

/// A broadcast control lead in milliseconds, at most 10 s.
fn lead_millis(name: &str, ms: u64) -> anyhow::Result<Duration> {
    if ms > 10_000 {
        bail!("{name} must be at most 10000 ms");
    }
    Ok(Duration::from_millis(ms))
}

/// A duration in seconds where 0 means "do not wait".
fn seconds_or_none(_: &str, secs: u64) -> anyhow::Result<Duration> {
    Ok(Duration::from_secs(secs))
}

/// A share of something, from 0 (none) to 1 (all).
fn fraction(name: &str, value: f64) -> anyhow::Result<f64> {
    if !(0.0..=1.0).contains(&value) {
        bail!("{name} must be a fraction from 0 to 1");
    }
    Ok(value)
}

fn plain_token(name: &str, token: Option<Secret>) -> anyhow::Result<Option<Secret>> {
    match token {
        Some(t) if t.expose().trim().is_empty() => bail!("{name} must not be empty"),
        Some(t) if t.expose().chars().any(|c| c.is_whitespace() || c.is_control()) => {
            bail!("{name} must not contain spaces or control characters")
        }
        t => Ok(t),
    }
}

fn scoped_tokens(_: &str, specs: Option<Vec<TokenSpec>>) -> anyhow::Result<Vec<Token>> {
    let mut names = HashSet::new();
    let mut checked = Vec::new();
    for spec in specs.unwrap_or_default() {
        let token = spec.validate().map_err(anyhow::Error::msg)?;
        if !names.insert(token.name.clone()) {
            bail!("two tokens are named `{}`", token.name);
        }
        checked.push(token);
    }
    Ok(checked)
}

fn cors(_: &str, origins: Option<Vec<String>>) -> anyhow::Result<Cors> {
    let origins = origins.unwrap_or_default();
    if origins.is_empty() {
        return Ok(Cors::Off);
    }
    if origins.iter().any(|o| o == "*") {
        if origins.len() > 1 {
            bail!("cors origin `*` cannot be combined with other origins");
        }
        return Ok(Cors::Any);
    }
    for o in &origins {
        let ok = (o.starts_with("http://") || o.starts_with("https://"))
            && !o.ends_with('/')
            && axum::http::HeaderValue::from_str(o).is_ok();
        if !ok {
            bail!("cors origin `{o}` must look like https://host[:port], without a path");
        }
    }
    Ok(Cors::Origins(origins))
}

fn trusted_proxies(name: &str, entries: Option<Vec<String>>) -> anyhow::Result<TrustedProxies> {
    let nets =
        entries.unwrap_or_default().into_iter().map(|e| Net::parse(&e).with_context(|| format!("{name}: `{e}`")));
    Ok(TrustedProxies(nets.collect::<anyhow::Result<_>>()?))
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

    /// Fills defaults and checks every value, alone and together.
    ///
    /// # Errors
    /// A value the server cannot run with (zero limits, an empty token, an
    /// unsupported database URL, a malformed CORS origin, settings that
    /// contradict each other).
    pub fn validate(self) -> anyhow::Result<Config> {
        let s = self.checked()?;
        s.limits.check_buffers()?;
        check_token_names(&s)?;
        Ok(Config {
            store: store(s.data_dir, s.database_url)?,
            db: PoolSettings {
                max_connections: s.db_max_connections,
                acquire_timeout: s.db_acquire_timeout,
                retry: RetryPolicy { retries: s.db_retries, ..RetryPolicy::default() },
                durability: if s.unsafe_fast_writes { Durability::UnsafeFast } else { Durability::Required },
            },
            tls: tls(s.tls_cert, s.tls_key)?,
            listen: s.listen,
            grpc_listen: s.grpc_listen,
            write_token: s.api_token,
            read_token: s.read_token,
            tokens: s.tokens,
            cors: s.cors_origins,
            log_format: s.log_format,
            drain_timeout: s.drain_timeout,
            trusted_proxies: s.trusted_proxies,
            compression: Compression { enabled: s.compression, min_bytes: s.compression_min_bytes },
            access_log_sample: s.access_log_sample,
            limits: s.limits,
        })
    }
}

impl Limits {
    /// The ceilings on IK constraints (docs/ik.md errors), for the core.
    pub fn ik(&self) -> anim::ik::IkLimits {
        anim::ik::IkLimits {
            max_constraints: self.ik_max_constraints,
            max_iterations: self.ik_max_iterations,
            max_effectors: self.ik_max_effectors,
        }
    }

    fn check_buffers(&self) -> anyhow::Result<()> {
        if self.ws_max_write_buffer_bytes <= self.ws_write_buffer_bytes {
            bail!("ws_max_write_buffer_bytes must be larger than ws_write_buffer_bytes");
        }
        if self.max_blend_points > anim::motion::MAX_LAYERS {
            bail!("max_blend_points must be at most {} (each point is a layer)", anim::motion::MAX_LAYERS);
        }
        if self.max_arriving_bytes < self.max_body_bytes {
            bail!("max_arriving_bytes must be at least max_body_bytes");
        }
        Ok(())
    }
}

/// The plain tokens are callers named `api-token` and `read-token`
/// (`server::auth`); a scoped token may not take a name one of them holds,
/// or the two would share per-caller limits.
fn check_token_names(s: &Settings) -> anyhow::Result<()> {
    let plain = [("api-token", &s.api_token), ("read-token", &s.read_token)];
    for (name, _) in plain.iter().filter(|(_, secret)| secret.is_some()) {
        if s.tokens.iter().any(|t| &*t.name == *name) {
            bail!("a scoped token cannot be named `{name}`: that is the name of the plain {name}");
        }
    }
    Ok(())
}

/// Where clips are stored: `database_url`, or `data_dir` (default `data`).
fn store(data_dir: Option<PathBuf>, database_url: Option<Secret>) -> anyhow::Result<StoreConfig> {
    let url = match (database_url, data_dir) {
        (Some(_), Some(_)) => bail!("give either data_dir or database_url, not both"),
        (None, dir) => return Ok(StoreConfig::DataDir(dir.unwrap_or_else(|| PathBuf::from("data")))),
        (Some(url), None) => url,
    };
    let text = url.expose();
    if text.starts_with("sqlite:") {
        Ok(StoreConfig::SqliteUrl(url))
    } else if text.starts_with("postgres:") || text.starts_with("postgresql:") {
        Ok(StoreConfig::Postgres(url))
    } else {
        bail!("database_url must start with sqlite: or postgres:")
    }
}

fn tls(cert: Option<PathBuf>, key: Option<PathBuf>) -> anyhow::Result<Option<TlsFiles>> {
    match (cert, key) {
        (Some(cert), Some(key)) => Ok(Some(TlsFiles { cert, key })),
        (None, None) => Ok(None),
        _ => bail!("tls_cert and tls_key go together"),
    }
}

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

impl fmt::Display for LogFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            LogFormat::Text => "text",
            LogFormat::Json => "json",
        })
    }
}

/// Content codings (`compression`, `compression_min_bytes`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Compression {
    /// Offer compressed answers and accept compressed requests, on both ports.
    pub enabled: bool,
    /// REST answers of a known length under this go uncompressed.
    pub min_bytes: usize,
}

/// Where clips are stored.
#[derive(Clone, PartialEq)]
pub enum StoreConfig {
    /// `DIR/inbetween.db`, the directory created if missing.
    DataDir(PathBuf),
    /// A `sqlite:` URL.
    SqliteUrl(Secret),
    /// A `postgres:` URL: the shared store of a multi-node deployment.
    Postgres(Secret),
}

/// Shows a URL's host and database but never its password (the startup log
/// line prints the effective configuration).
impl fmt::Debug for StoreConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StoreConfig::DataDir(dir) => f.debug_tuple("DataDir").field(dir).finish(),
            StoreConfig::SqliteUrl(url) => f.debug_tuple("SqliteUrl").field(&redacted_url(url.expose())).finish(),
            StoreConfig::Postgres(url) => f.debug_tuple("Postgres").field(&redacted_url(url.expose())).finish(),
        }
    }
}

/// `url` with the password of its user info and the value of every query
/// parameter whose name mentions a password, key or secret (`password`,
/// `sslpassword`, `sslkey`) replaced by `***`.
fn redacted_url(url: &str) -> String {
    let (base, query) = url.split_once('?').map_or((url, None), |(b, q)| (b, Some(q)));
    let mut out = match base.split_once("://") {
        Some((scheme, rest)) => {
            let (authority, path) = rest.split_once('/').map_or((rest, None), |(a, p)| (a, Some(p)));
            let authority = match authority.rsplit_once('@') {
                Some((user_info, host)) => match user_info.split_once(':') {
                    Some((user, _password)) => format!("{user}:***@{host}"),
                    None => format!("{user_info}@{host}"),
                },
                None => authority.to_owned(),
            };
            format!("{scheme}://{authority}{}", path.map(|p| format!("/{p}")).unwrap_or_default())
        }
        None => base.to_owned(),
    };
    if let Some(query) = query {
        let pairs: Vec<String> = query
            .split('&')
            .map(|pair| match pair.split_once('=') {
                Some((k, _)) if ["pass", "key", "secret"].iter().any(|s| k.to_ascii_lowercase().contains(s)) => {
                    format!("{k}=***")
                }
                _ => pair.to_owned(),
            })
            .collect();
        out.push('?');
        out.push_str(&pairs.join("&"));
    }
    out
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

/// The reverse proxies whose forwarding headers are believed (`trusted_proxies`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TrustedProxies(Vec<Net>);

impl TrustedProxies {
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    pub fn contains(&self, ip: IpAddr) -> bool {
        self.0.iter().any(|net| net.contains(ip))
    }
}

/// One address or CIDR block (`10.0.0.0/8`, `::1`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Net {
    base: IpAddr,
    prefix: u8,
}

impl Net {
    fn parse(text: &str) -> anyhow::Result<Net> {
        let (ip, prefix) = match text.trim().split_once('/') {
            Some((ip, prefix)) => (ip, Some(prefix)),
            None => (text.trim(), None),
        };
        let base: IpAddr = ip.parse().context("not an IP address")?;
        let bits = if base.is_ipv4() { 32 } else { 128 };
        let prefix = match prefix {
            Some(p) => p.parse::<u8>().ok().filter(|p| *p <= bits).context("not a prefix length")?,
            None => bits,
        };
        Ok(Net { base, prefix })
    }

    fn contains(self, ip: IpAddr) -> bool {
        let ip = match ip {
            IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(ip, IpAddr::V4),
            v4 => v4,
        };
        let shift = |bits: u32| (self.prefix as u32).min(bits);
        match (self.base, ip) {
            (IpAddr::V4(net), IpAddr::V4(ip)) => {
                let mask = u32::MAX.checked_shl(32 - shift(32)).unwrap_or(0);
                u32::from(net) & mask == u32::from(ip) & mask
            }
            (IpAddr::V6(net), IpAddr::V6(ip)) => {
                let mask = u128::MAX.checked_shl(128 - shift(128)).unwrap_or(0);
                u128::from(net) & mask == u128::from(ip) & mask
            }
            _ => false,
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
    pub db: PoolSettings,
    pub write_token: Option<Secret>,
    pub read_token: Option<Secret>,
    /// Scoped tokens (hashes), beside the plain write and read tokens.
    pub tokens: Vec<Token>,
    /// Serve both listeners over TLS with these files.
    pub tls: Option<TlsFiles>,
    pub cors: Cors,
    pub log_format: LogFormat,
    pub drain_timeout: Duration,
    /// Peers whose `X-Forwarded-For` / `Forwarded` name the client (`server::auth`).
    pub trusted_proxies: TrustedProxies,
    /// Content codings on both ports (`server::compression`).
    pub compression: Compression,
    /// The share of 1xx–3xx REST requests the access log shows (`server::access_log`).
    pub access_log_sample: f64,
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
        let hash = crate::tokens::TokenHash::of(b"t");
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

    /// The startup line prints the configuration's `Debug`: a database URL
    /// keeps its user, host and database, never its password.
    #[test]
    fn database_passwords_never_print_but_the_host_does() {
        let url = "postgres://app:s3cret@db.internal:5432/clips?sslmode=require&sslpassword=k3y";
        let c = RawConfig { database_url: Some(Secret::new(url)), ..Default::default() }.validate().unwrap();
        let shown = format!("{c:?}");
        assert!(!shown.contains("s3cret") && !shown.contains("k3y"), "{shown}");
        assert!(shown.contains("postgres://app:***@db.internal:5432/clips?sslmode=require&sslpassword=***"), "{shown}");
        assert_eq!(redacted_url("postgres://app@h/db"), "postgres://app@h/db");
        assert_eq!(redacted_url("postgresql://h"), "postgresql://h");
        assert_eq!(redacted_url("sqlite://data/a.db?mode=rwc"), "sqlite://data/a.db?mode=rwc");
        assert_eq!(redacted_url("postgres://u:p@ss@h/db"), "postgres://u:***@h/db", "the last @ ends the user info");
    }

    #[test]
    fn compression_and_access_log_settings() {
        let d = RawConfig::default().validate().unwrap();
        assert_eq!(d.compression, Compression { enabled: true, min_bytes: 1024 });
        assert!((d.access_log_sample - 0.01).abs() < 1e-12);
        let c = parse_flags(&["--compression", "false", "--compression-min-bytes", "0", "--access-log-sample", "1"])
            .validate()
            .unwrap();
        assert_eq!((c.compression, c.access_log_sample), (Compression { enabled: false, min_bytes: 0 }, 1.0));
        let file: RawConfig = toml::from_str("compression = false\naccess_log_sample = 0\n").unwrap();
        let c = file.validate().unwrap();
        assert_eq!((c.compression.enabled, c.access_log_sample), (false, 0.0));
        for bad in ["1.5", "-0.1", "NaN"] {
            let raw = parse_flags(&[&format!("--access-log-sample={bad}")]);
            assert_eq!(raw.validate().unwrap_err().to_string(), "access_log_sample must be a fraction from 0 to 1");
        }
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

    #[test]
    fn the_defaults_are_the_documented_ones() {
        let c = RawConfig::default().validate().unwrap();
        assert_eq!((c.listen, c.grpc_listen), ("127.0.0.1:8080".parse().unwrap(), "127.0.0.1:50051".parse().unwrap()));
        assert_eq!((c.db.max_connections, c.db.acquire_timeout, c.db.retry.retries), (8, Duration::from_secs(10), 3));
        assert_eq!((c.cors, c.log_format, c.drain_timeout), (Cors::Off, LogFormat::Text, Duration::from_secs(10)));
        assert!(c.tls.is_none() && c.tokens.is_empty() && c.write_token.is_none() && c.read_token.is_none());
        assert!(c.trusted_proxies.is_empty());
        let cores = std::thread::available_parallelism().unwrap().get();
        let expected = Limits {
            max_body_bytes: 16_777_216,
            max_import_resolved_bytes: 67_108_864,
            max_import_bytes: 268_435_456,
            max_import_uploads: 8,
            max_import_uploads_per_caller: 2,
            import_slot_wait: Duration::from_secs(2),
            min_upload_bytes_per_sec: 16_384,
            upload_rate_window: Duration::from_secs(3),
            max_texture_pixels: 16_777_216,
            max_tracks: 4096,
            max_keys_per_track: 1_000_000,
            max_joints: 4096,
            max_parameters: 1024,
            max_poses: 10_000,
            max_joint_poses: 16_777_216,
            max_answer_bytes: 268_435_456,
            max_frame_bytes: 1_048_576,
            max_stream_bytes_per_sec: 67_108_864,
            request_timeout: Duration::from_secs(30),
            header_read_timeout: Duration::from_secs(10),
            cache_entries: 1024,
            cache_bytes: 268_435_456,
            motion_cache_entries: 1024,
            max_graph_bytes: 1_048_576,
            max_graph_nodes: 256,
            max_blend_points: 32,
            graph_cache_entries: 256,
            max_build_work: 16_000_000,
            ik_max_constraints: 32,
            ik_max_effectors: 16,
            ik_max_iterations: 1000,
            max_request_work: 100_000_000,
            node_work_per_sec: 0,
            caller_work_share: 0.5,
            broadcast_work_share: 0.5,
            work_threads: cores,
            max_streams: 1024,
            max_streams_per_client: 64,
            max_streams_per_token: 64,
            max_broadcasts: 64,
            broadcast_control_lead: Duration::from_millis(50),
            broadcast_checkpoint: Duration::from_secs(10),
            broadcast_max_journal: 1024,
            body_read_timeout: Duration::from_secs(10),
            max_in_flight: 64 * cores,
            write_rate: 100,
            write_burst: 200,
            ws_max_message_bytes: 4096,
            ws_write_buffer_bytes: 131_072,
            ws_max_write_buffer_bytes: 16_777_216,
            request_message_timeout: Duration::from_secs(10),
            http2_max_concurrent_streams: 256,
            max_in_flight_per_client: 32,
            idle_timeout: Duration::from_secs(60),
            write_stall_timeout: Duration::from_secs(30),
            max_connections: 4096,
            stream_buffer_bytes: 262_144,
            max_compressed_answers: 4 * cores,
            max_arriving_bytes: 268_435_456,
        };
        assert_eq!(c.limits, expected);
    }

    /// The flags as `inbetween serve` parses them.
    fn parse_flags(args: &[&str]) -> RawConfig {
        use clap::{Args, FromArgMatches};
        let command = RawConfig::augment_args(clap::Command::new("serve").no_binary_name(true));
        RawConfig::from_arg_matches(&command.try_get_matches_from(args).unwrap()).unwrap()
    }

    #[test]
    fn each_flag_sets_its_own_setting() {
        let hash = crate::tokens::TokenHash::of(b"t");
        let raw = parse_flags(&[
            "--request-timeout-secs",
            "5",
            "--drain-timeout-secs",
            "0",
            "--db-acquire-timeout-secs",
            "2",
            "--token",
            &format!("a:read:{hash},b:write:{hash}"),
            "--cors-origin",
            "https://a.example,https://b.example:8443",
            "--unsafe-fast-writes",
            "--max-in-flight",
            "7",
        ]);
        let c = raw.validate().unwrap();
        assert_eq!((c.limits.request_timeout, c.drain_timeout), (Duration::from_secs(5), Duration::ZERO));
        assert_eq!((c.db.acquire_timeout, c.db.durability), (Duration::from_secs(2), Durability::UnsafeFast));
        assert_eq!(c.tokens.iter().map(|t| &*t.name).collect::<Vec<_>>(), ["a", "b"]);
        assert_eq!(c.cors, Cors::Origins(vec!["https://a.example".into(), "https://b.example:8443".into()]));
        assert_eq!(c.limits.max_in_flight, 7);
        assert_eq!(c.limits.max_poses, 10_000, "untouched settings keep their defaults");
        // The same settings under their TOML keys.
        let file: RawConfig =
            toml::from_str("drain_timeout_secs = 0\n[limits]\nrequest_timeout_secs = 5\nmax_in_flight = 7\n").unwrap();
        let c = file.validate().unwrap();
        assert_eq!(
            (c.limits.request_timeout, c.drain_timeout, c.limits.max_in_flight),
            (Duration::from_secs(5), Duration::ZERO, 7)
        );
    }

    #[test]
    fn errors_name_the_toml_key() {
        let err = |raw: RawConfig| raw.validate().unwrap_err().to_string();
        let zero_timeout: RawConfig = toml::from_str("[limits]\nheader_read_timeout_secs = 0\n").unwrap();
        assert_eq!(err(zero_timeout), "header_read_timeout_secs must be at least 1 second");
        let zero_rate: RawConfig = toml::from_str("[limits]\nwrite_rate = 0\n").unwrap();
        assert_eq!(err(zero_rate), "write_rate must be at least 1");
        assert_eq!(err(parse_flags(&["--motion-cache-entries", "0"])), "motion_cache_entries must be at least 1");
        let motions = parse_flags(&["--motion-cache-entries", "3"]).validate().unwrap();
        assert_eq!((motions.limits.motion_cache_entries, motions.limits.cache_entries), (3, 1024));
        let buffers = parse_flags(&["--ws-write-buffer-bytes", "10", "--ws-max-write-buffer-bytes", "10"]);
        assert_eq!(err(buffers), "ws_max_write_buffer_bytes must be larger than ws_write_buffer_bytes");
        let blank = parse_flags(&["--api-token", " "]);
        assert_eq!(err(blank), "api_token must not be empty");
    }

    #[test]
    fn trusted_proxies_are_addresses_and_cidr_blocks() {
        let c = parse_flags(&["--trusted-proxy", "10.1.0.0/16,192.168.7.7", "--trusted-proxy", "fd00::/8"])
            .validate()
            .unwrap();
        let trusts = |ip: &str| c.trusted_proxies.contains(ip.parse().unwrap());
        assert!(trusts("10.1.255.3") && trusts("192.168.7.7") && trusts("fd12::1") && trusts("::ffff:10.1.0.9"));
        assert!(!trusts("10.2.0.1") && !trusts("192.168.7.8") && !trusts("fe80::1") && !trusts("127.0.0.1"));
        let all: RawConfig = toml::from_str("trusted_proxies = [\"0.0.0.0/0\"]").unwrap();
        assert!(all.validate().unwrap().trusted_proxies.contains("203.0.113.9".parse().unwrap()));
        for bad in ["10.0.0.0/33", "nginx", "10.0.0.1/", "::/129"] {
            let raw = RawConfig { trusted_proxies: Some(vec![bad.into()]), ..Default::default() };
            assert!(raw.validate().is_err(), "{bad}");
        }
    }

    #[test]
    fn a_scoped_token_cannot_take_a_plain_tokens_name() {
        let hash = crate::tokens::TokenHash::of(b"t");
        let taken = parse_flags(&["--api-token", "w", "--token", &format!("api-token:read:{hash}")]);
        assert!(taken.validate().is_err());
        let free = parse_flags(&["--token", &format!("api-token:read:{hash}")]);
        assert!(free.validate().is_ok(), "without the plain token the name is free");
    }

    #[test]
    fn help_shows_each_flag_with_its_variable_and_default() {
        use clap::Args;
        let mut command = RawConfig::augment_args(clap::Command::new("serve"));
        let help = command.render_help().to_string();
        for [_, flag, env] in RawConfig::NAMES.iter().chain(RawLimits::NAMES) {
            assert!(help.contains(&format!("--{flag} ")), "--{flag} in\n{help}");
            assert!(help.contains(&format!("[env: {env}")), "{env} in\n{help}");
        }
        for shown in ["[default: 127.0.0.1:8080]", "[default: ./data]", "[default: 8]", "[default: text]"] {
            assert!(help.contains(shown), "{shown} in\n{help}");
        }
        for shown in ["[default: 16777216]", "[default: 64 per core]", "[default: 131072]", "[default: 30]"] {
            assert!(help.contains(shown), "{shown} in\n{help}");
        }
    }

    /// docs/configuration.md's table is the rendering of the rows (with
    /// `INBETWEEN_BLESS=1` this test writes it).
    #[test]
    fn the_configuration_doc_is_rendered_from_the_rows() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/configuration.md");
        let text = std::fs::read_to_string(&path).unwrap();
        let rendered = doc::render(&text, &RawConfig::doc_rows());
        if std::env::var("INBETWEEN_BLESS").is_ok_and(|v| v == "1") {
            std::fs::write(&path, rendered).unwrap();
            return;
        }
        assert!(text == rendered, "docs/configuration.md differs from the settings rows; rewrite it: {}", doc::BLESS);
    }
}
