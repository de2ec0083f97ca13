//! The live calibrator: collect the session, calibrate once it is complete, announce, and
//! (simulation only) evaluate the straight-line test.
//!
//! ## Why the raw streams and not `sync`'s matched samples
//!
//! The calibration estimates the tracker latency itself (it is a parameter of the joint fit)
//! and re-interpolates the encoders at every latency it tries; a matched sample is frozen at
//! `sync`'s latency and cannot be re-matched. So the calibrator subscribes to exactly what the
//! recorder writes — encoder samples, tracker frames and phase marks — and keeps them as the
//! same recording rows ([`sabr_recording::live`], under the writer's rules), then hands them to the
//! same library call as `sabr calibrate`. The library uses only the session's span of the data
//! (`sabr_calibration::data::span`), so the parameters equal those of `sabr calibrate` on the
//! recorder's recording, which also holds the graph's idle start and the later line test.
//!
//! ## Refusals
//!
//! The calibrator never announces a model from incomplete data: a motion fault or a session
//! that ends without every calibration phase, streams that stall before the session's end,
//! a calibrator that started listening after the session started, lost samples beyond
//! `--max-lost-fraction`, and every refusal of the library end the process with an error
//! naming the reason (the launcher then stops the graph as failed).

mod line_test;
mod session;

use anyhow::{bail, Context};
use sabr_calibration::{
    calibrate, write_outputs, Calibration, CalibrationError, CalibrationOptions,
};
use sabr_msgs::{
    services, EncoderSample, FixedString, MotionState, MotionStatus, MotorSetpoint,
    ParameterSetAnnouncement, PhaseMark, RigTruth, TrackerFrame,
};
use sabr_node::{
    monotonic_ns, out, outln, Exit, LoopCtx, NodeRuntime, Publisher, Subscriber, Waitable,
};
use std::path::{Path, PathBuf};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use line_test::{LineTest, LineTestReport};
use session::{LiveSession, Progress, StreamStats};

/// Longest sleep of the loop without data.
const IDLE: Duration = Duration::from_millis(50);

/// Command line of the live calibrator.
#[derive(Debug, clap::Parser)]
#[command(name = "sabr-calibrator", version, about)]
pub struct Args {
    /// Output directory of params.toml, report.json, report.html [default:
    /// $SABR_RUN_DIR/calibration].
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// The nominal model of the session, as given to the recorder [default: the built-in
    /// nominal model].
    #[arg(long, value_name = "FILE")]
    robot_toml: Option<PathBuf>,
    /// Version number of the announced parameter set.
    #[arg(long, value_name = "N", default_value_t = 1)]
    version: u64,
    /// Longest wait, after the last calibration phase, for the streams to cover the end of
    /// the session, s.
    #[arg(long, value_name = "S", default_value_t = 5.0)]
    tail_timeout_s: f64,
    /// Refuse to calibrate when more than this fraction of the encoder samples or tracker
    /// frames was lost on the way to the calibrator.
    #[arg(long, value_name = "F", default_value_t = 0.001)]
    max_lost_fraction: f64,
    /// After announcing, evaluate the straight-line test (phase `--line-phase`) against the
    /// rig's truth (`sabr/rig/truth`). Simulation only: the truth is never used to calibrate.
    #[arg(long)]
    line_test: bool,
    /// Phase name of the straight-line test.
    #[arg(
        long,
        value_name = "NAME",
        default_value = "line",
        requires = "line_test"
    )]
    line_phase: String,
    /// Announce the graph's job done when finished (after the line test with `--line-test`).
    #[arg(long)]
    finish_graph: bool,
}

/// Runs the live calibrator until its job is done or it is stopped.
pub fn run(args: &Args, rt: &mut NodeRuntime) -> anyhow::Result<Exit> {
    if !(args.tail_timeout_s.is_finite() && args.tail_timeout_s > 0.0) {
        bail!(
            "--tail-timeout-s {}: must be a positive number",
            args.tail_timeout_s
        );
    }
    if !(0.0..=1.0).contains(&args.max_lost_fraction) {
        bail!(
            "--max-lost-fraction {}: must be between 0 and 1",
            args.max_lost_fraction
        );
    }
    let robot_toml = robot_toml(args.robot_toml.as_deref())?;
    let out = output_dir(args)?;
    let ports = Ports::open(rt, args.line_test)?;
    let mut calibrator = Calibrator {
        args,
        out,
        session: LiveSession::new(robot_toml),
        stage: Stage::Collecting { tail_since: None },
        line_test: args.line_test.then(|| LineTest::new(&args.line_phase)),
        last_status: None,
    };
    let inputs = ports.inputs();
    let exit = rt.run_on_data(&inputs, IDLE, |ctx| calibrator.step(ctx, &ports))?;
    tracing::info!(?exit, "calibrator leaving");
    Ok(exit)
}

