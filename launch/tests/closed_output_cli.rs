//! `sabr` commands whose standard output goes away: a reader who left (`| head`) ends the
//! printing quietly and the command still does its work; a failing output (a full disk) is
//! an error naming standard output.

mod common;

use common::arg;
use std::path::Path;
use std::process::{Command, Output, Stdio};

use sabr_model::RobotParams;

/// Runs `sabr args` with standard output a pipe whose reader has already left.
fn run_with_reader_gone(args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    Command::new(env!("CARGO_BIN_EXE_sabr"))
        .args(args)
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .unwrap()
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Records a short simulated session into `dir` with nobody reading the summary line.
fn record_with_reader_gone(dir: &Path) {
    let output = run_with_reader_gone(&[
        "sim",
        "record",
        "--out",
        arg(dir),
        "--seed",
        "3",
        "--duration-scale",
        "0.1",
    ]);
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(stderr(&output).is_empty(), "{}", stderr(&output));
    for file in [
        "encoders.csv",
        "tracker.csv",
        "robot.toml",
        "truth/params.toml",
    ] {
        assert!(dir.join(file).is_file(), "{file} missing");
    }
}

#[test]
fn sim_record_finishes_its_recording_when_the_reader_left() {
    let work = tempfile::tempdir().unwrap();
    record_with_reader_gone(&work.path().join("recording"));
}

/// The nominal robot's `robot.toml` in `dir`.
fn nominal_robot(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("robot.toml");
    std::fs::write(&path, RobotParams::nominal().to_toml_string()).unwrap();
    path
}

/// A joints CSV of `rows` rows near the contract's first test vector.
fn joints_csv(dir: &Path, rows: usize) -> std::path::PathBuf {
    let mut csv = "q1,q2,q3,q4,q5\n".to_owned();
    for i in 0..rows {
        let dq = i as f64 * 1e-5;
        csv += &format!("{},-0.777628,0,-2.685073,-0.601543\n", -2.368404 + dq);
    }
    let path = dir.join("joints.csv");
    std::fs::write(&path, csv).unwrap();
    path
}

#[test]
fn fk_ends_quietly_when_the_reader_left() {
    let work = tempfile::tempdir().unwrap();
    let robot = nominal_robot(work.path());
    // More rows than a pipe buffers, so the command meets the closed pipe mid-stream.
    let joints = joints_csv(work.path(), 20_000);
    let output = run_with_reader_gone(&["fk", "--params", arg(&robot), "--joints", arg(&joints)]);
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(stderr(&output).is_empty(), "{}", stderr(&output));
}

#[test]
fn a_full_standard_output_is_an_error_naming_it() {
    let work = tempfile::tempdir().unwrap();
    let robot = nominal_robot(work.path());
    let joints = joints_csv(work.path(), 10);
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_sabr"))
        .args(["fk", "--params", arg(&robot), "--joints", arg(&joints)])
        .stdout(full)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = stderr(&output);
    assert!(
        stderr.contains("cannot write to standard output: No space left on device"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "heavy: cargo test --release -p sabr --test closed_output_cli"
)]
fn calibrate_writes_its_outputs_when_the_reader_left() {
    let work = tempfile::tempdir().unwrap();
    let recording = work.path().join("recording");
    let out = work.path().join("calibration");
    record_with_reader_gone(&recording);
    let output = run_with_reader_gone(&["calibrate", arg(&recording), "--out", arg(&out)]);
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(!stderr(&output).contains("panicked"), "{}", stderr(&output));
    for file in ["params.toml", "report.json", "report.html"] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
}
