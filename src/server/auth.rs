//! Bearer-token checks as extractors, so a handler's signature says what it
//! needs: [`WriteAccess`] for create/replace/delete, [`ReadAccess`] for clip
//! and pose reads. Extractors run before the body is read, so an
//! unauthorised upload is refused without buffering it.
//!
//! Tokens are compared in constant time (`subtle`); only the token's length
//! can leak through timing, which is not secret in any useful sense.
//! Without a configured write token, writes are open; without a read token,
//! reads are open. When a read token is set, the write token reads too.

use axum::extract::FromRequestParts;
use axum::http::header::AUTHORIZATION;
use axum::http::request::Parts;
use subtle::ConstantTimeEq;

use super::config::Secret;
use super::error::ApiError;
use super::state::AppState;

/// Proof that the request may write.
#[derive(Debug)]
pub struct WriteAccess;

/// Proof that the request may read clips and poses.
#[derive(Debug)]
pub struct ReadAccess;

fn bearer(parts: &Parts) -> Option<&[u8]> {
    let value = parts.headers.get(AUTHORIZATION)?.as_bytes();
    let (scheme, token) = value.split_at_checked(7)?;
    scheme.eq_ignore_ascii_case(b"bearer ").then_some(token)
}

fn matches(given: Option<&[u8]>, expected: &Secret) -> bool {
    given.is_some_and(|g| bool::from(g.ct_eq(expected.expose().as_bytes())))
}

impl FromRequestParts<AppState> for WriteAccess {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        match &state.config.write_token {
            Some(token) if !matches(bearer(parts), token) => Err(ApiError::Unauthorized),
            _ => Ok(WriteAccess),
        }
    }
}

impl FromRequestParts<AppState> for ReadAccess {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        let Some(read) = &state.config.read_token else { return Ok(ReadAccess) };
        let given = bearer(parts);
        let write_ok = state.config.write_token.as_ref().is_some_and(|w| matches(given, w));
        if matches(given, read) || write_ok { Ok(ReadAccess) } else { Err(ApiError::Unauthorized) }
    }
}
