//! The main job as shipped: `launch/graphs/sim-calibration.toml` run by the launcher (same
//! code as `sabr launch`) in a fresh domain and run directory. It must run to completion
//! (exit 0) and leave the recording, the calibration outputs and every node's log; the
//! straight-line test with the new parameters must keep the tip within 0.3 mm RMS of its
//! commanded path (against the simulated rig's truth), and the paper's line-length comparison
//! must be reported.
//!
//! Needs the service binaries: `cargo build --release --workspace --bins` before the tests.
//! The graph runs about a minute (release build); the wall time is printed.

use sabr_integration_tests::LaunchedGraph;
use sabr_recording::Recording;
use std::path::Path;
use std::time::{Duration, Instant};

/// The launch file under test.
const LAUNCH_FILE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../launch/graphs/sim-calibration.toml"
);
/// Longest run of the main job: the goal is 2 minutes; a loaded CI host gets some slack.
const RUN_TIMEOUT: Duration = Duration::from_secs(180);
/// The straight-line test's goal: tip path error against the truth, RMS (mm).
const PATH_ERROR_GOAL_MM: f64 = 0.3;
/// Every node of the graph (one log each).
const NODES: [&str; 8] = sabr_integration_tests::SERVICES;

fn read_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn number(value: &serde_json::Value, what: &str) -> f64 {
    value
        .as_f64()
        .unwrap_or_else(|| panic!("{what} is not a number: {value}"))
}

#[test]
fn the_main_job_calibrates_and_passes_the_straight_line_test() {
    let _alone = sabr_integration_tests::run_alone();
    let text = std::fs::read_to_string(LAUNCH_FILE).expect("read the launch file");
    let started = Instant::now();
    let mut graph = LaunchedGraph::start("mainjob", &text, &[], false);
    let status = graph.wait_exit(RUN_TIMEOUT);
    let wall = started.elapsed();
    let output = graph.output();
    let status = status.unwrap_or_else(|| panic!("not done within {RUN_TIMEOUT:?}:\n{output}"));
    assert!(status.success(), "the main job failed:\n{output}");
    println!("main job wall time {:.1} s", wall.as_secs_f64());

    let runs = graph.run_dirs();
    assert_eq!(runs.len(), 1, "one run directory: {runs:?}");
    let run = &runs[0];

    let recording = Recording::read(&run.join("recording")).expect("the recording reads back");
    for phase in ["homing", "excitation", "tip", "validation", "line"] {
        assert!(
            recording.phases.iter().any(|p| p.phase == phase),
            "phase {phase} missing from the recording: {:?}",
            recording.phases
        );
    }
    let calibration = run.join("calibration");
    for file in ["params.toml", "report.json", "report.html", "summary.txt"] {
        let path = calibration.join(file);
        let size = std::fs::metadata(&path).map_or(0, |m| m.len());
        assert!(size > 0, "{} is missing or empty", path.display());
    }
    let params = std::fs::read_to_string(calibration.join("params.toml")).expect("params.toml");
    let params = sabr_model::RobotParams::from_toml_str(&params).expect("params.toml parses");
    assert!(params.joints.offset.is_some(), "calibrated joint offsets");
    for node in NODES {
        let log = run.join("logs").join(format!("{node}.log"));
        assert!(log.is_file(), "{} is missing", log.display());
    }

    let report = read_json(&calibration.join("report.json"));
    let steps = report["final"]["steps"]
        .as_array()
        .expect("report.json final.steps");
    assert!(!steps.is_empty(), "the residual loop reported no step");

    let line = read_json(&calibration.join("line_test.json"));
    let path_rms = number(&line["tip_path_error"]["rms_mm"], "tip path error RMS");
    let commanded = number(&line["commanded_length_mm"], "commanded length");
    let measured = number(&line["tracker_length_mm"], "tracker-measured length");
    let truth = number(&line["true_length_mm"], "true length");
    println!(
        "straight-line test: tip path error RMS {path_rms:.3} mm; line length commanded \
         {commanded:.3} mm, tracker {measured:.3} mm, true {truth:.3} mm"
    );
    assert!(
        path_rms <= PATH_ERROR_GOAL_MM,
        "tip path error RMS {path_rms:.3} mm > {PATH_ERROR_GOAL_MM} mm"
    );
    assert!(
        (commanded - 20.0).abs() < 1e-6,
        "the line is 20 mm long, commanded {commanded} mm"
    );
    for (what, length) in [("tracker", measured), ("true", truth)] {
        assert!(
            (length - commanded).abs() < 1.0,
            "{what} line length {length:.3} mm is far from the commanded {commanded:.3} mm"
        );
    }
    for shown in [
        "paper model",
        "straight-line test",
        "line length: commanded",
    ] {
        assert!(
            output.contains(shown),
            "the launcher output lacks {shown:?}:\n{output}"
        );
    }
}
