//! An offline session: sample the truth, build the plan, drive the true robot through it
//! and record the encoder and tracker streams as a [`Recording`] together with the [`Truth`].
//!
//! The offline session polls no device: a tracker frame is recorded at the instant it becomes
//! available (exposure + latency + jitter, the emulator's `arrival_ns`), as both its
//! availability stamp `t_ns` and its arrival stamp `arrival_t_ns`. That is what the live
//! driver's availability estimate is on average (the midpoint of the polls around the instant,
//! unbiased); the live arrival stamp is later by the wait for a poll and one serial exchange,
//! which the offline session does not model.

use std::path::PathBuf;

use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sabr_model::kinematics::HOME_JOINTS;
use sabr_model::plan::{excitation_centre, PlanDurations, SessionPlan};
use sabr_model::{Counts, Joints, RobotParams};
use sabr_recording::{EncoderRow, PhaseRow, Recording, TrackerRow};

use crate::effect_spec::SimEffect;
use crate::encoder::{EncoderClock, EncoderConfig};
use crate::tracker::{TrackerConfig, TrackerEmulator, TrackerTruth};
use crate::truth::{Perturbation, RobotTruth, TrueRobot};
use crate::SimError;

/// Everything that defines a simulated session. Same config → identical output.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// Seed of every random choice.
    pub seed: u64,
    /// Multiplies the phase durations (1 ≈ 5 minutes of robot time).
    pub duration_scale: f64,
    /// Injected effects (none by default).
    pub effects: Vec<SimEffect>,
    /// The nominal model (written as `robot.toml`).
    pub nominal: RobotParams,
    /// How far the true robot is from nominal.
    pub perturbation: Perturbation,
    /// Phase durations at scale 1.
    pub durations: PlanDurations,
    /// Encoder sampling.
    pub encoder: EncoderConfig,
    /// Tracker emulation.
    pub tracker: TrackerConfig,
}

impl SimConfig {
    /// The default session for `seed`: nominal robot, issue-3 perturbations, no effects.
    pub fn new(seed: u64) -> Self {
        SimConfig {
            seed,
            duration_scale: 1.0,
            effects: Vec::new(),
            nominal: RobotParams::nominal(),
            perturbation: Perturbation::default(),
            durations: PlanDurations::default(),
            encoder: EncoderConfig::default(),
            tracker: TrackerConfig::default(),
        }
    }

    fn validate(&self) -> Result<(), SimError> {
        if !(self.duration_scale.is_finite() && self.duration_scale > 0.0) {
            return Err(SimError::Config(format!(
                "duration scale must be a positive number, got {}",
                self.duration_scale
            )));
        }
        if self.duration_scale > MAX_DURATION_SCALE {
            return Err(SimError::Config(format!(
                "duration scale {} is above the limit {MAX_DURATION_SCALE}",
                self.duration_scale
            )));
        }
        for (index, effect) in self.effects.iter().enumerate() {
            let name = match effect {
                SimEffect::TrackerLatency { .. } => "latency",
                SimEffect::NeedleSag { .. } => "sag",
                SimEffect::TrackerClockDrift { .. } => "clockdrift",
                _ => continue,
            };
            let kind = std::mem::discriminant(effect);
            if self.effects[..index]
                .iter()
                .any(|e| std::mem::discriminant(e) == kind)
            {
                return Err(SimError::Config(format!(
                    "the {name} effect is given more than once"
                )));
            }
        }
        let rate = self.tracker.rate_hz;
        if !(rate.is_finite() && rate > 0.0) || self.tracker.frame_increment == 0 {
            return Err(SimError::Config(
                "tracker rate must be positive and the frame increment at least 1".into(),
            ));
        }
        Ok(())
    }
}

/// Largest accepted duration scale (≈ 100 minutes of robot time).
const MAX_DURATION_SCALE: f64 = 20.0;

/// Independent random streams, so that changing one part (e.g. an effect) leaves the others.
#[derive(Clone, Copy)]
enum Stream {
    Robot = 1,
    Plan = 2,
    Encoder = 3,
    Tracker = 4,
    TrackerSession = 5,
    HostClock = 6,
}

fn stream(seed: u64, which: Stream) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(which as u64);
    rng
}

