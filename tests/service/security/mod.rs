//! Security tests: the authorization matrix over every REST route and RPC,
//! REST statuses against gRPC codes for the same errors, and TLS. The real
//! `Application` on 127.0.0.1:0 with its own SQLite file, real clients
//! (reqwest, tonic, tokio-tungstenite, tokio-rustls) over loopback.

mod codes;
mod grpc_matrix;
mod rest_matrix;
pub mod status_table;
mod tls;

use formats::wire::proto::pb;
use server::Config;
use server::auth::{Scope, TokenHash, TokenSpec};

pub use crate::common::{TestApp, WAVE};

/// The plain tokens of the three scoped tokens the matrix configures (the
/// server only ever sees their hashes).
pub const READER: &str = "ib_reader-7f3a";
pub const WRITER: &str = "ib_writer-c91d";
pub const ADMIN: &str = "ib_admin-04be";

/// Who calls, in the matrix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    None,
    Invalid,
    Read,
    Write,
    Admin,
}

impl Role {
    pub const ALL: [Role; 5] = [Role::None, Role::Invalid, Role::Read, Role::Write, Role::Admin];

    pub fn token(self) -> Option<&'static str> {
        match self {
            Role::None => None,
            Role::Invalid => Some("ib_not-a-configured-token"),
            Role::Read => Some(READER),
            Role::Write => Some(WRITER),
            Role::Admin => Some(ADMIN),
        }
    }

    /// The highest scope this role holds (written out here, not taken from the server).
    pub fn scope(self) -> Option<Scope> {
        match self {
            Role::None | Role::Invalid => None,
            Role::Read => Some(Scope::Read),
            Role::Write => Some(Scope::Write),
            Role::Admin => Some(Scope::Admin),
        }
    }
}

/// What a route or RPC needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Need {
    /// No token is looked at (probes, clock sync).
    Open,
    Scope(Scope),
}

impl Need {
    /// What a route table row's scope (`None`: open) needs.
    pub fn of(scope: Option<Scope>) -> Need {
        scope.map_or(Need::Open, Need::Scope)
    }
}

/// The outcome the matrix expects for `role` on an operation needing `need`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    Allowed,
    Unauthenticated,
    Forbidden,
}

pub fn expected(need: Need, role: Role) -> Outcome {
    match (need, role) {
        (Need::Open, _) => Outcome::Allowed,
        (Need::Scope(_), Role::None | Role::Invalid) => Outcome::Unauthenticated,
        (Need::Scope(s), r) if r.scope().is_some_and(|held| held >= s) => Outcome::Allowed,
        (Need::Scope(_), _) => Outcome::Forbidden,
    }
}

/// The three scoped tokens, as `[[tokens]]` would configure them.
pub fn scoped_tokens(config: &mut Config) {
    let spec = |name: &str, scopes: Vec<Scope>, token: &str| {
        TokenSpec { name: name.into(), scopes, hash: TokenHash::of(token.as_bytes()) }.validate().unwrap()
    };
    config.tokens = vec![
        spec("reader", vec![Scope::Read], READER),
        spec("writer", vec![Scope::Write], WRITER),
        spec("ops", vec![Scope::Admin], ADMIN),
    ];
}

/// Every stored clip as (id, version), read with the admin token: what a
/// refused write must leave unchanged.
pub async fn snapshot(app: &TestApp) -> Vec<(String, u64)> {
    let clips = app.list_all(100, Some(ADMIN)).await;
    clips.iter().map(|c| (c["id"].as_str().unwrap().to_owned(), c["version"].as_u64().unwrap())).collect()
}

/// A gRPC request carrying `token` as `authorization: Bearer …` metadata.
pub fn with_token<T>(msg: T, token: Option<&str>) -> tonic::Request<T> {
    let mut req = tonic::Request::new(msg);
    if let Some(t) = token {
        req.metadata_mut().insert("authorization", format!("Bearer {t}").parse().unwrap());
    }
    req
}

/// The wave clip under a name of its own (names identify clips), for
/// tests that make a clip per request.
pub fn fresh_wave() -> String {
    WAVE.replacen("\"wave\"", &format!("\"wave {}\"", server::store::new_clip_id()), 1)
}

/// The wave clip as a protobuf `Clip`.
pub fn wave_pb() -> pb::Clip {
    formats::wire::proto::clip_to_pb(&formats::wire::json::parse_clip(WAVE.as_bytes()).unwrap().1)
}

/// A two-frame BVH file, for the import route.
pub const TINY_BVH: &str = "HIERARCHY\nROOT hip\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition Zposition\n  \
End Site\n  {\n    OFFSET 0 1 0\n  }\n}\nMOTION\nFrames: 2\nFrame Time: 0.5\n0 0 0\n1 0 0\n";
