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
