//! The session executor: a state machine advanced once per setpoint period with explicit host
//! times, fed with feedback arrivals and parameter sets, answering with events (setpoints,
//! status changes, finished phases). It has no I/O of its own, so it is tested with injected
//! time.
//!
//! Safety rules: nothing moves before encoder (and tracker) data arrived; every plan is checked
//! against the joint and speed limits before its first setpoint; once a feedback stream is
//! stale (no data for longer than its deadline) the executor faults at once, commands the last
//! setpoint again (the robot holds) and never moves again.

use crate::feedback::FeedbackWatch;
use crate::homing::{offsets_from_stops, Homing, HomingConfig, HomingStep};
use crate::limits::{check_plan, JointLimits};
use crate::line::{line_segments, IkService, LinePlanner, LineSpec, PlannerStep};
use crate::plan::{Segment, PERIOD_NS};
use sabr_ik::ParameterSet;
use sabr_model::realtime::RealtimeGeometry;
use sabr_model::{Counts, JointMotion, Joints, RobotParams};
use sabr_msgs::MotionState;
use std::collections::VecDeque;

/// Status reason of the homing motion and name of its phase (the dwell at the stops).
pub const HOMING: &str = "homing";

/// How the line is chosen.
#[derive(Debug, Clone, PartialEq)]
pub struct LineConfig {
    /// Start tip and direction in `Bb` (mm, any length but zero); `None`: an insertion along
    /// the needle centred on the excitation centre's tip.
    pub start_and_direction: Option<([f64; 3], [f64; 3])>,
    /// Length (mm).
    pub length_mm: f64,
    /// Peak tip speed (mm/s).
    pub speed_mm_s: f64,
    /// Dwell before and after the line (s).
    pub dwell_s: f64,
}

/// Everything the executor is configured with.
#[derive(Debug, Clone, PartialEq)]
pub struct ExecutorConfig {
    /// Joint box and speed limit of every plan.
    pub limits: JointLimits,
    /// Homing into the stops.
    pub homing: HomingConfig,
    /// Staleness deadline of the encoder stream (ns).
    pub encoder_deadline_ns: i64,
    /// Staleness deadline of the tracker stream (ns); `None`: the tracker is not watched.
    pub tracker_deadline_ns: Option<i64>,
    /// How long to wait for the first feedback (ns).
    pub feedback_timeout_ns: i64,
    /// How long the line waits for the parameter set calibrated after a calibration (ns).
    pub parameters_timeout_ns: i64,
    /// The line.
    pub line: LineConfig,
    /// IK requests per setpoint period while planning the line.
    pub ik_requests_per_period: usize,
}

/// One step of the session.
#[derive(Debug, Clone, PartialEq)]
pub enum Task {
    /// Home into the stops (sets the joint offsets).
    Home,
    /// Play a plan that was checked against the limits when it was made.
    Play(Vec<Segment>),
    /// Wait for a parameter set announced after this point (the calibrator's result).
    AwaitParameters,
    /// Plan the line with the IK server, check it, then play it.
    PlanLine,
}

/// What the executor asks its process to do.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// Publish this motor setpoint (counts) now.
    Setpoint([f64; 5]),
    /// The status changed.
    Status {
        /// New state.
        state: MotionState,
        /// Why, or the running segment's name.
        reason: String,
    },
    /// A phase ended (host ns).
    Phase {
        /// Phase name.
        name: String,
        /// Start.
        start_ns: i64,
        /// End.
        end_ns: i64,
    },
    /// The line was planned and passed the checks.
    LinePlanned {
        /// The line.
        spec: LineSpec,
        /// Version of the parameter set it was planned with.
        version: u64,
    },
}

/// Where the executor ended up after a tick.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Still working.
    Running,
    /// Every task is done.
    Finished,
    /// Stopped on a fault; the reason.
    Faulted(String),
}

#[derive(Debug)]
enum Stage {
    AwaitFeedback,
    Idle,
    Homing(Box<Homing>),
    Playing {
        segments: VecDeque<Segment>,
        segment_start_ns: i64,
    },
    AwaitParameters {
        since_ns: i64,
        newer_than: u64,
    },
    PlanningLine {
        planner: Box<LinePlanner>,
        spec: LineSpec,
        params: Box<RobotParams>,
        version: u64,
    },
    Finished,
    Faulted(String),
}