/// True pose of the robot during one validation hold (host time).
#[derive(Debug, Clone, PartialEq)]
pub struct ValidationTruth {
    /// Start of the hold (host ns).
    pub t_start_ns: i64,
    /// End of the hold (host ns).
    pub t_end_ns: i64,
    /// True tip in `Bb` (mm) at the middle of the hold.
    pub tip: Point3<f64>,
    /// True needle direction `z_N` in `Bb` (unit).
    pub direction: Vector3<f64>,
    /// True joint angles (rad).
    pub joints: Joints,
    /// Encoder counts.
    pub counts: Counts,
}

/// Timing truth of one tracker frame (host time).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameTruth {
    /// Frame counter.
    pub frame: u32,
    /// Exposure instant (host ns).
    pub exposure_ns: i64,
    /// Arrival stamp (host ns), `None` if the frame was dropped.
    pub arrival_ns: Option<i64>,
}

/// What only tests and reports may know about a session.
#[derive(Debug, Clone, PartialEq)]
pub struct Truth {
    /// The true robot.
    pub robot: RobotTruth,
    /// The injected effects.
    pub effects: Vec<SimEffect>,
    /// The tracker's truth (pose `T_S_M`, latency, clock).
    pub tracker: TrackerTruth,
    /// Host clock at power-up (ns): host time = robot time + this.
    pub host_start_ns: i64,
    /// True tip poses at the validation holds.
    pub validation: Vec<ValidationTruth>,
    /// Exposure and arrival of every tracker frame, dropped ones included.
    pub frames: Vec<FrameTruth>,
}

/// A prepared session: truth sampled, plan built and checked; nothing recorded yet.
#[derive(Debug, Clone)]
pub struct Session {
    config: SimConfig,
    robot: RobotTruth,
    tracker: TrackerTruth,
    plan: SessionPlan,
    host_start_ns: i64,
}

