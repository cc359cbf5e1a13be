//! What a broadcast and its controllers may spend (docs/broadcasts.md,
//! "Work" and "Control"): a broadcast's price per second charged to its
//! creator at create, in the node's meter and the producers' thread's
//! (`work`), for as long as it lives; and the write budget of REST
//! (`ratelimit`) drawn on by every control a socket or gRPC `Play` sends.

use std::sync::Arc;

use crate::auth::{Caller, CallerKey};
use crate::error::ApiError;
use crate::state::AppState;
use futures_util::future::BoxFuture;

use crate::stream::{BroadcastCharge, BroadcastSpec, ControlError, ControlGate, Held, LayoutWork};

/// Whom the broadcasts this node runs for another node (or for itself
/// before a restart) are charged to: they were admitted where they were
/// created, and run here whatever this node holds.
const ADOPTED: &str = "broadcasts created elsewhere";

/// Charges a new broadcast of `spec` to its creator `caller`.
///
/// # Errors
/// `caller_work_limit` (429) over the caller's share of the node;
/// `overloaded` (503) over the node's capacity or the producers' thread's.
pub fn charge(state: &AppState, spec: &BroadcastSpec, caller: &CallerKey) -> Result<BroadcastCharge, ApiError> {
    let per_sec = spec.work_per_sec;
    let tickets = state.work.broadcast_meters().map(|meter| meter.charge(caller, per_sec));
    let [node, producers] = tickets;
    Ok(priced(state, spec, vec![node?, producers?]))
}

/// Charges a broadcast created elsewhere, which runs here anyway.
pub fn hold(state: &AppState, spec: &BroadcastSpec) -> BroadcastCharge {
    let adopted = CallerKey::Token(Arc::from(ADOPTED));
    let tickets = state.work.broadcast_meters().map(|meter| meter.hold(&adopted, spec.work_per_sec));
    priced(state, spec, tickets.into())
}

fn priced(state: &AppState, spec: &BroadcastSpec, tickets: Vec<crate::work::Ticket>) -> BroadcastCharge {
    BroadcastCharge {
        per_tick: spec.work_per_sec / u64::from(spec.params.fps.max(1)),
        limit_per_sec: state.config.limits.max_request_work,
        ns_per_unit: state.work.ns_per_unit(),
        tickets,
    }
}

/// A controlling viewer's gate: each control takes one write of `caller`'s
/// budget, as a REST control does.
pub fn gate(state: &AppState, caller: Caller) -> ControlGate {
    let writes = Arc::clone(&state.writes);
    Arc::new(move || writes.admit(&caller).map_err(|e| e.to_control()))
}

/// Whom broadcasts' new compact layouts are charged to: they serve every
/// compact viewer of the broadcast, on every node, whoever sent the control.
const LAYOUTS: &str = "broadcasts' compact layouts";

/// Broadcasts' new compact layouts (docs/compact-frames.md, "A broadcast's
/// layouts"), priced in the node's meter and chosen on its work pool.
pub struct PooledLayouts {
    pub work: Arc<crate::work::Work>,
}

impl LayoutWork for PooledLayouts {
    fn charge(&self, units: u64) -> Result<Held, ControlError> {
        let caller = CallerKey::Token(Arc::from(LAYOUTS));
        let ticket = self.work.charge(&caller, units).map_err(|e| {
            let detail = format!("choosing this broadcast's new compact layouts costs {units} work units: {e}");
            ApiError::Relayed { status: e.status().as_u16(), code: e.code(), detail }.to_control()
        })?;
        Ok(Box::new(ticket))
    }

    fn hold(&self, units: u64) -> Held {
        Box::new(self.work.broadcast_meters()[0].hold(&CallerKey::Token(Arc::from(LAYOUTS)), units))
    }

    fn run(&self, held: Held, job: Box<dyn FnOnce() + Send>) -> BoxFuture<'static, bool> {
        let work = Arc::clone(&self.work);
        let ticket = work.broadcast_meters()[0].hold(&CallerKey::Token(Arc::from(LAYOUTS)), 0);
        Box::pin(async move {
            let ran = work
                .run(ticket, move |_| {
                    let _held = held;
                    job();
                })
                .await;
            if let Err(e) = &ran {
                tracing::warn!(error = %e, "choosing a broadcast's compact layouts failed");
            }
            ran.is_ok()
        })
    }
}
