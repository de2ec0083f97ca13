//! Same seed → byte-identical recording and truth; what is written reads back.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::{short_config, temp_dir};
use sabr_recording::Recording;
use sabr_sim::{record_session, truth_dir, write_session, Truth};

/// Every file under `dir` (relative path → bytes), in sorted order.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(current) = stack.pop() {
        for entry in std::fs::read_dir(&current).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let name = path.strip_prefix(dir).unwrap().display().to_string();
                out.insert(name, std::fs::read(&path).unwrap());
            }
        }
    }
    out
}

#[test]
fn same_seed_writes_byte_identical_files_and_another_seed_does_not() {
    let root = temp_dir("determinism");
    let mut config = short_config(11, 0.05);
    config.effects = vec![
        "ripple:joint=2,harmonic=1,amplitude=0.002,phase=0.3"
            .parse()
            .unwrap(),
        "latency:ms=10".parse().unwrap(),
    ];
    let mut written = Vec::new();
    for (name, seed) in [("a", 11), ("b", 11), ("c", 12)] {
        config.seed = seed;
        let dir = root.join(name);
        let (recording, truth) = record_session(&config).unwrap();
        write_session(&dir, &recording, &truth).unwrap();
        written.push(files(&dir));
    }
    let expected = [
        "encoders.csv",
        "phases.csv",
        "robot.toml",
        "tracker.csv",
        "truth/effects.toml",
        "truth/frames.csv",
        "truth/params.toml",
        "truth/validation.csv",
    ];
    assert_eq!(written[0].keys().collect::<Vec<_>>(), expected);
    assert_eq!(written[0], written[1]);
    for name in expected.iter().filter(|n| **n != "robot.toml") {
        assert_ne!(
            written[0][*name], written[2][*name],
            "{name} does not depend on the seed"
        );
    }
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn written_recording_and_truth_read_back_equal_to_memory() {
    let root = temp_dir("roundtrip");
    let mut config = short_config(5, 0.05);
    config.effects = vec![
        "thermal:joint=3,amplitude=0.002,tau_s=60".parse().unwrap(),
        "link:link=l_b,delta=0.3".parse().unwrap(),
        "thermal:link=l_fe,delta=0.2,tau_s=30".parse().unwrap(),
        "sag:mm=0.4".parse().unwrap(),
        "clockdrift:ppm=120".parse().unwrap(),
    ];
    let (recording, truth) = record_session(&config).unwrap();
    let dir = root.join("rec");
    write_session(&dir, &recording, &truth).unwrap();

    let read = Recording::read(&dir).unwrap();
    assert_eq!(read.robot_toml, recording.robot_toml);
    assert_eq!(read.encoders, recording.encoders);
    assert_eq!(read.tracker, recording.tracker);
    assert_eq!(read.phases, recording.phases);
    assert_eq!(
        sabr_model::RobotParams::from_toml_str(&read.robot_toml).unwrap(),
        config.nominal
    );

    let read_truth = Truth::read_dir(&truth_dir(&dir)).unwrap();
    assert_eq!(read_truth.robot.params, truth.robot.params);
    assert_eq!(read_truth.robot.stops, truth.robot.stops);
    assert_eq!(read_truth.robot.thermal, truth.robot.thermal);
    assert_eq!(read_truth.robot.link_drift, truth.robot.link_drift);
    assert_eq!(read_truth.robot.link_drift.len(), 1);
    assert_eq!(read_truth.robot.needle_sag_mm, 0.4);
    let effects_toml = std::fs::read_to_string(truth_dir(&dir).join("effects.toml")).unwrap();
    for spec in [
        "thermal:link=l_fe,delta=0.2,tau_s=30",
        "sag:mm=0.4",
        "clockdrift:ppm=120",
    ] {
        assert!(effects_toml.contains(spec), "{spec} not in {effects_toml}");
    }
    assert_eq!(read_truth.tracker.period_ns, truth.tracker.period_ns);
    assert_eq!(truth.tracker.period_ns, 5e7 * (1.0 + 120.0 * 1e-6));
    assert_eq!(read_truth.effects, truth.effects);
    assert_eq!(read_truth.validation, truth.validation);
    assert_eq!(read_truth.frames, truth.frames);
    let (a, b) = (&read_truth.tracker, &truth.tracker);
    assert_eq!(a.base_latency_ms, b.base_latency_ms);
    assert_eq!(a.first_frame, b.first_frame);
    let pose_error = (a.tracker_from_base.inverse() * b.tracker_from_base)
        .translation
        .vector
        .norm();
    assert!(pose_error < 1e-9, "{pose_error}");

    let again = write_session(&dir, &recording, &truth).unwrap_err();
    assert!(again.to_string().contains("robot.toml"), "{again}");
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn malformed_truth_files_are_rejected_naming_file_and_line() {
    let root = temp_dir("malformed");
    let (recording, truth) = record_session(&short_config(2, 0.05)).unwrap();
    let dir = root.join("rec");
    write_session(&dir, &recording, &truth).unwrap();
    let frames = truth_dir(&dir).join("frames.csv");
    let text = std::fs::read_to_string(&frames).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines[3] = "12,abc,14";
    std::fs::write(&frames, lines.join("\n")).unwrap();
    let err = Truth::read_dir(&truth_dir(&dir)).unwrap_err().to_string();
    assert!(err.contains("frames.csv line 4"), "{err}");
    assert!(err.contains("exposure_t_ns"), "{err}");
    std::fs::remove_dir_all(&root).unwrap();
}
