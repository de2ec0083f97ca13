//! The server loop of the `sabr-ik` process: sleeps in a WaitSet until a client's wake-up, a
//! parameter announcement or the heartbeat interval, then answers every pending request.
//!
//! It never spins: an idle server wakes only every [`POLL_PERIOD`] (heartbeat, stop check,
//! and a poll for requests of clients that did not wake it).

use crate::solver::{IkSolver, ReloadOutcome};
use sabr_msgs::{services, IkRequest, IkResponse, IkStatus, ParameterSetAnnouncement};
use sabr_node::iceoryx2::prelude::{ipc, CallbackProgression, WaitSetBuilder};
use sabr_node::iceoryx2::waitset::WaitSetRunResult;
use sabr_node::{NodeError, NodeRuntime, Server, Subscriber, Waitable, HEARTBEAT_PERIOD};
use std::time::Duration;

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
pub fn serve(rt: &mut NodeRuntime, solver: &mut IkSolver) -> Result<ServeCounts, NodeError> {
    let server = rt.server::<IkRequest, IkResponse>(services::IK_SOLVE)?;
    let wakeups = rt.listener(services::IK_SOLVE)?;
    let announcements =
        rt.subscriber::<ParameterSetAnnouncement>(services::CALIBRATOR_PARAMETERS)?;
    let waitset = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| port_error("create a WaitSet", e))?;
    let request_guard = waitset
        .attach_notification(&wakeups)
        .map_err(|e| port_error("wait for client wake-ups", e))?;
    let announcement_guard = waitset
        .attach_notification(announcements.wake_listener())
        .map_err(|e| port_error("wait for parameter announcements", e))?;
    let tick_guard = waitset
        .attach_interval(POLL_PERIOD)
        .map_err(|e| port_error("attach the poll interval", e))?;

    // An announcement made before the server started (kept as history) applies now.
    apply_announcements(&announcements, solver)?;
    rt.ready();
    let mut counts = ServeCounts::default();
    loop {
        let (mut tick, mut announced) = (false, false);
        let result = waitset.wait_and_process_once(|id| {
            tick |= id.has_event_from(&tick_guard);
            announced |= id.has_event_from(&announcement_guard);
            // Wake-ups from clients need no flag: requests are polled on every wake.
            let _ = id.has_event_from(&request_guard);
            CallbackProgression::Continue
        });
        match result {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => break,
            Ok(_) => {}
            Err(error) => tracing::warn!(?error, "WaitSet wait failed"),
        }
        // Drain the wake-ups before reading requests, so a request sent after the last read
        // always leaves a wake-up behind.
        let _ = wakeups.try_wait(|_| {});
        answer_requests(&server, solver, &mut counts)?;
        if announced {
            announcements.clear();
            apply_announcements(&announcements, solver)?;
        }
        if tick && !rt.keep_running() {
            break;
        }
    }
    Ok(counts)
}

/// Answers every request waiting on the server.
fn answer_requests(
    server: &Server<IkRequest, IkResponse>,
    solver: &IkSolver,
    counts: &mut ServeCounts,
) -> Result<(), NodeError> {
    while let Some(request) = server
        .receive()
        .map_err(|e| port_error("receive a request", e))?
    {
        let response = solver.solve(request.payload());
        if response.status == IkStatus::Ok {
            counts.solved += 1;
        } else {
            counts.refused += 1;
            tracing::debug!(id = response.id, status = ?response.status, reason = %response.error, "refused");
        }
        if let Err(error) = request.send_copy(response) {
            counts.send_failures += 1;
            tracing::warn!(?error, id = response.id, "cannot send the response");
        }
    }
    Ok(())
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

fn port_error(operation: &'static str, error: impl std::fmt::Debug) -> NodeError {
    NodeError::Port {
        service: services::IK_SOLVE.to_owned(),
        operation,
        reason: format!("{error:?}"),
    }
}