/// The nominal model: the file given (checked), else the built-in one (as the recorder).
fn robot_toml(path: Option<&Path>) -> anyhow::Result<String> {
    let Some(path) = path else {
        return Ok(sabr_model::RobotParams::nominal().to_toml_string());
    };
    let robot = sabr_recording::RobotToml::read(path).context("--robot-toml")?;
    let text = robot.text.clone();
    robot.biopsy().context("--robot-toml")?;
    Ok(text)
}

fn output_dir(args: &Args) -> anyhow::Result<PathBuf> {
    let dir = sabr_node::in_run_dir(args.out.as_deref(), "calibration", "--out")?;
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("cannot create the output directory {}", dir.display()))?;
    dir.canonicalize()
        .with_context(|| format!("cannot resolve {}", dir.display()))
}

/// The calibrator's ports.
struct Ports {
    encoders: Subscriber<EncoderSample>,
    frames: Subscriber<TrackerFrame>,
    motion_phases: Subscriber<PhaseMark>,
    rig_phases: Subscriber<PhaseMark>,
    status: Subscriber<MotionStatus>,
    truth: Option<Subscriber<RigTruth>>,
    setpoints: Option<Subscriber<MotorSetpoint>>,
    announcer: Publisher<ParameterSetAnnouncement>,
}

impl Ports {
    fn open(rt: &NodeRuntime, line_test: bool) -> anyhow::Result<Self> {
        Ok(Self {
            encoders: rt.subscriber(services::ENCODER_SAMPLES)?,
            frames: rt.subscriber(services::TRACKER_FRAMES)?,
            motion_phases: rt.subscriber(services::MOTION_PHASES)?,
            rig_phases: rt.subscriber(services::RIG_PHASES)?,
            status: rt.subscriber(services::MOTION_STATUS)?,
            truth: line_test
                .then(|| rt.subscriber(services::RIG_TRUTH))
                .transpose()?,
            setpoints: line_test
                .then(|| rt.subscriber(services::MOTION_SETPOINTS))
                .transpose()?,
            announcer: rt.publisher(services::CALIBRATOR_PARAMETERS)?,
        })
    }

    fn inputs(&self) -> Vec<&dyn Waitable> {
        let mut inputs: Vec<&dyn Waitable> = vec![
            &self.encoders,
            &self.frames,
            &self.motion_phases,
            &self.rig_phases,
            &self.status,
        ];
        inputs.extend(self.truth.as_ref().map(|s| s as &dyn Waitable));
        // The setpoints (1 kHz) are drained on the other wake-ups: no need to wake on them.
        inputs
    }
}

/// Where the calibrator is.
enum Stage {
    /// Keeping the session's rows until the calibration phases and the tail are in.
    Collecting {
        /// When the last calibration phase arrived (the tail timeout runs from there).
        tail_since: Option<Instant>,
    },
    /// The library is calibrating on a worker thread.
    Calibrating {
        worker: JoinHandle<Result<Calibration, CalibrationError>>,
        started: Instant,
    },
    /// Announced; evaluating the straight-line test when it comes.
    Testing {
        calibration: Box<Calibration>,
        summary: String,
    },
    /// Nothing left to do but stay up until stopped.
    Finished,
}

struct Calibrator<'a> {
    args: &'a Args,
    out: PathBuf,
    session: LiveSession,
    stage: Stage,
    line_test: Option<LineTest>,
    /// The motion's last state and reason, to show changes only.
    last_status: Option<(MotionState, FixedString<96>)>,
}

