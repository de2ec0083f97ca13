//! `sabr calibrate` end to end: `sabr sim record` → `sabr calibrate` → `sabr fk` with the
//! calibrated `params.toml`.
//!
//! The accuracy test calibrates a simulated session and is ignored in debug builds (a debug
//! calibration takes about a minute); run it with
//! `cargo test --release -p sabr --test calibrate_cli`.

mod common;

use common::{arg, run};
use std::path::Path;

use sabr_sim::Truth;

/// Data rows of a CSV (header skipped) as numbers.
fn rows(text: &str) -> Vec<Vec<f64>> {
    text.lines()
        .skip(1)
        .map(|line| line.split(',').map(|v| v.parse().unwrap()).collect())
        .collect()
}

fn record(dir: &Path, seed: &str, scale: &str) {
    let (ok, _, stderr) = run(&[
        "sim",
        "record",
        "--out",
        arg(dir),
        "--seed",
        seed,
        "--duration-scale",
        scale,
    ]);
    assert!(ok, "{stderr}");
}

#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "heavy: cargo test --release -p sabr --test calibrate_cli"
)]
fn fk_with_the_calibrated_params_reproduces_the_predictions_and_the_truth() {
    let work = tempfile::tempdir().unwrap();
    let recording = work.path().join("recording");
    let out = work.path().join("calibration");
    record(&recording, "21", "0.5");

    let (ok, stdout, stderr) = run(&["calibrate", arg(&recording), "--out", arg(&out)]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("tracker latency") && stdout.contains("stepwise"),
        "{stdout}"
    );
    for file in [
        "params.toml",
        "report.json",
        "report.html",
        "validation_predictions.csv",
    ] {
        assert!(out.join(file).is_file(), "{file} missing");
    }

    // `sabr fk` reproduces the calibrator's own predictions at the validation holds.
    let predictions = out.join("validation_predictions.csv");
    let params = out.join("params.toml");
    let (ok, stdout, stderr) = run(&[
        "fk",
        "--params",
        arg(&params),
        "--counts",
        arg(&predictions),
    ]);
    assert!(ok, "{stderr}");
    let expected = rows(&std::fs::read_to_string(&predictions).unwrap());
    let fk = rows(&stdout);
    assert!(!expected.is_empty());
    assert_eq!(fk.len(), expected.len());
    for (fk_row, expected_row) in fk.iter().zip(&expected) {
        for k in 0..6 {
            assert!(
                (fk_row[k] - expected_row[5 + k]).abs() < 1e-9,
                "{fk_row:?} vs {expected_row:?}"
            );
        }
    }

    // And at the true validation poses it is within the accuracy goal of the truth.
    let truth = Truth::read_dir(&recording.join("truth")).unwrap();
    let mut counts = "c1,c2,c3,c4,c5\n".to_owned();
    for hold in &truth.validation {
        let c = hold.counts;
        counts += &format!("{},{},{},{},{}\n", c[0], c[1], c[2], c[3], c[4]);
    }
    let counts_path = work.path().join("truth_counts.csv");
    std::fs::write(&counts_path, counts).unwrap();
    let (ok, stdout, stderr) = run(&[
        "fk",
        "--params",
        arg(&params),
        "--counts",
        arg(&counts_path),
    ]);
    assert!(ok, "{stderr}");
    let tips = rows(&stdout);
    let squared: f64 = tips
        .iter()
        .zip(&truth.validation)
        .map(|(row, hold)| (0..3).map(|k| (row[k] - hold.tip[k]).powi(2)).sum::<f64>())
        .sum();
    let rms = (squared / tips.len() as f64).sqrt();
    assert!(rms <= 0.15, "tip error {rms:.4} mm RMS against the truth");
}

#[test]
fn a_recording_without_a_tip_phase_is_refused_naming_it() {
    let work = tempfile::tempdir().unwrap();
    let recording = work.path().join("recording");
    let out = work.path().join("calibration");
    record(&recording, "4", "0.1");
    let phases = recording.join("phases.csv");
    let text = std::fs::read_to_string(&phases).unwrap();
    let kept: Vec<&str> = text
        .lines()
        .filter(|line| !line.ends_with(",tip"))
        .collect();
    assert!(kept.len() < text.lines().count(), "the tip phase was there");
    std::fs::write(&phases, kept.join("\n") + "\n").unwrap();

    let (ok, stdout, stderr) = run(&["calibrate", arg(&recording), "--out", arg(&out)]);
    assert!(!ok, "{stdout}");
    assert!(stderr.contains("phase `tip` is missing"), "{stderr}");
    assert!(!out.join("params.toml").exists(), "no model may be written");
}
