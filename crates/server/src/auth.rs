//! Who is calling, and what they may do: the [`Caller`] of each request,
//! worked out once, and the scopes its token grants.
//!
//! A token grants one of three nested scopes: **read** (clips, poses,
//! streams), **write** (create, replace, delete, import; implies read) and
//! **admin** (operational routes such as `/metrics`; implies write and read).
//! Tokens come from the `[[tokens]]` list (name, scopes and the token's
//! `sha256:<hex>` hash, never the token itself; see `server::tokens`) and
//! from the older plain `--api-token` (write) and `--read-token` (read).
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
//! reporting. A valid token without the scope a route needs is 403. On a
//! server without tokens the `Authorization` header means nothing and is
//! ignored.
//!
//! The given token is hashed once and compared with every configured hash in
//! constant time (`subtle`), without stopping at the first match, so timing
//! tells nothing about which token, or how much of one, matched.
//!
//! **One identity per request.** [`Auth::identify`] turns a request's
//! `Authorization` value and peer address into an [`Identity`]: the
//! [`Caller`] (the token's name when a token identifies it, its address
//! otherwise) or a refusal. REST and WebSocket requests get it once, from the
//! [`identify_requests`] middleware, as a request extension; gRPC calls
//! [`Auth::identify`] once per RPC. Everything that counts per caller — the
//! write rate limit and the stream caps — keys on that `Caller`, never on the
//! raw header, so a client cannot become someone new by inventing tokens.
//!
//! **The client's address** is the peer's, except when the peer is one of
//! the configured `trusted_proxies`: then it is the rightmost address of
//! `Forwarded: for=` (or, without that header, `X-Forwarded-For`) that is not
//! itself a trusted proxy ([`Auth::client_addr`]). From any other peer those
//! headers are ignored, so a client cannot choose its own address.
//! Handlers state the scope they need with the extractors [`ReadAccess`],
//! [`WriteAccess`] and [`AdminAccess`], each carrying the `Caller`.
//!
//! **Tokens on a browser's WebSocket.** A browser cannot set headers on a
//! WebSocket handshake; it can only offer subprotocols. So a handshake
//! without `Authorization` may carry its token as the subprotocol
//! `inbetween.bearer.<base64url of the token, unpadded>`, offered next to
//! [`WS_PROTOCOL`] (`inbetween`), which the stream routes select: the token
//! is never echoed. It is the same token under the same rules (a malformed
//! entry is a token that matches nothing); `Authorization` wins when both are
//! sent. This keeps the server stateless (any node accepts it, unlike a
//! ticket kept in one node's memory) and the token out of URLs and logs.

use std::net::{IpAddr, SocketAddr};
use std::sync::{Arc, LazyLock};

use axum::extract::{ConnectInfo, FromRequestParts, Request, State};
use axum::http::header::{AUTHORIZATION, FORWARDED, SEC_WEBSOCKET_PROTOCOL};
use axum::http::request::Parts;
use axum::http::{HeaderMap, HeaderName};
use axum::middleware::Next;
use axum::response::Response;
use base64::Engine as _;
use subtle::ConstantTimeEq;

use super::config::{Config, Secret};
use super::error::ApiError;
pub use super::tokens::{Scope, Scopes, Token, TokenHash, TokenSpec, new_token};

/// The caller of a request, once its token (if any) has been checked.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Caller {
    /// The configured name of the token that identified the caller
    /// (`api-token` and `read-token` for the plain tokens); `None` when it
    /// sent no token, or the server has none.
    pub token: Option<Arc<str>>,
    /// The client's IP address, when the transport reports it (in-process
    /// tests that skip the listener have none).
    pub addr: Option<IpAddr>,
    pub scopes: Scopes,
}

/// What per-caller limits count under: the token's name when a token
/// identifies the caller, else its address.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum CallerKey {
    Token(Arc<str>),
    Addr(IpAddr),
    /// Neither a token nor an address: such callers share one count.
    Unknown,
    /// The node's own work, done for whoever waits on it: a cache miss's
    /// build, shared by every request that missed on the clip.
    Node,
}

impl Caller {
    /// A caller at `addr` without a token.
    pub fn anonymous(addr: Option<IpAddr>) -> Caller {
        Caller { token: None, addr, scopes: Scopes::NONE }
    }

    pub fn key(&self) -> CallerKey {
        match (&self.token, self.addr) {
            (Some(name), _) => CallerKey::Token(Arc::clone(name)),
            (None, Some(ip)) => CallerKey::Addr(ip),
            (None, None) => CallerKey::Unknown,
        }
    }
}

