//! How a node hears what other nodes committed, so its cache of compiled
//! clips stays in step (`server::notify` drives it). PostgreSQL announces
//! changes with `LISTEN`/`NOTIFY` ([`super::postgres::PgChangeFeed`]); a
//! store used by one node alone (SQLite) has no feed.
//!
//! A payload is `<op> <version> <id>` (`migrations/postgres/0001_clips.sql`
//! and `0004_broadcasts.sql` write them). A feed queues nothing for a
//! subscriber that is not connected: what is announced meanwhile is lost,
//! which is why `server::notify` suspends its cache between subscriptions.

use futures_util::future::BoxFuture;

/// A feed's failure, for the logs.
pub type FeedError = Box<dyn std::error::Error + Send + Sync>;

/// Announcements of committed changes, shared by every node of one store.
pub trait ChangeFeed: Send + Sync + 'static {
    /// What the logs call this feed (PostgreSQL: the channel).
    fn name(&self) -> &str;

    /// A fresh subscription of its own (not a pooled connection).
    fn subscribe(&self) -> BoxFuture<'_, Result<Box<dyn Subscription>, FeedError>>;

    /// Announces `ping 0 -`, so subscribers can tell a quiet feed from a dead connection.
    fn ping(&self) -> BoxFuture<'_, Result<(), FeedError>>;
}

/// One live subscription to a [`ChangeFeed`].
pub trait Subscription: Send {
    /// The next payload; `Ok(None)` when the connection has closed. Dropping
    /// the future midway is harmless only if the subscription is dropped too.
    fn next(&mut self) -> BoxFuture<'_, Result<Option<String>, FeedError>>;
}
