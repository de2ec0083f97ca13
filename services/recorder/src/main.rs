//! `sabr-recorder`: writes the live streams of the graph as a recording (format v2,
//! docs/robot-model.md §7) that `sabr calibrate` reads offline.
//!
//! Subscribes to `sabr/encoders/samples` (→ `encoders.csv`), `sabr/tracker/frames`
//! (→ `tracker.csv`, one row per tool), and `sabr/motion/phases` and `sabr/rig/phases`
//! (→ `phases.csv`). Rows reach the operating system at least every `--flush-ms`, so a
//! recorder killed with SIGKILL leaves a recording readable up to its last complete row; on
//! SIGINT/SIGTERM every file is flushed and synced to disk. With `--mcap` the same rows also
//! go to `session.mcap` (Foxglove), finished with its index on a clean stop.

mod recorder;

use anyhow::{bail, Context};
use recorder::{Continuity, Recorder};
use sabr_msgs::{services, EncoderSample, PhaseMark, TrackerFrame};
use sabr_node::{Exit, NodeRuntime, StallWatch, StatusTimer};
use sabr_recording::{FlushPolicy, RecordingError};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Command line of the recorder.
#[derive(Debug, clap::Parser)]
#[command(name = "sabr-recorder", about)]
struct Args {
    /// Recording directory [default: $SABR_RUN_DIR/recording]. If it already holds files
    /// (e.g. a restarted recorder), DIR-2, DIR-3, ... is used instead: nothing is overwritten.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// The nominal model written as robot.toml [default: the built-in nominal model].
    #[arg(long, value_name = "FILE")]
    robot_toml: Option<PathBuf>,
    /// About the longest time a written row stays in the recorder's buffers, ms.
    #[arg(long, value_name = "MS", default_value_t = 50)]
    flush_ms: u64,
    /// Also write the session as MCAP for Foxglove to DIR/session.mcap (robot frames from the
    /// end of homing on; topics in docs/robot-model.md §8).
    #[arg(long)]
    mcap: bool,
    /// Warn when no encoder sample or tracker frame arrives for this long, ms.
    #[arg(long, value_name = "MS", default_value_t = 500)]
    stall_ms: u64,
}

/// The MCAP file's name inside the recording directory (with `--mcap`).
const MCAP_FILE: &str = "session.mcap";
/// Longest sleep of the loop without data.
const IDLE: Duration = Duration::from_millis(20);
/// Index of the encoder stream in [`Watch::streams`].
const ENCODER_STREAM: usize = 0;
/// Index of the tracker stream in [`Watch::streams`].
const TRACKER_STREAM: usize = 1;
/// Most numbered alternatives tried for the output directory.
const MAX_DIR_SUFFIX: u32 = 999;

fn main() -> ExitCode {
    sabr_node::service_main("recorder", run)
}

/// The nominal model's `robot.toml` text: the file given (checked by the one `robot.toml`
/// reader), else the built-in one.
fn robot_toml(path: Option<&Path>) -> anyhow::Result<String> {
    let Some(path) = path else {
        return Ok(sabr_model::RobotParams::nominal().to_toml_string());
    };
    let robot = sabr_recording::RobotToml::read(path).context("--robot-toml")?;
    let text = robot.text.clone();
    robot.biopsy().context("--robot-toml")?;
    Ok(text)
}

/// `base`, or the first of `base-2`, `base-3`, ... that does not exist or is empty.
fn free_dir(base: &Path) -> anyhow::Result<PathBuf> {
    let usable = |dir: &Path| match std::fs::read_dir(dir) {
        Ok(mut entries) => entries.next().is_none(),
        Err(error) => error.kind() == std::io::ErrorKind::NotFound,
    };
    if usable(base) {
        return Ok(base.to_path_buf());
    }
    for k in 2..=MAX_DIR_SUFFIX {
        let mut name = base.as_os_str().to_owned();
        name.push(format!("-{k}"));
        let dir = PathBuf::from(name);
        if usable(&dir) {
            return Ok(dir);
        }
    }
    bail!(
        "{} and its numbered alternatives up to -{MAX_DIR_SUFFIX} are all in use",
        base.display()
    )
}

fn output_dir(args: &Args) -> anyhow::Result<PathBuf> {
    free_dir(&sabr_node::in_run_dir(
        args.out.as_deref(),
        "recording",
        "--out",
    )?)
}

