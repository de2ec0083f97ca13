//! Homing into the mechanical stops: every joint is driven towards its stop at a constant
//! speed until its encoder shows it stalled, then held there; once all are stalled the robot
//! dwells, and the counts at the stops give the joint offsets (docs/robot-model.md §2).

use crate::limits::stop_sides;
use sabr_model::{Counts, Joints, RobotParams, JOINT_COUNT};
use std::collections::VecDeque;
use std::f64::consts::TAU;

/// A joint counts as stalled when, over the stall window, its encoder moved less than this
/// share of the commanded motion.
const STALL_RATIO: f64 = 0.25;

/// How homing moves and decides.
#[derive(Debug, Clone, PartialEq)]
pub struct HomingConfig {
    /// Joint speed towards the stops (rad/s).
    pub speed_rad_s: f64,
    /// Largest commanded travel of a joint before homing gives up (rad).
    pub max_travel_rad: f64,
    /// Dwell at the stops once all joints stalled (s).
    pub dwell_s: f64,
    /// Window over which a stall is judged (s).
    pub stall_window_s: f64,
}

impl Default for HomingConfig {
    /// 0.1 rad/s, at most 0.6 rad of travel, 5 s dwell, 100 ms stall window.
    fn default() -> Self {
        Self {
            speed_rad_s: 0.1,
            max_travel_rad: 0.6,
            dwell_s: 5.0,
            stall_window_s: 0.1,
        }
    }
}

impl HomingConfig {
    /// Checks that every value is a positive number.
    pub fn validate(&self) -> Result<(), String> {
        for (name, value) in [
            ("homing speed", self.speed_rad_s),
            ("homing travel", self.max_travel_rad),
            ("homing dwell", self.dwell_s),
            ("stall window", self.stall_window_s),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!("the {name} must be a positive number, got {value}"));
            }
        }
        Ok(())
    }
}

/// What homing commands at one instant.
#[derive(Debug, Clone, PartialEq)]
pub enum HomingStep {
    /// Moving towards the stops: the setpoint (counts).
    Approach([f64; JOINT_COUNT]),
    /// All joints at their stops, dwelling: the setpoint (counts).
    Dwell([f64; JOINT_COUNT]),
    /// Finished: the counts at the stops and the dwell (host ns).
    Done {
        /// Encoder counts at the stops at the end of the dwell.
        stop_counts: Counts,
        /// Start of the dwell.
        dwell_start_ns: i64,
        /// End of the dwell.
        dwell_end_ns: i64,
    },
    /// Homing failed (a stop was not found).
    Failed(String),
}

/// The homing state machine, on explicit host times and encoder readings.
#[derive(Debug, Clone)]
pub struct Homing {
    config: HomingConfig,
    /// Counts per second of each joint's approach (signed towards its stop).
    rate: [f64; JOINT_COUNT],
    start_ns: i64,
    start: [f64; JOINT_COUNT],
    command: [f64; JOINT_COUNT],
    stalled: [bool; JOINT_COUNT],
    /// (time, command, encoder) over the last stall window.
    history: VecDeque<(i64, [f64; JOINT_COUNT], Counts)>,
    dwell_start_ns: Option<i64>,
}

impl Homing {
    /// Starts homing at `now_ns` from the encoder reading `encoder`.
    pub fn new(params: &RobotParams, config: HomingConfig, now_ns: i64, encoder: Counts) -> Self {
        let side = stop_sides(&params.joints.home_stops);
        let joints = &params.joints;
        let rate = std::array::from_fn(|i| {
            let counts_per_rad = f64::from(joints.counts_per_rev[i]) / (TAU * joints.gear_ratio[i]);
            side[i] * counts_per_rad * config.speed_rad_s
        });
        let start = encoder.map(|c| c as f64);
        Self {
            config,
            rate,
            start_ns: now_ns,
            start,
            command: start,
            stalled: [false; JOINT_COUNT],
            history: VecDeque::new(),
            dwell_start_ns: None,
        }
    }

