//! The server loop of the `sabr-ik` process: sleeps on the process's doorbell until a client
//! rings it with a request or a parameter announcement arrives, then answers every pending
//! request.
//!
//! It never spins: an idle server wakes only every [`POLL_PERIOD`] (heartbeat, stop check).

use crate::solver::{IkSolver, ReloadOutcome};
use sabr_msgs::{services, IkRequest, IkResponse, IkStatus, ParameterSetAnnouncement};
use sabr_node::{Exit, NodeError, NodeRuntime, Subscriber, HEARTBEAT_PERIOD};
use std::time::{Duration, Instant};

/// Longest sleep of the server loop: the heartbeat period.
pub const POLL_PERIOD: Duration = HEARTBEAT_PERIOD;

/// Requests answered, by outcome.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ServeCounts {
    /// Answered with a solution.
    pub solved: u64,
    /// Answered with an error status.
    pub refused: u64,
    /// Responses that could not be sent (the client left).
    pub send_failures: u64,
}

/// Serves [`services::IK_SOLVE`] with `solver` until SIGINT/SIGTERM, reloading parameters on
/// announcements from the calibrator. Announces readiness once its ports exist.
pub fn serve(
    rt: &mut NodeRuntime,
    solver: &mut IkSolver,
) -> Result<(Exit, ServeCounts), NodeError> {
    let server = rt.server::<IkRequest, IkResponse>(services::IK_SOLVE)?;
    let announcements =
        rt.subscriber::<ParameterSetAnnouncement>(services::CALIBRATOR_PARAMETERS)?;
    // An announcement made before the server started (kept as history) applies now.
    apply_announcements(&announcements, solver)?;
    let mut counts = ServeCounts::default();
    let exit = rt.run_on_data(&[&server, &announcements], POLL_PERIOD, |ctx| {
        if ctx.woken_by(&announcements) {
            apply_announcements(&announcements, solver)?;
        }
        if !ctx.woken_by(&server) {
            return Ok(());
        }
        let answered = server.answer(|request| {
            let started = Instant::now();
            let mut response = solver.solve(request);
            response.solve_ns = u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
            if response.status == IkStatus::Ok {
                counts.solved += 1;
            } else {
                counts.refused += 1;
                tracing::debug!(id = response.id, status = ?response.status, reason = %response.error, "refused");
            }
            response
        })?;
        counts.send_failures += answered.undelivered as u64;
        Ok::<_, NodeError>(())
    })?;
    Ok((exit, counts))
}

/// Loads every announced parameter set (oldest first); a bad file is logged and the set in
/// service stays.
fn apply_announcements(
    announcements: &Subscriber<ParameterSetAnnouncement>,
    solver: &mut IkSolver,
) -> Result<(), NodeError> {
    announcements.drain(|announcement| match solver.reload(&announcement) {
        Ok(ReloadOutcome::Loaded { version }) => {
            tracing::info!(version, path = %announcement.path, "parameter set in service");
        }
        Ok(ReloadOutcome::Ignored { announced, current }) => {
            tracing::info!(
                announced,
                current,
                "announced parameter set is not newer; ignored"
            );
        }
        Err(error) => {
            let kept = solver.parameters().map(|set| set.version);
            tracing::error!(%error, version = announcement.version, ?kept,
                "rejected the announced parameter set; the previous one stays in service");
        }
    })?;
    Ok(())
}
