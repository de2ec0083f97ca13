//! Command line of `sabr-motion` and what it turns into: parameters, limits, tasks.

use crate::executor::{ExecutorConfig, LineConfig, Task};
use crate::homing::HomingConfig;
use crate::limits::{check_plan, JointLimits, DEFAULT_MAX_SPEED_RAD_S, DEFAULT_RANGE_RAD};
use crate::plan::calibration_segments;
use anyhow::{bail, Context};
use sabr_model::plan::PlanDurations;
use sabr_model::{Joints, RobotParams};
use std::path::PathBuf;

/// A session the executor can run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Session {
    /// Homing into the mechanical stops (sets the joint offsets).
    Homing,
    /// Homing, excitation, tip phase and validation poses (the calibration recording).
    Calibration,
    /// Straight-line insertion through the IK server; after `calibration` it waits for the
    /// calibrator's new parameter set.
    Line,
}

/// The motion executor of the SABR graph: runs sessions as 1 kHz motor setpoints on
/// `sabr/motion/setpoints`, announces phases and status, enforces joint and speed limits on
/// the whole plan before moving, and stops the robot when encoder or tracker feedback goes
/// stale.
#[derive(Debug, clap::Parser)]
#[command(name = "sabr-motion", version, about)]
pub struct Args {
    /// Sessions to run, in order (comma-separated).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "calibration")]
    pub session: Vec<Session>,
    /// Robot parameters: a robot.toml, or a calibrated params.toml (its joint offsets are then
    /// in force, version 0, as for `sabr-ik --params`). Default: the nominal model.
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// Multiplies the phase durations of the calibration session (1 ≈ 5 minutes).
    #[arg(long, default_value_t = 1.0)]
    pub duration_scale: f64,
    /// Seed of the calibration plan's random choices (multi-sine phases, validation poses).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Lower joint limits θ1..θ5 (rad, comma-separated). Default box: from 0.05 rad beyond
    /// each nominal stop (the true stops differ by up to about 2°) to --joint-range from the
    /// stop into the workspace.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub joint_lower: Option<Vec<f64>>,
    /// Upper joint limits θ1..θ5 (rad, comma-separated).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub joint_upper: Option<Vec<f64>>,
    /// Travel of each joint from its nominal stop into the workspace for the default limits (rad).
    #[arg(long, default_value_t = DEFAULT_RANGE_RAD)]
    pub joint_range: f64,
    /// Highest joint speed of any plan (rad/s).
    #[arg(long, default_value_t = DEFAULT_MAX_SPEED_RAD_S)]
    pub max_joint_speed: f64,
    /// Joint speed while homing towards the stops (rad/s).
    #[arg(long, default_value_t = HomingConfig::default().speed_rad_s)]
    pub homing_speed: f64,
    /// Largest travel towards a stop before homing gives up (rad).
    #[arg(long, default_value_t = HomingConfig::default().max_travel_rad)]
    pub homing_travel: f64,
    /// Staleness deadline of the encoder stream (ms).
    #[arg(long, default_value_t = 20.0)]
    pub encoder_deadline_ms: f64,
    /// Staleness deadline of the tracker stream (ms).
    #[arg(long, default_value_t = 200.0)]
    pub tracker_deadline_ms: f64,
    /// Do not require or watch tracker frames (e.g. a rig without a tracker).
    #[arg(long)]
    pub ignore_tracker: bool,
    /// How long to wait for the first encoder sample and tracker frame (s).
    #[arg(long, default_value_t = 30.0)]
    pub feedback_timeout_s: f64,
    /// How long `line` after `calibration` waits for the new parameter set (s).
    #[arg(long, default_value_t = 300.0)]
    pub parameters_timeout_s: f64,
    /// Start tip of the line in Bb (mm, comma-separated); default: centred on the excitation
    /// centre's tip, along its needle.
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        requires = "line_direction"
    )]
    pub line_start: Option<Vec<f64>>,
    /// Direction of the line and of the needle along it (Bb, comma-separated, any length but zero).
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        requires = "line_start"
    )]
    pub line_direction: Option<Vec<f64>>,
    /// Length of the line (mm).
    #[arg(long, default_value_t = 20.0)]
    pub line_length_mm: f64,
    /// Peak tip speed along the line (mm/s).
    #[arg(long, default_value_t = 5.0)]
    pub line_speed_mm_s: f64,
    /// Dwell before and after the line (s).
    #[arg(long, default_value_t = 0.5)]
    pub line_dwell_s: f64,
    /// Timeout of one IK request (ms).
    #[arg(long, default_value_t = 20.0)]
    pub ik_timeout_ms: f64,
    /// When the sessions are done, announce the graph's job done (the launcher then stops
    /// the graph with success). Otherwise the node stays, holding, until stopped.
    #[arg(long)]
    pub finish_when_done: bool,
    /// On a fault (stale feedback, refused plan, failed homing) exit with a failure at once
    /// instead of holding until stopped.
    #[arg(long)]
    pub exit_on_fault: bool,
}

