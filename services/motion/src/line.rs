//! The straight-line insertion: the needle tip moves along a task-space line (by default along
//! the needle through the excitation centre's pose). The line is sampled into waypoints, each
//! solved by the IK server; the plan is an approach move to the first waypoint, a dwell, the
//! line (joints and counts interpolated between waypoints), and a dwell.

use crate::plan::{Segment, PERIOD_S};
use nalgebra::{Point3, Unit, Vector3};
use sabr_model::realtime::RealtimeGeometry;
use sabr_model::{JointMotion, Joints, RobotParams, HOME_JOINTS};
use sabr_msgs::{IkRequest, IkResponse, IkStatus};
use std::f64::consts::PI;

/// Setpoint periods between two waypoints solved by the IK server (10 ms).
const WAYPOINT_PERIODS: usize = 10;
/// Shortest approach move (s).
const MIN_APPROACH_S: f64 = 0.5;
/// How long the planner waits for the IK server to serve the parameter set motion planned
/// with (it reloads on the same announcement), ns.
const VERSION_WAIT_NS: i64 = 2_000_000_000;
/// Name of the approach segment.
pub const APPROACH: &str = "approach";
/// Name of the line phase (in the recording's `phases.csv`).
pub const LINE_PHASE: &str = "line";

/// Where and how fast the tip moves.
#[derive(Debug, Clone, PartialEq)]
pub struct LineSpec {
    /// First point of the line: the tip in `Bb` (mm).
    pub start: Point3<f64>,
    /// Direction of travel, also the needle direction held along the line (unit, `Bb`).
    pub direction: Unit<Vector3<f64>>,
    /// Length (mm).
    pub length_mm: f64,
    /// Peak tip speed (mm/s).
    pub speed_mm_s: f64,
    /// Dwell before and after the line (s).
    pub dwell_s: f64,
}

/// The answer of an IK service to one request (the IK server, or a local solver in tests).
pub trait IkService {
    /// Solves `request`; an error only when no answer came (the status may be an error).
    fn solve(&mut self, request: IkRequest) -> Result<IkResponse, String>;
}

impl LineSpec {
    /// An insertion along the needle centred on the tip of the excitation centre's pose
    /// (the middle of the calibrated workspace), computed with `geometry`.
    pub fn centred_insertion(
        geometry: &RealtimeGeometry,
        home_stops: &Joints,
        length_mm: f64,
        speed_mm_s: f64,
        dwell_s: f64,
    ) -> Result<Self, String> {
        let centre = sabr_model::plan::excitation_centre(home_stops, &HOME_JOINTS);
        let pose = geometry
            .forward(&centre)
            .map_err(|e| format!("the excitation centre has no forward kinematics: {e}"))?;
        let start = pose.tip - pose.direction * (length_mm / 2.0);
        let spec = Self {
            start: Point3::from(start.to_array()),
            direction: Unit::new_unchecked(Vector3::from(pose.direction.to_array())),
            length_mm,
            speed_mm_s,
            dwell_s,
        };
        spec.validate()?;
        Ok(spec)
    }

    /// Checks the numbers: finite, positive length and speed, non-negative dwell.
    pub fn validate(&self) -> Result<(), String> {
        if !self
            .start
            .coords
            .iter()
            .chain(self.direction.iter())
            .all(|v| v.is_finite())
        {
            return Err("the line's start and direction must be finite".into());
        }
        for (name, value) in [("length", self.length_mm), ("speed", self.speed_mm_s)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!(
                    "the line {name} must be a positive number, got {value}"
                ));
            }
        }
        if !(self.dwell_s.is_finite() && self.dwell_s >= 0.0) {
            return Err(format!(
                "the line dwell must be ≥ 0 s, got {}",
                self.dwell_s
            ));
        }
        Ok(())
    }

    /// The tips of the waypoints: a smooth (cosine) speed profile along the line with the
    /// peak speed, one waypoint every [`WAYPOINT_PERIODS`] setpoint periods, ending exactly at
    /// the end of the line.
    pub fn waypoints(&self) -> Vec<Point3<f64>> {
        let duration_s = PI / 2.0 * self.length_mm / self.speed_mm_s;
        let step_s = WAYPOINT_PERIODS as f64 * PERIOD_S;
        let count = (duration_s / step_s).ceil().max(1.0) as usize;
        (0..=count)
            .map(|k| {
                let s = 0.5 * (1.0 - (PI * k as f64 / count as f64).cos());
                self.start + self.direction.into_inner() * (s * self.length_mm)
            })
            .collect()
    }

    /// The end of the line.
    pub fn end(&self) -> Point3<f64> {
        self.start + self.direction.into_inner() * self.length_mm
    }
}

