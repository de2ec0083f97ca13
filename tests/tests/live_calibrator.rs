//! The live calibrator in a running graph: rig (autoplaying a short session plan), encoders,
//! tracker, sync, recorder and `sabr-calibrator`, in a fresh domain and run directory.
//!
//! - Its announced parameters are exactly those of `sabr calibrate` on the recording the
//!   recorder wrote, although the recording holds more than the session (the graph's idle
//!   start and end).
//! - A session without tip-sphere readings is refused: nothing announced, no `params.toml`,
//!   the graph fails, and the reason is named.
//!
//! Needs the service binaries: `cargo build --release --workspace --bins` before the tests.
//! Each graph runs about 37 s (release build).

use sabr_integration_tests::{bin, LaunchedGraph};
use sabr_model::RobotParams;
use sabr_msgs::{services, ParameterSetAnnouncement};
use sabr_node::{NodeRuntime, Subscriber};
use sabr_recording::Recording;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// Longest run of the graph (it runs about 37 s).
const RUN_TIMEOUT: Duration = Duration::from_secs(120);

/// The graph; `{tip_sphere}` is the rig's `--tip-sphere` choice.
const GRAPH: &str = r#"
# A tenth of the paper's session: on a twentieth, `sabr calibrate`'s model-free latency search
# (seeds 1-8, true latency 23-45 ms) found anything from 0 to 215 ms, so live jitter sometimes
# put its best delay at the edge of the searched range and the session was refused; on a
# tenth it found 16-62 ms.
[[node]]
name = "rig"
exec = "sabr-rig"
args = ["--autoplay", "--duration-scale", "0.1", "--tip-sphere", "{tip_sphere}",
        "--autoplay-after", "recorder", "--autoplay-after", "calibrator",
        "--autoplay-delay-s", "0.5"]

[[node]]
name = "encoders"
exec = "sabr-encoders"
depends_on = ["rig"]
restart = "on-failure"

[[node]]
name = "tracker"
exec = "sabr-tracker"
depends_on = ["rig"]
restart = "on-failure"
ready_timeout_s = 15.0

[[node]]
name = "sync"
exec = "sabr-sync"
args = ["--latency-ms", "40"]
depends_on = ["encoders", "tracker"]

[[node]]
name = "recorder"
exec = "sabr-recorder"
depends_on = ["encoders", "tracker", "sync"]

[[node]]
name = "calibrator"
exec = "sabr-calibrator"
args = ["--finish-graph"]
depends_on = ["encoders", "tracker"]
console = true
"#;

/// A finished graph: whether the launcher succeeded, its run directory and the parameter
/// sets announced while it ran.
struct Finished {
    success: bool,
    run: PathBuf,
    announced: Vec<ParameterSetAnnouncement>,
    graph: LaunchedGraph,
}

/// Runs the graph to its end, listening to the calibrator's announcements.
fn run_graph(test: &str, tip_sphere: &str) -> Finished {
    let text = GRAPH.replace("{tip_sphere}", tip_sphere);
    let mut graph = LaunchedGraph::start(test, &text, &[], false);
    let started = Instant::now();
    let probe = NodeRuntime::with_domain("probe", graph.domain.clone()).expect("probe node");
    let announcements: Subscriber<ParameterSetAnnouncement> = probe
        .subscriber(services::CALIBRATOR_PARAMETERS)
        .expect("announcement subscriber");
    let mut announced = Vec::new();
    let status = loop {
        announcements
            .drain(|a| announced.push(a))
            .expect("read announcements");
        if let Some(status) = graph.wait_exit(Duration::from_millis(100)) {
            break status;
        }
        assert!(
            started.elapsed() < RUN_TIMEOUT,
            "the graph did not end within {RUN_TIMEOUT:?}:\n{}",
            graph.output()
        );
    };
    announcements
        .drain(|a| announced.push(a))
        .expect("read announcements");
    drop(probe);
    let runs = graph.run_dirs();
    assert_eq!(runs.len(), 1, "one run directory: {runs:?}");
    Finished {
        success: status.success(),
        run: runs[0].canonicalize().expect("run directory"),
        announced,
        graph,
    }
}

fn params(path: &Path) -> RobotParams {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let mut params =
        RobotParams::from_toml_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    // The calibration's source names where the data came from: the only field that differs.
    if let Some(info) = params.calibration.as_mut() {
        info.source = None;
    }
    params
}

#[test]
fn live_parameters_equal_sabr_calibrate_on_the_recording() {
    let _alone = sabr_integration_tests::run_alone();
    let Finished {
        success,
        run,
        announced,
        graph,
    } = run_graph("livecal", "auto");
    let output = graph.output();
    assert!(success, "the graph failed:\n{output}");
    let live_path = run.join("calibration/params.toml");
    assert_eq!(
        announced.len(),
        1,
        "one parameter set announced: {announced:?}"
    );
    assert_eq!(announced[0].version, 1);
    assert_eq!(announced[0].path.as_str(), live_path.display().to_string());

    let live_json = std::fs::read_to_string(run.join("calibration/live.json")).expect("live.json");
    let live: serde_json::Value = serde_json::from_str(&live_json).expect("live.json is JSON");
    let streams = &live["streams"];
    assert_eq!(
        (
            streams["encoder_lost"].as_u64(),
            streams["tracker_lost"].as_u64()
        ),
        (Some(0), Some(0)),
        "the calibrator lost samples, so its data differs from the recording: {live_json}"
    );

    let recording = Recording::read(&run.join("recording")).expect("the recording reads back");
    let live_samples = streams["encoder_samples"]
        .as_u64()
        .expect("encoder_samples");
    assert!(
        recording.encoders.len() as u64 > live_samples,
        "the recording ({} encoder samples) should hold more than the session the calibrator \
         kept ({live_samples})",
        recording.encoders.len()
    );

    let offline = graph.dir.path().join("offline");
    let calibrate = Command::new(bin("sabr"))
        .arg("calibrate")
        .arg(run.join("recording"))
        .arg("--out")
        .arg(&offline)
        .output()
        .expect("run sabr calibrate");
    assert!(
        calibrate.status.success(),
        "sabr calibrate failed: {}",
        String::from_utf8_lossy(&calibrate.stderr)
    );
    let live = params(&live_path);
    let offline = params(&offline.join("params.toml"));
    assert!(live.joints.offset.is_some(), "calibrated offsets");
    assert_eq!(live, offline, "live and offline calibrations differ");
    println!(
        "live calibration = sabr calibrate on the recording ({} encoder samples recorded, {} \
         used live); latency {:?} ms",
        recording.encoders.len(),
        live_samples,
        live.calibration.and_then(|c| c.latency_ms)
    );
}

#[test]
fn a_session_without_tip_readings_is_refused() {
    let _alone = sabr_integration_tests::run_alone();
    let Finished {
        success,
        run,
        announced,
        graph,
    } = run_graph("livecal-refuse", "never");
    let output = graph.output();
    assert!(!success, "the graph should fail:\n{output}");
    assert!(
        announced.is_empty(),
        "nothing may be announced: {announced:?}"
    );
    assert!(
        !run.join("calibration/params.toml").exists(),
        "no params.toml may be written"
    );
    assert!(
        output.contains("refusing to announce") && output.contains("tip-sphere readings"),
        "the launcher output names the reason:\n{output}"
    );
    assert!(
        output.contains("required node calibrator ended"),
        "the calibrator's failure ends the graph:\n{output}"
    );
}
