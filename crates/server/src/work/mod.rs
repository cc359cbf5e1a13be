//! Work has a price (docs/api.md, “Work and its price”): every request and
//! stream is priced in work units before it runs (`price`), charged to its
//! caller against the node's capacity (`meter`) and run on a pool of threads
//! bounded by the cores, with a cancel flag its caller's leaving or its
//! deadline raises (`pool`).
//!
//! The node's capacity is configured (`node_work_per_sec`) or measured once
//! at startup: a fixed sampling job timed a few times, the fastest kept (a
//! busy machine only makes it slower), logged.

mod meter;
mod pool;
pub mod price;
#[cfg(test)]
mod tests;

use std::sync::Arc;
use std::time::{Duration, Instant};

pub use self::meter::{Meter, Ticket};
pub use self::pool::{Cancel, Pool};
use crate::auth::CallerKey;
use crate::config::Limits;
use crate::error::ApiError;

/// Work priced at most this runs on the task that asks for it: about
/// 40 µs, what handing it to a work thread and back costs anyway, and short
/// enough never to hold up an async worker noticeably.
pub const INLINE_UNITS: u64 = 4096;

/// The pool, the meter and the deadline every job shares.
pub struct Work {
    pool: Pool,
    meter: Arc<Meter>,
    /// The producers' thread's capacity, which broadcasts are charged to
    /// besides the node's meter.
    producers: Arc<Meter>,
    ns_per_unit: f64,
    deadline: Duration,
}

impl std::fmt::Debug for Work {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Work")
            .field("threads", &self.pool.threads())
            .field("capacity", &self.meter.capacity())
            .finish_non_exhaustive()
    }
}

impl Work {
    /// The node's work, as `limits` configure it (measuring its capacity
    /// if `node_work_per_sec` is 0).
    pub fn new(limits: &Limits) -> Work {
        let threads = limits.work_threads;
        let (capacity, ns_per_unit) = match limits.node_work_per_sec {
            0 => {
                let ns = measure_ns_per_unit();
                let capacity = (threads as f64 * 1e9 / ns) as u64;
                tracing::info!(ns_per_unit = ns, threads, capacity, "measured the node's work capacity (units/s)");
                (capacity, ns)
            }
            configured => (configured, threads.max(1) as f64 * 1e9 / configured.max(1) as f64),
        };
        let meter = Meter::new(capacity, limits.caller_work_share);
        let one_core = capacity / threads.max(1) as u64;
        // Broadcasts' ticks all run on the producers' thread (`stream::producer`).
        let producers = Meter::new((one_core as f64 * limits.broadcast_work_share) as u64, 1.0);
        Work { pool: Pool::new(threads), meter, producers, ns_per_unit, deadline: limits.request_timeout }
    }

    /// Charges `units` to `caller` (see `meter`).
    ///
    /// # Errors
    /// `caller_work_limit` (429), `overloaded` (503).
    pub fn charge(&self, caller: &CallerKey, units: u64) -> Result<Ticket, ApiError> {
        self.meter.charge(caller, units)
    }

    /// Charges `units` to `caller`, then runs `job`: on the pool (as
    /// [`Work::run`]), or here if it is priced under [`INLINE_UNITS`].
    ///
    /// # Errors
    /// As [`Work::charge`], then as [`Work::run`].
    pub async fn spend<T, F>(&self, caller: &CallerKey, units: u64, job: F) -> Result<T, ApiError>
    where
        F: FnOnce(&Cancel) -> T + Send + 'static,
        T: Send + 'static,
    {
        let ticket = self.charge(caller, units)?;
        self.spend_held(ticket, job).await
    }

    /// Runs `job`, already charged for with `ticket`, as [`Work::spend`]
    /// does: on the pool, or here if the ticket holds at most
    /// [`INLINE_UNITS`].
    ///
    /// # Errors
    /// As [`Work::run`].
    pub async fn spend_held<T, F>(&self, ticket: Ticket, job: F) -> Result<T, ApiError>
    where
        F: FnOnce(&Cancel) -> T + Send + 'static,
        T: Send + 'static,
    {
        if ticket.units() <= INLINE_UNITS {
            let out = job(&self.pool.cancel());
            drop(ticket);
            return Ok(out);
        }
        self.run(ticket, job).await
    }

    /// Runs `job` on the pool holding `ticket` until it ends; stopped and
    /// answered 503 at `request_timeout_secs`.
    ///
    /// # Errors
    /// `request_timeout`; `internal` if the job panicked.
    pub async fn run<T, F>(&self, ticket: Ticket, job: F) -> Result<T, ApiError>
    where
        F: FnOnce(&Cancel) -> T + Send + 'static,
        T: Send + 'static,
    {
        self.pool
            .run(self.deadline, move |cancel| {
                let _held = ticket;
                job(cancel)
            })
            .await
    }

    pub fn pool(&self) -> &Pool {
        &self.pool
    }

    pub fn meter(&self) -> &Meter {
        &self.meter
    }

    /// The meters a broadcast is charged to: the node's, and the
    /// producers' thread's (`broadcast_work_share` of one core).
    pub fn broadcast_meters(&self) -> [&Arc<Meter>; 2] {
        [&self.meter, &self.producers]
    }

    /// Nanoseconds of one core a work unit takes on this node (measured
    /// at startup, or what `node_work_per_sec` implies).
    pub fn ns_per_unit(&self) -> f64 {
        self.ns_per_unit
    }
}

/// Joints in the measuring clip, and poses per timed run.
const MEASURE_JOINTS: usize = 64;
const MEASURE_POSES: usize = 64;

/// Nanoseconds per work unit here: the fastest of a few runs of sampling a
/// 64-joint clip (one unit per joint per pose).
fn measure_ns_per_unit() -> f64 {
    use anim::{Channel, ClipSpec, Interpolation, Keys, SampleOptions, Sampler, TrackSpec};
    use glam::{Vec3, Vec4};
    let times: Vec<f32> = (0..30).map(|k| k as f32 / 30.0).collect();
    let tracks = (0..MEASURE_JOINTS)
        .flat_map(|j| {
            let name = format!("j{j}");
            let v3 = Keys::Vec3(times.iter().map(|&t| Vec3::new(t, 1.0 - t, 0.5 * t)).collect());
            let q = Keys::Vec4(times.iter().map(|&t| Vec4::new(0.0, (t * 0.5).sin(), 0.0, (t * 0.5).cos())).collect());
            [
                TrackSpec::new(&name, Channel::Translation, Interpolation::Linear, times.clone(), v3),
                TrackSpec::new(&name, Channel::Rotation, Interpolation::Linear, times.clone(), q),
            ]
        })
        .collect();
    let spec = ClipSpec { name: "measure".into(), tracks, ..Default::default() };
    let Ok(clip) = anim::Clip::build(&spec) else { return price::NS_PER_UNIT as f64 };
    let (mut sampler, options) = (Sampler::new(), SampleOptions::default());
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let started = Instant::now();
        for k in 0..MEASURE_POSES {
            std::hint::black_box(clip.sample(k as f64 * 0.013, &options, &mut sampler));
        }
        best = best.min(started.elapsed().as_nanos() as f64);
    }
    (best / (MEASURE_JOINTS * MEASURE_POSES) as f64).max(0.1)
}