    /// Advances to `now_ns` with the latest encoder reading.
    pub fn step(&mut self, now_ns: i64, encoder: Counts) -> HomingStep {
        let elapsed_s = (now_ns - self.start_ns) as f64 * 1e-9;
        if self.dwell_start_ns.is_none() {
            let travel = self.config.speed_rad_s * elapsed_s;
            if travel > self.config.max_travel_rad {
                let missing: Vec<String> = (0..JOINT_COUNT)
                    .filter(|&i| !self.stalled[i])
                    .map(|i| (i + 1).to_string())
                    .collect();
                return HomingStep::Failed(format!(
                    "homing: joint(s) {} found no stop within {} rad",
                    missing.join(", "),
                    self.config.max_travel_rad
                ));
            }
            for i in 0..JOINT_COUNT {
                if !self.stalled[i] {
                    self.command[i] = self.start[i] + self.rate[i] * elapsed_s;
                }
            }
            self.detect_stalls(now_ns, encoder);
        }
        if self.stalled.iter().all(|&s| s) {
            let dwell_start_ns = *self.dwell_start_ns.get_or_insert(now_ns);
            if (now_ns - dwell_start_ns) as f64 * 1e-9 >= self.config.dwell_s {
                return HomingStep::Done {
                    stop_counts: encoder,
                    dwell_start_ns,
                    dwell_end_ns: now_ns,
                };
            }
            return HomingStep::Dwell(self.command);
        }
        HomingStep::Approach(self.command)
    }

    fn detect_stalls(&mut self, now_ns: i64, encoder: Counts) {
        let window_ns = (self.config.stall_window_s * 1e9) as i64;
        self.history.push_back((now_ns, self.command, encoder));
        while self
            .history
            .get(1)
            .is_some_and(|(t, _, _)| now_ns - t >= window_ns)
        {
            self.history.pop_front();
        }
        let Some(&(then_ns, then_command, then_encoder)) = self.history.front() else {
            return;
        };
        if now_ns - then_ns < window_ns {
            return;
        }
        for i in 0..JOINT_COUNT {
            if self.stalled[i] {
                continue;
            }
            let side = self.rate[i].signum();
            let commanded = side * (self.command[i] - then_command[i]);
            let moved = side * (encoder[i] - then_encoder[i]) as f64;
            if commanded > 0.0 && moved < STALL_RATIO * commanded {
                self.stalled[i] = true;
                self.command[i] = encoder[i] as f64;
                tracing::info!(
                    joint = i + 1,
                    counts = encoder[i],
                    "homing: joint stalled at its stop"
                );
            }
        }
    }
}

