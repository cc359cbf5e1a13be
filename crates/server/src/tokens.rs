//! API tokens as the configuration holds them: scopes, the SHA-256 that
//! stands in for a token, and the `[[tokens]]` / `--token` entries.
//!
//! Plain data with no server types, so that `config` can parse tokens and
//! `auth` can check them without either importing the other.

use std::fmt;
use std::str::FromStr;
use std::sync::Arc;

use serde::Deserialize;
use sha2::{Digest, Sha256};
use subtle::{Choice, ConstantTimeEq};

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

    /// Compares in constant time.
    pub fn ct_eq(&self, other: &TokenHash) -> Choice {
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
