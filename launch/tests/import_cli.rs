//! `sabr import ipa` on the fixture subset of the UR10 laser-tracker data: the poses-v1
//! recording it writes (set-ups, order, orientation convention, units, mounting), the
//! `--setup` override, and clear errors for malformed series.

use std::path::{Path, PathBuf};
use std::process::Command;

use sabr_recording::poses::PosesRecording;

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/recording/tests/fixtures/ipa-robot-accuracy")
}

fn import(series: &[&Path], out: &Path, extra: &[&str]) -> (bool, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_sabr"))
        .args(["import", "ipa"])
        .args(series)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    (
        output.status.success(),
        String::from_utf8(output.stderr).unwrap(),
    )
}

fn all_series() -> Vec<PathBuf> {
    ["Series_A", "Series_B", "Series_C"]
        .iter()
        .map(|s| fixture().join(s))
        .collect()
}

fn refs(paths: &[PathBuf]) -> Vec<&Path> {
    paths.iter().map(PathBuf::as_path).collect()
}

#[test]
fn imports_the_three_series_into_two_setups() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("rec");
    let series = all_series();
    let (ok, stderr) = import(&refs(&series), &out, &[]);
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("Series_A: set-up Series_A (no hand-eye set: its own placement)"),
        "{stderr}"
    );
    let recording = PosesRecording::read(&out).unwrap();
    assert_eq!(
        recording.joints,
        [
            "shoulder_pan_joint",
            "shoulder_lift_joint",
            "elbow_joint",
            "wrist_1_joint",
            "wrist_2_joint",
            "wrist_3_joint"
        ]
    );
    let count = |sequence: &str, setup: &str| {
        recording
            .rows
            .iter()
            .filter(|r| r.sequence == sequence && r.setup == setup)
            .count()
    };
    assert_eq!(count("Series_A", "Series_A"), 298);
    assert_eq!(count("Series_B", "Series_B+Series_C"), 299);
    assert_eq!(count("Series_C", "Series_B+Series_C"), 309);
    // The URDF is copied in and parses.
    let tree = sabr_model::KinematicTree::from_urdf_str(&recording.urdf_text).unwrap();
    assert_eq!(tree.name(), "ur10");
    assert_eq!(
        recording
            .joint_order(
                &recording
                    .joints
                    .iter()
                    .map(String::as_str)
                    .collect::<Vec<_>>()
            )
            .unwrap(),
        [0, 1, 2, 3, 4, 5]
    );

    // First row of A: measurement_x/y/z in mm, rx/ry/rz = (-90.409151, -59.885105,
    // -90.887438) degrees, intrinsic XYZ (scipy `Rotation.from_euler('XYZ', ..., degrees=True)`
    // gives x, y, z, w = -0.18083566, -0.68490138, -0.18653568, 0.68074444); no std columns.
    let first = &recording.rows[0];
    assert_eq!((first.index, first.line), (0, 2));
    // The file's own rounded quarter turns, as written.
    let quarter: f64 = "-1.5708".parse().unwrap();
    assert_eq!(first.joints, [quarter, quarter, 0.0, quarter, 0.0, 0.0]);
    assert_eq!(first.temperature_c, Some(23.6800003051758));
    let tmac = first.targets[0].unwrap();
    assert_eq!(tmac.position_mm, [2361.9831, -1368.5474, 119.39713]);
    let expected = [
        0.680744444672422,
        -0.1808356610527434,
        -0.6849013823797772,
        -0.18653568332499665,
    ];
    let q = tmac.orientation.unwrap();
    for (a, b) in q.iter().zip(expected) {
        assert!((a - b).abs() < 1e-12, "{q:?} vs {expected:?}");
    }
    assert!(tmac.position_std_mm.is_none() && tmac.orientation_std_rad.is_none());

    // First row of B: standard deviations in mm, angular ones converted from degrees.
    let b = recording
        .rows
        .iter()
        .find(|r| r.sequence == "Series_B")
        .unwrap();
    assert_eq!(b.index, 0);
    let b = b.targets[0].unwrap();
    assert_eq!(b.position_std_mm, Some([0.031674, 0.013252, 0.0037622]));
    let std = b.orientation_std_rad.unwrap();
    assert!((std[0] - 0.0011832f64.to_radians()).abs() < 1e-15);
    // Order index = row order within the series.
    let c: Vec<u64> = recording
        .rows
        .iter()
        .filter(|r| r.sequence == "Series_C")
        .map(|r| r.index)
        .collect();
    assert_eq!(c, (0..309).collect::<Vec<_>>());

    // The nominal mounting is the inverse of Trafo_TM_F_init: 109 mm out along the flange z.
    let target = &recording.robot.targets[0];
    assert_eq!(
        (target.name.as_str(), target.link.as_str()),
        ("tmac", "tool0")
    );
    let t = target.mounting_translation.unwrap();
    assert!(
        t[0].abs() < 1e-3 && t[1].abs() < 1e-3 && (t[2] - 109.0).abs() < 1e-3,
        "{t:?}"
    );
    let r = target.mounting_rotation.unwrap();
    assert!((r[2] - std::f64::consts::FRAC_PI_2).abs() < 1e-3, "{r:?}");
}

