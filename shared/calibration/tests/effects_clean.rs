//! No false discoveries: on clean simulated sessions (no effect injected) the residual loop
//! adds no effect, reports no structure, and finds the residual consistent with the
//! tracker noise.
//!
//! Release only: `cargo test --release -p sabr-calibration --test effects_clean`.

mod effects_support;

use effects_support::{config, run};

#[test]
#[cfg_attr(debug_assertions, ignore = "release only")]
fn eight_clean_seeds_get_no_effect() {
    for seed in 1..=8 {
        let run = run(&config(seed, 0.25, &[]));
        let report = &run.calibration.report;
        let last = &report.r#final;
        assert!(report.effects.is_empty(), "seed {seed}: {}", last.verdict);
        assert!(run.calibration.params.effects.is_empty(), "seed {seed}");
        assert!(last.leads.is_empty(), "seed {seed}: {:?}", last.leads);
        assert!(
            last.residual_is_noise && !last.structured_residual,
            "seed {seed}: {:?}",
            last.metrics.noise_test
        );
        assert_eq!(last.steps.len(), 1, "seed {seed}: only the paper model");
        // The strongest correlate stays well below the selection threshold.
        let strongest = &last.strongest_correlates[0];
        assert!(!strongest.significant, "seed {seed}: {strongest:?}");
        assert!(
            last.verdict.contains("No effect"),
            "seed {seed}: {}",
            last.verdict
        );
    }
}
