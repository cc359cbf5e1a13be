//! Who is calling, and what they may do: bearer tokens with scopes.
//!
//! A token grants one of three nested scopes: **read** (clips, poses,
//! streams), **write** (create, replace, delete, import; implies read) and
//! **admin** (operational routes such as `/metrics`; implies write and read).
//! Tokens come from the `[[tokens]]` list (name, scopes and the token's
//! `sha256:<hex>` hash, never the token itself; `inbetween token new` makes
//! one) and from the older plain `--api-token` (write) and `--read-token`
//! (read).
//!
//! Which scopes are enforced follows from the tokens configured, so a server
//! with no tokens stays open and adding a token closes only what it is for:
//! - writes need write once any token grants write;
//! - reads need read once any token's highest scope is read (a server whose
//!   tokens are all write or admin keeps public reads);
//! - admin routes need admin once any token grants admin.
//!
//! A bearer token that matches nothing is refused (401) whenever tokens are
//! configured, even on an open route: a wrong token is a client bug worth
//! reporting. A valid token without the scope a route needs is 403.
//!
//! The given token is hashed once and compared with every configured hash in
//! constant time (`subtle`), without stopping at the first match, so timing
//! tells nothing about which token, or how much of one, matched.
//!
//! Handlers state what they need with the extractors [`ReadAccess`],
//! [`WriteAccess`] and [`AdminAccess`]; each carries the [`Caller`], whose
//! `id` keys per-token limits. gRPC uses [`check_read`] / [`check_write`]
//! on the `authorization` metadata.

use std::fmt;
use std::str::FromStr;
use std::sync::{Arc, LazyLock};

use axum::extract::FromRequestParts;
use axum::http::header::AUTHORIZATION;
use axum::http::request::Parts;
use serde::Deserialize;
use sha2::{Digest, Sha256};
use subtle::{Choice, ConstantTimeEq};

use super::config::{Config, Secret};
use super::error::ApiError;
use super::state::AppState;

/// One permission level. Ordered: each implies the ones before it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Scope {
    Read,
    Write,
    Admin,
}

impl Scope {
    pub fn as_str(self) -> &'static str {
        match self {
            Scope::Read => "read",
            Scope::Write => "write",
            Scope::Admin => "admin",
        }
    }
}

impl FromStr for Scope {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "read" => Ok(Scope::Read),
            "write" => Ok(Scope::Write),
            "admin" => Ok(Scope::Admin),
            other => Err(format!("unknown scope `{other}` (read, write or admin)")),
        }
    }
}

/// The scopes a caller holds. Because scopes nest, the highest one says it
/// all; `None` is an anonymous caller on an open server.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Scopes(Option<Scope>);

impl Scopes {
    pub const NONE: Scopes = Scopes(None);

    /// The scopes granted by a list (its highest entry).
    pub fn granted(list: &[Scope]) -> Scopes {
        Scopes(list.iter().copied().max())
    }

    pub fn highest(self) -> Option<Scope> {
        self.0
    }

    /// Whether these scopes include `scope` (admin ⊃ write ⊃ read).
    pub fn allows(self, scope: Scope) -> bool {
        self.0.is_some_and(|h| h >= scope)
    }
}

/// The SHA-256 of a token: what the configuration holds instead of the token.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct TokenHash([u8; 32]);

impl TokenHash {
    pub fn of(token: &[u8]) -> TokenHash {
        TokenHash(Sha256::digest(token).into())
    }

    fn ct_eq(&self, other: &TokenHash) -> Choice {
        self.0.ct_eq(&other.0)
    }
}

impl fmt::Display for TokenHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "sha256:{}", hex::encode(self.0))
    }
}

impl fmt::Debug for TokenHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

impl FromStr for TokenHash {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let hex_digits = s.strip_prefix("sha256:").ok_or("a token hash must look like sha256:<64 hex digits>")?;
        let mut out = [0u8; 32];
        hex::decode_to_slice(hex_digits, &mut out)
            .map_err(|_| "a token hash must look like sha256:<64 hex digits>".to_owned())?;
        Ok(TokenHash(out))
    }
}

impl<'de> Deserialize<'de> for TokenHash {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// A configured token: a `[[tokens]]` table in TOML, or on the command line
/// and in `INBETWEEN_TOKENS` as `NAME:SCOPE[+SCOPE…]:sha256:HEX`.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TokenSpec {
    /// Who holds it (logs, per-token limits). Letters, digits, `-`, `_`, `.`.
    pub name: String,
    pub scopes: Vec<Scope>,
    /// `sha256:<hex>` of the token (`inbetween token hash`).
    pub hash: TokenHash,
}