/// A waypoint solved by the IK server.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolvedWaypoint {
    /// Joints (rad).
    pub joints: Joints,
    /// Motor counts.
    pub counts: [f64; 5],
}

/// Where the planner is.
#[derive(Debug, Clone, PartialEq)]
pub enum PlannerStep {
    /// More waypoints to solve.
    Pending,
    /// All waypoints solved, in order.
    Ready(Vec<SolvedWaypoint>),
}

/// Solves the waypoints of a line a few at a time (so the control loop keeps its period).
#[derive(Debug, Clone)]
pub struct LinePlanner {
    waypoints: Vec<Point3<f64>>,
    direction: [f64; 3],
    version: u64,
    solved: Vec<SolvedWaypoint>,
    near: Joints,
    started_ns: i64,
}

impl LinePlanner {
    /// A planner for `spec` that expects answers under parameter set `version`, starting the
    /// IK branch choice at the joints `near`.
    pub fn new(spec: &LineSpec, version: u64, near: Joints, now_ns: i64) -> Self {
        Self {
            waypoints: spec.waypoints(),
            direction: spec.direction.into_inner().into(),
            version,
            solved: Vec::new(),
            near,
            started_ns: now_ns,
        }
    }

    /// Solves up to `budget` more waypoints. Errors (the line is refused) on an error status,
    /// on no answer, or when the server keeps serving another parameter set.
    pub fn advance(
        &mut self,
        ik: &mut dyn IkService,
        now_ns: i64,
        budget: usize,
    ) -> Result<PlannerStep, String> {
        let total = self.waypoints.len();
        for _ in 0..budget {
            let index = self.solved.len();
            let Some(tip) = self.waypoints.get(index) else {
                break;
            };
            let request = IkRequest {
                id: 0,
                tip_mm: tip.coords.into(),
                direction: self.direction,
                near_joints_rad: self.near,
            };
            let response = ik.solve(request)?;
            if response.parameter_version != self.version {
                if response.parameter_version < self.version
                    && now_ns - self.started_ns < VERSION_WAIT_NS
                {
                    // The server has not loaded the announced set yet: ask again later.
                    return Ok(PlannerStep::Pending);
                }
                return Err(format!(
                    "the IK server answers with parameter set v{}, motion planned with v{}",
                    response.parameter_version, self.version
                ));
            }
            if response.status != IkStatus::Ok {
                return Err(format!(
                    "waypoint {} of {total} at ({:.3}, {:.3}, {:.3}) mm: {:?}: {}",
                    index + 1,
                    tip.x,
                    tip.y,
                    tip.z,
                    response.status,
                    response.error
                ));
            }
            self.near = response.joints_rad;
            self.solved.push(SolvedWaypoint {
                joints: response.joints_rad,
                counts: response.counts,
            });
        }
        if self.solved.len() == total {
            Ok(PlannerStep::Ready(std::mem::take(&mut self.solved)))
        } else {
            Ok(PlannerStep::Pending)
        }
    }
}

fn lerp<const N: usize>(a: &[f64; N], b: &[f64; N], s: f64) -> [f64; N] {
    std::array::from_fn(|i| a[i] + s * (b[i] - a[i]))
}

