//! Cross-node cache consistency: each node subscribes to its store's
//! [`ChangeFeed`] (PostgreSQL: the channel its schema's trigger announces
//! clip changes on, `migrations/postgres`), and drops what another node
//! changed from its cache of compiled clips. No broker beyond the database.
//!
//! The payload is `<op> <version> <id>`. Handling is idempotent, so a node
//! hears its own writes too and ignores them: a `create` or `replace` at a
//! version the cache already holds (the write-through of a local write)
//! changes nothing; anything newer, and every `delete`, invalidates the id,
//! which also bumps the cache's epoch so a load that was reading the old row
//! cannot put it back.
//!
//! Notifications are not queued for a disconnected listener: whatever is
//! announced while the connection is down is lost. So the cache is
//! *suspended* (empty, every request reads the store) from the moment the
//! connection is known lost (or before the first subscription) until
//! `LISTEN` is in place again, and resuming empties it once more: whatever
//! it then holds was read after the node could hear changes. A silently
//! dead connection (no reset, no error) is caught by a heartbeat: every node
//! sends a `ping` on the channel every [`HEARTBEAT`], and a listener that has
//! heard nothing for [`SILENCE_LIMIT`] treats its connection as lost.
//!
//! Graphs and characters are announced alike
//! (`migrations/postgres/0007_graphs.sql`); their ids are UUIDs like clips',
//! so each change is handed to every cache, and the one holding the id at
//! an older version lets it go (`AppState::document_heard`).
//!
//! Streams are not touched: each holds the compiled clip it started on
//! (`Arc<CachedClip>`) until it ends, exactly as after a local replace.
//!
//! Broadcasts (docs/broadcasts.md) are announced on the same channel
//! (`migrations/postgres/0004_broadcasts.sql`): `broadcast 0 <id>` (created),
//! `control 0 <id>` (a control stored), `unbroadcast 0 <id>` (deleted). They
//! are handed to `broadcast_store`, which reads the rows back; and since a
//! lost connection loses announcements too, every (re)subscription starts a
//! `broadcast_store::resync`.

use std::sync::Arc;
use std::time::Duration;

use tokio::time::Instant;

use super::broadcast_store::{self, Heard};
use super::state::AppState;
use crate::store::feed::{ChangeFeed, Subscription};

/// How often each node proves the channel alive.
pub const HEARTBEAT: Duration = Duration::from_secs(2);
/// Silence after which the listener's connection is presumed dead.
pub const SILENCE_LIMIT: Duration = Duration::from_secs(7);
/// The longest wait between reconnection attempts.
const MAX_RECONNECT_WAIT: Duration = Duration::from_secs(2);

/// One announced change.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Change<'a> {
    Written {
        id: &'a str,
        version: u64,
    },
    Deleted {
        id: &'a str,
    },
    /// A broadcast created or given a control (docs/broadcasts.md).
    Broadcast {
        id: &'a str,
    },
    BroadcastDeleted {
        id: &'a str,
    },
    Ping,
}

/// Parses a payload; `None` for anything malformed (ignored, and logged).
pub fn parse(payload: &str) -> Option<Change<'_>> {
    let mut parts = payload.splitn(3, ' ');
    let (op, version, id) = (parts.next()?, parts.next()?, parts.next()?);
    let version: u64 = version.parse().ok()?;
    match op {
        "create" | "replace" => Some(Change::Written { id, version }),
        "delete" => Some(Change::Deleted { id }),
        "broadcast" | "control" => Some(Change::Broadcast { id }),
        "unbroadcast" => Some(Change::BroadcastDeleted { id }),
        "ping" => Some(Change::Ping),
        _ => None,
    }
}

/// Applies one change to this node's cache (idempotent).
pub fn apply(state: &AppState, change: &Change<'_>) {
    tracing::debug!(?change, "clip change heard");
    match *change {
        Change::Written { id, version } => {
            state.document_heard(id, Some(version));
            if state.cache.version_of(id).is_some_and(|cached| cached >= version) {
                return;
            }
            state.cache_invalidate(id);
        }
        Change::Deleted { id } => {
            state.document_heard(id, None);
            state.cache_invalidate(id);
        }
        Change::Broadcast { id } => return broadcast_store::heard(state, Heard::Changed(id.to_owned())),
        Change::BroadcastDeleted { id } => return broadcast_store::heard(state, Heard::Deleted(id.to_owned())),
        Change::Ping => return,
    }
    metrics::counter!("inbetween_cache_remote_invalidations_total").increment(1);
}