impl FromStr for TokenSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let form = "a token must look like NAME:SCOPE[+SCOPE]:sha256:HEX";
        let (name, rest) = s.split_once(':').ok_or(form)?;
        let (scopes, hash) = rest.split_once(':').ok_or(form)?;
        let scopes = scopes.split('+').map(str::parse).collect::<Result<Vec<_>, _>>()?;
        Ok(TokenSpec { name: name.to_owned(), scopes, hash: hash.parse()? })
    }
}

/// A validated token of the configuration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Token {
    pub name: Arc<str>,
    pub scopes: Scopes,
    pub hash: TokenHash,
}

impl TokenSpec {
    /// Checks the name and scopes.
    ///
    /// # Errors
    /// An empty or oddly spelt name, or no scope.
    pub fn validate(self) -> Result<Token, String> {
        let name_ok = !self.name.is_empty()
            && self.name.len() <= 64
            && self.name.bytes().all(|b| b.is_ascii_alphanumeric() || b"-_.".contains(&b));
        if !name_ok {
            return Err(format!("token name `{}` must be 1–64 letters, digits, `-`, `_` or `.`", self.name));
        }
        if self.scopes.is_empty() {
            return Err(format!("token `{}` needs at least one scope", self.name));
        }
        Ok(Token { name: self.name.into(), scopes: Scopes::granted(&self.scopes), hash: self.hash })
    }
}

/// The caller of a request, once its token (if any) has been checked.
///
/// `id` is the token's configured name (`api-token` and `read-token` for the
/// plain tokens), or `None` for a caller without a token on an open server.
/// Per-token limits key on `id`; anonymous callers share one bucket.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Caller {
    pub id: Option<Arc<str>>,
    pub scopes: Scopes,
}

impl Caller {
    /// A caller without a token.
    pub const ANONYMOUS: Caller = Caller { id: None, scopes: Scopes::NONE };
}

static API_TOKEN_ID: LazyLock<Arc<str>> = LazyLock::new(|| Arc::from("api-token"));
static READ_TOKEN_ID: LazyLock<Arc<str>> = LazyLock::new(|| Arc::from("read-token"));

/// The token of an `authorization: Bearer <token>` value (HTTP header or
/// gRPC metadata).
pub fn bearer_token(value: &[u8]) -> Option<&[u8]> {
    let (scheme, token) = value.split_at_checked(7)?;
    scheme.eq_ignore_ascii_case(b"bearer ").then_some(token)
}

/// Which scopes the configuration enforces (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Enforced {
    pub any_token: bool,
    pub read: bool,
    pub write: bool,
    pub admin: bool,
}

impl Enforced {
    pub fn of(config: &Config) -> Enforced {
        let highest = config
            .tokens
            .iter()
            .filter_map(|t| t.scopes.highest())
            .chain(config.write_token.as_ref().map(|_| Scope::Write))
            .chain(config.read_token.as_ref().map(|_| Scope::Read));
        let mut e = Enforced { any_token: false, read: false, write: false, admin: false };
        for scope in highest {
            e.any_token = true;
            e.read |= scope == Scope::Read;
            e.write |= scope >= Scope::Write;
            e.admin |= scope == Scope::Admin;
        }
        e
    }

    fn requires(self, scope: Scope) -> bool {
        match scope {
            Scope::Read => self.read,
            Scope::Write => self.write,
            Scope::Admin => self.admin,
        }
    }
}

/// Who `authorization` (the whole header or metadata value) identifies.
///
/// # Errors
/// [`ApiError::Unauthorized`] when tokens are configured and a token is given
/// that matches none, or the header is not a bearer token.
pub fn identify(config: &Config, authorization: Option<&[u8]>) -> Result<Caller, ApiError> {
    let Some(value) = authorization else { return Ok(Caller::ANONYMOUS) };
    if !Enforced::of(config).any_token {
        return Ok(Caller::ANONYMOUS);
    }
    let token = bearer_token(value).ok_or(ApiError::Unauthorized)?;
    lookup(config, token).ok_or(ApiError::Unauthorized)
}

/// The configured token equal to `token`, compared in constant time against
/// every candidate (no early exit).
fn lookup(config: &Config, token: &[u8]) -> Option<Caller> {
    let mut found: Option<Caller> = None;
    let plain =
        |secret: &Option<Secret>| secret.as_ref().is_some_and(|s| bool::from(token.ct_eq(s.expose().as_bytes())));
    if plain(&config.write_token) {
        found = Some(Caller { id: Some(API_TOKEN_ID.clone()), scopes: Scopes(Some(Scope::Write)) });
    }
    if plain(&config.read_token) && found.is_none() {
        found = Some(Caller { id: Some(READ_TOKEN_ID.clone()), scopes: Scopes(Some(Scope::Read)) });
    }
    let hash = TokenHash::of(token);
    for t in &config.tokens {
        let hit = bool::from(t.hash.ct_eq(&hash));
        if hit && found.is_none() {
            found = Some(Caller { id: Some(t.name.clone()), scopes: t.scopes });
        }
    }
    found
}