static API_TOKEN_NAME: LazyLock<Arc<str>> = LazyLock::new(|| Arc::from("api-token"));
static READ_TOKEN_NAME: LazyLock<Arc<str>> = LazyLock::new(|| Arc::from("read-token"));

/// The WebSocket subprotocol the stream routes select when a client offers
/// it; a browser offers it next to its `inbetween.bearer.…` token (module doc).
pub const WS_PROTOCOL: &str = "inbetween";

/// The subprotocol prefix that carries a token (module doc).
const WS_BEARER_PREFIX: &str = "inbetween.bearer.";

/// `Bearer <token>` from a handshake's `inbetween.bearer.<base64url>`
/// subprotocol, if it offers one. An entry that does not decode gives an
/// empty value, which identifies nobody (like a header of another scheme).
fn protocol_authorization(headers: &HeaderMap) -> Option<Vec<u8>> {
    let offered = headers.get_all(SEC_WEBSOCKET_PROTOCOL).iter().filter_map(|v| v.to_str().ok());
    let encoded = offered.flat_map(|v| v.split(',')).find_map(|p| p.trim().strip_prefix(WS_BEARER_PREFIX))?;
    let engine = base64::engine::general_purpose::URL_SAFE_NO_PAD;
    Some(
        engine
            .decode(encoded.trim_end_matches('='))
            .map(|token| [b"Bearer ".as_slice(), &token].concat())
            .unwrap_or_default(),
    )
}

/// The token of an `authorization: Bearer <token>` value (HTTP header or
/// gRPC metadata).
fn bearer_token(value: &[u8]) -> Option<&[u8]> {
    let (scheme, token) = value.split_at_checked(7)?;
    scheme.eq_ignore_ascii_case(b"bearer ").then_some(token)
}

/// Which scopes the configuration enforces (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Enforced {
    any_token: bool,
    read: bool,
    write: bool,
    admin: bool,
}