/// The line's segments: the approach from the commanded counts `from_counts` to the first
/// waypoint (a cosine move in joint space at up to `approach_speed_rad_s`, counts by
/// `params`), then the `line` phase: dwell, the waypoints interpolated at the setpoint
/// period, dwell.
pub fn line_segments(
    spec: &LineSpec,
    waypoints: &[SolvedWaypoint],
    params: &RobotParams,
    from_counts: &[f64; 5],
    approach_speed_rad_s: f64,
) -> Result<Vec<Segment>, String> {
    let (Some(first), Some(last)) = (waypoints.first(), waypoints.last()) else {
        return Err("the line has no waypoints".into());
    };
    let rest = JointMotion::default();
    let from = params
        .joints_from_fractional_counts(from_counts, &rest)
        .map_err(|e| format!("cannot tell where the robot is: {e}"))?;
    let distance = from
        .iter()
        .zip(&first.joints)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let approach_s = (PI / 2.0 * distance / approach_speed_rad_s).max(MIN_APPROACH_S);
    let periods = (approach_s / PERIOD_S).ceil() as usize;
    let mut approach = Vec::with_capacity(periods);
    let mut approach_counts = Vec::with_capacity(periods);
    for k in 1..=periods {
        let s = 0.5 * (1.0 - (PI * k as f64 / periods as f64).cos());
        let q = lerp(&from, &first.joints, s);
        let counts = if k == periods {
            first.counts
        } else {
            params
                .counts_from_joints(&q, &rest)
                .map_err(|e| format!("approach: {e}"))?
        };
        approach.push(q);
        approach_counts.push(counts);
    }

    let dwell = (spec.dwell_s / PERIOD_S).round() as usize;
    let mut joints = vec![first.joints; dwell];
    let mut counts = vec![first.counts; dwell];
    for pair in waypoints.windows(2) {
        for k in 1..=WAYPOINT_PERIODS {
            let s = k as f64 / WAYPOINT_PERIODS as f64;
            joints.push(lerp(&pair[0].joints, &pair[1].joints, s));
            counts.push(lerp(&pair[0].counts, &pair[1].counts, s));
        }
    }
    joints.extend(std::iter::repeat_n(last.joints, dwell));
    counts.extend(std::iter::repeat_n(last.counts, dwell));
    Ok(vec![
        Segment {
            name: APPROACH.into(),
            phase: false,
            joints: approach,
            counts: Some(approach_counts),
        },
        Segment {
            name: LINE_PHASE.into(),
            phase: true,
            joints,
            counts: Some(counts),
        },
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::limits::{check_plan, JointLimits, DEFAULT_MAX_SPEED_RAD_S, DEFAULT_RANGE_RAD};
    use crate::plan::PERIOD_NS;
    use glam::DVec3;
    use sabr_ik::{IkSolver, ParameterSet};
    use std::path::Path;

    /// A local solver standing in for the IK server.
    struct LocalIk(IkSolver);

    impl IkService for LocalIk {
        fn solve(&mut self, request: IkRequest) -> Result<IkResponse, String> {
            Ok(self.0.solve(&request))
        }
    }

    fn calibrated() -> RobotParams {
        let mut params = RobotParams::nominal();
        params.joints.offset = Some([-2.3, -0.75, 0.02, -2.7, -0.55]);
        params
    }

    fn local_ik(params: &RobotParams, version: u64) -> LocalIk {
        LocalIk(IkSolver::with_parameters(ParameterSet::new(
            params.clone(),
            version,
            Path::new("params.toml"),
        )))
    }

    fn plan_line(
        spec: &LineSpec,
        ik: &mut LocalIk,
        version: u64,
    ) -> Result<Vec<SolvedWaypoint>, String> {
        let mut planner = LinePlanner::new(spec, version, HOME_JOINTS, 0);
        let mut now = 0;
        loop {
            match planner.advance(ik, now, 10)? {
                PlannerStep::Ready(points) => return Ok(points),
                PlannerStep::Pending => now += PERIOD_NS,
            }
        }
    }

    #[test]
    fn default_line_is_straight_reachable_and_within_the_default_limits() {
        let params = calibrated();
        let geometry = RealtimeGeometry::from(&params.effective_geometry());
        let spec =
            LineSpec::centred_insertion(&geometry, &params.joints.home_stops, 20.0, 5.0, 0.5)
                .unwrap();
        let waypoints = plan_line(&spec, &mut local_ik(&params, 2), 2).unwrap();
        assert_eq!(waypoints.len(), spec.waypoints().len());
        // Start from the stops (as after homing) and play the whole plan through the check.
        let stops_counts = params
            .counts_from_joints(&params.joints.home_stops, &JointMotion::default())
            .unwrap();
        let segments = line_segments(&spec, &waypoints, &params, &stops_counts, 0.25).unwrap();
        let limits = JointLimits::from_stops(
            &params.joints.home_stops,
            DEFAULT_RANGE_RAD,
            DEFAULT_MAX_SPEED_RAD_S,
        );
        check_plan(&limits, &params.joints.home_stops, &segments).unwrap();
        // Every setpoint of the line puts the tip on the line (FK of the interpolated joints),
        // from its start to its end, with the needle along it.
        let line = &segments[1];
        let start = DVec3::from_array(spec.start.coords.into());
        let direction = DVec3::from_array(spec.direction.into_inner().into());
        let mut max_off = 0.0f64;
        for q in &line.joints {
            let pose = geometry.forward(q).unwrap();
            let along = (pose.tip - start).dot(direction);
            let off = (pose.tip - start - direction * along).length();
            max_off = max_off.max(off);
            assert!((-1e-6..=spec.length_mm + 1e-6).contains(&along));
            assert!((pose.direction - direction).length() < 1e-6);
        }
        assert!(max_off < 1e-3, "tip leaves the line by {max_off} mm");
        let last = geometry.forward(line.joints.last().unwrap()).unwrap();
        let end = DVec3::from_array(spec.end().coords.into());
        assert!((last.tip - end).length() < 1e-6);
        // Counts of the line are the IK server's: each waypoint's counts at its sample.
        let counts = line.counts.as_ref().unwrap();
        let dwell = (spec.dwell_s / PERIOD_S).round() as usize;
        assert_eq!(counts[dwell - 1], waypoints[0].counts);
        assert_eq!(counts[dwell - 1 + WAYPOINT_PERIODS], waypoints[1].counts);
        // The approach starts next to the stops and ends at the first waypoint exactly.
        let approach = &segments[0];
        assert_eq!(
            approach.counts.as_ref().unwrap().last(),
            Some(&waypoints[0].counts)
        );
        assert!(approach.duration_s() >= MIN_APPROACH_S);
    }

    #[test]
    fn an_unreachable_waypoint_refuses_the_line_and_names_it() {
        let params = calibrated();
        let geometry = RealtimeGeometry::from(&params.effective_geometry());
        let mut spec =
            LineSpec::centred_insertion(&geometry, &params.joints.home_stops, 20.0, 5.0, 0.5)
                .unwrap();
        spec.length_mm = 400.0;
        let reason = plan_line(&spec, &mut local_ik(&params, 1), 1).unwrap_err();
        assert!(reason.starts_with("waypoint "), "{reason}");
        assert!(reason.contains("Unreachable"), "{reason}");
    }

    #[test]
    fn the_planner_waits_briefly_for_the_server_to_load_the_planned_parameter_set() {
        let params = calibrated();
        let geometry = RealtimeGeometry::from(&params.effective_geometry());
        let spec = LineSpec::centred_insertion(&geometry, &params.joints.home_stops, 5.0, 5.0, 0.1)
            .unwrap();
        let mut old_server = local_ik(&params, 1);
        let mut planner = LinePlanner::new(&spec, 2, HOME_JOINTS, 0);
        assert_eq!(
            planner.advance(&mut old_server, 1_000, 5).unwrap(),
            PlannerStep::Pending
        );
        let reason = planner
            .advance(&mut old_server, VERSION_WAIT_NS + 1, 5)
            .unwrap_err();
        assert!(reason.contains("v1") && reason.contains("v2"), "{reason}");
        let mut newer_server = local_ik(&params, 3);
        let mut planner = LinePlanner::new(&spec, 2, HOME_JOINTS, 0);
        assert!(planner.advance(&mut newer_server, 0, 5).is_err());
    }

    #[test]
    fn bad_line_numbers_are_rejected() {
        let params = calibrated();
        let geometry = RealtimeGeometry::from(&params.effective_geometry());
        let stops = params.joints.home_stops;
        assert!(LineSpec::centred_insertion(&geometry, &stops, 0.0, 5.0, 0.5).is_err());
        assert!(LineSpec::centred_insertion(&geometry, &stops, 10.0, f64::NAN, 0.5).is_err());
        assert!(LineSpec::centred_insertion(&geometry, &stops, 10.0, 5.0, -1.0).is_err());
    }
}
