//! The simulated hardware in motion: the true robot of a `sabr-sim` session behind five motor
//! servos, and its tracker, advanced in robot time (ns since power-up).
//!
//! [`SimRig::advance`] integrates the servos up to a time with the motor setpoints held and
//! captures every tracker exposure that falls inside the step at its exact instant, so the
//! truth of a frame is the robot's state at the exposure, not at the rig's tick.

use std::f64::consts::TAU;

use sabr_model::{Counts, Joints};
use sabr_sim::{Session, SimError, TrackerEmulator, TrackerFrame, TrueRobot};

use crate::servo::ServoConfig;

/// One captured tracker exposure and the robot's true state at that instant.
#[derive(Debug, Clone, PartialEq)]
pub struct Capture {
    /// The frame as the tracker emulation produced it (robot time; arrival `None` = dropped).
    pub frame: TrackerFrame,
    /// True joint angles θ1..θ5 at the exposure, rad.
    pub joints: Joints,
    /// True motor positions at the exposure in encoder counts (before quantisation).
    pub counts: [f64; 5],
    /// True needle tip `p_n` in `Bb`, mm.
    pub tip_mm: [f64; 3],
    /// True needle direction `z_N` in `Bb` (unit).
    pub direction: [f64; 3],
}

/// The true robot, its motor servos and its tracker, at one robot time.
#[derive(Debug)]
pub struct SimRig {
    robot: TrueRobot,
    servos: [ServoConfig; 5],
    counts_per_rev: [u32; 5],
    /// Motor positions in counts (fractional).
    position: [f64; 5],
    tracker: TrackerEmulator,
    t_ns: i64,
}

impl SimRig {
    /// The rig of `session` at power-up (robot time 0, counts 0), with servos of time constant
    /// `tau_s` (s) and top motor speed `max_motor_rad_s` (rad/s).
    pub fn new(session: &Session, tau_s: f64, max_motor_rad_s: f64) -> Result<Self, String> {
        let truth = session.robot_truth().clone();
        let counts_per_rev = truth.params.joints.counts_per_rev;
        let mut servos = [ServoConfig::new(tau_s, max_motor_rad_s, 1)?; 5];
        for (servo, cpr) in servos.iter_mut().zip(counts_per_rev) {
            *servo = ServoConfig::new(tau_s, max_motor_rad_s, cpr)?;
        }
        Ok(SimRig {
            robot: TrueRobot::new(truth),
            servos,
            counts_per_rev,
            position: [0.0; 5],
            tracker: session.tracker_emulator(),
            t_ns: 0,
        })
    }

    /// Robot time of the current state, ns since power-up.
    pub fn time_ns(&self) -> i64 {
        self.t_ns
    }

    /// The counter register: quantised counts of the true motor angles.
    pub fn counts(&self) -> Counts {
        self.robot.counts()
    }

    /// The true motor positions in counts (fractional, before quantisation).
    pub fn true_counts(&self) -> [f64; 5] {
        self.position
    }

    /// Motor setpoint in counts that puts the true robot's paper joints at `q` (rad): what a
    /// planner that knew the true gear ratios would command (the autoplay plan).
    pub fn counts_for_joints(&self, q: &Joints) -> [f64; 5] {
        let motor = self.robot.truth().motor_for_joints(q);
        std::array::from_fn(|i| motor[i] * f64::from(self.counts_per_rev[i]) / TAU)
    }

    /// Advances to robot time `t_ns` with the motor setpoints `target` (counts) held, capturing
    /// every tracker exposure up to `t_ns`; `tip_attached(t)` says whether the tip sphere is on
    /// the needle at exposure time `t`. A time in the past changes nothing.
    pub fn advance(
        &mut self,
        t_ns: i64,
        target: &[f64; 5],
        tip_attached: impl Fn(i64) -> bool,
    ) -> Result<Vec<Capture>, SimError> {
        let mut captures = Vec::new();
        while self.tracker.next_exposure().exposure_ns <= t_ns {
            let exposure_ns = self.tracker.next_exposure().exposure_ns;
            self.move_to(exposure_ns, target);
            captures.push(self.capture(tip_attached(exposure_ns))?);
        }
        self.move_to(t_ns, target);
        Ok(captures)
    }

    fn move_to(&mut self, t_ns: i64, target: &[f64; 5]) {
        if t_ns <= self.t_ns {
            return;
        }
        let dt_s = (t_ns - self.t_ns) as f64 * 1e-9;
        let motor: Joints = std::array::from_fn(|i| {
            let position = self.servos[i].step(self.position[i], target[i], dt_s);
            position * TAU / f64::from(self.counts_per_rev[i])
        });
        // The true robot stops a motor whose joint runs into its mechanical stop.
        self.robot.command(t_ns, &motor);
        let actual = self.robot.motor_angles();
        self.position =
            std::array::from_fn(|i| actual[i] * f64::from(self.counts_per_rev[i]) / TAU);
        self.t_ns = t_ns;
    }

