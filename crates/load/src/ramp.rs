//! `--ramp`: step the load up until a target breaks, and report the knee.
//!
//! Each stage runs at a load `n` (streams, or unary workers) and yields its
//! p99 latency (receive lateness for streams), the fraction of frames or
//! requests lost, and its errors. A stage passes when p99 ≤ the target, the
//! loss ≤ the allowed ratio and there were no errors. The ramp multiplies `n`
//! by a factor after each passing stage (at least +1, at most the cap) and
//! stops at the first failing stage: the knee is the last `n` that passed.

use serde::Serialize;

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RampPlan {
    pub start: usize,
    pub factor: f64,
    pub max: usize,
    pub target_p99_us: f64,
    pub max_loss_ratio: f64,
}

/// What one stage measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Stage {
    pub n: usize,
    pub p99_us: f64,
    pub loss_ratio: f64,
    pub errors: u64,
    pub passed: bool,
}

/// The walk through the stages.
#[derive(Debug, Clone)]
pub struct Ramp {
    plan: RampPlan,
    next: Option<usize>,
    stages: Vec<Stage>,
}

impl Ramp {
    pub fn new(plan: RampPlan) -> Self {
        Ramp { next: (plan.start >= 1 && plan.start <= plan.max).then_some(plan.start), plan, stages: Vec::new() }
    }

    /// The load of the next stage to run; `None` once the ramp is over.
    pub fn current(&self) -> Option<usize> {
        self.next
    }

    /// Records the stage just run at `current()` and picks the next.
    pub fn record(&mut self, p99_us: f64, loss_ratio: f64, errors: u64) {
        let Some(n) = self.next else { return };
        let plan = &self.plan;
        let passed = p99_us <= plan.target_p99_us && loss_ratio <= plan.max_loss_ratio && errors == 0;
        self.stages.push(Stage { n, p99_us, loss_ratio, errors, passed });
        self.next = if passed && n < plan.max {
            let grown = ((n as f64) * plan.factor).ceil() as usize;
            Some(grown.max(n + 1).min(plan.max))
        } else {
            None
        };
    }

    pub fn stages(&self) -> &[Stage] {
        &self.stages
    }

    /// The last load that passed (`None` if the first stage failed).
    pub fn knee(&self) -> Option<usize> {
        self.stages.iter().take_while(|s| s.passed).last().map(|s| s.n)
    }

    /// The load that broke the target (`None` if the cap was reached first).
    pub fn broke_at(&self) -> Option<usize> {
        self.stages.iter().find(|s| !s.passed).map(|s| s.n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan() -> RampPlan {
        RampPlan { start: 100, factor: 2.0, max: 10_000, target_p99_us: 2000.0, max_loss_ratio: 0.01 }
    }

    /// Runs a ramp against a system whose p99 is `n` µs (so it breaks past 2000).
    fn walk(plan: RampPlan, loss: impl Fn(usize) -> f64, errors: impl Fn(usize) -> u64) -> Ramp {
        let mut ramp = Ramp::new(plan);
        let mut guard = 0;
        while let Some(n) = ramp.current() {
            ramp.record(n as f64, loss(n), errors(n));
            guard += 1;
            assert!(guard < 100, "the ramp must end");
        }
        ramp
    }

    #[test]
    fn doubles_until_the_target_breaks() {
        let ramp = walk(plan(), |_| 0.0, |_| 0);
        let ns: Vec<usize> = ramp.stages().iter().map(|s| s.n).collect();
        assert_eq!(ns, [100, 200, 400, 800, 1600, 3200]);
        assert_eq!(ramp.knee(), Some(1600));
        assert_eq!(ramp.broke_at(), Some(3200));
    }

    #[test]
    fn loss_or_errors_break_it_too() {
        let ramp = walk(plan(), |n| if n >= 400 { 0.02 } else { 0.0 }, |_| 0);
        assert_eq!((ramp.knee(), ramp.broke_at()), (Some(200), Some(400)));
        let ramp = walk(plan(), |_| 0.0, |n| u64::from(n >= 200));
        assert_eq!((ramp.knee(), ramp.broke_at()), (Some(100), Some(200)));
    }

    #[test]
    fn stops_at_the_cap_and_always_grows() {
        let capped = RampPlan { max: 1000, target_p99_us: 1e9, ..plan() };
        let ramp = walk(capped, |_| 0.0, |_| 0);
        assert_eq!(ramp.stages().last().unwrap().n, 1000);
        assert_eq!((ramp.knee(), ramp.broke_at()), (Some(1000), None));
        let slow = RampPlan { start: 1, factor: 1.0, max: 3, target_p99_us: 1e9, ..plan() };
        assert_eq!(walk(slow, |_| 0.0, |_| 0).stages().len(), 3);
        let first_fails = RampPlan { target_p99_us: 10.0, ..plan() };
        assert_eq!(walk(first_fails, |_| 0.0, |_| 0).knee(), None);
    }
}
