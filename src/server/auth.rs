//! Bearer-token checks as extractors, so a handler's signature says what it
//! needs: [`WriteAccess`] for create/replace/delete, [`ReadAccess`] for clip
//! and pose reads. Extractors run before the body is read, so an
//! unauthorised upload is refused without buffering it.
//!
//! Tokens are compared in constant time (`subtle`); only the token's length
//! can leak through timing, which is not secret in any useful sense.
//! Without a configured write token, writes are open; without a read token,
//! reads are open. When a read token is set, the write token reads too.
//! [`check_read`] and [`check_write`] apply the same rules to gRPC metadata.

use axum::extract::FromRequestParts;
use axum::http::header::AUTHORIZATION;
use axum::http::request::Parts;
use subtle::ConstantTimeEq;

use super::config::{Config, Secret};
use super::error::ApiError;
use super::state::AppState;

/// Proof that the request may write.
#[derive(Debug)]
pub struct WriteAccess;

/// Proof that the request may read clips and poses.
#[derive(Debug)]
pub struct ReadAccess;

/// The token of an `authorization: Bearer <token>` value (HTTP header or
/// gRPC metadata).
pub fn bearer_token(value: &[u8]) -> Option<&[u8]> {
    let (scheme, token) = value.split_at_checked(7)?;
    scheme.eq_ignore_ascii_case(b"bearer ").then_some(token)
}

/// Whether `authorization` (the whole header or metadata value) may write.
///
/// # Errors
/// [`ApiError::Unauthorized`] when a write token is set and not given.
pub fn check_write(config: &Config, authorization: Option<&[u8]>) -> Result<(), ApiError> {
    let given = authorization.and_then(bearer_token);
    match &config.write_token {
        Some(token) if !matches(given, token) => Err(ApiError::Unauthorized),
        _ => Ok(()),
    }
}

/// Whether `authorization` may read (the read or the write token).
///
/// # Errors
/// [`ApiError::Unauthorized`] when a read token is set and neither is given.
pub fn check_read(config: &Config, authorization: Option<&[u8]>) -> Result<(), ApiError> {
    let Some(read) = &config.read_token else { return Ok(()) };
    let given = authorization.and_then(bearer_token);
    let write_ok = config.write_token.as_ref().is_some_and(|w| matches(given, w));
    if matches(given, read) || write_ok { Ok(()) } else { Err(ApiError::Unauthorized) }
}

fn matches(given: Option<&[u8]>, expected: &Secret) -> bool {
    given.is_some_and(|g| bool::from(g.ct_eq(expected.expose().as_bytes())))
}

impl FromRequestParts<AppState> for WriteAccess {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        let authorization = parts.headers.get(AUTHORIZATION).map(|v| v.as_bytes());
        check_write(&state.config, authorization).map(|()| WriteAccess)
    }
}

impl FromRequestParts<AppState> for ReadAccess {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        let authorization = parts.headers.get(AUTHORIZATION).map(|v| v.as_bytes());
        check_read(&state.config, authorization).map(|()| ReadAccess)
    }
}