/// The caller, if it may act with `scope`.
///
/// # Errors
/// [`ApiError::Unauthorized`] for a missing or unknown token where `scope` is
/// enforced (or any unknown token); [`ApiError::Forbidden`] for a known token
/// without `scope`.
pub fn authorize(config: &Config, authorization: Option<&[u8]>, scope: Scope) -> Result<Caller, ApiError> {
    let caller = identify(config, authorization)?;
    if !Enforced::of(config).requires(scope) || caller.scopes.allows(scope) {
        Ok(caller)
    } else if caller.id.is_none() {
        Err(ApiError::Unauthorized)
    } else {
        Err(ApiError::Forbidden { needed: scope.as_str() })
    }
}

/// [`authorize`] for reads.
///
/// # Errors
/// As [`authorize`].
pub fn check_read(config: &Config, authorization: Option<&[u8]>) -> Result<Caller, ApiError> {
    authorize(config, authorization, Scope::Read)
}

/// [`authorize`] for writes.
///
/// # Errors
/// As [`authorize`].
pub fn check_write(config: &Config, authorization: Option<&[u8]>) -> Result<Caller, ApiError> {
    authorize(config, authorization, Scope::Write)
}

/// A fresh random token (32 bytes, URL-safe base64, `ib_` prefix).
///
/// # Errors
/// The OS has no randomness to give.
pub fn new_token() -> anyhow::Result<String> {
    use base64::Engine;
    let mut bytes = [0u8; 32];
    getrandom::fill(&mut bytes).map_err(|e| anyhow::anyhow!("no randomness from the OS: {e}"))?;
    Ok(format!("ib_{}", base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(bytes)))
}

/// Proof that the request may read clips and poses.
#[derive(Debug)]
pub struct ReadAccess(pub Caller);

/// Proof that the request may write.
#[derive(Debug)]
pub struct WriteAccess(pub Caller);

/// Proof that the request may use operational routes.
#[derive(Debug)]
pub struct AdminAccess(pub Caller);

fn authorization(parts: &Parts) -> Option<&[u8]> {
    parts.headers.get(AUTHORIZATION).map(|v| v.as_bytes())
}

impl FromRequestParts<AppState> for ReadAccess {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        check_read(&state.config, authorization(parts)).map(ReadAccess)
    }
}

impl FromRequestParts<AppState> for WriteAccess {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        check_write(&state.config, authorization(parts)).map(WriteAccess)
    }
}

impl FromRequestParts<AppState> for AdminAccess {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        authorize(&state.config, authorization(parts), Scope::Admin).map(AdminAccess)
    }
}

/// The caller without any scope requirement (for middleware such as
/// per-token rate limits): anonymous, or the token's holder.
impl FromRequestParts<AppState> for Caller {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        identify(&state.config, authorization(parts))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn token_specs_parse_from_the_flag_form() {
        let hash = TokenHash::of(b"t0k");
        let spec: TokenSpec = format!("ci:read+write:{hash}").parse().unwrap();
        assert_eq!(spec.name, "ci");
        assert_eq!(spec.scopes, [Scope::Read, Scope::Write]);
        assert_eq!(spec.hash, hash);
        assert!("ci:root:sha256:00".parse::<TokenSpec>().is_err());
        assert!(format!("ci:read:{}", "md5:00").parse::<TokenSpec>().is_err());
    }

    #[test]
    fn the_hash_is_sha256_in_hex() {
        // SHA-256("abc") from FIPS 180-2, appendix B.1.
        let expected = "sha256:ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad";
        assert_eq!(TokenHash::of(b"abc").to_string(), expected);
        assert_eq!(expected.parse::<TokenHash>().unwrap(), TokenHash::of(b"abc"));
    }

    #[test]
    fn scopes_nest() {
        let admin = Scopes::granted(&[Scope::Admin]);
        assert!(admin.allows(Scope::Read) && admin.allows(Scope::Write) && admin.allows(Scope::Admin));
        let write = Scopes::granted(&[Scope::Read, Scope::Write]);
        assert!(write.allows(Scope::Read) && !write.allows(Scope::Admin));
        assert!(!Scopes::NONE.allows(Scope::Read));
    }

    #[test]
    fn new_tokens_differ() {
        let (a, b) = (new_token().unwrap(), new_token().unwrap());
        assert_ne!(a, b);
        assert_eq!(a.len(), 3 + 43);
    }
}
