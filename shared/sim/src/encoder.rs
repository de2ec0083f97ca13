//! Encoder emulation: when the host samples the counters (about 1 kHz, with scheduling
//! jitter and occasional late samples). The counts themselves come from
//! [`crate::TrueRobot::counts`]; a sample's stamp is the instant its counts were read.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Timing of the host's encoder sampling.
#[derive(Debug, Clone, PartialEq)]
pub struct EncoderConfig {
    /// Nominal sampling rate (Hz).
    pub rate_hz: f64,
    /// Standard deviation of the sampling-instant jitter (µs), clipped at ±3σ.
    pub jitter_us: f64,
    /// Probability that a sample is late (a scheduling hiccup).
    pub late_probability: f64,
    /// Lateness of a late sample, uniform in this range (µs).
    pub late_us: (f64, f64),
}

impl Default for EncoderConfig {
    /// 1 kHz, 20 µs jitter, 0.1 % of samples 100–600 µs late.
    fn default() -> Self {
        EncoderConfig {
            rate_hz: 1000.0,
            jitter_us: 20.0,
            late_probability: 0.001,
            late_us: (100.0, 600.0),
        }
    }
}

/// Gap (ns) kept between consecutive samples so stamps strictly increase.
const MIN_GAP_NS: i64 = 1_000;

/// The sequence of sampling instants (robot time, ns since power-up).
#[derive(Debug, Clone)]
pub struct EncoderClock {
    config: EncoderConfig,
    rng: ChaCha8Rng,
    start_ns: i64,
    index: i64,
    next_ns: i64,
}

impl EncoderClock {
    /// A clock whose first nominal sample is at `start_ns`.
    pub fn new(config: EncoderConfig, start_ns: i64, rng: ChaCha8Rng) -> Self {
        let mut clock = EncoderClock {
            config,
            rng,
            start_ns,
            index: 0,
            next_ns: i64::MIN,
        };
        clock.next_ns = clock.draw(start_ns - MIN_GAP_NS);
        clock
    }

    fn draw(&mut self, previous_ns: i64) -> i64 {
        let period_ns = 1e9 / self.config.rate_hz;
        let nominal = self.start_ns as f64 + self.index as f64 * period_ns;
        let z: f64 = self.rng.sample(StandardNormal);
        let mut offset_us = self.config.jitter_us * z.clamp(-3.0, 3.0);
        if self.rng.random_bool(self.config.late_probability) {
            let (low, high) = self.config.late_us;
            offset_us += self.rng.random_range(low..=high);
        }
        ((nominal + offset_us * 1e3).round() as i64).max(previous_ns + MIN_GAP_NS)
    }

    /// The next sampling instant (robot time, ns).
    pub fn peek_ns(&self) -> i64 {
        self.next_ns
    }

    /// Consumes the next sampling instant and returns it.
    pub fn advance(&mut self) -> i64 {
        let current = self.next_ns;
        self.index += 1;
        self.next_ns = self.draw(current);
        current
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn samples_at_the_configured_rate_with_bounded_jitter() {
        let config = EncoderConfig::default();
        let mut clock = EncoderClock::new(config.clone(), 5_000, ChaCha8Rng::seed_from_u64(3));
        let times: Vec<i64> = (0..20_000).map(|_| clock.advance()).collect();
        let span_s = (times[times.len() - 1] - times[0]) as f64 * 1e-9;
        let rate = (times.len() - 1) as f64 / span_s;
        assert!(
            (rate - config.rate_hz).abs() < 0.01 * config.rate_hz,
            "{rate}"
        );
        assert!(times.windows(2).all(|w| w[1] > w[0]));
        let deviations: Vec<f64> = times
            .iter()
            .enumerate()
            .map(|(k, t)| (*t - 5_000 - k as i64 * 1_000_000) as f64 * 1e-3)
            .filter(|d| d.abs() < 90.0)
            .collect();
        let rms = (deviations.iter().map(|d| d * d).sum::<f64>() / deviations.len() as f64).sqrt();
        assert!(
            (rms - config.jitter_us).abs() < 0.1 * config.jitter_us,
            "{rms}"
        );
    }
}
