//! `sabr calibrate` and `sabr evaluate` on poses-v1 recordings of the fixture subset of the
//! UR10 laser-tracker data: the calibration lowers the held-out error, `sabr evaluate
//! --json` prints the documented fields, `--refit-setup` re-registers a new placement, and
//! bad inputs give errors naming the file, line and field.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fixture(series: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/recording/tests/fixtures/ipa-robot-accuracy")
        .join(series)
}

fn sabr(args: &[&std::ffi::OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sabr"))
        .args(args)
        .output()
        .unwrap()
}

fn run(args: &[&str]) -> Output {
    let args: Vec<&std::ffi::OsStr> = args.iter().map(std::ffi::OsStr::new).collect();
    sabr(&args)
}

fn import(dir: &Path, name: &str, series: &[&str]) -> PathBuf {
    let out = dir.join(name);
    let mut args = vec!["import".to_string(), "ipa".to_string()];
    args.extend(series.iter().map(|s| fixture(s).display().to_string()));
    args.extend(["--out".to_string(), out.display().to_string()]);
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let output = run(&refs);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    out
}

fn json_field(text: &str, field: &str) -> f64 {
    let value: serde_json::Value = serde_json::from_str(text.trim()).unwrap();
    value[field]
        .as_f64()
        .unwrap_or_else(|| panic!("no `{field}` in {text}"))
}

#[test]
fn calibrate_then_evaluate_on_another_placement() {
    let tmp = tempfile::tempdir().unwrap();
    let ab = import(tmp.path(), "ab", &["Series_A", "Series_B"]);
    let c = import(tmp.path(), "c", &["Series_C"]);
    let out = tmp.path().join("out");
    let output = run(&[
        "calibrate",
        &ab.display().to_string(),
        "--out",
        &out.display().to_string(),
    ]);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        stdout.contains("nominal") && stdout.contains("geometric"),
        "{stdout}"
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let held = |k: usize| report["steps"][k]["held_out"]["rms_mm"].as_f64().unwrap();
    assert!(
        held(1) < held(0),
        "geometric {} vs nominal {}",
        held(1),
        held(0)
    );
    assert!(std::fs::read_to_string(out.join("report.html"))
        .unwrap()
        .contains("<svg"));

    let params = out.join("params-1.json").display().to_string();
    let c_dir = c.display().to_string();
    let refused = run(&["evaluate", "--params", &params, &c_dir]);
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains("Series_C") && stderr.contains("--refit-setup"),
        "{stderr}"
    );

    let output = run(&[
        "evaluate",
        "--params",
        &params,
        &c_dir,
        "--refit-setup",
        "--json",
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let text = String::from_utf8(output.stdout).unwrap();
    assert_eq!(json_field(&text, "count"), 309.0, "{text}");
    let (rms, mean, max) = (
        json_field(&text, "rms_mm"),
        json_field(&text, "mean_mm"),
        json_field(&text, "max_mm"),
    );
    assert!(
        mean <= rms && rms <= max && rms > 0.05 && rms < 3.0,
        "{text}"
    );
}

#[test]
fn bad_parameter_files_name_the_file_line_and_field() {
    let tmp = tempfile::tempdir().unwrap();
    let c = import(tmp.path(), "c", &["Series_C"]);
    let c_dir = c.display().to_string();
    let broken = tmp.path().join("broken.json");
    std::fs::write(
        &broken,
        "{\n  \"format\": \"serial-params-v1\",\n  \"robot\": 12\n}\n",
    )
    .unwrap();
    let output = run(&[
        "evaluate",
        "--params",
        &broken.display().to_string(),
        &c_dir,
    ]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains(&format!("{}:3:", broken.display())),
        "{stderr}"
    );

    let wrong = tmp.path().join("wrong.json");
    std::fs::write(
        &wrong,
        r#"{"format":"serial-params-v1","robot":"ur10","use_orientation":false,
            "reference_temperature_c":22.0,"setups":[],"targets":[
            {"name":"tmac","translation_mm":[0,0,100],"rotation_rad":[0,0,0]}],
            "geometric_errors":{"elbow_joint.qq":1.0},"covered_ranges":{},"effects":[]}"#,
    )
    .unwrap();
    let output = run(&[
        "evaluate",
        "--params",
        &wrong.display().to_string(),
        &c_dir,
        "--refit-setup",
    ]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("wrong.json")
            && stderr.contains("geometric_errors")
            && stderr.contains("elbow_joint.qq"),
        "{stderr}"
    );
}

#[test]
fn a_bad_pose_row_is_refused_with_its_line() {
    let tmp = tempfile::tempdir().unwrap();
    let c = import(tmp.path(), "c", &["Series_C"]);
    let csv = c.join("poses.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    lines[4] = lines[4].replacen(",0.", ",x.", 1);
    std::fs::write(&csv, lines.join("\n") + "\n").unwrap();
    let out = tmp.path().join("out");
    let output = run(&[
        "calibrate",
        &c.display().to_string(),
        "--out",
        &out.display().to_string(),
    ]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("poses.csv line 5") && stderr.contains("invalid number"),
        "{stderr}"
    );
}
