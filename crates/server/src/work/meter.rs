//! The node's capacity and each caller's share of it (docs/api.md, “Work
//! and its price”). Work being done holds a [`Ticket`] for its price: a
//! request its whole price while it runs (as if it were done within a
//! second: a node that falls behind holds more and admits less), a stream
//! its price per second of playback while it is open. A charge that would
//! take a caller over its share is refused 429 `caller_work_limit`; one that
//! would take the node over its capacity 503 `overloaded`. A caller, or the
//! node, holding nothing may always take one charge (each is within
//! `max_request_work`), so a price over a small node's share still runs,
//! alone.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use crate::auth::CallerKey;
use crate::error::ApiError;
use crate::sync::lock;

/// Seconds a refused caller is told to wait.
const RETRY_AFTER_SECS: u64 = 1;

#[derive(Debug, Default)]
struct Held {
    total: u64,
    callers: HashMap<CallerKey, u64>,
}

/// Work units per second the node can do, what one caller may hold, and
/// what is held now.
#[derive(Debug)]
pub struct Meter {
    capacity: u64,
    share: u64,
    held: Mutex<Held>,
}

/// Units charged to a caller until dropped.
#[derive(Debug)]
pub struct Ticket {
    meter: Arc<Meter>,
    caller: CallerKey,
    units: u64,
}

impl Ticket {
    pub fn units(&self) -> u64 {
        self.units
    }

    /// Holds `units` from now on instead (a stream whose control changed
    /// its price): more is charged as a new charge would be, except that
    /// what this ticket held already counts as its caller's and the node's.
    ///
    /// # Errors
    /// As [`Meter::charge`], and the ticket holds what it held.
    pub fn change(&mut self, units: u64) -> Result<(), ApiError> {
        let meter = Arc::clone(&self.meter);
        let mut held = lock(&meter.held);
        let mine = held.callers.get(&self.caller).copied().unwrap_or(0);
        if units > self.units {
            let more = units - self.units;
            if mine > self.units && mine.saturating_add(more) > meter.share {
                metrics::counter!("inbetween_work_refused_total", "reason" => "caller").increment(1);
                let (share, retry_after) = (meter.share, RETRY_AFTER_SECS);
                return Err(ApiError::CallerWorkLimit { held: mine, units: more, share, retry_after });
            }
            if held.total > self.units && held.total.saturating_add(more) > meter.capacity {
                metrics::counter!("inbetween_work_refused_total", "reason" => "node").increment(1);
                return Err(ApiError::WorkOverloaded { retry_after: RETRY_AFTER_SECS });
            }
        }
        held.total = held.total.saturating_sub(self.units).saturating_add(units);
        held.callers.insert(self.caller.clone(), mine.saturating_sub(self.units).saturating_add(units));
        self.units = units;
        Ok(())
    }
}

impl Meter {
    /// A node of `capacity` units per second whose callers may each hold
    /// `share` of it.
    pub fn new(capacity: u64, share: f64) -> Arc<Meter> {
        let share = ((capacity as f64) * share).ceil() as u64;
        Arc::new(Meter { capacity: capacity.max(1), share: share.max(1), held: Mutex::default() })
    }

    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    /// Units held now, by every caller together.
    pub fn held(&self) -> u64 {
        lock(&self.held).total
    }

    /// Charges `units` to `caller` until the ticket is dropped.
    ///
    /// # Errors
    /// `caller_work_limit` (429) over the caller's share; `overloaded` (503)
    /// over the node's capacity. Both with `Retry-After`.
    pub fn charge(self: &Arc<Self>, caller: &CallerKey, units: u64) -> Result<Ticket, ApiError> {
        let mut held = lock(&self.held);
        let mine = held.callers.get(caller).copied().unwrap_or(0);
        if mine > 0 && mine.saturating_add(units) > self.share {
            metrics::counter!("inbetween_work_refused_total", "reason" => "caller").increment(1);
            let (share, retry_after) = (self.share, RETRY_AFTER_SECS);
            return Err(ApiError::CallerWorkLimit { held: mine, units, share, retry_after });
        }
        if held.total > 0 && held.total.saturating_add(units) > self.capacity {
            metrics::counter!("inbetween_work_refused_total", "reason" => "node").increment(1);
            return Err(ApiError::WorkOverloaded { retry_after: RETRY_AFTER_SECS });
        }
        held.total = held.total.saturating_add(units);
        *held.callers.entry(caller.clone()).or_insert(0) += units;
        Ok(Ticket { meter: Arc::clone(self), caller: caller.clone(), units })
    }
}

impl Drop for Ticket {
    fn drop(&mut self) {
        let mut held = lock(&self.meter.held);
        held.total = held.total.saturating_sub(self.units);
        if let Some(mine) = held.callers.get_mut(&self.caller) {
            *mine = mine.saturating_sub(self.units);
            if *mine == 0 {
                held.callers.remove(&self.caller);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(n: u8) -> CallerKey {
        CallerKey::Addr(std::net::IpAddr::from([10, 0, 0, n]))
    }

    #[test]
    fn a_caller_over_its_share_is_429_and_the_node_over_capacity_503() {
        let meter = Meter::new(1000, 0.5);
        let a = meter.charge(&key(1), 400).unwrap();
        assert_eq!(meter.charge(&key(1), 101).unwrap_err().code(), "caller_work_limit");
        let b = meter.charge(&key(2), 500).unwrap();
        assert_eq!(meter.charge(&key(3), 101).unwrap_err().code(), "overloaded");
        let c = meter.charge(&key(3), 100).unwrap();
        assert_eq!(meter.held(), 1000);
        drop((a, b, c));
        assert_eq!(meter.held(), 0, "every ticket gave its units back");
        assert!(lock(&meter.held).callers.is_empty());
    }

    #[test]
    fn a_ticket_changed_is_charged_for_what_it_adds() {
        let meter = Meter::new(1000, 0.5);
        let mut stream = meter.charge(&key(1), 100).unwrap();
        stream.change(5000).unwrap();
        assert_eq!(meter.held(), 5000, "alone, a caller's one charge may grow past its share");
        stream.change(100).unwrap();
        let other = meter.charge(&key(1), 300).unwrap();
        assert_eq!(stream.change(201).unwrap_err().code(), "caller_work_limit", "300 + 201 > 500");
        assert_eq!((stream.units(), meter.held()), (100, 400), "a refused change holds what it held");
        stream.change(200).unwrap();
        let b = meter.charge(&key(2), 500).unwrap();
        assert_eq!(stream.change(201).unwrap_err().code(), "caller_work_limit");
        drop(other);
        // Alone on its caller now, so only the node's capacity holds it.
        assert_eq!(stream.change(601).unwrap_err().code(), "overloaded", "601 + 500 > 1000");
        stream.change(300).unwrap();
        assert_eq!(meter.held(), 800);
        drop((stream, b));
        assert_eq!(meter.held(), 0);
        assert!(lock(&meter.held).callers.is_empty());
    }

    #[test]
    fn an_idle_caller_on_an_idle_node_may_take_one_charge_over_its_share() {
        let meter = Meter::new(1000, 0.5);
        let big = meter.charge(&key(1), 5000).unwrap();
        assert_eq!(meter.charge(&key(2), 1).unwrap_err().code(), "overloaded");
        drop(big);
        assert!(meter.charge(&key(2), 1).is_ok());
    }
}
