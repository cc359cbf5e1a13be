//! A broadcast's work (docs/broadcasts.md, "Work"): its price, charged to
//! its creator for its whole life and raised or lowered by the controls
//! that change what it evaluates, and the CPU its ticks really take,
//! measured against that price so that a broadcast the price misjudged
//! ends alone instead of starving the others on the producers' thread.
//!
//! - [`Budget`]: the price of one tick in work units (`work::price`): every
//!   motion its crossfades may leave the player evaluating (`fade_chain`:
//!   the fades in progress and the motion playing, at the tick and at each
//!   spring substep), the constraints of the latest `ik` control on their
//!   mix, and the rest (the frame's
//!   encoding, the tick itself) as admitted. Its price per second is held
//!   in the node's meters by [`Ticket`]s.
//! - [`Overrun`]: the thread CPU of each tick's stepping and encoding
//!   (waking its viewers' tasks is theirs) against the price of a tick;
//!   a broadcast whose ticks took more than [`OVERRUN_FACTOR`] times their
//!   price (plus [`TICK_ALLOWANCE`]) over a whole second of ticks is over
//!   budget, and ends with `too_much_work`.

use super::control::{Control, ControlError};
use super::fade_chain::FadeChain;
use super::pinned::StreamMotion;
use crate::error::ApiError;
use crate::work::{Ticket, price};
use std::collections::VecDeque;
use std::sync::Arc;

/// How many times its price a broadcast's ticks may take, over a second.
pub const OVERRUN_FACTOR: u64 = 4;

/// Work units a tick may take besides its price: the noise of measuring,
/// a page fault, a cache miss (200 µs at 10 ns a unit; in the units of the
/// node's measured speed, so a slower build allows as much more).
pub const TICK_ALLOWANCE_UNITS: u64 = 20_000;

/// What a broadcast was admitted at, and the tickets that hold it.
#[derive(Debug)]
pub struct BroadcastCharge {
    /// Work units of one tick.
    pub per_tick: u64,
    /// The most a broadcast may cost per second (`max_request_work`).
    pub limit_per_sec: u64,
    /// Nanoseconds of one core a unit takes here.
    pub ns_per_unit: f64,
    /// Its price per second, held until it ends (the node's meters).
    pub tickets: Vec<Ticket>,
}

impl BroadcastCharge {
    /// A charge that holds nothing (tests, and engines without a meter).
    pub fn free() -> Self {
        BroadcastCharge { per_tick: 0, limit_per_sec: u64::MAX, ns_per_unit: 0.0, tickets: Vec::new() }
    }
}

/// A broadcast's price now (see the module docs).
#[derive(Debug)]
pub(crate) struct Budget {
    fps: u64,
    /// Units of a tick besides the motions and the `ik` control's constraints.
    base: u64,
    chain: FadeChain,
    ik: u64,
    limit_per_sec: u64,
    ns_per_unit: f64,
    tickets: Vec<Ticket>,
}

impl Budget {
    /// The budget of a broadcast of `motion` at `fps`, admitted as `charge` says.
    pub(crate) fn new(charge: BroadcastCharge, motion: &Arc<StreamMotion>, fps: u32) -> Self {
        Budget {
            fps: u64::from(fps),
            base: charge.per_tick.saturating_sub(price::broadcast_frame(&[motion], 0, fps)),
            chain: FadeChain::new(motion),
            ik: 0,
            limit_per_sec: charge.limit_per_sec,
            ns_per_unit: charge.ns_per_unit,
            tickets: charge.tickets,
        }
    }

    /// The most one piece of its work may cost (`max_request_work`).
    pub(crate) fn limit(&self) -> u64 {
        self.limit_per_sec
    }

    /// Work units of one tick now.
    pub(crate) fn per_tick(&self) -> u64 {
        self.base.saturating_add(price::broadcast_frame(&self.chain.motions(), self.ik, self.fps as u32))
    }

    /// Nanoseconds of one core a tick may take on average over a second:
    /// [`OVERRUN_FACTOR`] times its price, and [`TICK_ALLOWANCE_UNITS`].
    /// Unbounded when not metered (no unit speed: tests, tools).
    pub(crate) fn tick_allowed_ns(&self) -> u64 {
        if self.ns_per_unit <= 0.0 {
            return u64::MAX;
        }
        let units = self.per_tick().saturating_mul(OVERRUN_FACTOR).saturating_add(TICK_ALLOWANCE_UNITS);
        (units as f64 * self.ns_per_unit) as u64
    }

    /// Prices the checked `control` for `skeleton_of` (the broadcast's
    /// motion): a crossfade or an `ik` control changes the price, and the
    /// tickets follow. Any other control costs what the broadcast costs.
    ///
    /// # Errors
    /// `too_much_work` over `max_request_work` per second; the meters'
    /// `caller_work_limit` and `overloaded`. Nothing changed then.
    pub(crate) fn reprice(&mut self, control: &Control, skeleton_of: &StreamMotion) -> Result<(), ControlError> {
        let mut next = Budget { chain: self.chain.clone(), tickets: Vec::new(), ..*self };
        match control {
            Control::Crossfade(fade) => next.chain = self.chain.crossfaded(&fade.to),
            Control::SetIk(constraints) => next.ik = price::ik(constraints, skeleton_of.skeleton()),
            Control::Play
            | Control::Pause
            | Control::Seek(_)
            | Control::Speed(_)
            | Control::Stop
            | Control::Layer { .. }
            | Control::Ik(_)
            | Control::ResetSprings
            | Control::Set(_)
            | Control::SetGraph(_) => return Ok(()),
        }
        let per_sec = next.per_tick().saturating_mul(self.fps);
        if per_sec > self.limit_per_sec {
            let detail = format!(
                "after this control the broadcast would cost {per_sec} work units per second; the limit \
                 (max_request_work, --max-request-work) is {}",
                self.limit_per_sec
            );
            return Err(ApiError::invalid("too_much_work", "", detail).to_control());
        }
        self.resize(per_sec)?;
        next.tickets = std::mem::take(&mut self.tickets);
        *self = next;
        Ok(())
    }