fn five(values: &[f64], name: &str) -> anyhow::Result<Joints> {
    values
        .try_into()
        .with_context(|| format!("--{name} needs 5 values, got {}", values.len()))
}

fn three(values: &Option<Vec<f64>>, name: &str) -> anyhow::Result<Option<[f64; 3]>> {
    values
        .as_deref()
        .map(|v| {
            v.try_into()
                .with_context(|| format!("--{name} needs 3 values, got {}", v.len()))
        })
        .transpose()
}

fn ms_to_ns(ms: f64, name: &str) -> anyhow::Result<i64> {
    if !(ms.is_finite() && ms > 0.0) {
        bail!("--{name} must be a positive number, got {ms}");
    }
    Ok((ms * 1e6).round() as i64)
}

impl Args {
    /// The robot parameters (`--params`, else nominal).
    pub fn robot_params(&self) -> anyhow::Result<RobotParams> {
        match &self.params {
            Some(path) => Ok(sabr_model::read_params_file(path)?),
            None => Ok(RobotParams::nominal()),
        }
    }

    /// The joint limits: the default box from the stops, with given bounds replacing it.
    pub fn limits(&self, params: &RobotParams) -> anyhow::Result<JointLimits> {
        let mut limits = JointLimits::from_stops(
            &params.joints.home_stops,
            self.joint_range,
            self.max_joint_speed,
        );
        if let Some(lower) = &self.joint_lower {
            limits.lower = five(lower, "joint-lower")?;
        }
        if let Some(upper) = &self.joint_upper {
            limits.upper = five(upper, "joint-upper")?;
        }
        limits.validate().map_err(anyhow::Error::msg)?;
        Ok(limits)
    }

    /// The executor's configuration.
    pub fn executor_config(&self, limits: JointLimits) -> anyhow::Result<ExecutorConfig> {
        let durations = PlanDurations::default().scaled(self.duration_scale);
        let homing = HomingConfig {
            speed_rad_s: self.homing_speed,
            max_travel_rad: self.homing_travel,
            dwell_s: durations.homing_dwell_s,
            ..HomingConfig::default()
        };
        homing.validate().map_err(anyhow::Error::msg)?;
        if homing.speed_rad_s > limits.max_speed_rad_s {
            bail!(
                "--homing-speed {} rad/s is above the speed limit {} rad/s",
                homing.speed_rad_s,
                limits.max_speed_rad_s
            );
        }
        let start = three(&self.line_start, "line-start")?;
        let direction = three(&self.line_direction, "line-direction")?;
        Ok(ExecutorConfig {
            limits,
            homing,
            encoder_deadline_ns: ms_to_ns(self.encoder_deadline_ms, "encoder-deadline-ms")?,
            tracker_deadline_ns: if self.ignore_tracker {
                None
            } else {
                Some(ms_to_ns(self.tracker_deadline_ms, "tracker-deadline-ms")?)
            },
            feedback_timeout_ns: ms_to_ns(self.feedback_timeout_s * 1e3, "feedback-timeout-s")?,
            parameters_timeout_ns: ms_to_ns(
                self.parameters_timeout_s * 1e3,
                "parameters-timeout-s",
            )?,
            line: LineConfig {
                start_and_direction: start.zip(direction),
                length_mm: self.line_length_mm,
                speed_mm_s: self.line_speed_mm_s,
                dwell_s: self.line_dwell_s,
            },
            ik_requests_per_period: sabr_msgs::IK_REQUESTS_PER_SETPOINT_PERIOD,
        })
    }

