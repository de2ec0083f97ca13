//! Calibration of simulated sessions against the simulator's truth.
//!
//! Heavy (a 5-minute session per seed): ignored in debug builds; run with
//! `cargo test --release -p sabr-calibration --test sim_accuracy`.

mod common;

use common::{rms, session, truth_tip_errors};
use sabr_calibration::{calibrate, CalibrationOptions};

#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "heavy: cargo test --release -p sabr-calibration"
)]
fn five_clean_seeds_meet_the_accuracy_goals() {
    for seed in 1..=5 {
        let (recording, truth) = session(seed, 1.0);
        let calibration = calibrate(&recording, &CalibrationOptions::default()).unwrap();
        let report = &calibration.report;

        let errors = truth_tip_errors(&calibration.params, &truth);
        let tip_rms = rms(&errors);
        assert!(
            tip_rms <= 0.15,
            "seed {seed}: held-out tip error {tip_rms:.4} mm RMS vs truth"
        );

        let latency_error = report.latency_ms - truth.tracker.latency_ms();
        assert!(
            latency_error.abs() <= 2.0,
            "seed {seed}: latency off by {latency_error:.3} ms"
        );

        for j in 0..5 {
            let fitted = calibration.params.joints.gear_ratio[j];
            let true_ratio = truth.robot.params.joints.gear_ratio[j];
            let relative = (fitted / true_ratio - 1.0).abs();
            assert!(
                relative <= 0.005,
                "seed {seed}: gear ratio {} off by {:.4} %",
                j + 1,
                relative * 100.0
            );
        }

        // Nominal, stepwise and joint fit are all reported, and the joint fit gains.
        let names: Vec<&str> = report
            .residual_rms
            .iter()
            .map(|r| r.model.as_str())
            .collect();
        assert_eq!(names, ["nominal", "stepwise", "joint"], "seed {seed}");
        let stepwise_errors = truth_tip_errors(&calibration.stepwise.robot, &truth);
        assert!(
            rms(&stepwise_errors) > tip_rms,
            "seed {seed}: the joint fit must beat the stepwise method"
        );
        let [nominal, stepwise, joint] = [0, 1, 2].map(|k| &report.residual_rms[k]);
        assert!(
            joint.tip_mm < stepwise.tip_mm && joint.tip_mm < nominal.tip_mm,
            "seed {seed}"
        );
        assert!(
            report
                .parameters
                .iter()
                .all(|p| p.std_dev.is_some_and(f64::is_finite)),
            "seed {seed}"
        );
        assert_eq!(
            report.identifiability.rank, report.identifiability.parameters,
            "seed {seed}"
        );
        let tip = report.validation.tip_error.expect("a tip error estimate");
        assert!(tip.rms_mm > 0.0 && tip.max_mm >= tip.rms_mm, "seed {seed}");
        // The validation phase is held out: no fitted observation lies in it.
        assert!(calibration
            .fit
            .observations
            .iter()
            .all(|o| o.phase != sabr_calibration::data::phases::Phase::Validation));
    }
}
