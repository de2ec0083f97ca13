//! `sabr calibrate RECORDING --out DIR`: calibrates the robot from a recording and writes
//! `params.toml` (readable by `sabr fk`/`sabr ik`), `report.json`, `report.html` and
//! `validation_predictions.csv` to DIR.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use sabr_calibration::{calibrate, write_outputs, CalibrationOptions};
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
}

/// Runs `sabr calibrate`: prints a short summary of the errors of the nominal model, the
/// stepwise (paper) method and the joint fit.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<ExitCode> {
    let recording = Recording::read(&args.recording)
        .with_context(|| format!("cannot read the recording {}", args.recording.display()))?;
    let calibration = calibrate(&recording, &CalibrationOptions::default())
        .with_context(|| format!("cannot calibrate from {}", args.recording.display()))?;
    write_outputs(&calibration, &args.out)?;
    let report = &calibration.report;
    println!(
        "tracker latency {:.2} ± {:.2} ms",
        report.latency_ms, report.latency_std_ms
    );
    println!("model      front mm  back mm  tip mm  held-out marker tip RMS mm");
    for r in &report.residual_rms {
        let held_out = r
            .validation_marker_tip
            .map_or("–".to_string(), |e| format!("{:.3}", e.rms_mm));
        println!(
            "{:<9} {:>9.3} {:>8.3} {:>7.3}  {held_out}",
            r.model, r.front_mm, r.back_mm, r.tip_mm
        );
    }
    if let Some(tip) = report.validation.tip_error {
        println!(
            "tip error ({}): RMS {:.3} mm, max {:.3} mm over {}",
            report.validation.tip_error_source, tip.rms_mm, tip.max_mm, tip.count
        );
    }
    let identifiability = &report.identifiability;
    println!(
        "identifiability: rank {} of {}, condition number {:.3e}, {} fixed",
        identifiability.rank,
        identifiability.parameters,
        identifiability.condition_number,
        identifiability.fixed.len()
    );
    print!("{}", sabr_calibration::report::summary_text(report));
    println!(
        "wrote params.toml, report.json, report.html, validation_predictions.csv to {} in {:.2} s",
        args.out.display(),
        report.run_time_s
    );
    Ok(ExitCode::SUCCESS)
}
