//! Shared helpers of the integration tests: simulated sessions and truth comparisons.

// Each test crate uses a subset of these helpers.
#![allow(dead_code)]

use sabr_model::{forward, JointMotion, RobotParams};
use sabr_recording::Recording;
use sabr_sim::{record_session, SimConfig, Truth};

/// A simulated session for `seed` at `duration_scale`, without effects.
pub fn session(seed: u64, duration_scale: f64) -> (Recording, Truth) {
    let mut config = SimConfig::new(seed);
    config.duration_scale = duration_scale;
    record_session(&config).expect("simulated session")
}

/// 3-D tip errors (mm) of `params` against the true tip at every validation hold.
pub fn truth_tip_errors(params: &RobotParams, truth: &Truth) -> Vec<f64> {
    let geometry = params.effective_geometry();
    truth
        .validation
        .iter()
        .map(|hold| {
            let q = params
                .joints_from_counts(&hold.counts, &JointMotion::default())
                .expect("offsets defined");
            (forward(&geometry, &q).expect("reachable").tip - hold.tip).norm()
        })
        .collect()
}

/// Root mean square.
pub fn rms(values: &[f64]) -> f64 {
    (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
}