impl Calibrator<'_> {
    /// One wake-up: take the new messages, then move on if the stage is complete.
    fn step(&mut self, ctx: &mut LoopCtx, ports: &Ports) -> anyhow::Result<()> {
        let collecting = matches!(self.stage, Stage::Collecting { .. });
        let mut marks = Vec::new();
        ports.motion_phases.drain(|mark| marks.push(mark))?;
        ports.rig_phases.drain(|mark| marks.push(mark))?;
        if collecting {
            ports
                .encoders
                .drain(|sample| self.session.encoder(&sample))?;
        } else {
            ports.encoders.drain(|_| {})?;
        }
        let mut frames = Vec::new();
        ports.frames.drain(|frame| frames.push(frame))?;
        for frame in &frames {
            if collecting {
                self.session.frame(frame);
            }
        }
        if let Some(test) = &mut self.line_test {
            if let Some(truth) = &ports.truth {
                truth.drain(|t| test.truth(t))?;
            }
            if let Some(setpoints) = &ports.setpoints {
                setpoints.drain(|s| test.setpoint(s))?;
            }
            frames.iter().for_each(|f| test.frame(*f));
        }
        for mark in &marks {
            outln!(
                "phase {} done ({:.1} s)",
                mark.phase.as_str(),
                (mark.t_end_ns - mark.t_start_ns) as f64 * 1e-9
            );
            if collecting {
                self.session.phase(mark);
            } else if let Some(test) = &mut self.line_test {
                test.phase(mark);
            }
        }
        let mut statuses = Vec::new();
        ports.status.drain(|status| statuses.push(status))?;
        for status in &statuses {
            self.show_status(status);
            if collecting {
                self.check_status(status)?;
            } else if let Some(test) = &mut self.line_test {
                test.motion_status(status)?;
            }
        }
        self.advance(ctx, ports)
    }

    /// Prints the motion's state when it changes (the progress of the session).
    fn show_status(&mut self, status: &MotionStatus) {
        let shown = (status.state, status.reason);
        if self.last_status != Some(shown) {
            self.last_status = Some(shown);
            outln!("motion {:?}: {}", status.state, status.reason.as_str());
        }
    }

    /// A motion fault or a finished session while the phases are still missing is a refusal.
    fn check_status(&self, status: &MotionStatus) -> anyhow::Result<()> {
        let missing = match self.session.progress() {
            Progress::Phases(missing) => missing,
            _ => return Ok(()),
        };
        match status.state {
            MotionState::Faulted => bail!(
                "refusing to calibrate: the motion faulted ({}) before the calibration phases \
                 were complete (missing: {})",
                status.reason.as_str(),
                missing.join(", ")
            ),
            MotionState::Finished => bail!(
                "refusing to calibrate: the motion session finished without the phases {}",
                missing.join(", ")
            ),
            MotionState::Idle | MotionState::Moving => Ok(()),
        }
    }

    fn advance(&mut self, ctx: &mut LoopCtx, ports: &Ports) -> anyhow::Result<()> {
        match &mut self.stage {
            Stage::Collecting { tail_since } => match self.session.progress() {
                Progress::Phases(_) => {}
                Progress::Tail { end_ns } => {
                    let since = *tail_since.get_or_insert_with(Instant::now);
                    if since.elapsed().as_secs_f64() > self.args.tail_timeout_s {
                        bail!(
                            "refusing to calibrate: the encoder and tracker streams did not reach \
                             the end of the session (t = {end_ns} ns) within {} s of its last \
                             phase: they stalled",
                            self.args.tail_timeout_s
                        );
                    }
                }
                Progress::Complete => self.start_calibration()?,
            },
            Stage::Calibrating { worker, .. } if worker.is_finished() => {
                let Stage::Calibrating { worker, started } =
                    std::mem::replace(&mut self.stage, Stage::Finished)
                else {
                    return Ok(());
                };
                let calibration = worker
                    .join()
                    .map_err(|_| anyhow::anyhow!("the calibration thread panicked"))?
                    .context("refusing to announce: the calibration failed")?;
                self.publish(calibration, started, ports)?;
                if self.line_test.is_none() && self.args.finish_graph {
                    ctx.finish_graph();
                }
            }
            Stage::Testing {
                calibration,
                summary,
            } => {
                let Some(test) = &self.line_test else {
                    return Ok(());
                };
                if let Some(report) = test.evaluate_when_complete(calibration)? {
                    finish_line_test(&self.out, summary, &report)?;
                    self.stage = Stage::Finished;
                    if self.args.finish_graph {
                        ctx.finish_graph();
                    }
                }
            }
            Stage::Calibrating { .. } | Stage::Finished => {}
        }
        Ok(())
    }

    /// Checks the collected session and starts the library on a worker thread.
    fn start_calibration(&mut self) -> anyhow::Result<()> {
        let stats = self.session.stats();
        let span = self
            .session
            .span()
            .context("the session has phases but no span")?;
        match self.session.first_encoder_ns() {
            Some(first) if first <= span.start_ns => {}
            first => bail!(
                "refusing to calibrate: the calibrator's data starts at {first:?} ns, after the \
                 session's data start {} ns: it started listening too late",
                span.start_ns
            ),
        }
        check_losses(&stats, self.args.max_lost_fraction)?;
        let dir = match sabr_node::run_dir() {
            Some(run) => PathBuf::from(format!("live session of {}", run.display())),
            None => PathBuf::from("live session"),
        };
        let recording = self.session.to_recording(dir);
        tracing::info!(?stats, "session complete; calibrating");
        outln!(
            "session complete: {} encoder samples, {} tracker frames, {} phases; calibrating…",
            stats.encoder_samples,
            stats.tracker_frames,
            stats.phases
        );
        write_json(
            &self.out.join("live.json"),
            &LiveReport {
                streams: stats,
                version: self.args.version,
            },
        )?;
        let worker = std::thread::Builder::new()
            .name("calibrate".into())
            .spawn(move || calibrate(&recording, &CalibrationOptions::default()))
            .context("cannot start the calibration thread")?;
        self.stage = Stage::Calibrating {
            worker,
            started: Instant::now(),
        };
        Ok(())
    }

    /// Writes the outputs, announces the parameter set and prints the summary.
    fn publish(
        &mut self,
        calibration: Calibration,
        started: Instant,
        ports: &Ports,
    ) -> anyhow::Result<()> {
        write_outputs(&calibration, &self.out)?;
        let params = self.out.join("params.toml");
        let path = FixedString::new(&params.display().to_string())
            .map_err(|e| anyhow::anyhow!("{}: path too long to announce: {e}", params.display()))?;
        ports.announcer.send(ParameterSetAnnouncement {
            version: self.args.version,
            t_ns: monotonic_ns(),
            path,
        })?;
        let summary = summary(&calibration, started.elapsed());
        out!("{summary}");
        write_text(&self.out.join("summary.txt"), &summary)?;
        tracing::info!(version = self.args.version, path = %params.display(), "parameter set announced");
        self.stage = if self.line_test.is_some() {
            outln!(
                "waiting for the straight-line test (phase {})…",
                self.args.line_phase
            );
            Stage::Testing {
                calibration: Box::new(calibration),
                summary,
            }
        } else {
            Stage::Finished
        };
        Ok(())
    }
}

