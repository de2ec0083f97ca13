//! The executor with injected time: feedback gating, stale-feedback stops, a whole calibration
//! session against a simulated robot, and the line through a local IK solver.

use crate::executor::{Event, Executor, ExecutorConfig, LineConfig, Outcome, Task, HOMING};
use crate::homing::HomingConfig;
use crate::limits::{JointLimits, DEFAULT_MAX_SPEED_RAD_S, DEFAULT_RANGE_RAD};
use crate::line::{IkService, LINE_PHASE};
use crate::plan::{calibration_segments, PERIOD_NS};
use rand::SeedableRng;
use sabr_ik::{IkSolver, ParameterSet};
use sabr_model::{Counts, JointMotion, Joints, RobotParams, HOME_JOINTS};
use sabr_msgs::{IkRequest, IkResponse, MotionState};
use sabr_sim::{Perturbation, RobotTruth, TrueRobot};
use std::f64::consts::TAU;
use std::path::Path;

const MS: i64 = 1_000_000;
/// Host time of the first tick (any value: the executor only uses differences).
const T0: i64 = 5_000 * MS;

/// A local solver standing in for the IK server.
struct LocalIk(IkSolver);

impl IkService for LocalIk {
    fn solve(&mut self, request: IkRequest) -> Result<IkResponse, String> {
        Ok(self.0.solve(&request))
    }
}

fn no_ik() -> LocalIk {
    LocalIk(IkSolver::new())
}

fn config() -> ExecutorConfig {
    let stops = RobotParams::nominal().joints.home_stops;
    ExecutorConfig {
        limits: JointLimits::from_stops(&stops, DEFAULT_RANGE_RAD, DEFAULT_MAX_SPEED_RAD_S),
        homing: HomingConfig {
            dwell_s: 0.3,
            ..HomingConfig::default()
        },
        encoder_deadline_ns: 20 * MS,
        tracker_deadline_ns: Some(200 * MS),
        feedback_timeout_ns: 1_000 * MS,
        parameters_timeout_ns: 2_000 * MS,
        line: LineConfig {
            start_and_direction: None,
            length_mm: 10.0,
            speed_mm_s: 10.0,
            dwell_s: 0.2,
        },
        ik_requests_per_period: 10,
    }
}

/// A simulated robot whose motors follow each setpoint by the next period.
struct Rig {
    robot: TrueRobot,
    cpr: [u32; 5],
    /// From the excitation on: the closest any joint came to its true stop (rad).
    closest_to_stop_from_excitation: Option<f64>,
}

impl Rig {
    fn new(seed: u64) -> Self {
        let nominal = RobotParams::nominal();
        let centre = sabr_model::plan::excitation_centre(&nominal.joints.home_stops, &HOME_JOINTS);
        let truth = RobotTruth::sample(
            &nominal,
            &Perturbation::default(),
            &centre,
            &[],
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed),
        )
        .unwrap();
        Self {
            robot: TrueRobot::new(truth),
            cpr: nominal.joints.counts_per_rev,
            closest_to_stop_from_excitation: None,
        }
    }

    fn counts(&self) -> Counts {
        self.robot.counts()
    }

    fn follow(&mut self, t_ns: i64, events: &[Event]) {
        for event in events {
            if let Event::Setpoint(target) = event {
                let motor: Joints =
                    std::array::from_fn(|i| target[i] * TAU / f64::from(self.cpr[i]));
                self.robot.command(t_ns, &motor);
                if let Some(closest) = &mut self.closest_to_stop_from_excitation {
                    let q = self.robot.paper_joints();
                    let stops = self.robot.truth().stops;
                    for (joint, stop) in q.iter().zip(&stops) {
                        *closest = closest.min((joint - stop).abs());
                    }
                }
            }
            if matches!(event, Event::Status { reason, .. } if reason == "excitation") {
                self.closest_to_stop_from_excitation = Some(f64::INFINITY);
            }
        }
    }
}

