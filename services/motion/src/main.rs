//! `sabr-motion`: the motion executor process. Runs sessions (homing into the stops,
//! excitation, tip phase, validation poses, a straight-line insertion through the IK server)
//! as 1 kHz `MotorSetpoint`s, announces phases and status, refuses plans outside the joint and
//! speed limits before moving, and stops the robot when encoder or tracker feedback goes stale.

mod cli;
mod executor;
#[cfg(test)]
mod executor_tests;
mod feedback;
mod homing;
mod limits;
mod line;
mod plan;

use executor::{Event, Executor, Outcome};
use line::{IkService, LineSpec};
use sabr_ik::{IkClient, ParameterSet};
use sabr_msgs::{
    services, EncoderSample, FixedString, IkRequest, IkResponse, MotionState, MotionStatus,
    MotorSetpoint, ParameterSetAnnouncement, PhaseMark, TrackerFrame,
};
use sabr_node::{monotonic_ns, Exit, NodeRuntime, Publisher};
use std::path::Path;
use std::process::ExitCode;
use std::time::Duration;

/// The IK server as the line planner sees it.
struct RemoteIk {
    client: IkClient,
    timeout: Duration,
}

impl IkService for RemoteIk {
    fn solve(&mut self, request: IkRequest) -> Result<IkResponse, String> {
        self.client
            .solve(request, self.timeout)
            .map_err(|e| e.to_string())
    }
}

/// The publishing side of the node.
struct Outputs {
    setpoints: Publisher<MotorSetpoint>,
    status: Publisher<MotionStatus>,
    phases: Publisher<PhaseMark>,
    setpoint_seq: u64,
    status_seq: u64,
    phase_seq: u64,
}

impl Outputs {
    fn new(rt: &NodeRuntime) -> anyhow::Result<Self> {
        Ok(Self {
            setpoints: rt.publisher(services::MOTION_SETPOINTS)?,
            status: rt.publisher(services::MOTION_STATUS)?,
            phases: rt.publisher(services::MOTION_PHASES)?,
            setpoint_seq: 0,
            status_seq: 0,
            phase_seq: 0,
        })
    }

    fn status(&mut self, now_ns: i64, state: MotionState, reason: &str) -> anyhow::Result<()> {
        self.status_seq += 1;
        match state {
            MotionState::Faulted => tracing::error!(reason, "motion faulted: the robot holds"),
            _ => tracing::info!(?state, reason, "motion status"),
        }
        self.status.send(MotionStatus {
            seq: self.status_seq,
            t_ns: now_ns,
            state,
            reason: FixedString::truncated(reason),
        })?;
        Ok(())
    }

    fn publish(&mut self, now_ns: i64, event: Event) -> anyhow::Result<()> {
        match event {
            Event::Setpoint(target_counts) => {
                self.setpoint_seq += 1;
                self.setpoints.send(MotorSetpoint {
                    seq: self.setpoint_seq,
                    t_ns: now_ns,
                    target_counts,
                })?;
            }
            Event::Status { state, reason } => self.status(now_ns, state, &reason)?,
            Event::Phase {
                name,
                start_ns,
                end_ns,
            } => {
                self.phase_seq += 1;
                tracing::info!(phase = %name, seconds = (end_ns - start_ns) as f64 * 1e-9, "phase done");
                self.phases.send(PhaseMark {
                    seq: self.phase_seq,
                    t_start_ns: start_ns,
                    t_end_ns: end_ns,
                    phase: FixedString::truncated(&name),
                })?;
            }
            Event::LinePlanned { spec, version } => write_line_record(&spec, version),
        }
        Ok(())
    }
}

/// The commanded line, for whoever evaluates it (`line.toml` in the run directory).
#[derive(serde::Serialize)]
struct LineRecord {
    parameter_version: u64,
    start_mm: [f64; 3],
    end_mm: [f64; 3],
    direction: [f64; 3],
    length_mm: f64,
    peak_speed_mm_s: f64,
}

fn write_line_record(spec: &LineSpec, version: u64) {
    let Some(dir) = sabr_node::run_dir() else {
        return;
    };
    let record = LineRecord {
        parameter_version: version,
        start_mm: spec.start.coords.into(),
        end_mm: spec.end().coords.into(),
        direction: spec.direction.into_inner().into(),
        length_mm: spec.length_mm,
        peak_speed_mm_s: spec.speed_mm_s,
    };
    let path = dir.join("line.toml");
    let written = toml::to_string(&record)
        .map_err(|e| e.to_string())
        .and_then(|text| std::fs::write(&path, text).map_err(|e| e.to_string()));
    if let Err(error) = written {
        tracing::warn!(path = %path.display(), error, "cannot write the line record");
    }
}

