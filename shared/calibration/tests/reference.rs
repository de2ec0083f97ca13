//! The engine gives the same calibration as before it was restructured: parameters, latency,
//! the effects found and the leads, on the default simulated sessions (seeds 1..5) and the
//! effect sessions of the residual-loop tests, against `fixtures/reference.json` (recorded
//! with `sabr sim record` + `sabr calibrate` before the move).
//!
//! Tolerance: every value within [`TOLERANCE_SIGMAS`] of the reference's own standard
//! deviation (the statistical uncertainty of the value), so a change of the engine that
//! moves a result by a meaningful amount fails, while rounding differences pass.
//!
//! Release only (eleven 5-minute sessions):
//! `cargo test --release -p sabr-calibration --test reference`.

use sabr_calibration::{calibrate, Calibration, CalibrationOptions};
use sabr_sim::{record_session, SimConfig};
use serde_json::Value;

/// Largest allowed difference, in standard deviations of the reference value.
const TOLERANCE_SIGMAS: f64 = 0.01;

fn reference(name: &str) -> Value {
    let text = include_str!("fixtures/reference.json");
    let all: Value = serde_json::from_str(text).expect("reference.json parses");
    all["cases"]
        .as_array()
        .expect("cases")
        .iter()
        .find(|c| c["name"] == name)
        .unwrap_or_else(|| panic!("no reference case {name}"))
        .clone()
}

fn calibrated(case: &Value) -> Calibration {
    let mut config = SimConfig::new(case["seed"].as_u64().expect("seed"));
    config.effects = case["effects"]
        .as_array()
        .expect("effects")
        .iter()
        .map(|s| s.as_str().expect("spec").parse().expect("effect spec"))
        .collect();
    let (recording, _) = record_session(&config).expect("simulated session");
    calibrate(&recording, &CalibrationOptions::default()).expect("calibration")
}

fn number(value: &Value) -> f64 {
    value
        .as_f64()
        .unwrap_or_else(|| panic!("{value} is not a number"))
}

fn assert_close(what: &str, found: f64, expected: f64, sigma: f64) {
    let allowed = (TOLERANCE_SIGMAS * sigma).max(1e-12 * expected.abs());
    assert!(
        (found - expected).abs() <= allowed,
        "{what}: {found} vs reference {expected} (allowed ±{allowed:.3e}, σ {sigma:.3e})"
    );
}

fn check(name: &str) {
    let case = reference(name);
    let calibration = calibrated(&case);
    let report = &calibration.report;
    let latency_std = number(&case["latency_std_ms"]);
    assert_close(
        "latency_ms",
        report.latency_ms,
        number(&case["latency_ms"]),
        latency_std,
    );

    let expected = case["parameters"].as_object().expect("parameters");
    assert_eq!(
        report.parameters.len(),
        expected.len(),
        "{name}: parameters"
    );
    for row in &report.parameters {
        let values = expected[&row.name].as_array().expect("triple");
        let sigma = number(&values[2]);
        assert_close(
            &format!("{name} {} (stepwise)", row.name),
            row.stepwise,
            number(&values[0]),
            sigma,
        );
        assert_close(
            &format!("{name} {} (joint)", row.name),
            row.joint,
            number(&values[1]),
            sigma,
        );
    }

    let found = case["effects_found"].as_array().expect("effects_found");
    let labels: Vec<String> = report.effects.iter().map(|e| e.label.clone()).collect();
    assert_eq!(
        report.effects.len(),
        found.len(),
        "{name}: effects {labels:?}"
    );
    for (effect, expected) in report.effects.iter().zip(found) {
        assert_eq!(effect.name, expected["name"].as_str().unwrap(), "{name}");
        assert_eq!(
            effect.joint,
            expected["joint"].as_u64().map(|j| j as usize),
            "{name}"
        );
        assert_eq!(effect.link.as_deref(), expected["link"].as_str(), "{name}");
        assert_eq!(effect.harmonic, expected["harmonic"].as_f64(), "{name}");
        let parameters = expected["parameters"].as_object().expect("parameters");
        assert_eq!(effect.parameters.len(), parameters.len(), "{name}");
        for p in &effect.parameters {
            let values = parameters[&p.name].as_array().expect("pair");
            assert_close(
                &format!("{name} {} {}", effect.label, p.name),
                p.value,
                number(&values[0]),
                number(&values[1]),
            );
        }
    }
    assert_eq!(
        calibration.params.effects.len(),
        found.len(),
        "{name}: params.toml effects"
    );

    let leads: Vec<&str> = report
        .r#final
        .leads
        .iter()
        .map(|l| l.label.as_str())
        .collect();
    let expected_leads: Vec<&str> = case["leads"]
        .as_array()
        .expect("leads")
        .iter()
        .map(|l| l.as_str().unwrap())
        .collect();
    assert_eq!(leads, expected_leads, "{name}: leads");
}

macro_rules! reference_cases {
    ($($name:ident),* $(,)?) => {
        $(
            #[test]
            #[cfg_attr(debug_assertions, ignore = "release only")]
            fn $name() {
                check(stringify!($name));
            }
        )*
    };
}

reference_cases!(
    seed1,
    seed2,
    seed3,
    seed4,
    seed5,
    backlash3,
    ripple2,
    link4,
    compliance5,
    ripple_backlash7,
    thermal8,
);

/// Prints the reference entries of the cases named in `REFERENCE_CASES` (comma-separated)
/// as JSON, computed by today's engine, for a deliberate change of the physics (a new
/// simulator or model effect) to re-record them:
/// `REFERENCE_CASES=backlash3 cargo test --release -p sabr-calibration --test reference --
/// --ignored --nocapture record_reference_cases`.
#[test]
#[ignore = "re-records reference cases on request"]
fn record_reference_cases() {
    let names = std::env::var("REFERENCE_CASES").unwrap_or_default();
    for name in names.split(',').filter(|n| !n.is_empty()) {
        let mut case = reference(name);
        let calibration = calibrated(&case);
        let report = &calibration.report;
        case["latency_ms"] = report.latency_ms.into();
        case["latency_std_ms"] = report.latency_std_ms.into();
        let mut parameters = serde_json::Map::new();
        for row in &report.parameters {
            parameters.insert(
                row.name.clone(),
                serde_json::json!([row.stepwise, row.joint, row.std_dev]),
            );
        }
        case["parameters"] = parameters.into();
        case["effects_found"] = report
            .effects
            .iter()
            .map(|e| {
                let parameters: serde_json::Map<String, Value> = e
                    .parameters
                    .iter()
                    .map(|p| (p.name.clone(), serde_json::json!([p.value, p.std_dev])))
                    .collect();
                serde_json::json!({
                    "name": e.name,
                    "joint": e.joint,
                    "link": e.link,
                    "harmonic": e.harmonic,
                    "parameters": parameters,
                })
            })
            .collect::<Vec<_>>()
            .into();
        case["leads"] = report
            .r#final
            .leads
            .iter()
            .map(|l| Value::from(l.label.clone()))
            .collect::<Vec<_>>()
            .into();
        println!("REFERENCE {}", serde_json::to_string(&case).unwrap());
    }
}
