//! The service suite: the real `Application` in this process on
//! 127.0.0.1:0 (`common::TestApp`), driven by real clients (reqwest, tonic,
//! tokio-tungstenite, tokio-rustls, a headless Chromium), plus the store
//! behind it on SQLite and PostgreSQL. One binary (one link) for the whole
//! area, one module per concern; `common::ServerProcess` where one process of
//! the real binary is the subject (flags, environment, `kill -9`).
//!
//! PostgreSQL tests skip without a server unless `INBETWEEN_REQUIRE_POSTGRES=1`;
//! the browser tests skip without Chromium unless `INBETWEEN_REQUIRE_BROWSER=1`.

#[path = "../common/mod.rs"]
mod common;

mod api;
mod hardening;
mod load;
mod security;
mod store;
mod streaming;
mod viewer;
