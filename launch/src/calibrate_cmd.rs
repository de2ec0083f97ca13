//! `sabr calibrate RECORDING --out DIR`: calibrates the robot from a recording. A recording
//! of the biopsy robot (format v1) gives `params.toml` (readable by `sabr fk`/`sabr ik`),
//! `report.json`, `report.html` and `validation_predictions.csv`; a poses-v1 recording of an
//! arm described by URDF gives `params.json` (and `params-<step>.json` per step),
//! `report.json` and `report.html` (docs/measured-data.md).

use sabr_node::{out, outln};
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use sabr_calibration::calibrate_serial::{calibrate_serial, write_serial_outputs, SerialOptions};
use sabr_calibration::{calibrate, write_outputs, CalibrationOptions};
use sabr_recording::poses::PosesRecording;
use sabr_recording::Recording;

/// Arguments of `sabr calibrate`.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// Recording directory (format v1: robot.toml, encoders.csv, tracker.csv, phases.csv).
    #[arg(value_name = "RECORDING")]
    recording: PathBuf,
    /// Output directory (created if needed; the output files in it are replaced atomically).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Poses-v1 only: fraction of the poses held out at random to measure each step.
    #[arg(long, default_value_t = 0.2)]
    holdout: f64,
    /// Poses-v1 only: seed of the held-out draw and of the loop's folds.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Poses-v1 only: fit pose targets with their orientation (default: positions only).
    #[arg(long)]
    with_orientation: bool,
}

/// Whether `dir` holds a poses-v1 recording (its `robot.toml` says `format = "poses-v1"`).
pub fn is_poses_recording(dir: &std::path::Path) -> bool {
    std::fs::read_to_string(dir.join(sabr_recording::ROBOT_TOML))
        .ok()
        .and_then(|text| text.parse::<toml::Table>().ok())
        .and_then(|table| table.get("format")?.as_str().map(str::to_owned))
        .is_some_and(|format| format == sabr_recording::poses::POSES_FORMAT)
}

fn run_serial(args: &CalibrateArgs) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(
        (0.0..1.0).contains(&args.holdout),
        "--holdout {}: must be at least 0 and below 1",
        args.holdout
    );
    let recording = PosesRecording::read(&args.recording)
        .with_context(|| format!("cannot read the recording {}", args.recording.display()))?;
    let options = SerialOptions {
        holdout: args.holdout,
        seed: args.seed,
        use_orientation: args.with_orientation,
    };
    let calibration = calibrate_serial(&recording, &options)
        .with_context(|| format!("cannot calibrate from {}", args.recording.display()))?;
    let written = write_serial_outputs(&calibration, &args.out).map_err(anyhow::Error::msg)?;
    let report = &calibration.report;
    outln!(
        "{}: {} poses fitted, {} held out",
        report.robot,
        report.poses[0],
        report.poses[1]
    );
    outln!("step                                 params  fit RMS mm  held-out RMS / mean / max mm");
    for step in &report.steps {
        let held = step.held_out.map_or("–".to_string(), |s| {
            format!("{:.3} / {:.3} / {:.3}", s.rms_mm, s.mean_mm, s.max_mm)
        });
        outln!(
            "{:<36} {:>6} {:>11.3}  {held}",
            step.model,
            step.parameters,
            step.fit.rms_mm
        );
    }
    outln!(
        "dropped by identifiability: {} parameters; rejected families: {}",
        report.dropped_parameters.len(),
        if report.rejected.is_empty() {
            "none".to_string()
        } else {
            report.rejected.join(", ")
        }
    );
    outln!(
        "wrote {} to {} in {:.2} s",
        written.join(", "),
        args.out.display(),
        report.run_time_s
    );
    Ok(ExitCode::SUCCESS)
}

/// Runs `sabr calibrate`: prints a short summary of the errors of the nominal model, the
/// stepwise (paper) method and the joint fit.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<ExitCode> {
    if is_poses_recording(&args.recording) {
        return run_serial(args);
    }
    let recording = Recording::read(&args.recording)
        .with_context(|| format!("cannot read the recording {}", args.recording.display()))?;
    let calibration = calibrate(&recording, &CalibrationOptions::default())
        .with_context(|| format!("cannot calibrate from {}", args.recording.display()))?;
    write_outputs(&calibration, &args.out)?;
    let report = &calibration.report;
    outln!(
        "tracker latency {:.2} ± {:.2} ms",
        report.latency_ms,
        report.latency_std_ms
    );
    outln!("model      front mm  back mm  tip mm  held-out marker tip RMS mm");
    for r in &report.residual_rms {
        let held_out = r
            .validation_marker_tip
            .map_or("–".to_string(), |e| format!("{:.3}", e.rms_mm));
        outln!(
            "{:<9} {:>9.3} {:>8.3} {:>7.3}  {held_out}",
            r.model,
            r.front_mm,
            r.back_mm,
            r.tip_mm
        );
    }
    if let Some(tip) = report.validation.tip_error {
        outln!(
            "tip error ({}): RMS {:.3} mm, max {:.3} mm over {}",
            report.validation.tip_error_source,
            tip.rms_mm,
            tip.max_mm,
            tip.count
        );
    }
    let identifiability = &report.identifiability;
    outln!(
        "identifiability: rank {} of {}, condition number {:.3e}, {} fixed",
        identifiability.rank,
        identifiability.parameters,
        identifiability.condition_number,
        identifiability.fixed.len()
    );
    out!("{}", sabr_calibration::report::summary_text(report));
    outln!(
        "wrote params.toml, report.json, report.html, validation_predictions.csv to {} in {:.2} s",
        args.out.display(),
        report.run_time_s
    );
    Ok(ExitCode::SUCCESS)
}