    fn capture(&mut self, tip_attached: bool) -> Result<Capture, SimError> {
        let unreachable =
            |robot: &TrueRobot, error: sabr_model::KinematicsError| SimError::Unreachable {
                t_s: robot.time_ns() as f64 * 1e-9,
                joints: robot.joints(),
                reason: error.to_string(),
            };
        let tools = self
            .robot
            .tool_poses()
            .map_err(|e| unreachable(&self.robot, e))?;
        let pose = self.robot.pose().map_err(|e| unreachable(&self.robot, e))?;
        let frame = self.tracker.capture(&tools, tip_attached);
        Ok(Capture {
            frame,
            joints: self.robot.joints(),
            counts: self.position,
            tip_mm: [pose.tip.x, pose.tip.y, pose.tip.z],
            direction: [pose.direction.x, pose.direction.y, pose.direction.z],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sabr_sim::{quantise_counts, SimConfig};

    /// Counts of fractional motor positions, as the counter hardware reports them.
    fn quantise(position: &[f64; 5], counts_per_rev: &[u32; 5]) -> Counts {
        let motor: Joints =
            std::array::from_fn(|i| position[i] * TAU / f64::from(counts_per_rev[i]));
        quantise_counts(&motor, counts_per_rev)
    }

    fn session() -> Session {
        let mut config = SimConfig::new(7);
        config.duration_scale = 0.02;
        Session::new(&config).unwrap()
    }

    #[test]
    fn counters_are_the_rounded_true_positions() {
        let session = session();
        let mut rig = SimRig::new(&session, 0.005, 50.0).unwrap();
        let cpr = session.robot_truth().params.joints.counts_per_rev;
        let mut t = 0;
        let mut moved = [false; 5];
        for step in 0..400 {
            t += 500_000;
            // A wandering setpoint, a few hundred counts peak.
            let target: [f64; 5] =
                std::array::from_fn(|i| 300.0 * ((step as f64) * 0.02 + i as f64).sin());
            rig.advance(t, &target, |_| false).unwrap();
            let truth = rig.true_counts();
            let counts = rig.counts();
            assert_eq!(counts, quantise(&truth, &cpr));
            for i in 0..5 {
                assert!((counts[i] as f64 - truth[i]).abs() <= 0.5 + 1e-9);
                moved[i] |= counts[i].abs() > 10;
            }
        }
        assert_eq!(moved, [true; 5], "every motor followed its setpoint");
    }

    #[test]
    fn exposures_are_captured_at_their_own_instants() {
        let session = session();
        let mut rig = SimRig::new(&session, 0.0, 1e9).unwrap();
        let mut reference = SimRig::new(&session, 0.0, 1e9).unwrap();
        let target = [200.0, -150.0, 400.0, 120.0, -80.0];
        // One big step versus 1 ms ticks: the same exposures at the same states.
        let coarse = rig.advance(1_000_000_000, &target, |_| false).unwrap();
        let mut fine = Vec::new();
        for k in 1..=1000 {
            fine.extend(
                reference
                    .advance(k * 1_000_000, &target, |_| false)
                    .unwrap(),
            );
        }
        assert_eq!(coarse.len(), fine.len());
        assert!(
            (19..=21).contains(&coarse.len()),
            "{} frames in 1 s",
            coarse.len()
        );
        for (a, b) in coarse.iter().zip(&fine) {
            assert_eq!(a.frame.exposure, b.frame.exposure);
            assert_eq!(a.counts, b.counts);
            assert!(a.frame.exposure.exposure_ns <= 1_000_000_000);
        }
        let frames: Vec<u32> = coarse.iter().map(|c| c.frame.exposure.frame).collect();
        assert!(frames.windows(2).all(|w| w[1] == w[0] + 1));
    }

    #[test]
    fn truth_of_a_capture_is_the_state_at_the_exposure() {
        let session = session();
        let mut rig = SimRig::new(&session, 0.02, 50.0).unwrap();
        let target = [500.0; 5];
        let captures = rig.advance(300_000_000, &target, |_| true).unwrap();
        let first = &captures[0];
        let exposure = first.frame.exposure.exposure_ns;
        // Replaying to the exposure instant alone gives the same motor positions.
        let mut replay = SimRig::new(&session, 0.02, 50.0).unwrap();
        replay.advance(exposure - 1, &target, |_| true).unwrap();
        replay.move_to(exposure, &target);
        for (a, b) in replay.true_counts().iter().zip(&first.counts) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
        // Counts and joints agree through the true gear ratios and offsets.
        let truth = session.robot_truth();
        let motor: Joints = std::array::from_fn(|i| {
            first.counts[i] * TAU / f64::from(truth.params.joints.counts_per_rev[i])
        });
        let paper = truth.paper_joints(&motor);
        for (p, q) in paper.iter().zip(&first.joints) {
            assert!((p - q).abs() < 1e-9, "{p} vs {q}");
        }
        let z = first.direction;
        assert!(((z[0] * z[0] + z[1] * z[1] + z[2] * z[2]).sqrt() - 1.0).abs() < 1e-9);
        // The tip sphere is reported while attached.
        assert!(captures.iter().any(|c| matches!(
            c.frame.readings[3].1,
            sabr_recording::ToolReading::Point { .. }
        )));
    }

    #[test]
    fn joints_setpoint_round_trips_through_the_true_robot() {
        let session = session();
        let rig = SimRig::new(&session, 0.0, 1e9).unwrap();
        let power_up = session.robot_truth().power_up_joints;
        let counts = rig.counts_for_joints(&power_up);
        assert!(counts.iter().all(|c| c.abs() < 1e-9), "{counts:?}");
        let mut q = power_up;
        q[2] += 0.01;
        let counts = rig.counts_for_joints(&q);
        let expected = 0.01 / session.robot_truth().params.joints.gear_ratio[2] * 4000.0 / TAU;
        assert!(
            (counts[2] - expected).abs() < 1e-6,
            "{counts:?} vs {expected}"
        );
    }
}