/// What `live.json` holds: the live streams behind the announced parameter set.
#[derive(Debug, serde::Serialize)]
struct LiveReport {
    streams: StreamStats,
    version: u64,
}

/// Refuses a session whose streams lost more than `max_fraction` on the way.
fn check_losses(stats: &StreamStats, max_fraction: f64) -> anyhow::Result<()> {
    let fraction = |lost: u64, kept: u64| lost as f64 / (lost + kept).max(1) as f64;
    for (what, lost, kept) in [
        ("encoder samples", stats.encoder_lost, stats.encoder_samples),
        ("tracker frames", stats.tracker_lost, stats.tracker_frames),
    ] {
        if fraction(lost, kept) > max_fraction {
            bail!(
                "refusing to calibrate: {lost} of {} {what} were lost on the way to the \
                 calibrator (more than {max_fraction})",
                lost + kept
            );
        }
        if lost > 0 {
            tracing::warn!(lost, what, "samples lost on the way to the calibrator");
        }
    }
    Ok(())
}

/// The before/after errors: the library's summary (nominal, paper model, after each effect).
fn summary(calibration: &Calibration, took: Duration) -> String {
    let report = &calibration.report;
    format!(
        "calibrated in {:.1} s: tracker latency {:.2} ± {:.2} ms\n{}",
        took.as_secs_f64(),
        report.latency_ms,
        report.latency_std_ms,
        sabr_calibration::report::summary_text(report)
    )
}

fn finish_line_test(out: &Path, summary: &str, report: &LineTestReport) -> anyhow::Result<()> {
    write_json(&out.join("line_test.json"), report)?;
    let text = report.text();
    out!("{text}");
    write_text(&out.join("summary.txt"), &format!("{summary}{text}"))
}

fn write_json(path: &Path, value: &impl serde::Serialize) -> anyhow::Result<()> {
    let json = serde_json::to_string_pretty(value)?;
    write_text(path, &json)
}

fn write_text(path: &Path, text: &str) -> anyhow::Result<()> {
    sabr_calibration::report::output::write_atomically(path, text.as_bytes())?;
    Ok(())
}