/// Runs the executor with fresh encoder and tracker data every period until it stops or
/// `until_ns`; returns the events, with their times, and the outcome.
fn run(
    executor: &mut Executor,
    rig: &mut Rig,
    ik: &mut LocalIk,
    until_ns: i64,
) -> (Vec<(i64, Event)>, Outcome) {
    let mut all = Vec::new();
    let mut events = Vec::new();
    let mut t = T0;
    while t < until_ns {
        executor.on_encoder(t, rig.counts());
        if (t - T0) % (50 * MS) == 0 {
            executor.on_tracker(t);
        }
        let outcome = executor.tick(t, ik, &mut events);
        rig.follow(t, &events);
        all.extend(events.drain(..).map(|e| (t, e)));
        if outcome != Outcome::Running {
            return (all, outcome);
        }
        t += PERIOD_NS;
    }
    (all, Outcome::Running)
}

fn setpoints(events: &[(i64, Event)]) -> Vec<(i64, [f64; 5])> {
    events
        .iter()
        .filter_map(|(t, e)| match e {
            Event::Setpoint(c) => Some((*t, *c)),
            _ => None,
        })
        .collect()
}

fn statuses(events: &[(i64, Event)]) -> Vec<(MotionState, String)> {
    events
        .iter()
        .filter_map(|(_, e)| match e {
            Event::Status { state, reason } => Some((*state, reason.clone())),
            _ => None,
        })
        .collect()
}

fn phases(events: &[(i64, Event)]) -> Vec<(String, i64, i64)> {
    events
        .iter()
        .filter_map(|(_, e)| match e {
            Event::Phase {
                name,
                start_ns,
                end_ns,
            } => Some((name.clone(), *start_ns, *end_ns)),
            _ => None,
        })
        .collect()
}

#[test]
fn nothing_moves_before_feedback_and_missing_feedback_is_a_fault() {
    let mut executor = Executor::new(config(), RobotParams::nominal(), vec![Task::Home], T0);
    let mut events = Vec::new();
    let mut ik = no_ik();
    // Encoders only: the tracker is still missing, so nothing moves.
    for k in 0..1_000 {
        let t = T0 + k * MS;
        executor.on_encoder(t, [0; 5]);
        assert_eq!(executor.tick(t, &mut ik, &mut events), Outcome::Running);
    }
    assert!(events.iter().all(|e| !matches!(e, Event::Setpoint(_))));
    let outcome = executor.tick(T0 + 1_001 * MS, &mut ik, &mut events);
    let Outcome::Faulted(reason) = outcome else {
        panic!("{outcome:?}")
    };
    assert!(reason.contains("no tracker frames"), "{reason}");
    assert!(events.iter().all(|e| !matches!(e, Event::Setpoint(_))));
}

#[test]
fn a_stalled_encoder_stream_stops_the_robot_at_its_deadline_and_says_why() {
    let mut executor = Executor::new(config(), RobotParams::nominal(), vec![Task::Home], T0);
    let mut rig = Rig::new(1);
    let mut ik = no_ik();
    // Homing runs with fresh data for 200 ms.
    let (events, outcome) = run(&mut executor, &mut rig, &mut ik, T0 + 200 * MS);
    assert_eq!(outcome, Outcome::Running);
    let moving = setpoints(&events);
    assert!(moving.len() > 150, "homing commands setpoints");
    let last_sample = T0 + 199 * MS;
    // The encoders stop; the tracker goes on.
    let mut events = Vec::new();
    let mut fault_at = None;
    for k in 0..100 {
        let t = T0 + 200 * MS + k * MS;
        executor.on_tracker(t);
        if let Outcome::Faulted(reason) = executor.tick(t, &mut ik, &mut events) {
            assert!(reason.starts_with("encoder feedback stale"), "{reason}");
            fault_at = Some(t);
            break;
        }
    }
    let fault_at = fault_at.expect("the executor faults");
    assert!(fault_at - last_sample > 20 * MS, "not before the deadline");
    assert!(
        fault_at - last_sample <= 21 * MS,
        "within one period of the deadline"
    );
    // The last event before the fault status is a hold of the last commanded setpoint.
    let hold = executor.commanded().unwrap();
    let tail: Vec<&Event> = events.iter().rev().take(2).collect();
    assert_eq!(tail[1], &Event::Setpoint(hold));
    assert!(
        matches!(tail[0], Event::Status { state: MotionState::Faulted, reason } if reason.contains("encoder"))
    );
    // Faulted stays faulted, silently, even if data comes back.
    events.clear();
    executor.on_encoder(fault_at + MS, rig.counts());
    assert!(matches!(
        executor.tick(fault_at + MS, &mut ik, &mut events),
        Outcome::Faulted(_)
    ));
    assert!(events.is_empty());
}