/// The executor of one run's tasks.
#[derive(Debug)]
pub struct Executor {
    config: ExecutorConfig,
    base: RobotParams,
    /// The base parameters with the offsets of this run's homing: what joint plans that
    /// start at the stops are played with.
    homed: Option<RobotParams>,
    /// A given parameter set with offsets (`--params`, version 0).
    given: Option<RobotParams>,
    announced: Option<ParameterSet>,
    tasks: VecDeque<Task>,
    stage: Stage,
    encoder: FeedbackWatch,
    tracker: Option<FeedbackWatch>,
    counts: Option<Counts>,
    commanded: Option<[f64; 5]>,
    status: Option<(MotionState, String)>,
    created_ns: i64,
}

impl Executor {
    /// An executor of `tasks` for the robot `base` (nominal or given parameters; if they have
    /// joint offsets they are the line's parameter set version 0 until one is announced),
    /// created at `now_ns`.
    pub fn new(config: ExecutorConfig, base: RobotParams, tasks: Vec<Task>, now_ns: i64) -> Self {
        let given = base.joints.offset.is_some().then(|| base.clone());
        Self {
            encoder: FeedbackWatch::new("encoder", config.encoder_deadline_ns),
            tracker: config
                .tracker_deadline_ns
                .map(|deadline| FeedbackWatch::new("tracker", deadline)),
            config,
            base,
            homed: None,
            given,
            announced: None,
            tasks: tasks.into(),
            stage: Stage::AwaitFeedback,
            counts: None,
            commanded: None,
            status: None,
            created_ns: now_ns,
        }
    }

    /// An encoder sample read at host time `t_ns`.
    pub fn on_encoder(&mut self, t_ns: i64, counts: Counts) {
        self.encoder.feed(t_ns);
        self.counts = Some(counts);
    }

    /// A tracker frame that arrived at host time `t_ns`.
    pub fn on_tracker(&mut self, t_ns: i64) {
        if let Some(tracker) = &mut self.tracker {
            tracker.feed(t_ns);
        }
    }

    /// A parameter set the calibrator announced (already loaded and valid).
    pub fn on_parameters(&mut self, set: ParameterSet) {
        if self
            .announced
            .as_ref()
            .is_none_or(|old| set.version > old.version)
        {
            self.announced = Some(set);
        }
    }

    /// The last setpoint commanded, if any.
    pub fn commanded(&self) -> Option<[f64; 5]> {
        self.commanded
    }

    /// Advances to host time `now_ns`, appending what to do to `events`.
    pub fn tick(
        &mut self,
        now_ns: i64,
        ik: &mut dyn IkService,
        events: &mut Vec<Event>,
    ) -> Outcome {
        match &self.stage {
            Stage::Finished => return Outcome::Finished,
            Stage::Faulted(reason) => return Outcome::Faulted(reason.clone()),
            Stage::AwaitFeedback => {}
            _ => {
                let stale = self.encoder.stale(now_ns).or_else(|| {
                    self.tracker
                        .as_ref()
                        .and_then(|tracker| tracker.stale(now_ns))
                });
                if let Some(reason) = stale {
                    return self.fault(reason, events);
                }
            }
        }
        match self.advance(now_ns, ik, events) {
            Ok(()) if matches!(self.stage, Stage::Finished) => Outcome::Finished,
            Ok(()) => Outcome::Running,
            Err(reason) => self.fault(reason, events),
        }
    }

    fn fault(&mut self, reason: String, events: &mut Vec<Event>) -> Outcome {
        if let Some(hold) = self.commanded {
            events.push(Event::Setpoint(hold));
        }
        self.set_status(MotionState::Faulted, &reason, events);
        self.stage = Stage::Faulted(reason.clone());
        Outcome::Faulted(reason)
    }

    fn set_status(&mut self, state: MotionState, reason: &str, events: &mut Vec<Event>) {
        let changed = self
            .status
            .as_ref()
            .is_none_or(|(s, r)| *s != state || r != reason);
        if changed {
            self.status = Some((state, reason.to_owned()));
            events.push(Event::Status {
                state,
                reason: reason.to_owned(),
            });
        }
    }

    fn command(&mut self, counts: [f64; 5], events: &mut Vec<Event>) {
        self.commanded = Some(counts);
        events.push(Event::Setpoint(counts));
    }

    /// Where the robot is commanded to be (the last setpoint, else the encoder reading).
    fn current_counts(&self) -> Option<[f64; 5]> {
        self.commanded
            .or_else(|| self.counts.map(|c| c.map(|v| v as f64)))
    }

