//! The stored form of broadcasts (SPEC §9, `migrations/*/0004_broadcasts.sql`):
//! a definition row and one row per stamped control. The store keeps the
//! JSON it is handed and parses none of it; the server (`server::broadcast_sync`)
//! writes and reads it back.

/// A broadcast as stored, with its controls in application order.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredBroadcast {
    pub id: String,
    /// What the server needs to build it again (opaque here).
    pub definition: String,
    /// Unix nanoseconds of its tick 0.
    pub created_at: i64,
    /// In `(seq, id)` order.
    pub controls: Vec<StoredControl>,
}

/// One control as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredControl {
    /// A UUIDv7, unique; orders the controls of one `seq`.
    pub id: String,
    /// The tick it applies from.
    pub seq: u64,
    /// The control as the server will parse it again (opaque here).
    pub control: String,
}

/// The broadcast methods of [`ClipStore`](super::ClipStore), the same for
/// both backends but for the pool type and `$sql`, the backend's statement
/// module (`lite` or `pg`). Expanded inside each backend's `impl ClipStore`,
/// where `self.pool`, `self.controls_of`, `timed` and `now_millis` are the
/// backend's own.
macro_rules! broadcast_methods {
    ($sql:ident) => {
        fn create_broadcast(&self, broadcast: StoredBroadcast) -> BoxFuture<'_, Result<(), StoreError>> {
            async move {
                let started = Instant::now();
                let r = sqlx::query($sql::INSERT)
                    .bind(&broadcast.id)
                    .bind(&broadcast.definition)
                    .bind(broadcast.created_at)
                    .bind(now_millis())
                    .execute(&self.pool)
                    .await
                    .map(|_| ());
                timed("create_broadcast", started, r)
            }
            .boxed()
        }

        fn add_broadcast_control<'a>(
            &'a self,
            id: &'a str,
            control: StoredControl,
        ) -> BoxFuture<'a, Result<(), StoreError>> {
            async move {
                let started = Instant::now();
                let r = async {
                    let mut tx = self.pool.begin().await?;
                    let done = sqlx::query($sql::INSERT_CONTROL)
                        .bind(&control.id)
                        .bind(id)
                        .bind(control.seq as i64)
                        .bind(&control.control)
                        .execute(&mut *tx)
                        .await?;
                    sqlx::query($sql::TOUCH).bind(id).bind(now_millis()).execute(&mut *tx).await?;
                    tx.commit().await?;
                    Ok(done.rows_affected() == 1)
                }
                .await;
                match timed("add_broadcast_control", started, r)? {
                    true => Ok(()),
                    false => Err(StoreError::NotFound),
                }
            }
            .boxed()
        }

        fn broadcast<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<Option<StoredBroadcast>, StoreError>> {
            async move {
                let started = Instant::now();
                let r = async {
                    let Some(row) = sqlx::query($sql::ONE).bind(id).fetch_optional(&self.pool).await? else {
                        return Ok(None);
                    };
                    let mut b = broadcast_from_row(&row)?;
                    b.controls = self.controls_of(&b.id).await?;
                    Ok(Some(b))
                }
                .await;
                timed("broadcast", started, r)
            }
            .boxed()
        }

        fn broadcasts(&self) -> BoxFuture<'_, Result<Vec<StoredBroadcast>, StoreError>> {
            async move {
                let started = Instant::now();
                let r = async {
                    let rows = sqlx::query($sql::ALL).fetch_all(&self.pool).await?;
                    let mut all = Vec::with_capacity(rows.len());
                    for row in &rows {
                        let mut b = broadcast_from_row(row)?;
                        b.controls = self.controls_of(&b.id).await?;
                        all.push(b);
                    }
                    Ok(all)
                }
                .await;
                timed("broadcasts", started, r)
            }
            .boxed()
        }

        fn delete_broadcast<'a>(&'a self, id: &'a str) -> BoxFuture<'a, Result<bool, StoreError>> {
            async move {
                let started = Instant::now();
                let r = sqlx::query($sql::DELETE).bind(id).execute(&self.pool).await.map(|d| d.rows_affected() == 1);
                timed("delete_broadcast", started, r)
            }
            .boxed()
        }

        fn touch_broadcast<'a>(&'a self, id: &'a str, now_ms: i64) -> BoxFuture<'a, Result<(), StoreError>> {
            async move {
                let started = Instant::now();
                let r = sqlx::query($sql::TOUCH).bind(id).bind(now_ms).execute(&self.pool).await.map(|_| ());
                timed("touch_broadcast", started, r)
            }
            .boxed()
        }

        fn expire_broadcast<'a>(&'a self, id: &'a str, before_ms: i64) -> BoxFuture<'a, Result<bool, StoreError>> {
            async move {
                let started = Instant::now();
                let r = sqlx::query($sql::EXPIRE)
                    .bind(id)
                    .bind(before_ms)
                    .execute(&self.pool)
                    .await
                    .map(|d| d.rows_affected() == 1);
                timed("expire_broadcast", started, r)
            }
            .boxed()
        }
    };
}
pub(crate) use broadcast_methods;

