//! Synthetic tracker and encoder streams for the unit tests, with known truth.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use sabr_msgs::EncoderSample;

/// One tracker frame as the host sees it, with its true exposure.
#[derive(Debug, Clone, Copy)]
pub struct SyntheticFrame {
    pub counter: u32,
    pub exposure_ns: i64,
    pub arrival_ns: i64,
}

/// Frames of a tracker with its own clock: exposure every `period_ns` (per frame, i.e.
/// `increment` counter ticks), arrival `latency_ns` later plus Gaussian jitter, some frames
/// late (one-sided) and some dropped.
pub struct TrackerStream {
    rng: ChaCha8Rng,
    index: u64,
    counter: u32,
    increment: u32,
    period_ns: f64,
    first_exposure_ns: f64,
    last_arrival_ns: i64,
    pub latency_ns: i64,
    pub jitter_ns: f64,
    pub late_probability: f64,
    pub drop_probability: f64,
}

impl TrackerStream {
    pub fn new(seed: u64, period_ns: f64, increment: u32, latency_ns: i64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let counter = rng.random_range(100..100_000);
        Self {
            rng,
            index: 0,
            counter,
            increment,
            period_ns,
            first_exposure_ns: 5e9,
            last_arrival_ns: 0,
            latency_ns,
            jitter_ns: 1e6,
            late_probability: 0.02,
            drop_probability: 0.01,
        }
    }

    /// The next frame that reaches the host (`None` when this exposure was dropped).
    pub fn next_frame(&mut self) -> Option<SyntheticFrame> {
        let exposure_ns = (self.first_exposure_ns + self.index as f64 * self.period_ns) as i64;
        let counter = self
            .counter
            .wrapping_add((self.index as u32).wrapping_mul(self.increment));
        self.index += 1;
        let z: f64 = self.rng.sample(StandardNormal);
        let mut delay = self.latency_ns as f64 + self.jitter_ns * z.clamp(-3.0, 3.0);
        if self.rng.random_bool(self.late_probability) {
            delay += self.rng.random_range(2e6..15e6);
        }
        if self.rng.random_bool(self.drop_probability) {
            return None;
        }
        let arrival_ns = (exposure_ns + delay as i64).max(self.last_arrival_ns + 1_000_000);
        self.last_arrival_ns = arrival_ns;
        Some(SyntheticFrame {
            counter,
            exposure_ns,
            arrival_ns,
        })
    }
}

/// Counts of a joint moving with a known law, for checking interpolation.
pub fn true_counts(t_ns: i64) -> [f64; 5] {
    let t = t_ns as f64 * 1e-9;
    [
        1000.0 * t,
        -250.0 * t,
        500.0 * (2.0 * t).sin(),
        3.0,
        40.0 * t * t,
    ]
}

/// Encoder samples every `period_ns` from `start_ns` with ±`jitter_ns` uniform sampling
/// jitter; counts are the true counts, rounded.
pub fn encoder_samples(
    start_ns: i64,
    period_ns: i64,
    n: usize,
    jitter_ns: i64,
) -> Vec<EncoderSample> {
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    (0..n)
        .map(|k| {
            let jitter = if jitter_ns > 0 {
                rng.random_range(-jitter_ns..=jitter_ns)
            } else {
                0
            };
            let t_ns = start_ns + k as i64 * period_ns + jitter;
            EncoderSample {
                seq: k as u64 + 1,
                t_ns,
                counts: true_counts(t_ns).map(|c| c.round() as i64),
            }
        })
        .collect()
}
