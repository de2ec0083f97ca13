//! `sabr evaluate --params FILE REC [--refit-setup] [--json]`: the position error of a
//! calibrated serial arm (a `params.json` of `sabr calibrate` on a poses-v1 recording) on
//! another poses-v1 recording of the same robot. `--refit-setup` registers and fits only
//! the set-up frames (a new instrument placement) and keeps everything else.

use sabr_node::outln;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use sabr_calibration::calibrate_serial::evaluate_serial;
use sabr_calibration::model::serial::params_file::SerialParamsFile;
use sabr_recording::poses::PosesRecording;

/// Arguments of `sabr evaluate`.
#[derive(Debug, clap::Args)]
pub struct EvaluateArgs {
    /// Calibrated parameters (`params.json` of `sabr calibrate`).
    #[arg(long, value_name = "FILE")]
    params: PathBuf,
    /// Poses-v1 recording to evaluate on.
    #[arg(value_name = "REC")]
    recording: PathBuf,
    /// Fit the set-up frames again (a new instrument placement) before measuring.
    #[arg(long)]
    refit_setup: bool,
    /// Print one JSON object: rms_mm, mean_mm, max_mm, count.
    #[arg(long)]
    json: bool,
}

/// Runs `sabr evaluate`.
pub fn run(args: &EvaluateArgs) -> anyhow::Result<ExitCode> {
    let text = std::fs::read_to_string(&args.params)
        .with_context(|| format!("cannot read {}", args.params.display()))?;
    let params = SerialParamsFile::parse(&args.params, &text)?;
    let recording = PosesRecording::read(&args.recording)
        .with_context(|| format!("cannot read the recording {}", args.recording.display()))?;
    let stats = evaluate_serial(&recording, &params, &args.params, args.refit_setup)
        .with_context(|| format!("cannot evaluate on {}", args.recording.display()))?;
    if args.json {
        outln!("{}", serde_json::to_string(&stats)?);
    } else {
        outln!(
            "position error over {} measurements: RMS {:.3} mm, mean {:.3} mm, max {:.3} mm",
            stats.count,
            stats.rms_mm,
            stats.mean_mm,
            stats.max_mm
        );
    }
    Ok(ExitCode::SUCCESS)
}
