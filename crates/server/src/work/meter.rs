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

    /// A further charge of `units` to this ticket's caller on its meter,
    /// held until the new ticket drops (work a stream's control asks for
    /// once: choosing a new compact layout).
    ///
    /// # Errors
    /// As [`Meter::charge`].
    pub fn also(&self, units: u64) -> Result<Ticket, ApiError> {
        self.meter.charge(&self.caller, units)
    }

    /// Holds `units` from now on instead (a broadcast re-priced by a
    /// control): a rise is checked like a new charge of the difference,
    /// a fall always succeeds.
    ///
    /// # Errors
    /// As [`Meter::charge`]; the ticket then holds what it held.
    pub fn resize(&mut self, units: u64) -> Result<(), ApiError> {
        let meter = Arc::clone(&self.meter);
        let mut held = lock(&meter.held);
        if units > self.units {
            let more = units - self.units;
            let mine = held.callers.get(&self.caller).copied().unwrap_or(0);
            let others = mine.saturating_sub(self.units);
            meter.admits(&held, others, mine, more)?;
        }
        held.total = held.total.saturating_sub(self.units).saturating_add(units);
        let mine = held.callers.entry(self.caller.clone()).or_insert(0);
        *mine = mine.saturating_sub(self.units).saturating_add(units);
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
        self.admits(&held, mine, mine, units)?;
        Ok(self.take(&mut held, caller, units))
    }

    /// Charges `units` to `caller` whatever is held: work admitted
    /// elsewhere (a broadcast another node created) that runs here anyway,
    /// counted so that what is admitted next sees it.
    pub fn hold(self: &Arc<Self>, caller: &CallerKey, units: u64) -> Ticket {
        let mut held = lock(&self.held);
        self.take(&mut held, caller, units)
    }

    /// Whether `more` units fit: the caller holding `mine` (`before` of
    /// them besides the charge being raised), the node `held.total`.
    fn admits(&self, held: &Held, before: u64, mine: u64, more: u64) -> Result<(), ApiError> {
        if before > 0 && mine.saturating_add(more) > self.share {
            metrics::counter!("inbetween_work_refused_total", "reason" => "caller").increment(1);
            let (share, retry_after) = (self.share, RETRY_AFTER_SECS);
            return Err(ApiError::CallerWorkLimit { held: mine, units: more, share, retry_after });
        }
        let others = held.total.saturating_sub(mine.saturating_sub(before));
        if others > 0 && held.total.saturating_add(more) > self.capacity {
            metrics::counter!("inbetween_work_refused_total", "reason" => "node").increment(1);
            return Err(ApiError::WorkOverloaded { retry_after: RETRY_AFTER_SECS });
        }
        Ok(())
    }

    fn take(self: &Arc<Self>, held: &mut Held, caller: &CallerKey, units: u64) -> Ticket {
        held.total = held.total.saturating_add(units);
        *held.callers.entry(caller.clone()).or_insert(0) += units;
        Ticket { meter: Arc::clone(self), caller: caller.clone(), units }
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
    fn a_ticket_resized_up_is_checked_like_a_charge_and_down_always_succeeds() {
        let meter = Meter::new(1000, 0.5);
        let mut a = meter.charge(&key(1), 300).unwrap();
        let other = meter.charge(&key(1), 100).unwrap();
        assert_eq!(a.resize(401).unwrap_err().code(), "caller_work_limit", "400 + 101 over the share of 500");
        assert_eq!((a.units(), meter.held()), (300, 400), "a refused resize holds what it held");
        a.resize(400).unwrap();
        let b = meter.charge(&key(2), 500).unwrap();
        drop(other);
        assert_eq!(a.resize(501).unwrap_err().code(), "overloaded", "900 + 101 over the node's 1000");
        a.resize(10).unwrap();
        assert_eq!(meter.held(), 510);
        // Alone on the meter, a ticket may grow past the share (as one charge may).
        drop(b);
        a.resize(5000).unwrap();
        let held = meter.hold(&key(3), 7);
        assert_eq!(meter.held(), 5007, "held whatever the node holds");
        drop((a, held));
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