    fn advance(
        &mut self,
        now_ns: i64,
        ik: &mut dyn IkService,
        events: &mut Vec<Event>,
    ) -> Result<(), String> {
        loop {
            match std::mem::replace(&mut self.stage, Stage::Idle) {
                Stage::AwaitFeedback => {
                    let tracker_ok = self.tracker.as_ref().is_none_or(FeedbackWatch::has_data);
                    if self.encoder.has_data() && tracker_ok {
                        continue;
                    }
                    if now_ns - self.created_ns > self.config.feedback_timeout_ns {
                        let missing = if self.encoder.has_data() {
                            "tracker frames"
                        } else {
                            "encoder samples"
                        };
                        return Err(format!(
                            "no {missing} within {:.1} s: not starting",
                            self.config.feedback_timeout_ns as f64 * 1e-9
                        ));
                    }
                    self.stage = Stage::AwaitFeedback;
                    self.set_status(MotionState::Idle, "waiting for feedback", events);
                    return Ok(());
                }
                Stage::Idle => {
                    self.start_next_task(now_ns)?;
                    if matches!(self.stage, Stage::Finished) {
                        self.set_status(MotionState::Finished, "session done", events);
                        return Ok(());
                    }
                }
                Stage::Homing(mut homing) => {
                    let counts = self.counts.ok_or("homing without encoder data")?;
                    match homing.step(now_ns, counts) {
                        HomingStep::Approach(target) | HomingStep::Dwell(target) => {
                            self.stage = Stage::Homing(homing);
                            self.command(target, events);
                            self.set_status(MotionState::Moving, HOMING, events);
                            return Ok(());
                        }
                        HomingStep::Done {
                            stop_counts,
                            dwell_start_ns,
                            dwell_end_ns,
                        } => {
                            let mut params = self.base.clone();
                            params.joints.offset = Some(offsets_from_stops(&params, &stop_counts));
                            tracing::info!(?stop_counts, offsets = ?params.joints.offset, "homed");
                            self.homed = Some(params);
                            events.push(Event::Phase {
                                name: HOMING.into(),
                                start_ns: dwell_start_ns,
                                end_ns: dwell_end_ns,
                            });
                        }
                        HomingStep::Failed(reason) => return Err(reason),
                    }
                }
                Stage::Playing {
                    segments,
                    segment_start_ns,
                } => {
                    if let Some(counts) = self.play(segments, segment_start_ns, now_ns, events)? {
                        self.command(counts, events);
                        return Ok(());
                    }
                }
                Stage::AwaitParameters {
                    since_ns,
                    newer_than,
                } => {
                    if let Some(set) = self.announced.as_ref().filter(|s| s.version > newer_than) {
                        tracing::info!(version = set.version, path = %set.path.display(),
                            "calibrated parameter set in force");
                        continue;
                    }
                    if now_ns - since_ns > self.config.parameters_timeout_ns {
                        return Err(format!(
                            "no new parameter set was announced within {:.0} s",
                            self.config.parameters_timeout_ns as f64 * 1e-9
                        ));
                    }
                    self.stage = Stage::AwaitParameters {
                        since_ns,
                        newer_than,
                    };
                    self.set_status(
                        MotionState::Idle,
                        "waiting for the calibrated parameter set",
                        events,
                    );
                    return Ok(());
                }
                Stage::PlanningLine {
                    mut planner,
                    spec,
                    params,
                    version,
                } => {
                    let budget = self.config.ik_requests_per_period;
                    match planner
                        .advance(ik, now_ns, budget)
                        .map_err(|reason| format!("line refused: {reason}"))?
                    {
                        PlannerStep::Pending => {
                            self.stage = Stage::PlanningLine {
                                planner,
                                spec,
                                params,
                                version,
                            };
                            self.set_status(MotionState::Idle, "planning the line", events);
                            return Ok(());
                        }
                        PlannerStep::Ready(waypoints) => {
                            let segments = self.line_plan(&spec, &params, &waypoints)?;
                            tracing::info!(version, start = ?spec.start, end = ?spec.end(),
                                "line planned and within the limits");
                            events.push(Event::LinePlanned { spec, version });
                            self.stage = Stage::Playing {
                                segments: segments.into(),
                                segment_start_ns: now_ns,
                            };
                        }
                    }
                }
                Stage::Finished => {
                    self.stage = Stage::Finished;
                    return Ok(());
                }
                Stage::Faulted(reason) => {
                    self.stage = Stage::Faulted(reason.clone());
                    return Err(reason);
                }
            }
        }
    }