/// Joint offsets θ_off = home_stops − GR·θ_enc(stop counts) (rad): at the stops the model's
/// joints are the nominal stops.
pub fn offsets_from_stops(params: &RobotParams, stop_counts: &Counts) -> Joints {
    let motor = params.motor_angles(stop_counts);
    std::array::from_fn(|i| params.joints.home_stops[i] - params.joints.gear_ratio[i] * motor[i])
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use sabr_model::JointMotion;
    use sabr_sim::{Perturbation, RobotTruth, TrueRobot};

    const MS: i64 = 1_000_000;

    fn true_robot(seed: u64) -> TrueRobot {
        let nominal = RobotParams::nominal();
        let centre = sabr_model::plan::excitation_centre(
            &nominal.joints.home_stops,
            &sabr_model::HOME_JOINTS,
        );
        let truth = RobotTruth::sample(
            &nominal,
            &Perturbation::default(),
            &centre,
            &[],
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed),
        )
        .unwrap();
        TrueRobot::new(truth)
    }

    /// Runs homing against a simulated robot whose motors follow the setpoint with a
    /// one-period lag; returns the result and the robot.
    fn home(seed: u64, config: HomingConfig) -> (HomingStep, TrueRobot, Vec<HomingStep>) {
        let params = RobotParams::nominal();
        let mut robot = true_robot(seed);
        let cpr = params.joints.counts_per_rev;
        let mut homing = Homing::new(&params, config, 0, robot.counts());
        let mut steps = Vec::new();
        let mut t = 0;
        loop {
            t += MS;
            let step = homing.step(t, robot.counts());
            match &step {
                HomingStep::Approach(target) | HomingStep::Dwell(target) => {
                    let motor: Joints =
                        std::array::from_fn(|i| target[i] * TAU / f64::from(cpr[i]));
                    robot.command(t, &motor);
                }
                _ => return (step, robot, steps),
            }
            steps.push(step);
        }
    }

    #[test]
    fn finds_the_true_stops_and_gives_offsets_that_put_them_at_the_nominal_stops() {
        for seed in [1, 2, 3] {
            let config = HomingConfig {
                dwell_s: 0.5,
                ..HomingConfig::default()
            };
            let (step, robot, steps) = home(seed, config.clone());
            let HomingStep::Done {
                stop_counts,
                dwell_start_ns,
                dwell_end_ns,
            } = step
            else {
                panic!("homing did not finish: {step:?}");
            };
            assert_eq!(stop_counts, robot.counts());
            assert!(((dwell_end_ns - dwell_start_ns) as f64 * 1e-9 - config.dwell_s).abs() < 2e-3);
            // Every joint is at its true stop.
            let truth = robot.truth();
            let joints = robot.paper_joints();
            for (i, (joint, stop)) in joints.iter().zip(&truth.stops).enumerate() {
                assert!((joint - stop).abs() < 1e-3, "seed {seed} joint {i}");
            }
            // The offsets map the stop counts to the nominal stops.
            let mut params = RobotParams::nominal();
            params.joints.offset = Some(offsets_from_stops(&params, &stop_counts));
            let q = params
                .joints_from_counts(&stop_counts, &JointMotion::default())
                .unwrap();
            for (joint, stop) in q.iter().zip(&params.joints.home_stops) {
                assert!((joint - stop).abs() < 1e-12);
            }
            // No commanded step towards a stop is faster than the homing speed (a stalled
            // joint's command falls back to its encoder), and the robot dwelt.
            let ratio = params.joints.gear_ratio;
            let side = stop_sides(&params.joints.home_stops);
            let commands: Vec<&[f64; 5]> = steps
                .iter()
                .map(|s| match s {
                    HomingStep::Approach(c) | HomingStep::Dwell(c) => c,
                    other => panic!("unexpected {other:?}"),
                })
                .collect();
            for pair in commands.windows(2) {
                for i in 0..JOINT_COUNT {
                    let joint_step = side[i] * (pair[1][i] - pair[0][i]) * TAU * ratio[i]
                        / f64::from(params.joints.counts_per_rev[i]);
                    assert!(joint_step <= config.speed_rad_s * 1e-3 * (1.0 + 1e-9) + 1e-9);
                }
            }
            assert!(steps.iter().any(|s| matches!(s, HomingStep::Dwell(_))));
        }
    }

    #[test]
    fn a_joint_that_never_stalls_fails_homing_after_the_travel_limit() {
        let params = RobotParams::nominal();
        let config = HomingConfig {
            max_travel_rad: 0.05,
            ..HomingConfig::default()
        };
        let mut homing = Homing::new(&params, config, 0, [0; 5]);
        let cpr = params.joints.counts_per_rev;
        let ratio = params.joints.gear_ratio;
        let mut t = 0;
        loop {
            t += MS;
            // An ideal encoder following the command: no joint ever stalls.
            let elapsed = t as f64 * 1e-9;
            let side = stop_sides(&params.joints.home_stops);
            let encoder: Counts = std::array::from_fn(|i| {
                (side[i] * 0.1 * elapsed * f64::from(cpr[i]) / (TAU * ratio[i])).round() as i64
            });
            match homing.step(t, encoder) {
                HomingStep::Failed(reason) => {
                    assert!(reason.contains("joint(s) 1, 2, 3, 4, 5"), "{reason}");
                    assert!((elapsed - 0.5).abs() < 2e-3, "failed after {elapsed} s");
                    return;
                }
                HomingStep::Approach(_) => {}
                other => panic!("unexpected {other:?}"),
            }
        }
    }

    #[test]
    fn invalid_config_is_rejected() {
        let bad = HomingConfig {
            speed_rad_s: 0.0,
            ..HomingConfig::default()
        };
        assert!(bad.validate().unwrap_err().contains("homing speed"));
        HomingConfig::default().validate().unwrap();
    }
}