/// The broadcast SQL of PostgreSQL.
pub(crate) mod pg {
    pub const INSERT: &str = "INSERT INTO broadcasts (id, definition, created_at, active_at) VALUES ($1, $2, $3, $4)";
    pub const INSERT_CONTROL: &str = "INSERT INTO broadcast_controls (id, broadcast_id, seq, control) SELECT $1, $2, $3, $4 \
         WHERE EXISTS (SELECT 1 FROM broadcasts WHERE id = $2)";
    pub const TOUCH: &str = "UPDATE broadcasts SET active_at = $2 WHERE id = $1 AND active_at < $2";
    pub const DELETE: &str = "DELETE FROM broadcasts WHERE id = $1";
    pub const EXPIRE: &str = "DELETE FROM broadcasts WHERE id = $1 AND active_at < $2";
    pub const ALL: &str = "SELECT id, definition, created_at FROM broadcasts ORDER BY id";
    pub const ONE: &str = "SELECT id, definition, created_at FROM broadcasts WHERE id = $1";
    pub const CONTROLS: &str =
        "SELECT id, seq, control FROM broadcast_controls WHERE broadcast_id = $1 ORDER BY seq, id";
}

/// The same SQL for SQLite (`?n` placeholders).
pub(crate) mod lite {
    pub const INSERT: &str = "INSERT INTO broadcasts (id, definition, created_at, active_at) VALUES (?1, ?2, ?3, ?4)";
    pub const INSERT_CONTROL: &str = "INSERT INTO broadcast_controls (id, broadcast_id, seq, control) SELECT ?1, ?2, ?3, ?4 \
         WHERE EXISTS (SELECT 1 FROM broadcasts WHERE id = ?2)";
    pub const TOUCH: &str = "UPDATE broadcasts SET active_at = ?2 WHERE id = ?1 AND active_at < ?2";
    pub const DELETE: &str = "DELETE FROM broadcasts WHERE id = ?1";
    pub const EXPIRE: &str = "DELETE FROM broadcasts WHERE id = ?1 AND active_at < ?2";
    pub const ALL: &str = "SELECT id, definition, created_at FROM broadcasts ORDER BY id";
    pub const ONE: &str = "SELECT id, definition, created_at FROM broadcasts WHERE id = ?1";
    pub const CONTROLS: &str =
        "SELECT id, seq, control FROM broadcast_controls WHERE broadcast_id = ?1 ORDER BY seq, id";
}

/// A `broadcasts` row (without its controls).
pub(crate) fn broadcast_from_row<'r, R>(row: &'r R) -> Result<StoredBroadcast, sqlx::Error>
where
    R: sqlx::Row,
    &'static str: sqlx::ColumnIndex<R>,
    String: sqlx::Decode<'r, R::Database> + sqlx::Type<R::Database>,
    i64: sqlx::Decode<'r, R::Database> + sqlx::Type<R::Database>,
{
    Ok(StoredBroadcast {
        id: row.try_get("id")?,
        definition: row.try_get("definition")?,
        created_at: row.try_get("created_at")?,
        controls: Vec::new(),
    })
}

/// A `broadcast_controls` row.
pub(crate) fn control_from_row<'r, R>(row: &'r R) -> Result<StoredControl, sqlx::Error>
where
    R: sqlx::Row,
    &'static str: sqlx::ColumnIndex<R>,
    String: sqlx::Decode<'r, R::Database> + sqlx::Type<R::Database>,
    i64: sqlx::Decode<'r, R::Database> + sqlx::Type<R::Database>,
{
    Ok(StoredControl {
        id: row.try_get("id")?,
        seq: row.try_get::<i64, _>("seq")?.max(0) as u64,
        control: row.try_get("control")?,
    })
}
