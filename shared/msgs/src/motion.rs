//! Acting messages: motor setpoints, IK request/response, parameter sets, session phases.

use crate::{FixedString, JOINTS};
use iceoryx2::prelude::ZeroCopySend;

/// Period of the motion node's setpoints (ns): it publishes a [`MotorSetpoint`] every 1 ms.
pub const SETPOINT_PERIOD_NS: i64 = 1_000_000;

/// Most [`IkRequest`]s the motion node sends back to back in one setpoint period: its line
/// planner solves the line's waypoints in bursts of this many per period, so the IK server
/// sees bursts, the first request of each finding the path cold after a period of other work.
pub const IK_REQUESTS_PER_SETPOINT_PERIOD: usize = 10;

/// A position setpoint for the five motors (published by `motion` at 1 kHz, read by the rig).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.MotorSetpoint.v1")]
pub struct MotorSetpoint {
    /// Sequence number, +1 per setpoint.
    pub seq: u64,
    /// Host `CLOCK_MONOTONIC` time at which the setpoint applies, ns.
    pub t_ns: i64,
    /// Target encoder counts of joints 1..5 (fractional counts allowed).
    pub target_counts: [f64; JOINTS],
}

/// Request to the IK server: needle tip and direction → joints.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.IkRequest.v1")]
pub struct IkRequest {
    /// Caller-chosen id, echoed in the response.
    pub id: u64,
    /// Target needle tip `p_n` in the robot base `Bb`, mm.
    pub tip_mm: [f64; 3],
    /// Target needle direction `z_N` in `Bb` (need not be normalised; zero is invalid).
    pub direction: [f64; 3],
    /// Current joints θ1..θ5, rad: the solution closest to them is chosen.
    pub near_joints_rad: [f64; JOINTS],
}

/// Outcome of an IK request.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, ZeroCopySend)]
pub enum IkStatus {
    /// Solved; `joints_rad` and `counts` are valid.
    Ok,
    /// The target is outside the workspace.
    Unreachable,
    /// The request holds NaN, infinite or degenerate values.
    #[default]
    InvalidInput,
    /// The server has no valid parameter set loaded.
    NoParameters,
}

/// Response of the IK server to an [`IkRequest`].
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.IkResponse.v2")]
pub struct IkResponse {
    /// The request's id.
    pub id: u64,
    /// Whether the solution is valid.
    pub status: IkStatus,
    /// Human-readable reason when `status` is not `Ok` (empty otherwise).
    pub error: FixedString<96>,
    /// Joint angles θ1..θ5, rad.
    pub joints_rad: [f64; JOINTS],
    /// Encoder counts of those joints under the current parameters.
    pub counts: [f64; JOINTS],
    /// Version of the parameter set used ([`ParameterSetAnnouncement::version`]).
    pub parameter_version: u64,
    /// How long the server spent solving this request, ns (its `CLOCK_MONOTONIC`, from the
    /// request in hand to the response's contents): a round trip's time outside the
    /// transport. 0 when no server solved it.
    pub solve_ns: u64,
}

/// Announces that a new calibration parameter file was written (by `calibrator`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.ParameterSetAnnouncement.v1")]
pub struct ParameterSetAnnouncement {
    /// Increasing version number of the parameter set.
    pub version: u64,
    /// Host `CLOCK_MONOTONIC` time of the announcement, ns.
    pub t_ns: i64,
    /// Absolute path of the `params.toml` that was written atomically.
    pub path: FixedString<256>,
}

/// A completed session phase (homing, excitation, tip, validation, …), for `phases.csv`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.PhaseMark.v1")]
pub struct PhaseMark {
    /// Sequence number, +1 per phase.
    pub seq: u64,
    /// Start of the phase, host `CLOCK_MONOTONIC` ns.
    pub t_start_ns: i64,
    /// End of the phase, host `CLOCK_MONOTONIC` ns.
    pub t_end_ns: i64,
    /// Phase name as written to the recording.
    pub phase: FixedString<32>,
}

/// State of the motion executor.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, ZeroCopySend)]
pub enum MotionState {
    /// Holding position, no motion running.
    #[default]
    Idle,
    /// Executing a motion.
    Moving,
    /// Stopped on a fault (stale feedback, refused plan); `reason` says why.
    Faulted,
    /// The session finished.
    Finished,
}

/// Status of the motion executor, published on every state change.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("sabr.MotionStatus.v1")]
pub struct MotionStatus {
    /// Sequence number, +1 per status.
    pub seq: u64,
    /// Host `CLOCK_MONOTONIC` time of the change, ns.
    pub t_ns: i64,
    /// The new state.
    pub state: MotionState,
    /// Why (for `Faulted`), or the running phase's name.
    pub reason: FixedString<96>,
}