fn run(args: &Args, rt: &mut NodeRuntime) -> anyhow::Result<Exit> {
    if args.flush_ms == 0 {
        bail!("--flush-ms must be at least 1 ms");
    }
    let toml = robot_toml(args.robot_toml.as_deref())?;
    let dir = output_dir(args)?;
    let flush_every = Duration::from_millis(args.flush_ms);
    let encoders = rt.subscriber::<EncoderSample>(services::ENCODER_SAMPLES)?;
    let frames = rt.subscriber::<TrackerFrame>(services::TRACKER_FRAMES)?;
    let motion_phases = rt.subscriber::<PhaseMark>(services::MOTION_PHASES)?;
    let rig_phases = rt.subscriber::<PhaseMark>(services::RIG_PHASES)?;
    let mut recorder = Recorder::create(&dir, &toml, FlushPolicy::Interval(flush_every))
        .with_context(|| format!("cannot start the recording in {}", dir.display()))?;
    if args.mcap {
        let params = sabr_model::RobotParams::from_toml_str(&toml)
            .context("the robot model for the MCAP stream")?;
        recorder = recorder.with_mcap(&dir.join(MCAP_FILE), params)?;
    }
    if let Some(path) = recorder.mcap_path() {
        tracing::info!(mcap = %path.display(), "also writing the session as MCAP");
    }
    tracing::info!(dir = %dir.display(), flush_ms = args.flush_ms, "recording");

    let stall = Duration::from_millis(args.stall_ms.max(1));
    let mut watch = Watch {
        streams: StallWatch::new(["encoder", "tracker"], stall),
        last_flush: Instant::now(),
        status: StatusTimer::new(),
    };
    let inputs: [&dyn sabr_node::Waitable; 4] = [&encoders, &frames, &motion_phases, &rig_phases];
    let looped = rt.run_on_data(&inputs, IDLE, |_ctx| {
        let mut result = Ok(());
        let mut keep = |written: Result<(), RecordingError>| {
            if let Err(error) = written {
                match error {
                    RecordingError::Refused { .. } => tracing::warn!("row not recorded: {error}"),
                    fatal => {
                        if result.is_ok() {
                            result = Err(fatal);
                        }
                    }
                }
            }
        };
        for subscriber in [&motion_phases, &rig_phases] {
            subscriber.drain(|mark| keep(recorder.phase(&mark)))?;
        }
        frames.drain(|frame| {
            watch.streams.feed(TRACKER_STREAM);
            keep(recorder.frame(&frame));
        })?;
        encoders.drain(|sample| {
            watch.streams.feed(ENCODER_STREAM);
            keep(
                recorder
                    .encoder(&sample)
                    .map(|continuity| match continuity {
                        Continuity::Lost(lost) => tracing::warn!(
                            lost,
                            seq = sample.seq,
                            "encoder samples lost before this one (sequence gap)"
                        ),
                        Continuity::Restarted => tracing::warn!(
                            seq = sample.seq,
                            "encoder sequence restarted (encoders process restarted?)"
                        ),
                        Continuity::InSequence => {}
                    }),
            );
        })?;
        result?;
        if watch.last_flush.elapsed() >= flush_every {
            recorder.flush()?;
            watch.last_flush = Instant::now();
        }
        watch.check(&recorder);
        Ok::<_, anyhow::Error>(())
    });
    // Whatever ended the loop, what was recorded is kept: flush and sync before leaving.
    let dir = recorder.dir().to_path_buf();
    let finished = recorder.finish();
    let exit = looped?;
    let stats =
        finished.with_context(|| format!("cannot finish the recording in {}", dir.display()))?;
    tracing::info!(
        dir = %dir.display(),
        encoder_rows = stats.encoder_rows,
        tracker_frames = stats.tracker_frames,
        phase_rows = stats.phase_rows,
        encoder_lost = stats.encoder_lost,
        encoder_restarts = stats.encoder_restarts,
        refused = stats.refused,
        ?exit,
        "recording finished"
    );
    Ok(exit)
}

/// Stream deadlines, periodic flush and status line.
struct Watch {
    streams: StallWatch<2>,
    last_flush: Instant,
    status: StatusTimer,
}

impl Watch {
    fn check(&mut self, recorder: &Recorder) {
        self.streams.check();
        if self.status.due() {
            let stats = recorder.stats();
            tracing::info!(
                encoder_rows = stats.encoder_rows,
                tracker_frames = stats.tracker_frames,
                phase_rows = stats.phase_rows,
                encoder_lost = stats.encoder_lost,
                refused = stats.refused,
                "status"
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_used_directory_is_never_reused() {
        let dir = tempfile::tempdir().unwrap();
        let base = dir.path().join("recording");
        assert_eq!(free_dir(&base).unwrap(), base);
        std::fs::create_dir(&base).unwrap();
        assert_eq!(free_dir(&base).unwrap(), base, "an empty directory is fine");
        std::fs::write(base.join("robot.toml"), "x").unwrap();
        let second = dir.path().join("recording-2");
        assert_eq!(free_dir(&base).unwrap(), second);
        std::fs::create_dir(&second).unwrap();
        std::fs::write(second.join("robot.toml"), "x").unwrap();
        assert_eq!(free_dir(&base).unwrap(), dir.path().join("recording-3"));
    }

    #[test]
    fn a_bad_robot_toml_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("robot.toml");
        std::fs::write(&path, "format = 1\n[geometry]\nl_f = -1\n").unwrap();
        let error = format!("{:#}", robot_toml(Some(&path)).unwrap_err());
        assert!(error.contains("robot.toml"), "{error}");
        let nominal = robot_toml(None).unwrap();
        assert!(sabr_model::RobotParams::from_toml_str(&nominal).is_ok());
    }
}