#[test]
fn the_setup_option_overrides_the_hand_eye_rule() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("rec");
    let series = all_series();
    let (ok, stderr) = import(
        &refs(&series[1..]),
        &out,
        &["--setup", "Series_C=second-placement"],
    );
    assert!(ok, "{stderr}");
    let recording = PosesRecording::read(&out).unwrap();
    let setups: std::collections::BTreeSet<_> = recording
        .rows
        .iter()
        .map(|r| (r.sequence.as_str(), r.setup.as_str()))
        .collect();
    assert_eq!(
        setups.into_iter().collect::<Vec<_>>(),
        [
            ("Series_B", "Series_B+Series_C"),
            ("Series_C", "second-placement")
        ]
    );
    let (ok, stderr) = import(
        &refs(&series[1..]),
        &tmp.path().join("x"),
        &["--setup", "Series_D=x"],
    );
    assert!(!ok);
    assert!(
        stderr.contains("no series directory is named Series_D"),
        "{stderr}"
    );
}

/// A copy of the fixture's Series_B with its measurement file's line `line` replaced.
fn broken_series(tmp: &Path, edit: impl Fn(&str) -> String) -> PathBuf {
    let dir = tmp.join("Series_B");
    std::fs::create_dir_all(&dir).unwrap();
    for entry in std::fs::read_dir(fixture().join("Series_B")).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, dir.join(path.file_name().unwrap())).unwrap();
    }
    let file = dir.join("measurements_joint_configurations.csv");
    let text = std::fs::read_to_string(&file).unwrap();
    std::fs::write(&file, edit(&text)).unwrap();
    dir
}

#[test]
fn malformed_series_are_refused_with_file_line_and_field() {
    let tmp = tempfile::tempdir().unwrap();
    let bad_number = broken_series(&tmp.path().join("n"), |text| {
        let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
        lines[3] = lines[3].replacen(";21,86750031;", ";warm;", 1);
        lines.join("\n")
    });
    let (ok, stderr) = import(&[&bad_number], &tmp.path().join("out1"), &[]);
    assert!(!ok);
    assert!(
        stderr.contains("measurements_joint_configurations.csv line 4: field `measurement_temperature`: \"warm\" is not a number"),
        "{stderr}"
    );
    let short = broken_series(&tmp.path().join("s"), |text| {
        let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
        lines[5] = lines[5].split(';').take(10).collect::<Vec<_>>().join(";");
        lines.join("\n")
    });
    let (ok, stderr) = import(&[&short], &tmp.path().join("out2"), &[]);
    assert!(!ok);
    assert!(
        stderr.contains("line 6: field `measurement_rx`: missing (the row has 10 fields)"),
        "{stderr}"
    );
    let no_column = broken_series(&tmp.path().join("c"), |text| {
        text.replacen("elbow_joint", "elbow", 1)
    });
    let (ok, stderr) = import(&[&no_column], &tmp.path().join("out3"), &[]);
    assert!(!ok);
    assert!(
        stderr.contains("line 1: missing column `elbow_joint`"),
        "{stderr}"
    );
    // Nothing was written for a failed import.
    assert!(!tmp.path().join("out1").join("poses.csv").exists());
}

#[test]
fn refuses_a_non_empty_output_directory() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("keep.txt"), "mine").unwrap();
    let series = all_series();
    let (ok, stderr) = import(&refs(&series[..1]), tmp.path(), &[]);
    assert!(!ok);
    assert!(stderr.contains("is not empty"), "{stderr}");
    assert_eq!(
        std::fs::read_to_string(tmp.path().join("keep.txt")).unwrap(),
        "mine"
    );
}