/// Loads every announced parameter set; a bad file is logged and ignored.
fn load_announced(announcement: &ParameterSetAnnouncement) -> Option<ParameterSet> {
    match ParameterSet::load(Path::new(announcement.path.as_str()), announcement.version) {
        Ok(set) => {
            tracing::info!(version = set.version, path = %set.path.display(), "parameter set announced");
            Some(set)
        }
        Err(error) => {
            tracing::error!(%error, version = announcement.version,
                "rejected the announced parameter set; keeping the previous one");
            None
        }
    }
}

fn run(args: &cli::Args, rt: &mut NodeRuntime) -> anyhow::Result<Exit> {
    let mut outputs = Outputs::new(rt)?;
    let encoders = rt.subscriber::<EncoderSample>(services::ENCODER_SAMPLES)?;
    let frames = rt.subscriber::<TrackerFrame>(services::TRACKER_FRAMES)?;
    let announcements =
        rt.subscriber::<ParameterSetAnnouncement>(services::CALIBRATOR_PARAMETERS)?;
    let mut ik = RemoteIk {
        client: IkClient::new(rt)?,
        timeout: Duration::from_secs_f64(args.ik_timeout_ms.max(0.0) * 1e-3),
    };

    // Everything that can be refused is refused here, before any setpoint.
    let prepared = args.robot_params().and_then(|params| {
        let limits = args.limits(&params)?;
        let tasks = args.tasks(&params, &limits)?;
        let config = args.executor_config(limits)?;
        Ok((params, tasks, config))
    });
    let (params, tasks, config) = match prepared {
        Ok(prepared) => prepared,
        Err(error) => {
            let reason = format!("{error:#}");
            outputs.status(monotonic_ns(), MotionState::Faulted, &reason)?;
            return hold_after_fault(rt, args, reason);
        }
    };
    for task in &tasks {
        if let executor::Task::Play(segments) = task {
            let seconds: f64 = segments.iter().map(plan::Segment::duration_s).sum();
            tracing::info!(
                seconds,
                "calibration plan checked: within the joint and speed limits"
            );
        }
    }
    let mut executor = Executor::new(config, params, tasks, monotonic_ns());
    let mut events = Vec::new();
    let mut fault = None;
    let exit = rt.run_loop(Duration::from_nanos(plan::PERIOD_NS as u64), |ctx| {
        encoders.drain(|sample| executor.on_encoder(sample.t_ns, sample.counts))?;
        frames.drain(|frame| executor.on_tracker(frame.arrival_t_ns))?;
        let mut announced = Vec::new();
        announcements.drain(|a| announced.push(a))?;
        announced
            .iter()
            .filter_map(load_announced)
            .for_each(|set| executor.on_parameters(set));
        let now_ns = monotonic_ns();
        let outcome = executor.tick(now_ns, &mut ik, &mut events);
        for event in events.drain(..) {
            outputs.publish(now_ns, event)?;
        }
        match outcome {
            Outcome::Running => {}
            Outcome::Finished if args.finish_when_done => ctx.finish_graph(),
            Outcome::Finished => ctx.stop(),
            Outcome::Faulted(reason) => {
                tracing::error!(hold = ?executor.commanded(), "holding the last setpoint");
                fault = Some(reason);
                ctx.stop();
            }
        }
        Ok::<_, anyhow::Error>(())
    })?;
    if exit == Exit::Signal {
        return Ok(exit);
    }
    match fault {
        Some(reason) => hold_after_fault(rt, args, reason),
        // Finished without ending the graph: hold (the rig keeps the last setpoint) until
        // stopped.
        None => Ok(rt.idle()),
    }
}

/// After a fault (the status says why): exit at once with `--exit-on-fault`, else stay, the
/// robot holding its last setpoint, until stopped; either way the exit is a failure.
fn hold_after_fault(
    rt: &mut NodeRuntime,
    args: &cli::Args,
    reason: String,
) -> anyhow::Result<Exit> {
    if !args.exit_on_fault {
        rt.idle();
    }
    Err(anyhow::anyhow!("faulted: {reason}"))
}

fn main() -> ExitCode {
    sabr_node::service_main("motion", run)
}