    /// Gives its charge back (it ended): what it held is the node's again
    /// at once, whoever still holds the broadcast.
    pub(crate) fn release(&mut self) {
        self.tickets.clear();
    }

    /// Every ticket holds `per_sec`, or none changes.
    fn resize(&mut self, per_sec: u64) -> Result<(), ControlError> {
        let before = self.per_tick().saturating_mul(self.fps);
        for i in 0..self.tickets.len() {
            if let Err(e) = self.tickets[i].resize(per_sec) {
                for t in &mut self.tickets[..i] {
                    let _ = t.resize(before);
                }
                return Err(e.to_control());
            }
        }
        Ok(())
    }
}

/// The CPU of a broadcast's last second of ticks against their price.
#[derive(Debug)]
pub(crate) struct Overrun {
    ticks: VecDeque<u64>,
    sum: u64,
    window: usize,
}

impl Overrun {
    /// Over one second of ticks at `fps`.
    pub(crate) fn new(fps: u32) -> Self {
        Overrun { ticks: VecDeque::with_capacity(fps as usize), sum: 0, window: fps.max(1) as usize }
    }

    /// Counts a tick that took `cpu_ns`; returns whether the last second
    /// of ticks took more than `allowed_ns` each on average
    /// ([`Budget::tick_allowed_ns`]).
    pub(crate) fn over(&mut self, cpu_ns: u64, allowed_ns: u64) -> bool {
        if self.ticks.len() == self.window {
            self.sum -= self.ticks.pop_front().unwrap_or(0);
        }
        self.ticks.push_back(cpu_ns);
        self.sum += cpu_ns;
        self.ticks.len() == self.window && self.sum > allowed_ns.saturating_mul(self.window as u64)
    }
}

/// CPU time this thread has used, in nanoseconds.
pub(crate) fn thread_cpu_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid timespec to write; the clock id is a constant.
    let ok = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &raw mut ts) } == 0;
    if !ok {
        return 0;
    }
    (ts.tv_sec as u64).saturating_mul(1_000_000_000).saturating_add(ts.tv_nsec as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_of_ticks_over_their_allowance_on_average_is_an_overrun() {
        // 100 units a tick at 10 ns a unit: (4 × 100 + the allowance) × 10 ns on average.
        let charge = BroadcastCharge { per_tick: 100, limit_per_sec: u64::MAX, ns_per_unit: 10.0, tickets: vec![] };
        let clip = crate::stream::tests::pinned("c1", crate::stream::tests::clip());
        let request = crate::stream::StreamRequest { fps: 10, ..Default::default() };
        let motion = crate::stream::StreamParams::new(clip, request).unwrap().motion;
        let budget = Budget::new(charge, &motion, 10);
        let most = budget.tick_allowed_ns();
        assert_eq!(most, (400 + TICK_ALLOWANCE_UNITS) * 10);
        let mut o = Overrun::new(10);
        for _ in 0..9 {
            assert!(!o.over(10 * most, most), "not a whole second yet");
        }
        assert!(o.over(10 * most, most), "a second of ticks at ten times the allowed");
        let mut o = Overrun::new(10);
        for _ in 0..100 {
            assert!(!o.over(most, most), "exactly the allowed is not over");
        }
        // One slow tick among free ones is not an overrun while the second's average holds.
        let mut o = Overrun::new(10);
        let over: Vec<bool> = (0..30).map(|k| o.over(if k == 20 { 10 * most } else { 0 }, most)).collect();
        assert!(over.iter().all(|o| !o), "{over:?}");
        // One nanosecond more than the second allows is over, for as long as that tick is in the second.
        let mut o = Overrun::new(10);
        let over: Vec<bool> = (0..40).map(|k| o.over(if k == 25 { 10 * most + 1 } else { 0 }, most)).collect();
        let at: Vec<usize> = over.iter().enumerate().filter(|(_, o)| **o).map(|(k, _)| k).collect();
        assert_eq!(at, (25..35).collect::<Vec<_>>(), "{over:?}");
        // Not metered (no unit speed): never over.
        assert_eq!(Budget::new(BroadcastCharge::free(), &motion, 10).tick_allowed_ns(), u64::MAX);
    }

    #[test]
    fn thread_cpu_advances_with_work_on_this_thread() {
        let before = thread_cpu_ns();
        let mut x = 0u64;
        for i in 0..5_000_000u64 {
            x = std::hint::black_box(x.wrapping_mul(31).wrapping_add(i));
        }
        let after = thread_cpu_ns();
        assert!(after > before, "{before} → {after} ({x})");
    }
}
