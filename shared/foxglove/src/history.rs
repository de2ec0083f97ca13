//! Recent encoder samples, for what needs counts at a time between two samples (the model's
//! prediction at a tracker frame's exposure) or over a past interval (the homing dwell).

use std::collections::VecDeque;

use sabr_model::{Joints, RobotParams};
use sabr_recording::EncoderRow;

/// The encoder samples of the last `span_ns`, oldest first.
#[derive(Debug, Clone)]
pub struct EncoderHistory {
    span_ns: i64,
    rows: VecDeque<EncoderRow>,
}

impl EncoderHistory {
    /// Keeps the samples of the last `span_ns` nanoseconds.
    pub fn new(span_ns: i64) -> Self {
        EncoderHistory {
            span_ns,
            rows: VecDeque::new(),
        }
    }

    /// Adds the next sample (time stamps increasing) and forgets those older than the span.
    pub fn push(&mut self, row: EncoderRow) {
        self.rows.push_back(row);
        while self
            .rows
            .front()
            .is_some_and(|oldest| row.t_ns - oldest.t_ns > self.span_ns)
        {
            self.rows.pop_front();
        }
    }

    /// The counts at `t_ns`, linearly interpolated between the samples around it; `None`
    /// outside the samples kept.
    pub fn counts_at(&self, t_ns: i64) -> Option<[f64; 5]> {
        let after = self.rows.partition_point(|row| row.t_ns < t_ns);
        let next = self.rows.get(after)?;
        if next.t_ns == t_ns {
            return Some(next.counts.map(|c| c as f64));
        }
        let previous = self.rows.get(after.checked_sub(1)?)?;
        let fraction = (t_ns - previous.t_ns) as f64 / (next.t_ns - previous.t_ns) as f64;
        Some(std::array::from_fn(|j| {
            let (a, b) = (previous.counts[j] as f64, next.counts[j] as f64);
            a + fraction * (b - a)
        }))
    }

    /// The samples from `start_ns` to `end_ns` (inclusive).
    pub fn between(&self, start_ns: i64, end_ns: i64) -> impl Iterator<Item = &EncoderRow> {
        self.rows
            .iter()
            .filter(move |row| (start_ns..=end_ns).contains(&row.t_ns))
    }
}

/// The joint offsets homing gives (docs/robot-model.md §2): at the stops the joints are the
/// nominal `home_stops`, so `θ_off = home_stops − GR·θ_enc(median counts at the stops)`.
/// `None` without samples.
pub fn homing_offsets<'a>(
    params: &RobotParams,
    samples: impl Iterator<Item = &'a EncoderRow>,
) -> Option<Joints> {
    let mut per_joint: [Vec<i64>; 5] = Default::default();
    for row in samples {
        for (joint, &count) in row.counts.iter().enumerate() {
            per_joint[joint].push(count);
        }
    }
    if per_joint[0].is_empty() {
        return None;
    }
    let median: [i64; 5] = std::array::from_fn(|j| {
        let counts = &mut per_joint[j];
        counts.sort_unstable();
        counts[counts.len() / 2]
    });
    let motor = params.motor_angles(&median);
    Some(std::array::from_fn(|j| {
        params.joints.home_stops[j] - params.joints.gear_ratio[j] * motor[j]
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(t_ns: i64, count: i64) -> EncoderRow {
        EncoderRow {
            t_ns,
            counts: [count, -count, 2 * count, 0, 7],
        }
    }

    #[test]
    fn counts_are_interpolated_between_samples_and_unknown_outside() {
        let mut history = EncoderHistory::new(1_000);
        history.push(row(100, 10));
        history.push(row(200, 20));
        assert_eq!(history.counts_at(150), Some([15.0, -15.0, 30.0, 0.0, 7.0]));
        assert_eq!(history.counts_at(200), Some([20.0, -20.0, 40.0, 0.0, 7.0]));
        assert_eq!(history.counts_at(99), None);
        assert_eq!(history.counts_at(201), None);
    }

    #[test]
    fn samples_older_than_the_span_are_forgotten() {
        let mut history = EncoderHistory::new(100);
        for t in [0, 50, 100, 150] {
            history.push(row(t, t));
        }
        let kept: Vec<i64> = history
            .between(i64::MIN, i64::MAX)
            .map(|r| r.t_ns)
            .collect();
        assert_eq!(kept, [50, 100, 150]);
        assert_eq!(history.counts_at(25), None);
    }

    #[test]
    fn homing_offsets_put_the_median_counts_at_the_nominal_stops() {
        let params = RobotParams::nominal();
        // One outlier sample does not move the median.
        let rows = [row(0, 400), row(1, 400), row(2, 9_999)];
        let offsets = homing_offsets(&params, rows.iter()).unwrap();
        let mut with_offsets = params.clone();
        with_offsets.joints.offset = Some(offsets);
        let q = with_offsets
            .joints_from_counts(&rows[0].counts, &Default::default())
            .unwrap();
        for (joint, stop) in q.iter().zip(params.joints.home_stops) {
            assert!((joint - stop).abs() < 1e-12, "{joint} vs {stop}");
        }
        assert_eq!(homing_offsets(&params, [].iter()), None);
    }
}
