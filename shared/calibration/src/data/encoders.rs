//! The encoder stream of a recording, interpolated linearly at any host time, with the
//! direction of motion of every joint from its count history.

use sabr_model::{JointMotion, DIRECTION_DEAD_BAND_COUNTS};
use sabr_recording::EncoderRow;

use crate::data::motion::MotionTrack;
use crate::error::CalibrationError;
use crate::math::stats::median;

/// The encoder stream, sorted by host stamp, interpolated linearly between samples.
#[derive(Debug, Clone)]
pub struct EncoderTrack {
    times_ns: Vec<i64>,
    counts: Vec<[i64; 5]>,
    max_gap_ns: i64,
    motion: MotionTrack,
}

impl EncoderTrack {
    /// Builds the track; samples further apart than `max_gap_ns` are not interpolated
    /// across. Errors when there are fewer than two samples.
    pub fn new(rows: &[EncoderRow], max_gap_ns: i64) -> Result<Self, CalibrationError> {
        if rows.len() < 2 {
            return Err(CalibrationError::NoTrackerFrames(format!(
                "encoders.csv holds {} samples: no encoder stream to calibrate against",
                rows.len()
            )));
        }
        let mut sorted = rows.to_vec();
        sorted.sort_by_key(|row| row.t_ns);
        let times_ns: Vec<i64> = sorted.iter().map(|r| r.t_ns).collect();
        let counts: Vec<[i64; 5]> = sorted.iter().map(|r| r.counts).collect();
        let motion = MotionTrack::new(&times_ns, &counts, DIRECTION_DEAD_BAND_COUNTS);
        Ok(Self {
            times_ns,
            counts,
            max_gap_ns,
            motion,
        })
    }

    /// Direction of motion of every joint at host time `t_ns` (from the count history, see
    /// [`MotionTrack`]).
    pub fn motion_at(&self, t_ns: f64) -> JointMotion {
        self.motion.at(t_ns)
    }

    /// Counts (fractional) at host time `t_ns`; `None` outside the stream or inside a gap
    /// longer than the allowed one.
    pub fn counts_at(&self, t_ns: f64) -> Option<[f64; 5]> {
        self.counts_bridging(t_ns, self.max_gap_ns)
    }

    /// Counts (fractional) at host time `t_ns`, interpolated across gaps up to `max_gap_ns`
    /// (ns) instead of the track's own limit: for coarse, model-free uses that tolerate the
    /// interpolation error of a longer gap; `None` outside the stream or inside a longer gap.
    pub fn counts_bridging(&self, t_ns: f64, max_gap_ns: i64) -> Option<[f64; 5]> {
        let i = self.times_ns.partition_point(|&t| (t as f64) <= t_ns);
        if i == 0 || i > self.times_ns.len() {
            return None;
        }
        if i == self.times_ns.len() {
            let last = i - 1;
            return (self.times_ns[last] as f64 == t_ns)
                .then(|| self.counts[last].map(|c| c as f64));
        }
        let (t0, t1) = (self.times_ns[i - 1], self.times_ns[i]);
        if t1 - t0 > max_gap_ns {
            return None;
        }
        let f = (t_ns - t0 as f64) / (t1 - t0) as f64;
        let (c0, c1) = (&self.counts[i - 1], &self.counts[i]);
        Some(std::array::from_fn(|j| {
            c0[j] as f64 + f * (c1[j] - c0[j]) as f64
        }))
    }

    /// Count rate (counts/s) at `t_ns` by a central difference over ±`half_window_ns`.
    pub fn rate_at(&self, t_ns: f64, half_window_ns: f64) -> Option<[f64; 5]> {
        let before = self.counts_at(t_ns - half_window_ns)?;
        let after = self.counts_at(t_ns + half_window_ns)?;
        let dt = 2.0 * half_window_ns * 1e-9;
        Some(std::array::from_fn(|j| (after[j] - before[j]) / dt))
    }

    /// Median interval between samples (ns).
    pub fn median_interval_ns(&self) -> f64 {
        let mut d: Vec<f64> = self
            .times_ns
            .windows(2)
            .map(|w| (w[1] - w[0]) as f64)
            .collect();
        median(&mut d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoder_interpolation_and_gaps() {
        let rows: Vec<EncoderRow> = [0i64, 1_000_000, 2_000_000, 10_000_000]
            .iter()
            .enumerate()
            .map(|(i, &t)| EncoderRow {
                t_ns: t,
                counts: [i as i64 * 10, 0, 0, 0, -(i as i64)],
            })
            .collect();
        let track = EncoderTrack::new(&rows, 5_000_000).unwrap();
        let c = track.counts_at(1_500_000.0).unwrap();
        assert!((c[0] - 15.0).abs() < 1e-12 && (c[4] + 1.5).abs() < 1e-12);
        assert!(track.counts_at(5_000_000.0).is_none(), "inside an 8 ms gap");
        let bridged = track.counts_bridging(6_000_000.0, 10_000_000).unwrap();
        assert!((bridged[0] - 25.0).abs() < 1e-12, "halfway from 20 to 30");
        assert!(track.counts_bridging(6_000_000.0, 7_999_999).is_none());
        assert!(track.counts_at(-1.0).is_none());
        let rate = track.rate_at(1_000_000.0, 500_000.0).unwrap();
        assert!((rate[0] - 10_000.0).abs() < 1e-6);
    }
}
