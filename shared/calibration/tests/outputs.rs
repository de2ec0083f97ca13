//! The output files of a calibration: complete, parseable and consistent with the model.
//! Needs a simulated session: ignored in debug builds; run with `cargo test --release`.

mod common;

use common::session;
use sabr_calibration::{calibrate, write_outputs, CalibrationOptions};
use sabr_model::{forward, JointMotion, RobotParams};

#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "heavy: cargo test --release -p sabr-calibration"
)]
fn params_toml_report_json_and_html_are_written_and_consistent() {
    let (recording, _truth) = session(11, 0.4);
    let calibration = calibrate(&recording, &CalibrationOptions::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("calibration");
    write_outputs(&calibration, &out).unwrap();

    let text = std::fs::read_to_string(out.join("params.toml")).unwrap();
    let params = RobotParams::from_toml_str(&text).unwrap();
    let latency = params
        .calibration
        .as_ref()
        .and_then(|c| c.latency_ms)
        .unwrap();
    assert!((latency - calibration.report.latency_ms).abs() < 1e-9);
    // The file reproduces the calibrated predictions at the validation holds.
    assert!(!calibration.predictions.is_empty());
    for prediction in &calibration.predictions {
        let q = params
            .joints_from_fractional_counts(&prediction.counts, &JointMotion::default())
            .unwrap();
        let tip = forward(&params.effective_geometry(), &q).unwrap().tip;
        let expected = nalgebra::Point3::from(prediction.tip);
        assert!((tip - expected).norm() < 1e-9, "{tip} vs {expected}");
    }

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert!(json["latency_ms"].as_f64().unwrap() > 0.0);
    assert_eq!(json["residual_rms"].as_array().unwrap().len(), 3);
    for model in json["residual_rms"].as_array().unwrap() {
        for key in ["front_mm", "back_mm", "tip_mm", "front_deg", "back_deg"] {
            assert!(model[key].as_f64().unwrap() > 0.0, "{key}");
        }
    }
    let parameters = json["parameters"].as_array().unwrap();
    assert_eq!(parameters.len(), 29);
    assert!(parameters.iter().all(|p| p["std_dev"].as_f64().is_some()));
    assert!(json["validation"]["tip_error"]["rms_mm"].as_f64().unwrap() > 0.0);
    assert!(json["run_time_s"].as_f64().unwrap() > 0.0);
    assert!(
        json["identifiability"]["condition_number"]
            .as_f64()
            .unwrap()
            >= 1.0
    );

    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>") && html.contains("gear_ratio[3]"));
    let csv = std::fs::read_to_string(out.join("validation_predictions.csv")).unwrap();
    assert_eq!(csv.lines().count(), calibration.predictions.len() + 1);
    // Atomic writes leave no temporary files behind.
    let names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 4, "{names:?}");
}