impl Session {
    /// Samples the truth and builds the plan; errors on an invalid config or a plan that
    /// leaves the reachable workspace.
    pub fn new(config: &SimConfig) -> Result<Self, SimError> {
        config.validate()?;
        let nominal = &config.nominal;
        let centre = excitation_centre(&nominal.joints.home_stops, &HOME_JOINTS);
        let robot = RobotTruth::sample(
            nominal,
            &config.perturbation,
            &centre,
            &config.effects,
            &mut stream(config.seed, Stream::Robot),
        )?;
        let durations = config.durations.scaled(config.duration_scale);
        let plan = SessionPlan::build(
            &nominal.geometry,
            &nominal.joints.home_stops,
            &centre,
            &robot.power_up_joints,
            &durations,
            &mut stream(config.seed, Stream::Plan),
        )
        .map_err(|e| SimError::Config(e.to_string()))?;
        robot.check_reachable(&plan)?;

        let centre_pose = sabr_model::forward(&nominal.geometry, &centre)
            .map_err(|e| SimError::Config(format!("excitation centre has no FK: {e}")))?;
        let centre_in_base = nominal.markers.base_to_robot * centre_pose.tip;
        let extra_latency_ms = config
            .effects
            .iter()
            .find_map(|e| match e {
                SimEffect::TrackerLatency { extra_ms } => Some(*extra_ms),
                _ => None,
            })
            .unwrap_or(0.0);
        let clock_drift_ppm = config.effects.iter().find_map(|e| match e {
            SimEffect::TrackerClockDrift { ppm } => Some(*ppm),
            _ => None,
        });
        let tracker = TrackerTruth::sample(
            &config.tracker,
            &centre_in_base,
            extra_latency_ms,
            clock_drift_ppm,
            &mut stream(config.seed, Stream::TrackerSession),
        );
        let host_start_ns = stream(config.seed, Stream::HostClock)
            .random_range(100_000_000_000..10_000_000_000_000);
        Ok(Session {
            config: config.clone(),
            robot,
            tracker,
            plan,
            host_start_ns,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// The true robot.
    pub fn robot_truth(&self) -> &RobotTruth {
        &self.robot
    }

    /// The tracker's truth (pose `T_S_M`, latency, clock).
    pub fn tracker_truth(&self) -> &TrackerTruth {
        &self.tracker
    }

    /// The true robot at power-up, ready to take motor setpoints (e.g. from a live rig).
    pub fn true_robot(&self) -> TrueRobot {
        TrueRobot::new(self.robot.clone())
    }

    /// The encoder sampling clock of this session, first nominal sample at power-up.
    pub fn encoder_clock(&self) -> EncoderClock {
        EncoderClock::new(
            self.config.encoder.clone(),
            0,
            stream(self.config.seed, Stream::Encoder),
        )
    }

    /// The commanded plan.
    pub fn plan(&self) -> &SessionPlan {
        &self.plan
    }

    /// Host clock at power-up (ns).
    pub fn host_start_ns(&self) -> i64 {
        self.host_start_ns
    }

    /// A fresh tracker emulator of this session (its truth, configuration and noise stream),
    /// the one [`Session::record`] uses; for driving the tracker in real time (the rig).
    pub fn tracker_emulator(&self) -> TrackerEmulator {
        TrackerEmulator::new(
            self.config.tracker.clone(),
            self.tracker.clone(),
            self.robot.params.markers.base_to_robot,
            stream(self.config.seed, Stream::Tracker),
        )
    }

    /// Runs the session: drives the true robot through the plan in time order of encoder
    /// samples, tracker exposures and validation instants, and records everything.
    pub fn record(&self) -> Result<(Recording, Truth), SimError> {
        let host = self.host_start_ns;
        let mut robot = self.true_robot();
        let mut encoder = self.encoder_clock();
        let mut tracker = self.tracker_emulator();
        let end_ns = self.plan.end_ns();
        let windows = self.plan.validation();
        let mut next_window = 0;
        let capacity = (end_ns as f64 * 1e-9 * self.config.encoder.rate_hz) as usize + 16;
        let mut encoders = Vec::with_capacity(capacity);
        let mut tracker_rows = Vec::new();
        let mut frames = Vec::new();
        let mut validation = Vec::with_capacity(windows.len());

        loop {
            let t_encoder = encoder.peek_ns();
            let t_exposure = tracker.next_exposure().exposure_ns;
            let t_probe = windows
                .get(next_window)
                .map_or(i64::MAX, |w| (w.start_ns + w.end_ns) / 2);
            let t_ns = t_encoder.min(t_exposure).min(t_probe);
            if t_ns > end_ns {
                break;
            }
            let setpoint = self.robot.motor_for_joints(&self.plan.joints_at(t_ns));
            robot.command(t_ns, &setpoint);
            if t_ns == t_encoder {
                encoder.advance();
                encoders.push(EncoderRow {
                    t_ns: host + t_ns,
                    counts: robot.counts(),
                });
            } else if t_ns == t_exposure {
                let tools = robot
                    .tool_poses()
                    .map_err(|e| kinematics(t_ns, &robot, e))?;
                let frame = tracker.capture(&tools, self.plan.tip_attached(t_ns));
                frames.push(FrameTruth {
                    frame: frame.exposure.frame,
                    exposure_ns: host + t_ns,
                    arrival_ns: frame.arrival_ns.map(|t| host + t),
                });
                if let Some(arrival) = frame.arrival_ns {
                    tracker_rows.extend(frame.readings.iter().map(|(tool, reading)| TrackerRow {
                        t_ns: host + arrival,
                        arrival_t_ns: host + arrival,
                        frame: frame.exposure.frame,
                        tool: *tool,
                        reading: *reading,
                    }));
                }
            } else {
                let window = &windows[next_window];
                next_window += 1;
                let pose = robot.pose().map_err(|e| kinematics(t_ns, &robot, e))?;
                validation.push(ValidationTruth {
                    t_start_ns: host + window.start_ns,
                    t_end_ns: host + window.end_ns,
                    tip: pose.tip,
                    direction: pose.direction.into_inner(),
                    joints: robot.joints(),
                    counts: robot.counts(),
                });
            }
        }

        let phases = self
            .plan
            .phases()
            .iter()
            .map(|p| PhaseRow {
                t_start_ns: host + p.start_ns,
                t_end_ns: host + p.end_ns,
                phase: p.name.to_string(),
            })
            .collect();
        let recording = Recording {
            dir: PathBuf::new(),
            robot_toml: self.config.nominal.to_toml_string(),
            encoders,
            tracker: tracker_rows,
            phases,
        };
        let truth = Truth {
            robot: self.robot.clone(),
            effects: self.config.effects.clone(),
            tracker: self.tracker.clone(),
            host_start_ns: host,
            validation,
            frames,
        };
        Ok((recording, truth))
    }
}

fn kinematics(t_ns: i64, robot: &TrueRobot, error: sabr_model::KinematicsError) -> SimError {
    SimError::Unreachable {
        t_s: t_ns as f64 * 1e-9,
        joints: robot.joints(),
        reason: error.to_string(),
    }
}

/// Records a whole session in memory: the recording (nominal `robot.toml`, encoders,
/// tracker, phases) and the truth.
pub fn record_session(config: &SimConfig) -> Result<(Recording, Truth), SimError> {
    Session::new(config)?.record()
}
