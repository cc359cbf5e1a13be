//! A fresh PostgreSQL schema per test, on the server at 127.0.0.1:5432
//! (database `test`; `INBETWEEN_TEST_POSTGRES_URL` overrides). Shared by the
//! `service` (store) and `system` (multinode) test binaries.
//!
//! Without a reachable server a test skips with a message, unless
//! `INBETWEEN_REQUIRE_POSTGRES=1` (CI), which turns the skip into a failure.

use std::time::Duration;

use sqlx::postgres::{PgPool, PgPoolOptions};

pub const DEFAULT_URL: &str = "postgres://postgres@127.0.0.1:5432/test";

/// The server URL (without a schema).
pub fn base_url() -> String {
    std::env::var("INBETWEEN_TEST_POSTGRES_URL").unwrap_or_else(|_| DEFAULT_URL.to_owned())
}

/// A schema of its own, dropped by [`Schema::drop_now`].
pub struct Schema {
    pub name: String,
    pub admin: PgPool,
}

impl Schema {
    /// Creates `t_<tag>_<unique>`; `None` (after a message) if PostgreSQL is
    /// unreachable and not required.
    pub async fn create(tag: &str) -> Option<Schema> {
        let url = base_url();
        let connect = PgPoolOptions::new().max_connections(2).acquire_timeout(Duration::from_secs(3)).connect(&url);
        let admin = match tokio::time::timeout(Duration::from_secs(5), connect).await {
            Ok(Ok(pool)) => pool,
            failure => {
                let why = match failure {
                    Ok(Err(e)) => e.to_string(),
                    _ => "timed out".to_owned(),
                };
                if std::env::var("INBETWEEN_REQUIRE_POSTGRES").is_ok_and(|v| v == "1") {
                    panic!(
                        "PostgreSQL at {} is required (INBETWEEN_REQUIRE_POSTGRES=1) but unreachable: {why}",
                        base_url()
                    );
                }
                eprintln!(
                    "SKIPPED: PostgreSQL at {} is unreachable ({why}); set INBETWEEN_TEST_POSTGRES_URL, or \
                     INBETWEEN_REQUIRE_POSTGRES=1 to fail instead",
                    base_url()
                );
                return None;
            }
        };
        let name = format!("t_{tag}_{}", uuid::Uuid::now_v7().simple()).chars().take(60).collect::<String>();
        sqlx::query(sqlx::AssertSqlSafe(format!("CREATE SCHEMA \"{name}\""))).execute(&admin).await.unwrap();
        Some(Schema { name, admin })
    }

    /// A URL whose connections use this schema (`search_path`), for the
    /// store and for the server binary alike; `extra` is appended as more
    /// query parameters (e.g. `application_name=node-a`).
    pub fn url(&self, extra: &str) -> String {
        let mut url = format!("{}?options=-csearch_path%3D{}", base_url(), self.name);
        if !extra.is_empty() {
            url.push('&');
            url.push_str(extra);
        }
        url
    }

    /// Terminates every backend whose `application_name` is `app`; returns how many.
    pub async fn terminate(&self, app: &str) -> i64 {
        sqlx::query_scalar(
            "SELECT count(*) FROM (SELECT pg_terminate_backend(pid) FROM pg_stat_activity \
             WHERE application_name = $1 AND pid <> pg_backend_pid()) AS t",
        )
        .bind(app)
        .fetch_one(&self.admin)
        .await
        .unwrap()
    }

    /// Waits until no backend of `app` is left (a terminated one exits a
    /// moment after [`Schema::terminate`] answers).
    pub async fn until_gone(&self, app: &str) {
        let what = format!("the backends of {app} exited");
        super::eventually(Duration::from_secs(10), &what, || async {
            let left: i64 = sqlx::query_scalar("SELECT count(*) FROM pg_stat_activity WHERE application_name = $1")
                .bind(app)
                .fetch_one(&self.admin)
                .await
                .unwrap();
            left == 0
        })
        .await;
    }

    pub async fn drop_now(self) {
        sqlx::query(sqlx::AssertSqlSafe(format!("DROP SCHEMA \"{}\" CASCADE", self.name)))
            .execute(&self.admin)
            .await
            .unwrap();
        self.admin.close().await;
    }
}