#[test]
fn a_stalled_tracker_stream_stops_the_robot_at_its_deadline() {
    let mut executor = Executor::new(config(), RobotParams::nominal(), vec![Task::Home], T0);
    let mut rig = Rig::new(2);
    let mut ik = no_ik();
    let (_, outcome) = run(&mut executor, &mut rig, &mut ik, T0 + 101 * MS);
    assert_eq!(outcome, Outcome::Running);
    let last_frame = T0 + 100 * MS;
    let mut events = Vec::new();
    for k in 1..400 {
        let t = last_frame + k * MS;
        executor.on_encoder(t, rig.counts());
        if let Outcome::Faulted(reason) = executor.tick(t, &mut ik, &mut events) {
            assert!(reason.starts_with("tracker feedback stale"), "{reason}");
            assert_eq!(k, 201, "faults one period after the 200 ms deadline");
            return;
        }
    }
    panic!("no fault");
}

#[test]
fn a_calibration_session_homes_then_plays_the_phases_and_finishes() {
    let params = RobotParams::nominal();
    let segments = calibration_segments(&params, 0.02, 5).unwrap();
    let planned: f64 = segments.iter().map(|s| s.duration_s()).sum();
    let tasks = vec![Task::Home, Task::Play(segments)];
    let mut executor = Executor::new(config(), params.clone(), tasks, T0);
    let mut rig = Rig::new(3);
    let mut ik = no_ik();
    let (events, outcome) = run(&mut executor, &mut rig, &mut ik, T0 + 120_000 * MS);
    assert_eq!(outcome, Outcome::Finished);
    let names: Vec<String> = phases(&events).into_iter().map(|p| p.0).collect();
    assert_eq!(names, [HOMING, "excitation", "tip", "validation"]);
    // Phases follow each other in time, the played ones lasting as planned.
    let spans = phases(&events);
    for pair in spans.windows(2) {
        assert!(pair[0].2 <= pair[1].1);
    }
    let played = (spans[3].2 - spans[0].2) as f64 * 1e-9;
    assert!((played - planned).abs() < 0.01, "{played} vs {planned}");
    // The status names the running phase (the rig attaches the tip sphere on "tip").
    let status = statuses(&events);
    assert!(status.contains(&(MotionState::Moving, "tip".into())));
    assert_eq!(
        status.last().unwrap(),
        &(MotionState::Finished, "session done".into())
    );
    // A setpoint every period while moving, never two in one period.
    let times: Vec<i64> = setpoints(&events).iter().map(|(t, _)| *t).collect();
    assert!(times.windows(2).all(|w| w[1] > w[0]));
    // With the homing offsets, the excitation, tip and validation phases keep every true
    // joint off its true stop (their envelope ends 0.06 rad short of the nominal stops; the
    // true stops differ by up to 2°, the gear ratios by 3 %).
    let closest = rig.closest_to_stop_from_excitation.expect("excitation ran");
    assert!(closest > 0.002, "came within {closest} rad of a stop");
}

