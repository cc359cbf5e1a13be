//! Admission: a cap on concurrent streams, global, per client address and
//! per token, so one client (or a crowd, or one leaked token used from many
//! addresses) cannot hold every stream the server can serve. The transport
//! says who is asking: the caller's address and, when a configured token
//! identified it, the token's name (the server's `auth::Caller`; the engine
//! knows nothing of how it was found).
//!
//! A [`StreamPermit`] is taken before a stream starts and released when it
//! is dropped, whatever ended the stream. The counts sit behind a std mutex:
//! they are touched once per stream start and end, never across an await.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex};

use tokio::sync::Notify;

use super::control::Repricing;

/// Why a stream was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AdmitError {
    #[error("the server is at its limit of {limit} concurrent streams; try again later")]
    Global { limit: usize },
    #[error("this client address already has {limit} concurrent streams (the per-client limit)")]
    PerClient { limit: usize },
    #[error("this token already has {limit} concurrent streams (the per-token limit)")]
    PerToken { limit: usize },
    #[error("the server is shutting down")]
    ShuttingDown,
}

#[derive(Debug, Default)]
struct Counts {
    total: usize,
    per_client: HashMap<IpAddr, usize>,
    per_token: HashMap<Arc<str>, usize>,
    closed: bool,
}

#[derive(Debug)]
pub(crate) struct Limits {
    max_total: usize,
    max_per_client: usize,
    max_per_token: usize,
    counts: Mutex<Counts>,
    idle: Notify,
}

/// One admitted stream; dropping it frees the slot.
#[derive(Debug)]
pub struct StreamPermit {
    limits: Arc<Limits>,
    client: Option<IpAddr>,
    token: Option<Arc<str>>,
    /// The stream's price per second, charged to its caller while it is
    /// open (`server::work`).
    ticket: Option<crate::work::Ticket>,
    /// The stream's charge, priced again by its controls (it holds the
    /// stream's ticket until the stream ends).
    repricing: Option<Arc<dyn Repricing>>,
}

impl StreamPermit {
    /// This permit, also holding `ticket` until the stream ends.
    pub fn holding(mut self, ticket: crate::work::Ticket) -> StreamPermit {
        self.ticket = Some(ticket);
        self
    }

    /// This permit, also holding `charge` until the stream ends; the
    /// stream's controls are priced by it.
    pub fn priced(mut self, charge: Arc<dyn Repricing>) -> StreamPermit {
        self.repricing = Some(charge);
        self
    }

    /// What prices the stream's controls, if anything does.
    pub(crate) fn repricing(&self) -> Option<Arc<dyn Repricing>> {
        self.repricing.clone()
    }
}

impl Limits {
    pub(crate) fn new(max_total: usize, max_per_client: usize) -> Self {
        Limits {
            max_total,
            max_per_client,
            max_per_token: max_per_client,
            counts: Mutex::default(),
            idle: Notify::new(),
        }
    }

    /// The same limits with a per-token cap of `n`.
    pub(crate) fn per_token(self, n: usize) -> Self {
        Limits { max_per_token: n, ..self }
    }

    pub(crate) fn admit(self: &Arc<Self>, client: Option<IpAddr>) -> Result<StreamPermit, AdmitError> {
        self.admit_for(client, None)
    }

    /// Admits a stream of `client` (its address) identified by `token` (the
    /// name of its token, if one identified it).
    pub(crate) fn admit_for(
        self: &Arc<Self>,
        client: Option<IpAddr>,
        token: Option<Arc<str>>,
    ) -> Result<StreamPermit, AdmitError> {
        let mut c = crate::sync::lock(&self.counts);
        if c.closed {
            return Err(AdmitError::ShuttingDown);
        }
        if c.total >= self.max_total {
            return Err(AdmitError::Global { limit: self.max_total });
        }
        if client.is_some_and(|ip| c.per_client.get(&ip).is_some_and(|n| *n >= self.max_per_client)) {
            return Err(AdmitError::PerClient { limit: self.max_per_client });
        }
        if token.as_ref().is_some_and(|t| c.per_token.get(t).is_some_and(|n| *n >= self.max_per_token)) {
            return Err(AdmitError::PerToken { limit: self.max_per_token });
        }
        if let Some(ip) = client {
            *c.per_client.entry(ip).or_default() += 1;
        }
        if let Some(t) = &token {
            *c.per_token.entry(Arc::clone(t)).or_default() += 1;
        }
        c.total += 1;
        metrics::gauge!("inbetween_streams_active").set(c.total as f64);
        Ok(StreamPermit { limits: Arc::clone(self), client, token, ticket: None, repricing: None })
    }

    /// Refuses new streams from now on.
    pub(crate) fn close(&self) {
        crate::sync::lock(&self.counts).closed = true;
    }

    pub(crate) fn active(&self) -> usize {
        crate::sync::lock(&self.counts).total
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
        let mut c = crate::sync::lock(&self.limits.counts);
        c.total -= 1;
        if let Some(ip) = self.client
            && let Some(n) = c.per_client.get_mut(&ip)
        {
            *n -= 1;
            if *n == 0 {
                c.per_client.remove(&ip);
            }
        }
        if let Some(t) = &self.token
            && let Some(n) = c.per_token.get_mut(t)
        {
            *n -= 1;
            if *n == 0 {
                c.per_token.remove(t);
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

    #[test]
    fn one_token_is_capped_across_addresses_and_other_tokens_are_not() {
        let limits = Arc::new(Limits::new(10, 10).per_token(2));
        let (t, u): (Arc<str>, Arc<str>) = (Arc::from("alpha"), Arc::from("beta"));
        let ips: Vec<IpAddr> = (1..=4).map(|i| format!("10.0.0.{i}").parse().unwrap()).collect();
        let p1 = limits.admit_for(Some(ips[0]), Some(t.clone())).unwrap();
        let _p2 = limits.admit_for(Some(ips[1]), Some(t.clone())).unwrap();
        assert_eq!(limits.admit_for(Some(ips[2]), Some(t.clone())).unwrap_err(), AdmitError::PerToken { limit: 2 });
        // A refusal takes no slot anywhere.
        assert_eq!(limits.active(), 2);
        let _p3 = limits.admit_for(Some(ips[2]), Some(u)).unwrap();
        drop(p1);
        let _p4 = limits.admit_for(Some(ips[3]), Some(t)).unwrap();
        assert_eq!(limits.active(), 3);
    }
}
