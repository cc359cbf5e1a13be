//! Latency histograms: HDR histograms of nanoseconds, and the percentile
//! summary every report prints.
//!
//! An HDR histogram keeps 3 significant digits over the whole range (1 ns to
//! an hour) in a fixed few tens of kilobytes, so each worker records into its
//! own without locking and the workers' histograms are merged at the end;
//! percentiles of the merged histogram are exact to 0.1%, unlike averages of
//! per-worker percentiles.

use hdrhistogram::Histogram;
use serde::Serialize;

/// The largest value recorded: an hour. Larger values are clamped to it.
const MAX_NS: u64 = 3_600_000_000_000;

/// A histogram of durations in nanoseconds.
#[derive(Debug, Clone)]
pub struct Latency {
    hist: Histogram<u64>,
}

impl Default for Latency {
    fn default() -> Self {
        Latency::new()
    }
}

impl Latency {
    pub fn new() -> Self {
        Latency { hist: Histogram::new_with_bounds(1, MAX_NS, 3).expect("static bounds are valid") }
    }

    /// Records one duration; 0 and negative values count as 1 ns (the
    /// histogram's floor), values over an hour as an hour.
    pub fn record_ns(&mut self, ns: i64) {
        let v = u64::try_from(ns).unwrap_or(0).clamp(1, MAX_NS);
        self.hist.saturating_record(v);
    }

    pub fn record(&mut self, d: std::time::Duration) {
        self.record_ns(i64::try_from(d.as_nanos()).unwrap_or(i64::MAX));
    }

    /// Adds `other`'s counts to this one.
    pub fn merge(&mut self, other: &Latency) {
        self.hist.add(&other.hist).expect("histograms of the same bounds merge");
    }

    /// The value at quantile `q` (0..=1), in nanoseconds; 0 when empty.
    pub fn quantile_ns(&self, q: f64) -> u64 {
        if self.hist.is_empty() { 0 } else { self.hist.value_at_quantile(q) }
    }

    pub fn summary(&self) -> Summary {
        let us = |ns: u64| ns as f64 / 1000.0;
        if self.hist.is_empty() {
            return Summary::default();
        }
        Summary {
            count: self.hist.len(),
            min_us: us(self.hist.min()),
            mean_us: self.hist.mean() / 1000.0,
            p50_us: us(self.quantile_ns(0.50)),
            p90_us: us(self.quantile_ns(0.90)),
            p99_us: us(self.quantile_ns(0.99)),
            p999_us: us(self.quantile_ns(0.999)),
            max_us: us(self.hist.max()),
        }
    }
}

/// Percentiles of one histogram, in microseconds (the JSON report's unit).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Summary {
    pub count: u64,
    pub min_us: f64,
    pub mean_us: f64,
    pub p50_us: f64,
    pub p90_us: f64,
    pub p99_us: f64,
    pub p999_us: f64,
    pub max_us: f64,
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.count == 0 {
            return write!(f, "no samples");
        }
        write!(
            f,
            "p50 {} p90 {} p99 {} p99.9 {} max {} (n={})",
            human_us(self.p50_us),
            human_us(self.p90_us),
            human_us(self.p99_us),
            human_us(self.p999_us),
            human_us(self.max_us),
            self.count
        )
    }
}

/// `812 µs`, `2.41 ms`, `1.20 s`.
pub fn human_us(us: f64) -> String {
    if us < 1000.0 {
        format!("{us:.0} µs")
    } else if us < 1_000_000.0 {
        format!("{:.2} ms", us / 1000.0)
    } else {
        format!("{:.2} s", us / 1_000_000.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_of_a_uniform_sweep_are_its_ranks() {
        // 1..=10_000 µs, one sample each: the q-quantile is q·10_000 µs.
        let mut h = Latency::new();
        for us in 1..=10_000i64 {
            h.record_ns(us * 1000);
        }
        let s = h.summary();
        assert_eq!(s.count, 10_000);
        for (got, want) in [(s.p50_us, 5000.0), (s.p90_us, 9000.0), (s.p99_us, 9900.0), (s.p999_us, 9990.0)] {
            assert!((got - want).abs() <= want * 0.001 + 1.0, "{got} vs {want}");
        }
        assert!((s.mean_us - 5000.5).abs() < 5.0, "{}", s.mean_us);
    }

    #[test]
    fn merged_histograms_equal_one_that_saw_everything() {
        let (mut a, mut b, mut all) = (Latency::new(), Latency::new(), Latency::new());
        for i in 0..1000i64 {
            let v = (i * 7919) % 100_000 + 1;
            if i % 3 == 0 {
                a.record_ns(v)
            } else {
                b.record_ns(v)
            }
            all.record_ns(v);
        }
        a.merge(&b);
        assert_eq!(a.summary(), all.summary());
    }

    #[test]
    fn out_of_range_values_are_clamped_not_lost() {
        let mut h = Latency::new();
        h.record_ns(-5);
        h.record_ns(0);
        h.record_ns(i64::MAX);
        assert_eq!(h.summary().count, 3);
        assert_eq!(h.quantile_ns(0.0), 1);
        assert!(h.quantile_ns(1.0) >= MAX_NS);
        assert_eq!(Latency::new().summary().count, 0);
    }
}