    /// Plays the segments at `now_ns`: the counts to command, or `None` when they are done
    /// (the stage is then idle). Announces each phase that ended.
    fn play(
        &mut self,
        mut segments: VecDeque<Segment>,
        mut segment_start_ns: i64,
        now_ns: i64,
        events: &mut Vec<Event>,
    ) -> Result<Option<[f64; 5]>, String> {
        while let Some(segment) = segments.front() {
            let index = ((now_ns - segment_start_ns).max(0) / PERIOD_NS) as usize;
            if index < segment.joints.len() {
                let counts = match &segment.counts {
                    Some(counts) => counts[index],
                    None => {
                        let params = self
                            .homed
                            .as_ref()
                            .or(self.given.as_ref())
                            .ok_or("no joint offsets to turn the plan into counts")?;
                        params
                            .counts_from_joints(&segment.joints[index], &JointMotion::default())
                            .map_err(|e| format!("{}: {e}", segment.name))?
                    }
                };
                let name = segment.name.clone();
                self.set_status(MotionState::Moving, &name, events);
                self.stage = Stage::Playing {
                    segments,
                    segment_start_ns,
                };
                return Ok(Some(counts));
            }
            let end_ns = segment_start_ns + segment.joints.len() as i64 * PERIOD_NS;
            if segment.phase {
                events.push(Event::Phase {
                    name: segment.name.clone(),
                    start_ns: segment_start_ns,
                    end_ns,
                });
            }
            segment_start_ns = end_ns;
            segments.pop_front();
        }
        Ok(None)
    }

    fn start_next_task(&mut self, now_ns: i64) -> Result<(), String> {
        self.stage = match self.tasks.pop_front() {
            None => Stage::Finished,
            Some(Task::Home) => {
                let counts = self.counts.ok_or("homing without encoder data")?;
                Stage::Homing(Box::new(Homing::new(
                    &self.base,
                    self.config.homing.clone(),
                    now_ns,
                    counts,
                )))
            }
            Some(Task::Play(segments)) => Stage::Playing {
                segments: segments.into(),
                segment_start_ns: now_ns,
            },
            Some(Task::AwaitParameters) => Stage::AwaitParameters {
                since_ns: now_ns,
                newer_than: self.announced.as_ref().map_or(0, |set| set.version),
            },
            Some(Task::PlanLine) => self.start_line(now_ns)?,
        };
        Ok(())
    }

    /// The parameter set the line is planned with: the newest announced one, else a given
    /// one with offsets (homing offsets alone are not a set the IK server serves).
    fn line_parameters(&self) -> Result<(RobotParams, u64), String> {
        match (&self.announced, &self.given) {
            (Some(set), _) => Ok((set.params.clone(), set.version)),
            (None, Some(params)) => Ok((params.clone(), 0)),
            (None, None) => Err(
                "line refused: it needs a calibrated parameter set (none was \
                 announced and --params has no joint offsets)"
                    .into(),
            ),
        }
    }

    fn start_line(&mut self, now_ns: i64) -> Result<Stage, String> {
        let (params, version) = self.line_parameters()?;
        let line = &self.config.line;
        let spec = match line.start_and_direction {
            Some((start, direction)) => {
                let direction = nalgebra::Vector3::from(direction);
                if direction.norm() <= 0.0 || direction.norm().is_nan() {
                    return Err("line refused: its direction has zero length".into());
                }
                let spec = LineSpec {
                    start: start.into(),
                    direction: nalgebra::Unit::new_normalize(direction),
                    length_mm: line.length_mm,
                    speed_mm_s: line.speed_mm_s,
                    dwell_s: line.dwell_s,
                };
                spec.validate().map(|()| spec)
            }
            None => LineSpec::centred_insertion(
                &RealtimeGeometry::from(&params.effective_geometry()),
                &params.joints.home_stops,
                line.length_mm,
                line.speed_mm_s,
                line.dwell_s,
            ),
        }
        .map_err(|reason| format!("line refused: {reason}"))?;
        let near = self.current_joints(&params)?;
        Ok(Stage::PlanningLine {
            planner: Box::new(LinePlanner::new(&spec, version, near, now_ns)),
            spec,
            params: Box::new(params),
            version,
        })
    }

    fn current_joints(&self, params: &RobotParams) -> Result<Joints, String> {
        let counts = self.current_counts().ok_or("no encoder data")?;
        params
            .joints_from_fractional_counts(&counts, &JointMotion::default())
            .map_err(|e| format!("cannot tell where the robot is: {e}"))
    }

    /// The line's segments from the current setpoint, checked against the limits.
    fn line_plan(
        &self,
        spec: &LineSpec,
        params: &RobotParams,
        waypoints: &[crate::line::SolvedWaypoint],
    ) -> Result<Vec<Segment>, String> {
        let from = self.current_counts().ok_or("no encoder data")?;
        let approach_speed = 0.5 * self.config.limits.max_speed_rad_s;
        let segments = line_segments(spec, waypoints, params, &from, approach_speed)
            .map_err(|reason| format!("line refused: {reason}"))?;
        let start = self.current_joints(params)?;
        check_plan(&self.config.limits, &start, &segments)
            .map_err(|refusal| refusal.to_string())?;
        Ok(segments)
    }
}
