//! What drives the simulated motors when `motion` does: its motor setpoints, each applied at
//! its own time, and whether the tip sphere is on the needle.

use std::collections::VecDeque;

use sabr_msgs::{MotionState, MotionStatus, MotorSetpoint};

/// Why a setpoint was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SetpointError {
    /// A target is NaN or infinite.
    #[error("setpoint seq {seq}: target counts {counts:?} are not all finite; refused")]
    NotFinite {
        /// The setpoint's sequence number.
        seq: u64,
        /// Its targets.
        counts: [f64; 5],
    },
}

/// Motor setpoints received but not yet due, and the one in force.
#[derive(Debug, Default)]
pub struct SetpointQueue {
    pending: VecDeque<MotorSetpoint>,
    current: Option<[f64; 5]>,
}

impl SetpointQueue {
    /// Queues a setpoint, to take effect at its `t_ns`; non-finite targets are refused.
    pub fn push(&mut self, setpoint: MotorSetpoint) -> Result<(), SetpointError> {
        if !setpoint.target_counts.iter().all(|c| c.is_finite()) {
            return Err(SetpointError::NotFinite {
                seq: setpoint.seq,
                counts: setpoint.target_counts,
            });
        }
        // Setpoints arrive in time order from one publisher; keep the queue sorted anyway.
        let at = self
            .pending
            .partition_point(|queued| queued.t_ns <= setpoint.t_ns);
        self.pending.insert(at, setpoint);
        Ok(())
    }

    /// The target counts in force at host time `now_ns` (the newest setpoint due by then),
    /// or `None` before any setpoint is due.
    pub fn current_at(&mut self, now_ns: i64) -> Option<[f64; 5]> {
        while self.pending.front().is_some_and(|s| s.t_ns <= now_ns) {
            self.current = self.pending.pop_front().map(|s| s.target_counts);
        }
        self.current
    }
}

/// Whether the tip sphere is on the needle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TipSphere {
    /// During the plan's tip phase (autoplay), or while `motion` reports the phase `tip`
    /// running.
    Auto,
    /// Always attached.
    Always,
    /// Never attached.
    Never,
}

/// Name of the session phase during which the tip sphere is attached.
pub const TIP_PHASE: &str = "tip";

/// Whether a motion status means the tip phase is running.
pub fn tip_phase_running(status: &MotionStatus) -> bool {
    status.state == MotionState::Moving && status.reason.as_str() == TIP_PHASE
}

#[cfg(test)]
mod tests {
    use super::*;
    use sabr_msgs::FixedString;

    fn setpoint(seq: u64, t_ns: i64, value: f64) -> MotorSetpoint {
        MotorSetpoint {
            seq,
            t_ns,
            target_counts: [value; 5],
        }
    }

    #[test]
    fn setpoints_take_effect_at_their_time() {
        let mut queue = SetpointQueue::default();
        assert_eq!(queue.current_at(1_000), None);
        queue.push(setpoint(1, 100, 1.0)).unwrap();
        queue.push(setpoint(3, 300, 3.0)).unwrap();
        queue.push(setpoint(2, 200, 2.0)).unwrap();
        assert_eq!(queue.current_at(99), None);
        assert_eq!(queue.current_at(250), Some([2.0; 5]));
        assert_eq!(queue.current_at(299), Some([2.0; 5]));
        assert_eq!(queue.current_at(300), Some([3.0; 5]));
        assert_eq!(queue.current_at(10_000), Some([3.0; 5]));
    }

    #[test]
    fn non_finite_setpoints_are_refused_and_the_last_one_holds() {
        let mut queue = SetpointQueue::default();
        queue.push(setpoint(1, 100, 5.0)).unwrap();
        let mut bad = setpoint(2, 200, 6.0);
        bad.target_counts[3] = f64::NAN;
        assert!(matches!(
            queue.push(bad),
            Err(SetpointError::NotFinite { seq: 2, .. })
        ));
        assert!(queue.push(setpoint(3, 300, f64::INFINITY)).is_err());
        assert_eq!(queue.current_at(1_000), Some([5.0; 5]));
    }

    #[test]
    fn tip_phase_is_read_from_the_motion_status() {
        let status = |state, reason: &str| MotionStatus {
            state,
            reason: FixedString::new(reason).unwrap(),
            ..MotionStatus::default()
        };
        assert!(tip_phase_running(&status(MotionState::Moving, "tip")));
        assert!(!tip_phase_running(&status(
            MotionState::Moving,
            "excitation"
        )));
        assert!(!tip_phase_running(&status(MotionState::Faulted, "tip")));
    }
}
