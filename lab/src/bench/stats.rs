//! Measured distributions (hdrhistogram) and their percentile summaries.

use anyhow::Context;
use hdrhistogram::Histogram;
use std::time::Duration;

/// Significant decimal digits every histogram keeps: values are exact up to 2048 and within
/// 0.1 % above (1 ns resolution for latencies below 2 µs).
pub const SIGNIFICANT_DIGITS: u8 = 3;

/// One measured distribution: its name, the unit of its values and the histogram.
pub struct Measurement {
    /// `<group>/<item>`, e.g. `iox2-event/encoder-sample`; also names the `.hgrm` file.
    pub name: String,
    /// Unit of the recorded integers, e.g. `ns` or `ns/solve`.
    pub unit: &'static str,
    /// The recorded values, in `unit`.
    pub histogram: Histogram<u64>,
}

impl Measurement {
    /// An empty measurement (auto-resizing histogram, lowest value 1, 3 significant digits).
    pub fn new(name: impl Into<String>, unit: &'static str) -> Self {
        // `new` only fails for more than 5 significant digits.
        let histogram = Histogram::new(SIGNIFICANT_DIGITS).expect("3 significant digits are valid");
        Self {
            name: name.into(),
            unit,
            histogram,
        }
    }

    /// Records one value (in `unit`).
    pub fn record(&mut self, value: u64) -> anyhow::Result<()> {
        self.histogram
            .record(value)
            .with_context(|| format!("{}: cannot record {value} {}", self.name, self.unit))
    }

    /// Records a duration in nanoseconds.
    pub fn record_duration(&mut self, duration: Duration) -> anyhow::Result<()> {
        self.record(duration_ns(duration))
    }

    /// The percentiles of what was recorded.
    pub fn summary(&self) -> Summary {
        Summary::of(&self.histogram)
    }
}

/// A duration in whole nanoseconds (saturating at `u64::MAX`, about 584 years).
pub fn duration_ns(duration: Duration) -> u64 {
    u64::try_from(duration.as_nanos()).unwrap_or(u64::MAX)
}

/// The percentiles reported for every measurement (values in the measurement's unit; each is
/// the highest value equivalent to the true percentile within the histogram's precision).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Summary {
    /// Number of recorded values.
    pub count: u64,
    /// Median.
    pub p50: u64,
    /// 90th percentile.
    pub p90: u64,
    /// 99th percentile.
    pub p99: u64,
    /// 99.9th percentile.
    pub p999: u64,
    /// Largest recorded value.
    pub max: u64,
}

impl Summary {
    /// The summary of a histogram; all zero for an empty one.
    pub fn of(histogram: &Histogram<u64>) -> Self {
        Self {
            count: histogram.len(),
            p50: histogram.value_at_quantile(0.50),
            p90: histogram.value_at_quantile(0.90),
            p99: histogram.value_at_quantile(0.99),
            p999: histogram.value_at_quantile(0.999),
            max: histogram.max(),
        }
    }
}

/// A nanosecond value for people: `850 ns`, `12.3 µs`, `4.56 ms`, `7.89 s`.
pub fn format_ns(value: u64) -> String {
    let v = value as f64;
    if value < 1_000 {
        format!("{value} ns")
    } else if value < 1_000_000 {
        format!("{:.3} µs", v / 1e3)
    } else if value < 1_000_000_000 {
        format!("{:.3} ms", v / 1e6)
    } else {
        format!("{:.3} s", v / 1e9)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_of_1_to_1000_has_the_expected_percentiles() {
        let mut m = Measurement::new("test/uniform", "ns");
        for v in 1..=1000 {
            m.record(v).unwrap();
        }
        let s = m.summary();
        // Below 2048 the histogram is exact.
        assert_eq!(
            s,
            Summary {
                count: 1000,
                p50: 500,
                p90: 900,
                p99: 990,
                p999: 999,
                max: 1000
            }
        );
    }

    #[test]
    fn large_values_keep_three_significant_digits() {
        let mut m = Measurement::new("test/large", "ns");
        m.record_duration(Duration::from_micros(123_456)).unwrap();
        let s = m.summary();
        assert_eq!(s.count, 1);
        let relative = (s.max as f64 - 123_456_000.0).abs() / 123_456_000.0;
        assert!(relative < 1e-3, "max {} is off by {relative}", s.max);
        assert_eq!(s.p50, s.max);
    }

    #[test]
    fn empty_summary_is_zero() {
        let s = Measurement::new("test/empty", "ns").summary();
        assert_eq!(s.count, 0);
        assert_eq!(s.max, 0);
    }

    #[test]
    fn formats_each_magnitude() {
        assert_eq!(format_ns(850), "850 ns");
        assert_eq!(format_ns(12_345), "12.345 µs");
        assert_eq!(format_ns(4_560_000), "4.560 ms");
        assert_eq!(format_ns(7_890_000_000), "7.890 s");
    }
}
