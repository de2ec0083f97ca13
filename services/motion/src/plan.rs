//! Plans as sampled joint trajectories, and the calibration session plan taken from the
//! simulator's session plan (`sabr_model::plan::SessionPlan`: excitation, tip phase, validation).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sabr_model::plan::{excitation_centre, PlanDurations, SessionPlan};
use sabr_model::{Joints, RobotParams, HOME_JOINTS};

/// Setpoint period (ns): setpoints go out at 1 kHz.
pub const PERIOD_NS: i64 = sabr_msgs::SETPOINT_PERIOD_NS;
/// Setpoint period (s).
pub const PERIOD_S: f64 = PERIOD_NS as f64 * 1e-9;
/// Name of the pieces of a plan between its phases (moves and pauses).
pub const TRANSITION: &str = "transition";

/// One named piece of a plan, sampled every [`PERIOD_NS`].
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// What the motion status says while it plays (a phase name, or [`TRANSITION`]).
    pub name: String,
    /// True if it is a session phase, announced as a `PhaseMark` when it ends.
    pub phase: bool,
    /// Commanded joints θ1..θ5 (rad), one per setpoint period.
    pub joints: Vec<Joints>,
    /// Motor counts of `joints` when known at planning time (from the IK server); `None`:
    /// converted with the parameters in force when the segment plays (after homing).
    pub counts: Option<Vec<[f64; 5]>>,
}

impl Segment {
    /// Duration (s).
    pub fn duration_s(&self) -> f64 {
        self.joints.len() as f64 * PERIOD_S
    }
}

/// Samples the plan every [`PERIOD_NS`] over `[from_ns, to_ns)`, or `[from_ns, to_ns]` when
/// `inclusive`.
fn sample(plan: &SessionPlan, from_ns: i64, to_ns: i64, inclusive: bool) -> Vec<Joints> {
    let mut samples = Vec::with_capacity(((to_ns - from_ns) / PERIOD_NS + 2) as usize);
    let mut t = from_ns;
    while t < to_ns || (inclusive && t == to_ns) {
        samples.push(plan.joints_at(t));
        t += PERIOD_NS;
    }
    samples
}

/// The simulator's session plan for a robot that starts at its nominal stops (as the model
/// sees it after homing): homing itself is done by sensing the stops, so the plan's own
/// homing is built to end exactly at the stops (its overtravel target is moved back by the
/// overtravel the simulator uses) and only what follows it is played.
fn session_plan_from_stops(
    params: &RobotParams,
    durations: &PlanDurations,
    seed: u64,
) -> Result<(SessionPlan, i64), String> {
    let stops = params.joints.home_stops;
    let centre = excitation_centre(&stops, &HOME_JOINTS);
    let build = |homing_target: &Joints| {
        SessionPlan::build(
            &params.geometry,
            homing_target,
            &centre,
            &stops,
            durations,
            &mut ChaCha8Rng::seed_from_u64(seed),
        )
        .map_err(|e| format!("cannot build the session plan: {e}"))
    };
    let homing_end = |plan: &SessionPlan| {
        plan.phases()
            .iter()
            .find(|p| p.name == "homing")
            .map(|p| (p.start_ns, p.end_ns))
            .ok_or_else(|| "the session plan has no homing phase".to_string())
    };
    let first = build(&stops)?;
    let overtravel = first.joints_at(homing_end(&first)?.0);
    let target: Joints = std::array::from_fn(|i| 2.0 * stops[i] - overtravel[i]);
    let plan = build(&target)?;
    let (dwell_start, dwell_end) = homing_end(&plan)?;
    let at_stops = plan.joints_at(dwell_start);
    if at_stops
        .iter()
        .zip(&stops)
        .any(|(a, b)| (a - b).abs() > 1e-9)
    {
        return Err(format!(
            "the session plan dwells at {at_stops:?} rad, not at the nominal stops {stops:?}"
        ));
    }
    Ok((plan, dwell_end))
}

/// The calibration session after homing, as segments: transitions, `excitation`, `tip`,
/// `validation`, with durations scaled by `scale` (1 ≈ 5 minutes) and random choices
/// (multi-sine phases, validation poses) from `seed`. Starts at the nominal stops.
pub fn calibration_segments(
    params: &RobotParams,
    scale: f64,
    seed: u64,
) -> Result<Vec<Segment>, String> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(format!(
            "the duration scale must be a positive number, got {scale}"
        ));
    }
    let durations = PlanDurations::default().scaled(scale);
    let (plan, start_ns) = session_plan_from_stops(params, &durations, seed)?;
    let end_ns = plan.end_ns();
    let mut segments = Vec::new();
    let mut t = start_ns;
    let phases = plan.phases().iter().filter(|p| p.start_ns >= start_ns);
    for phase in phases {
        if phase.start_ns > t {
            segments.push(segment(
                TRANSITION,
                false,
                sample(&plan, t, phase.start_ns, false),
            ));
        }
        let last = phase.end_ns >= end_ns;
        let joints = sample(&plan, phase.start_ns, phase.end_ns, last);
        segments.push(segment(phase.name, true, joints));
        t = phase.end_ns;
    }
    if t < end_ns {
        segments.push(segment(TRANSITION, false, sample(&plan, t, end_ns, true)));
    }
    Ok(segments)
}

fn segment(name: &str, phase: bool, joints: Vec<Joints>) -> Segment {
    Segment {
        name: name.to_owned(),
        phase,
        joints,
        counts: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn calibration_plan_starts_at_the_stops_and_has_the_sessions_phases() {
        let params = RobotParams::nominal();
        let segments = calibration_segments(&params, 0.05, 7).unwrap();
        let phases: Vec<&str> = segments
            .iter()
            .filter(|s| s.phase)
            .map(|s| s.name.as_str())
            .collect();
        assert_eq!(phases, ["excitation", "tip", "validation"]);
        assert_eq!(segments[0].name, TRANSITION);
        let first = segments[0].joints[0];
        for (a, b) in first.iter().zip(&params.joints.home_stops) {
            assert!((a - b).abs() < 1e-9, "{first:?}");
        }
        // Durations follow the simulator's scaled phase durations.
        let durations = PlanDurations::default().scaled(0.05);
        let excitation = segments.iter().find(|s| s.name == "excitation").unwrap();
        assert!((excitation.duration_s() - durations.excitation_s).abs() < 2e-3);
        let tip = segments.iter().find(|s| s.name == "tip").unwrap();
        assert!((tip.duration_s() - durations.tip_s).abs() < 2e-3);
        // Same seed, same plan; another seed, another plan.
        assert_eq!(segments, calibration_segments(&params, 0.05, 7).unwrap());
        assert_ne!(segments, calibration_segments(&params, 0.05, 8).unwrap());
    }

    #[test]
    fn bad_scales_are_rejected() {
        let params = RobotParams::nominal();
        for scale in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(calibration_segments(&params, scale, 1).is_err());
        }
    }
}
