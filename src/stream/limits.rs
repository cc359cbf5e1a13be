//! Admission: a cap on concurrent streams, global and per client address,
//! so one client (or a crowd) cannot hold every stream the server can serve.
//!
//! A [`StreamPermit`] is taken before a stream starts and released when it
//! is dropped, whatever ended the stream. The counts sit behind a std mutex:
//! they are touched once per stream start and end, never across an await.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex};

use tokio::sync::Notify;

/// Why a stream was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AdmitError {
    #[error("the server is at its limit of {limit} concurrent streams; try again later")]
    Global { limit: usize },
    #[error("this client address already has {limit} concurrent streams (the per-client limit)")]
    PerClient { limit: usize },
    #[error("the server is shutting down")]
    ShuttingDown,
}

#[derive(Debug, Default)]
struct Counts {
    total: usize,
    per_client: HashMap<IpAddr, usize>,
    closed: bool,
}

#[derive(Debug)]
pub(crate) struct Limits {
    max_total: usize,
    max_per_client: usize,
    counts: Mutex<Counts>,
    idle: Notify,
}

/// One admitted stream; dropping it frees the slot.
#[derive(Debug)]
pub struct StreamPermit {
    limits: Arc<Limits>,
    client: Option<IpAddr>,
}

impl Limits {
    pub(crate) fn new(max_total: usize, max_per_client: usize) -> Self {
        Limits { max_total, max_per_client, counts: Mutex::default(), idle: Notify::new() }
    }

    pub(crate) fn admit(self: &Arc<Self>, client: Option<IpAddr>) -> Result<StreamPermit, AdmitError> {
        let mut c = self.counts.lock().expect("limits lock poisoned");
        if c.closed {
            return Err(AdmitError::ShuttingDown);
        }
        if c.total >= self.max_total {
            return Err(AdmitError::Global { limit: self.max_total });
        }
        if let Some(ip) = client {
            let n = c.per_client.entry(ip).or_default();
            if *n >= self.max_per_client {
                return Err(AdmitError::PerClient { limit: self.max_per_client });
            }
            *n += 1;
        }
        c.total += 1;
        metrics::gauge!("inbetween_streams_active").set(c.total as f64);
        Ok(StreamPermit { limits: Arc::clone(self), client })
    }

    /// Refuses new streams from now on.
    pub(crate) fn close(&self) {
        self.counts.lock().expect("limits lock poisoned").closed = true;
    }

    pub(crate) fn active(&self) -> usize {
        self.counts.lock().expect("limits lock poisoned").total
    }

    /// Resolves once no stream holds a permit.
    pub(crate) async fn idle(&self) {
        loop {
            let notified = self.idle.notified();
            if self.active() == 0 {
                return;
            }
            notified.await;
        }
    }
}

impl Drop for StreamPermit {
    fn drop(&mut self) {
        let mut c = self.limits.counts.lock().expect("limits lock poisoned");
        c.total -= 1;
        if let Some(ip) = self.client
            && let Some(n) = c.per_client.get_mut(&ip)
        {
            *n -= 1;
            if *n == 0 {
                c.per_client.remove(&ip);
            }
        }
        metrics::gauge!("inbetween_streams_active").set(c.total as f64);
        let idle = c.total == 0;
        drop(c);
        if idle {
            self.limits.idle.notify_waiters();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn caps_apply_globally_and_per_client_and_permits_free_their_slot() {
        let limits = Arc::new(Limits::new(3, 2));
        let (a, b): (IpAddr, IpAddr) = ("10.0.0.1".parse().unwrap(), "10.0.0.2".parse().unwrap());
        let p1 = limits.admit(Some(a)).unwrap();
        let _p2 = limits.admit(Some(a)).unwrap();
        assert_eq!(limits.admit(Some(a)).unwrap_err(), AdmitError::PerClient { limit: 2 });
        let _p3 = limits.admit(Some(b)).unwrap();
        assert_eq!(limits.admit(Some(b)).unwrap_err(), AdmitError::Global { limit: 3 });
        drop(p1);
        let _p4 = limits.admit(Some(a)).unwrap();
        assert_eq!(limits.active(), 3);
        limits.close();
        assert_eq!(limits.admit(None).unwrap_err(), AdmitError::ShuttingDown);
    }
}
