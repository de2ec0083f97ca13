//! `sabr export mcap REC --out FILE.mcap [--calibration DIR]`: writes a recording as MCAP for
//! Foxglove (topics and frames: docs/robot-model.md §8), with the nominal model and the
//! offsets of the homing phase, or with a calibrated `params.toml` and the residual per
//! tracker frame.

use sabr_node::outln;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use sabr_foxglove::{export_recording, read_calibrated_params, ExportModel};
use sabr_recording::Recording;

/// Arguments of `sabr export`.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    #[command(subcommand)]
    command: ExportCommand,
}

#[derive(Debug, clap::Subcommand)]
enum ExportCommand {
    /// A recording as MCAP with Foxglove schemas: robot and marker frames, joint states,
    /// tip, phases, and with --calibration the residual per tracker frame.
    Mcap(McapArgs),
}

/// Arguments of `sabr export mcap`.
#[derive(Debug, clap::Args)]
struct McapArgs {
    /// Recording directory (format v1: robot.toml, encoders.csv, tracker.csv, phases.csv).
    #[arg(value_name = "REC")]
    recording: PathBuf,
    /// The MCAP file to write (must not exist).
    #[arg(long, value_name = "FILE.mcap")]
    out: PathBuf,
    /// A `sabr calibrate` output directory: its params.toml places the robot frames and the
    /// residuals are written [default: the recording's robot.toml, offsets from homing].
    #[arg(long, value_name = "DIR")]
    calibration: Option<PathBuf>,
}

/// Runs `sabr export ...`.
pub fn run(args: &ExportArgs) -> anyhow::Result<ExitCode> {
    match &args.command {
        ExportCommand::Mcap(mcap) => run_mcap(mcap),
    }
}

fn run_mcap(args: &McapArgs) -> anyhow::Result<ExitCode> {
    let started = Instant::now();
    let recording = Recording::read(&args.recording)
        .with_context(|| format!("cannot read the recording {}", args.recording.display()))?;
    let model = match &args.calibration {
        Some(dir) => {
            ExportModel::Calibrated(Box::new(read_calibrated_params(&dir.join("params.toml"))?))
        }
        None => ExportModel::Nominal,
    };
    let summary = export_recording(&recording, &model, &args.out)?;
    let size = std::fs::metadata(&args.out).map_or(0, |meta| meta.len());
    outln!(
        "wrote {} ({:.1} MB) in {:.2} s: {} encoder samples, {} tracker frames, {} phases",
        args.out.display(),
        size as f64 / 1e6,
        started.elapsed().as_secs_f64(),
        recording.encoders.len(),
        summary.tracker_frames,
        recording.phases.len()
    );
    for (topic, count) in &summary.messages {
        outln!(
            "  {:<22} {:>8} messages  {}",
            topic.name(),
            count,
            topic.schema().name
        );
    }
    if let Some(medians) = summary.median_residual_mm {
        let shown = medians.map(|m| m.map_or("–".to_owned(), |m| format!("{m:.3} mm")));
        outln!(
            "median residual of the calibrated model: front {}, back {}, tip {}",
            shown[0],
            shown[1],
            shown[2]
        );
    }
    Ok(ExitCode::SUCCESS)
}
