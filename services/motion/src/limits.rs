//! Joint and speed limits, and the check of a whole plan against them before it moves.

use crate::plan::{Segment, PERIOD_S};
use sabr_model::{Joints, HOME_JOINTS, JOINT_COUNT};

/// Default travel of each joint from its nominal stop into the workspace (rad).
pub const DEFAULT_RANGE_RAD: f64 = 0.8;
/// How far the default box reaches beyond each nominal stop (rad, about 3°): the true stops
/// differ from the nominal ones by up to about 2°, and a robot resting at its true stop
/// (after homing) must be inside the box to move away from it.
pub const STOP_TOLERANCE_RAD: f64 = 0.05;
/// Default highest joint speed (rad/s).
pub const DEFAULT_MAX_SPEED_RAD_S: f64 = 0.5;
/// Rounding allowance of the checks (rad, and relative for speeds).
const TOLERANCE: f64 = 1e-9;

/// The joint box and speed limit every commanded joint vector must respect.
#[derive(Debug, Clone, PartialEq)]
pub struct JointLimits {
    /// Lowest joint angles θ1..θ5 (rad).
    pub lower: Joints,
    /// Highest joint angles θ1..θ5 (rad).
    pub upper: Joints,
    /// Highest speed of any joint (rad/s).
    pub max_speed_rad_s: f64,
}

/// Which way each joint's mechanical stop bounds it: +1 from above, −1 from below (the stop
/// lies on that side of the home pose, as in `sabr_model::plan::excitation_centre`).
pub fn stop_sides(home_stops: &Joints) -> [f64; JOINT_COUNT] {
    std::array::from_fn(|i| (home_stops[i] - HOME_JOINTS[i]).signum())
}

impl JointLimits {
    /// The default box: each joint from [`STOP_TOLERANCE_RAD`] beyond its nominal stop to
    /// `range_rad` from the stop into the workspace.
    pub fn from_stops(home_stops: &Joints, range_rad: f64, max_speed_rad_s: f64) -> Self {
        let side = stop_sides(home_stops);
        let near: Joints = std::array::from_fn(|i| home_stops[i] + side[i] * STOP_TOLERANCE_RAD);
        let far: Joints = std::array::from_fn(|i| home_stops[i] - side[i] * range_rad);
        Self {
            lower: std::array::from_fn(|i| near[i].min(far[i])),
            upper: std::array::from_fn(|i| near[i].max(far[i])),
            max_speed_rad_s,
        }
    }

    /// Checks that the limits are usable: finite, lower < upper, a positive speed.
    pub fn validate(&self) -> Result<(), String> {
        for i in 0..JOINT_COUNT {
            let (lower, upper) = (self.lower[i], self.upper[i]);
            if !(lower.is_finite() && upper.is_finite() && lower < upper) {
                return Err(format!(
                    "joint {} limits [{lower}, {upper}] rad are not a finite interval",
                    i + 1
                ));
            }
        }
        let speed = self.max_speed_rad_s;
        if !(speed.is_finite() && speed > 0.0) {
            return Err(format!(
                "the joint speed limit must be a positive number of rad/s, got {speed}"
            ));
        }
        Ok(())
    }

    /// Checks one joint vector against the box.
    pub fn check_pose(&self, q: &Joints) -> Result<(), String> {
        for (i, &value) in q.iter().enumerate() {
            if !value.is_finite() {
                return Err(format!("joint {} is not finite ({value})", i + 1));
            }
            if value < self.lower[i] - TOLERANCE {
                return Err(format!(
                    "joint {} at {value:.4} rad < lower limit {:.4} rad",
                    i + 1,
                    self.lower[i]
                ));
            }
            if value > self.upper[i] + TOLERANCE {
                return Err(format!(
                    "joint {} at {value:.4} rad > upper limit {:.4} rad",
                    i + 1,
                    self.upper[i]
                ));
            }
        }
        Ok(())
    }

    /// Checks the speed of going from `from` to `to` in `dt_s` seconds.
    pub fn check_step(&self, from: &Joints, to: &Joints, dt_s: f64) -> Result<(), String> {
        for i in 0..JOINT_COUNT {
            let speed = (to[i] - from[i]).abs() / dt_s;
            if speed > self.max_speed_rad_s * (1.0 + TOLERANCE) {
                return Err(format!(
                    "joint {} at {speed:.4} rad/s > speed limit {} rad/s",
                    i + 1,
                    self.max_speed_rad_s
                ));
            }
        }
        Ok(())
    }
}

/// Why a plan was refused: where in it and what limit it breaks.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("plan refused: {segment} at {t_s:.3} s: {reason}")]
pub struct PlanRefusal {
    /// The segment where the first violation is.
    pub segment: String,
    /// Time from the start of that segment (s).
    pub t_s: f64,
    /// The broken limit.
    pub reason: String,
}