impl Enforced {
    fn of(config: &Config) -> Enforced {
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

/// The configured tokens and what they enforce: identifies callers.
#[derive(Debug, Clone)]
pub struct Auth {
    config: Arc<Config>,
    enforced: Enforced,
}

impl Auth {
    pub fn new(config: Arc<Config>) -> Auth {
        let enforced = Enforced::of(&config);
        Auth { config, enforced }
    }

    /// Who `authorization` (the whole header or metadata value) identifies,
    /// calling from `addr`. Only a configured token makes a caller someone
    /// other than its address; a server without tokens ignores the header.
    pub fn identify(&self, authorization: Option<&[u8]>, addr: Option<IpAddr>) -> Identity {
        let caller = match authorization {
            Some(value) if self.enforced.any_token => bearer_token(value).and_then(|token| self.lookup(token, addr)),
            _ => Some(Caller::anonymous(addr)),
        };
        Identity { caller, enforced: self.enforced }
    }

    /// The client's address: `peer`, or what a trusted proxy says (module doc).
    pub fn client_addr(&self, peer: Option<IpAddr>, headers: &HeaderMap) -> Option<IpAddr> {
        let trusted = &self.config.trusted_proxies;
        let Some(peer) = peer.filter(|p| trusted.contains(*p)) else { return peer };
        let hops = forwarded_hops(headers);
        for hop in hops.iter().rev() {
            match hop {
                Some(ip) if trusted.contains(*ip) => {}
                Some(ip) => return Some(*ip),
                // A hop that names no address (`unknown`, garbage): go no further than the proxy.
                None => return Some(peer),
            }
        }
        // Every hop is a trusted proxy: the leftmost is the nearest thing to a client.
        hops.first().copied().flatten().or(Some(peer))
    }

    /// The configured token equal to `token`, compared in constant time
    /// against every candidate (no early exit).
    fn lookup(&self, token: &[u8], addr: Option<IpAddr>) -> Option<Caller> {
        let config = &self.config;
        let named = |name: &Arc<str>, scopes| Caller { token: Some(Arc::clone(name)), addr, scopes };
        let mut found: Option<Caller> = None;
        let plain =
            |secret: &Option<Secret>| secret.as_ref().is_some_and(|s| bool::from(token.ct_eq(s.expose().as_bytes())));
        if plain(&config.write_token) {
            found = Some(named(&API_TOKEN_NAME, Scopes::granted(&[Scope::Write])));
        }
        if plain(&config.read_token) && found.is_none() {
            found = Some(named(&READ_TOKEN_NAME, Scopes::granted(&[Scope::Read])));
        }
        let hash = TokenHash::of(token);
        for t in &config.tokens {
            let hit = bool::from(t.hash.ct_eq(&hash));
            if hit && found.is_none() {
                found = Some(named(&t.name, t.scopes));
            }
        }
        found
    }
}

/// The hops a proxy chain reports, client first: `Forwarded`'s `for=`
/// values if it is present, else `X-Forwarded-For`'s (every header line, in
/// order). `None` marks a hop that names no IP address.
fn forwarded_hops(headers: &HeaderMap) -> Vec<Option<IpAddr>> {
    let values = |name: HeaderName| headers.get_all(name).iter().filter_map(|v| v.to_str().ok());
    if headers.contains_key(FORWARDED) {
        values(FORWARDED)
            .flat_map(|v| v.split(','))
            .filter_map(|element| {
                let pair = element
                    .split(';')
                    .find_map(|p| p.trim().split_once('=').filter(|(k, _)| k.eq_ignore_ascii_case("for")));
                pair.map(|(_, node)| forwarded_node(node))
            })
            .collect()
    } else {
        values(HeaderName::from_static("x-forwarded-for"))
            .flat_map(|v| v.split(','))
            .map(|hop| forwarded_node(hop.trim()))
            .collect()
    }
}

/// The IP address of one hop: `1.2.3.4`, `1.2.3.4:80`, `"[2001:db8::1]:443"`, `2001:db8::1`.
fn forwarded_node(node: &str) -> Option<IpAddr> {
    let node = node.trim().trim_matches('"');
    if let Some(rest) = node.strip_prefix('[') {
        return rest.split(']').next()?.parse().ok();
    }
    let with_port = || node.rsplit_once(':')?.0.parse::<std::net::Ipv4Addr>().ok().map(IpAddr::V4);
    node.parse::<IpAddr>().ok().or_else(with_port)
}

/// What auth found out about one request: its caller, or that the token it
/// sent matches nothing.
#[derive(Debug, Clone)]
pub struct Identity {
    /// `None`: a bearer token (or another scheme) that matches no configured token.
    caller: Option<Caller>,
    enforced: Enforced,
}

impl Identity {
    /// The caller, unless its token was refused.
    pub fn caller(&self) -> Option<&Caller> {
        self.caller.as_ref()
    }

    /// The caller, if it may act with `scope`.
    ///
    /// # Errors
    /// [`ApiError::Unauthorized`] for an unknown token, or a missing one where
    /// `scope` is enforced; [`ApiError::Forbidden`] for a known token without
    /// `scope`.
    pub fn authorize(&self, scope: Scope) -> Result<Caller, ApiError> {
        let caller = self.caller.as_ref().ok_or(ApiError::Unauthorized)?;
        if !self.enforced.requires(scope) || caller.scopes.allows(scope) {
            Ok(caller.clone())
        } else if caller.token.is_none() {
            Err(ApiError::Unauthorized)
        } else {
            Err(ApiError::Forbidden { needed: scope.as_str() })
        }
    }
}

/// The middleware that identifies every REST and WebSocket request once and
/// leaves the [`Identity`] in its extensions, for the rate limit and the
/// access extractors. It refuses nothing itself: routes that take no token
/// (probes, the OpenAPI document) answer whatever the header says. The
/// identity also goes on the answer's extensions, for the access log
/// (`access_log`), which sits outside this layer.
pub async fn identify_requests(State(auth): State<Auth>, mut request: Request, next: Next) -> Response {
    let peer = request.extensions().get::<ConnectInfo<SocketAddr>>().map(|ConnectInfo(a)| a.ip());
    let addr = auth.client_addr(peer, request.headers());
    let headers = request.headers();
    let authorization =
        headers.get(AUTHORIZATION).map(|v| v.as_bytes().to_vec()).or_else(|| protocol_authorization(headers));
    let identity = auth.identify(authorization.as_deref(), addr);
    request.extensions_mut().insert(identity.clone());
    let mut response = next.run(request).await;
    response.extensions_mut().insert(identity);
    response
}

/// The identity [`identify_requests`] left on the request.
fn identity(parts: &Parts) -> Result<&Identity, ApiError> {
    parts
        .extensions
        .get::<Identity>()
        .ok_or_else(|| ApiError::internal(anyhow::anyhow!("no caller identity: the auth middleware is not installed")))
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

impl<S: Send + Sync> FromRequestParts<S> for ReadAccess {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, ApiError> {
        identity(parts)?.authorize(Scope::Read).map(ReadAccess)
    }
}

impl<S: Send + Sync> FromRequestParts<S> for WriteAccess {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, ApiError> {
        identity(parts)?.authorize(Scope::Write).map(WriteAccess)
    }
}

impl<S: Send + Sync> FromRequestParts<S> for AdminAccess {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, ApiError> {
        identity(parts)?.authorize(Scope::Admin).map(AdminAccess)
    }
}

#[cfg(test)]
mod tests {
    use std::net::SocketAddr;

    use super::*;

    const ALPHA: &str = "ib_alpha-token";

    fn config_with(tokens: &[(&str, Scope, &str)]) -> Arc<Config> {
        let mut config = Config::new(SocketAddr::from(([127, 0, 0, 1], 0)), "unused");
        config.tokens = tokens
            .iter()
            .map(|(name, scope, token)| {
                let hash = TokenHash::of(token.as_bytes());
                TokenSpec { name: (*name).into(), scopes: vec![*scope], hash }.validate().unwrap()
            })
            .collect();
        Arc::new(config)
    }

    fn bearer(token: &str) -> Vec<u8> {
        format!("Bearer {token}").into_bytes()
    }

    fn ip(last: u8) -> Option<IpAddr> {
        Some(IpAddr::from([10, 0, 0, last]))
    }

    #[test]
    fn without_tokens_any_header_is_the_callers_address() {
        let auth = Auth::new(config_with(&[]));
        let keys: Vec<CallerKey> = ["ib_random-1", "ib_random-2", "not even bearer"]
            .iter()
            .map(|t| auth.identify(Some(&bearer(t)), ip(7)).authorize(Scope::Write).unwrap().key())
            .collect();
        assert_eq!(keys, vec![CallerKey::Addr(IpAddr::from([10, 0, 0, 7])); 3]);
        let silent = auth.identify(None, ip(7)).authorize(Scope::Write).unwrap();
        assert_eq!(silent, Caller::anonymous(ip(7)));
        assert_eq!(auth.identify(None, None).caller().unwrap().key(), CallerKey::Unknown);
    }

    #[test]
    fn a_known_token_is_its_name_from_any_address() {
        let auth = Auth::new(config_with(&[("ci", Scope::Write, ALPHA)]));
        for addr in [ip(1), ip(2), None] {
            let caller = auth.identify(Some(&bearer(ALPHA)), addr).authorize(Scope::Write).unwrap();
            assert_eq!(caller.key(), CallerKey::Token(Arc::from("ci")));
            assert_eq!((caller.addr, caller.scopes.highest()), (addr, Some(Scope::Write)));
        }
        // The scheme is case-insensitive, the token is not.
        assert!(auth.identify(Some(format!("bEaReR {ALPHA}").as_bytes()), ip(1)).caller().is_some());
        assert!(auth.identify(Some(&bearer(&ALPHA.to_uppercase())), ip(1)).caller().is_none());
    }

    #[test]
    fn an_unknown_token_is_refused_even_where_no_scope_is_needed() {
        // Only a write token: reads are open, but a wrong token is still 401.
        let auth = Auth::new(config_with(&[("ci", Scope::Write, ALPHA)]));
        for header in [bearer("ib_guess"), b"Basic YWxhZGRpbjpvcGVuc2VzYW1l".to_vec()] {
            let identity = auth.identify(Some(&header), ip(1));
            assert!(identity.caller().is_none());
            assert!(matches!(identity.authorize(Scope::Read), Err(ApiError::Unauthorized)));
        }
        // Without a header the caller is its address, and reads stay open.
        let anonymous = auth.identify(None, ip(1));
        assert_eq!(anonymous.authorize(Scope::Read).unwrap().key(), CallerKey::Addr(IpAddr::from([10, 0, 0, 1])));
        assert!(matches!(anonymous.authorize(Scope::Write), Err(ApiError::Unauthorized)));
    }

    #[test]
    fn a_token_without_the_scope_is_forbidden() {
        let auth = Auth::new(config_with(&[("viewer", Scope::Read, "ib_r"), ("ops", Scope::Admin, "ib_a")]));
        let reader = auth.identify(Some(&bearer("ib_r")), ip(1));
        assert_eq!(reader.authorize(Scope::Read).unwrap().token.as_deref(), Some("viewer"));
        assert!(matches!(reader.authorize(Scope::Write), Err(ApiError::Forbidden { needed: "write" })));
        let admin = auth.identify(Some(&bearer("ib_a")), ip(1));
        assert!(admin.authorize(Scope::Admin).is_ok() && admin.authorize(Scope::Read).is_ok());
    }

    fn headers(pairs: &[(&str, &str)]) -> HeaderMap {
        let mut map = HeaderMap::new();
        for (name, value) in pairs {
            map.append(axum::http::HeaderName::from_bytes(name.as_bytes()).unwrap(), value.parse().unwrap());
        }
        map
    }

    #[test]
    fn forwarding_headers_count_only_from_a_trusted_proxy() {
        let mut config = Config::new(SocketAddr::from(([127, 0, 0, 1], 0)), "unused");
        let raw = crate::config::RawConfig { trusted_proxies: Some(vec!["10.0.0.0/24".into()]), ..Default::default() };
        config.trusted_proxies = raw.validate().unwrap().trusted_proxies;
        let auth = Auth::new(Arc::new(config));
        let at = |peer: [u8; 4], pairs: &[(&str, &str)]| {
            auth.client_addr(Some(IpAddr::from(peer)), &headers(pairs)).unwrap().to_string()
        };
        let xff = [("x-forwarded-for", "203.0.113.5, 198.51.100.7")];
        // An untrusted peer is itself, whatever it claims.
        assert_eq!(at([192, 0, 2, 1], &xff), "192.0.2.1");
        // A trusted proxy: the rightmost hop that is not a trusted proxy.
        assert_eq!(at([10, 0, 0, 9], &xff), "198.51.100.7");
        assert_eq!(at([10, 0, 0, 9], &[("x-forwarded-for", "203.0.113.5, 10.0.0.3")]), "203.0.113.5");
        assert_eq!(
            at([10, 0, 0, 9], &[("x-forwarded-for", "203.0.113.5"), ("x-forwarded-for", "10.0.0.4")]),
            "203.0.113.5"
        );
        assert_eq!(at([10, 0, 0, 9], &[]), "10.0.0.9", "no header: the proxy itself");
        assert_eq!(at([10, 0, 0, 9], &[("x-forwarded-for", "nonsense")]), "10.0.0.9");
        // Forwarded wins over X-Forwarded-For; ports, brackets and quotes are stripped.
        let fwd = [("forwarded", "for=198.51.100.1;proto=https, for=\"[2001:db8::7]:4711\""), xff[0]];
        assert_eq!(at([10, 0, 0, 9], &fwd), "2001:db8::7");
        assert_eq!(at([10, 0, 0, 9], &[("forwarded", "for=\"192.0.2.60:8080\"")]), "192.0.2.60");
        assert_eq!(at([10, 0, 0, 9], &[("forwarded", "For=unknown")]), "10.0.0.9");
    }

    #[test]
    fn the_plain_tokens_are_named_api_token_and_read_token() {
        let mut config = Config::new(SocketAddr::from(([127, 0, 0, 1], 0)), "unused");
        config.write_token = Some(Secret::new("w"));
        config.read_token = Some(Secret::new("r"));
        let auth = Auth::new(Arc::new(config));
        let name = |t: &str| auth.identify(Some(&bearer(t)), None).caller().and_then(|c| c.token.clone());
        assert_eq!(name("w").as_deref(), Some("api-token"));
        assert_eq!(name("r").as_deref(), Some("read-token"));
        assert_eq!(name("x"), None);
    }

    #[test]
    fn a_websocket_subprotocol_carries_a_base64url_token() {
        let mut headers = HeaderMap::new();
        assert_eq!(protocol_authorization(&headers), None);
        // "r/t+?" is not a valid subprotocol token; its base64url form is: ci90Kz8.
        headers.insert(SEC_WEBSOCKET_PROTOCOL, "inbetween, inbetween.bearer.ci90Kz8".parse().unwrap());
        assert_eq!(protocol_authorization(&headers).as_deref(), Some(b"Bearer r/t+?".as_slice()));
        headers.insert(SEC_WEBSOCKET_PROTOCOL, "inbetween.bearer.ci90Kz8=".parse().unwrap());
        assert_eq!(
            protocol_authorization(&headers).as_deref(),
            Some(b"Bearer r/t+?".as_slice()),
            "padding is accepted"
        );
        headers.insert(SEC_WEBSOCKET_PROTOCOL, "inbetween.bearer.!!".parse().unwrap());
        assert_eq!(protocol_authorization(&headers).as_deref(), Some(b"".as_slice()), "undecodable: nobody");
        headers.insert(SEC_WEBSOCKET_PROTOCOL, "graphql-ws".parse().unwrap());
        assert_eq!(protocol_authorization(&headers), None);
    }
}