#[test]
fn the_line_waits_for_the_calibrated_set_then_plays_through_the_ik_answers() {
    let rig = Rig::new(4);
    // The calibrated set is the truth's paper model (the effects-free true robot).
    let mut calibrated = rig.robot.truth().params.clone();
    calibrated.markers = RobotParams::nominal().markers;
    let set = ParameterSet::new(calibrated.clone(), 7, Path::new("params.toml"));
    let mut ik = LocalIk(IkSolver::with_parameters(set.clone()));
    let tasks = vec![Task::AwaitParameters, Task::PlanLine];
    let mut executor = Executor::new(config(), RobotParams::nominal(), tasks, T0);
    let mut rig = rig;
    let (events, outcome) = run(&mut executor, &mut rig, &mut ik, T0 + 500 * MS);
    assert_eq!(outcome, Outcome::Running);
    assert!(
        setpoints(&events).is_empty(),
        "no motion before the parameter set"
    );
    assert!(statuses(&events).contains(&(
        MotionState::Idle,
        "waiting for the calibrated parameter set".into()
    )));
    executor.on_parameters(set);
    let (events, outcome) = run(&mut executor, &mut rig, &mut ik, T0 + 30_000 * MS);
    assert_eq!(outcome, Outcome::Finished);
    let line = phases(&events);
    assert_eq!(line.len(), 1);
    assert_eq!(line[0].0, LINE_PHASE);
    let planned = events.iter().find_map(|(_, e)| match e {
        Event::LinePlanned { spec, version } => Some((spec.clone(), *version)),
        _ => None,
    });
    let (spec, version) = planned.expect("line planned");
    assert_eq!(version, 7);
    // The true robot (its model is the calibrated set) ends with its tip at the line's end.
    let tip = rig.robot.pose().unwrap().tip;
    assert!(
        (tip - spec.end()).norm() < 0.05,
        "tip {tip} vs end {}",
        spec.end()
    );
    // Counts of the last setpoint are the IK server's for the end of the line.
    let last = setpoints(&events).last().unwrap().1;
    let q = calibrated
        .joints_from_fractional_counts(&last, &JointMotion::default())
        .unwrap();
    let end = sabr_model::forward(&calibrated.effective_geometry(), &q).unwrap();
    assert!((end.tip - spec.end()).norm() < 1e-6);
}

#[test]
fn an_out_of_limit_line_is_refused_before_any_setpoint() {
    let mut calibrated = RobotParams::nominal();
    calibrated.joints.offset = Some(HOME_JOINTS);
    let set = ParameterSet::new(calibrated, 1, Path::new("params.toml"));
    let mut ik = LocalIk(IkSolver::with_parameters(set.clone()));
    // The line along the needle turns θ3 by about ±0.07 rad about 0.06 rad: an upper limit
    // of 0.08 rad cuts it.
    let mut config = config();
    config.limits.upper[2] = 0.08;
    let mut executor = Executor::new(config, RobotParams::nominal(), vec![Task::PlanLine], T0);
    executor.on_parameters(set);
    let mut rig = Rig::new(5);
    let (events, outcome) = run(&mut executor, &mut rig, &mut ik, T0 + 5_000 * MS);
    let Outcome::Faulted(reason) = outcome else {
        panic!("{outcome:?}")
    };
    assert!(reason.starts_with("plan refused"), "{reason}");
    assert!(
        reason.contains("joint 3") && reason.contains("upper limit"),
        "{reason}"
    );
    assert!(setpoints(&events).is_empty());
    assert_eq!(
        statuses(&events).last().unwrap(),
        &(MotionState::Faulted, reason)
    );
}

#[test]
fn homing_keeps_a_given_calibrated_set_for_the_line() {
    let mut rig = Rig::new(6);
    let mut calibrated = rig.robot.truth().params.clone();
    calibrated.markers = RobotParams::nominal().markers;
    let set = ParameterSet::new(calibrated.clone(), 0, Path::new("params.toml"));
    let mut ik = LocalIk(IkSolver::with_parameters(set));
    let tasks = vec![Task::Home, Task::PlanLine];
    let mut executor = Executor::new(config(), calibrated, tasks, T0);
    let (events, outcome) = run(&mut executor, &mut rig, &mut ik, T0 + 60_000 * MS);
    assert_eq!(outcome, Outcome::Finished, "{:?}", statuses(&events));
    let names: Vec<String> = phases(&events).into_iter().map(|p| p.0).collect();
    assert_eq!(names, [HOMING, LINE_PHASE]);
    let version = events.iter().find_map(|(_, e)| match e {
        Event::LinePlanned { version, .. } => Some(*version),
        _ => None,
    });
    assert_eq!(
        version,
        Some(0),
        "planned with the given set, not the homing offsets"
    );
}
