//! Diagnostics that point at hysteresis: each frame's residual expressed as joint errors
//! (see [`plots`](crate::report::plots)), averaged per direction of motion and along the
//! distance the joint has travelled since its last reversal. A backlash the model lacks
//! shows as a difference between the two directions; a play modelled as a sign switch
//! shows as a ramp over the first gap-width of travel after each reversal.

use serde::Serialize;

/// Bins of the travel since the last reversal.
const TRAVEL_BINS: usize = 12;
/// Longest travel since the last reversal that is binned (mrad): a few times the widest
/// plausible backlash (`sabr_model::effects::spec::MAX_JOINT_EFFECT_RAD`), so the gap's
/// width is resolved whatever the stroke lengths.
const TRAVEL_RANGE_MRAD: f64 = 60.0;
/// Fewest frames in a reported bin.
const MIN_BIN_FRAMES: usize = 5;

/// One frame's joint error with its motion state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionSample {
    /// Joint error (mrad): the joint change that best explains the frame's residual.
    pub error_mrad: f64,
    /// Direction of motion (−1, 0, +1).
    pub direction: f64,
    /// Joint travel since the last reversal (mrad); `None` before the first motion.
    pub travel_mrad: Option<f64>,
}

/// The hysteresis diagnostic of one joint (`report.json`: `final.hysteresis`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HysteresisDiagnostic {
    /// Joint 1..5.
    pub joint: usize,
    /// Mean joint error (mrad) of the frames moving down and up (`null` without frames).
    pub mean_by_direction_mrad: [Option<f64>; 2],
    /// Frames moving down and up.
    pub frames_by_direction: [usize; 2],
    /// Along the travel since the last reversal: `[travel (mrad, bin mean), mean of
    /// direction × joint error (mrad), frames]`; a bin needs at least 5 frames.
    pub by_travel_mrad: Vec<(f64, f64, usize)>,
}

impl HysteresisDiagnostic {
    /// The diagnostic of joint `joint` (0-based) from its frames. Travel is binned up to
    /// 60 mrad, or the 95th percentile of the travels seen when that is shorter.
    pub fn of(joint: usize, samples: &[MotionSample]) -> Self {
        let mut sums = [(0.0, 0usize); 2];
        for s in samples {
            let side = match s.direction {
                d if d < 0.0 => 0,
                d if d > 0.0 => 1,
                _ => continue,
            };
            sums[side].0 += s.error_mrad;
            sums[side].1 += 1;
        }
        let mut travels: Vec<f64> = samples.iter().filter_map(|s| s.travel_mrad).collect();
        travels.sort_by(f64::total_cmp);
        let top = travels
            .get((travels.len() as f64 * 0.95) as usize)
            .copied()
            .unwrap_or(0.0)
            .min(TRAVEL_RANGE_MRAD);
        let mut bins = [(0.0, 0.0, 0usize); TRAVEL_BINS];
        if top > 0.0 {
            for s in samples {
                let (Some(travel), true) = (s.travel_mrad, s.direction != 0.0) else {
                    continue;
                };
                if travel > top {
                    continue;
                }
                let bin = ((travel / top * TRAVEL_BINS as f64) as usize).min(TRAVEL_BINS - 1);
                bins[bin].0 += travel;
                bins[bin].1 += s.direction * s.error_mrad;
                bins[bin].2 += 1;
            }
        }
        Self {
            joint: joint + 1,
            mean_by_direction_mrad: sums.map(|(sum, n)| (n > 0).then(|| sum / n as f64)),
            frames_by_direction: sums.map(|(_, n)| n),
            by_travel_mrad: bins
                .iter()
                .filter(|b| b.2 >= MIN_BIN_FRAMES)
                .map(|b| (b.0 / b.2 as f64, b.1 / b.2 as f64, b.2))
                .collect(),
        }
    }

    /// Difference of the mean joint error moving up minus moving down (mrad); `None` unless
    /// the joint moved both ways.
    pub fn direction_split_mrad(&self) -> Option<f64> {
        Some(self.mean_by_direction_mrad[1]? - self.mean_by_direction_mrad[0]?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unmodelled_play_splits_the_directions_and_ramps_with_the_travel() {
        // A play of 10 mrad modelled as nothing: the joint error is −direction·5 mrad once
        // engaged, and ramps from +5 to −5 (times direction) over the first 10 mrad.
        let samples: Vec<MotionSample> = (0..400)
            .map(|k| {
                let direction = if k % 2 == 0 { 1.0 } else { -1.0 };
                let travel = (k / 2) as f64 * 0.2;
                let folded = if travel < 10.0 { 5.0 - travel } else { -5.0 };
                MotionSample {
                    error_mrad: direction * folded,
                    direction,
                    travel_mrad: Some(travel),
                }
            })
            .collect();
        let d = HysteresisDiagnostic::of(3, &samples);
        assert_eq!(d.joint, 4);
        assert_eq!(d.frames_by_direction, [200, 200]);
        assert!(d.direction_split_mrad().unwrap() < -4.0, "{d:?}");
        let first = d.by_travel_mrad.first().unwrap();
        let last = d.by_travel_mrad.last().unwrap();
        assert!(first.1 > 3.0 && (last.1 + 5.0).abs() < 1e-9, "{d:?}");
    }

    #[test]
    fn joints_that_never_moved_have_no_figures() {
        let samples = [MotionSample {
            error_mrad: 1.0,
            direction: 0.0,
            travel_mrad: None,
        }];
        let d = HysteresisDiagnostic::of(0, &samples);
        assert_eq!(d.mean_by_direction_mrad, [None, None]);
        assert!(d.by_travel_mrad.is_empty() && d.direction_split_mrad().is_none());
    }
}
