//! Is what is left just noise? The tail probabilities the loop's tests need, and the test of
//! a fit's residual against the tracker noise measured with the robot at rest.
//!
//! The residual of each tested quantity kind is whitened by the noise measured at rest (for
//! the biopsy robot the static homing dwell), not by the noise re-estimated from the fit,
//! which would absorb any structure. Its variance
//! per degree of freedom, against 1, is an F ratio: both the residual and the reference
//! variance are estimates, with `dof` and `reference_dof` degrees of freedom. The test uses
//! `ln F ≈ N(0, 2/dof + 2/reference_dof)`. The distributions are `statrs`'s.

use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF, Normal};

use crate::fit::joint_fit::JointFit;
use crate::model::{NoiseModel, QuantityKind, RobotModel};

/// Upper tail `P(Z > z)` of the standard normal.
pub fn normal_tail(z: f64) -> f64 {
    Normal::standard().sf(z)
}

/// The χ² distribution with `k` degrees of freedom (at least 1).
fn chi2(k: usize) -> ChiSquared {
    ChiSquared::new(k.max(1) as f64).expect("a positive number of degrees of freedom")
}

/// Upper tail `P(χ²_k > x)`.
pub fn chi2_tail(x: f64, k: usize) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    chi2(k).sf(x)
}

/// The value `x` with `P(χ²_k > x) = p`.
pub fn chi2_quantile(p: f64, k: usize) -> f64 {
    chi2(k).inverse_cdf(1.0 - p)
}

/// Significance level of the test against the tracker noise.
pub const NOISE_TEST_LEVEL: f64 = 1e-3;

/// The residual of one quantity kind against the noise at rest.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NoiseTest {
    /// The quantity kind's name (e.g. `front`).
    pub tool: String,
    /// Residual variance per degree of freedom, whitened by the tracker noise at rest
    /// (1 = tracker noise only).
    pub variance_ratio: f64,
    /// Degrees of freedom of the residual (rows minus their share of the parameters).
    pub dof: f64,
    /// Degrees of freedom of the noise measured at rest.
    pub reference_dof: f64,
    /// One-sided probability of a ratio this large if the residual were tracker noise.
    pub p_value: f64,
    /// Whether the residual is consistent with tracker noise at [`NOISE_TEST_LEVEL`].
    pub is_noise: bool,
}

/// Tests the residuals of the pose kinds `kinds` of `fit` against `rest_noise`, measured on
/// `rest_frames` static frames (the reference has `6 · (rest_frames − 1)` degrees of
/// freedom).
pub fn noise_tests<M: RobotModel>(
    fit: &JointFit<M>,
    rest_noise: &NoiseModel,
    rest_frames: usize,
    kinds: &[QuantityKind],
) -> Vec<NoiseTest> {
    let raws = fit.problem().raw_residuals(&fit.model);
    let names = fit.model.quantities();
    let parameter_share = fit.layout.len() as f64 / fit.rows.max(1) as f64;
    let reference_dof = 6.0 * rest_frames.saturating_sub(1) as f64;
    kinds
        .iter()
        .map(|&kind| {
            let (mut sum, mut rows) = (0.0, 0.0);
            for ((block, raw), weight) in fit.blocks.iter().zip(&raws).zip(&fit.weights) {
                let Some(raw) = raw.filter(|_| block.kind == kind) else {
                    continue;
                };
                let mut white = [0.0; 6];
                rest_noise.of(kind).whiten(&raw, 6, &mut white);
                sum += weight * white.iter().map(|v| v * v).sum::<f64>();
                rows += weight * 6.0;
            }
            let dof = (rows * (1.0 - parameter_share)).max(1.0);
            let variance_ratio = sum / dof;
            let spread = (2.0 / dof + 2.0 / reference_dof.max(1.0)).sqrt();
            let p_value = normal_tail(variance_ratio.ln() / spread);
            NoiseTest {
                tool: names[kind.0].name.clone(),
                variance_ratio,
                dof,
                reference_dof,
                p_value,
                is_noise: p_value >= NOISE_TEST_LEVEL,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tails_match_known_values() {
        assert!((normal_tail(0.0) - 0.5).abs() < 1e-7);
        assert!((normal_tail(1.959_964) - 0.025).abs() < 1e-6);
        assert!((normal_tail(-1.0) - 0.841_344_7).abs() < 1e-6);
        // The 5 % points of χ²_1, χ²_2, χ²_3 and the 0.1 % point of χ²_1 (tables).
        assert!((chi2_tail(3.841_459, 1) - 0.05).abs() < 1e-6);
        assert!((chi2_tail(5.991_465, 2) - 0.05).abs() < 1e-6);
        assert!((chi2_tail(7.814_728, 3) - 0.05).abs() < 1e-6);
        assert!((chi2_quantile(0.05, 2) - 5.991_465).abs() < 1e-4);
        assert!((chi2_quantile(1e-3, 1) - 10.827_566).abs() < 1e-4);
        assert_eq!(chi2_tail(-1.0, 4), 1.0);
    }
}
