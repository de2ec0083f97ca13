//! An effect outside the library (the simulator's thermal drift of a joint offset) is
//! reported as structured residual with its strongest correlates, and no library effect is
//! claimed for it (issue 5).
//!
//! Release only: `cargo test --release -p sabr-calibration --test effects_outside`.

mod effects_support;

use effects_support::{config, run};

#[test]
#[cfg_attr(debug_assertions, ignore = "release only")]
fn thermal_drift_is_reported_as_structure_and_not_claimed() {
    let run = run(&config(
        8,
        0.25,
        &["thermal:joint=3,amplitude=0.003,tau_s=20"],
    ));
    let report = &run.calibration.report;
    let last = &report.r#final;
    assert!(
        report.effects.is_empty(),
        "claimed {:?}",
        last.effects_added
    );
    assert!(run.calibration.params.effects.is_empty());
    assert!(last.structured_residual);
    let lead = last.leads.first().expect("a lead");
    assert_eq!(lead.label, "drift_in_time θ3", "{:?}", last.leads);
    assert!(!lead.in_library && lead.significant);
    assert_eq!(last.strongest_correlates[0].label, "drift_in_time θ3");
    assert!(
        last.verdict.contains("not claimed") && last.verdict.contains("drift_in_time θ3"),
        "{}",
        last.verdict
    );
}
