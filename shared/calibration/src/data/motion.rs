//! The direction of motion of each joint from the encoder count history, for history-
//! dependent effects (backlash).
//!
//! A joint's direction changes when its count has moved back by at least a dead-band from
//! the last extremum (so encoder dither of ±1 count at rest never flips it). The calibration
//! runs on a whole recording, so the change is dated with hindsight, where the motor turned
//! rather than when the dead-band was crossed: at the middle of the run of samples at the
//! extremum count for a smooth turn, but no earlier than [`SMOOTH_TURN_HALF_NS`] before the
//! motor left that count (after a dwell the motor turns when it starts to move again).
//! Before its first motion a joint's direction is 0 (unknown).
//!
//! Each change also records the count where the joint turned (the extremum), so that the
//! backlash play operator sees the joint's recent turning points.

use sabr_model::effects::play::PlayMemory;
use sabr_model::JointMotion;

/// Longest half-duration (ns) of a smooth turn within one count; a longer stay at the
/// extremum count is a dwell.
pub const SMOOTH_TURN_HALF_NS: f64 = 1e8;

/// Direction changes of every joint over a recording.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MotionTrack {
    /// Per joint: `(host time ns from which it holds, direction ±1, turning points so far)`,
    /// in time order.
    changes: [Vec<(f64, f64, PlayMemory)>; 5],
}

/// Running state of one joint.
struct JointState {
    direction: f64,
    extremum: i64,
    first_at_extremum: i64,
    last_at_extremum: i64,
}

impl MotionTrack {
    /// Builds the track from encoder samples sorted by host time `times_ns` with raw
    /// `counts`, using `dead_band` counts (at least 1).
    pub fn new(times_ns: &[i64], counts: &[[i64; 5]], dead_band: i64) -> Self {
        let dead_band = dead_band.max(1);
        let mut track = Self::default();
        let Some(first) = counts.first() else {
            return track;
        };
        for joint in 0..5 {
            let mut memory = PlayMemory::default();
            let mut state = JointState {
                direction: 0.0,
                extremum: first[joint],
                first_at_extremum: times_ns[0],
                last_at_extremum: times_ns[0],
            };
            for (&t, c) in times_ns.iter().zip(counts) {
                let count = c[joint];
                if count == state.extremum {
                    state.last_at_extremum = t;
                    continue;
                }
                let beyond = (count - state.extremum) as f64 * state.direction > 0.0;
                if beyond || (state.direction == 0.0 && (count - state.extremum).abs() < dead_band)
                {
                    if beyond {
                        state.extremum = count;
                        state.first_at_extremum = t;
                        state.last_at_extremum = t;
                    }
                    continue;
                }
                if (count - state.extremum).abs() >= dead_band {
                    let (entered, left) = (
                        state.first_at_extremum as f64,
                        state.last_at_extremum as f64,
                    );
                    let turned_at = (0.5 * (entered + left)).max(left - SMOOTH_TURN_HALF_NS);
                    let direction = (count - state.extremum).signum() as f64;
                    memory.push(state.extremum as f64, state.direction == 0.0);
                    track.changes[joint].push((turned_at, direction, memory));
                    state = JointState {
                        direction,
                        extremum: count,
                        first_at_extremum: t,
                        last_at_extremum: t,
                    };
                }
            }
        }
        track
    }

    /// The direction and recent turning points of every joint at host time `t_ns`.
    pub fn at(&self, t_ns: f64) -> JointMotion {
        let mut motion = JointMotion::default();
        for (joint, changes) in self.changes.iter().enumerate() {
            let i = changes.partition_point(|(t, _, _)| *t <= t_ns);
            if i > 0 {
                let (_, direction, memory) = changes[i - 1];
                motion.direction[joint] = direction;
                motion.turns[joint] = memory;
            }
        }
        motion
    }

    /// Number of direction changes of each joint.
    pub fn reversals(&self) -> [usize; 5] {
        std::array::from_fn(|joint| self.changes[joint].len().saturating_sub(1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sabr_model::DIRECTION_DEAD_BAND_COUNTS;

    /// Samples 1 ms apart of a joint moving as `counts(t)` on joint 2 only.
    fn samples(count: impl Fn(f64) -> f64, n: usize) -> (Vec<i64>, Vec<[i64; 5]>) {
        let times: Vec<i64> = (0..n as i64).map(|k| k * 1_000_000).collect();
        let counts = times
            .iter()
            .map(|&t| {
                let mut c = [7; 5];
                c[1] = count(t as f64 * 1e-9).round() as i64;
                c
            })
            .collect();
        (times, counts)
    }

    #[test]
    fn reversals_are_dated_at_the_turning_point() {
        // 100 counts amplitude, period 2 s: turns at 0.5 s (max) and 1.5 s (min).
        let (times, counts) = samples(|t| 100.0 * (std::f64::consts::PI * t).sin(), 2_500);
        let track = MotionTrack::new(&times, &counts, DIRECTION_DEAD_BAND_COUNTS);
        assert_eq!(track.at(0.3e9).direction[1], 1.0);
        assert_eq!(track.at(0.48e9).direction[1], 1.0);
        assert_eq!(track.at(0.52e9).direction[1], -1.0);
        assert_eq!(track.at(1.45e9).direction[1], -1.0);
        assert_eq!(track.at(1.55e9).direction[1], 1.0);
        assert_eq!(track.reversals()[1], 2);
        // Joints that never move keep an unknown direction.
        assert_eq!(track.at(2.0e9).direction[0], 0.0);
    }

    #[test]
    fn after_a_dwell_the_direction_changes_when_the_motor_moves_again() {
        // Up to 200 counts by 0.5 s, dwell until 2 s, then back down.
        let (times, counts) = samples(
            |t| {
                if t < 0.5 {
                    400.0 * t
                } else if t < 2.0 {
                    200.0
                } else {
                    200.0 - 400.0 * (t - 2.0)
                }
            },
            2_500,
        );
        let track = MotionTrack::new(&times, &counts, DIRECTION_DEAD_BAND_COUNTS);
        assert_eq!(
            track.at(1.25e9).direction[1],
            1.0,
            "the middle of the dwell"
        );
        assert_eq!(track.at(1.85e9).direction[1], 1.0);
        assert_eq!(track.at(2.01e9).direction[1], -1.0);
    }

    #[test]
    fn dither_inside_the_dead_band_does_not_flip_the_direction() {
        let (times, counts) = samples(
            |t| {
                if t < 0.5 {
                    400.0 * t
                } else {
                    200.0 + if (t * 1e3) as i64 % 2 == 0 { 1.0 } else { 0.0 }
                }
            },
            1_000,
        );
        let track = MotionTrack::new(&times, &counts, DIRECTION_DEAD_BAND_COUNTS);
        assert_eq!(track.at(0.9e9).direction[1], 1.0);
        assert_eq!(track.reversals()[1], 0);
    }
}