    /// The tasks of the sessions, in order. The calibration plan is built and checked
    /// against `limits` here, before anything moves: a plan out of limits is an error.
    pub fn tasks(&self, params: &RobotParams, limits: &JointLimits) -> anyhow::Result<Vec<Task>> {
        if self.session.is_empty() {
            bail!("--session names no session");
        }
        let mut tasks = Vec::new();
        let mut calibrated_before = false;
        for session in &self.session {
            match session {
                Session::Homing => tasks.push(Task::Home),
                Session::Calibration => {
                    let segments = calibration_segments(params, self.duration_scale, self.seed)
                        .map_err(anyhow::Error::msg)?;
                    check_plan(limits, &params.joints.home_stops, &segments)?;
                    tasks.push(Task::Home);
                    tasks.push(Task::Play(segments));
                    calibrated_before = true;
                }
                Session::Line => {
                    if calibrated_before {
                        tasks.push(Task::AwaitParameters);
                    }
                    tasks.push(Task::PlanLine);
                }
            }
        }
        Ok(tasks)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    fn args(extra: &[&str]) -> Args {
        let mut all = vec!["sabr-motion"];
        all.extend_from_slice(extra);
        Args::try_parse_from(all).unwrap()
    }

    #[test]
    fn sessions_become_tasks_and_the_line_waits_for_calibration() {
        let params = RobotParams::nominal();
        let a = args(&["--session", "calibration,line", "--duration-scale", "0.02"]);
        let limits = a.limits(&params).unwrap();
        let tasks = a.tasks(&params, &limits).unwrap();
        assert!(matches!(
            tasks.as_slice(),
            [
                Task::Home,
                Task::Play(_),
                Task::AwaitParameters,
                Task::PlanLine
            ]
        ));
        let a = args(&["--session", "line"]);
        assert_eq!(a.tasks(&params, &limits).unwrap(), vec![Task::PlanLine]);
    }

    #[test]
    fn an_out_of_limit_calibration_plan_is_refused_when_the_tasks_are_made() {
        let params = RobotParams::nominal();
        let a = args(&["--duration-scale", "0.02", "--joint-range", "0.3"]);
        let limits = a.limits(&params).unwrap();
        let error = a.tasks(&params, &limits).unwrap_err().to_string();
        assert!(error.starts_with("plan refused"), "{error}");
        assert!(
            error.contains("lower limit") || error.contains("upper limit"),
            "{error}"
        );
    }

    #[test]
    fn limits_and_numbers_are_validated() {
        let params = RobotParams::nominal();
        let a = args(&[
            "--joint-lower",
            "-3,-0.9,-0.2,-3.3,-0.75",
            "--joint-upper",
            "-2.2,-0.1,0.6,-2.55,0.05",
        ]);
        let limits = a.limits(&params).unwrap();
        assert_eq!(limits.lower[0], -3.0);
        assert_eq!(limits.upper[4], 0.05);
        let a = args(&["--joint-upper", "-3.5,-0.1,0.6,-2.55,0.05"]);
        assert!(a
            .limits(&params)
            .unwrap_err()
            .to_string()
            .contains("joint 1"));
        let a = args(&["--joint-lower", "1,2"]);
        assert!(a
            .limits(&params)
            .unwrap_err()
            .to_string()
            .contains("needs 5 values"));
        let a = args(&["--homing-speed", "0.9"]);
        let limits = a.limits(&params).unwrap();
        assert!(a.executor_config(limits).is_err());
        let a = args(&["--encoder-deadline-ms", "0"]);
        let limits = a.limits(&params).unwrap();
        assert!(a.executor_config(limits).is_err());
        assert!(Args::try_parse_from(["sabr-motion", "--line-start", "0,-90,180"]).is_err());
    }
}
