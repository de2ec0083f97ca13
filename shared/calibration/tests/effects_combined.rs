//! Two effects at once are both found, and the outputs carry them: `report.json` lists them
//! with their parameters, standard deviations and errors before and after, `report.html`
//! shows the residual plots, `params.toml` holds them.
//!
//! Release only: `cargo test --release -p sabr-calibration --test effects_combined`.

mod effects_support;

use effects_support::{assert_discovers, assert_parameter, Named};
use sabr_calibration::write_outputs;
use sabr_model::RobotParams;

#[test]
#[cfg_attr(debug_assertions, ignore = "release only")]
fn ripple_and_backlash_together_are_both_found_and_reported() {
    let specs = [
        "ripple:joint=3,harmonic=2,amplitude=0.004,phase=1.0",
        "backlash:joint=4,width=0.004",
    ];
    let expected = [
        Named::joint("transmission_ripple", 3),
        Named::joint("backlash", 4),
    ];
    let (run, figures) = assert_discovers(7, 0.25, &specs, &expected);
    figures.assert_paper_model_alone_fails();
    let report = &run.calibration.report;
    let index = |class: &str| report.effects.iter().position(|e| e.name == class).unwrap();
    assert_parameter(&run, index("transmission_ripple"), "amplitude", 0.004);
    assert_parameter(&run, index("backlash"), "width", 0.004);

    let dir = tempfile::tempdir().unwrap();
    write_outputs(&run.calibration, dir.path()).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("report.json")).unwrap())
            .unwrap();
    let effects = json["effects"].as_array().unwrap();
    assert_eq!(effects.len(), 2);
    for effect in effects {
        assert!(effect["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .all(|p| p["std_dev"].as_f64().is_some()));
        for side in ["before", "after"] {
            assert!(
                effect[side]["residual_rms"]["front_mm"].as_f64().is_some(),
                "{side}"
            );
            assert!(
                effect[side]["residual_rms"]["validation_marker_tip"]["rms_mm"]
                    .as_f64()
                    .is_some(),
                "{side}"
            );
        }
        let evidence = &effect["evidence"];
        assert!(
            evidence["chi2_gain"].as_f64().unwrap() > evidence["chi2_threshold"].as_f64().unwrap()
        );
    }
    let last = &json["final"];
    assert_eq!(
        last["steps"].as_array().unwrap().len(),
        3,
        "paper model and two effects"
    );
    assert_eq!(last["effects_added"].as_array().unwrap().len(), 2);
    assert!(last["strongest_correlates"]
        .as_array()
        .is_some_and(|c| !c.is_empty()));
    assert!(
        last.get("plots").is_none(),
        "plot data stays out of report.json"
    );

    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(html.contains("Residual loop") && html.ends_with("</body></html>"));
    assert!(html.contains("travel since the last reversal"));
    // Before and after: 5 joints × 2 scatter plots, a histogram and two step charts.
    assert!(
        html.matches("<svg").count() >= 13,
        "{} svg",
        html.matches("<svg").count()
    );

    let params = RobotParams::from_toml_str(
        &std::fs::read_to_string(dir.path().join("params.toml")).unwrap(),
    )
    .unwrap();
    assert_eq!(params.effects, run.calibration.params.effects);
    assert_eq!(params.effects.len(), 2);
}
