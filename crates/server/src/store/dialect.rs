//! Where the two backends differ, and nothing else: the statements
//! themselves are shared (`store::sql`).

use std::fmt::Debug;

use futures_util::future::BoxFuture;
use sqlx::{Database, Encode, Type};

use super::Durability;
use super::retry::Transience;

/// Where the backends' SQL and error handling differ.
pub trait Dialect: Database {
    /// What an open store of this backend keeps beside its pool.
    type Extra: Clone + Debug + Send + Sync + 'static;
    /// How a list of strings is bound for [`Dialect::INSERT_TAGS`].
    type StringList: for<'q> Encode<'q, Self> + Type<Self> + Send;

    /// Opens a write transaction.
    const BEGIN_WRITE: &'static str;
    /// `$1` a clip id, `$2` its tags ([`Dialect::string_list`]): one `clip_tags` row per distinct tag.
    const INSERT_TAGS: &'static str;
    /// As [`Dialect::INSERT_TAGS`], for `clip_joints`.
    const INSERT_JOINTS: &'static str;
    /// The name column compared bytewise (code-point order), as the index
    /// the list's prefix range uses sorts it.
    const BYTEWISE_NAME: &'static str;
    /// `$1` a broadcast id, `$2` a tick, `$3` control ids ([`Dialect::string_list`]):
    /// deletes its controls stamped at or before `$2` except those.
    const FORGET_CONTROLS: &'static str;
    /// `f(haystack, needle)`: the 1-based position of a substring, 0 if absent.
    const POSITION_FN: &'static str;
    /// `$1` a clip name: held until the transaction ends, so two writes of
    /// one name check and write it one after the other. `None` when
    /// [`Dialect::BEGIN_WRITE`] already serialises every writer.
    const LOCK_NAME: Option<&'static str>;

    fn string_list(items: &[String]) -> Self::StringList;

    /// Whether a failure is worth a retry, and whether the statement may have run.
    fn classify(e: &sqlx::Error) -> Transience;

    /// Whether `e` is the primary-key conflict of clips, characters or graphs (ids a write chose).
    fn is_clip_id_conflict(e: &sqlx::Error) -> bool;

    fn rows_affected(done: &Self::QueryResult) -> u64;

    /// Refuses a connection whose commits would not be on disk when they
    /// return, unless `durability` accepts that (then it only warns).
    fn check_durability(conn: &mut Self::Connection, durability: Durability) -> BoxFuture<'_, Result<(), sqlx::Error>>;
}
