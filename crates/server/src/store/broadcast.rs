//! The stored form of broadcasts (docs/broadcasts.md, `migrations/*/0004_broadcasts.sql`,
//! `migrations/*/0005_broadcast_checkpoints.sql`): a definition row, one row
//! per stamped control, and the newest checkpoint. The store keeps the
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

/// The controls a checkpoint's state has applied, as the node that wrote
/// it knows them: every control it heard stamped from `from` on, up to the
/// checkpoint's tick, as (id, seq).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Covers {
    pub from: u64,
    pub controls: Vec<(String, u64)>,
}

/// A broadcast's checkpoint as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredCheckpoint {
    /// The last tick it has stepped.
    pub seq: u64,
    /// The state as the server reads it again (opaque here).
    pub state: String,
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