/// Checks a whole plan, starting from the joints `start`, sample by sample: every joint
/// vector inside the box and every step within the speed limit (the first step goes from
/// `start`). Nothing is clamped: the first violation refuses the plan.
pub fn check_plan(
    limits: &JointLimits,
    start: &Joints,
    segments: &[Segment],
) -> Result<(), PlanRefusal> {
    let mut previous = *start;
    for segment in segments {
        for (k, q) in segment.joints.iter().enumerate() {
            let refuse = |reason| PlanRefusal {
                segment: segment.name.clone(),
                t_s: k as f64 * PERIOD_S,
                reason,
            };
            limits.check_pose(q).map_err(refuse)?;
            limits.check_step(&previous, q, PERIOD_S).map_err(refuse)?;
            previous = *q;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::calibration_segments;
    use sabr_model::RobotParams;

    fn limits() -> JointLimits {
        let stops = RobotParams::nominal().joints.home_stops;
        JointLimits::from_stops(&stops, DEFAULT_RANGE_RAD, DEFAULT_MAX_SPEED_RAD_S)
    }

    fn segment(name: &str, joints: Vec<Joints>) -> Segment {
        Segment {
            name: name.into(),
            phase: true,
            joints,
            counts: None,
        }
    }

    #[test]
    fn default_box_runs_from_each_stop_into_the_workspace() {
        let stops = RobotParams::nominal().joints.home_stops;
        let limits = limits();
        limits.validate().unwrap();
        let side = stop_sides(&stops);
        for i in 0..JOINT_COUNT {
            assert!(limits.lower[i] <= HOME_JOINTS[i] && HOME_JOINTS[i] <= limits.upper[i]);
            let near_end = stops[i] + side[i] * STOP_TOLERANCE_RAD;
            assert!(
                (near_end - limits.lower[i]).abs() < 1e-12
                    || (near_end - limits.upper[i]).abs() < 1e-12
            );
            let width = DEFAULT_RANGE_RAD + STOP_TOLERANCE_RAD;
            assert!((limits.upper[i] - limits.lower[i] - width).abs() < 1e-12);
        }
        // The stops themselves are inside (homing ends there), and so is a true stop up to
        // the tolerance beyond; further is not.
        limits.check_pose(&stops).unwrap();
        let mut beyond = stops;
        beyond[2] += side[2] * (STOP_TOLERANCE_RAD - 1e-3);
        limits.check_pose(&beyond).unwrap();
        beyond[2] += side[2] * 2e-3;
        let reason = limits.check_pose(&beyond).unwrap_err();
        assert!(reason.starts_with("joint 3 at"), "{reason}");
    }

    #[test]
    fn invalid_limits_are_rejected() {
        let mut bad = limits();
        bad.lower[1] = bad.upper[1];
        assert!(bad.validate().unwrap_err().contains("joint 2"));
        let mut bad = limits();
        bad.max_speed_rad_s = f64::NAN;
        assert!(bad.validate().is_err());
        let mut bad = limits();
        bad.upper[4] = f64::INFINITY;
        assert!(bad.validate().is_err());
    }

    #[test]
    fn a_plan_leaving_the_box_is_refused_where_it_leaves() {
        let limits = limits();
        let start = HOME_JOINTS;
        let mut path: Vec<Joints> = Vec::new();
        let mut q = start;
        // Joint 4 creeps up at 0.4 rad/s (within the speed limit) until it crosses its upper
        // limit (0.05 rad beyond the stop at -2.55 rad): the refusal names the first sample
        // beyond it.
        let crossing = ((limits.upper[3] - start[3]) / (0.4 * PERIOD_S)).ceil() as usize;
        for _ in 0..crossing + 10 {
            q[3] += 0.4 * PERIOD_S;
            path.push(q);
        }
        let refusal = check_plan(&limits, &start, &[segment("excitation", path)]).unwrap_err();
        assert_eq!(refusal.segment, "excitation");
        assert!(refusal.reason.contains("joint 4") && refusal.reason.contains("upper"));
        assert!((refusal.t_s - (crossing - 1) as f64 * PERIOD_S).abs() < 1.5 * PERIOD_S);
        assert!(refusal
            .to_string()
            .starts_with("plan refused: excitation at "));
    }

    #[test]
    fn a_plan_too_fast_is_refused_and_the_first_step_counts() {
        let limits = limits();
        let start = HOME_JOINTS;
        let step = limits.max_speed_rad_s * PERIOD_S;
        let mut ok = start;
        ok[0] += 0.99 * step;
        check_plan(&limits, &start, &[segment("move", vec![ok])]).unwrap();
        let mut fast = start;
        fast[0] += 1.01 * step;
        let refusal = check_plan(&limits, &start, &[segment("move", vec![fast])]).unwrap_err();
        assert!(refusal.reason.contains("joint 1 at"), "{}", refusal.reason);
        // A jump between two segments is a step too.
        let refusal = check_plan(
            &limits,
            &start,
            &[segment("a", vec![start]), segment("b", vec![fast])],
        )
        .unwrap_err();
        assert_eq!((refusal.segment.as_str(), refusal.t_s), ("b", 0.0));
    }

    #[test]
    fn calibration_plan_is_within_the_default_limits_and_continuous() {
        let params = RobotParams::nominal();
        let stops = params.joints.home_stops;
        let limits = JointLimits::from_stops(&stops, DEFAULT_RANGE_RAD, DEFAULT_MAX_SPEED_RAD_S);
        let segments = calibration_segments(&params, 0.05, 3).unwrap();
        check_plan(&limits, &stops, &segments).unwrap();
        // A tighter speed limit than the plan's moves refuses it.
        let slow = JointLimits {
            max_speed_rad_s: 0.1,
            ..limits
        };
        let refusal = check_plan(&slow, &stops, &segments).unwrap_err();
        assert!(refusal.reason.contains("speed limit"), "{refusal}");
    }
}