/// Listens until aborted: subscribe, resume the cache, apply changes; on a
/// lost connection suspend the cache and subscribe again, with backoff.
/// Runs beside the server (spawned by `Application::run_until_stopped`).
pub async fn run(feed: Arc<dyn ChangeFeed>, state: AppState) {
    let heartbeat = tokio::spawn(heartbeat(Arc::clone(&feed)));
    let _stop_heartbeat = AbortOnDrop(heartbeat);
    let mut failures = 0u32;
    loop {
        state.cache_suspend();
        metrics::gauge!("inbetween_notify_subscribed").set(0.0);
        match feed.subscribe().await {
            Ok(subscription) => {
                failures = 0;
                state.cache_resume();
                metrics::gauge!("inbetween_notify_subscribed").set(1.0);
                tracing::info!(channel = feed.name(), "listening for clip changes");
                // Whatever was announced while this node could not hear.
                tokio::spawn({
                    let state = state.clone();
                    async move { broadcast_store::resync(&state).await }
                });
                listen(subscription, &state).await;
                tracing::warn!("lost the clip-change subscription: serving from the store until it is back");
            }
            Err(e) => {
                let wait = store_backoff(failures);
                failures = failures.saturating_add(1);
                tracing::warn!(error = %e, ?wait, "cannot subscribe to clip changes: retrying");
                tokio::time::sleep(wait).await;
            }
        }
    }
}

/// Applies notifications until the connection fails or falls silent.
async fn listen(mut subscription: Box<dyn Subscription>, state: &AppState) {
    let mut deadline = Instant::now() + SILENCE_LIMIT;
    loop {
        tokio::select! {
            received = subscription.next() => match received {
                Ok(Some(payload)) => {
                    deadline = Instant::now() + SILENCE_LIMIT;
                    match parse(&payload) {
                        Some(change) => apply(state, &change),
                        None => tracing::warn!(payload = payload.as_str(), "ignoring a malformed clip-change notification"),
                    }
                }
                Ok(None) => return,
                Err(e) => {
                    tracing::warn!(error = %e, "clip-change listener failed");
                    return;
                }
            },
            // The subscription is dropped after this, never polled again, so
            // cancelling its receive midway is harmless.
            () = tokio::time::sleep_until(deadline) => {
                tracing::warn!(silence = ?SILENCE_LIMIT, "no clip-change notification or heartbeat heard");
                return;
            }
        }
    }
}

/// Sends a `ping` on the feed every [`HEARTBEAT`], so listeners can tell
/// a quiet feed from a dead connection.
async fn heartbeat(feed: Arc<dyn ChangeFeed>) {
    let mut every = tokio::time::interval(HEARTBEAT);
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        every.tick().await;
        if let Err(e) = feed.ping().await {
            tracing::debug!(error = %e, "heartbeat not sent");
        }
    }
}

fn store_backoff(failures: u32) -> Duration {
    (Duration::from_millis(100) * 2u32.saturating_pow(failures.min(8))).min(MAX_RECONNECT_WAIT)
}

struct AbortOnDrop(tokio::task::JoinHandle<()>);

impl Drop for AbortOnDrop {
    fn drop(&mut self) {
        self.0.abort();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn payloads_parse_and_junk_is_refused() {
        let id = "0190a1b2-c3d4-7e5f-8a9b-0c1d2e3f4a5b";
        assert_eq!(parse(&format!("replace 7 {id}")), Some(Change::Written { id, version: 7 }));
        assert_eq!(parse(&format!("create 1 {id}")), Some(Change::Written { id, version: 1 }));
        assert_eq!(parse(&format!("delete 3 {id}")), Some(Change::Deleted { id }));
        assert_eq!(parse("ping 0 -"), Some(Change::Ping));
        assert_eq!(parse(&format!("broadcast 0 {id}")), Some(Change::Broadcast { id }));
        assert_eq!(parse(&format!("control 0 {id}")), Some(Change::Broadcast { id }));
        assert_eq!(parse(&format!("unbroadcast 0 {id}")), Some(Change::BroadcastDeleted { id }));
        for junk in ["", "replace", "replace x id", "drop 1 id", "replace 1"] {
            assert_eq!(parse(junk), None, "{junk:?}");
        }
    }
}
